"""Type stubs of the handeye package (frames: ``T_a_b`` maps points of ``b`` into ``a``; 4x4
homogeneous matrices, metres unless a call is given ``units="mm"``; figures people read in
degrees and millimetres)."""

from os import PathLike
from pathlib import Path
from typing import Any, Callable, Dict, List, Literal, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Path = Union[str, "PathLike[str]"]
_Matrices = npt.ArrayLike  # (N, 4, 4) homogeneous transforms, metres (or the call's units)
_Units = Literal["m", "mm"]
_Mat4 = npt.NDArray[np.float64]  # (4, 4)

class HandeyeError(Exception):
    """Base of every handeye error."""

class InputError(HandeyeError, ValueError):
    """Bad input (shapes, NaN, non-rigid matrices, millimetres, a refused solve, a bad file)."""

    verdict: Optional[Verdict]
    """The REDO verdict of a refused solve, else None."""

class FileError(HandeyeError, OSError):
    """A file or folder that cannot be read or written."""

class CalibrationWarning(UserWarning):
    """An answer whose verdict is CHECK or REDO: the verdict's reason and next step."""

    verdict: Optional[Verdict]
    """The verdict that raised it."""

    def __init__(self, message: str, verdict: Optional[Verdict] = None) -> None: ...

class Verdict:
    """GOOD / CHECK / REDO with the one reason that decided it and the next action."""

    @property
    def level(self) -> str:
        """``"GOOD"``, ``"CHECK"`` or ``"REDO"``."""
    @property
    def basis(self) -> str:
        """What decided it (``held_out_error``, ``uncertainty``, ``refused``, ...)."""
    @property
    def reason(self) -> str:
        """The measured fact that decided it, with its numbers and threshold."""
    @property
    def next_action(self) -> str:
        """What to do next."""
    @property
    def accuracy(self) -> Dict[str, float]:
        """``{"translation_mm", "rotation_deg"}`` judged against."""
    @property
    def figures(self) -> Dict[str, Any]:
        """Held-out errors (mm, degrees), 1-sigma, residual RMS, rotation spread, poses."""
    @property
    def also(self) -> List[Dict[str, Any]]:
        """Further findings, worst first: ``{"level", "basis", "reason", "next_action"}``."""

class Calibration:
    """The answer of a solve."""

    @property
    def setup(self) -> str:
        """``"eye_in_hand"`` or ``"eye_to_hand"``."""
    @property
    def units(self) -> str:
        """``"m"`` or ``"mm"``: the unit of the transforms' translations (the call's ``units``)."""
    @property
    def camera_mount(self) -> _Mat4:
        """``T_flange_camera`` (eye-in-hand) or ``T_base_camera`` (eye-to-hand), 4x4, ``units``."""
    @property
    def target_mount(self) -> _Mat4:
        """``T_base_target`` (eye-in-hand) or ``T_flange_target`` (eye-to-hand), 4x4, ``units``."""
    @property
    def transforms(self) -> Dict[str, _Mat4]:
        """Both transforms by frame name, camera mount first."""
    @property
    def T_flange_camera(self) -> _Mat4:
        """Eye-in-hand camera mount (AttributeError for eye-to-hand), 4x4, ``units``."""
    @property
    def T_base_target(self) -> _Mat4:
        """Eye-in-hand target mount, 4x4, ``units``."""
    @property
    def T_base_camera(self) -> _Mat4:
        """Eye-to-hand camera mount, 4x4, ``units``."""
    @property
    def T_flange_target(self) -> _Mat4:
        """Eye-to-hand target mount, 4x4, ``units``."""
    @property
    def sigma(self) -> Optional[Dict[str, Dict[str, Any]]]:
        """1-sigma per transform: ``rotation_deg``, ``translation_mm`` (totals) and
        ``rotation_axes_deg``, ``translation_axes_mm`` (per axis of its first frame)."""
    @property
    def covariance(self) -> Optional[npt.NDArray[np.float64]]:
        """12x12: camera mount [rotation rad, translation in ``units``], target mount [same]."""
    @property
    def residuals(self) -> Dict[str, Any]:
        """Per sample ``rotation_deg``, ``translation_mm``, ``normalised`` (arrays, NaN for a
        dropped sample) and ``rotation_rms_deg``, ``rotation_max_deg``,
        ``translation_rms_mm``, ``translation_max_mm``."""
    @property
    def outliers(self) -> List[int]:
        """Indices of the samples flagged as outliers."""
    @property
    def dropped(self) -> List[int]:
        """Indices of the samples left out of the final solve."""
    @property
    def ids(self) -> List[Optional[str]]:
        """Sample ids."""
    @property
    def noise(self) -> Optional[Dict[str, Any]]:
        """Board-pose noise used: ``rotation_sigma_deg``, ``translation_sigma_mm`` (per axis)
        and where each came from (``estimated``, ``given``, ...)."""
    @property
    def notices(self) -> List[Dict[str, str]]:
        """``{"severity": "info" | "warning" | "error", "kind", "message"}``."""
    @property
    def solver(self) -> Dict[str, Any]:
        """``method``, ``iterations``, ``converged``, ``restarts``."""
    @property
    def reprojection(self) -> Optional[Dict[str, Any]]:
        """A session's reprojection-space summary (px), else None."""
    @property
    def verdict(self) -> Optional[Verdict]:
        """GOOD / CHECK / REDO (computed by the call, or with ``verdict=False`` on first read)."""
    def predict(self, T_base_flange: _Matrices) -> npt.NDArray[np.float64]:
        """The ``T_camera_target`` predicted for each ``T_base_flange``: (N, 4, 4), ``units``."""
    def summary(self) -> str:
        """The summary ``handeye solve`` prints."""
    def save(self, path: _Path) -> None:
        """Writes the result file ``handeye solve -o`` writes (metres, whatever ``units``)."""

