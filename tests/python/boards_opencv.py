#!/usr/bin/env python3
"""Camera frames of a ChArUco board and a chessboard rendered by OpenCV, and OpenCV's own figures.

Independent of handeye: the ChArUco board image comes from OpenCV's
`cv2.aruco.CharucoBoard(...).generateImage`, the chessboard is drawn here with numpy, and each is
warped into 1280x720 camera frames at known poses (0.45-0.8 m, tilted, plumb_bob distortion,
blur, shading, sensor noise) by exact ray casting with 3x3 supersampling. OpenCV then detects
the same frames (CharucoDetector; findChessboardCornersSB and findChessboardCorners +
cornerSubPix) and solves solvePnP, and the script writes its figures for tests/it/boards.rs:

    OUT/frames.json   camera, boards, ground-truth poses, visible corner ids and OpenCV's results
    OUT/charuco_NN.png, OUT/chessboard_NN.png
    OUT/charuco_board.png  the board as generateImage draws it (for the renderer's test)

Poses are `T_camera_board` in OpenCV's board frame (origin at the board's top-left chessboard
corner, x right, y down on the print, z into the board). Relative camera motion between two
frames does not depend on the board frame, so handeye's figures in its own target frame are
compared with these directly.

Usage: boards_opencv.py OUT_DIR
"""

import json
import sys
from pathlib import Path

import cv2
import numpy as np

W, H = 1280, 720
K = np.array([[910.0, 0.0, 641.3], [0.0, 905.0, 358.7], [0.0, 0.0, 1.0]])
DIST = np.array([-0.11, 0.07, 0.0006, -0.0004, -0.012])  # plumb_bob k1 k2 p1 p2 k3
SUPER = 3  # supersampling factor
NOISE_SIGMA = 2.0  # grey levels
BLUR_SIGMA = 0.6  # px (lens/sensor blur)
FRAMES = 8

CHARUCO = dict(squaresX=9, squaresY=6, squareLength=0.035, markerLength=0.026,
               dictionary="DICT_5X5_100")
CHESS = dict(squaresX=10, squaresY=7, squareLength=0.03)  # 9x6 inner corners
PX_PER_SQUARE = 240


def normalised_rays():
    """Undistorted normalised image coordinates of every supersampled pixel centre."""
    xs = (np.arange(W * SUPER) + 0.5) / SUPER - 0.5
    ys = (np.arange(H * SUPER) + 0.5) / SUPER - 0.5
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1).reshape(-1, 1, 2)
    und = cv2.undistortPointsIter(pts, K, DIST, None, None,
                                  (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10))
    return und.reshape(H * SUPER, W * SUPER, 2)


