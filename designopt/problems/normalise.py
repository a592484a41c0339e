"""Normalised composite objectives: f = Σ w_i (x_i − min_i)/(max_i − min_i).

The bounds (min_i, max_i) of each weighted index come from scoring a space-filling
(Halton) sample of the design box once, before optimising (the haptic master paper,
IEEE Access 2019, eq. 43, does not say where its normalisation bounds come from); they
stay fixed during the run, travel in ``params["bounds"]`` (k, 2) for the trace and are
archived (``Problem.norm_bounds``). Studies call :func:`probe_bounds` at set-up and
:func:`weighted_sum` inside their swarm function. Within :func:`evaluation_shape` (the
pipeline sets the optimizer's (runs, particles) around building a problem) the probe
scores its designs in batches of that shape through ``evaluate_batch``: the very program
the run evaluates its swarm with, so the probe compiles nothing of its own.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from designopt.numerics import montecarlo as mc

Array = jnp.ndarray


_SHAPE: contextvars.ContextVar[tuple[int, int] | None] = contextvars.ContextVar(
    "designopt_evaluation_shape", default=None
)


@contextlib.contextmanager
def evaluation_shape(shape: tuple[int, int] | None) -> Iterator[None]:
    """Within: :func:`probe_bounds` scores in batches of ``shape`` (groups, rows), the
    shape of the run's objective calls (``RunResult.eval_shape``)."""
    token = _SHAPE.set(shape)
    try:
        yield
    finally:
        _SHAPE.reset(token)


def unit_bounds(k: int, dtype: Any) -> Array:
    """(k, 2) bounds [0, 1] per index: the weighted sum of the raw indices."""
    return jnp.asarray([[0.0, 1.0]] * k, dtype)


def probe_bounds(
    fn: Callable[[Any, Array, jax.Array], tuple[Array, Mapping[str, Array]]],
    params: Any,
    names: Sequence[str],
    lower: np.ndarray,
    upper: np.ndarray,
    n_norm: int,
    keys: Mapping[str, jax.Array],
    dtype: Any,
    staged: Any = None,
    constraints: Callable | None = None,
    identity: str | None = None,
) -> np.ndarray:
    """(len(names), 2) min and max of the indices ``names`` over ``n_norm`` Halton designs
    of the box [lower, upper] (shifted by the ``normalisation`` stream), scored once by
    the swarm function ``fn`` with the Monte-Carlo key ``keys["samples"]`` (within
    :func:`evaluation_shape`: through ``problems.evaluate.score``, key 0, as the run's scoring; the
    studies' functions draw their samples from ``params`` and ignore the key). An index
    that is flat over the sample gets max = min + 1 (no scaling, never a division by 0);
    n/a values (NaN: a ratio over too few items) are left out, and an index n/a at every
    design gets [0, 1]. ``staged`` (``Problem.staged``) and ``constraints``: the
    problem's two-stage scoring and constraints, which the probe then shares with the
    run (``problems.evaluate.staged_scores``: the same programs). ``identity``: what
    identifies ``fn`` between processes (``core.exported.fingerprint`` of the study's
    settings); with it and a cache folder, the bounds are kept there and a later process
    with the same settings, arguments and params reads them back instead of scoring the
    ``n_norm`` designs again (a warm ``eval`` or ``run``)."""
    shape = _SHAPE.get()
    file = None
    if identity is not None:
        file = _bounds_file(identity, params, names, lower, upper, n_norm, keys, dtype, shape,
                            staged is not None, constraints is not None)  # fmt: skip
        b = _read_bounds(file, len(names))
        if b is not None:
            return b
    Xn = mc.box_samples(keys["normalisation"], lower, upper, n_norm, "halton", dtype)
    if staged is not None:
        from designopt.problems.base import Problem
        from designopt.problems.evaluate import staged_scores

        box = Problem(tuple(f"x{i}" for i in range(len(lower))), lower, upper, fn, params,
                      constraints=constraints, staged=staged)  # fmt: skip
        sub = staged_scores(box, np.asarray(Xn), dtype=dtype)[1]
        vals = [sub[k] for k in names]
    elif shape is None:
        _, sub = jax.jit(fn)(params, Xn, keys["samples"])
        vals = [np.asarray(sub[k]) for k in names]  # on the host: no reduction to compile
    else:
        from designopt.problems.base import Problem
        from designopt.problems.evaluate import score

        box = Problem(tuple(f"x{i}" for i in range(len(lower))), lower, upper, fn, params)
        sub = score(box, np.asarray(Xn), eval_shape=shape, dtype=dtype)
        vals = [sub[k] for k in names]
    b = np.array([[float(np.nanmin(v)), float(np.nanmax(v))] if np.any(np.isfinite(v))
                  else [0.0, 1.0] for v in vals])  # fmt: skip  # n/a values (NaN) left out
    b[:, 1] = np.where(b[:, 1] > b[:, 0], b[:, 1], b[:, 0] + 1.0)
    if file is not None:
        _write_bounds(file, b)
    return b