def calibrate(
    T_base_flange: _Matrices,
    T_camera_target: _Matrices,
    setup: str = "eye_in_hand",
    *,
    units: _Units = "m",
    verdict: bool = True,
    method: str = "refined",
    rotation_sigma_deg: Optional[float] = None,
    translation_sigma_mm: Optional[float] = None,
    robust: str = "none",
    robust_scale: float = 3.0,
    keep_outliers: bool = False,
    warm_start: bool = False,
    ids: Optional[Sequence[str]] = None,
    weights: Optional[Sequence[float]] = None,
    view_sigmas: Optional[Any] = None,
    weigh_views: bool = True,
    accuracy_mm: float = 1.0,
    accuracy_deg: float = 0.1,
) -> Calibration:
    """Solves both unknown transforms from (N, 4, 4) pose pairs (as ``handeye solve``); warns
    with CalibrationWarning when the verdict is not GOOD."""

CALIB_HAND_EYE_TSAI: int
CALIB_HAND_EYE_PARK: int
CALIB_HAND_EYE_HORAUD: int
CALIB_HAND_EYE_ANDREFF: int
CALIB_HAND_EYE_DANIILIDIS: int
CALIB_ROBOT_WORLD_HAND_EYE_SHAH: int
CALIB_ROBOT_WORLD_HAND_EYE_LI: int

def calibrateHandEye(
    R_gripper2base: Any,
    t_gripper2base: Any,
    R_target2cam: Any,
    t_target2cam: Any,
    R_cam2gripper: Any = None,
    t_cam2gripper: Any = None,
    method: Union[int, str, None] = None,
    *,
    units: _Units = "m",
    verdict: bool = True,
    return_calibration: bool = False,
) -> Any:
    """``cv2.calibrateHandEye`` with handeye's solver: ``(R_cam2gripper (3, 3), t_cam2gripper (3, 1))``
    (plus the Calibration with ``return_calibration=True``)."""

def calibrateRobotWorldHandEye(
    R_world2cam: Any,
    t_world2cam: Any,
    R_base2gripper: Any,
    t_base2gripper: Any,
    R_base2world: Any = None,
    t_base2world: Any = None,
    R_gripper2cam: Any = None,
    t_gripper2cam: Any = None,
    method: Union[int, str, None] = None,
    *,
    units: _Units = "m",
    verdict: bool = True,
    return_calibration: bool = False,
) -> Any:
    """``cv2.calibrateRobotWorldHandEye`` with handeye's solver: ``(R_base2world, t_base2world,
    R_gripper2cam, t_gripper2cam)`` (plus the Calibration with ``return_calibration=True``)."""

class Board:
    """A calibration board: Kalibr aprilgrid, OpenCV ChArUco or chessboard."""

    @staticmethod
    def load(path: _Path) -> Board:
        """Reads a board YAML file."""
    @staticmethod
    def from_yaml(text: str) -> Board:
        """Parses board YAML text."""
    @staticmethod
    def aprilgrid(
        cols: int, rows: int, tag_size: float, tag_spacing: float, *, family: str = "tag36h11",
        first_id: int = 0, border_bits: int = 2,
    ) -> Board:
        """Kalibr aprilgrid: tag_size in m (black square), tag_spacing a fraction of it."""
    @staticmethod
    def charuco(
        squares_x: int, squares_y: int, square_length: float, marker_length: float,
        dictionary: str = "DICT_4X4_50",
    ) -> Board:
        """OpenCV ChArUco board, lengths in m."""
    @staticmethod
    def checkerboard(cols: int, rows: int, spacing: float) -> Board:
        """Chessboard of cols x rows inner corners, spacing in m."""
    def points(self) -> Tuple[npt.NDArray[np.uint32], npt.NDArray[np.uint8], npt.NDArray[np.float64]]:
        """Every board point: ids, subs, (N, 3) target-frame points in m."""

