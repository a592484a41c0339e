"""Pipeline end to end: archive schema, figures, refine, sweep, resume, bench, report."""

import h5py
import numpy as np
import pytest

from designopt.cli.commands import main
from designopt.io import archive

TINY = """
study:
  name: master9
  indices: {n_samples: 2048}
  n_norm: 8
optimizer: {name: ptpso, n_particles: 8, n_iters: 6, n_runs: 2}
precision: float64
seed: 1
output: OUT
"""

SCHEMA = {
    "optimizer": ["history", "best_f", "best_x", "converged_at", "history_x"],
    "best_run": ["iteration", "f", "f_k", "f_k_se", "f_l", "f_l_se", "f_p", "f_p_se",
                 "volume", "volume_se", "L"],
    "final": ["x", "f", "f_k", "f_k_se", "gci", "gci_se", "gpi", "gpi_se"],
    "problem": ["names", "lower", "upper", "norm_bounds"],
    "refine": ["run_index", "x0", "f0", "x", "f", "history", "gain"],
}  # fmt: skip
ROOT_ATTRS = ["kind", "config_yaml", "config_resolved_yaml", "seed", "versions", "jax_backend",
              "jax_devices", "wall_time_s", "compile_time_s", "run_time_s", "complete"]  # fmt: skip


def write(tmp_path, text, name="c.yaml"):
    p = tmp_path / name
    p.write_text(text.replace("OUT", str(tmp_path / "a.h5")))
    return p


