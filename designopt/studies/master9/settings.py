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

    n_samples: int = Field(
        20_000,
        gt=1,
        description="Joint-space samples per design (shared by the swarm).",
    )
    chunk: int = Field(
        8_192,
        gt=0,
        description="Samples per step of the memory-bounded scan; (particles × chunk) arrays that "
        "fit the CPU cache are fastest.",
    )
    measure: Literal["cartesian", "joint"] = Field(
        "cartesian",
        description="`cartesian` (the paper's ∫_W dW: weights |det J_v|) or `joint` (uniform in "
        "the joint box).",
    )
    # rqmc in configs/master9.yaml; uniform here keeps tiny runs (short replicates) bitwise
    # equal under particle sharding (docs/indices.md)
    sampler: Literal["uniform", "halton", "rqmc"] = Field(
        "uniform",
        description="How the samples are drawn: `uniform` (i.i.d.), `halton` (one randomly shifted "
        "Halton set) or `rqmc` (R independently shifted Halton sets; standard errors "
        "from the replicates' spread).",
    )
    replicates: int | None = Field(
        None,
        ge=1,
        le=1024,
        description="R, the independent randomisations of the sampler: at least 2 with `rqmc` (16 "
        "unless given), 1 with `halton`; `uniform` accepts R ≥ 2 (i.i.d. groups).",
    )
    backlash_deg: float | list[float] = Field(
        0.1,
        description="Backlash (deg) of the position joints (q1, q2, q3): one number or a list of "
        "3.",
    )
    norm: Literal["fro", "2"] = Field(
        "fro",
        description="Condition-number convention: `fro` (Frobenius, the paper's) or `2`.",
    )
    normalized: bool = Field(
        False,
        description="Switch to the normalised condition-number convention (default: the raw "
        "Frobenius one, 1/k in [0, 1/3]; docs/indices.md).",
    )
    weights: list[float] = Field(
        [4.0, 2.0, 1.0],
        description="Weights (w_k, w_l, w_p) of f_k, f_l, f_p in eq. (43): one number or a list of "
        "3.",
    )

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

    name: Literal["master9"] = Field("master9", description="`master9`: the 9-DOF haptic master.")
    variables: dict[str, tuple[float, float]] = Field(
        {"a1": (250, 350), "a3": (250, 350), "d3": (50, 150)},
        description="Design variables and their box {name: [lo, hi]} (mm): any of a1, a3, d3, a4, "
        "a5, d2, d5, d6.",
    )
    fixed: dict[str, float] = Field(
        {},
        description="Lengths (mm) that are not varied (default a4 10, a5 60, d2 30, d5 50, d6 80).",
    )
    indices: Indices = Field(Indices(), description="How the indices are estimated.")
    n_norm: int = Field(
        64,
        gt=1,
        description="Designs scored over the box for the objective's normalisation bounds.",
    )
