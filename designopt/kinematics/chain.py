"""Transitional: ``ET`` now lives in ``designopt.kinematics.kernel`` (the frame kernel is the
only chain type; the 4×4-product chains are test references, tests/kinref.py). This module
only re-exports ``ET`` for the one remaining importer (the da Vinci study's mechanism);
delete it once that imports ``from designopt.kinematics import ET``."""

from designopt.kinematics.kernel import ET

__all__ = ["ET"]
