"""HDF5 archives (schema: docs/archive.md), built in memory and written atomically by the one
writer (``designopt.io.writer``: a temporary file, fsync, rename).

``save(path, record)`` and ``load(path) -> Record`` store and read the typed records of
``designopt.results``; underneath, ``write(path, tree, attrs)`` stores a nested dict: dict values become groups, everything
else a dataset; a group's ``"attrs"`` entry becomes its HDF5 attributes (non-scalars as
JSON). A run in progress writes checkpoints to ``partial_path(out)`` — a valid archive
with ``complete = False`` — and removes it once the final archive is in place.
"""

from __future__ import annotations

import io
import json
import platform
from importlib import metadata
from pathlib import Path
from typing import Any

import h5py
import jax
import numpy as np

from designopt.core.errors import ConfigError
from designopt.io import writer

SCHEMA_VERSION = 1


def versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for pkg in ("designopt", "jax", "jaxlib", "numpy", "optax", "h5py", "pydantic", "matplotlib"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def _attr(v: Any) -> Any:
    if isinstance(v, (str, bool, int, float, np.integer, np.floating)):
        return v
    if isinstance(v, np.ndarray) and v.dtype.kind in "biuf":
        return v
    return json.dumps(v, default=lambda o: np.asarray(o).tolist())


def _put(grp: h5py.Group, tree: dict[str, Any]) -> None:
    for name, val in tree.items():
        if name == "attrs":
            for k, v in val.items():
                grp.attrs[k] = _attr(v)
        elif isinstance(val, dict):
            _put(grp.create_group(name), val)
        else:
            arr = np.asarray(val)
            if arr.dtype.kind == "U":
                arr = arr.astype("S")
            grp.create_dataset(name, data=arr, compression="gzip" if arr.size > 4096 else None)


def image(tree: dict[str, Any], attrs: dict[str, Any], complete: bool = True) -> bytes:
    """The bytes of an HDF5 archive holding ``tree`` and root ``attrs``, built in memory
    (so a disk fault can never leave HDF5 half-written or open: ``writer.write_file``
    writes the bytes)."""
    buf = io.BytesIO()
    with h5py.File(buf, "w") as h:
        _put(h, {"attrs": attrs})
        h.attrs["schema_version"] = SCHEMA_VERSION
        h.attrs["versions"] = json.dumps(versions())
        h.attrs["jax_backend"] = jax.default_backend()
        h.attrs["jax_devices"] = json.dumps([str(d) for d in jax.devices()])
        h.attrs["complete"] = complete
        _put(h, tree)
    return buf.getvalue()


def write(
    path: str | Path, tree: dict[str, Any], attrs: dict[str, Any], complete: bool = True
) -> Path:
    """Write the nested dict ``tree`` and root ``attrs`` to ``path`` atomically through
    the one writer (``designopt.io.writer``); WriteError (one line) on a disk fault."""
    what = "archive" if complete else "checkpoint"
    return writer.write_file(path, image(tree, attrs, complete), what)


def partial_path(path: str | Path) -> Path:
    """Where a run in progress keeps its checkpoint archive (``x.h5`` → ``x.partial.h5``)."""
    p = Path(path)
    return p.with_name(f"{p.stem}.partial{p.suffix or '.h5'}")


def read(path: str | Path, group: str = "/") -> dict[str, Any]:
    """Read a group back into a nested dict of numpy arrays (attrs under ``"attrs"``)."""

    def get(g: h5py.Group) -> dict[str, Any]:
        out: dict[str, Any] = {"attrs": {}}
        for k, v in g.attrs.items():
            if isinstance(v, str) and v[:1] in "[{":
                try:
                    v = json.loads(v)
                except json.JSONDecodeError:
                    pass
            out["attrs"][k] = v
        for k, v in g.items():
            out[k] = get(v) if isinstance(v, h5py.Group) else v[()]
        return out

    with h5py.File(path, "r") as h:
        return get(h[group])


def save(path: str | Path, record: Any, overwrite: bool = False, complete: bool = True) -> Path:
    """Write a record (``designopt.results``) atomically through the one writer; the
    output is claimed first if this command has not (``writer.claim``: lock, free space,
    an existing archive refused unless ``overwrite``). A disk fault is one WriteError
    line (exit 1) and keeps what was there."""
    path = Path(path)
    ses = writer.current()
    if ses is None or not ses.covers(path):
        writer.claim(path, overwrite)
    tree = record.to_tree()
    attrs = tree.pop("attrs")
    replaced = path.is_file()
    out = write(path, tree, attrs, complete)
    if replaced and complete:  # what was derived from the archive it replaced is stale
        for d in derived(path):
            writer.discard(d)
    return out


def derived(path: str | Path) -> list[Path]:
    """The files made from an archive beside it: its figures folder ``<stem>_figures``,
    its HTML page ``<stem>.html`` and an IK archive's ``<stem>_joints.csv``. Replacing the
    archive (``--overwrite``) removes them: they described the old one."""
    path = Path(path)
    return [path.parent / f"{path.stem}_figures", path.with_suffix(".html"),
            path.parent / f"{path.stem}_joints.csv"]  # fmt: skip


def load(path: str | Path) -> Any:
    """The record an archive holds (``designopt.results``: a run, scan, sweep, bench or
    IK record; an interrupted run's checkpoint; a replay). ConfigError naming the file
    when it is missing, not HDF5, or of an unknown kind."""
    from designopt import results

    p = Path(path)
    if p.is_dir():
        raise ConfigError(f"{p}: is a folder; give a run's .h5 archive in it")
    if not p.is_file():
        raise ConfigError(f"{p}: archive not found")
    with open(p, "rb") as f:
        head = f.read(8)
    if head != b"\x89HDF\r\n\x1a\n":  # HDF5's signature (at offset 0 for our archives)
        what = " (a config: `designopt run` takes it)" if p.suffix in (".yaml", ".yml") else ""
        raise ConfigError(f"{p}: not a readable HDF5 archive{what}; give a run's .h5 archive")
    try:
        tree = read(p)
    except OSError as e:
        raise ConfigError(f"{p}: not a readable HDF5 archive ({e})") from None
    try:
        return results.from_tree(tree)
    except (ValueError, KeyError) as e:
        raise ConfigError(f"{p}: not a designopt archive ({e})") from None
