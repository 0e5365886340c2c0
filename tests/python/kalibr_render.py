#!/usr/bin/env python3
"""Independent renderer and OpenCV baseline for tests/it/kalibr_print.rs (numpy + OpenCV only).

Draws a Kalibr aprilgrid the way `kalibr_create_target_pdf` does (tag36h11, black border two
cells wide, tag ids row by row from the bottom-left, optional black squares of side
tagSpacing*tagSize at every tag corner), takes the tag bitmaps from OpenCV's
DICT_APRILTAG_36h11 dictionary (not from handeye's tables), and renders camera frames with a
plumb_bob (radial-tangential) lens by inverse mapping every pixel on an s x s grid of samples:
pixel -> undistorted ray -> board plane -> printed reflectance. Then blur and sensor noise.
Pixel convention: OpenCV's (pixel centres at integers).

It also runs OpenCV's ArUco detector (DICT_APRILTAG_36h11, 2-cell border, sub-pixel corner
refinement) and cv2.solvePnP on the frames and writes what it found.

Usage: kalibr_render.py SPEC.json OUT_DIR
SPEC: {"board": {"cols", "rows", "tag_size", "tag_spacing", "corner_squares"},
       "camera": {"width", "height", "fx", "fy", "cx", "cy", "dist": [k1, k2, p1, p2, k3]},
       "frames", "seed", "near", "far", "max_tilt_deg", "supersample", "blur_sigma",
       "noise_sigma"}
OUT_DIR/frame_NN.png and OUT_DIR/truth.json: per frame the true T_camera_target (4x4,
row-major), the ids of the tags whose four corners are in the image, and OpenCV's ids and
T_camera_target (or null).
"""
import json
import math
import os
import sys

import cv2
import numpy as np

WHITE, BLACK, BACKGROUND = 205.0, 28.0, 105.0
BORDER_BITS = 2  # Kalibr's default (generateAprilTag's borderBits)
DATA_BITS = 6  # tag36h11: 6x6 data cells


def kalibr_code_matrices(count):
    """Black (True) data cells of tags 0..count-1, row 0 at the top of the printed tag.

    OpenCV's generateImageMarker draws DICT_APRILTAG_36h11 markers rotated by 180 degrees
    against the AprilTag library's (and Kalibr's) tag images, so the bits are turned back."""
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    out = np.zeros((count, DATA_BITS, DATA_BITS), dtype=bool)
    for tag_id in range(count):
        marker = cv2.aruco.generateImageMarker(dictionary, tag_id, DATA_BITS + 2, borderBits=1)
        inner = marker[1:-1, 1:-1] < 128
        out[tag_id] = np.rot90(inner, 2)
    return out


class KalibrBoard:
    """A board as kalibr_create_target_pdf draws it, in the target frame (m, y up)."""

    def __init__(self, cols, rows, tag_size, tag_spacing, corner_squares):
        self.cols, self.rows = cols, rows
        self.size, self.spacing = tag_size, tag_spacing
        self.squares = corner_squares
        self.pitch = tag_size * (1.0 + tag_spacing)
        self.bit = tag_size / (DATA_BITS + 2 * BORDER_BITS)
        self.square = tag_spacing * tag_size
        self.codes = kalibr_code_matrices(cols * rows)
        # White paper beyond the outermost squares.
        pad = self.square + 0.5 * tag_size
        self.paper = (-pad, -pad, (cols - 1) * self.pitch + tag_size + pad,
                      (rows - 1) * self.pitch + tag_size + pad)

    def corners(self, tag_id):
        """Black-square corners of a tag: bottom-left, bottom-right, top-right, top-left."""
        col, row = tag_id % self.cols, tag_id // self.cols
        x, y, s = col * self.pitch, row * self.pitch, self.size
        return np.array([[x, y, 0], [x + s, y, 0], [x + s, y + s, 0], [x, y + s, 0]], float)

    def is_black(self, x, y):
        col = np.floor(x / self.pitch)
        row = np.floor(y / self.pitch)
        u = x - col * self.pitch
        v = y - row * self.pitch
        in_tag = ((col >= 0) & (col < self.cols) & (row >= 0) & (row < self.rows)
                  & (u < self.size) & (v < self.size))
        # Cells counted from the tag's bottom-left corner, as the PDF's rectangles are placed.
        cx = np.clip(np.floor(u / self.bit), 0, DATA_BITS + 2 * BORDER_BITS - 1).astype(int)
        cy = np.clip(np.floor(v / self.bit), 0, DATA_BITS + 2 * BORDER_BITS - 1).astype(int)
        border = ((cx < BORDER_BITS) | (cx >= BORDER_BITS + DATA_BITS)
                  | (cy < BORDER_BITS) | (cy >= BORDER_BITS + DATA_BITS))
        # generateAprilTag puts bit (i, j) at x = (j + borderBits) * bit,
        # y = ((borderBits - 1) + sqrtBits - i) * bit: row i counted from the top.
        j = np.clip(cx - BORDER_BITS, 0, DATA_BITS - 1)
        i = np.clip(BORDER_BITS - 1 + DATA_BITS - cy, 0, DATA_BITS - 1)
        tag_index = np.clip(row * self.cols + col, 0, self.cols * self.rows - 1).astype(int)
        data = self.codes[tag_index, i, j]
        black = in_tag & (border | data)
        if self.squares:
            g = self.square

            def on_square(w, count):
                k = np.floor((w + g) / self.pitch)
                return (k >= 0) & (k <= count) & (w + g - k * self.pitch < g)

            black |= on_square(x, self.cols) & on_square(y, self.rows)
        return black

    def on_paper(self, x, y):
        x0, y0, x1, y1 = self.paper
        return (x >= x0) & (x < x1) & (y >= y0) & (y < y1)


