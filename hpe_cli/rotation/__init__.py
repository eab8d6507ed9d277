"""Pure-numpy rotation mathematics: systems, Euler angles (both solutions), distances."""

from .check import ROTATION_TOL, check_rotation, rotation_mask, rotation_reasons
from .convert import Conversion, canonical_to_labels, convert_angles, convert_matrices
from .distances import angle_diff_deg, frobenius, geodesic_deg
from .elemental import rx, ry, rz
from .euler import euler_to_matrix, matrix_to_euler, wrap_180, wrap_pi
from .systems import (
    GIMBAL_TOL,
    ROLES,
    RotationSystem,
    SystemError_,
    Turn,
    builtin_systems,
    get_system,
    load_system,
    system_from_dict,
    system_names,
)

__all__ = [
    "ROTATION_TOL",
    "check_rotation",
    "rotation_mask",
    "rotation_reasons",
    "angle_diff_deg",
    "frobenius",
    "geodesic_deg",
    "rx",
    "ry",
    "rz",
    "euler_to_matrix",
    "matrix_to_euler",
    "wrap_180",
    "wrap_pi",
    "GIMBAL_TOL",
    "ROLES",
    "RotationSystem",
    "SystemError_",
    "Turn",
    "builtin_systems",
    "get_system",
    "load_system",
    "system_from_dict",
    "system_names",
    "Conversion",
    "convert_angles",
    "convert_matrices",
    "canonical_to_labels",
]
