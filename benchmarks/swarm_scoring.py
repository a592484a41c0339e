"""Score a swarm of 50 designs with 20,000 workspace samples each (seed 000 indices).

Prints Jacobian condition numbers per second and wall time per swarm evaluation for the
dexterity part (GCI/GCSEI) and for the full composite f, float32 and float64, next to a
numpy implementation of the same formulas measured in this run. ``--memory`` also scores
10^7 samples × 50 designs and prints the process's peak resident memory.

    python benchmarks/swarm_scoring.py [--designs 50] [--samples 20000] [--memory]
"""

from __future__ import annotations

import argparse
import resource
import time

import jax

jax.config.update("jax_enable_x64", True)  # the float64 columns (designopt leaves it to us)
import jax.numpy as jnp
import numpy as np
from _timing import best_of, compile_time, header

from designopt.numerics import montecarlo as mc
from designopt.studies.master9 import mechanism as m
from designopt.studies.master9 import objective as obj
from designopt.studies.master9.indices import (
    _features,
    inv_cond_fro_jv,
    jv_entries,
    swarm_indices,
)
from designopt.studies.master9.settings import Indices


def numpy_dexterity(X: np.ndarray, q: np.ndarray, a4: float) -> tuple[np.ndarray, np.ndarray]:
    """GCI, GCSEI (Cartesian-weighted) in numpy: eq. (34) entries, adjugate 1/k_F."""
    a1, a3, d3 = X[:, 0:1], X[:, 1:2], X[:, 2:3]
    q1, q2, q3 = q[:, 0], q[:, 1], q[:, 2]
    s12, c12, s3, c3 = np.sin(q1 + q2), np.cos(q1 + q2), np.sin(q3), np.cos(q3)
    w = a3 * c3 + a4
    j01 = w * c12 - d3 * s12
    j11 = w * s12 + d3 * c12
    j00, j10 = j01 - a1 * np.sin(q1), j11 + a1 * np.cos(q1)
    j02, j12, j22 = -a3 * s12 * s3, a3 * c12 * s3, -a3 * c3
    mm = j00 * j11 - j01 * j10
    det = j22 * mm
    c20, c21 = j01 * j12 - j02 * j11, j02 * j10 - j00 * j12
    nJ = j00**2 + j01**2 + j02**2 + j10**2 + j11**2 + j12**2 + j22**2
    nC = j22**2 * (j00**2 + j01**2 + j10**2 + j11**2) + c20**2 + c21**2 + mm**2
    r = np.abs(det) / np.sqrt(nJ * nC)
    wt = np.abs(det)
    gci = (wt * r).sum(1) / wt.sum(1)
    gcsei = np.sqrt((wt * (r - gci[:, None]) ** 2).sum(1) / wt.sum(1))
    return gci, gcsei


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--designs", type=int, default=50)
    ap.add_argument("--samples", type=int, default=20_000)
    ap.add_argument("--memory", action="store_true")
    a = ap.parse_args()
    header("swarm scoring: master9 indices")
    M, N = a.designs, a.samples
    rng = np.random.default_rng(0)
    Xn = np.stack([rng.uniform(250, 350, M), rng.uniform(250, 350, M), rng.uniform(50, 150, M)], 1)
    qn = np.asarray(m.sample_joints(jax.random.key(0), N))[:, :3]
    a4 = m.default_design()["a4"]
    t_np = best_of(lambda: numpy_dexterity(Xn, qn, a4), 3)
    print(f"numpy dexterity (float64):   {M * N / t_np:10.3e} cond/s   {t_np * 1e3:8.1f} ms/swarm")

    for dtype in (jnp.float32, jnp.float64):
        name = jnp.dtype(dtype).name
        X = jnp.asarray(Xn, dtype)
        q = jnp.asarray(qn, dtype)
        fixed = {k: jnp.full((M,), v, dtype) for k, v in m.default_design().items()}

        @jax.jit
        def dexterity(X, q):
            x = {"a1": X[:, 0:1], "a3": X[:, 1:2], "d3": X[:, 2:3], "a4": fixed["a4"][:, None]}
            det, r = inv_cond_fro_jv(jv_entries(x, _features(q)))
            ps = mc.power_sums(jnp.abs(det), r)
            return mc.mean(ps).value, mc.std(ps).value

        P = obj.problem({"indices": {"n_samples": N, "chunk": N}, "dtype": name, "n_norm": 16})
        full = jax.jit(P.fn)
        key = jax.random.key(0)
        tc_d = compile_time(lambda: dexterity(X, q))
        t_d = best_of(lambda: dexterity(X, q), 10)
        tc_f = compile_time(lambda: full(P.params, X, key))
        t_f = best_of(lambda: full(P.params, X, key), 10)
        gci, _ = dexterity(X, q)
        err = float(np.abs(np.asarray(gci) - numpy_dexterity(Xn, qn, a4)[0]).max())
        print(
            f"jax dexterity ({name}):     {M * N / t_d:10.3e} cond/s   {t_d * 1e3:8.2f} ms/swarm "
            f"(compile {tc_d:4.2f} s)  {t_np / t_d:6.1f}x numpy   max|ΔGCI|={err:.1e}"
        )
        print(
            f"jax full composite ({name}): {M * N / t_f:10.3e} cond/s   {t_f * 1e3:8.2f} ms/swarm "
            f"(compile {tc_f:4.2f} s)  {t_np / t_f:6.1f}x numpy dexterity"
        )

    if a.memory:
        s = Indices(n_samples=10_000_000, chunk=32_768)
        D = {k: jnp.full((M,), v, jnp.float32) for k, v in m.default_design().items()}
        D.update(
            a1=jnp.asarray(Xn[:, 0], jnp.float32),
            a3=jnp.asarray(Xn[:, 1], jnp.float32),
            d3=jnp.asarray(Xn[:, 2], jnp.float32),
        )
        t0 = time.perf_counter()
        out = jax.block_until_ready(
            jax.jit(lambda D, k: swarm_indices(D, k, s, jnp.float32))(D, jax.random.key(1))
        )
        dt = time.perf_counter() - t0
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
        print(
            f"10^7 samples x {M} designs (float32, chunk 32768): {dt:.1f} s, peak RSS {peak:.2f} GB, "
            f"GCI[0] = {float(out['gci'][0]):.5f} ± {float(out['gci_se'][0]):.1e}"
        )


if __name__ == "__main__":
    main()
