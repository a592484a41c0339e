"""Kernel layer shared by every study (SPEC §2): transforms, the frame kernel, conditioning."""

from designopt.kinematics.conditioning import cond, inv_cond, singular_values_sq
from designopt.kinematics.kernel import ET, SerialModel, dh_model, et_model
from designopt.kinematics.transforms import (
    dh_modified,
    dh_standard,
    rotx,
    roty,
    rotz,
    trans,
    transx,
    transy,
    transz,
)

__all__ = [
    "ET",
    "SerialModel",
    "cond",
    "dh_model",
    "dh_modified",
    "dh_standard",
    "et_model",
    "inv_cond",
    "rotx",
    "roty",
    "rotz",
    "singular_values_sq",
    "trans",
    "transx",
    "transy",
    "transz",
]
