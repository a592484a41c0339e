"""The published numbers the study is compared with (docs/sphere.md says where each comes
from and what could not be checked).

- Lum, Warden, Rosen, Sinanan, Hannaford, "Hybrid analysis of a spherical mechanism for a
  minimally invasive surgical robot" (IOS Press, Medicine Meets Virtual Reality; abstract
  at ebooks.iospress.nl/publication/10596): the kinematic metrics' optimum
  (α12, α23) = (90°, 90°); with the hybrid (kinematic and dynamic) metrics and the arm
  required to reach a human's whole abdomen, "around (51°, 54°)".
- The Raven II's link angles as built: La12 = 75°, La23 = 52° (its control code,
  github.com/uw-biorobotics/raven2, include/raven/r2_kinematics.h; configs/raven2.yaml).
"""

from __future__ import annotations

CITATION = ("M. J. H. Lum, D. Warden, J. Rosen, M. N. Sinanan, B. Hannaford: Hybrid analysis "
            "of a spherical mechanism for a minimally invasive surgical robot (IOS Press, "
            "Medicine Meets Virtual Reality)")  # fmt: skip
KINEMATIC_OPTIMUM = (90.0, 90.0)
"""(α12, α23) in degrees: the optimum of the kinematic metrics (the abstract)."""
HYBRID_OPTIMUM = (51.0, 54.0)
"""(α12, α23) in degrees, "around": the hybrid metrics' optimum with full-abdomen reach."""
RAVEN_II = (75.0, 52.0)
"""(La12, La23) in degrees of the Raven II's control code (r2_kinematics.h)."""
DWS_VERTEX_DEG = 60.0
"""The full vertex angle of the dexterous-workspace cone (our default task: half-angle 30°)."""
