"""The generic serial study against independent references (closed forms of the planar 2R
arm, a numpy DH implementation of the PUMA 560 on the very same samples) and its bad input."""

import numpy as np
import pytest
from scipy import integrate

from designopt.app import pipeline
from designopt.app.config import load, validate
from designopt.cli.commands import main
from designopt.numerics import montecarlo as mc
from designopt.studies import streams
from designopt.studies.serial.mechanism import build

PLANAR = """
study:
  name: serial
  chain:
    convention: standard
    joints:
      - {type: R, a: l1, alpha: 0, d: 0, theta: 0, limits: [-180, 180]}
      - {type: R, a: l2, alpha: 0, d: 0, theta: 0, limits: [-180, 180]}
  variables: {l1: [0.2, 2.0], l2: [0.2, 2.0]}
  indices: {jacobian: [vx, vy], norm: "2", measure: joint, n_samples: 4096, chunk: 1024}
  objective: {gci: -1.0}
optimizer: {name: ptpso, n_particles: 6, n_iters: 3, n_runs: 1}
scan:
  vary: {l2: [0.25, 0.5, 1.0]}
  design: {l1: 1.0}
precision: float64
output: OUT
"""


def planar_inv_k(q2, l1, l2):
    """σmin/σmax of the planar 2R position Jacobian: a function of q2 and the lengths only."""
    F = l1**2 + 2 * l2**2 + 2 * l1 * l2 * np.cos(q2)  # ‖J‖_F²
    det = l1 * l2 * np.sin(q2)
    D = np.sqrt(np.maximum(F**2 - 4 * det**2, 0.0))
    return np.sqrt(np.maximum(F - D, 0.0) / (F + D))


def samples(cfg, n):
    """The joint samples the study uses (same stream, same chunks)."""
    ind = cfg.study.indices
    mech = build(cfg.study)
    n_chunks, chunk = mc.chunking(ind.n_samples, ind.chunk)
    key = streams(cfg.seed)["samples"]
    u = np.concatenate([np.asarray(mc.unit_samples(key, k * chunk, chunk, n, ind.sampler))
                        for k in range(n_chunks)])  # fmt: skip
    assert len(u) >= ind.n_samples
    return mech.lower + (mech.upper - mech.lower) * u


def write(tmp_path, text, name="c.yaml"):
    p = tmp_path / name
    p.write_text(text.replace("OUT", str(tmp_path / "a.h5")))
    return p


def test_planar_2r_fk_jacobian_and_singularity():
    cfg = validate(__import__("yaml").safe_load(PLANAR.replace("OUT", "x.h5")), "planar")
    m = build(cfg.study).model
    q = np.random.default_rng(0).uniform(-np.pi, np.pi, (50, 2))
    L = np.array([[1.3, 0.7]])
    R, p = m.fk(L, q)
    q1, q12 = q[:, 0], q.sum(1)
    np.testing.assert_allclose(p[0, :, 0], 1.3 * np.cos(q1) + 0.7 * np.cos(q12), atol=1e-12)
    np.testing.assert_allclose(p[0, :, 1], 1.3 * np.sin(q1) + 0.7 * np.sin(q12), atol=1e-12)
    J = np.asarray(m.jacobian(L, q, rows=(0, 1)))[0]
    np.testing.assert_allclose(J[:, 0, 1], -0.7 * np.sin(q12), atol=1e-12)
    np.testing.assert_allclose(J[:, 1, 0], 1.3 * np.cos(q1) + 0.7 * np.cos(q12), atol=1e-12)
    from designopt.studies.serial.objective import measures

    inv_k, man, adet = measures(J, "2", False)
    np.testing.assert_allclose(inv_k, planar_inv_k(q[:, 1], 1.3, 0.7), atol=1e-12)
    np.testing.assert_allclose(adet, np.abs(1.3 * 0.7 * np.sin(q[:, 1])), atol=1e-12)
    qs = np.array([[0.3, 0.0], [1.0, np.pi]])  # stretched and folded: singular
    inv_k, _, _ = measures(np.asarray(m.jacobian(L, qs, rows=(0, 1)))[0], "2", False)
    assert np.all(inv_k == 0.0)


@pytest.mark.parametrize("l2", [0.25, 0.5, 1.0])
def test_planar_2r_gci_volume_manipulability_against_closed_forms(l2):
    cfg = validate(__import__("yaml").safe_load(PLANAR.replace("OUT", "x.h5")), "planar")
    res = pipeline.evaluate(cfg, {"l1": 1.0, "l2": l2})
    q = samples(cfg, 2)
    # same samples: the estimate is exactly the sample mean of the closed form
    np.testing.assert_allclose(res["gci"], planar_inv_k(q[:, 1], 1.0, l2).mean(), rtol=1e-12)
    np.testing.assert_allclose(res["gcsei"], planar_inv_k(q[:, 1], 1.0, l2).std(), rtol=1e-10)
    man = np.abs(l2 * np.sin(q[:, 1]))
    np.testing.assert_allclose(res["manipulability"], man.mean(), rtol=1e-12)
    np.testing.assert_allclose(res["volume"], 4 * np.pi**2 * man.mean(), rtol=1e-12)
    # and the exact integrals lie within 4 standard errors
    gci = integrate.quad(lambda t: planar_inv_k(t, 1.0, l2), -np.pi, np.pi)[0] / (2 * np.pi)
    assert abs(res["gci"] - gci) < 4 * res["gci_se"]
    assert abs(res["volume"] - 8 * np.pi * l2) < 4 * res["volume_se"]  # ∫∫ |l1 l2 sin q2|
    assert abs(res["manipulability"] - 2 * l2 / np.pi) < 4 * res["manipulability_se"]
    assert res["f"] == -res["gci"]


