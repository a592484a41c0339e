"""The benchmark suite: ``benchsuite.command`` end to end (PSO variants beside CMA-ES),
bad input, and redrawing the figures from the archive."""

import pytest

from designopt import archive, benchsuite
from designopt.config import ConfigError
from designopt.figures import bench as bench_figs

BENCH = """
bench:
  functions: [sphere, rastrigin]
  dim: 5
  shifted: true
  variants: [p2, p3, p5, cmaes, {name: p3, label: p3_wide, settings: {gamma: 1.0e-3}}]
  n_particles: 10
  n_iters: 50
  n_runs: 12
precision: float64
output: OUT
"""


def write(tmp_path, text, name="c.yaml"):
    p = tmp_path / name
    p.write_text(text.replace("OUT", str(tmp_path / "a.h5")))
    return p


def test_bench_small_suite(tmp_path, capsys):
    cfg = write(tmp_path, BENCH)
    assert benchsuite.command(str(cfg), None, None, True) == 0
    out = capsys.readouterr().out
    assert "rastrigin_shifted" in out and "p (Holm)" in out and "cmaes" in out
    assert f"archive: {tmp_path / 'a.h5'}" in out
    a = archive.read(tmp_path / "a.h5")
    assert a["attrs"]["kind"] == "bench"
    st = a["bench"]["sphere"]["attrs"]["stats"]["rows"]
    assert set(st) == {"p2", "p3", "p5", "cmaes", "p3_wide"}
    assert "p_holm" in st["cmaes"] and "p_holm" not in st["p3"]
    assert a["bench"]["sphere"]["p3_wide"]["attrs"]["settings"]["gamma"] == pytest.approx(1e-3)
    assert a["bench"]["sphere"]["cmaes"]["attrs"]["settings"]["optimizer"] == "cmaes"
    h = a["bench"]["rastrigin"]["p5"]["history"]
    assert h.shape == (12, 51)
    assert st["p2"]["mean"] == pytest.approx(a["bench"]["sphere"]["p2"]["best_f"].mean())
    assert st["cmaes"]["median"] < 1.0  # CMA-ES makes progress on Sphere-5 (from ~1e4)
    names = ("fig10_final_values", "fig11_convergence_iterations", "convergence_curves")
    for n in names:
        assert (tmp_path / f"{n}.png").exists() and (tmp_path / f"{n}.pdf").exists()
    figs = bench_figs.draw_record(archive.load(tmp_path / "a.h5"), tmp_path / "again")
    assert {p.stem for p in figs} == set(names)


@pytest.mark.parametrize(
    "old,new,needle",
    [
        (
            "[p2, p3, p5, cmaes,",
            "[p2, p8, p5, cmaes,",
            "key 'bench.variants.1': unknown optimizer 'p8'",
        ),
        ("gamma: 1.0e-3", "sigma0: 0.3", "key 'bench.variants.4': unknown setting 'sigma0'"),
        ("n_runs: 12", "n_runs: 12\n  reference: p9", "key 'bench.reference'"),
        ("n_particles: 10", "n_particles: 3", "key 'bench.variants.3': population size"),
        ("n_runs: 12", "n_runs: 12\n  settings: {p4: {w: 0.5}}", "key 'bench.settings.p4'"),
        ("dim: 5", "dim: 0", "key 'bench.dim'"),
    ],
)
def test_bench_bad_input(tmp_path, old, new, needle):
    assert old in BENCH
    cfg = write(tmp_path, BENCH.replace(old, new))
    with pytest.raises(ConfigError) as e:
        benchsuite.command(str(cfg), None, None, True)
    assert needle in str(e.value) and "\n" not in str(e.value)
    assert not (tmp_path / "a.h5").exists()


def test_bench_unwritable_output(tmp_path):
    (tmp_path / "afile").write_text("")
    target = tmp_path / "afile" / "x.h5"  # its folder cannot be created (a file is in the way)
    cfg = write(tmp_path, BENCH)
    with pytest.raises(ConfigError, match="output '.*x.h5'"):
        benchsuite.command(str(cfg), None, str(target), True)


def test_shipped_config_is_valid():
    from pathlib import Path

    from designopt.config import load

    p = Path(__file__).resolve().parents[1] / "configs" / "pso_benchmark.yaml"
    cfg, _ = load(p, benchsuite.BenchConfig)
    benchsuite.check(cfg, str(p))
    labels = [lab for lab, _, _ in benchsuite.entries(cfg)]
    assert labels == ["p1", "p2", "p3", "p4", "p5", "p6", "p7", "cmaes"]
