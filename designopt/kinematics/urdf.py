"""A robot's URDF as a frame-kernel chain, with joint-origin numbers as design variables.

Parsing is yourdfpy's (meshes never opened); the structure checks, the path base → tip and
the lowering to the kernel's elementary steps are here (docs/urdf.md):

- a URDF joint is T = Trans(xyz) · Rz(yaw) Ry(pitch) Rx(roll) · Motion(axis, q);
- constant rotations are carried along as one pending 3×3 matrix ``Rc`` and pushed *through*
  the joints (Rc · Rot_a(q) = Rot_{Rc a}(q) · Rc), so a joint whose axis ends up along a
  frame axis costs one kernel rotation and nothing else; an oblique axis costs two constant
  rotations in front of it. Translations are summed per frame axis, each component linear
  in the length variables. Fixed joints therefore fold away at trace time, except where a
  ``set`` key makes one of their numbers a variable;
- mimic joints and negative axes are rows of the kernel's coupling map
  (q_chain = C q_active + offset), like the haptic master's q4 = −q3.

The same ``SerialModel`` the DH path builds comes out, so every index and command treats a
URDF chain as a DH chain. ``export_text`` writes the user's file back with new numbers in
the ``set`` fields and every other byte unchanged.
"""

from __future__ import annotations

import io
import math
import re
import xml.parsers.expat
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from designopt.core.errors import ConfigError
from designopt.kinematics.kernel import SerialModel, _Lin, _Step

FIELDS = ("x", "y", "z", "roll", "pitch", "yaw", "length")
ANGLE_FIELDS = ("roll", "pitch", "yaw")
MOVABLE = ("revolute", "continuous", "prismatic")
SUPPORTED = (*MOVABLE, "fixed")
_TOL = 1e-12


@dataclass(frozen=True)
class UJoint:
    """One URDF joint as read (radians, file length units)."""

    name: str
    type: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    axis: tuple[float, float, float]
    limits: tuple[float, float] | None
    mimic: tuple[str, float, float] | None  # (master, multiplier, offset)


@dataclass(frozen=True)
class Robot:
    """A parsed URDF: its joints by name and its links."""

    where: str
    name: str
    joints: dict[str, UJoint]
    links: tuple[str, ...]

    def parent_joint(self) -> dict[str, UJoint]:
        return {j.child: j for j in self.joints.values()}


@dataclass(frozen=True)
class Imported:
    """The path base → tip: its joints, the active (independent) joints and their box."""

    robot: Robot
    base: str
    tip: str
    path: tuple[UJoint, ...]  # every joint on the path, fixed ones included, base first
    chain: tuple[str, ...]  # movable joints on the path (the kernel's chain joints)
    active: tuple[str, ...]  # independent joints (non-mimic), the columns of q
    types: tuple[str, ...]  # "R" / "P" per active joint
    lower: tuple[float, ...]  # per active joint, rad / length units
    upper: tuple[float, ...]

    def joint(self, name: str) -> UJoint:
        return self.robot.joints[name]


# ------------------------------------------------------------------------- parsing


def _finite(where: str, what: str, v: Sequence[float]) -> tuple[float, ...]:
    out = tuple(float(x) for x in v)
    for x in out:
        if not math.isfinite(x):
            raise ConfigError(f"{where}: {what}: {x} is not a finite number")
    return out


PARSE_VERSION = 1
"""Part of a parsed URDF's cache key (:func:`parse`), with yourdfpy's and lxml's versions:
raise it when :func:`parse` changes what it makes of a file."""


def _parsed_file(text: str, where: str):
    """Where :func:`parse` keeps what it made of ``text`` (JSON, beside the compiled
    programs and mesh grids of ``kinematics.sdf.cache_folder``), or None without a cache."""
    import hashlib

    from designopt.kinematics.sdf import cache_folder, package_version

    folder = cache_folder()
    if folder is None:
        return None
    ver = f"{PARSE_VERSION} {package_version('yourdfpy')} {package_version('lxml')}"
    h = hashlib.sha256(f"{ver}\0{where}\0{text}".encode()).hexdigest()
    return folder / f"designopt-urdf-{h[:40]}.json"


