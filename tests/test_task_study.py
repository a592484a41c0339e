"""The serial study under ``indices.measure: task`` against independent references: the
planar 2R over a disk off its base (reach from the circle-circle lens area, task GCI,
manipulability and the 5 % quantile of 1/k by quadrature in the distance from the base,
the joint margin by a 2-D quadrature), a spatial 3R arm over a ball (reach = the ball's
volume inside the reachable shell, sphere-sphere lens volumes), tool-axis targets checked
with a numpy DH forward kinematics, index constraints under Deb's rules and the penalty,
common random numbers, bad input and the commands."""

from __future__ import annotations

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate, optimize

import designopt
from designopt.cli.commands import main

PI = math.pi
C, RHO = 1.2, 0.5  # the disk: centre (C, 0, 0), radius RHO, in the base's xy-plane
DISK = {"shape": "cylinder", "center": [C, 0, 0], "axis": [0, 0, 1], "radius": RHO, "height": 0}
IK = {"n_db": 256, "n_nearest": 0, "n_random": 3}
DESIGNS = [(1.0, 0.6), (1.0, 0.8), (1.2, 0.3), (1.3, 0.7)]  # partial, whole, partial, whole


# ----------------------------------------------------------------- references (numpy/scipy)


def lens_area(r: float, c: float = C, rho: float = RHO) -> float:
    """Area of the disk of radius r about the base ∩ the disk of radius rho at distance c."""
    if r <= 0 or c >= r + rho:
        return 0.0
    if c <= abs(r - rho):
        return PI * min(r, rho) ** 2
    a = r * r * math.acos((c * c + r * r - rho * rho) / (2 * c * r))
    b = rho * rho * math.acos((c * c + rho * rho - r * r) / (2 * c * rho))
    return a + b - 0.5 * math.sqrt((-c + r + rho) * (c + r - rho) * (c - r + rho) * (c + r + rho))


def arc(r):
    """dA/dr: the length of the circle of radius r about the base inside the disk,
    2 r θ(r) with cos θ = (r² + c² − ρ²) / (2 r c) (law of cosines)."""
    r = np.asarray(r, np.float64)
    return 2 * r * np.arccos(np.clip((r * r + C * C - RHO**2) / (2 * r * C), -1.0, 1.0))


