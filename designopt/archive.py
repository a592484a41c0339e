"""HDF5 archives (docs/archive.md), written atomically: a temporary file, then rename."""

from __future__ import annotations

import json
import os
import platform
from importlib import metadata
from pathlib import Path
from typing import Any

import h5py
import jax
import numpy as np


def versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for pkg in ("designopt", "jax", "jaxlib", "numpy", "optax", "h5py", "pydantic"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def write(path: str | Path, groups: dict[str, dict[str, Any]], attrs: dict[str, Any]) -> Path:
    """Write {group: {name: array}} and root attributes to ``path`` atomically."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with h5py.File(tmp, "w") as h:
            for k, v in attrs.items():
                h.attrs[k] = v if isinstance(v, (str, int, float, np.ndarray)) else json.dumps(v)
            h.attrs["versions"] = json.dumps(versions())
            h.attrs["jax_backend"] = jax.default_backend()
            h.attrs["jax_devices"] = json.dumps([str(d) for d in jax.devices()])
            h.attrs["complete"] = True
            for g, items in groups.items():
                grp = h.create_group(g)
                for name, val in items.items():
                    if isinstance(val, dict):
                        grp.attrs[name] = json.dumps(val)
                    else:
                        grp.create_dataset(name, data=np.asarray(val))
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path