def _dh_numpy(q, a, alpha, d):
    """Standard-DH geometric Jacobian (base frame, rows v then ω), numpy, (N, 6, n)."""
    N, n = q.shape
    T = np.broadcast_to(np.eye(4), (N, 4, 4)).copy()
    z, o = [T[:, :3, 2].copy()], [T[:, :3, 3].copy()]
    for i in range(n):
        ct, st = np.cos(q[:, i]), np.sin(q[:, i])
        ca, sa = np.cos(alpha[i]), np.sin(alpha[i])
        A = np.zeros((N, 4, 4))
        A[:, 0] = np.stack([ct, -st * ca, st * sa, a[i] * ct], -1)
        A[:, 1] = np.stack([st, ct * ca, -ct * sa, a[i] * st], -1)
        A[:, 2] = np.stack([0 * ct, sa + 0 * ct, ca + 0 * ct, d[i] + 0 * ct], -1)
        A[:, 3, 3] = 1
        T = T @ A
        z.append(T[:, :3, 2].copy())
        o.append(T[:, :3, 3].copy())
    cols = [np.concatenate([np.cross(z[i], o[n] - o[i]), z[i]], -1) for i in range(n)]
    return np.stack(cols, -1)


def test_puma560_gci_against_numpy_dh_on_the_same_samples(tmp_path):
    cfg, _ = load("configs/puma560.yaml")
    raw = cfg.model_dump(by_alias=True) | {"precision": "float64"}
    raw["study"]["indices"] |= {"n_samples": 1024, "chunk": 512, "norm": "2", "normalized": False}
    raw["study"]["objective"] = {"gci": -1.0}
    cfg = validate(raw, "puma")
    a2, d4 = 0.45, 0.41
    res = pipeline.evaluate(cfg, {"a2": a2, "d4": d4})
    q = samples(cfg, 6)
    a = [0, a2, 0.0203, 0, 0, 0]
    d = [0, 0, 0.15005, d4, 0, 0]
    alpha = np.deg2rad([90, 0, -90, 90, -90, 0])
    J = _dh_numpy(q, a, alpha, d)
    J[:, 3:] *= 0.5  # length_scale
    s = np.linalg.svd(J, compute_uv=False)
    inv_k = np.where(s[:, -1] > 6 * np.finfo(float).eps * s[:, 0], s[:, -1] / s[:, 0], 0.0)
    np.testing.assert_allclose(res["gci"], inv_k.mean(), rtol=1e-10)
    man = np.abs(np.linalg.det(J))
    np.testing.assert_allclose(res["manipulability"], man.mean(), rtol=1e-10)
    # and the normalised Frobenius 1/k_F = 6 / (‖J‖_F ‖J⁻¹‖_F)
    raw["study"]["indices"] |= {"norm": "fro", "normalized": True}
    res_f = pipeline.evaluate(validate(raw, "puma"), {"a2": a2, "d4": d4})
    kf = np.sqrt((J**2).sum((1, 2)) * (np.linalg.inv(J) ** 2).sum((1, 2)))
    np.testing.assert_allclose(res_f["gci"], (6 / kf).mean(), rtol=1e-9)
    assert "volume" not in res  # full Jacobian: no position volume


def test_scan_and_eval_commands(tmp_path, capsys):
    cfg = write(tmp_path, PLANAR)
    assert main(["eval", str(cfg), "--design", "l1=1", "--design", "l2=0.5", "--json"]) == 0
    import json

    one = json.loads(capsys.readouterr().out)
    idx = ("f", "gci", "gcsei", "manipulability", "volume")
    assert set(one) == set(idx) | {k + "_se" for k in idx} | {"warnings"}
    assert one["warnings"] == []  # what run would print under the summary
    assert main(["scan", str(cfg), "--quiet", "--out", str(tmp_path / "s.h5")]) == 0
    from designopt.io import archive

    sc = archive.read(tmp_path / "s.h5")["scan"]
    assert sc["x"].shape == (3, 2) and sc["gci"].shape == (3,) and sc["gci_se"].shape == (3,)
    assert [n.decode() for n in sc["names"]] == ["l1", "l2"]
    np.testing.assert_allclose(sc["gci"][1], one["gci"], rtol=1e-12)
    assert (tmp_path / "s_figures" / "scan_l2.png").exists()
    assert main(["studies"]) == 0
    out = capsys.readouterr().out
    assert "serial" in out and "master9" in out


