"""A URDF's <collision> shapes as capsules (designopt.kinematics.urdf_collision): the
batched link frames against yourdfpy's FK (design numbers written into the file), every
capsule holding its shape and not much more, mesh files found as the URDF importer finds
them, and the errors that name the link and the file."""

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh
from test_urdf import BIND, BIND_NAMES, FEATURES

from designopt.kinematics import urdf as U
from designopt.kinematics import urdf_collision as UC

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = ROOT / "configs" / "robots"


def _var(k: int, scale: float = 1.0, const: float = 0.0) -> U.Lin:
    return (const, ((k, scale),))


DEG = math.pi / 180
# (URDF text, base, tip, bindings, design box (lo, hi) per column)
CASES = {
    "puma560": (
        (ROBOTS / "puma560.urdf").read_text(), None, "tool0",
        {("joint3", "x"): _var(0), ("joint4", "x"): _var(1), ("joint4", "z"): _var(2),
         ("joint5", "z"): _var(3), ("joint2", "roll"): _var(4, DEG, 0.05),
         ("tool_joint", "pitch"): (0.3, ())},
        ([0.3, 0.0, 0.1, 0.3, -20], [0.6, 0.05, 0.2, 0.6, 20]),
    ),
    "surgical_arm6": (
        (ROBOTS / "surgical_arm6.urdf").read_text(), "rcm_link", "jaw_tip",
        {("wrist_pitch", "length"): _var(0), ("jaw", "length"): _var(1, 2.0, 0.001),
         ("wrist_yaw", "z"): (-0.009, ()), ("outer_pitch", "yaw"): _var(2, DEG)},
        ([0.004, 0.005, -30], [0.03, 0.03, 30]),
    ),
    "features": (
        FEATURES, "world", "tip",
        {k: _var(BIND_NAMES.index(v)) for k, v in BIND.items()},
        ([0.1, -0.1, 0.05, -0.5], [0.5, 0.1, 0.2, 0.5]),
    ),
}  # fmt: skip


def _values(bindings, x) -> dict:
    return {k: c + sum(s * x[i] for i, s in xc) for k, (c, xc) in bindings.items()}


@pytest.mark.parametrize("name", list(CASES))
def test_link_frames_match_yourdfpy(name):
    text, base, tip, bindings, (lo, hi) = CASES[name]
    imp = U.import_path(U.parse(text, name), base, tip)
    links = UC.path_links(imp)
    rng = np.random.default_rng(7)
    X = rng.uniform(lo, hi, (3, len(lo)))
    Q = rng.uniform(imp.lower, imp.upper, (4, len(imp.active)))
    T = np.asarray(UC.link_frames(imp, bindings, X, Q, links))
    assert T.shape == (3, 4, len(links), 4, 4)
    for m in range(len(X)):
        ref = U.Reference(U.export_text(text, _values(bindings, X[m]), name)).u
        for c in range(len(Q)):
            cfg = dict(zip(imp.active, Q[c], strict=True))
            ref.update_cfg(np.array([cfg.get(n, 0.0) for n in ref.actuated_joint_names]))
            for i, lk in enumerate(links):
                np.testing.assert_allclose(T[m, c, i], ref.get_transform(lk, imp.base),
                                           rtol=0, atol=1e-12, err_msg=f"{lk} m={m} c={c}")  # fmt: skip
    if name != "features":
        return
    # a 1-D X or q drops its axis; a subset of links in any order
    sub, at = [links[-1], links[0], links[2]], [len(links) - 1, 0, 2]
    T1 = np.asarray(UC.link_frames(imp, bindings, X[1], Q, sub))
    assert T1.shape == (4, 3, 4, 4)
    np.testing.assert_allclose(T1, T[1][:, at], atol=1e-15)
    T2 = np.asarray(UC.link_frames(imp, bindings, X, Q[2], sub))
    assert T2.shape == (3, 3, 4, 4)
    np.testing.assert_allclose(T2, T[:, 2][:, at], atol=1e-15)


def test_link_frames_trace_once_and_differentiate():
    text, base, tip, bindings, (lo, hi) = CASES["features"]
    imp = U.import_path(U.parse(text, "f"), base, tip)
    traces = []

    @jax.jit
    def f(X, q):
        traces.append(1)
        return UC.link_frames(imp, bindings, X, q, ["l3", "tip"])

    rng = np.random.default_rng(1)
    x0 = jnp.asarray(rng.uniform(lo, hi, 4))
    q0 = jnp.asarray(rng.uniform(imp.lower, imp.upper, 4))
    E = 1e-6 * jnp.eye(4)
    X = jnp.concatenate([x0 + E, x0 - E, x0[None]])  # (9, 4): central differences in X
    Q = jnp.concatenate([q0 + E, q0 - E, q0[None]])  # and in q
    T = f(X, Q)
    f(X + 0.01, Q - 0.01)
    assert len(traces) == 1 and T.shape == (9, 9, 2, 4, 4)
    assert f(X.astype(jnp.float32), Q.astype(jnp.float32)).dtype == jnp.float32
    # the gradient of the tip's x in x and q against central differences
    g = jax.jit(jax.grad(lambda x, q: f(x, q)[1, 0, 3], argnums=(0, 1)))(x0, q0)
    fx, fq = T[:8, 8, 1, 0, 3], T[8, :8, 1, 0, 3]
    np.testing.assert_allclose(g[0], (fx[:4] - fx[4:]) / 2e-6, atol=1e-7)
    np.testing.assert_allclose(g[1], (fq[:4] - fq[4:]) / 2e-6, atol=1e-7)