def _to_json(r: Robot) -> str:
    import json

    return json.dumps({"where": r.where, "name": r.name, "links": list(r.links),
                       "joints": [list(vars(j).values()) for j in r.joints.values()]})  # fmt: skip


def _from_json(text: str) -> Robot:
    import json

    d = json.loads(text)

    def tup(x):
        return None if x is None else tuple(x)

    joints = {}
    for name, typ, par, ch, xyz, rpy, axis, lim, mim in d["joints"]:
        joints[name] = UJoint(name, typ, par, ch, tup(xyz), tup(rpy), tup(axis), tup(lim),
                              tup(mim))  # fmt: skip
    return Robot(d["where"], d["name"], joints, tuple(d["links"]))


def parse(text: str, where: str) -> Robot:
    """Parse URDF text (yourdfpy, meshes off) and check what the kernel needs: a <robot>
    document with named links and joints, finite numbers, known links, no closed loop,
    one root link (a tree). What a file that passed made is kept in the cache folder
    (keyed by the text and ``where``), so a warm command reads it back instead of
    importing yourdfpy and trimesh (about 0.5 s) and parsing again."""
    file = _parsed_file(text, where)
    if file is not None:
        try:
            return _from_json(file.read_text(encoding="utf-8"))
        except (OSError, ValueError, KeyError, TypeError):
            pass  # none yet, or unreadable: parse
    robot = _parse(text, where)
    if file is not None:
        from designopt.core import exported

        exported.write_cached(file, _to_json(robot).encode("utf-8"))
    return robot


def _parse(text: str, where: str) -> Robot:
    import yourdfpy
    from lxml import etree

    try:
        root = etree.fromstring(text.encode("utf-8"))  # strict: yourdfpy would recover
    except etree.XMLSyntaxError as e:
        raise ConfigError(f"{where}: malformed XML: {e}") from None
    _is_urdf(root, where)
    try:
        u = yourdfpy.URDF.load(
            io.BytesIO(text.encode("utf-8")),
            build_scene_graph=False,
            build_collision_scene_graph=False,
            load_meshes=False,
            load_collision_meshes=False,
        )
    except etree.XMLSyntaxError as e:
        raise ConfigError(f"{where}: malformed XML: {e}") from None
    except Exception as e:  # yourdfpy raises plain exceptions for bad elements
        raise ConfigError(f"{where}: not a URDF yourdfpy can read: {e}") from None
    origins = _origins(text, where)
    rob = u.robot
    links = tuple(link.name for link in rob.links)
    joints: dict[str, UJoint] = {}
    for j in rob.joints:
        el = f'<joint name="{j.name}">'
        if j.name in joints:
            raise ConfigError(f"{where}: {el}: a second joint of that name")
        for side in ("parent", "child"):
            if getattr(j, side) not in links:
                raise ConfigError(
                    f"{where}: {el}: {side} link '{getattr(j, side)}' is not a <link>"
                )
        xyz, rpy = origins[j.name]
        axis = (1.0, 0.0, 0.0) if j.axis is None else _finite(where, f"{el} <axis>", j.axis)
        if j.type in MOVABLE:
            nrm = math.sqrt(sum(a * a for a in axis))
            if nrm < 1e-9:
                raise ConfigError(f"{where}: {el} <axis>: a zero vector")
            axis = tuple(a / nrm for a in axis)
        lim = None
        if j.limit is not None and j.limit.lower is not None and j.limit.upper is not None:
            lim = _finite(where, f"{el} <limit>", (j.limit.lower, j.limit.upper))
        mim = None
        if j.mimic is not None:
            mult = 1.0 if j.mimic.multiplier is None else j.mimic.multiplier
            off = 0.0 if j.mimic.offset is None else j.mimic.offset
            mult, off = _finite(where, f"{el} <mimic>", (mult, off))
            mim = (str(j.mimic.joint), mult, off)
        joints[j.name] = UJoint(j.name, j.type, j.parent, j.child, xyz, rpy, axis, lim, mim)  # type: ignore[arg-type]
    seen: dict[str, str] = {}
    for j in joints.values():
        if j.child in seen:
            raise ConfigError(
                f"{where}: closed loop: link '{j.child}' is the child of joints "
                f"'{seen[j.child]}' and '{j.name}' (a URDF is a tree)"
            )
        seen[j.child] = j.name
    roots = [lk for lk in links if lk not in seen]
    if len(roots) > 1:
        raise ConfigError(
            f"{where}: {len(roots)} root links ({', '.join(repr(r) for r in roots)}): a URDF is "
            "one tree with one root link; join them with a joint or remove the extra links"
        )
    if not roots:
        raise ConfigError(
            f"{where}: closed loop: every link is the child of a joint (no root link)"
        )
    return Robot(where, str(rob.name), joints, links)


