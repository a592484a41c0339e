"""Whether a serial study's results can mean anything: before optimising, a task region
that no design in the box can reach is refused (the reach of every design is bounded by
the sum of its link lengths along the chain, ``SerialModel.reach_bound``); after, the
final design's reach and index constraints are compared with what was asked, and what is
far off is said (``Study.warnings``)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from designopt.kinematics import task as tk
from designopt.studies.serial.mechanism import build
from designopt.studies.serial.settings import SerialSettings, length_unit

REACH_WARNING = 0.95
"""A task run whose best design reaches a smaller share of its targets is warned about,
with or without a reach constraint."""
Z = 2.0
"""An index constraint is missed when the final value is beyond its bound by more than Z
standard errors (a miss within the Monte-Carlo noise is not called one)."""


def largest_reach(s: SerialSettings) -> float:
    """An upper bound of the tip's distance from the base over every design in the box
    and every configuration in the joint limits (the chain's length unit)."""
    mech = build(s)
    lo, hi = s.box()[1:]
    fixed = np.asarray(mech.fixed, np.float64)
    x_lo = np.concatenate([lo, fixed]) * mech.scale
    x_hi = np.concatenate([hi, fixed]) * mech.scale
    return mech.model.reach_bound(x_lo, x_hi, mech.lower, mech.upper)


def check(s: SerialSettings) -> None:
    """ValueError naming ``task.region`` when no design in the box can reach any point of
    the task region."""
    if s.task is None:
        return
    _check_ports(s)
    if s.collision is not None:
        from designopt.studies.serial import bodies

        bodies.check(s, build(s))
    if s.arms is not None:
        return  # the bases move the arms: the region's distance is from each arm's base
    near = tk.nearest_distance(s.task.region)
    far = largest_reach(s)
    if near > far * (1 + 1e-9) + 1e-12:
        u = length_unit(s)
        raise ValueError(
            f"task.region: no design in the box reaches the task region: its nearest point "
            f"is {near:.4g} {u} from the base, and the longest design reaches at most "
            f"{far:.4g} {u} (the sum of its link lengths along the chain); check the "
            f"region's position and the chain's length unit"
        )


def _check_ports(s: SerialSettings) -> None:
    """ValueError when a port leaves no target within the insertion range, or sits on
    an arm's base (inside its base link: within a capsule radius, or at the origin
    without collision capsules)."""
    r = 0.0
    if s.collision is not None:
        r = min(s.collision.radius) if isinstance(s.collision.radius, list) else s.collision.radius
    for k, port in enumerate(s.ports()):
        if port is None:
            continue
        where = "task.port" if s.arms is None or s.arms[k].port is None else f"arms.{k}.port"
        tk.check_port(s.task, port=port, where=where)  # type: ignore[arg-type]
        base = (0.0, 0.0, 0.0) if s.arms is None else s.arms[k].base.xyz
        if all(isinstance(v, float | int) for v in base):
            d = float(np.linalg.norm(np.subtract(port, base)))  # type: ignore[arg-type]
            if d <= max(r, 1e-9):
                raise ValueError(f"{where}: the port {list(port)} lies inside the arm's base "
                                 f"link ({d:.3g} from its base origin); the instrument must "
                                 "enter the body away from the base")  # fmt: skip


def warnings(s: SerialSettings, final: Mapping[str, Any]) -> list[str]:
    """What is far from what was asked in the final design's results: a task region
    reached at less than :data:`REACH_WARNING`, an index constraint missed by more than
    :data:`Z` standard errors."""
    out = []

    def val(k: str) -> tuple[float, float]:
        return float(np.asarray(final[k])), float(np.asarray(final.get(k + "_se", 0.0)))

    asked_reach = None
    for c in s.index_constraints():
        if c.index not in final:
            continue
        v, se = val(c.index)
        if c.index == "reach" and c.ge is not None:
            asked_reach = c.ge
        if c.ge is not None and v < c.ge - Z * se:
            out.append(f"{c.index} = {v:.4g} ± {se:.2g}, asked ≥ {c.ge:g}: the constraint is "
                       "missed by the best design found")  # fmt: skip
        elif c.le is not None and v > c.le + Z * se:
            out.append(f"{c.index} = {v:.4g} ± {se:.2g}, asked ≤ {c.le:g}: the constraint is "
                       "missed by the best design found")  # fmt: skip
    if s.indices.measure == "task" and "reach" in final and asked_reach is None:
        v, se = val("reach")
        if v < REACH_WARNING:
            out.append(f"reach = {v:.3g} ± {se:.2g}: the best design reaches "
                       f"{100 * v:.0f} % of the task region's targets (gci and the other "
                       "task indices count an unreached target as 0)")  # fmt: skip
    return out