def test_link_frames_bad_input():
    text, base, tip, bindings, _ = CASES["features"]
    imp = U.import_path(U.parse(text, "f"), base, tip)
    with pytest.raises(ValueError, match="'side' is not on the path"):
        UC.link_frames(imp, bindings, np.zeros(4), np.zeros(4), ["side"])
    with pytest.raises(ValueError, match="D ≥ 4"):
        UC.link_frames(imp, bindings, np.zeros(3), np.zeros(4), ["tip"])
    with pytest.raises(ValueError, match=r"\(C, 4\)"):
        UC.link_frames(imp, bindings, np.zeros(4), np.zeros(3), ["tip"])


def test_the_shipped_robots_have_no_collision_shapes():
    for name in ("puma560", "surgical_arm6"):
        text, base, tip, _, _ = CASES[name]
        imp = U.import_path(U.parse(text, name), base, tip)
        assert UC.capsules(text, str(ROBOTS / f"{name}.urdf"), imp) == []


# ------------------------------------------------------------------ the shapes


def _seg_dist(P, a, b):
    P, a, b = np.asarray(P), np.asarray(a), np.asarray(b)
    d = b - a
    dd = d @ d
    s = np.zeros(len(P)) if dd == 0 else np.clip((P - a) @ d / dd, 0, 1)
    return np.linalg.norm(P - (a + s[:, None] * d), axis=1)


def _frame(xyz, rpy):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = U.rpy_matrix(*rpy), xyz
    return T


def _apply(T, P):
    return np.asarray(P) @ T[:3, :3].T + T[:3, 3]


def _sphere_pts(rng, n=400):
    u = rng.normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _cylinder_pts(rng, r, length, n=400):
    t = rng.uniform(0, 2 * np.pi, n)
    z = np.concatenate([rng.uniform(-length / 2, length / 2, n), np.full(n, length / 2),
                        np.full(n, -length / 2)])  # fmt: skip
    rad = np.concatenate([np.full(n, r), rng.uniform(0, r, 2 * n)])
    t = np.concatenate([t, t, t])
    return np.column_stack([rad * np.cos(t), rad * np.sin(t), z])


def _box_pts(rng, size, n=200):
    h = np.asarray(size) / 2
    corners = np.array(np.meshgrid(*[[-1, 1]] * 3)).reshape(3, -1).T * h
    faces = rng.uniform(-h, h, (6 * n, 3))
    for f in range(6):  # n points on each face
        faces[f * n : (f + 1) * n, f % 3] = h[f % 3] * (1 if f < 3 else -1)
    return np.vstack([corners, faces])


PART = trimesh.creation.box(extents=(0.02, 0.05, 0.12))
PART.apply_transform(trimesh.transformations.rotation_matrix(0.4, (1, 2, 3)))
PART.apply_translation((0.003, -0.01, 0.02))
PART.vertices = PART.vertices.astype(np.float32).astype(np.float64)  # as the STL stores them

SHAPES = {  # link -> (geometry element, origin xyz, origin rpy)
    "b": ('<sphere radius="0.04"/>', (0.01, 0.02, 0.03), (0, 0, 0)),
    "l1": ('<cylinder radius="0.03" length="0.25"/>', (0.0, 0.05, 0.1), (0.3, -0.2, 0.5)),
    "l3": ('<box size="0.05 0.2 0.08"/>', (0.02, -0.01, 0.0), (0.1, 0.7, -0.4)),
    "l4": ('<mesh filename="meshes/part.stl" scale="2 1 0.5"/>', (0.1, 0, 0), (0, 0.2, 0)),
    "l6": ('<mesh filename="package://armpkg/meshes/part.stl"/>', (0, 0, 0.05), (1.0, 0, 0)),
}


def _with_collisions(shapes) -> str:
    text = FEATURES
    for link, (geo, xyz, rpy) in shapes.items():
        x, r = " ".join(map(str, xyz)), " ".join(map(str, rpy))
        col = f'<collision><origin xyz="{x}" rpy="{r}"/><geometry>{geo}</geometry></collision>'
        text = text.replace(f'<link name="{link}"/>', f'<link name="{link}">{col}</link>', 1)
    return text


