"""Calls shaped like OpenCV's ``cv2.calibrateHandEye`` and ``cv2.calibrateRobotWorldHandEye``:
the same arguments in the same order and conventions, the same return values, so a user swaps
one call; the solve is handeye's (:func:`handeye.calibrate`).

OpenCV's names say ``a2b`` for the transform that maps points of ``a`` into ``b``, i.e.
``R_gripper2base, t_gripper2base`` is ``T_base_flange`` here and ``R_target2cam`` is
``T_camera_target``. Rotations are 3x3 matrices or rotation vectors (3,), (3, 1) or (1, 3)
(Rodrigues, as OpenCV takes them); translations are (3,), (3, 1) or (1, 3); float32 or float64;
lists, tuples or stacked arrays. Translations must be in metres (handeye refuses millimetres
with a clear error). A rotation matrix within 1e-3 of orthonormal (float32 round-off, printed
digits) is projected onto the nearest rotation, as OpenCV's Rodrigues does; one farther off is
refused rather than silently "fixed".
"""

import numpy as np

from ._errors import InputError

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

# A rotation matrix this far from orthonormal (Frobenius norm of RᵀR − I) is projected onto
# SO(3); farther is refused.
_PROJECT_TOLERANCE = 1e-3


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


def _rodrigues(rvec):
    theta = float(np.linalg.norm(rvec))
    if theta < 1e-12:
        return np.eye(3)
    k = rvec / theta
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(theta) * K + (1.0 - np.cos(theta)) * (K @ K)


def _rotation(value, name):
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise InputError(f"{name}: not an array of numbers: {error}") from None
    if a.shape == (3, 3):
        if not np.all(np.isfinite(a)):
            raise InputError(f"{name}: value is not finite")
        off = np.linalg.norm(a.T @ a - np.eye(3))
        if off > _PROJECT_TOLERANCE or np.linalg.det(a) <= 0.0:
            raise InputError(
                f"{name}: not a rotation matrix: ‖RᵀR − I‖ = {off:.3e}, det = "
                f"{np.linalg.det(a):.6f} (expected orthonormal with det +1)"
            )
        u, _, vt = np.linalg.svd(a)
        return u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    if a.size == 3 and a.ndim <= 2:
        v = a.reshape(3)
        if not np.all(np.isfinite(v)):
            raise InputError(f"{name}: value is not finite")
        return _rodrigues(v)
    raise InputError(
        f"{name}: expected a 3x3 rotation matrix or a rotation vector (3,), (3, 1) or (1, 3), "
        f"found shape {a.shape}"
    )


def _translation(value, name):
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise InputError(f"{name}: not an array of numbers: {error}") from None
    if a.size != 3 or a.ndim > 2:
        raise InputError(f"{name}: expected a translation (3,), (3, 1) or (1, 3), found shape {a.shape}")
    return a.reshape(3)


def _items(values, name):
    if isinstance(values, np.ndarray) and values.ndim >= 2:
        return list(values)
    try:
        return list(values)
    except TypeError:
        raise InputError(f"{name}: expected a list of arrays (one per pose)") from None


def _transforms(R, t, names):
    rs, ts = _items(R, names[0]), _items(t, names[1])
    if len(rs) != len(ts):
        raise InputError(f"{names[0]} has {len(rs)} entries but {names[1]} has {len(ts)}")
    out = np.zeros((len(rs), 4, 4))
    for i, (r, v) in enumerate(zip(rs, ts)):
        out[i, :3, :3] = _rotation(r, f"{names[0]}[{i}]")
        out[i, :3, 3] = _translation(v, f"{names[1]}[{i}]")
        out[i, 3, 3] = 1.0
    return out


def _split(T):
    return np.array(T[:3, :3], dtype=np.float64), np.array(T[:3, 3:4], dtype=np.float64)


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
    return_calibration=False,
):
    """``cv2.calibrateHandEye`` with handeye's solver: returns ``(R_cam2gripper, t_cam2gripper)``
    (3x3 and 3x1 float64), i.e. ``T_flange_camera`` (eye-in-hand).

    ``method``: OpenCV's ``cv2.CALIB_HAND_EYE_*`` number (the method of the same name in
    handeye) or a handeye method name; default (None) handeye's ``refined``. ``R_cam2gripper``
    and ``t_cam2gripper`` are OpenCV's optional output arguments and are ignored. For
    eye-to-hand pass ``R_base2gripper``/``t_base2gripper`` as OpenCV's documentation says: the
    result is then ``R_cam2base``/``t_cam2base`` (or use ``handeye.calibrate(...,
    setup="eye_to_hand")``). With ``return_calibration=True`` the full :class:`Calibration`
    (1-sigma, residuals, verdict) comes third.
    """
    from . import calibrate

    flange = _transforms(R_gripper2base, t_gripper2base, ("R_gripper2base", "t_gripper2base"))
    camera = _transforms(R_target2cam, t_target2cam, ("R_target2cam", "t_target2cam"))
    calibration = calibrate(
        flange,
        camera,
        "eye_in_hand",
        method=_method(method, _HAND_EYE_METHODS, "calibrateHandEye"),
    )
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
    return_calibration=False,
):
    """``cv2.calibrateRobotWorldHandEye`` with handeye's solver: returns ``(R_base2world,
    t_base2world, R_gripper2cam, t_gripper2cam)`` (3x3 and 3x1 float64), i.e. ``T_world_base``
    and ``T_camera_flange`` with world = the board (``T_base_target`` and ``T_flange_camera``
    inverted).

    ``method``: ``cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH`` (handeye's ``closed_form``) or ``_LI``
    (``li``), or a handeye method name; default (None) handeye's ``refined``. The four output
    arguments are OpenCV's optional outputs and are ignored. With ``return_calibration=True``
    the full :class:`Calibration` comes fifth.
    """
    from . import calibrate

    camera = _transforms(R_world2cam, t_world2cam, ("R_world2cam", "t_world2cam"))
    gripper_from_base = _transforms(R_base2gripper, t_base2gripper, ("R_base2gripper", "t_base2gripper"))
    flange = np.array([_inverse(T) for T in gripper_from_base]).reshape(-1, 4, 4)
    calibration = calibrate(
        flange,
        camera,
        "eye_in_hand",
        method=_method(method, _ROBOT_WORLD_METHODS, "calibrateRobotWorldHandEye"),
    )
    R_bw, t_bw = _split(_inverse(calibration.target_mount))
    R_gc, t_gc = _split(_inverse(calibration.camera_mount))
    out = (R_bw, t_bw, R_gc, t_gc)
    return out + (calibration,) if return_calibration else out
