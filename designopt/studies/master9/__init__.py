"""Study A: the 9-DOF haptic master of seed 000 (SPEC §3)."""
