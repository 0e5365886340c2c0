"""handeye.detect against independent references: a ChArUco board drawn by OpenCV
(`CharucoBoard.generateImage`) and warped into a camera frame at a known pose — the corners
against OpenCV's own CharucoDetector on the same frame, the board pose against the truth — and
the simulated cell's recorded frames, whose board poses the CLI recorded (`samples.yaml`)."""

import numpy as np
import pytest

import handeye
from conftest import REPO
from synth import record_matrix, transform

W, H = 1280, 720
K = np.array([[900.0, 0.0, 640.0], [0.0, 900.0, 360.0], [0.0, 0.0, 1.0]])
SQUARES_X, SQUARES_Y, SQUARE, MARKER = 7, 5, 0.04, 0.03
PX_PER_SQUARE = 120


def render(cv2, cam_from_cvboard):
    """The OpenCV board image warped into a W x H frame seen from `cam_from_cvboard` (OpenCV's
    board frame: origin top-left, x right, y down on the print)."""
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    board = cv2.aruco.CharucoBoard((SQUARES_X, SQUARES_Y), SQUARE, MARKER, dictionary)
    size = (SQUARES_X * PX_PER_SQUARE, SQUARES_Y * PX_PER_SQUARE)
    image = board.generateImage(size, marginSize=0, borderBits=1)
    s = PX_PER_SQUARE / SQUARE  # board pixels per metre
    # Board pixel (u, v), centres at integers, to board metres; then the plane's homography.
    A = np.array([[1 / s, 0, 0.5 / s], [0, 1 / s, 0.5 / s], [0, 0, 1]])
    Rt = cam_from_cvboard[:3, [0, 1, 3]]
    Hm = K @ Rt @ A
    # White paper around the board: warp an inverted image and invert back.
    frame = 255 - cv2.warpPerspective(255 - image, Hm, (W, H), flags=cv2.INTER_AREA)
    return cv2.GaussianBlur(frame, (0, 0), 0.6), board


def test_charuco_corners_match_opencv_and_the_pose_matches_the_truth(cv2):
    cam_from_cvboard = transform([0.25, -0.3, 0.1], [-0.12, -0.08, 0.55])
    frame, cv_board = render(cv2, cam_from_cvboard)
    board = handeye.Board.charuco(SQUARES_X, SQUARES_Y, SQUARE, MARKER, "DICT_4X4_50")
    camera = handeye.Camera(W, H, K[0, 0], K[1, 1], K[0, 2], K[1, 2])
    found = handeye.detect(frame, board, camera)
    assert found.pose_error is None and len(found.ids) >= 20

    # OpenCV's detector on the same frame finds the same ids; each detector's corners against
    # the truth (the board's corners projected from the pose the frame was drawn from).
    corners, ids, _, _ = cv2.aruco.CharucoDetector(cv_board).detectBoard(frame)
    theirs = {int(i): c.ravel() for i, c in zip(ids.ravel(), corners)}
    common = [i for i in found.ids.tolist() if i in theirs]
    assert len(common) >= 0.9 * len(found.ids)
    cv_points = cv_board.getChessboardCorners()

    def truth_px(i):
        p = cam_from_cvboard @ np.append(cv_points[i], 1.0)
        return (K @ (p[:3] / p[2]))[:2]

    ours = [np.linalg.norm(found.corners[k] - truth_px(i)) for k, i in enumerate(found.ids.tolist())]
    opencv = [np.linalg.norm(theirs[i] - truth_px(i)) for i in common]
    print(f"\ncorner error vs truth, median px: handeye {np.median(ours):.3f}, OpenCV {np.median(opencv):.3f}")
    assert np.median(ours) < 0.2 and max(ours) < 0.6, ours
    assert np.median(ours) <= 1.5 * np.median(opencv) + 0.02

    # The board points: OpenCV's chessboard corners in its frame are handeye's target points
    # through one rigid map (origin bottom-left, y up, z out of the print).
    height = (SQUARES_Y) * SQUARE
    cvboard_from_target = np.array([[1, 0, 0, 0], [0, -1, 0, height], [0, 0, -1, 0], [0, 0, 0, 1.0]])
    for k, i in enumerate(found.ids.tolist()):
        p = cvboard_from_target @ np.append(found.object_points[k], 1.0)
        assert np.allclose(p[:3], cv_points[i], atol=1e-9)

    # The pose against the truth the frame was drawn from.
    truth = cam_from_cvboard @ cvboard_from_target
    T = found.T_camera_target
    angle = np.degrees(np.arccos(np.clip((np.trace(T[:3, :3] @ truth[:3, :3].T) - 1) / 2, -1, 1)))
    assert angle < 0.1 and np.linalg.norm(T[:3, 3] - truth[:3, 3]) < 1e-3, (angle, T[:3, 3] - truth[:3, 3])
    assert found.rms_px < 0.3

    # Colour frames (OpenCV's BGR) give the same corners; no camera gives corners, no pose.
    colour = handeye.detect(cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR), board)
    assert np.allclose(colour.corners, found.corners) and colour.T_camera_target is None


def test_no_board_in_view_is_an_empty_detection_with_the_reason():
    board = handeye.Board.aprilgrid(6, 6, 0.04, 0.25)
    found = handeye.detect(np.full((480, 640), 200, np.uint8), board)
    assert len(found.ids) == 0 and found.corners.shape == (0, 2)
    assert "no tag of the board found" in found.pose_error


def test_detect_on_the_recorded_frames_gives_the_cli_board_poses(cv2, yaml, sim_session):
    """The simulated cell's frames: the board poses handeye.detect estimates are the ones
    `handeye run` recorded in samples.yaml (same detector, same PnP) to 1e-9."""
    session = handeye.Session(sim_session)
    config = yaml.safe_load(session.config.read_text())
    base = session.config.parent
    board = handeye.Board.load(base / config["target"])
    camera = handeye.Camera.load(base / config["intrinsics"])
    samples = session.samples
    checked = 0
    for i, sample_id in enumerate(samples["ids"][:4]):
        index = int(sample_id.split("-")[1])
        record = yaml.safe_load((sim_session / "poses" / f"{index:03d}.yaml").read_text())
        frame = cv2.imread(str(sim_session / record["frame"]), cv2.IMREAD_GRAYSCALE)
        found = handeye.detect(frame, board, camera)
        assert np.allclose(found.T_camera_target, samples["T_camera_target"][i], atol=1e-9, rtol=0)
        checked += 1
    assert checked == 4
