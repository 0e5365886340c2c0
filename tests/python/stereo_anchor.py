"""Independent anchor for the fixed cameras of a several-camera run (issue #27): OpenCV's
cv2.stereoCalibrate on the same corners handeye detected.

Reads a JSON file (argv[1]) written by tests/it/rig.rs:
  {"size": [w, h], "K1": 3x3, "D1": [k1, k2, p1, p2, k3], "K2": ..., "D2": ...,
   "views": [{"object": [[x, y, z], ...], "left": [[u, v], ...], "right": [[u, v], ...]}, ...]}
where each view holds the board corners both cameras saw at one robot pose (board frame, metres;
pixels in OpenCV's convention). The intrinsics are fixed (CALIB_FIX_INTRINSIC): only the pose of
the second camera relative to the first is estimated, as handeye's joint solve estimates it.

Prints JSON: {"R": 3x3, "T": [x, y, z], "rms_px": e, "views": n}, where [R|T] maps points of
the left camera's frame into the right camera's frame (OpenCV's convention: x_right = R x_left + T),
i.e. T_cam_right_cam_left.
"""

import json
import sys

import cv2
import numpy as np


def main() -> None:
    with open(sys.argv[1], encoding="utf-8") as f:
        data = json.load(f)
    object_points = [np.asarray(v["object"], dtype=np.float32) for v in data["views"]]
    left = [np.asarray(v["left"], dtype=np.float32).reshape(-1, 1, 2) for v in data["views"]]
    right = [np.asarray(v["right"], dtype=np.float32).reshape(-1, 1, 2) for v in data["views"]]
    k1 = np.asarray(data["K1"], dtype=np.float64)
    d1 = np.asarray(data["D1"], dtype=np.float64)
    k2 = np.asarray(data["K2"], dtype=np.float64)
    d2 = np.asarray(data["D2"], dtype=np.float64)
    size = tuple(data["size"])
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 200, 1e-12)
    rms, _, _, _, _, r, t, _, _ = cv2.stereoCalibrate(
        object_points, left, right, k1, d1, k2, d2, size,
        flags=cv2.CALIB_FIX_INTRINSIC, criteria=criteria,
    )
    print(json.dumps({"R": r.tolist(), "T": t.ravel().tolist(), "rms_px": float(rms), "views": len(object_points)}))


if __name__ == "__main__":
    main()
