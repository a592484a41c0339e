"""The pre-flight memory estimate (issue #38 §4): its terms against hand numbers, and one
small job's estimate against the peak resident set its real run reaches
(benchmarks/preflight.py measures the shipped configs)."""

import os
import re
import subprocess
import sys
from pathlib import Path

from designopt.app import preflight
from designopt.app.config import load
from designopt.app.preflight import BASE_BYTES, FRONT_BYTES, PROGRAM_BYTES, estimate
from designopt.studies import get
from designopt.studies.base import Cost

ROOT = Path(__file__).resolve().parent.parent
MiB = 1 << 20
UNITS = {"B": 1, "kB": 1e3, "MB": 1e6, "GB": 1e9, "TB": 1e12}


def test_memory_terms_by_hand():
    """A Cost with the memory fields at their defaults: 128 B per design-sample, nothing per design
    and no program of its own; with them, they count; a front adds its programs and the
    larger of the run's and the re-scoring's buffers."""
    plain = Cost(samples=10_000, chunk=5_000)
    assert preflight.extra(plain) == (128, 0, 0)
    m = preflight.memory(plain, designs=50, per_chunk=5_000, host=1_000)
    assert m == {"base": BASE_BYTES, "programs": PROGRAM_BYTES, "study program": 0,
                 "buffers": 50 * 5_000 * 128, "host": 1_000}  # fmt: skip
    rich = Cost(samples=2048, chunk=1024, bytes_per_sample=100, per_design=7_000, program=3 * MiB)
    m = preflight.memory(rich, designs=10, per_chunk=1024, front=True, rescore=(20, 4096))
    assert m["programs"] == PROGRAM_BYTES + FRONT_BYTES and m["study program"] == 3 * MiB
    assert m["buffers"] == max(10 * (1024 * 100 + 7_000), 20 * (4096 * 100 + 7_000))


def test_study_costs_by_hand():
    """The serial task study's IK (PUMA 560: 6 joints, 6×6 Jacobian, tool axis, n_best 8,
    4096 database entries; a block of 16 designs × 1024 targets: 4096 slots, three slot
    phases) and master9's fused chunk."""
    cfg = load(ROOT / "configs/puma560_task.yaml")[0]
    c = get("serial").cost(cfg.study)
    assert (c.samples, c.chunk, c.designs) == (2048, 1024, 16)
    assert preflight.extra(c) == (8 * 9 * (9 + 2 * 36), 8 * 12 * 4096,
                                  int((250 + 3 * (40 + 4.6 * 36)) * MiB))  # fmt: skip
    joint = load(ROOT / "configs/planar2r.yaml")[0]
    assert preflight.extra(get("serial").cost(joint.study)) == (24 * 2 * 2, 0, 0)
    m9 = load(ROOT / "configs/master9.yaml")[0]
    assert preflight.extra(get("master9").cost(m9.study)) == (8, 0, 0)


def test_estimate_of_the_main_job_by_hand():
    """configs/master9.yaml: n_norm 64 designs in flight (above 50 particles and 41
    iterations) × 8192 samples × 8 B halved for float32, and the host's histories."""
    cfg = load(ROOT / "configs/master9.yaml")[0]
    est = estimate(cfg, get("master9"))
    host = 8 * (1 * 41 * (3 + 3) * 3 + 50 * 3 * 8)
    assert est.parts == {"base": BASE_BYTES, "programs": PROGRAM_BYTES, "study program": 0,
                         "buffers": 64 * 8192 * 4, "host": host}  # fmt: skip
    assert est.memory == sum(est.parts.values())
    assert "about 453 MB" in est.lines[0]


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return env


SMALL_TASK = """
study:
  name: serial
  chain:
    convention: standard
    joints:
      - {type: R, a: l1, alpha: 0, d: 0, theta: 0, limits: [-180, 180]}
      - {type: R, a: l2, alpha: 0, d: 0, theta: 0, limits: [-180, 180]}
  variables: {l1: [0.2, 2.0], l2: [0.2, 2.0]}
  task: {region: {shape: cylinder, center: [1.2, 0, 0], axis: [0, 0, 1], radius: 0.5, height: 0}}
  indices: {jacobian: [vx, vy], norm: "2", measure: task, n_samples: 512}
  objective: {gci: -1.0}
optimizer: {name: ptpso, n_particles: 16, n_iters: 2, n_runs: 1}
precision: float64
seed: 0
"""


def test_estimate_within_1_5x_of_the_measured_peak(tmp_path):
    """A small task job (planar 2R; 16 designs × 512 targets fill the IK's three slot
    phases, as a swarm does): the dry run's estimate and the real run's peak resident set
    (the child's VmHWM; --no-figures: figures fork children) agree within 1.5×. Its
    peak is mostly XLA compiling the IK: 0.54 GB measured with the block program of 16
    designs × 256 targets (0.8 GB when the 16 designs × 512 targets were one program)."""
    cfg = tmp_path / "small.yaml"
    cfg.write_text(SMALL_TASK)
    cli = [sys.executable, "-m", "designopt", "run", str(cfg)]
    dry = subprocess.run([*cli, "--dry-run", "--out", str(tmp_path / "a.h5")],
                         capture_output=True, text=True, env=_env(), cwd=ROOT)  # fmt: skip
    m = re.search(r"pre-flight: about ([\d.]+) (B|kB|MB|GB|TB) of memory", dry.stdout)
    assert dry.returncode == 0 and m, dry.stdout + dry.stderr
    est = float(m.group(1)) * UNITS[m.group(2)]
    # the child's own high-water mark (VmHWM of its address space): ru_maxrss from wait4
    # would count this test process's resident set too, copied at the fork before exec
    code = ("import sys\nfrom designopt.cli.commands import main\nrc = main(sys.argv[1:])\n"
            "hwm = next(ln for ln in open('/proc/self/status') if ln.startswith('VmHWM:'))\n"
            "print('VmHWM', hwm.split()[1], file=sys.stderr)\nsys.exit(rc)")
    r = subprocess.run([sys.executable, "-c", code, "run", str(cfg), "--no-figures", "--quiet",
                        "--no-cache", "--overwrite", "--out", str(tmp_path / "a.h5")],
                       env=_env(), cwd=ROOT, capture_output=True, text=True)  # fmt: skip
    assert r.returncode == 0, r.stderr
    peak = float(re.search(r"VmHWM (\d+)", r.stderr).group(1)) * 1024  # kB
    assert 1 / 1.5 <= est / peak <= 1.5, (est, peak)