@pytest.fixture
def arm(tmp_path):
    """FEATURES with a collision shape of each kind, in a package folder armpkg/ with its
    mesh at armpkg/meshes/part.stl and the URDF at armpkg/urdf/arm.urdf."""
    pkg = tmp_path / "armpkg"
    (pkg / "meshes").mkdir(parents=True)
    (pkg / "urdf").mkdir()
    PART.export(pkg / "meshes" / "part.stl")
    shapes = dict(SHAPES)
    shapes["l4"] = (SHAPES["l4"][0].replace("meshes/", "../meshes/"), *SHAPES["l4"][1:])
    text = _with_collisions(shapes)
    # a second <collision> on the base link, and one on a link off the path (left out)
    text = text.replace('<link name="b">', '<link name="b"><collision><geometry>'
                        '<sphere radius="0.01"/></geometry></collision>', 1)  # fmt: skip
    text = text.replace('<link name="side"/>', '<link name="side"><collision><geometry>'
                        '<sphere radius="0.5"/></geometry></collision></link>', 1)  # fmt: skip
    path = pkg / "urdf" / "arm.urdf"
    path.write_text(text)
    imp = U.import_path(U.parse(text, str(path)), "world", "tip")
    return text, path, imp


def _shape_points(link, rng):
    geo, xyz, rpy = SHAPES[link]
    T = _frame(xyz, rpy)
    if link == "b":
        return _apply(T, 0.04 * _sphere_pts(rng))
    if link == "l1":
        return _apply(T, _cylinder_pts(rng, 0.03, 0.25))
    if link == "l3":
        return _apply(T, _box_pts(rng, (0.05, 0.2, 0.08)))
    scale = np.array([2, 1, 0.5]) if link == "l4" else np.ones(3)
    return _apply(T, PART.vertices * scale)


def test_capsules_parse_and_hold_their_shapes(arm):
    text, path, imp = arm
    caps = UC.capsules(text, str(path), imp)
    assert [(c.link, c.kind) for c in caps] == [
        ("b", "sphere"), ("b", "sphere"), ("l1", "cylinder"), ("l3", "box"), ("l4", "mesh"),
        ("l6", "mesh")]  # fmt: skip
    rng = np.random.default_rng(0)
    by = {c.link: c for c in caps[1:]}
    for link in SHAPES:
        c = by[link]
        d = _seg_dist(_shape_points(link, rng), c.a, c.b)
        assert d.max() <= c.radius + 1e-12, link
    sph, cyl, box = by["b"], by["l1"], by["l3"]
    np.testing.assert_array_equal(sph.a, (0.01, 0.02, 0.03))
    np.testing.assert_array_equal(sph.b, sph.a)
    assert sph.radius == 0.04 and caps[0].radius == 0.01 and np.all(caps[0].a == 0)
    # the cylinder: its own axis and radius
    assert cyl.radius == 0.03 and np.isclose(np.linalg.norm(cyl.b - cyl.a), 0.25, rtol=1e-14)
    axis = U.rpy_matrix(0.3, -0.2, 0.5)[:, 2]
    np.testing.assert_allclose((cyl.b - cyl.a) / 0.25, axis, atol=1e-14)
    # the box: along its longest side (y), radius half the cross-section's diagonal, which
    # its corners reach (tight), well below half the box's diagonal
    assert np.isclose(box.radius, 0.5 * math.hypot(0.05, 0.08), rtol=1e-14)
    assert box.radius <= 0.5 * math.sqrt(0.05**2 + 0.2**2 + 0.08**2)
    corners = _apply(_frame(*SHAPES["l3"][1:]), _box_pts(rng, (0.05, 0.2, 0.08))[:8])
    assert np.isclose(_seg_dist(corners, box.a, box.b).max(), box.radius, rtol=1e-12)
    # the meshes: some vertex on the surface (exact radius), radius ≤ half the diagonal
    for link, ext in (("l4", PART.extents * (2, 1, 0.5)), ("l6", PART.extents)):
        c = by[link]
        d = _seg_dist(_shape_points(link, rng), c.a, c.b)
        assert np.isclose(d.max(), c.radius, rtol=1e-12)
        assert c.radius <= 0.5 * np.linalg.norm(ext) and c.filename.endswith("part.stl")
    # the unscaled box-shaped part: its capsule's radius is its cross-section's, as for a
    # <box> (PCA finds the long axis of a 2:5:12 box)
    assert np.isclose(by["l6"].radius, 0.5 * math.hypot(0.02, 0.05), rtol=1e-6)