def look_at(rng, centre, distance, tilt_max_deg, offset):
    """`T_camera_board` of a camera `distance` from a point near `centre`, looking at it."""
    ax, ay = np.radians(rng.uniform(-tilt_max_deg, tilt_max_deg, size=2))
    # Direction from the board towards the camera: -z (out of the printed face) tilted.
    d = np.array([np.sin(ay) * np.cos(ax), np.sin(ax), -np.cos(ay) * np.cos(ax)])
    target = centre + np.array([offset[0], offset[1], 0.0])
    position = target + distance * d
    z = (target - position) / np.linalg.norm(target - position)
    y_hint = np.array([0.0, 1.0, 0.0])  # board +y (down on the print) appears down
    x = np.cross(y_hint, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    roll = np.radians(rng.uniform(-25, 25))
    c, s = np.cos(roll), np.sin(roll)
    x, y = c * x + s * y, -s * x + c * y
    board_from_camera = np.eye(4)
    board_from_camera[:3, 0], board_from_camera[:3, 1], board_from_camera[:3, 2] = x, y, z
    board_from_camera[:3, 3] = position
    return np.linalg.inv(board_from_camera)


def render(rays, board_img, margin_px, ppm, cam_from_board, rng):
    """Ray-cast the board image (`ppm` px per metre, board origin at `margin_px`) into a frame."""
    board_from_cam = np.linalg.inv(cam_from_board)
    r, t = board_from_cam[:3, :3], board_from_cam[:3, 3]
    dx = r[0, 0] * rays[..., 0] + r[0, 1] * rays[..., 1] + r[0, 2]
    dy = r[1, 0] * rays[..., 0] + r[1, 1] * rays[..., 1] + r[1, 2]
    dz = r[2, 0] * rays[..., 0] + r[2, 1] * rays[..., 1] + r[2, 2]
    s = -t[2] / dz
    bx = t[0] + s * dx
    by = t[1] + s * dy
    # Continuous board-image coordinate with pixel centres at integers.
    map_x = (margin_px + bx * ppm - 0.5).astype(np.float32)
    map_y = (margin_px + by * ppm - 0.5).astype(np.float32)
    hi = cv2.remap(board_img, map_x, map_y, cv2.INTER_LINEAR,
                   borderMode=cv2.BORDER_CONSTANT, borderValue=70)
    hi[s <= 0] = 70
    img = cv2.resize(hi.astype(np.float32), (W, H), interpolation=cv2.INTER_AREA)
    # Print contrast, a lighting gradient, blur and sensor noise.
    img = 25.0 + img * (210.0 / 255.0)
    gx = np.linspace(0.8, 1.05, W)[None, :]
    gy = np.linspace(1.0, 0.9, H)[:, None]
    img = img * gx * gy
    img = cv2.GaussianBlur(img, (0, 0), BLUR_SIGMA)
    img += rng.normal(0.0, NOISE_SIGMA, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def project(points, cam_from_board):
    rvec, _ = cv2.Rodrigues(cam_from_board[:3, :3])
    px, _ = cv2.projectPoints(points.astype(np.float64), rvec, cam_from_board[:3, 3], K, DIST)
    return px.reshape(-1, 2)


def inside(px, margin):
    return (px[:, 0] >= margin) & (px[:, 0] <= W - 1 - margin) & \
           (px[:, 1] >= margin) & (px[:, 1] <= H - 1 - margin)


def pose_from_pnp(obj, img):
    ok, rvec, tvec = cv2.solvePnP(obj.astype(np.float64), img.astype(np.float64), K, DIST,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        return None
    rvec, tvec = cv2.solvePnPRefineLM(obj.astype(np.float64), img.astype(np.float64), K, DIST,
                                      rvec, tvec)
    pose = np.eye(4)
    pose[:3, :3] = cv2.Rodrigues(rvec)[0]
    pose[:3, 3] = tvec.ravel()
    return pose


def relative_motion_errors(truth, estimates):
    """Median rotation (deg) and translation (mm) error of camera motion over all frame pairs."""
    rot, trans = [], []
    n = len(truth)
    for i in range(n):
        for j in range(i + 1, n):
            if estimates[i] is None or estimates[j] is None:
                continue
            true_rel = truth[i] @ np.linalg.inv(truth[j])
            est_rel = estimates[i] @ np.linalg.inv(estimates[j])
            delta = np.linalg.inv(est_rel) @ true_rel
            angle = np.degrees(np.arccos(np.clip((np.trace(delta[:3, :3]) - 1) / 2, -1, 1)))
            rot.append(angle)
            trans.append(1e3 * np.linalg.norm(true_rel[:3, 3] - est_rel[:3, 3]))
    return float(np.median(rot)), float(np.median(trans)), len(rot)


def charuco_frames(out, rays, rng):
    c = CHARUCO
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, c["dictionary"]))
    board = cv2.aruco.CharucoBoard((c["squaresX"], c["squaresY"]), c["squareLength"],
                                   c["markerLength"], dictionary)
    margin = PX_PER_SQUARE
    size = (c["squaresX"] * PX_PER_SQUARE + 2 * margin, c["squaresY"] * PX_PER_SQUARE + 2 * margin)
    board_img = board.generateImage(size, marginSize=margin, borderBits=1)
    cv2.imwrite(str(out / "charuco_board.png"), board_img)
    ppm = PX_PER_SQUARE / c["squareLength"]
    corners3d = board.getChessboardCorners()  # id -> (x, y, 0), OpenCV board frame
    sq = c["squareLength"]
    centre = np.array([c["squaresX"] * sq / 2, c["squaresY"] * sq / 2, 0.0])
    detector = cv2.aruco.CharucoDetector(board)
    frames, truth, estimates = [], [], []
    i = 0
    while len(frames) < FRAMES:
        partial = len(frames) >= FRAMES - 2  # the last two views see part of the board
        offset = rng.uniform(-0.02, 0.02, size=2) + (np.array([0.12, 0.05]) if partial else 0)
        pose = look_at(rng, centre, rng.uniform(0.45, 0.8), 35, offset)
        px = project(corners3d, pose)
        # A corner is visible when the 2x2 squares around it are in the image.
        visible = []
        for k, p in enumerate(corners3d):
            block = np.array([[p[0] + dx * sq, p[1] + dy * sq, 0.0]
                              for dx in (-1, 0, 1) for dy in (-1, 0, 1)])
            if inside(project(block, pose), 3).all():
                visible.append(k)
        if partial:
            if not (10 <= len(visible) < len(corners3d) - 8):
                continue
        elif not inside(px, 40).all():
            continue
        img = render(rays, board_img, margin, ppm, pose, rng)
        name = f"charuco_{i:02d}.png"
        cv2.imwrite(str(out / name), img)
        ch_corners, ch_ids, _, _ = detector.detectBoard(img)
        ids = [] if ch_ids is None else [int(v) for v in ch_ids.ravel()]
        estimate = None
        if len(ids) >= 4:
            estimate = pose_from_pnp(corners3d[np.array(ids)], ch_corners.reshape(-1, 2))
        found_visible = len(set(ids) & set(visible))
        frames.append(dict(file=name, camera_from_board=pose.tolist(), visible_ids=visible,
                           opencv_ids=ids, opencv_found_visible=found_visible,
                           opencv_camera_from_board=None if estimate is None
                           else estimate.tolist(),
                           true_pixels={str(k): px[k].tolist() for k in visible}))
        truth.append(pose)
        estimates.append(estimate)
        i += 1
    rot, trans, pairs = relative_motion_errors(truth, estimates)
    return dict(board=c, frames=frames,
                board_image=dict(file="charuco_board.png", margin_px=margin,
                                 px_per_square=PX_PER_SQUARE),
                opencv=dict(detector="CharucoDetector + solvePnP", median_rot_deg=rot,
                            median_trans_mm=trans, pairs=pairs,
                            found_visible=sum(f["opencv_found_visible"] for f in frames),
                            visible=sum(len(f["visible_ids"]) for f in frames)))


def chessboard_image(c):
    sx, sy = c["squaresX"], c["squaresY"]
    margin = PX_PER_SQUARE
    img = np.full((sy * PX_PER_SQUARE + 2 * margin, sx * PX_PER_SQUARE + 2 * margin), 255,
                  np.uint8)
    for j in range(sy):
        for i in range(sx):
            if (i + j) % 2 == 0:  # top-left square black, as OpenCV's pattern
                y0, x0 = margin + j * PX_PER_SQUARE, margin + i * PX_PER_SQUARE
                img[y0:y0 + PX_PER_SQUARE, x0:x0 + PX_PER_SQUARE] = 0
    return img, margin


def chessboard_frames(out, rays, rng):
    c = CHESS
    sq = c["squareLength"]
    cols, rows = c["squaresX"] - 1, c["squaresY"] - 1
    board_img, margin = chessboard_image(c)
    ppm = PX_PER_SQUARE / sq
    # Inner corner id r*cols + col, row-major from the top-left inner corner (OpenCV's order).
    corners3d = np.array([[(k % cols + 1) * sq, (k // cols + 1) * sq, 0.0]
                          for k in range(cols * rows)])
    centre = np.array([c["squaresX"] * sq / 2, c["squaresY"] * sq / 2, 0.0])
    frames, truth, est_sb, est_classic = [], [], [], []
    i = 0
    while len(frames) < FRAMES:
        pose = look_at(rng, centre, rng.uniform(0.45, 0.8), 35, rng.uniform(-0.02, 0.02, size=2))
        outer = np.array([[x * sq, y * sq, 0.0] for x in (0, c["squaresX"])
                          for y in (0, c["squaresY"])])
        if not inside(project(outer, pose), 30).all():
            continue
        px = project(corners3d, pose)
        img = render(rays, board_img, margin, ppm, pose, rng)
        name = f"chessboard_{i:02d}.png"
        cv2.imwrite(str(out / name), img)
        results = {}
        ok, found = cv2.findChessboardCornersSB(img, (cols, rows), flags=cv2.CALIB_CB_ACCURACY)
        results["sb"] = found.reshape(-1, 2) if ok else None
        ok, found = cv2.findChessboardCorners(img, (cols, rows))
        if ok:
            found = cv2.cornerSubPix(img, found, (5, 5), (-1, -1),
                                     (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4))
        results["classic"] = found.reshape(-1, 2) if ok else None
        poses = {}
        for key, pts in results.items():
            if pts is None:
                poses[key] = None
                continue
            # OpenCV does not settle the 180-degree ambiguity: give it the order that fits truth.
            best = None
            for order in (pts, pts[::-1]):
                if np.linalg.norm(order - px, axis=1).max() < 5.0:
                    best = order
            poses[key] = None if best is None else pose_from_pnp(corners3d, best)
        frames.append(dict(file=name, camera_from_board=pose.tolist(),
                           visible_ids=list(range(cols * rows)),
                           opencv_sb_found=results["sb"] is not None,
                           opencv_classic_found=results["classic"] is not None,
                           true_pixels={str(k): px[k].tolist() for k in range(cols * rows)}))
        truth.append(pose)
        est_sb.append(poses["sb"])
        est_classic.append(poses["classic"])
        i += 1
    sb = relative_motion_errors(truth, est_sb)
    classic = relative_motion_errors(truth, est_classic)
    best = min((sb, "findChessboardCornersSB + solvePnP"),
               (classic, "findChessboardCorners + cornerSubPix + solvePnP"),
               key=lambda x: x[0][0])
    return dict(board=c, frames=frames,
                opencv=dict(detector=best[1], median_rot_deg=best[0][0],
                            median_trans_mm=best[0][1], pairs=best[0][2],
                            sb=dict(median_rot_deg=sb[0], median_trans_mm=sb[1], pairs=sb[2]),
                            classic=dict(median_rot_deg=classic[0], median_trans_mm=classic[1],
                                         pairs=classic[2])))


def main():
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(18)
    rays = normalised_rays()
    result = dict(opencv_version=cv2.__version__, width=W, height=H,
                  camera_matrix=K.tolist(), distortion=DIST.tolist(),
                  charuco=charuco_frames(out, rays, rng),
                  chessboard=chessboard_frames(out, rays, rng))
    (out / "frames.json").write_text(json.dumps(result, indent=1))
    for key in ("charuco", "chessboard"):
        o = result[key]["opencv"]
        print(f"{key}: OpenCV {o['detector']}: median {o['median_rot_deg']:.4f} deg / "
              f"{o['median_trans_mm']:.3f} mm over {o['pairs']} frame pairs")


if __name__ == "__main__":
    main()