def test_run_with_refine_matches_schema_and_draws_figures(tmp_path, capsys):
    cfg = write(tmp_path, TINY + "refine: {steps: 15, learning_rate: 0.02, n_best: 2}\n")
    assert main(["run", str(cfg), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "polish" in out and "compile" in out
    with h5py.File(tmp_path / "a.h5") as h:
        for g, names in SCHEMA.items():
            for n in names:
                assert n in h[g], f"{g}/{n} missing"
        for a in ROOT_ATTRS:
            assert a in h.attrs, a
        assert h.attrs["kind"] == "run" and h.attrs["complete"]
        assert h["best_run/f"].shape == (7,) and h["refine/history"].shape == (2, 16)
        # the polish never loses, stays in the box, and the final design is the better stage
        assert np.all(h["refine/gain"][()] >= 0)
        x = h["refine/x"][()]
        assert np.all(x >= h["problem/lower"][()]) and np.all(x <= h["problem/upper"][()])
        assert h["final/f"][()] <= h["optimizer/best_f"][()].min() + 1e-12
        assert np.all(h["final/f_k_se"][()] > 0)
    figs = sorted(p.name for p in (tmp_path / "a_figures").iterdir())
    for n in (
        "fig12_convergence",
        "fig13_dexterity_maps",
        "fig14_backlash_maps",
        "fig15_workspace",
    ):
        assert f"{n}.png" in figs and f"{n}.pdf" in figs
    assert main(["report", str(tmp_path / "a.h5")]) == 0


def test_sweep_of_three_values_gives_three_members(tmp_path, capsys):
    text = TINY + "sweep:\n  mode: list\n  vary: {optimizer.gamma: [1.0e-7, 1.0e-3, 1.0e-1]}\n"
    cfg = write(tmp_path, text)
    assert main(["sweep", str(cfg), "--quiet", "--no-figures"]) == 0
    assert "1 vmapped batch" in capsys.readouterr().out
    a = archive.read(tmp_path / "a.h5")
    mem = {k: v for k, v in a["members"].items() if k != "attrs"}
    assert len(mem) == 3 and a["attrs"]["n_members"] == 3
    gammas = [m["attrs"]["overrides"]["optimizer.settings.gamma"] for m in mem.values()]
    assert gammas == [1e-7, 1e-3, 1e-1]
    assert [m["optimizer"]["attrs"]["settings"]["gamma"] for m in mem.values()] == pytest.approx(
        gammas
    )
    # member 0 equals a plain run with the same gamma (common random numbers, same kernel)
    one = write(tmp_path, TINY.replace("output: OUT", f"output: {tmp_path / 'one.h5'}"), "one.yaml")
    assert main(["run", str(one), "--quiet", "--no-figures"]) == 0
    b = archive.read(tmp_path / "one.h5")
    np.testing.assert_allclose(
        mem["000"]["optimizer"]["history"], b["optimizer"]["history"], rtol=1e-12
    )


def test_sweep_over_a_study_key_runs_one_batch_per_value(tmp_path, capsys):
    text = TINY + "sweep:\n  vary: {design.a4: [5, 15], optimizer.rho_c: [0.5, 0.9]}\n"
    assert main(["sweep", str(write(tmp_path, text)), "--quiet", "--no-figures"]) == 0
    assert "4 members in 2 vmapped batch" in capsys.readouterr().out
    a = archive.read(tmp_path / "a.h5")
    a4 = [a["members"][k]["problem"]["attrs"]["info"]["fixed"]["a4"] for k in ("000", "002")]
    assert a4 == [5.0, 15.0]


@pytest.mark.parametrize(
    "text,cmd,needle",
    [
        (TINY + "sweep:\n  vary: {optimizer.nonsense: [1, 2]}\n", "sweep", "sweep.vary"),
        (TINY + "sweep:\n  vary: {design.a1: [300]}\n", "sweep", "design variable"),
        (TINY + "sweep:\n  vary: {study.n_samples: [-5]}\n", "sweep", "n_samples"),
        (TINY, "sweep", "key 'sweep'"),
        (TINY + "sweep:\n  vary: {optimizer.gamma: [1, 2]}\n", "run", "key 'sweep'"),
        (TINY + "refine: {steps: 0}\n", "run", "refine.steps"),
    ],
)
def test_bad_sweep_and_refine_input(tmp_path, capsys, text, cmd, needle):
    cfg = write(tmp_path, text)
    assert main([cmd, str(cfg), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1
    assert not (tmp_path / "a.h5").exists()


def _signal_at(monkeypatch, iteration, signum):
    """The CLI's progress bar raises ``signum`` in this process once ``iteration``
    iterations are done (a real signal, through the CLI's handlers)."""
    import contextlib
    import signal


    @contextlib.contextmanager
    def bar(total, desc):
        done = [0]

        def update(n):
            done[0] += n
            if done[0] >= iteration > done[0] - n:
                signal.raise_signal(signum)

        yield update

    from designopt.cli import commands as cli_main

    monkeypatch.setattr(cli_main, "_progress", lambda quiet: bar)


def test_interrupted_run_is_marked_incomplete_and_resume_matches(tmp_path, monkeypatch, capsys):
    import signal

    cfg = write(tmp_path, TINY.replace("n_iters: 6", "n_iters: 20"))
    assert (
        main(["run", str(cfg), "--quiet", "--no-figures", "--out", str(tmp_path / "ref.h5")]) == 0
    )
    # an existing good archive at the target must survive the interruption untouched
    (tmp_path / "a.h5").write_bytes((tmp_path / "ref.h5").read_bytes())
    before = (tmp_path / "a.h5").read_bytes()
    assert main(["run", str(cfg), "--quiet", "--no-figures"]) == 2  # exists: refused
    assert "--overwrite" in capsys.readouterr().err
    _signal_at(monkeypatch, 3, signal.SIGTERM)
    assert main(["run", str(cfg), "--quiet", "--no-figures", "--overwrite"]) == 143
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "SIGTERM" in err
    resume = err.split("`")[1].split()
    assert resume[:3] == ["designopt", "run", str(cfg)] and resume[-1] == "--resume"
    assert "--overwrite" in resume and resume[resume.index("--seed") + 1] == "1"
    partial = archive.partial_path(tmp_path / "a.h5")
    with h5py.File(partial) as h:
        assert not h.attrs["complete"] and h["checkpoint"].attrs["done"] == 3
    assert (tmp_path / "a.h5").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "a.h5",
        "a.partial.h5",
        "c.yaml",
        "ref.h5",
    ]
    assert main(["show", str(partial)]) == 0
    assert main(["report", str(partial)]) == 2  # incomplete: says so, draws nothing
    monkeypatch.undo()
    assert main(resume[1:]) == 0  # the printed command, as given
    assert not partial.exists()
    with h5py.File(tmp_path / "a.h5") as a, h5py.File(tmp_path / "ref.h5") as r:
        assert a.attrs["resumed_from"] == 3
        for k in ("optimizer/history", "optimizer/history_x", "final/x", "final/f"):
            np.testing.assert_array_equal(a[k][()], r[k][()])
    # resuming with another seed is refused
    assert main(["run", str(cfg), "--quiet", "--resume", "--seed", "5", "--overwrite"]) == 2


def test_score_reports_the_constraint_violation():
    from designopt.app import pipeline
    from designopt.problems.constrained import sphere_linear

    P = sphere_linear(3)
    X = np.array([[0.5, 0.5, 0.5], [0.1, 0.1, 0.1], [-1.0, 0.0, 0.0]])
    res = pipeline.score(P, X)
    np.testing.assert_allclose(res["violation"], np.maximum(1.0 - X.sum(1), 0.0), atol=1e-12)
    np.testing.assert_allclose(res["f"], (X * X).sum(1), atol=1e-12)
