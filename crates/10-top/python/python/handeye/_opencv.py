"""Calls shaped like OpenCV's ``cv2.calibrateHandEye`` and ``cv2.calibrateRobotWorldHandEye``:
the same arguments in the same order and conventions, the same return values, so a user swaps
one call; the solve is handeye's (:func:`handeye.calibrate`), and so are the checks (in Rust,
the same as a YAML pose's).

OpenCV's names say ``a2b`` for the transform that maps points of ``a`` into ``b``, i.e.
``R_gripper2base, t_gripper2base`` is ``T_base_flange`` here and ``R_target2cam`` is
``T_camera_target``. Rotations are 3x3 matrices or rotation vectors (3,), (3, 1) or (1, 3)
(Rodrigues, radians, as OpenCV takes them; a rotation vector longer than 2π is refused as
degrees); translations are (3,), (3, 1) or (1, 3), in ``units`` (metres by default, or
``"mm"``: the answer is then in millimetres too); float32 or float64; lists, tuples or stacked
arrays. A rotation matrix within 1e-3 of orthonormal (float32 round-off, printed digits) is
projected onto the nearest rotation, as OpenCV's Rodrigues does; one farther off is refused
rather than silently "fixed".
"""

import numpy as np

from . import _handeye
from ._errors import InputError, warn_verdict

# The method numbers of OpenCV (cv2.CALIB_HAND_EYE_*, cv2.CALIB_ROBOT_WORLD_HAND_EYE_*).
CALIB_HAND_EYE_TSAI = 0
CALIB_HAND_EYE_PARK = 1
CALIB_HAND_EYE_HORAUD = 2
CALIB_HAND_EYE_ANDREFF = 3
CALIB_HAND_EYE_DANIILIDIS = 4
CALIB_ROBOT_WORLD_HAND_EYE_SHAH = 0
CALIB_ROBOT_WORLD_HAND_EYE_LI = 1

_HAND_EYE_METHODS = {0: "tsai", 1: "park", 2: "horaud", 3: "andreff", 4: "daniilidis"}
_ROBOT_WORLD_METHODS = {0: "closed_form", 1: "li"}
_HAND_EYE_NAMES = ("R_gripper2base", "t_gripper2base", "R_target2cam", "t_target2cam")
_ROBOT_WORLD_NAMES = ("R_base2gripper", "t_base2gripper", "R_world2cam", "t_world2cam")


def _method(method, table, name):
    if method is None:
        return "refined"
    if isinstance(method, str):
        return method
    try:
        return table[int(method)]
    except (KeyError, TypeError, ValueError):
        raise InputError(
            f"{name}: method {method!r}: expected one of OpenCV's numbers {sorted(table)} "
            f"or a handeye method name"
        ) from None


def _split(T):
    return np.array(T[:3, :3]), np.array(T[:3, 3:4])


def _inverse(T):
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def calibrateHandEye(
    R_gripper2base,
    t_gripper2base,
    R_target2cam,
    t_target2cam,
    R_cam2gripper=None,
    t_cam2gripper=None,
    method=None,
    *,
    units="m",
    verdict=True,
    return_calibration=False,
):
    """``cv2.calibrateHandEye`` with handeye's solver: returns ``(R_cam2gripper, t_cam2gripper)``
    (3x3 and 3x1 float64), i.e. ``T_flange_camera`` (eye-in-hand).

    ``method``: OpenCV's ``cv2.CALIB_HAND_EYE_*`` number (the method of the same name in
    handeye, which drops and names outliers as every method does) or a handeye method name;
    default (None) handeye's ``refined``. ``R_cam2gripper`` and ``t_cam2gripper`` are OpenCV's
    optional output arguments and are ignored. ``units``: ``"m"`` (default) or ``"mm"``, the unit
    of every translation given and of ``t_cam2gripper``. ``verdict`` (default True): judge the
    answer (one held-out solve per sample) and warn with :class:`CalibrationWarning` when the
    verdict is not GOOD; False skips both (the verdict is then computed when first read). For
    eye-to-hand pass ``R_base2gripper``/``t_base2gripper`` as OpenCV's documentation says: the
    result is then ``R_cam2base``/``t_cam2base`` (or use ``handeye.calibrate(...,
    setup="eye_to_hand")``). With ``return_calibration=True`` the full :class:`Calibration`
    (1-sigma, residuals, verdict) comes third.
    """
    calibration = _handeye.calibrate_rt(
        R_gripper2base,
        t_gripper2base,
        R_target2cam,
        t_target2cam,
        _HAND_EYE_NAMES,
        method=_method(method, _HAND_EYE_METHODS, "calibrateHandEye"),
        units=units,
    )
    if verdict:
        warn_verdict(calibration.verdict, stacklevel=2)
    R, t = _split(calibration.camera_mount)
    return (R, t, calibration) if return_calibration else (R, t)


def calibrateRobotWorldHandEye(
    R_world2cam,
    t_world2cam,
    R_base2gripper,
    t_base2gripper,
    R_base2world=None,
    t_base2world=None,
    R_gripper2cam=None,
    t_gripper2cam=None,
    method=None,
    *,
    units="m",
    verdict=True,
    return_calibration=False,
):
    """``cv2.calibrateRobotWorldHandEye`` with handeye's solver: returns ``(R_base2world,
    t_base2world, R_gripper2cam, t_gripper2cam)`` (3x3 and 3x1 float64), i.e. ``T_world_base``
    and ``T_camera_flange`` with world = the board (``T_base_target`` and ``T_flange_camera``
    inverted).

    ``method``: ``cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH`` (handeye's ``closed_form``) or ``_LI``
    (``li``), or a handeye method name; default (None) handeye's ``refined``. The four output
    arguments are OpenCV's optional outputs and are ignored. ``units`` and ``verdict`` as in
    :func:`calibrateHandEye`. With ``return_calibration=True`` the full :class:`Calibration`
    comes fifth.
    """
    calibration = _handeye.calibrate_rt(
        R_base2gripper,
        t_base2gripper,
        R_world2cam,
        t_world2cam,
        _ROBOT_WORLD_NAMES,
        method=_method(method, _ROBOT_WORLD_METHODS, "calibrateRobotWorldHandEye"),
        units=units,
        invert_flange=True,
    )
    if verdict:
        warn_verdict(calibration.verdict, stacklevel=2)
    R_bw, t_bw = _split(_inverse(calibration.target_mount))
    R_gc, t_gc = _split(_inverse(calibration.camera_mount))
    out = (R_bw, t_bw, R_gc, t_gc)
    return out + (calibration,) if return_calibration else out
