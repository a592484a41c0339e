"""A user's serial chain from its YAML description, on the generic frame kernel
(``designopt.kinematics.kernel``): the DH table (or the URDF path, ``kinematics.urdf``) as
data, the joint box in SI-free units (rad for R joints, length units for P joints), and
the design columns.

Design columns are the variables (in config order) followed by the fixed names; angle
entries named by a variable are given in degrees and converted by ``scale``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from designopt.kinematics.kernel import SerialModel, dh_model
from designopt.studies.serial.settings import SerialSettings, UrdfChain, length_unit


@dataclass(frozen=True)
class Mechanism:
    model: SerialModel
    names: tuple[str, ...]  # design columns: variables then fixed
    n_var: int
    scale: np.ndarray  # (len(names),) deg→rad for angle names, 1 for lengths
    fixed: np.ndarray  # (len(names) - n_var,) values of the fixed names (user units)
    lower: np.ndarray  # (n,) joint box, rad / length units
    upper: np.ndarray

    @property
    def n(self) -> int:
        return len(self.lower)


def _entry(v: float | str, angle: bool) -> float | str:
    if isinstance(v, str):
        return v
    return float(np.deg2rad(v)) if angle else float(v)


def urdf_bindings(s: SerialSettings) -> dict[tuple[str, str], tuple[float, tuple]]:
    """A URDF chain's ``set`` as kernel bindings: (joint, field) → (const, ((design
    column, 1),)) in kernel units (rad for angles; the columns are variables then fixed
    names, angle columns scaled deg → rad by ``Mechanism.scale``)."""
    from designopt.kinematics import urdf

    names = tuple(s.variables) + tuple(s.fixed)
    out: dict[tuple[str, str], tuple[float, tuple]] = {}
    for (joint, fld), v in s.chain.bound().items():  # type: ignore[union-attr]
        if isinstance(v, str):
            out[(joint, fld)] = (0.0, ((names.index(v), 1.0),))
        else:
            out[(joint, fld)] = (float(np.deg2rad(v)) if fld in urdf.ANGLE_FIELDS else float(v), ())
    return out


def build(s: SerialSettings) -> Mechanism:
    """The chain of ``s`` as a kernel model with its joint box and design columns."""
    names = tuple(s.variables) + tuple(s.fixed)
    angles = s.angle_names()
    scale = np.array([np.pi / 180 if n in angles else 1.0 for n in names])
    fixed = np.array([s.fixed[n] for n in s.fixed], np.float64)
    if isinstance(s.chain, UrdfChain):
        from designopt.kinematics import urdf

        imp = s.chain.imported
        model = urdf.lower(imp, urdf_bindings(s), names)
        lo, hi = np.array(imp.lower), np.array(imp.upper)
        return Mechanism(model, names, len(s.variables), scale, fixed, lo, hi)
    joints = s.chain.joints
    model = dh_model(
        convention=s.chain.convention,
        joint_types=tuple(j.type for j in joints),
        alpha=[_entry(j.alpha, True) for j in joints],
        a=[_entry(j.a, False) for j in joints],
        d=[_entry(j.d, False) for j in joints],
        theta=[_entry(j.theta, True) for j in joints],
        variables=names,
    )
    lim = np.array([j.limits for j in joints], np.float64)
    rev = np.array([j.type == "R" for j in joints])
    lim[rev] = np.deg2rad(lim[rev])
    return Mechanism(model, names, len(s.variables), scale, fixed, lim[:, 0], lim[:, 1])


def set_values(s: Any, design: dict[str, float]) -> dict[tuple[str, str], float]:
    """{(joint, field): number in the URDF's units (rad, file lengths)} of ``set``."""
    from designopt.kinematics.urdf import ANGLE_FIELDS

    vals = design | {k: float(v) for k, v in s.fixed.items()}
    out = {}
    for (joint, fld), v in s.chain.bound().items():
        x = vals[v] if isinstance(v, str) else float(v)
        out[(joint, fld)] = math.radians(x) if fld in ANGLE_FIELDS else x
    return out


def home(mech: Mechanism) -> np.ndarray:
    """The home pose: each joint at 0 where its limits allow it, else mid-range."""
    lo, hi = np.asarray(mech.lower), np.asarray(mech.upper)
    return np.where((lo <= 0) & (0 <= hi), 0.0, (lo + hi) / 2)


def joint_names(s: SerialSettings) -> list[str]:
    """The active joints' names: the URDF's, or q1 … qn of a DH table."""
    if isinstance(s.chain, UrdfChain):
        return list(s.chain.imported.active)
    return [f"q{i + 1}" for i in range(len(s.chain.joints))]


def joint_values(s: SerialSettings, q: Sequence[float], sep: str = ", ") -> str:
    """``q1 = 10 deg, q3 = 0.135 m``: degrees for R joints, the chain's length unit for
    P joints."""
    u = length_unit(s)
    out = []
    for name, j, v in zip(joint_names(s), s.chain.joints, q, strict=True):
        out.append(
            f"{name} = {math.degrees(v):.4g} deg" if j.type == "R" else f"{name} = {v:.4g} {u}"
        )
    return sep.join(out)