def _is_urdf(root, where: str) -> None:
    """A ConfigError unless the XML document is a URDF as far as its names go: a <robot>
    root element, every <robot>, <link> and <joint> with a name (yourdfpy's own message
    for a missing name is a bare KeyError), at least one <link>."""
    from lxml import etree

    tag = etree.QName(root).localname
    if tag != "robot":
        raise ConfigError(f"{where}: not a URDF: no <robot> element (the root element is <{tag}>)")
    for el in (root, *root.findall("link"), *root.findall("joint")):
        if not el.get("name"):
            raise ConfigError(f"{where}: line {el.sourceline}: <{el.tag}> has no name attribute")
    if root.find("link") is None:
        raise ConfigError(f"{where}: not a URDF: <robot> has no <link> element")


def _origins(text: str, where: str) -> dict[str, tuple[tuple[float, ...], tuple[float, ...]]]:
    """Each joint's origin (xyz, rpy) as written (yourdfpy keeps the matrix only, and a
    matrix does not say which of its equivalent rpy triples the file holds)."""
    from lxml import etree

    root = etree.fromstring(text.encode("utf-8"))
    out = {}
    for j in root.findall("joint"):
        el = f'<joint name="{j.get("name")}"> <origin>'
        o = j.find("origin")
        vals = []
        for attr in ("xyz", "rpy"):
            raw = "0 0 0" if o is None or o.get(attr) is None else o.get(attr)
            try:
                v = tuple(float(x) for x in raw.split())
            except ValueError:
                raise ConfigError(f'{where}: {el} {attr}="{raw}": not three numbers') from None
            if len(v) != 3:
                raise ConfigError(f'{where}: {el} {attr}="{raw}": not three numbers')
            vals.append(_finite(where, f"{el} {attr}", v))
        out[str(j.get("name"))] = (vals[0], vals[1])
    return out