def test_capsules_are_placed_by_the_link_frames(arm):
    text, path, imp = arm
    caps = UC.capsules(text, str(path), imp)
    bindings = CASES["features"][3]
    lo, hi = CASES["features"][4]
    rng = np.random.default_rng(5)
    X = rng.uniform(lo, hi, (2, 4))
    Q = rng.uniform(imp.lower, imp.upper, (3, 4))
    seg, radii = UC.world_capsules(imp, bindings, caps, X, Q)
    assert seg.shape == (2, 3, len(caps), 2, 3) and radii.shape == (len(caps),)
    np.testing.assert_array_equal(radii, [c.radius for c in caps])
    for m in range(2):
        ref = U.Reference(U.export_text(text, _values(bindings, X[m]), "a")).u
        for c in range(3):
            cfg = dict(zip(imp.active, Q[c], strict=True))
            ref.update_cfg(np.array([cfg.get(n, 0.0) for n in ref.actuated_joint_names]))
            for k, cap in enumerate(caps):
                T = ref.get_transform(cap.link, "world")
                np.testing.assert_allclose(seg[m, c, k], _apply(T, [cap.a, cap.b]), atol=1e-12)
            # the shapes placed by yourdfpy lie in the placed capsules
            for k, cap in enumerate(caps[1:], 1):
                P = _apply(ref.get_transform(cap.link, "world"), _shape_points(cap.link, rng))
                d = _seg_dist(P, *np.asarray(seg[m, c, k]))
                assert d.max() <= cap.radius + 1e-12
    s1, _ = UC.world_capsules(imp, bindings, caps, X[1], Q[0])
    np.testing.assert_allclose(s1, seg[1, 0], atol=1e-15)


def test_bounding_capsule_of_point_clouds_holds_them_and_is_no_bigger_than_a_ball():
    rng = np.random.default_rng(11)
    for i in range(30):
        k = [1, 2, 5, 50, 400][i % 5]
        P = rng.normal(size=(k, 3)) * rng.uniform(0.01, 2, 3)
        P = P @ trimesh.transformations.random_rotation_matrix(rng.random(3))[:3, :3].T + 1
        a, b, r = UC.bounding_capsule(P)
        d = _seg_dist(P, a, b)
        assert d.max() <= r + 1e-12
        assert r <= np.linalg.norm(P - P.mean(0), axis=1).max() + 1e-12
    # a round ball's vertices: the capsule is (nearly) the ball
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.5).vertices
    a, b, r = UC.bounding_capsule(ball)
    assert np.linalg.norm(b - a) < 0.1 and r <= 0.5 + 1e-12


# ------------------------------------------------------------------ mesh files


def test_mesh_paths_resolve_like_the_importer(tmp_path, monkeypatch):
    ros = tmp_path / "ros" / "armpkg" / "meshes"
    ros.mkdir(parents=True)
    (ros / "part.stl").write_bytes(b"x")
    here = tmp_path / "elsewhere" / "armpkg" / "urdf"
    here.mkdir(parents=True)
    (here.parent / "meshes").mkdir()
    (here.parent / "meshes" / "part.stl").write_bytes(b"y")
    urdf = here / "arm.urdf"
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    # package://: the URDF's folders upwards; $ROS_PACKAGE_PATH first when set
    pkg = "package://armpkg/meshes/part.stl"
    assert UC.resolve_mesh(pkg, urdf) == here.parent / "meshes" / "part.stl"
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "ros"))
    assert UC.resolve_mesh(pkg, urdf) == ros / "part.stl"
    assert UC.resolve_mesh("../meshes/part.stl", urdf) == here / ".." / "meshes" / "part.stl"
    assert UC.resolve_mesh(f"file://{ros / 'part.stl'}", urdf) == ros / "part.stl"
    assert UC.resolve_mesh("package://armpkg/meshes/none.stl", urdf) is None


def test_a_mesh_that_cannot_be_found_or_read_names_the_link_and_the_file(arm, tmp_path):
    text, path, imp = arm
    bad = text.replace("../meshes/part.stl", "../meshes/gone.stl")
    with pytest.raises(ValueError, match=r"link 'l4'.*gone\.stl.*no such file"):
        UC.capsules(bad, str(path), imp)
    (path.parent / "junk.stl").write_text("not a mesh at all")
    bad = text.replace("../meshes/part.stl", "junk.stl")
    with pytest.raises(ValueError, match=r"link 'l4'.*junk\.stl"):
        UC.capsules(bad, str(path), imp)
    bad = text.replace('<sphere radius="0.04"/>', '<sphere radius="-1"/>')
    with pytest.raises(ValueError, match=r'<link name="b">.*radius'):
        UC.capsules(bad, str(path), imp)
    bad = text.replace('<sphere radius="0.04"/>', '<cone radius="1"/>')
    with pytest.raises(ValueError, match=r'<link name="b">.*<cone>.*unknown shape'):
        UC.capsules(bad, str(path), imp)
