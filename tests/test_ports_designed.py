"""Ports as design variables, on a body wall (issue: plan the operation): the wall's
closest-point projection against an independent optimisation and finite differences; a
port given by variables at the numbers of a fixed port gives that port's indices; the
instrument angle is the angle of the two arms' port lines; bad input is one line."""

from __future__ import annotations

import copy
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml
from scipy.optimize import minimize

from designopt.app.config import validate
from designopt.cli.commands import main
from designopt.core.keys import streams
from designopt.kinematics import wall as kw
from designopt.studies.serial import bodies, objective, taskindex

jax.config.update("jax_enable_x64", True)
ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------ the wall


def _closest_ellipsoid_scipy(p: np.ndarray, c: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The ellipsoid's closest point to p by a constrained minimisation from 12 starts."""
    best = None
    for th in np.linspace(0.2, 2.9, 4):
        for ph in np.linspace(-2.5, 2.5, 3):
            x0 = c + a * np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])
            r = minimize(lambda x: np.sum((x - p) ** 2), x0, method="SLSQP",
                         constraints=[{"type": "eq",
                                       "fun": lambda x: np.sum(((x - c) / a) ** 2) - 1}],
                         options={"ftol": 1e-15, "maxiter": 500})  # fmt: skip
            if best is None or r.fun < best.fun:
                best = r
    return best.x


