"""The benchmark suite: ``designopt.app.bench.command`` end to end (PSO variants beside CMA-ES),
bad input, and redrawing the figures from the archive."""

import pytest

from designopt.app import bench as bench_job
from designopt.app import records
from designopt.bench import suite
from designopt.core.errors import ConfigError
from designopt.figures import bench as bench_figs
from designopt.io import archive

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
    assert bench_job.command(str(cfg), None, None, True) == 0
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
    figs = bench_figs.draw_record(records.load(tmp_path / "a.h5"), tmp_path / "again")
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
        bench_job.command(str(cfg), None, None, True)
    assert needle in str(e.value) and "\n" not in str(e.value)
    assert not (tmp_path / "a.h5").exists()


def test_bench_unwritable_output(tmp_path):
    (tmp_path / "afile").write_text("")
    target = tmp_path / "afile" / "x.h5"  # its folder cannot be created (a file is in the way)
    cfg = write(tmp_path, BENCH)
    with pytest.raises(ConfigError, match="output '.*x.h5'"):
        bench_job.command(str(cfg), None, str(target), True)


def test_shipped_config_is_valid():
    from pathlib import Path

    from designopt.app.config import load

    p = Path(__file__).resolve().parents[1] / "configs" / "pso_benchmark.yaml"
    cfg, _ = load(p, suite.BenchConfig)
    suite.check(cfg, str(p))
    labels = [lab for lab, _, _ in suite.entries(cfg)]
    assert labels == ["p1", "p2", "p3", "p4", "p5", "p6", "p7", "cmaes"]


MO_BENCH = """
bench:
  functions: [zdt1, {name: dtlz2, n_objectives: 3, dim: 7}, sphere]
  dim: 4
  shifted: false
  variants: [nsga2, {name: nsga2, label: wide, settings: {eta_c: 5.0}}, p3]
  reference: nsga2
  n_particles: 24
  n_iters: 20
  n_runs: 5
precision: float64
output: OUT
"""


def test_multi_objective_cases_compare_hypervolumes(tmp_path, capsys):
    """ZDT1 and DTLZ2 (3 objectives) beside a single-objective case: each entry runs the
    cases of its kind; the archived hypervolume of every run equals moocore's of the
    archived front (NaN rows: dominated or infeasible), against (1.1, …, 1.1)."""
    moocore = pytest.importorskip("moocore")
    import numpy as np

    cfg = write(tmp_path, MO_BENCH)
    assert bench_job.command(str(cfg), None, None, True) == 0
    out = capsys.readouterr().out
    assert "zdt1  (hypervolume against (1.1, 1.1)" in out and "dtlz2_m3_d7" in out
    assert "IGD+ med" in out and "sphere  (success" in out
    rec = records.load(tmp_path / "a.h5")
    assert set(rec.entries("zdt1")) == {"nsga2", "wide"} and set(rec.entries("sphere")) == {"p3"}
    for case, m in (("zdt1", 2), ("dtlz2_m3_d7", 3)):
        st = rec.stats(case)
        assert st["higher_is_better"] and set(st["rows"]) == {"nsga2", "wide"}
        assert "p_holm" in st["rows"]["wide"]
        for e in ("nsga2", "wide"):
            g = rec.entries(case)[e]
            F = np.asarray(g["front_f"])
            assert F.shape == (5, 24, m)
            for i in range(5):
                pts = F[i][~np.isnan(F[i]).any(-1)]
                want = moocore.hypervolume(pts, ref=np.full(m, 1.1)) if len(pts) else 0.0
                assert g["hypervolume"][i] == pytest.approx(want, rel=1e-12, abs=1e-15)
            assert np.all(np.asarray(g["igd_plus"]) > 0)
        assert st["rows"]["nsga2"]["median"] == pytest.approx(
            np.median(rec.entries(case)["nsga2"]["hypervolume"])
        )
    assert "best hypervolume" in " ".join(rec.summary())


def test_multi_objective_bench_refuses_a_wrong_reference(tmp_path):
    cfg = write(
        tmp_path,
        MO_BENCH.replace(
            "reference: nsga2", "reference: nsga2\n  hypervolume_reference: [1.1, 1.1]"
        ),
    )
    with pytest.raises(ConfigError, match=r"key 'bench.hypervolume_reference': 2 values for 3"):
        bench_job.command(str(cfg), None, None, True)
    cfg = write(tmp_path, MO_BENCH.replace("zdt1, {name: dtlz2, n_objectives: 3, dim: 7}, ", ""))
    with pytest.raises(ConfigError, match=r"'nsga2' is multi-objective and bench.functions has no"):
        bench_job.command(str(cfg), None, None, True)
