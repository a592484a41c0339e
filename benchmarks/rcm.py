"""Scan throughput of the planar RCM study: η over box, cone and reachable cone for a batch
of designs (c from 200 to 400 mm) × Monte-Carlo samples, against a numpy vectorised
baseline computing the same estimates (same samples) in the same run.

    python benchmarks/rcm.py [--designs 81] [--samples 65536] [--repeat 5]

Prints designs × samples per second (median and spread over repeats) for the jitted
product kernel (compile time separately) and numpy, and their ratio.
"""

from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from designopt.numerics import montecarlo as mc  # noqa: E402
from designopt.studies import streams  # noqa: E402
from designopt.studies.rcm import objective as o  # noqa: E402
from designopt.studies.rcm.settings import RcmSettings  # noqa: E402


def _ratio(w: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Σwg/Σw along the last axis and its delta-method standard error."""
    n = g.shape[-1]
    sw = w.sum(-1)
    m = (w * g).sum(-1) / sw
    psi = w * (g - m[..., None])
    return m, np.sqrt((psi**2).sum(-1) / (n * (n - 1))) / (sw / n)


def numpy_eta(u: np.ndarray, a: float, cs: np.ndarray) -> np.ndarray:
    """The same estimates as the product (Cartesian measure, planar cone): η over the box,
    the cone and the reachable cone, and the reach fraction, each with its SE."""
    d1 = 22 + 193 * u[:, 0]
    d2 = 35 + 165 * u[:, 1]
    c = cs[:, None]
    r = np.hypot(d1 - a, d2)[None]
    e = np.abs(c - r)
    box = _ratio(np.abs(1 - c / r), np.minimum(e, r) / np.maximum(e, r))
    d = np.sqrt(2500 + u[:, 0] * (40000 - 2500))[None]
    phi = (2 * u[:, 1] - 1) * np.pi / 6
    x, y = d * np.sin(phi), -d * np.cos(phi)
    rr = c - d
    g = np.minimum(d, np.abs(rr)) / np.maximum(d, np.abs(rr))
    cone = _ratio(np.ones_like(g), g)
    s = 1 - c / d
    k1, k2 = a + s * x, s * y
    ok = ((k1 >= 22) & (k1 <= 215) & (k2 >= 35) & (k2 <= 200) & (rr > 0)).astype(float)
    reach_eta = _ratio(ok, g)
    reach = _ratio(np.ones_like(ok), ok)
    return np.stack(
        [box[0], cone[0], reach_eta[0], reach[0], box[1], cone[1], reach_eta[1], reach[1]], 1
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--designs", type=int, default=81)
    ap.add_argument("--samples", type=int, default=65_536)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    s = RcmSettings(variables={"c": (100, 500)}, fixed={"a": 120},
                    eta={"n_samples": args.samples, "measure": "cartesian"},
                    constraints={"eq19": False, "reach_min": None})  # fmt: skip
    P = o.problem(s, streams(0), jnp.float64)
    cs = np.linspace(200, 400, args.designs)
    X = jnp.asarray(cs)[:, None]
    fn = jax.jit(P.fn)
    t0 = time.perf_counter()
    out = fn(P.params, X, None)
    jax.block_until_ready(out)
    first = time.perf_counter() - t0
    tj = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(P.params, X, None))
        tj.append(time.perf_counter() - t0)
    n_chunks, chunk = mc.chunking(args.samples, o.CHUNK)
    u = np.concatenate([np.asarray(mc.unit_samples(P.params["sample_key"], k * chunk, chunk, 3,
                                                   "uniform", jnp.float64)) for k in range(n_chunks)])  # fmt: skip
    tn = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        ref = numpy_eta(u, 120.0, cs)
        tn.append(time.perf_counter() - t0)
    aux = out[1]
    ks = ("eta_box", "eta_cone", "eta_reach", "reach")
    got = np.stack([np.asarray(aux[k]) for k in ks] + [np.asarray(aux[k + "_se"]) for k in ks], 1)
    err = np.abs(got - ref).max()
    work = args.designs * n_chunks * chunk
    print(f"rcm scan: {args.designs} designs × {n_chunks * chunk} samples (η of three workspaces "
          f"and reach, each ± SE), {args.repeat} repeats; max |product − numpy| = {err:.1e}")  # fmt: skip
    print(f"  jax   first call {first:.2f} s (compile + run); then median {np.median(tj) * 1e3:.1f} ms "
          f"[{min(tj) * 1e3:.1f}, {max(tj) * 1e3:.1f}] → {work / np.median(tj) / 1e6:.1f} M design-samples/s")  # fmt: skip
    print(f"  numpy median {np.median(tn) * 1e3:.1f} ms [{min(tn) * 1e3:.1f}, {max(tn) * 1e3:.1f}] "
          f"→ {work / np.median(tn) / 1e6:.1f} M design-samples/s (the same 4 estimates ± SE)")  # fmt: skip
    print(f"  ratio numpy/jax (steady state): {np.median(tn) / np.median(tj):.2f}×; "
          f"numpy / jax's first call (compile included): {np.median(tn) / first:.2f}×")  # fmt: skip


if __name__ == "__main__":
    main()
