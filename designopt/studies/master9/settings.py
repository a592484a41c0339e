"""The ``study:`` section of a master9 config (docs/configs.md), validated by pydantic."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pydantic import Field, field_validator

from designopt.core.settings import Section
from designopt.studies.base import StudySettings, check_replicates

if TYPE_CHECKING:  # pragma: no cover
    from designopt.numerics.montecarlo import Plan

DESIGN_KEYS: tuple[str, ...] = ("a1", "a3", "d3", "a4", "a5", "d2", "d5", "d6")
"""The master's lengths (mm); mirrors ``mechanism.DESIGN_KEYS`` (kept import-light)."""


class Indices(Section):
    """How the indices of seed 000 eq. (35)-(43) are estimated: the config's
    ``study.indices`` section and the settings of the index kernel (``indices.py``), one
    model. Every field is recorded in archives (``record``).

    n_samples: joint-space samples per design (shared by the swarm); chunk: samples per
    step of the memory-bounded scan; measure: 'cartesian' (the paper's ∫_W dW, weights
    |det J_v|) or 'joint'; sampler: 'uniform', 'rqmc' or 'halton' with ``replicates``
    (``montecarlo.plan``); backlash_deg: backlash of (q1, q2, q3) in degrees (not in the
    paper), one number or three; norm/normalized: the condition number convention
    (default raw Frobenius, eq. 51-53); weights: (w_k, w_l, w_p) of eq. (43).
    """

    n_samples: int = Field(20_000, gt=1)
    chunk: int = Field(8_192, gt=0)  # (50, 8192) arrays stay in cache: 1.3-1.6× faster than 32768
    measure: Literal["cartesian", "joint"] = "cartesian"
    # rqmc in configs/master9.yaml; uniform here keeps tiny runs (short replicates) bitwise
    # equal under particle sharding (docs/indices.md)
    sampler: Literal["uniform", "halton", "rqmc"] = "uniform"
    replicates: int | None = Field(None, ge=1, le=1024)  # rqmc: 16 by default (docs/indices.md)
    backlash_deg: float | list[float] = 0.1
    norm: Literal["fro", "2"] = "fro"
    normalized: bool = False
    weights: list[float] = [4.0, 2.0, 1.0]

    _replicates = field_validator("replicates")(check_replicates)

    @field_validator("backlash_deg", "weights")
    @classmethod
    def _three(cls, v: float | list[float]) -> float | list[float]:
        if isinstance(v, list) and len(v) != 3:
            raise ValueError(f"needs one number or a list of 3, got {len(v)} values")
        return v

    @property
    def backlash(self) -> tuple[float, float, float]:
        """Backlash of (q1, q2, q3) in degrees, one number per joint."""
        return _three(self.backlash_deg)

    @property
    def weights3(self) -> tuple[float, float, float]:
        """(w_k, w_l, w_p), one number per sub-objective."""
        return _three(self.weights)

    @property
    def joint_limits_deg(self) -> tuple[tuple[float, float], ...]:
        """The position joints' limits (q1, q2, q3) in degrees (mechanism.POSITION_LIMITS)."""
        from designopt.studies.master9.mechanism import POSITION_LIMITS

        return tuple(map(tuple, np.rad2deg(POSITION_LIMITS).tolist()))

    @property
    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """The sampled joint box (lower, upper) in rad."""
        lim = np.deg2rad(np.asarray(self.joint_limits_deg, dtype=np.float64))
        return lim[:, 0], lim[:, 1]

    @property
    def plan(self) -> Plan:
        """The Monte-Carlo layout (replicates, chunks) of ``n_samples``."""
        from designopt.numerics import montecarlo as mc

        if self.sampler != "rqmc" and self.replicates in (None, 1):  # one stream
            c = min(self.chunk, self.n_samples)
            return mc.Plan(self.sampler, 1, -(-self.n_samples // c), c)
        return mc.plan(self.n_samples, self.chunk, self.sampler, self.replicates)

    @property
    def n_used(self) -> int:
        """Samples actually used (n_samples rounded up to whole chunks)."""
        return self.plan.n_used

    def record(self) -> dict[str, Any]:
        """What archives record (``problem.info["settings"]``): every field, backlash and
        weights per joint / sub-objective, and the sampled joint limits in degrees."""
        out = self.model_dump()
        out["backlash_deg"] = self.backlash
        out["weights"] = self.weights3
        out["joint_limits_deg"] = self.joint_limits_deg
        return out


def _three(v: float | list[float] | tuple[float, ...]) -> tuple[float, float, float]:
    if isinstance(v, list | tuple):
        a, b, c = (float(x) for x in v)
        return a, b, c
    return float(v), float(v), float(v)


class Master9Settings(StudySettings):
    """Study A: the 9-DOF haptic master of seed 000."""

    name: Literal["master9"] = "master9"
    variables: dict[str, tuple[float, float]] = {
        "a1": (250, 350),
        "a3": (250, 350),
        "d3": (50, 150),
    }
    fixed: dict[str, float] = {}
    indices: Indices = Indices()
    n_norm: int = Field(64, gt=1)