class Camera:
    """Camera intrinsics (pinhole in px, OpenCV pixel convention, plus distortion)."""

    def __init__(
        self, width: int, height: int, fx: float, fy: float, cx: float, cy: float,
        distortion: Optional[Sequence[float]] = None, model: str = "plumb_bob",
    ) -> None: ...
    @staticmethod
    def load(path: _Path) -> Camera:
        """Reads a ROS/OpenCV camera_info or Kalibr camchain YAML."""
    @property
    def matrix(self) -> npt.NDArray[np.float64]:
        """K (3x3, px)."""
    @property
    def distortion(self) -> List[float]:
        """Distortion coefficients (OpenCV's order for plumb_bob)."""
    @property
    def size(self) -> Tuple[int, int]:
        """(width, height), px."""

class Detection:
    """Corners found in one image, and the board pose when intrinsics were given."""

    ids: npt.NDArray[np.uint32]
    """(N,) tag id (aprilgrid) or inner-corner id (ChArUco, chessboard)."""
    subs: npt.NDArray[np.uint8]
    """(N,) corner of the tag 0..3 (aprilgrid), else 0."""
    corners: npt.NDArray[np.float64]
    """(N, 2) px, OpenCV convention."""
    object_points: npt.NDArray[np.float64]
    """(N, 3) the same corners on the board, target frame, m."""
    T_camera_target: Optional[_Mat4]
    """The board pose (4x4, m), or None."""
    rms_px: Optional[float]
    """RMS reprojection error of the pose, px."""
    pose_error: Optional[str]
    """Why there is no pose (or no corners)."""
    image_size: Tuple[int, int]
    """(width, height), px."""

def detect(image: npt.ArrayLike, board: Board, camera: Optional[Camera] = None, *, channels: str = "bgr") -> Detection:
    """Finds the board in a uint8 grey (H, W) or colour (H, W, 3) image."""

class Session:
    """A session folder written by ``handeye run``."""

    def __init__(self, path: _Path) -> None: ...
    @property
    def path(self) -> Path:
        """The session folder."""
    @property
    def config(self) -> Path:
        """The cell config the session was recorded with."""
    @property
    def setup(self) -> Optional[str]:
        """``eye_in_hand`` or ``eye_to_hand``; None for several cameras (each has its own)."""
    @property
    def cameras(self) -> Dict[str, "Session"]:
        """Several cameras: each camera's own session by name; empty for one camera."""
    @property
    def joint(self) -> Optional[Dict[str, Any]]:
        """Several cameras: the joint answer (``transforms``, ``sigma``, ``truth_error`` by
        name, ``verdicts`` by camera, the cell's ``verdict``); None for one camera or unsolved."""
    @property
    def samples(self) -> Dict[str, Any]:
        """``setup``, ``T_base_flange`` and ``T_camera_target`` (N, 4, 4) m, ``ids``, ``weights``,
        ``view_sigmas`` (N, 2): each view's ``(rotation_deg, translation_mm)``, NaN where unknown."""
    @property
    def result(self) -> Optional[Calibration]:
        """``result.yaml`` with its verdict, or None."""
    @property
    def verdict(self) -> Optional[Verdict]: ...
    @property
    def truth(self) -> Optional[Dict[str, _Mat4]]:
        """The simulator's ground truth by frame name, or None for a real cell."""
    def solve(self, space: Optional[str] = None, config: Optional[_Path] = None) -> Calibration:
        """Solves as ``handeye solve DIR --space SPACE`` (``pose`` or ``reprojection``); warns
        with CalibrationWarning when the verdict is not GOOD."""

def run(
    config: Optional[_Path] = None,
    out: Optional[_Path] = None,
    *,
    resume: Optional[_Path] = None,
    progress: Optional[Callable[[Dict[str, Any]], None]] = None,
    yes: bool = False,
    accept_changed: bool = False,
) -> Session:
    """Runs a cell as ``handeye run`` (progress as one dict per event; Ctrl-C keeps the samples),
    writes its report, and returns its session (``.path``, ``.result``, ``.verdict``; several
    cameras: ``.cameras``, ``.joint``)."""

def read_dataset(path: _Path) -> Dict[str, Any]:
    """A dataset file: ``setup``, ``T_base_flange``, ``T_camera_target`` (N, 4, 4), ``ids``,
    ``weights``, ``view_sigmas`` (N, 2: each view's ``(rotation_deg, translation_mm)``, NaN where
    the file records none)."""

def read_result(path: _Path) -> Calibration:
    """A result file as a Calibration with its verdict."""