def camera_matrix(cam):
    return np.array([[cam["fx"], 0, cam["cx"]], [0, cam["fy"], cam["cy"]], [0, 0, 1.0]])


def pixel_rays(cam, s):
    """Undistorted normalised coordinates of every sample: s x s per pixel, (H, W, s*s, 2)."""
    w, h = cam["width"], cam["height"]
    offsets = (np.arange(s) + 0.5) / s - 0.5
    ox, oy = np.meshgrid(offsets, offsets)
    u = np.arange(w)[None, :, None] + ox.reshape(1, 1, -1)
    v = np.arange(h)[:, None, None] + oy.reshape(1, 1, -1)
    u, v = np.broadcast_arrays(u, v)
    pts = np.stack([u, v], axis=-1).reshape(-1, 1, 2).astype(np.float64)
    k, dist = camera_matrix(cam), np.array(cam["dist"], float)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
    rays = cv2.undistortPointsIter(pts, k, dist, None, None, criteria)
    # The inverse must be exact: project a sample of rays back and compare.
    sample = rays[:: max(1, len(rays) // 20000)]
    obj = np.concatenate([sample.reshape(-1, 2), np.ones((len(sample), 1))], axis=1)
    back, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), k, dist)
    error = np.abs(back.reshape(-1, 2) - pts[:: max(1, len(rays) // 20000)].reshape(-1, 2)).max()
    if error > 1e-4:
        sys.exit(f"undistortion not exact enough: {error} px")
    return rays.reshape(h, w, s * s, 2)


def render(board, cam, rays, rotation, translation, spec, rng):
    """rotation, translation: camera_from_target."""
    h, w = cam["height"], cam["width"]
    d = np.concatenate([rays, np.ones(rays.shape[:-1] + (1,))], axis=-1)
    # Target-frame ray: origin o = -R^T t, direction R^T d; hit z = 0.
    o = -rotation.T @ translation
    dt = d @ rotation  # (R^T d)^T = d^T R
    lam = -o[2] / dt[..., 2]
    x = o[0] + lam * dt[..., 0]
    y = o[1] + lam * dt[..., 1]
    front = lam > 0
    on = front & board.on_paper(x, y)
    value = np.where(board.is_black(x, y), BLACK, WHITE)
    yy, xx = np.mgrid[0:h, 0:w]
    background = BACKGROUND + 25.0 * np.sin(xx / 97.0) * np.cos(yy / 71.0)
    samples = np.where(on, value, background[..., None])
    image = samples.mean(axis=-1)
    if spec["blur_sigma"] > 0:
        image = cv2.GaussianBlur(image, (0, 0), spec["blur_sigma"])
    image = image + rng.normal(0.0, spec["noise_sigma"], image.shape)
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


def random_pose(board, cam, rng, near, far, max_tilt):
    """Board facing the camera at near..far m, tilted, rolled; every tag corner 15 px inside."""
    k, dist = camera_matrix(cam), np.array(cam["dist"], float)
    x0, y0, x1, y1 = board.paper
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    all_corners = np.concatenate([board.corners(t) for t in range(board.cols * board.rows)])
    for _ in range(10000):
        distance = rng.uniform(near, far)
        tilt = math.radians(rng.uniform(0, max_tilt))
        axis_angle = rng.uniform(0, 2 * math.pi)
        roll = math.radians(rng.uniform(-30, 30))
        facing, _ = cv2.Rodrigues(np.array([math.pi, 0, 0]))
        tilt_r, _ = cv2.Rodrigues(tilt * np.array([math.cos(axis_angle), math.sin(axis_angle), 0]))
        roll_r, _ = cv2.Rodrigues(np.array([0, 0, roll]))
        rotation = roll_r @ facing @ tilt_r
        offset = np.array([rng.uniform(-0.04, 0.04), rng.uniform(-0.03, 0.03), distance])
        translation = offset - rotation @ centre
        px, _ = cv2.projectPoints(all_corners, cv2.Rodrigues(rotation)[0], translation, k, dist)
        px = px.reshape(-1, 2)
        if (px.min() > 15 and px[:, 0].max() < cam["width"] - 16
                and px[:, 1].max() < cam["height"] - 16):
            return rotation, translation
    sys.exit("no pose keeps the board in view: use a smaller board or a farther range")


def opencv_pose(board, cam, image):
    """OpenCV's ArUco detector (2-cell border, sub-pixel corners) and solvePnP."""
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    params = cv2.aruco.DetectorParameters()
    params.markerBorderBits = BORDER_BITS
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    detector = cv2.aruco.ArucoDetector(dictionary, params)
    corners, ids, _ = detector.detectMarkers(image)
    found, obj, img = [], [], []
    if ids is not None:
        for c, tag_id in zip(corners, ids.ravel()):
            tag_id = int(tag_id)
            if tag_id >= board.cols * board.rows or tag_id in found:
                continue
            found.append(tag_id)
            # OpenCV lists a marker's corners from its own top-left, clockwise; on a tag printed
            # as Kalibr does (turned 180 degrees against OpenCV's drawing) that is bottom-right,
            # bottom-left, top-left, top-right.
            truth = board.corners(tag_id)
            for k, ours in enumerate([1, 0, 3, 2]):
                obj.append(truth[ours])
                img.append(c.reshape(4, 2)[k])
    if len(found) < 2:
        return found, None
    ok, rvec, tvec = cv2.solvePnP(np.array(obj), np.array(img), camera_matrix(cam),
                                  np.array(cam["dist"], float), flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        return found, None
    pose = np.eye(4)
    pose[:3, :3] = cv2.Rodrigues(rvec)[0]
    pose[:3, 3] = tvec.ravel()
    return found, pose


def main():
    spec = json.load(open(sys.argv[1]))
    out = sys.argv[2]
    os.makedirs(out, exist_ok=True)
    b, cam = spec["board"], spec["camera"]
    board = KalibrBoard(b["cols"], b["rows"], b["tag_size"], b["tag_spacing"], b["corner_squares"])
    rng = np.random.default_rng(spec["seed"])
    rays = pixel_rays(cam, spec["supersample"])
    k, dist = camera_matrix(cam), np.array(cam["dist"], float)
    frames = []
    for n in range(spec["frames"]):
        rotation, translation = random_pose(board, cam, rng, spec["near"], spec["far"],
                                            spec["max_tilt_deg"])
        image = render(board, cam, rays, rotation, translation, spec, rng)
        name = f"frame_{n:02d}.png"
        cv2.imwrite(os.path.join(out, name), image)
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = rotation, translation
        visible = []
        for tag_id in range(board.cols * board.rows):
            px, _ = cv2.projectPoints(board.corners(tag_id), cv2.Rodrigues(rotation)[0],
                                      translation, k, dist)
            px = px.reshape(-1, 2)
            if (px.min() >= 0 and px[:, 0].max() <= cam["width"] - 1
                    and px[:, 1].max() <= cam["height"] - 1):
                visible.append(tag_id)
        found, cv_pose = opencv_pose(board, cam, image)
        frames.append({
            "file": name,
            "camera_from_target": pose.ravel().tolist(),
            "visible": visible,
            "opencv_ids": sorted(found),
            "opencv_camera_from_target": None if cv_pose is None else cv_pose.ravel().tolist(),
        })
    json.dump({"frames": frames}, open(os.path.join(out, "truth.json"), "w"), indent=1)


if __name__ == "__main__":
    main()