def _rpy_of(R: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) with R = Rz(yaw) Ry(pitch) Rx(roll)."""
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if math.hypot(R[0, 0], R[1, 0]) < 1e-12:
        return (math.atan2(-R[1, 2], R[1, 1]), pitch, 0.0)
    return (math.atan2(R[2, 1], R[2, 2]), pitch, math.atan2(R[1, 0], R[0, 0]))


def import_path(
    robot: Robot,
    base: str | None,
    tip: str | None,
    limits: Mapping[str, tuple[float, float]] | None = None,
) -> Imported:
    """The path base → tip, its active joints and their box (``limits`` overrides, in
    rad / length units, by joint name)."""
    where = robot.where
    parent = robot.parent_joint()
    for key, link in (("chain.base", base), ("chain.tip", tip)):
        if link is not None and link not in robot.links:
            raise ConfigError(f"{where}: {key}: no link '{link}' in the URDF "
                              f"(links: {', '.join(robot.links)})")  # fmt: skip
    if tip is None:
        has_child = {j.parent for j in robot.joints.values()}
        start = base if base is not None else None
        leaves = [lk for lk in robot.links if lk not in has_child]
        if start is not None:
            leaves = [lk for lk in leaves if _ancestors(robot, lk, parent)[0] and start in
                      _ancestors(robot, lk, parent)[1]]  # fmt: skip
        if len(leaves) != 1:
            raise ConfigError(
                f"{where}: chain.tip: the tree branches (leaf links: {', '.join(leaves)}); "
                "name the tip link"
            )
        tip = leaves[0]
    ok, up = _ancestors(robot, tip, parent)
    if not ok:
        raise ConfigError(f"{where}: closed loop: the links above '{tip}' form a cycle")
    if base is None:
        base = up[-1]  # the root of the tip's tree
    if base not in up:
        raise ConfigError(f"{where}: chain.base/tip: no path from base '{base}' to tip '{tip}' "
                          f"(the links above '{tip}': {', '.join(up)})")  # fmt: skip
    path: list[UJoint] = []
    link = tip
    while link != base:
        j = parent[link]
        path.append(j)
        link = j.parent
    path.reverse()
    for j in path:
        if j.type not in SUPPORTED:
            raise ConfigError(f"{where}: <joint name=\"{j.name}\">: type '{j.type}' is not "
                              f"supported on a serial chain (supported: {', '.join(SUPPORTED)})")  # fmt: skip
    chain = tuple(j.name for j in path if j.type in MOVABLE)
    if not chain:
        raise ConfigError(f"{where}: no movable joint on the path from '{base}' to '{tip}'")
    active: list[str] = []
    for n in chain:
        j = robot.joints[n]
        if j.mimic is None:
            if n not in active:
                active.append(n)
            continue
        m = j.mimic[0]
        if m not in robot.joints:
            raise ConfigError(f"{where}: <joint name=\"{n}\"> <mimic>: no joint '{m}'")
        mj = robot.joints[m]
        if mj.type not in MOVABLE or mj.mimic is not None:
            raise ConfigError(f"{where}: <joint name=\"{n}\"> <mimic>: joint '{m}' must be a "
                              "movable joint that mimics no other")  # fmt: skip
    for n in chain:  # masters off the path drive their mimics: active joints too
        j = robot.joints[n]
        if j.mimic is not None and j.mimic[0] not in active:
            active.append(j.mimic[0])
    limits = dict(limits or {})
    unknown = sorted(set(limits) - set(active))
    if unknown:
        raise ValueError(f"limits.{unknown[0]}: not an active joint on the path in {where} "
                         f"(active: {', '.join(active)})")  # fmt: skip
    lo, hi, types = [], [], []
    for n in active:
        j = robot.joints[n]
        types.append("P" if j.type == "prismatic" else "R")
        if n in limits:
            lim = limits[n]
        elif j.type == "continuous":
            lim = (-math.pi, math.pi)
        elif j.limits is None:
            raise ConfigError(f"{where}: <joint name=\"{n}\">: no <limit lower upper>; give "
                              f"chain.limits.{n}")  # fmt: skip
        else:
            lim = j.limits
        if not lim[0] < lim[1]:
            raise ConfigError(f"{where}: <joint name=\"{n}\"> limits: lower {lim[0]} is not "
                              f"below upper {lim[1]}")  # fmt: skip
        lo.append(float(lim[0]))
        hi.append(float(lim[1]))
    return Imported(robot, base, tip, tuple(path), chain, tuple(active), tuple(types),
                    tuple(lo), tuple(hi))  # fmt: skip


def _ancestors(robot: Robot, link: str, parent: dict[str, UJoint]) -> tuple[bool, list[str]]:
    """(no cycle, [link, its parent link, ..., the root])."""
    up = [link]
    seen = {link}
    while up[-1] in parent:
        nxt = parent[up[-1]].parent
        if nxt in seen:
            return False, up
        seen.add(nxt)
        up.append(nxt)
    return True, up


def parse_key(key: str, imp: Imported | Robot) -> tuple[str, str]:
    """``<joint>.origin.<field>`` as (joint, field); ValueError "set.<key>: ..." otherwise
    (a config error: the config loader names the file and the key)."""
    robot = imp.robot if isinstance(imp, Imported) else imp
    joint, sep, fld = key.rpartition(".origin.")
    if not sep or not joint:
        raise ValueError(f"set.{key}: expected <joint>.origin.<field> with field one of "
                         f"{', '.join(FIELDS)}")  # fmt: skip
    if joint not in robot.joints:
        raise ValueError(f"set.{key}: no joint '{joint}' in {robot.where}")
    if fld not in FIELDS:
        raise ValueError(f"set.{key}: unknown field '{fld}' (fields: {', '.join(FIELDS)})")
    if isinstance(imp, Imported) and joint not in {j.name for j in imp.path}:
        raise ValueError(f"set.{key}: joint '{joint}' is not on the path from '{imp.base}' "
                         f"to '{imp.tip}'")  # fmt: skip
    return joint, fld


# ------------------------------------------------------------------------ lowering

Lin = tuple[float, tuple[tuple[int, float], ...]]  # const + Σ scale·X[k]
Bindings = Mapping[tuple[str, str], Lin]


def _rot(axis: int, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def rpy_matrix(r: float, p: float, y: float) -> np.ndarray:
    return _rot(2, y) @ _rot(1, p) @ _rot(0, r)


def _zyx(R: np.ndarray) -> list[tuple[int, float]]:
    """Elementary rotations (axis, angle) whose product is R (z, y, x order)."""
    r, p, y = _rpy_of(R)
    return [(2, y), (1, p), (0, r)]


def _origin_lins(j: UJoint, b: Bindings, where: str) -> tuple[list[Lin], list[Lin]]:
    """xyz and rpy of joint j as linear forms in the design columns."""
    xyz: list[Lin] = [(v, ()) for v in j.xyz]
    rpy: list[Lin] = [(v, ()) for v in j.rpy]
    if (j.name, "length") in b:
        if any((j.name, f) in b for f in ("x", "y", "z")):
            raise ConfigError(f"{where}: chain.set.{j.name}.origin.length: cannot be set "
                              "together with x, y or z of the same origin")  # fmt: skip
        n = math.sqrt(sum(v * v for v in j.xyz))
        if n < 1e-12:
            raise ConfigError(f"{where}: chain.set.{j.name}.origin.length: the origin's xyz is "
                              "zero, so it has no direction to keep")  # fmt: skip
        c, xc = b[(j.name, "length")]
        xyz = [(c * v / n, tuple((k, s * v / n) for k, s in xc)) for v in j.xyz]
    for i, f in enumerate(("x", "y", "z")):
        if (j.name, f) in b:
            xyz[i] = b[(j.name, f)]
    for i, f in enumerate(ANGLE_FIELDS):
        if (j.name, f) in b:
            rpy[i] = b[(j.name, f)]
    return xyz, rpy


def lower(imp: Imported, bindings: Bindings, variables: Sequence[str]) -> SerialModel:
    """The kernel model of the imported path: a ``SerialModel`` over ``variables``.

    ``bindings`` maps (joint, field) to const + Σ scale·X[k] (angles in rad after the
    design columns' deg→rad scale)."""
    where = imp.robot.where
    chain = list(imp.chain)
    nA = len(imp.active)
    zq = (0.0,) * nA
    steps: list = []
    Rc = np.eye(3)
    pend: dict[int | None, np.ndarray] = {}
    C = np.zeros((len(chain), nA))
    off = np.zeros(len(chain))
    jtypes: list[str] = []

    def add_t(vec: np.ndarray, key: int | None, s: float) -> None:
        pend[key] = pend.get(key, np.zeros(3)) + s * vec

    def flush_t() -> None:
        for ax in range(3):
            c = float(pend.get(None, np.zeros(3))[ax])
            xc = tuple(sorted((k, float(v[ax])) for k, v in pend.items()
                              if k is not None and abs(v[ax]) > _TOL))  # fmt: skip
            if abs(c) > 0.0 or xc:
                steps.append(_Step("T", ax, _Lin(c, xc, zq), None))
        pend.clear()

    def emit_rot(R: np.ndarray) -> None:
        if np.max(np.abs(R - np.eye(3))) < _TOL:
            return
        for ax, a in _zyx(R):
            if abs(math.remainder(a, 2 * math.pi)) > _TOL:
                steps.append(_Step("R", ax, _Lin(_snap(a), (), zq), None))

    for j in imp.path:
        xyz, rpy = _origin_lins(j, bindings, where)
        for i in range(3):
            c, xc = xyz[i]
            add_t(Rc[:, i], None, c)
            for k, s in xc:
                add_t(Rc[:, i], k, s)
        if any(xc for _, xc in rpy):
            flush_t()
            emit_rot(Rc)
            Rc = np.eye(3)
            for ax, (c, xc) in zip((2, 1, 0), (rpy[2], rpy[1], rpy[0]), strict=True):
                steps.append(_Step("R", ax, _Lin(c, tuple(xc), zq), None))
        else:
            Rc = Rc @ rpy_matrix(rpy[0][0], rpy[1][0], rpy[2][0])
        if j.type not in MOVABLE:
            continue
        ci = chain.index(j.name)
        d = Rc @ np.asarray(j.axis)
        k = int(np.argmax(np.abs(d)))
        if np.all(np.abs(np.delete(d, k)) < _TOL):
            ax, sign = k, (1.0 if d[k] > 0 else -1.0)
        else:  # oblique: A e_z = d with A = Rz(φ) Ry(θ); Rc becomes Aᵀ Rc after the joint
            flush_t()
            th, ph = math.atan2(math.hypot(d[0], d[1]), d[2]), math.atan2(d[1], d[0])
            A = _rot(2, ph) @ _rot(1, th)
            steps.append(_Step("R", 2, _Lin(ph, (), zq), None))
            steps.append(_Step("R", 1, _Lin(th, (), zq), None))
            Rc = A.T @ Rc
            ax, sign = 2, 1.0
        kind = "T" if j.type == "prismatic" else "R"
        if kind == "R":
            flush_t()
        jtypes.append("P" if kind == "T" else "R")
        if j.mimic is None:
            C[ci, imp.active.index(j.name)] = sign
        else:
            m, mult, o = j.mimic
            C[ci, imp.active.index(m)] = sign * mult
            off[ci] = sign * o
        steps.append(_Step(kind, ax, _Lin(0.0, (), zq), ci))
    flush_t()
    emit_rot(Rc)
    Cm = tuple(tuple(float(x) for x in r) for r in C)
    return SerialModel(tuple(steps), tuple(jtypes), tuple(variables), Cm,
                       tuple(float(x) for x in off))  # fmt: skip


def _snap(a: float) -> float:
    """An angle within 1e-12 of a multiple of π/2 as that multiple (exact folding)."""
    n = round(a / (math.pi / 2))
    return n * (math.pi / 2) if abs(a - n * math.pi / 2) < _TOL else a


# ----------------------------------------------------------------- reference FK


class Reference:
    """yourdfpy's own forward kinematics of the URDF text (the independent check)."""

    def __init__(self, text: str) -> None:
        import yourdfpy

        self.u = yourdfpy.URDF.load(
            io.BytesIO(text.encode("utf-8")),
            build_scene_graph=True,
            build_collision_scene_graph=False,
            load_meshes=False,
            load_collision_meshes=False,
        )

    def fk(self, imp: Imported, q: Sequence[float]) -> np.ndarray:
        """base_T_tip (4×4) at active joint values q (rad / length units)."""
        u = self.u
        cfg = dict(zip(imp.active, (float(x) for x in q), strict=True))
        vec = [cfg.get(n, 0.0) for n in u.actuated_joint_names]
        u.update_cfg(np.asarray(vec, float))
        return np.asarray(u.get_transform(imp.tip, imp.base), float)


# ------------------------------------------------------------------------- export


def export_text(text: str, values: Mapping[tuple[str, str], float], where: str) -> str:
    """The URDF ``text`` with the origins' ``set`` fields replaced by ``values``
    ((joint, field) → number in rad / file units; ``length`` rescales xyz), every other
    byte unchanged. A joint without an <origin> gets one."""
    data = text.encode("utf-8")
    starts: dict[str, int] = {}  # joint -> byte index of its <origin
    jstart: dict[str, int] = {}  # joint -> byte index of its start tag
    stack: list[tuple[str, str | None]] = []
    p = xml.parsers.expat.ParserCreate()

    def start(tag, attrs):
        parent = stack[-1] if stack else None
        if tag == "joint" and len(stack) == 1:
            jstart[attrs.get("name", "")] = p.CurrentByteIndex
        if tag == "origin" and parent is not None and parent[0] == "joint" and len(stack) == 2:
            starts.setdefault(parent[1] or "", p.CurrentByteIndex)
        stack.append((tag, attrs.get("name")))

    def end(tag):
        stack.pop()

    p.StartElementHandler = start
    p.EndElementHandler = end
    try:
        p.Parse(data, True)
    except xml.parsers.expat.ExpatError as e:
        raise ConfigError(f"{where}: malformed XML: {e}") from None
    by_joint: dict[str, dict[str, float]] = {}
    for (jn, f), v in values.items():
        if not math.isfinite(v):
            raise ConfigError(f"{where}: {jn}.origin.{f}: {v} is not a finite number")
        by_joint.setdefault(jn, {})[f] = float(v)
    edits: list[tuple[int, int, bytes]] = []
    for jn, fv in by_joint.items():
        if jn not in jstart:
            raise ConfigError(f'{where}: no <joint name="{jn}"> to write')
        if jn in starts:
            i0 = starts[jn]
            i1 = _tag_end(data, i0)
            tag = data[i0:i1].decode("utf-8")
            new = _edit_origin(tag, fv)
            edits.append((i0, i1, new.encode("utf-8")))
        else:
            i1 = _tag_end(data, jstart[jn])
            new = _edit_origin("<origin/>", fv)
            edits.append((i1, i1, new.encode("utf-8")))
    for i0, i1, b in sorted(edits, reverse=True):
        data = data[:i0] + b + data[i1:]
    return data.decode("utf-8")


def _tag_end(data: bytes, i: int) -> int:
    """The index just past the '>' that closes the start tag at i (quotes skipped)."""
    q = None
    while i < len(data):
        c = data[i : i + 1]
        if q is not None:
            if c == q:
                q = None
        elif c in (b'"', b"'"):
            q = c
        elif c == b">":
            return i + 1
        i += 1
    raise ValueError("unterminated tag")


def _num(v: float) -> str:
    return repr(float(v))


def _edit_origin(tag: str, fv: Mapping[str, float]) -> str:
    def get(attr: str) -> tuple[list[str], re.Match | None]:
        m = re.search(r"(\s" + attr + r"\s*=\s*)([\"'])(.*?)\2", tag, re.S)
        return (m.group(3).split() if m else ["0", "0", "0"]), m

    out = tag
    for attr, names in (("xyz", ("x", "y", "z")), ("rpy", ANGLE_FIELDS)):
        vals, m = get(attr)
        changed = False
        if attr == "xyz" and "length" in fv:
            v = np.array([float(x) for x in vals])
            n = float(np.linalg.norm(v))
            vals = [_num(fv["length"] * x / n) for x in v]
            changed = True
        for i, f in enumerate(names):
            if f in fv:
                vals[i] = _num(fv[f])
                changed = True
        if not changed:
            continue
        text = " ".join(vals)
        m = get(attr)[1] if out is tag else re.search(
            r"(\s" + attr + r"\s*=\s*)([\"'])(.*?)\2", out, re.S)  # fmt: skip
        if m is not None:
            out = out[: m.start(3)] + text + out[m.end(3) :]
        else:
            k = out.rfind("/>") if out.rstrip().endswith("/>") else out.rfind(">")
            out = (
                out[:k].rstrip() + f' {attr}="{text}"' + (" " if out[k:] == "/>" else "") + out[k:]
            )
    return out
