"""Compiled programs kept as exported StableHLO next to the compilation cache (issue #46,
part 3): a warm run loads a large program's module instead of tracing and lowering it
again (3.7 s for the UR5-through-a-port block program on the 2-core box), and XLA's
compile of that module is the persistent cache's hit as before.

The file is keyed by a hash of everything that shapes the program: the caller's
structure key, the arguments' shapes and dtypes (their pytree too), the backend, JAX's
version and designopt's own source (any edit of the code invalidates every file).
Nothing is kept without a compilation cache folder (``jax_compilation_cache_dir``: the
CLI's ``compile_cache``); a file that cannot be read is exported again, and files are
written whole (a temporary file renamed), so parallel processes never read half of one.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax

_CALLS: dict[str, Callable] = {}
_LOCK = threading.RLock()
_LOCKS: dict[str, Any] = {}  # one per program: two programs export side by side
_SOURCE: list[str] = []
_READY = threading.Event()  # the first program has run
_TRACED = threading.Event()  # ... has been traced, its compile begun (or it has run)


def source_hash() -> str:
    """A hash of designopt's Python source (every file under the package)."""
    if not _SOURCE:
        h = hashlib.sha256()
        root = Path(__file__).resolve().parents[1]
        for p in sorted(root.rglob("*.py")):
            h.update(str(p.relative_to(root)).encode())
            h.update(p.read_bytes())
        _SOURCE.append(h.hexdigest())
    return _SOURCE[0]


def fingerprint(dumped: Any, base: Path | None = None) -> str:
    """A hash of settings as JSON (``model_dump(mode="json")``) and of every file they name
    (a string that is a path, as written or from ``base``: its resolved path, size and
    modification time), of designopt's source, and of JAX's version and precision: what
    identifies a result computed from the settings alone (a study's checks, its
    normalisation bounds) between processes."""
    import json

    files: list[str] = []
    base = Path(base) if base is not None else Path(".")

    def walk(v: Any) -> None:
        if isinstance(v, dict):
            for x in v.values():
                walk(x)
        elif isinstance(v, list):
            for x in v:
                walk(x)
        elif isinstance(v, str) and len(v) < 4096:
            for p in (Path(v), base / v):
                try:
                    if p.is_file():
                        st = p.stat()
                        files.append(f"{p.resolve()}:{st.st_size}:{st.st_mtime_ns}")
                        break
                except OSError:
                    pass

    walk(dumped)
    h = hashlib.sha256(json.dumps(dumped, sort_keys=True, default=str).encode())
    for f in sorted(files):
        h.update(f.encode())
    h.update(source_hash().encode())
    h.update(f"{jax.__version__} {jax.config.jax_enable_x64}".encode())
    return h.hexdigest()


def write_cached(path: Path, data: bytes) -> None:
    """``data`` into ``path`` in the cache folder whole (a temporary file beside it,
    renamed over it, so a reader sees the old file or the new one, never half of one), or
    nothing when the folder cannot be written: the cache only saves time."""
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except OSError:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def signature(key: str, args: tuple) -> str:
    """The text that identifies a program: ``key`` and the arguments' pytree, shapes and
    dtypes, the backend and the versions."""
    leaves, tree = jax.tree_util.tree_flatten(args)
    avals = [(tuple(getattr(a, "shape", ())), str(getattr(a, "dtype", type(a).__name__)))
             for a in leaves]  # fmt: skip
    return "\n".join([key, str(tree), str(avals), jax.default_backend(), jax.__version__,
                      source_hash()])  # fmt: skip


def folder() -> Path | None:
    d = jax.config.jax_compilation_cache_dir
    return None if not d else Path(d)


def compiled(key: str, fn: Callable, args: tuple, options: dict[str, Any] | None = None
             ) -> Callable:  # fmt: skip
    """``fn`` (jitted) for arguments shaped like ``args``: from its exported module in the
    cache folder when one is there, else exported now and kept there; ``fn`` itself
    without a cache folder or where exporting fails. ``options``: the XLA compile options
    ``fn`` was jitted with (``core.xlaoptions``), which the loaded module is compiled
    with too (the module itself does not depend on them)."""
    sig = signature(key, args)
    with _LOCK:
        lock = _LOCKS.setdefault(sig, threading.RLock())
    with lock:  # one export per program, whichever thread asks first
        call = _compiled(sig, fn, args, options or {})
    if _READY.is_set():
        return call

    def first(*a: Any) -> Any:  # the process's first call of such a program, compiled
        if call is not fn:  # exported (traced) ahead: its call compiles, and frees the GIL
            _TRACED.set()
        try:
            return jax.block_until_ready(call(*a))
        finally:
            _TRACED.set()
            _READY.set()

    return first


def wait_ready(timeout: float, traced: bool = False) -> bool:
    """Wait (at most ``timeout`` s, and in a background job of
    ``concurrency.in_background`` no longer than the work beside it) until the first
    program from :func:`compiled` in this process has been called, compiled and run, or,
    with ``traced``, until it has been traced and its call has begun (an exported
    program: its XLA compile, which frees the GIL; one traced by its call, with no cache
    folder: until that call has returned). A background trace that waits for it leaves
    the GIL to that first program's trace (two traces take turns); ``traced`` lets it
    compile beside that program's compile rather than beside its calls. True once it has."""
    from designopt.core import concurrency

    return concurrency.wait(_TRACED if traced else _READY, timeout)


def _compiled(sig: str, fn: Callable, args: tuple, options: dict[str, Any]) -> Callable:
    mem = f"{sig}\n{sorted(options.items())}"
    if mem in _CALLS:
        return _CALLS[mem]
    d = folder()
    call = fn
    if d is not None:
        from jax import export

        path = d / f"designopt-export-{hashlib.sha256(sig.encode()).hexdigest()[:40]}.bin"
        exp = None
        if path.is_file():
            try:
                exp = export.deserialize(bytearray(path.read_bytes()))
            except Exception:  # noqa: BLE001  (a damaged or foreign file: export again)
                exp = None
        if exp is None:
            try:
                exp = export.export(fn)(*args)
                data = exp.serialize()
            except Exception:  # noqa: BLE001  (no flatbuffers, an unsupported op: plain jit)
                exp = None
            else:
                write_cached(path, data)
        if exp is not None:
            call = jax.jit(exp.call, compiler_options=options or None)
    _CALLS[mem] = call
    return call
