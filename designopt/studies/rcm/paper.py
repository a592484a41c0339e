"""The planar RCM paper's printed formulas (Sensors 2023), kept beside the corrected ones
for the tests and docs/rcm.md.

- eq. (9) as printed: J = [[1 − E d2 sin θ, E (d1 − a) sin θ], [E d2 cos θ,
  1 − E (d1 − a) cos θ]] with **E = c/√((d1 − a)² + d2²)** = c/r. E must have the unit
  1/length (J is dimensionless: ∂D/∂d), so c/r (dimensionless) is wrong; the derivative
  of eq. (7) gives E = c/r². With the printed E, det J = 1 − E·r = 1 − c, which depends on
  the unit of c and vanishes only for c = 1, not when D = R as eq. (10) and §2.3 state.
- eq. (10) as printed, det J = 1 − c/r, is what the corrected E gives.
- Conclusions: "the range of motion of mobile joint I ... 25 mm and 215 mm"; Table 2
  gives 22-215 mm. We use Table 2.
"""

from __future__ import annotations

import jax.numpy as jnp

Array = jnp.ndarray

BUILT = {"a": 120.0, "b": 260.0, "c": 250.0}  # Table 1
JOINTS = {"theta1_deg": (-38.0, 38.0), "d1": (22.0, 215.0), "d2": (35.0, 200.0)}  # Table 2
ETA_PEAK = (230.0, 0.64)  # §2.4 and Fig. 4a: η peaks at 0.64 for c = 230 mm
TRACKING = {"max_mm": 1.49, "mean_mm": 0.45, "below_0.5": 62.54, "below_1": 96.54}  # Table 4


def jacobian_printed(d1: Array, d2: Array, a: Array, c: Array) -> Array:
    """eq. (9) exactly as printed, E = c/r (dimensionally wrong)."""
    u, v = d1 - a, d2
    r = jnp.sqrt(u * u + v * v)
    E = c / r
    sin, cos = v / r, u / r
    return jnp.stack(
        [
            jnp.stack([1 - E * v * sin, E * u * sin], -1),
            jnp.stack([E * v * cos, 1 - E * u * cos], -1),
        ],
        -2,
    )


def det_printed(d1: Array, d2: Array, a: Array, c: Array) -> Array:
    """eq. (10) as printed: 1 − c/√((d1 − a)² + d2²)."""
    return 1.0 - c / jnp.sqrt((d1 - a) ** 2 + d2**2)
