"""handeye: hand-eye and base-world calibration of robot cells, from Python.

The solver of the ``handeye`` tool (Hirsh-DeSouza-Kak ``A = X·B·Y``, refined jointly, with the
board-pose noise estimated, outliers dropped and named, a 1-sigma per transform and a
GOOD / CHECK / REDO verdict), its board detectors and its session folders, with numpy in and out.

Frames: ``T_a_b`` is the 4x4 rigid transform that maps points of frame ``b`` into frame ``a``
(``p_a = T_a_b @ p_b``), translations in metres (or millimetres where a call is given
``units="mm"``). ``T_base_flange`` is the flange pose the robot
reports; ``T_camera_target`` the board pose PnP reports (camera optical frame: x right, y down,
z forward).

- eye-in-hand (camera on the flange): unknowns ``T_flange_camera`` and ``T_base_target``;
- eye-to-hand (camera fixed, board on the flange): ``T_base_camera`` and ``T_flange_target``.

Errors are :class:`InputError` (a ``ValueError``) for bad input and :class:`FileError` (an
``OSError``) for files, both :class:`HandeyeError`, with the CLI's messages. An answer whose
verdict is CHECK or REDO comes with a :class:`CalibrationWarning` (a ``UserWarning``).
"""

import math as _math

from ._errors import CalibrationWarning, FileError, HandeyeError, InputError
from ._errors import warn_verdict as _warn_verdict
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
    "CalibrationWarning",
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
    "run",
]


def _wrong_call(positional):
    return TypeError(
        f"calibrate(T_base_flange, T_camera_target, setup=\"eye_in_hand\") was given {positional} "
        "positional arguments: it takes two (N, 4, 4) stacks of homogeneous transforms and the "
        "setup name; for the rotation and translation lists of cv2.calibrateHandEye call "
        "handeye.calibrateHandEye(R_gripper2base, t_gripper2base, R_target2cam, t_target2cam) "
        "(rotations 3x3 or rotation vectors (3,), translations (3,) or (3, 1), one per pose)"
    )


def _view_sigmas(rows):
    """``view_sigmas`` as the extension takes them: per sample ``(rotation_deg,
    translation_mm)`` or ``None`` (given as ``None`` or a row of NaN); the figures are checked in
    Rust."""
    out = []
    for i, row in enumerate(rows):
        if row is None:
            out.append(None)
            continue
        try:
            rotation, translation = (float(v) for v in row)
        except (TypeError, ValueError):
            raise InputError(
                f"view_sigmas[{i}] = {row!r}: expected (rotation_deg, translation_mm), or None "
                "for a view of unknown precision"
            ) from None
        unknown = _math.isnan(rotation) and _math.isnan(translation)
        out.append(None if unknown else (rotation, translation))
    return out


