"""One root key, split once into named streams: ``key(seed)`` → ``optimizer``,
``samples`` (Monte-Carlo samples, shared by the whole swarm), ``normalisation`` (the
designs that fix normalisation bounds) and ``figures``. The raw key data is archived
(root attr ``keys``), so a run's streams can be rebuilt from its archive."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import numpy as np

STREAMS = ("optimizer", "samples", "normalisation", "figures")
"""The named PRNG streams split once from the root key ``key(seed)``."""


def streams(seed: int) -> dict[str, jax.Array]:
    """One root key ``key(seed)`` split once into the named streams of :data:`STREAMS`."""
    return dict(zip(STREAMS, _split(np.uint32(seed)), strict=True))


@jax.jit
def _split(seed: Any) -> tuple[jax.Array, ...]:
    # one program (op by op: four, making the root key, splitting it, taking it apart)
    return tuple(jax.random.split(jax.random.key(seed), len(STREAMS)))


def key_data(keys: Mapping[str, jax.Array]) -> dict[str, list[int]]:
    """The raw key data of each stream (archived, so a run's keys can be rebuilt)."""
    return {k: np.asarray(jax.random.key_data(v)).tolist() for k, v in keys.items()}


def archived_keys(archive: Mapping[str, Any]) -> dict[str, jax.Array]:
    """The named streams of a run, rebuilt from its archive (the inverse of
    :func:`key_data`; root attribute ``keys``)."""
    raw = archive["attrs"]["keys"]
    return {k: jax.random.wrap_key_data(np.asarray(v, np.uint32)) for k, v in raw.items()}
