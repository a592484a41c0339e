"""Where a planning design puts its ports and bases (``Study.placement``): each port's
point, its projection onto the body wall and each arm's base pose, as numbers on the host
(NumPy), for the archive, ``show --csv``, the figures and the plan sheet."""

from __future__ import annotations

from typing import Any

from designopt.studies.serial.settings import SerialSettings, length_unit


def entry_range(s: SerialSettings, v: float | str) -> tuple[float, float]:
    """One base or port entry's range over the design box: a number, a variable's box, a
    fixed value, or minus one of these ("-b")."""
    if not isinstance(v, str):
        return float(v), float(v)
    name = v.removeprefix("-")
    if name in s.variables:
        lo, hi = (float(w) for w in s.variables[name])
    else:
        lo = hi = float(s.fixed[name])
    return (-hi, -lo) if v.startswith("-") else (lo, hi)


def entries(s: SerialSettings, row: Any, X: Any) -> Any:
    """Base or port entries (numbers, fixed values, design variables, "-name") as numbers
    (n, len(row)) for designs ``X`` (n, D) (config units; ``settings.entry_value``'s rule,
    vectorised over the designs)."""
    import numpy as np

    names = list(s.variables)
    cols = []
    for v in row:
        if not isinstance(v, str):
            cols.append(np.full(len(X), float(v)))
            continue
        name = v.removeprefix("-")
        col = np.full(len(X), float(s.fixed[name])) if name in s.fixed else X[:, names.index(name)]
        cols.append(-col if v.startswith("-") else col)
    return np.stack(cols, -1)


def placement(s: SerialSettings, X: Any) -> dict[str, Any] | None:
    """``Study.placement``: for designs ``X`` (n, D), in the world frame and the chain's
    length unit, each arm's port on the body wall ``ports`` (n, A, 3) (the design's
    point ``port_points`` projected onto ``task.body_wall`` by ``kinematics.wall.project``,
    as the objective places it), ``port_points`` (n, A, 3), the projection's distance
    ``port_shift`` (n, A), and with ``arms`` each base ``bases`` (n, A, 6): x, y, z,
    roll, pitch, yaw (degrees, the config's rpy). None: no port and no arms."""
    import numpy as np

    X = np.atleast_2d(np.asarray(X, np.float64))
    ports = s.ports() if s.task is not None else [None]
    out: dict[str, Any] = {}
    if all(p is not None for p in ports):
        raw = np.stack([entries(s, p, X) for p in ports], 1)  # (n, A, 3)
        wall = s.task.body_wall  # type: ignore[union-attr]
        on = raw
        if wall is not None:
            import jax
            import jax.numpy as jnp

            from designopt.kinematics import wall as kw

            dt = jnp.float64 if jax.config.jax_enable_x64 else jnp.float32
            on = np.asarray(kw.project(wall.shape, kw.wall_params(wall, dt), jnp.asarray(raw, dt)),
                            np.float64)  # fmt: skip
        out |= {"ports": on, "port_points": raw, "port_shift": np.linalg.norm(on - raw, axis=-1)}
    cam = None if s.task is None else s.task.camera
    if cam is not None:
        out["camera"] = camera_at(s, X)
    if s.arms is not None:
        out["bases"] = np.stack([np.concatenate([entries(s, a.base.xyz, X),
                                                 entries(s, a.base.rpy, X)], -1)
                                 for a in s.arms], 1)  # fmt: skip
    if not out:
        return None
    u = length_unit(s)
    xyz = [f"{c} [{u}]" for c in "xyz"]
    cols = {"ports": xyz, "port_points": xyz, "port_shift": [f"moved [{u}]"],
            "bases": xyz + [f"{c} [deg]" for c in ("roll", "pitch", "yaw")],
            "camera": [f"port {c} [{u}]" for c in "xyz"] + [f"tip {c} [{u}]" for c in "xyz"]}  # fmt: skip
    titles = {"ports": "port: the incision point on the body wall", "port_points":
              "the design's port point (before projection)", "port_shift":
              "port moved by the projection", "bases": "base pose",
              "camera": "the endoscope: its incision point and its tip"}  # fmt: skip
    wall = None if s.task is None or s.task.body_wall is None else s.task.body_wall.shape
    if wall is None:  # no projection: the design's point is the port
        titles["ports"] = "port: the incision point"
    return out | {"attrs": {"length_unit": u, "wall": wall,
                            "columns": {k: cols[k] for k in out},
                            "titles": {k: titles[k] for k in out}}}  # fmt: skip


def camera_at(s: SerialSettings, X: Any) -> Any:
    """The endoscope of designs ``X`` (n, D): (n, 6), its incision point (x, y, z) and
    its tip (``camera.pose``: the same function the index reads)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from designopt.kinematics import wall as kw
    from designopt.studies.serial import camera

    dt = jnp.float64 if jax.config.jax_enable_x64 else jnp.float32
    X = np.atleast_2d(np.asarray(X, np.float64))
    fixed = np.broadcast_to(np.asarray([s.fixed[k] for k in s.fixed], np.float64),
                            (len(X), len(s.fixed)))  # fmt: skip
    full = jnp.asarray(np.concatenate([X, fixed], 1), dt)  # a port's columns are lengths
    wall = s.task.body_wall  # type: ignore[union-attr]
    params = camera.camera_params(s, dt) | ({} if wall is None else
                                            {"scene_wall": kw.wall_params(wall, dt)})  # fmt: skip
    inc, tip, _ = camera.pose(params, full, None if wall is None else wall.shape)
    return np.concatenate([np.asarray(inc, np.float64), np.asarray(tip, np.float64)], -1)


def ports_of(s: SerialSettings, k: int, designs: list[dict[str, float] | None]) -> Any:
    """Arm ``k``'s port (D, 3) at each design (a mapping of the design variables), on
    ``task.body_wall`` when there is one (the projection the objective makes)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from designopt.kinematics import wall as kw
    from designopt.studies.serial.settings import port_at

    p = np.asarray([port_at(s, k, d) for d in designs], np.float64)
    wall = s.task.body_wall  # type: ignore[union-attr]
    if wall is None:
        return p
    dt = jnp.float64 if jax.config.jax_enable_x64 else jnp.float32
    return np.asarray(kw.project(wall.shape, kw.wall_params(wall, dt), jnp.asarray(p, dt)),
                      np.float64)  # fmt: skip