def calibrate(
    T_base_flange,
    T_camera_target,
    setup="eye_in_hand",
    *more,
    units="m",
    verdict=True,
    method="refined",
    rotation_sigma_deg=None,
    translation_sigma_mm=None,
    robust="none",
    robust_scale=3.0,
    keep_outliers=False,
    warm_start=False,
    ids=None,
    weights=None,
    view_sigmas=None,
    weigh_views=True,
    accuracy_mm=1.0,
    accuracy_deg=0.1,
):
    """Solves for both unknown transforms of a cell from its pose pairs, as ``handeye solve``.

    Args:
        T_base_flange: ``(N, 4, 4)`` flange poses in the robot base frame (translations in
            ``units``).
        T_camera_target: ``(N, 4, 4)`` board poses in the camera optical frame (``units``).
        setup: ``"eye_in_hand"`` (unknowns ``T_flange_camera``, ``T_base_target``) or
            ``"eye_to_hand"`` (``T_base_camera``, ``T_flange_target``).
        units: ``"m"`` (default) or ``"mm"``: the unit of every translation given, and of the
            answer's transforms (``cal.units``); robot and camera in the same unit (a mix is
            refused by the solver's units check).
        verdict: judge the answer now (one held-out solve per sample) and warn with
            :class:`CalibrationWarning` when the verdict is not GOOD (default). ``False`` skips
            both: the verdict is computed when first read and never warns (the behaviour before
            the warning).
        method: ``refined`` (default: joint weighted least squares from the iterative start),
            ``iterative`` (the paper), ``tsai``, ``park``, ``horaud``, ``andreff``,
            ``daniilidis``, ``closed_form`` (Shah), ``li``. Every method drops and names
            outliers the same way.
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
        view_sigmas: how precisely each view fixed its board pose, ``(rotation_deg,
            translation_mm)`` per sample (the 1-sigma of its ``T_camera_target``, e.g. from the
            pose estimate's covariance; ``read_dataset``'s and ``Session.samples``'
            ``view_sigmas``). Each sample is weighed by it against the typical view's, as
            ``handeye solve`` weighs a dataset that records them; ``None`` (or a row of NaN)
            for a view of unknown precision, which counts as a typical one.
        weigh_views: ``False`` takes every view as equally good (``handeye solve
            --every-view-alike``).
        accuracy_mm, accuracy_deg: the accuracy the verdict judges against.

    Returns:
        A :class:`Calibration`: the two transforms (4x4, translations in ``units``), their
        1-sigma (degrees, mm), the residuals, notices, and ``verdict`` (GOOD / CHECK / REDO with
        its reason).

    Raises:
        InputError: wrong shapes (the message names :func:`calibrateHandEye` for rotations and
            translations given apart), NaN, a matrix that is not rigid, translations in
            millimetres given as metres, or a refused solve (too few poses, rotations about one
            axis, ...): the CLI's message; a refused solve's exception has the REDO verdict as
            ``verdict``.
        TypeError: more than three positional arguments, or a setup that is not a name (the
            four lists of ``cv2.calibrateHandEye``): the message names :func:`calibrateHandEye`.

    Warns:
        CalibrationWarning: the verdict is CHECK or REDO (its reason and next step).
    """
    if more or not isinstance(setup, str):
        raise _wrong_call(3 + len(more))
    calibration = _handeye.calibrate(
        T_base_flange,
        T_camera_target,
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
        view_sigmas=None if view_sigmas is None else _view_sigmas(view_sigmas),
        weigh_views=bool(weigh_views),
        accuracy_mm=accuracy_mm,
        accuracy_deg=accuracy_deg,
        units=units,
    )
    if verdict:
        _warn_verdict(calibration.verdict, stacklevel=2)
    return calibration


def run(config=None, out=None, *, resume=None, progress=None, yes=False, accept_changed=False):
    """Runs a cell as ``handeye run`` does (the same library code: plan check, hardware, session
    loop, solve) and returns its :class:`Session` (``.path``, ``.result``, ``.verdict``,
    ``.samples``, ``.truth`` for a simulated cell).

    Args:
        config: the cell config (``configs/sim-cell.yaml``); on resume, overrides the session's.
        out: the new session folder (default ``sessions/<UTC start time>``, as the CLI).
        resume: continue the interrupted session in this folder instead (``handeye run
            --resume``).
        progress: called with one dict per event, ``{"event": ..., ...}``: ``plan_checked``
            (``report``), ``note`` (``message``), ``session_folder`` (``path``), ``started``
            (``poses``), ``moving`` (``plan_index``, ``T_base_flange``), ``recorded``
            (``plan_index``, ``camera``, ``reprojection_rms_px``, ``tags``, ``rejected``,
            ``will_retry``), ``camera_lost``, ``ended``. An exception it raises stops the run
            as Ctrl-C does.
        yes: a real robot may move without asking (``--yes``); without it a real arm is
            refused (a simulated cell needs no confirmation).
        accept_changed: resume even though input files changed (``--accept-changed``).

    Ctrl-C (or ``KeyboardInterrupt`` from ``progress``) stops the arm and ends the run with every
    sample recorded so far kept, as the CLI does: ``KeyboardInterrupt`` is raised with the
    session folder in its message and as ``session_folder``; ``run(resume=...)`` continues it.

    Raises:
        InputError, FileError: the run could not start or finish (the CLI's message).

    Warns:
        CalibrationWarning: the verdict is CHECK or REDO (its reason and next step).
    """
    session = _handeye.run(
        config, out, resume=resume, progress=progress, yes=yes, accept_changed=accept_changed
    )
    _warn_verdict(session.verdict, stacklevel=2)
    return session


def detect(image, board, camera=None, *, channels="bgr"):
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