@pytest.mark.parametrize(
    "old,new,needle",
    [
        ("theta: 0, limits: [-180, 180]}\n      - ", "theta: 0, bogus: 1, limits: [-180, 180]}\n      - ",
         "study.chain.joints.0.bogus"),
        ("a: l2,", "a: l3,", "'l3' is neither a design variable"),
        ("limits: [-180, 180]}\n  variables", "limits: [180, -180]}\n  variables",
         "study.chain.joints.1.limits"),
        ("jacobian: [vx, vy], norm: \"2\", measure: joint", "jacobian: position, norm: \"2\", measure: cartesian",
         "needs a square Jacobian"),
        ("objective: {gci: -1.0}\noptimizer", "objective: {gci: -1.0, volume: 1.0}\noptimizer",
         "square position Jacobian"),
        ("jacobian: [vx, vy]", "jacobian: [vx, vq]", "study.indices.jacobian"),
        ("objective: {gci: -1.0}", "objective: {dexterity: -1.0}", "objective.dexterity"),
        ("variables: {l1: [0.2, 2.0], l2: [0.2, 2.0]}", "variables: {l1: [0.2, 2.0], l2: [2.0, 0.2]}",
         "study.variables"),
    ],
)  # fmt: skip
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, capsys, old, new, needle):
    assert old in PLANAR
    text = PLANAR.replace(old, new, 1)
    if "volume: 1.0" in new:
        text = text.replace("jacobian: [vx, vy]", "jacobian: [vx, wz]")
    cfg = write(tmp_path, text)
    for cmd in (["run", str(cfg), "--quiet"], ["scan", str(cfg), "--quiet"],
                ["eval", str(cfg), "--design", "l1=1"]):  # fmt: skip
        assert main(cmd) == 2
        err = capsys.readouterr().err
        assert needle in err and str(cfg) in err and err.count("\n") == 1, err
    assert not any(p.suffix == ".h5" for p in tmp_path.iterdir())


def test_bad_design_on_the_command_line(tmp_path, capsys):
    cfg = write(tmp_path, PLANAR)
    assert main(["eval", str(cfg), "--design", "l9=1"]) == 2
    assert "l9" in capsys.readouterr().err
    assert main(["eval", str(cfg), "--design", "l1"]) == 2
    assert "NAME=NUMBER" in capsys.readouterr().err


def test_linear_constraints_from_yaml_bind_the_optimum(tmp_path):
    """max workspace area ∫|det J| dq = 8π·l1·l2 of a planar 2R s.t. l1 + l2 ≤ 1: the
    optimum is l1 = l2 = 0.5 on the constraint (Deb's rules and the quadratic penalty)."""
    from designopt.app import pipeline
    from designopt.app.config import validate

    base = {
        "study": {
            "name": "serial",
            "chain": {"joints": [{"type": "R", "a": "l1", "limits": [-180, 180]},
                                 {"type": "R", "a": "l2", "limits": [-180, 180]}]},
            "variables": {"l1": [0.1, 1.0], "l2": [0.1, 1.0]},
            "indices": {"jacobian": ["vx", "vy"], "n_samples": 4096},
            "objective": {"volume": -1.0},
            "constraints": [{"terms": {"l1": 1, "l2": 1}, "le": 1.0}],
        },
        "optimizer": {"name": "cmaes", "n_particles": 12, "n_iters": 60, "n_runs": 2},
        "precision": "float64", "seed": 2,
    }  # fmt: skip
    for method, tol in (("deb", 1e-3), ("penalty", 2e-2)):
        raw = base | {
            "optimizer": base["optimizer"] | {"constraints": {"method": method, "weight": 1e4}}
        }
        rep = pipeline.run(validate(raw, "t"), "t", "t", tmp_path / f"{method}.h5")
        x = rep.tree["final"]["x"]
        np.testing.assert_allclose(x, [0.5, 0.5], atol=0.05)
        assert x.sum() <= 1.0 + tol
        if method == "deb":
            assert float(rep.tree["final"]["violation"]) == 0.0


def test_linear_constraint_names_must_be_design_variables():
    from designopt.app.config import validate
    from designopt.core.errors import ConfigError

    raw = {"study": {"name": "serial",
                     "chain": {"joints": [{"type": "R", "a": "l1", "limits": [-90, 90]}]},
                     "variables": {"l1": [0.1, 1.0]},
                     "constraints": [{"terms": {"l9": 1}, "le": 1.0}]}}  # fmt: skip
    with pytest.raises(ConfigError, match="key 'study.constraints.0.terms': \\['l9'\\]"):
        validate(raw, "t")
    raw["study"]["constraints"] = [{"terms": {"l1": 1}, "le": 1.0, "ge": 0.0}]
    with pytest.raises(ConfigError, match="exactly one of 'le' and 'ge'"):
        validate(raw, "t")