def inv_k_2r(r, l1, l2):
    """σmin/σmax of the planar 2R's 2×2 Jacobian at a tip distance r from the base: the
    columns are the tip's velocity for each joint, of lengths r and l2, so ‖J‖_F² =
    r² + l2², and det J = l1 l2 sin q2 with cos q2 = (r² − l1² − l2²) / (2 l1 l2);
    σ² = (F ± √(F² − 4 det²)) / 2."""
    r = np.asarray(r, np.float64)
    c2 = (r * r - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    det2 = (l1 * l2) ** 2 * np.clip(1 - c2 * c2, 0.0, None)
    F = r * r + l2 * l2
    D = np.sqrt(np.clip(F * F - 4 * det2, 0.0, None))
    return np.sqrt(np.clip(F - D, 0.0, None) / (F + D))


def man_2r(r, l1, l2):
    """|det J| = l1 l2 |sin q2|."""
    c2 = (np.asarray(r, np.float64) ** 2 - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    return l1 * l2 * np.sqrt(np.clip(1 - c2 * c2, 0.0, None))


def disk_reference(l1: float, l2: float) -> dict[str, float]:
    """The exact task indices of the planar 2R over the disk: reach (lens areas), gci and
    manipulability (quadrature in r with weight dA/dr, 0 where unreached) and gci_q05 (the
    5 % quantile of 1/k: the root of its CDF, which is the unreached share plus the lens
    areas where 1/k ≤ t, 1/k being unimodal in r)."""
    area = PI * RHO**2
    lo, hi = max(abs(l1 - l2), C - RHO), min(l1 + l2, C + RHO)
    reach = max(lens_area(min(l1 + l2, C + RHO)) - lens_area(abs(l1 - l2)), 0.0) / area
    out = {"reach": reach, "gci": 0.0, "manipulability": 0.0, "gci_q05": 0.0}
    if hi <= lo:
        return out
    for k, g in (("gci", inv_k_2r), ("manipulability", man_2r)):
        out[k] = integrate.quad(lambda r, g=g: g(r, l1, l2) * arc(r), lo, hi, limit=200)[0] / area
    if 1 - reach >= 0.05:
        return out
    rs = np.linspace(lo, hi, 20001)
    g = inv_k_2r(rs, l1, l2)
    top = int(np.argmax(g))
    assert np.all(np.diff(g[: top + 1]) >= 0) and np.all(np.diff(g[top:]) <= 0)  # unimodal
    r_top = optimize.minimize_scalar(lambda r: -inv_k_2r(r, l1, l2), bounds=(rs[max(top - 1, 0)],
                                     rs[min(top + 1, len(rs) - 1)]), method="bounded").x  # fmt: skip

    def cdf(t):
        a = lo if inv_k_2r(lo, l1, l2) >= t else optimize.brentq(
            lambda r: inv_k_2r(r, l1, l2) - t, lo, r_top, xtol=1e-14)  # fmt: skip
        b = hi if inv_k_2r(hi, l1, l2) >= t else optimize.brentq(
            lambda r: inv_k_2r(r, l1, l2) - t, r_top, hi, xtol=1e-14)  # fmt: skip
        inside = lens_area(a) - lens_area(lo) + lens_area(hi) - lens_area(b)
        return 1 - reach + inside / area

    out["gci_q05"] = optimize.brentq(lambda t: cdf(t) - 0.05, 0.0, float(inv_k_2r(r_top, l1, l2)),
                                     xtol=1e-12)  # fmt: skip
    return out


def joint_margin_reference(l1: float, l2: float, elbow_up: bool) -> tuple[float, float]:
    """(lower, upper) mean joint margin over the disk (0 where unreached), by a midpoint
    rule in (r, u) with φ = θ(r)·u (dA = r θ(r) dr du). The two IK branches q2 = ±acos c2
    have q1 = φ ∓ β, β = atan2(l2 sin|q2|, l1 + l2 cos q2); a joint with limits ±180°
    has margin 1 − |q|/π. Limits ±180° on both joints: the IK may return either branch
    (equal 1/k), so the mean lies between the means of the per-target min and max of the
    two. ``elbow_up`` (q2 in [0°, 180°]): one branch, margin of q2 = 1 − |q2 − π/2|/(π/2);
    lower = upper."""
    lo, hi = max(abs(l1 - l2), C - RHO), min(l1 + l2, C + RHO)
    nr, nu = 3000, 2000
    r = lo + (np.arange(nr) + 0.5) * (hi - lo) / nr
    u = -1 + (np.arange(nu) + 0.5) * 2 / nu
    th = arc(r) / (2 * r)
    phi = th[:, None] * u[None, :]
    c2 = np.clip((r * r - l1 * l1 - l2 * l2) / (2 * l1 * l2), -1, 1)
    q2 = np.arccos(c2)[:, None]
    beta = np.arctan2(l2 * np.sin(q2), l1 + l2 * np.cos(q2))
    w = (r * th)[:, None] * (hi - lo) / nr * (2 / nu) / (PI * RHO**2)
    if elbow_up:
        m = np.minimum(1 - np.abs(phi - beta) / PI, 1 - np.abs(q2 - PI / 2) / (PI / 2))
        v = float(np.sum(w * m))
        return v, v
    ma = np.minimum(1 - np.abs(phi - beta) / PI, 1 - q2 / PI)
    mb = np.minimum(1 - np.abs(phi + beta) / PI, 1 - q2 / PI)
    return float(np.sum(w * np.minimum(ma, mb))), float(np.sum(w * np.maximum(ma, mb)))


def sphere_cap_volume(R1: float, R2: float, d: float) -> float:
    """Volume of the intersection of balls of radii R1, R2 with centres d apart."""
    if d >= R1 + R2:
        return 0.0
    if d <= abs(R1 - R2):
        return 4 / 3 * PI * min(R1, R2) ** 3
    return PI * (R1 + R2 - d) ** 2 * (d * d + 2 * d * (R1 + R2) - 3 * (R1 - R2) ** 2) / (12 * d)


def dh_fk(q, a, alpha, d):
    """Standard DH (T = Rz(θ) Tz(d) Tx(a) Rx(α)) tip frames (N, 4, 4), numpy."""
    N = q.shape[0]
    T = np.broadcast_to(np.eye(4), (N, 4, 4)).copy()
    for i in range(q.shape[1]):
        ct, st, ca, sa = np.cos(q[:, i]), np.sin(q[:, i]), math.cos(alpha[i]), math.sin(alpha[i])
        A = np.zeros((N, 4, 4))
        A[:, 0] = np.stack([ct, -st * ca, st * sa, a[i] * ct], -1)
        A[:, 1] = np.stack([st, ct * ca, -ct * sa, a[i] * st], -1)
        A[:, 2, 1], A[:, 2, 2], A[:, 2, 3], A[:, 3, 3] = sa, ca, d[i], 1.0
        T = T @ A
    return T


# ----------------------------------------------------------------------------- configs


def planar(n: int = 1024, limits2=(-180, 180), **study) -> dict:
    """A planar 2R (l1, l2) task config over the disk as a dict (api.evaluate takes it)."""
    s = {"name": "serial",
         "chain": {"convention": "standard",
                   "joints": [{"type": "R", "a": "l1", "limits": [-180, 180]},
                              {"type": "R", "a": "l2", "limits": list(limits2)}]},
         "variables": {"l1": [0.2, 2.0], "l2": [0.2, 2.0]},
         "task": {"region": DISK, "ik": IK},
         "indices": {"jacobian": ["vx", "vy"], "norm": "2", "measure": "task", "n_samples": n},
         "objective": {"gci": -1.0}} | study  # fmt: skip
    return {"study": s, "optimizer": {"name": "ptpso", "n_particles": 8, "n_iters": 10},
            "precision": "float64", "seed": 0}  # fmt: skip


def designs(pairs):
    return [{"l1": a, "l2": b} for a, b in pairs]


@pytest.fixture(scope="module")
def swarm():
    """The four DESIGNS scored in one swarm call (1024 targets)."""
    return designopt.evaluate(planar(), designs(DESIGNS))


# ------------------------------------------------------------------------------ tests


def test_reference_quadrature_is_consistent():
    """The references check themselves: dA/dr integrates to the disk's area, the lens
    area to πρ² beyond the disk, and the 3-D lens volume to a ball's."""
    assert integrate.quad(arc, C - RHO, C + RHO, limit=200)[0] == pytest.approx(PI * RHO**2, 1e-9)
    assert lens_area(C + RHO + 0.1) == pytest.approx(PI * RHO**2, 1e-12)
    r = 1.31
    dA = integrate.quad(arc, C - RHO, r, limit=200)[0]
    assert dA == pytest.approx(lens_area(r), 1e-9)
    assert sphere_cap_volume(1.0, 3.0, 0.5) == pytest.approx(4 / 3 * PI, 1e-12)
    # a lens volume against a numpy Monte Carlo estimate (1e6 points, ~0.3 % SE)
    p = np.random.default_rng(0).uniform(-1, 1, (1_000_000, 3))
    p = p[np.linalg.norm(p, axis=1) <= 1]
    share = np.mean(np.linalg.norm(p - [0.8, 0, 0], axis=1) <= 0.6)
    assert share == pytest.approx(sphere_cap_volume(1.0, 0.6, 0.8) / (4 / 3 * PI), rel=0.02)


def test_planar_2r_over_a_disk_matches_the_quadrature(swarm):
    """Reach, task GCI, manipulability and gci_q05 of four designs (one swarm call; two
    reach the whole disk, two do not) lie within 4 SE of the exact values."""
    for m, (l1, l2) in enumerate(DESIGNS):
        ref = disk_reference(l1, l2)
        for k in ("reach", "gci", "manipulability", "gci_q05"):
            v, se = float(swarm[k][m]), float(swarm[k + "_se"][m])
            if ref[k] == 0.0 and k == "gci_q05":  # over 5 % unreached: the quantile is 0
                assert v == 0.0, (l1, l2, k, v)
                continue
            assert se > 0, (l1, l2, k)
            assert abs(v - ref[k]) <= 4 * se, (l1, l2, k, v, ref[k], se)
        assert float(swarm["f"][m]) == -float(swarm["gci"][m])
    assert float(swarm["reach"][1]) == 1.0 and float(swarm["reach"][3]) == 1.0
    assert float(swarm["reach"][0]) < 0.97 and float(swarm["reach"][2]) < 0.8


def test_joint_margin_against_the_quadrature(swarm):
    """Limits ±180°: the joint margin lies between the quadratures of the two branches'
    per-target min and max; q2 in [0°, 180°] (one branch): within 4 SE of the exact mean."""
    for m, (l1, l2) in enumerate(DESIGNS):
        lo, hi = joint_margin_reference(l1, l2, elbow_up=False)
        v, se = float(swarm["joint_margin"][m]), float(swarm["joint_margin_se"][m])
        assert lo - 4 * se <= v <= hi + 4 * se, (l1, l2, v, lo, hi, se)
    pairs = DESIGNS[:2]
    res = designopt.evaluate(planar(limits2=(0, 180)), designs(pairs))
    for m, (l1, l2) in enumerate(pairs):
        ref, _ = joint_margin_reference(l1, l2, elbow_up=True)
        v, se = float(res["joint_margin"][m]), float(res["joint_margin_se"][m])
        assert abs(v - ref) <= 4 * se, (l1, l2, v, ref, se)
        # one branch or the other: reach and GCI do not depend on the limits of q2
        np.testing.assert_allclose(res["reach"][m], disk_reference(l1, l2)["reach"],
                                   atol=4 * float(res["reach_se"][m]))  # fmt: skip


def test_common_random_numbers(swarm):
    """A design scored alone gets the same targets and IK seeds as in the swarm: the same
    values to 1e-12 (reversed order too)."""
    for m, d in enumerate(designs(DESIGNS[:2])):
        one = designopt.evaluate(planar(), [d])
        for k, v in one.items():
            np.testing.assert_allclose(v[0], swarm[k][m], rtol=1e-12, atol=1e-12, err_msg=k)
    rev = designopt.evaluate(planar(), designs(DESIGNS[::-1]))
    for k, v in rev.items():
        np.testing.assert_allclose(v[::-1], swarm[k], rtol=1e-12, atol=1e-12, err_msg=k)


BALL = {"shape": "ball", "center": [0.3, 0.2, 0.1], "radius": 1.0}


def spatial_3r(n: int = 1024) -> dict:
    """An elbow arm: a vertical waist joint, then shoulder and elbow pitch joints with
    links l2, l3 (standard DH, all limits ±180°): its workspace is the spherical shell
    |l2 − l3| ≤ |p| ≤ l2 + l3 about the base."""
    s = {"name": "serial",
         "chain": {"joints": [{"type": "R", "alpha": 90, "limits": [-180, 180]},
                              {"type": "R", "a": "l2", "limits": [-180, 180]},
                              {"type": "R", "a": "l3", "limits": [-180, 180]}]},
         "variables": {"l2": [0.1, 2.0], "l3": [0.1, 2.0]},
         "task": {"region": BALL, "ik": IK},
         "indices": {"jacobian": "position", "measure": "task", "n_samples": n},
         "objective": {"reach": -1.0}}  # fmt: skip
    return {"study": s, "precision": "float64", "seed": 3}


def test_spatial_3r_reach_of_a_ball_is_its_volume_in_the_shell():
    """reach = (|ball ∩ B(0, l2 + l3)| − |ball ∩ B(0, |l2 − l3|)|) / |ball| (sphere-sphere
    lens volumes, the ball's centre 0.374 from the base) within 4 SE, for a shell that
    cuts the ball outside and inside, one that cuts it inside only, and one that holds
    all but a 0.1-radius core."""
    pairs = [(0.8, 0.5), (0.5, 1.4), (1.0, 0.9)]
    res = designopt.evaluate(spatial_3r(), [{"l2": a, "l3": b} for a, b in pairs])
    R, d = BALL["radius"], float(np.linalg.norm(BALL["center"]))
    for m, (l2, l3) in enumerate(pairs):
        ref = (sphere_cap_volume(R, l2 + l3, d) - sphere_cap_volume(R, abs(l2 - l3), d)) / (
            4 / 3 * PI * R**3)  # fmt: skip
        v, se = float(res["reach"][m]), float(res["reach_se"][m])
        assert abs(v - ref) <= 4 * se, (l2, l3, v, ref, se)
        assert float(res["f"][m]) == -v


PUMA_A = (0.0, "a2", "a3", 0.0, 0.0, 0.0)
PUMA_ALPHA = (90, 0, -90, 90, -90, 0)
PUMA_D = (0.0, 0.0, "d3", "d4", 0.0, 0.0)
PUMA_LIMITS = ((-160, 160), (-45, 225), (-225, 45), (-110, 170), (-100, 100), (-266, 266))
CONE = 30.0


def puma_task(n: int = 128) -> dict:
    """The PUMA 560 (configs/puma560.yaml's chain) over a box in front of it, the tool z
    axis within CONE degrees of straight down."""
    joints = [{"type": "R", "a": a, "alpha": al, "d": d, "limits": list(lim)}
              for a, al, d, lim in zip(PUMA_A, PUMA_ALPHA, PUMA_D, PUMA_LIMITS, strict=True)]  # fmt: skip
    s = {"name": "serial", "chain": {"convention": "standard", "joints": joints},
         "variables": {"a2": [0.3, 0.6], "d4": [0.3, 0.6]},
         "fixed": {"a3": 0.0203, "d3": 0.15005},
         "task": {"region": {"shape": "box", "center": [0.45, 0.1, -0.2], "size": [0.2, 0.3, 0.15]},
                  "tool_axis": {"direction": [0, 0, -1], "cone": CONE},
                  "ik": {"n_db": 256, "n_nearest": 0, "n_random": 4}},
         "indices": {"jacobian": "full", "length_scale": 0.5, "norm": "fro", "normalized": True,
                     "measure": "task", "n_samples": n},
         "objective": {"gci": -1.0}}  # fmt: skip
    return {"study": s, "precision": "float64", "seed": 0}


def test_tool_axis_targets_fill_the_cone_and_solutions_meet_them():
    """The targets' tool axes lie in the cone and spread over it (cos θ uniform on
    [cos 30°, 1]: its mean and the largest angle); at every solved target a numpy DH
    forward kinematics of the returned joints meets the position to 1e-9 of the reach and
    the tool axis to 1e-8 rad, within the joint limits."""
    from designopt.app.config import validate
    from designopt.app.job import build_problem
    from designopt.studies import streams
    from designopt.studies.serial import taskindex
    from designopt.studies.serial.mechanism import build
    from designopt.studies.serial.objective import design_full

    cfg = validate(puma_task(), "puma_task")
    problem = build_problem(cfg, streams(cfg.seed))
    R_t = np.asarray(problem.params["target_R"])
    p_t = np.asarray(problem.params["target_p"])
    z = R_t[:, :, 2]
    cos = -z[:, 2]
    n = len(cos)
    np.testing.assert_allclose(np.einsum("nij,nik->njk", R_t, R_t), np.broadcast_to(np.eye(3),
                               R_t.shape), atol=1e-12)  # fmt: skip
    c = math.cos(math.radians(CONE))
    assert np.all(cos >= c - 1e-12)
    assert abs(cos.mean() - (1 + c) / 2) <= 4 * (1 - c) / math.sqrt(12 * n)
    assert np.degrees(np.arccos(cos.min())) > 0.8 * CONE  # reaches out to the cone's rim
    assert np.all(np.abs(p_t - [0.45, 0.1, -0.2]) <= np.array([0.1, 0.15, 0.075]) + 1e-12)

    x = {"a2": 0.4318, "d4": 0.4318}
    X = np.array([[x["a2"], x["d4"]]])
    s, mech = cfg.study, build(cfg.study)
    per = jax.jit(lambda p, X: taskindex.per_target(mech, s, p, design_full(p, X, jnp.float64),
                                                    jnp.float64))(problem.params, X)  # fmt: skip
    ok = np.asarray(per["success"][0, 0]) > 0.5  # (arm, design, target)
    q = np.asarray(per["q"][0, 0])
    assert ok.mean() >= 0.5, ok.mean()
    T = dh_fk(q, [0, x["a2"], 0.0203, 0, 0, 0], np.radians(PUMA_ALPHA),
              [0, 0, 0.15005, x["d4"], 0, 0])  # fmt: skip
    pos = np.linalg.norm(T[:, :3, 3] - p_t, axis=1)
    ang = np.arctan2(np.linalg.norm(np.cross(T[:, :3, 2], z), axis=1), np.sum(T[:, :3, 2] * z, 1))
    assert np.all(pos[ok] <= 1e-9), pos[ok].max()
    assert np.all(ang[ok] <= 1e-8), ang[ok].max()
    assert np.all(pos[~ok] + ang[~ok] > 1e-10)  # a failure is not a hidden success
    lim = np.radians(PUMA_LIMITS)
    assert np.all((q >= lim[:, 0] - 1e-12) & (q <= lim[:, 1] + 1e-12))


def test_index_constraint_values_are_the_indices_minus_their_bounds(swarm):
    """violation = Σ max(g, 0) with g = ge − index and index − le: exactly, one design per
    violated constraint; the targets do not depend on the constraints or on the batch
    (each design scored alone gives the swarm's values to 1e-12)."""
    cons = [{"index": "reach", "ge": 0.99}, {"index": "gci", "le": 0.4}]
    for m in (0, 3):  # reach 0.93 < 0.99 (gci 0.36 ≤ 0.4); reach 1 (gci 0.52 > 0.4)
        one = designopt.evaluate(planar(constraints=cons), designs([DESIGNS[m]]))
        for k, v in swarm.items():
            np.testing.assert_allclose(one[k][0], v[m], rtol=1e-12, atol=1e-12, err_msg=k)
        g = [0.99 - float(one["reach"][0]), float(one["gci"][0]) - 0.4]
        assert (g[0] > 0) != (g[1] > 0), g
        assert float(one["violation"][0]) == max(g[0], 0.0) + max(g[1], 0.0)


@pytest.mark.parametrize("method", ["deb", "penalty"])
def test_reach_constraint_binds_a_run(method):
    """configs/planar2r_task.yaml pulled toward small arms (minimise manipulability) with
    reach ≥ 0.99: the final design's exact reach (lens areas: the re-evaluation on every
    point of the disk) is ≥ 0.99 − 2 SE, its fresh quoted reach is the exact one to 4 SE,
    the constraint binds (exact reach < 0.999), and with Deb's rules the reach on the
    search's own samples (``best_run/final``) is ≥ 0.99 with no violation."""
    cfg = designopt.load_config("configs/planar2r_task.yaml", {
        "study.indices.n_samples": 512, "study.task.ik": IK,
        "study.objective": {"manipulability": 1.0},
        "study.constraints": [{"index": "reach", "ge": 0.99}],
        "optimizer": {"name": "ptpso", "n_particles": 8, "n_iters": 10, "n_runs": 1,
                      "constraints": {"method": method, "weight": 1e4}}})  # fmt: skip
    rec = designopt.run(cfg)
    x = rec.x
    reach, se = rec.indices["reach"]  # on the fresh final samples
    exact = disk_reference(x["l1"], x["l2"])["reach"]
    assert abs(reach - exact) <= 4 * se, (x, reach, exact, se)
    found = float(np.asarray(rec.search["reach"]))  # on the samples the search chose it on
    found_se = float(np.asarray(rec.search["reach_se"]))
    assert exact >= 0.99 - 2 * found_se - 2 * se, (x, exact, found_se, se)
    assert exact < 0.999, (x, exact)  # the pull reached the constraint
    if method == "deb":  # Deb's rules hold the constraint where the search measured it
        assert found >= 0.99 and float(np.asarray(rec.search["violation"])) == 0.0


def joint_gci_2r(l1: float, l2: float) -> float:
    """The planar 2R's GCI over q2 uniform in [−π, π] (1/k from the tip distance r,
    r² = l1² + l2² + 2 l1 l2 cos q2), by quadrature."""
    return integrate.quad(lambda q: float(inv_k_2r(math.sqrt(l1 * l1 + l2 * l2 + 2 * l1 * l2
                          * math.cos(q)), l1, l2)), 0, PI, limit=200)[0] / PI  # fmt: skip


def test_index_constraint_on_the_joint_measure_is_honoured():
    """The planar 2R's joint-space GCI (at most 0.375, at l2/l1 = 1/√2, by quadrature)
    maximised under gci ≤ 0.25 (Deb's rules): the final design's GCI is ≤ 0.25 and
    within 0.01 of it (the bound binds), its violation is 0, and the quadrature of its
    GCI lies within 4 SE of 0.25."""
    best = optimize.minimize_scalar(lambda r: -joint_gci_2r(1.0, r), bounds=(0.1, 10),
                                    method="bounded")  # fmt: skip
    assert best.x == pytest.approx(1 / math.sqrt(2), abs=1e-3) and -best.fun > 0.37
    s = planar()["study"] | {"indices": {"jacobian": ["vx", "vy"], "norm": "2",
                                         "measure": "joint", "n_samples": 4096},
                             "constraints": [{"index": "gci", "le": 0.25}]}  # fmt: skip
    s.pop("task")
    opt = {"name": "ptpso", "n_particles": 10, "n_iters": 20, "n_runs": 1}
    rec = designopt.run({"study": s, "optimizer": opt, "precision": "float64"})
    gci, se = rec.indices["gci"]
    assert 0.24 <= gci <= 0.25 and rec.indices["violation"][0] == 0.0, rec.indices
    assert abs(joint_gci_2r(rec.x["l1"], rec.x["l2"]) - 0.25) <= 4 * se + 0.01


TINY = """
study:
  name: serial
  chain:
    convention: standard
    joints:
      - {type: R, a: l1, alpha: 0, d: 0, theta: 0, limits: [-180, 180]}
      - {type: R, a: l2, alpha: 0, d: 0, theta: 0, limits: [-180, 180]}
  variables: {l1: [0.2, 2.0], l2: [0.2, 2.0]}
  task:
    region: {shape: cylinder, center: [1.2, 0, 0], axis: [0, 0, 1], radius: 0.5, height: 0}
    ik: {n_db: 256, n_nearest: 0, n_random: 3}
  indices: {jacobian: [vx, vy], norm: "2", measure: task, n_samples: 256}
  objective: {gci: -1.0}
  constraints:
    - {index: reach, ge: 0.99}
optimizer: {name: ptpso, n_particles: 4, n_iters: 2, n_runs: 1}
scan:
  vary: {l2: [0.6, 0.8]}
  design: {l1: 1.0}
  batch: 1                        # the eval's compiled program serves the scan
precision: float64
output: OUT
"""
CYL = "{shape: cylinder, center: [1.2, 0, 0], axis: [0, 0, 1], radius: 0.5, height: 0}"
TASK_SECTION = "  task:\n    region: " + CYL + "\n    ik: {n_db: 256, n_nearest: 0, n_random: 3}\n"
CONE_AT = "{shape: cone, apex: [0, 0, 0], axis: [1, 0, 0], depth: [0.7, 1.7], half_angle: "
TASK_INDICES = "['reach', 'gci', 'gci_q05', 'manipulability', 'joint_margin']"


@pytest.mark.parametrize(
    "old,new,needles",
    [
        (CYL, "{shape: torus, center: [1.2, 0, 0], radius: 0.5}",
         ["key 'study.task.region'", "unknown region", "box, ball, cylinder or cone"]),
        ("radius: 0.5", "radius: 0", ["key 'study.task.region.radius'", "> 0"]),
        ("radius: 0.5", "radius: -0.5", ["key 'study.task.region.radius'", "> 0"]),
        (CYL, CONE_AT + "0}", ["key 'study.task.region.half_angle'", "(0, 90)", "got 0"]),
        (CYL, CONE_AT + "90}", ["key 'study.task.region.half_angle'", "(0, 90)", "got 90"]),
        (CYL, CONE_AT + "120}", ["key 'study.task.region.half_angle'", "(0, 90)", "got 120"]),
        (CYL, "{points: missing_z.csv}",
         ["key 'study.task.region.points'", "missing_z.csv", "no column(s) ['z']"]),
        (CYL, "{points: text.csv}",
         ["key 'study.task.region.points'", "text.csv", "row 2", "three numbers"]),
        (CYL, "{points: nan.csv}",
         ["key 'study.task.region.points'", "nan.csv", "row 1", "not a finite number"]),
        (TASK_SECTION, "", ["key 'study.indices.measure': 'task' needs a study.task section"]),
        ("measure: task", "measure: joint", ["key 'study.task':", "measure: task", "'joint'"]),
        ("measure: task,", "measure: task, sampler: rqmc,", ["indices.sampler", "'rqmc'", "uniform"]),
        ("precision: float64", "precision: float32", ["indices.measure: 'task'", "precision: float64"]),
        ("{index: reach, ge: 0.99}", "{index: dexterity, ge: 0.99}",
         ["constraints.0.index", "unknown index 'dexterity'", TASK_INDICES]),
        ("{index: reach, ge: 0.99}", "{index: volume, ge: 0.99}",
         ["constraints.0.index", "unknown index 'volume'", "under measure: task"]),
    ],
    ids=["shape", "radius0", "radius<0", "cone0", "cone90", "cone120", "points-column",
         "points-text", "points-nan", "no-task", "task-joint", "sampler", "float32",
         "constraint-index", "constraint-joint-index"],
)  # fmt: skip
def test_bad_task_input_one_line_exit_2_nothing_written(tmp_path, capsys, old, new, needles):
    assert old in TINY
    (tmp_path / "missing_z.csv").write_text("x,y\n1.0,0.0\n")
    (tmp_path / "text.csv").write_text("x,y,z\n1.0,0.0,0.0\n1.1,0.1,zero\n")
    (tmp_path / "nan.csv").write_text("x,y,z\n1.0,nan,0.0\n")
    cfg = tmp_path / "c.yaml"
    cfg.write_text(TINY.replace(old, new, 1).replace("OUT", str(tmp_path / "out" / "a.h5")))
    for cmd in (["run", str(cfg), "--quiet"], ["scan", str(cfg), "--quiet"],
                ["eval", str(cfg), "--design", "l1=1"]):  # fmt: skip
        assert main(cmd) == 2, cmd
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and str(cfg) in err, err
        for needle in needles:
            assert needle in err, (needle, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yaml", "missing_z.csv", "nan.csv",
                                                          "text.csv"]  # fmt: skip


def test_eval_scan_run_commands_on_a_tiny_task_config(tmp_path, capsys):
    """eval --json, scan and run from YAML exit 0; the archives hold every task index with
    its SE, and eval, scan and run agree on the shared design's values."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text(TINY.replace("OUT", str(tmp_path / "a.h5")))
    names = ("f", "reach", "gci", "gci_q05", "manipulability", "joint_margin")
    assert main(["eval", str(cfg), "--design", "l1=1", "--design", "l2=0.8", "--json"]) == 0
    one = json.loads(capsys.readouterr().out)
    assert set(one) >= {*names, *(k + "_se" for k in names), "violation", "feasible"}
    assert one["reach"] == 1.0 and one["violation"] == 0.0
    assert main(["scan", str(cfg), "--quiet", "--no-figures", "--out", str(tmp_path / "s.h5")]) == 0
    sc = designopt.load(tmp_path / "s.h5")
    assert sc.X.shape == (2, 2)
    for k in names:
        assert sc.values[k].shape == (2,) and sc.values[k + "_se"].shape == (2,), k
        np.testing.assert_allclose(sc.values[k][1], one[k], rtol=1e-12, atol=1e-15)
    assert main(["run", str(cfg), "--quiet", "--no-figures"]) == 0
    rec = designopt.load(tmp_path / "a.h5")
    for k in names:
        v, se = rec.indices[k]
        assert np.isfinite(v) and se is not None and se >= 0, k
    assert rec.indices["reach"][1] > 0
    capsys.readouterr()
