"""The inverse-kinematics protocol of a study (``Study.ik``): what its solver gets
(``IKJob``), what it returns (``IKSolution``) and what it declares (``IKHook``), for the
``designopt ik`` command and any other caller."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from designopt.kinematics.poses import DEFAULT_TOL, MODES, Targets


@dataclass(frozen=True)
class IKJob:
    """What a study's solver gets: its validated ``settings``, the ``design`` (the
    hook's ``design`` resolved it), the checked ``targets`` and the ``mode`` to solve,
    a PRNG ``key`` (the ``samples`` stream of the config's seed), the values of the
    study's own options (``IKHook.arguments``) and a ``progress(n)`` callback."""

    settings: Any
    design: dict[str, float]
    targets: Targets
    mode: str
    key: Any
    options: Mapping[str, Any] = field(default_factory=dict)
    progress: Callable[[int], None] | None = None


@dataclass(frozen=True)
class IKSolution:
    """A solver's answer: ``arrays`` with per-target ``q`` (N, n), ``success``,
    ``pos_err``, ``rot_err`` and whatever else it has (``iterations``, ``inv_k``), the
    joints' names, the units text (``"q1, q2 rad; q3 mm; pos_err mm; rot_err rad"``),
    extra ``ik`` attrs and lines printed before the summary."""

    arrays: dict[str, np.ndarray]
    joint_names: list[str]
    units: str
    attrs: dict[str, Any] = field(default_factory=dict)
    lines: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class IKHook:
    """A study's inverse kinematics (``Study.ik``), for ``designopt ik``.

    - ``design(settings, given, where) -> {name: value}``: the design to solve for,
      ``given`` the ``--design NAME=VALUE`` values (ConfigError naming ``where`` for an
      unknown name);
    - ``solve(job) -> IKSolution`` (float64 is on; a ValueError names the target);
    - ``modes``: the target modes it solves (of :data:`MODES`);
    - ``arguments(parser)``: the study's own optional flags (each with a default), given
      to ``solve`` as ``job.options``; the same flag given for another study is refused;
    - ``tol(settings)``: the tolerance of unit quaternions, axes and orthonormal rows."""

    solve: Callable[[IKJob], IKSolution]
    design: Callable[[Any, dict[str, float], str], dict[str, float]]
    modes: tuple[str, ...] = MODES
    arguments: Callable[[Any], None] | None = None
    tol: Callable[[Any], float] = lambda s: DEFAULT_TOL
