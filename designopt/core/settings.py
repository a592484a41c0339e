"""The base of every nested settings section (``studies.base`` re-exports it): a module of
its own, so that shared schemas such as ``designopt.kinematics.task`` need not import the study
registry."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict


class Section(BaseModel):
    """A nested section of a study's settings: unknown keys are errors."""

    model_config = ConfigDict(extra="forbid")
