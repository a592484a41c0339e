"""``optimizer.fidelity``: study settings the search scores with instead of the study's
own (docs/configs.md, "Scores you can quote"). The search is the search of a config whose
study has those settings, bit for bit; every quoted score is the study's own; a key that
is not the study's, or that the study refuses, is one line naming ``optimizer.fidelity``."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest

from designopt.app import records, reporting
from designopt.cli.commands import main
from designopt.figures import canvas
from designopt.io import archive
from tests.test_final_rescoring import SIX_R, _planar, _write
from tests.test_html_report import page

ROOT = Path(__file__).resolve().parents[1]


def test_the_search_uses_the_fidelity_settings_and_the_quoted_scores_the_studys(tmp_path, capsys):
    """A planar 2R of 4096 samples searched on 512: its optimizer's history and design are
    those of the same config with 512 samples in the study (and the same final stream
    size); its final/ is re-scored on 4 × 4096 fresh samples, as the 4096-sample study
    asks; ``eval`` scores with the study's 4096, ``eval --fresh`` gives final/."""
    fid = tmp_path / "fid"
    low = tmp_path / "low"
    fid.mkdir()
    low.mkdir()
    p = _write(fid, _planar(**{"optimizer.fidelity": {"study.indices.n_samples": 512}}))
    q = _write(low, _planar(**{"study.indices.n_samples": 512, "final.n_samples": 4 * 4096}))
    capsys.readouterr()
    assert main(["run", p, "--quiet", "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert main(["run", q, "--quiet", "--no-figures"]) == 0
    capsys.readouterr()
    a, b = records.load(fid / "r.h5"), records.load(low / "r.h5")
    for k in ("best_x", "best_f", "history"):
        np.testing.assert_array_equal(a["optimizer"][k], b["optimizer"][k])
    assert a.n_samples_search == 512 and a.n_samples_used == 4 * 4096
    at = a["best_run"]["final"]["attrs"]
    assert at["fidelity"] == {"study.indices.n_samples": 512}  # JSON in the file
    for k in ("f", "gci", "gci_se", "volume"):
        assert float(a.final[k]) == float(b.final[k]), k  # the same fresh stream and size
        assert float(a.search[k]) == float(b.search[k]), k
    assert "on the search's samples with optimizer.fidelity" in out
    html = page(archive.read(fid / "r.h5"))  # the HTML report says so beside the table
    assert "the search scored with optimizer.fidelity (study.indices.n_samples = 512)" in html
    assert a.fidelity == {"study.indices.n_samples": 512} and b.fidelity == {}
    canvas.RECORD = []  # the convergence figure (the best run: the search's values) says so
    try:
        reporting.draw_figures(fid / "r.h5", a)
        (fig,) = [f for n, f in canvas.RECORD if n == "convergence"]
        title = fig._suptitle.get_text()
    finally:
        canvas.RECORD = None
        plt.close("all")
    assert title.endswith("\nthe search scored with study.indices.n_samples = 512"), title
    x = a.x
    design = ["--design", f"l1={x['l1']!r}", "--design", f"l2={x['l2']!r}"]
    assert main(["eval", p, *design, "--fresh", "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    assert ev["gci"] == pytest.approx(float(a.final["gci"]), rel=1e-12)
    assert main(["eval", p, *design, "--json"]) == 0  # the study's own 4096 samples
    ev = json.loads(capsys.readouterr().out)
    assert main(["eval", q, *design, "--set", "study.indices.n_samples=4096", "--json"]) == 0
    want = json.loads(capsys.readouterr().out)
    assert ev["gci"] == want["gci"] and ev["gci"] != pytest.approx(float(a.search["gci"]), rel=1e-9)


@pytest.mark.parametrize("key, says", [
    ("optimizer.fidelity.optimizer.n_iters=2", "a fidelity setting is a key of the study"),
    ("optimizer.fidelity.study.indices.n_smaples=2", "'study.indices.n_smaples': unknown key"),
    ("optimizer.fidelity.study.indices.n_samples=0", "'study.indices.n_samples'"),
    ("optimizer.fidelity.study.indices.n_samples=inf", "'study.indices.n_samples' takes whole"),
    ("optimizer.fidelity.study.indices.n_samples=2.5", "'study.indices.n_samples' takes whole"),
    ("optimizer.fidelity.study.indices.n_samples=1e300", "(of at most 63 bits), got 1e300"),
])  # fmt: skip
def test_a_bad_fidelity_key_is_one_line_naming_it(tmp_path, capsys, key, says):
    p = _write(tmp_path, _planar())
    capsys.readouterr()
    assert main(["run", p, "--set", key, "--quiet"]) == 2
    out, err = capsys.readouterr()
    assert err.startswith("designopt: error: ") and err.count("\n") == 1, err
    assert "key 'optimizer.fidelity" in err and says in err, err
    assert "Traceback" not in out + err and not (tmp_path / "r.h5").exists()


def test_the_optimism_warning_names_the_fidelity(tmp_path, capsys):
    """The 6R arm whose every design has the same GCI, its study at 4096 samples, searched
    on 8 (``optimizer.fidelity``): the search's value is optimistic, and the line says
    the search scored with other settings."""
    raw = SIX_R | {"study": SIX_R["study"] | {"indices": SIX_R["study"]["indices"]
                                               | {"n_samples": 4096}}}  # fmt: skip
    raw = raw | {"optimizer": raw["optimizer"] | {"fidelity": {"study.indices.n_samples": 8}}}
    p = _write(tmp_path, raw)
    capsys.readouterr()
    assert main(["run", p, "--quiet", "--no-figures"]) == 0
    out = capsys.readouterr().out
    warn = [ln for ln in out.splitlines() if ln.strip().startswith("warning: f = ")]
    assert len(warn) == 1, out
    assert "optimistic: the search scored with optimizer.fidelity (study.indices.n_samples=8)" \
        in warn[0] and "on the search's samples (8)" in warn[0], warn[0]  # fmt: skip


def test_a_task_runs_reach_band_counts_the_searchs_targets(tmp_path, capsys):
    """A task study (configs/planar2r_task.yaml, 2,048 targets) searched on 64: the
    convergence figure's reach (the search's values) has the Wilson band of 64 trials,
    the search's targets, not of the study's 2,048 (a band √32 too narrow)."""
    import jax

    from designopt.figures import style

    jax.config.update("jax_enable_x64", True)  # the task's IK (the CLI turns it on itself)
    out = tmp_path / "t.h5"
    args = ["run", str(ROOT / "configs" / "planar2r_task.yaml"), "--quiet", "--no-figures",
            "--set", "optimizer.fidelity.study.indices.n_samples=64", "--set",
            "optimizer.n_iters=2", "--set", "optimizer.n_particles=4", "--set",
            "final.n_samples=256", "--out", str(out)]  # fmt: skip
    assert main(args) == 0
    capsys.readouterr()
    rec = records.load(out)
    assert rec.n_samples_search == 64 and rec.fidelity == {"study.indices.n_samples": 64}
    canvas.RECORD = []
    try:
        reporting.draw_figures(out, rec)
        (fig,) = [f for n, f in canvas.RECORD if n == "convergence"]
        (ax,) = [a for a in fig.axes if a.get_ylabel().startswith("reach")]
        band = ax.collections[0].get_paths()[0].vertices[:, 1]
    finally:
        canvas.RECORD = None
        plt.close("all")
    p = np.clip(rec.best_run["reach"], 0.0, 1.0)
    lo, hi = style.wilson(p, 64.0)
    assert band.min() == pytest.approx(lo.min(), abs=1e-12)
    assert band.min() < style.wilson(p, 2048.0)[0].min() - 1e-3  # the study's count is not it


def test_the_search_settings_are_checked_once_with_the_studys(monkeypatch):
    """``reach.check`` (the region in reach, the ports, an obstacle over every link) reads
    neither the IK's settings nor the samples: the search's settings of a fidelity
    config (only those differ) are not checked again; other collision settings are."""
    from designopt.app.config import load
    from designopt.studies.serial import reach

    s = load(str(ROOT / "configs" / "port_placement.yaml"))[0].study
    calls: list[int] = []
    monkeypatch.setattr(reach, "_PASSED", {})
    monkeypatch.setattr(reach, "_check", lambda st: calls.append(1))
    reach.check(s)
    ik = s.task.ik.model_copy(update={"n_best": 2, "n_db": 1024})
    search = s.model_copy(update={"task": s.task.model_copy(update={"ik": ik}),
                                  "indices": s.indices.model_copy(update={"n_samples": 48})})
    reach.check(search)
    assert calls == [1]
    col = s.collision.model_copy(update={"tool_radius": 0.003})
    reach.check(s.model_copy(update={"collision": col}))
    assert calls == [1, 1]