def test_ellipsoid_projection_is_the_closest_point():
    rng = np.random.default_rng(3)
    c, a = np.array([0.1, -0.2, 0.3]), np.array([0.25, 0.18, 0.12])
    par = kw.wall_params(kw.EllipsoidWall(shape="ellipsoid", center=tuple(c), radii=tuple(a)))
    # outside and inside (near the wall, off the principal planes)
    u = rng.normal(size=(12, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    p = c + a * u * rng.uniform(0.6, 1.8, size=(12, 1))
    got = np.asarray(kw.project("ellipsoid", par, jnp.asarray(p)))
    assert np.allclose(np.sum(((got - c) / a) ** 2, -1), 1.0, atol=1e-12)  # on the wall
    for i in range(len(p)):
        ref = _closest_ellipsoid_scipy(p[i], c, a)
        assert np.linalg.norm(got[i] - p[i]) <= np.linalg.norm(ref - p[i]) + 1e-9
        np.testing.assert_allclose(got[i], ref, atol=2e-6)
    # a plane: p − ((p − c)·n) n
    hp = kw.wall_params(kw.HalfSpaceWall(shape="halfspace", point=(0, 0, 0.2), normal=(0, 1, 2)))
    q = np.asarray(kw.project("halfspace", hp, jnp.asarray(p)))
    n = np.array([0, 1, 2]) / np.sqrt(5)
    np.testing.assert_allclose(q, p - ((p - [0, 0, 0.2]) @ n)[:, None] * n, atol=1e-15)


def test_ellipsoid_projection_gradient_matches_finite_differences():
    c, a = jnp.asarray([0.0, 0.0, 0.1]), jnp.asarray([0.3, 0.2, 0.15])
    par = {"c": c, "v": a}
    p0 = np.array([0.21, -0.17, 0.33])

    def f(p):
        return jnp.sum(kw.project("ellipsoid", par, p) * jnp.asarray([1.0, -2.0, 0.5]))

    g = np.asarray(jax.grad(f)(jnp.asarray(p0)))
    h = 1e-6
    fd = [(f(jnp.asarray(p0 + h * e)) - f(jnp.asarray(p0 - h * e))) / (2 * h) for e in np.eye(3)]
    np.testing.assert_allclose(g, np.asarray(fd), rtol=1e-6, atol=1e-8)


# ------------------------------------------------------- a port from variables


def _puma(port, variables=None, wall=None) -> dict:
    with open(ROOT / "configs/urdf_puma560_port.yaml") as f:
        cfg = yaml.safe_load(f)
    s = cfg["study"]
    s["chain"]["urdf"] = str(ROOT / "configs/robots/puma560.urdf")
    s["indices"]["n_samples"] = 24
    s["task"]["port"] = port
    # the ports are the point here, not the IK's definition: no neighbour pass, a smaller
    # program to compile (each of these configs' fused programs is compiled once)
    s["task"].setdefault("ik", {})["neighbours"] = 0
    s["variables"] |= variables or {}
    if wall is not None:
        s["task"]["body_wall"] = wall
    return cfg


def _scores(cfg: dict, X: np.ndarray) -> tuple[np.ndarray, dict]:
    c = validate(copy.deepcopy(cfg), "test")
    pb = objective.problem(c.study, streams(c.seed), jnp.float64)
    f, aux = jax.jit(pb.fn)(pb.params, jnp.asarray(X), jax.random.key(0))
    return np.asarray(f), {k: np.asarray(v) for k, v in aux.items()}


def test_a_port_of_variables_at_the_fixed_numbers_gives_the_fixed_ports_indices():
    X = np.array([[0.43, 0.43, 0.4], [0.5, 0.35, 0.3]])
    f0, a0 = _scores(_puma([0.5, 0.1, -0.2]), X)
    moved = _puma(["px", "-my", -0.2], {"px": [0.4, 0.6], "my": [-0.2, 0.0]})
    f1, a1 = _scores(moved, np.c_[X, [[0.5, -0.1]] * 2])
    np.testing.assert_allclose(f1, f0, rtol=0, atol=1e-12)
    for k in a0:
        np.testing.assert_allclose(a1[k], a0[k], rtol=0, atol=1e-12, err_msg=k)
    assert a0["reach"].max() > 0.3  # the comparison is about reached targets
    # the same port on a plane wall (z = -0.2): a designed port is projected onto it
    wall = {"shape": "halfspace", "point": [0, 0, -0.2], "normal": [0, 0, 1]}
    on = _puma(["px", "-my", "pz"], {"px": [0.4, 0.6], "my": [-0.2, 0.0], "pz": [-0.3, 0.0]},
               wall)  # fmt: skip
    f2, a2 = _scores(on, np.c_[X, [[0.5, -0.1, -0.05]] * 2])  # 15 cm above: onto the wall
    np.testing.assert_allclose(f2, f0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a2["reach"], a0["reach"], rtol=0, atol=1e-12)


def test_designed_ports_lie_on_the_ellipsoid_wall_for_every_design():
    cfg = _puma(
        ["px", "py", 0.0],
        {"px": [0.3, 0.7], "py": [-0.1, 0.3]},
        {"shape": "ellipsoid", "center": [0.5, 0.1, -0.36], "radii": [0.25, 0.2, 0.16]},
    )
    c = validate(copy.deepcopy(cfg), "test")
    s = c.study
    p = taskindex.scene_params(s, jnp.float64)
    from designopt.studies.serial.mechanism import build

    mech = build(s)
    rng = np.random.default_rng(0)
    lo, hi = (np.asarray(v) for v in s.box()[1:])
    x = lo + (hi - lo) * rng.uniform(size=(50, len(lo)))
    full = jnp.asarray(np.c_[x, np.broadcast_to(mech.fixed, (50, len(mech.fixed)))] * mech.scale)
    port = np.asarray(bodies.port_points(p, full, "ellipsoid"))[0]  # (M, 3)
    r = np.sum(((port - [0.5, 0.1, -0.36]) / [0.25, 0.2, 0.16]) ** 2, -1)
    np.testing.assert_allclose(r, 1.0, atol=1e-12)
    # each the closest wall point to the design's (px, py, 0)
    ref = _closest_ellipsoid_scipy(np.array([x[0, 3], x[0, 4], 0.0]),
                                   np.array([0.5, 0.1, -0.36]), np.array([0.25, 0.2, 0.16]))  # fmt: skip
    np.testing.assert_allclose(port[0], ref, atol=2e-6)


# ----------------------------------------------------------- bad input: one line


def _run_eval(tmp_path: Path, capsys, cfg: dict, *needles: str) -> str:
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(cfg))
    capsys.readouterr()
    assert main(["eval", str(p)]) == 2
    out, err = capsys.readouterr()
    assert err.startswith("designopt: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in out + err
    for n in needles:
        assert n in err, (n, err)
    assert sorted(q.name for q in tmp_path.iterdir()) == ["c.yaml"]  # nothing written
    return err


@pytest.mark.parametrize("edit, needles", [
    (lambda s: s["task"].update(port=["qx", 0.1, -0.2]),
     ("task.port.0", "'qx' is neither a design variable")),
    (lambda s: s["task"].update(body_wall={"shape": "halfspace", "point": [0, 0, -0.1],
                                           "normal": [0, 0, 1]}),
     ("task.port", "lies 0.1 m off task.body_wall", "[0.5, 0.1, -0.1]")),
    (lambda s: s["task"].update(body_wall={"shape": "ellipsoid", "center": [0, 0, 0],
                                           "radii": [0.3, 0, 0.2]}),
     ("body_wall.radii.1", "must be > 0")),
    (lambda s: s["task"].update(body_wall={"shape": "halfspace", "point": [0, 0, -0.2],
                                           "normal": [0, 0, 1], "inside": True}),
     ("task.body_wall.inside", "not an obstacle")),
    (lambda s: (s["task"].pop("port"), s["task"].pop("insertion"), s["collision"].update(
        obstacles=[]), s["task"].update(body_wall={"shape": "halfspace", "point": [0, 0, 0],
                                                   "normal": [0, 0, 1]})),
     ("task.body_wall", "give task.port")),
    (lambda s: s["task"].update(instrument_angle=[30, 90]),
     ("task.instrument_angle", "give study.arms")),
    (lambda s: s["variables"].update(px=[0.4, 0.6]),
     ("design variable(s) ['px'] appear in no chain.set entry",)),
    (lambda s: (s["variables"].update(px=[2.0, 3.0]), s["task"].update(port=["px", 0.1, -0.2])),
     ("task.insertion", "ports of", "designs across the box")),
])  # fmt: skip
def test_bad_port_input_is_one_line_naming_the_key(tmp_path, capsys, edit, needles):
    cfg = _puma([0.5, 0.1, -0.2])
    edit(cfg["study"])
    _run_eval(tmp_path, capsys, cfg, *needles)


def test_the_instrument_band_is_checked(tmp_path, capsys):
    with open(ROOT / "configs/two_ur5_front.yaml") as f:
        cfg = yaml.safe_load(f)
    cfg["study"]["chain"]["urdf"] = str(ROOT / "configs/robots/ur5/ur5_instrument.urdf")
    cfg["study"]["task"]["instrument_angle"] = [90, 30]
    _run_eval(tmp_path, capsys, cfg, "task.instrument_angle", "0 ≤ lo < hi ≤ 180")


# --------------------------------------------------------- the instrument angle


def test_instrument_angle_is_the_angle_of_the_two_port_lines():
    """Two UR5s through their ports: each arm's tool axis at a reached target is the
    line from its port to the target, and ``instrument_angle`` is the mean angle of
    those lines over the tuples both arms reach; ``instrument_ok`` the share in band."""
    with open(ROOT / "configs/two_ur5_front.yaml") as f:
        cfg = yaml.safe_load(f)
    s = cfg["study"]
    s["chain"]["urdf"] = str(ROOT / "configs/robots/ur5/ur5_instrument.urdf")
    s["indices"]["n_samples"] = 48
    s["task"]["instrument_angle"] = [40, 70]
    c = validate(cfg, "test")
    s = c.study
    from designopt.studies.serial.mechanism import build

    mech = build(s)
    keys = streams(c.seed)
    params = ({"q_lower": jnp.asarray(mech.lower), "q_upper": jnp.asarray(mech.upper),
               "sample_key": keys["samples"]} | taskindex.targets(s, keys["samples"], jnp.float64)
              | bodies.base_params(s, mech, jnp.float64) | taskindex.scene_params(s, jnp.float64))  # fmt: skip
    full = jnp.asarray([[0.425, 0.39225, 0.6]])
    per = jax.jit(lambda p, X: taskindex.per_target(mech, s, p, X, jnp.float64))(params, full)
    t = np.asarray(params["target_p"])
    ports = np.array([[-0.06, 0, 0.20], [0.06, 0, 0.20]])
    ok = np.asarray(per["success"]) > 0.5  # (A, 1, N)
    assert ok.mean() > 0.8
    for k in range(2):
        line = t - ports[k]
        line /= np.linalg.norm(line, axis=1, keepdims=True)
        ax = np.asarray(per["axis"])[k, 0]
        np.testing.assert_allclose(ax[ok[k, 0]], line[ok[k, 0]], atol=1e-7)
    est = taskindex.estimates_of(s, mech, per, params)
    # the tuples: arm 1's targets paired as taskindex pairs them (within a replication group)
    key = jax.random.fold_in(params["sample_key"], 2)
    R, run = taskindex.groups(s)
    lab = np.arange(len(t)) // run % R  # target t's replication group
    perm = np.asarray(taskindex.perms(key, len(t), jnp.asarray(lab), 2)[1])
    assert np.all(lab[perm] == lab) and not np.any(perm == np.arange(len(t)))
    u0 = t - ports[0]
    u1 = t[perm] - ports[1]
    cos = np.sum(u0 * u1, 1) / np.linalg.norm(u0, axis=1) / np.linalg.norm(u1, axis=1)
    ang = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    both = ok[0, 0] & ok[1, 0][perm]
    np.testing.assert_allclose(float(est["instrument_angle"][0][0]), ang[both].mean(), atol=1e-5)
    # its SE: batch means over the groups that hold targets (the ratio estimator Σ angle /
    # Σ both; 48 targets in runs of 16 under the neighbour pass fill 3 of the R groups)
    used = np.unique(lab)
    Rn = len(used)
    Y = np.bincount(lab, np.where(both, ang, 0.0), R)[used]
    X = np.bincount(lab, both.astype(float), R)[used]
    r = Y.sum() / X.sum()
    se = np.sqrt(np.sum((Y - r * X) ** 2) / (Rn * (Rn - 1))) / (X.sum() / Rn)
    np.testing.assert_allclose(float(est["instrument_angle"][1][0]), se, rtol=1e-9)
    assert 0 < float(est["instrument_ok"][0][0]) <= float(est["arms_ok"][0][0])


def test_a_port_is_projected_onto_a_mesh_wall_within_the_grid_bound():
    """A mesh body wall (the abdomen's mesh of the planning case): designed ports land on
    its surface to within the grid's error bound (trimesh's exact distance), and a port of
    numbers off it is refused naming the key."""
    import trimesh

    from designopt.kinematics import sdf

    path = ROOT / "configs/data/abdomen.stl"
    wall = kw.MeshWall(shape="mesh", file=str(path), resolution=48, padding=0.03)
    par = kw.wall_params(wall)
    rng = np.random.default_rng(1)
    p = np.c_[rng.uniform(-0.15, 0.15, (40, 2)), np.full(40, 0.3)]  # above the abdomen
    q = np.asarray(kw.project("mesh", par, jnp.asarray(p)))
    m = trimesh.load(str(path), force="mesh")
    exact = np.abs(sdf.exact_sdf(m.vertices, m.faces, q))
    assert exact.max() <= wall.grid().bound(), exact.max()
    # each the nearest wall point to within the bound: no wall point is much closer
    near = np.abs(sdf.exact_sdf(m.vertices, m.faces, p))
    assert np.all(np.linalg.norm(q - p, axis=1) <= near + 2 * wall.grid().bound())


@pytest.mark.parametrize("z,needle", [
    (-0.3, "off task.body_wall"),  # 7 cm above the organ (0.154 m across): off the wall
    (-0.2, "farther than the wall's size"),  # 17 cm above: far off, a unit to check
])  # fmt: skip
def test_a_port_of_numbers_off_a_mesh_wall_is_refused(tmp_path, capsys, z, needle):
    cfg = _puma([0.5, 0.1, z])
    cfg["study"]["task"]["body_wall"] = {"shape": "mesh", "file": str(ROOT / "configs/data/organ.stl"),
                                         "xyz": [0.5, 0.1, -0.4]}  # fmt: skip
    _run_eval(tmp_path, capsys, cfg, "task.port", needle)
