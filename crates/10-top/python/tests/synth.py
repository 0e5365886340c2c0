"""Seeded synthetic pose pairs of a cell with known ground truth (numpy only), and the error of
an answer against that truth. Frames as everywhere: `T_a_b` maps points of `b` into `a`."""

from pathlib import Path

import numpy as np


def rotation(rotvec):
    rotvec = np.asarray(rotvec, dtype=float)
    theta = np.linalg.norm(rotvec)
    if theta < 1e-15:
        return np.eye(3)
    k = rotvec / theta
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * K @ K


def transform(rotvec, translation):
    T = np.eye(4)
    T[:3, :3] = rotation(rotvec)
    T[:3, 3] = translation
    return T


def inverse(T):
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def cell(seed, n=20, setup="eye_in_hand", rotation_sigma_deg=0.2, translation_sigma_mm=1.0):
    """`(T_base_flange (n,4,4), T_camera_target (n,4,4), camera_mount, target_mount)` of a
    plausible cell: the arm tilts 15-40° about varied flange axes around a home pose; the board
    pose is measured with Gaussian noise (per axis, rotation in the camera frame)."""
    rng = np.random.default_rng(seed)
    if setup == "eye_in_hand":
        # T_flange_camera: a camera ~8 cm off the flange; T_base_target: a board on the table.
        camera_mount = transform(rng.normal(0, 0.3, 3), rng.uniform(-0.08, 0.08, 3))
        target_mount = transform([0, 0, rng.uniform(-np.pi, np.pi)], [0.6, rng.uniform(-0.2, 0.2), 0.0])
        home = transform([np.pi, 0, 0], [0.55, 0.0, 0.6])
    else:
        # T_base_camera: a camera 1.2 m from the base; T_flange_target: a board on the flange.
        camera_mount = transform([0, np.pi / 2 + 0.3, 0], [1.2, 0.1, 0.5])
        target_mount = transform(rng.normal(0, 0.3, 3), rng.uniform(-0.05, 0.05, 3) + [0, 0, 0.05])
        home = transform([0, np.pi / 2, 0], [0.6, 0.0, 0.5])
    flange, camera = [], []
    for k in range(n):
        axis = np.zeros(3)
        axis[k % 3] = 1.0
        axis = axis + 0.5 * rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        tilt = transform(axis * np.radians(rng.uniform(15, 40)), rng.uniform(-0.12, 0.12, 3))
        T_base_flange = home @ tilt
        if setup == "eye_in_hand":
            truth = inverse(camera_mount) @ inverse(T_base_flange) @ target_mount
        else:
            truth = inverse(camera_mount) @ T_base_flange @ target_mount
        noise = transform(
            rng.normal(0, np.radians(rotation_sigma_deg), 3),
            rng.normal(0, translation_sigma_mm * 1e-3, 3),
        )
        measured = truth.copy()
        measured[:3, :3] = noise[:3, :3] @ truth[:3, :3]
        measured[:3, 3] = truth[:3, 3] + noise[:3, 3]
        flange.append(T_base_flange)
        camera.append(measured)
    return np.array(flange), np.array(camera), camera_mount, target_mount


def errors(estimate, truth):
    """`(rotation error in degrees, translation error in mm)` of a 4x4 estimate."""
    R = estimate[:3, :3] @ truth[:3, :3].T
    # atan2 of the sine and cosine of the angle: exact near 0, where arccos of the cosine
    # alone cannot resolve below ~1e-6° (1 - cos is under the float64 round-off there).
    sine = np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2
    angle = np.degrees(np.arctan2(sine, (np.trace(R) - 1) / 2))
    return angle, 1e3 * np.linalg.norm(estimate[:3, 3] - truth[:3, 3])


def quaternion_matrix(q):
    """3x3 rotation of a keyed quaternion mapping {w, x, y, z}."""
    w, x, y, z = q["w"], q["x"], q["y"], q["z"]
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def record_matrix(record):
    """4x4 of a result file's pose record (translation + quaternion)."""
    T = np.eye(4)
    T[:3, :3] = quaternion_matrix(record["quaternion"])
    T[:3, 3] = record["translation"]
    return T


def write_dataset(path, setup, flange, camera, ids=None, view_sigmas=None):
    """A dataset file in the matrix form, every number written exactly (repr round-trips);
    `view_sigmas`: each sample's `(rotation_deg, translation_mm)`, NaN rows left out."""

    def pose(T):
        rows = ", ".join("[" + ", ".join(repr(float(v)) for v in T[r, :3]) + "]" for r in range(3))
        t = ", ".join(repr(float(v)) for v in T[:3, 3])
        return f"{{translation: [{t}], matrix: [{rows}]}}"

    lines = [f"setup: {setup}", "samples:"]
    for i, (F, C) in enumerate(zip(flange, camera)):
        lines.append(f"  - T_base_flange: {pose(F)}")
        lines.append(f"    T_camera_target: {pose(C)}")
        if ids is not None:
            lines.append(f'    id: "{ids[i]}"')
        if view_sigmas is not None and not np.isnan(view_sigmas[i]).all():
            r, t = (repr(float(v)) for v in view_sigmas[i])
            lines.append(f"    view_sigma: {{rotation_deg: {r}, translation_mm: {t}}}")
    Path(path).write_text("\n".join(lines) + "\n")

