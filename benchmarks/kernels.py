"""FK + Jacobian + inverse condition number throughput for the 9-DOF master.

50 designs × 20,000 configurations, float32 and float64, in configurations per second,
beside a vectorised numpy implementation of the same closed forms measured in this run.

    python benchmarks/kernels.py [--designs 50] [--configs 20000]
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp
import numpy as np
from _timing import best_of, compile_time, header

from designopt.kinematics import inv_cond_fro3
from designopt.studies.master9 import mechanism as m


def numpy_reference(q: np.ndarray, D: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form P (eq. 4), J_v (eq. 34, fixed) and 1/k_F via the adjugate, in numpy."""
    a1, a3, a4, d3 = (D[k][:, None] for k in ("a1", "a3", "a4", "d3"))
    q1, q2, q3 = q[None, :, 0], q[None, :, 1], q[None, :, 2]
    s12, c12, c3, s3 = np.sin(q1 + q2), np.cos(q1 + q2), np.cos(q3), np.sin(q3)
    w = a3 * c3 + a4
    px = a1 * np.cos(q1) + d3 * c12 + w * s12
    j12 = w * c12 - d3 * s12
    j22 = w * s12 + d3 * c12
    J = np.zeros(px.shape + (3, 3))
    J[..., 0, 0] = j12 - a1 * np.sin(q1)
    J[..., 0, 1] = j12
    J[..., 0, 2] = -a3 * s12 * s3
    J[..., 1, 0] = j22 + a1 * np.cos(q1)
    J[..., 1, 1] = j22
    J[..., 1, 2] = a3 * c12 * s3
    J[..., 2, 2] = -a3 * c3
    C = np.linalg.inv(J) * np.linalg.det(J)[..., None, None]
    r = np.abs(np.linalg.det(J)) / np.sqrt((J**2).sum((-1, -2)) * (C**2).sum((-1, -2)))
    return px, r


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--designs", type=int, default=50)
    ap.add_argument("--configs", type=int, default=20_000)
    args = ap.parse_args()
    header("kernels: master9 FK + Jacobian + 1/k")
    M, N = args.designs, args.configs
    rng = np.random.default_rng(0)
    Dn = {k: np.full(M, v) for k, v in m.default_design().items()}
    Dn["a1"] = rng.uniform(250, 350, M)
    Dn["a3"] = rng.uniform(250, 350, M)
    Dn["d3"] = rng.uniform(50, 150, M)
    qn = np.asarray(m.sample_joints(jax.random.key(0), N))
    total = M * N

    t_np = best_of(lambda: numpy_reference(qn, Dn), 3)
    print(
        f"numpy closed form (float64):          {total / t_np:12.3e} configs/s  ({t_np * 1e3:8.1f} ms)"
    )

    for dtype in (jnp.float32, jnp.float64):
        q = jnp.asarray(qn, dtype)
        D = {k: jnp.asarray(v, dtype)[:, None] for k, v in Dn.items()}

        @jax.jit
        def chain_path(q, D):
            T = m.fk(q, D)
            J = m.jacobian(q, D)
            return T[..., :3, 3], inv_cond_fro3(J[..., :3, :3])

        @jax.jit
        def closed_path(q, D):
            P = m.position(q[:, :3], D)
            return P, inv_cond_fro3(m.jacobian_v_closed(q[:, :3], D))

        name = jnp.dtype(dtype).name
        for label, fn in (("autodiff chain", chain_path), ("closed form   ", closed_path)):
            tc = compile_time(lambda fn=fn: fn(q, D))
            t = best_of(lambda fn=fn: fn(q, D), 5)
            print(
                f"jax {label} ({name}): {total / t:12.3e} configs/s  ({t * 1e3:8.1f} ms, "
                f"compile {tc:5.2f} s)  = {t_np / t:6.1f}x numpy"
            )
        # agreement with the numpy reference
        _, r = closed_path(q, D)
        _, rn = numpy_reference(qn, Dn)
        print(f"   max |1/k - numpy| ({name}): {float(np.abs(np.asarray(r) - rn).max()):.2e}")


if __name__ == "__main__":
    main()
