"""The one base of every settings model (the run config's sections, each study's
settings, the benchmark config, device settings, task regions): a pydantic model whose
unknown keys are errors."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict


class Section(BaseModel):
    """A settings model or section: unknown keys are errors."""

    model_config = ConfigDict(extra="forbid")
