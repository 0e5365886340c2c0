"""handeye: hand-eye and base-world calibration of robot cells, from Python.

The solver of the ``handeye`` tool (Hirsh-DeSouza-Kak ``A = X·B·Y``, refined jointly, with the
board-pose noise estimated, outliers dropped and named, a 1-sigma per transform and a
GOOD / CHECK / REDO verdict), its board detectors and its session folders, with numpy in and out.

Frames: ``T_a_b`` is the 4x4 rigid transform that maps points of frame ``b`` into frame ``a``
(``p_a = T_a_b @ p_b``), translations in metres. ``T_base_flange`` is the flange pose the robot
reports; ``T_camera_target`` the board pose PnP reports (camera optical frame: x right, y down,
z forward).

- eye-in-hand (camera on the flange): unknowns ``T_flange_camera`` and ``T_base_target``;
- eye-to-hand (camera fixed, board on the flange): ``T_base_camera`` and ``T_flange_target``.

Errors are :class:`InputError` (a ``ValueError``) for bad input and :class:`FileError` (an
``OSError``) for files, both :class:`HandeyeError`, with the CLI's messages.
"""

from typing import Optional, Sequence

import numpy as np

from ._errors import FileError, HandeyeError, InputError
from . import _handeye
from ._handeye import (
    Board,
    Calibration,
    Camera,
    Detection,
    Session,
    Verdict,
    __version__,
    read_dataset,
    read_result,
)
from ._opencv import (
    CALIB_HAND_EYE_ANDREFF,
    CALIB_HAND_EYE_DANIILIDIS,
    CALIB_HAND_EYE_HORAUD,
    CALIB_HAND_EYE_PARK,
    CALIB_HAND_EYE_TSAI,
    CALIB_ROBOT_WORLD_HAND_EYE_LI,
    CALIB_ROBOT_WORLD_HAND_EYE_SHAH,
    calibrateHandEye,
    calibrateRobotWorldHandEye,
)

__all__ = [
    "Board",
    "CALIB_HAND_EYE_ANDREFF",
    "CALIB_HAND_EYE_DANIILIDIS",
    "CALIB_HAND_EYE_HORAUD",
    "CALIB_HAND_EYE_PARK",
    "CALIB_HAND_EYE_TSAI",
    "CALIB_ROBOT_WORLD_HAND_EYE_LI",
    "CALIB_ROBOT_WORLD_HAND_EYE_SHAH",
    "Calibration",
    "Camera",
    "Detection",
    "FileError",
    "HandeyeError",
    "InputError",
    "Session",
    "Verdict",
    "calibrate",
    "calibrateHandEye",
    "calibrateRobotWorldHandEye",
    "detect",
    "read_dataset",
    "read_result",
]


def _poses(value, name):
    """``value`` as a float64 array (shape checked by the solver side, which names it)."""
    if isinstance(value, np.ndarray) and value.dtype == np.float64:
        return value
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise InputError(
            f"{name} must be an (N, 4, 4) array of homogeneous transforms (metres): {error}"
        ) from None


def calibrate(
    T_base_flange,
    T_camera_target,
    setup: str = "eye_in_hand",
    *,
    method: str = "refined",
    rotation_sigma_deg: Optional[float] = None,
    translation_sigma_mm: Optional[float] = None,
    robust: str = "none",
    robust_scale: float = 3.0,
    keep_outliers: bool = False,
    warm_start: bool = False,
    ids: Optional[Sequence[str]] = None,
    weights: Optional[Sequence[float]] = None,
    accuracy_mm: float = 1.0,
    accuracy_deg: float = 0.1,
) -> Calibration:
    """Solves for both unknown transforms of a cell from its pose pairs, as ``handeye solve``.

    Args:
        T_base_flange: ``(N, 4, 4)`` flange poses in the robot base frame, metres.
        T_camera_target: ``(N, 4, 4)`` board poses in the camera optical frame, metres.
        setup: ``"eye_in_hand"`` (unknowns ``T_flange_camera``, ``T_base_target``) or
            ``"eye_to_hand"`` (``T_base_camera``, ``T_flange_target``).
        method: ``refined`` (default: joint weighted least squares from the iterative start),
            ``iterative`` (the paper), ``tsai``, ``park``, ``horaud``, ``andreff``,
            ``daniilidis``, ``closed_form`` (Shah), ``li``.
        rotation_sigma_deg: per-axis rotation noise of ``T_camera_target``, degrees; used as
            given (default: estimated from the residuals).
        translation_sigma_mm: per-axis translation noise of ``T_camera_target``, mm; used as
            given (default: estimated).
        robust: robust loss of the refinement: ``none``, ``huber``, ``cauchy``.
        robust_scale: scale of the robust loss, sigmas.
        keep_outliers: fit every sample and only flag outliers (default: outliers are left out
            of the final fit, each named).
        warm_start: start the iterative method from the closed form.
        ids: a name per sample (carried into messages and the result file).
        weights: a relative weight (> 0) per sample.
        accuracy_mm, accuracy_deg: the accuracy the verdict judges against.

    Returns:
        A :class:`Calibration`: the two transforms (4x4, metres), their 1-sigma (degrees, mm),
        the residuals, notices, and ``verdict`` (GOOD / CHECK / REDO with its reason; computed
        when first read, by one held-out solve per sample).

    Raises:
        InputError: wrong shapes, NaN, a matrix that is not rigid, translations in millimetres,
            or a refused solve (too few poses, rotations about one axis, ...): the CLI's message;
            a refused solve's exception has the REDO verdict as ``verdict``.
    """
    return _handeye.calibrate(
        _poses(T_base_flange, "T_base_flange"),
        _poses(T_camera_target, "T_camera_target"),
        setup,
        method=method,
        rotation_sigma_deg=rotation_sigma_deg,
        translation_sigma_mm=translation_sigma_mm,
        robust=robust,
        robust_scale=robust_scale,
        keep_outliers=keep_outliers,
        warm_start=warm_start,
        ids=None if ids is None else [str(i) for i in ids],
        weights=None if weights is None else [float(w) for w in weights],
        accuracy_mm=accuracy_mm,
        accuracy_deg=accuracy_deg,
    )


def detect(image, board: Board, camera: Optional[Camera] = None, *, channels: str = "bgr") -> Detection:
    """Finds ``board`` in ``image`` and, with ``camera``, its pose ``T_camera_target``.

    Args:
        image: ``(H, W)`` uint8 grey, or ``(H, W, 3)`` uint8 colour (``channels`` order: ``bgr``
            as ``cv2.imread`` gives, or ``rgb``).
        board: a :class:`Board` (``Board.load(path)``, ``Board.aprilgrid(...)``, ...).
        camera: the intrinsics (:class:`Camera`) for the board pose; without it only corners.

    Returns:
        A :class:`Detection`: ``ids``, ``subs``, ``corners`` (N, 2) px, ``object_points``
        (N, 3) m in the target frame, ``T_camera_target`` (4x4, m) and ``rms_px`` when the pose
        was estimated, else ``pose_error`` saying why (a board not found gives no corners and
        the reason there).

    Raises:
        InputError: an image that is not 8-bit grey or colour, or too small for the detector.
    """
    return _handeye.detect(image, board, camera, channels=channels)