def _bytes(x: Any) -> bytes:
    """An array's (or a PRNG key's) shape, dtype and bytes."""
    if isinstance(x, jax.Array) and jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):
        x = jax.random.key_data(x)
    a = np.asarray(x)
    return f"{a.shape}{a.dtype}".encode() + a.tobytes()


def _bounds_file(identity: str, params: Any, names: Sequence[str], lower: np.ndarray,
                 upper: np.ndarray, n_norm: int, keys: Mapping[str, jax.Array], dtype: Any,
                 shape: tuple[int, int] | None, staged: bool, constrained: bool) -> Any:  # fmt: skip
    """The cache folder's file of the bounds for these arguments (None without a folder)."""
    import hashlib

    from designopt.core import exported

    folder = exported.folder()
    if folder is None:
        return None
    h = hashlib.sha256(f"{identity}|{tuple(names)}|{n_norm}|{jnp.dtype(dtype)}|{shape}|"
                       f"{staged}|{constrained}".encode())  # fmt: skip
    for x in (np.asarray(lower, np.float64), np.asarray(upper, np.float64),
              keys["normalisation"], keys["samples"], *jax.tree_util.tree_leaves(params)):  # fmt: skip
        h.update(_bytes(x))
    return folder / f"designopt-bounds-{h.hexdigest()[:40]}.npy"


def _read_bounds(file: Any, k: int) -> np.ndarray | None:
    if file is None:
        return None
    try:
        b = np.load(file, allow_pickle=False)
    except Exception:  # noqa: BLE001  (none yet, truncated, foreign: score the designs)
        return None
    ok = b.shape == (k, 2) and b.dtype == np.float64 and np.all(np.isfinite(b))
    return np.array(b) if ok and np.all(b[:, 1] > b[:, 0]) else None


def _write_bounds(file: Any, b: np.ndarray) -> None:
    """``b`` into ``file`` whole, or nothing when the folder cannot be written
    (``core.exported.write_cached``)."""
    import io

    from designopt.core import exported

    buf = io.BytesIO()
    np.save(buf, np.asarray(b, np.float64), allow_pickle=False)
    exported.write_cached(file, buf.getvalue())


def weighted_sum(
    values: Sequence[Array],
    bounds: Array,
    weights: Sequence[Any],
    ses: Sequence[Array] | None = None,
) -> Any:
    """f = Σ_i w_i (x_i − b_i0)/(b_i1 − b_i0) (values (M,) or per replicate (M, R)).

    With ``ses`` (the indices' standard errors), returns (f, f_se) where f_se =
    Σ_i |w_i| se_i/|b_i1 − b_i0| bounds f's standard error when the indices share their
    samples (correlated estimates). The terms are accumulated in index order, f and f_se
    together (the order fixes the last bit in float32)."""
    f: Any = 0.0
    f_se: Any = 0.0
    for i, (x, w) in enumerate(zip(values, weights, strict=True)):
        span = bounds[i, 1] - bounds[i, 0]
        f = f + w * (x - bounds[i, 0]) / span
        if ses is not None:
            f_se = f_se + abs(w) * ses[i] / jnp.abs(span)
    return f if ses is None else (f, f_se)
