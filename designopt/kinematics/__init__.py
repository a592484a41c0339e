"""Kernel layer shared by every study (SPEC §2): transforms, chains, Jacobians, conditioning."""

from designopt.kinematics.chain import ET, DHChain, ETChain
from designopt.kinematics.conditioning import (
    cond_2,
    cond_fro,
    det3,
    inv_cond,
    inv_cond_2,
    inv_cond_any,
    inv_cond_fro,
    inv_cond_fro3,
)
from designopt.kinematics.jacobian import geometric_jacobian, position_jacobian
from designopt.kinematics.kernel import SerialModel, dh_model, et_model
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
    "DHChain",
    "ET",
    "ETChain",
    "SerialModel",
    "cond_2",
    "cond_fro",
    "det3",
    "dh_model",
    "dh_modified",
    "dh_standard",
    "et_model",
    "geometric_jacobian",
    "inv_cond",
    "inv_cond_2",
    "inv_cond_any",
    "inv_cond_fro",
    "inv_cond_fro3",
    "position_jacobian",
    "rotx",
    "roty",
    "rotz",
    "trans",
    "transx",
    "transy",
    "transz",
]
