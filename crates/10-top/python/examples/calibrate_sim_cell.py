#!/usr/bin/env python3
"""Calibrates the simulated cell's recorded samples with handeye from Python.

    python crates/10-top/python/examples/calibrate_sim_cell.py            # the samples beside this file
    python crates/10-top/python/examples/calibrate_sim_cell.py SESSION    # a session `handeye run` wrote

The samples (sim-cell-samples.yaml) are what `handeye run --config configs/sim-cell.yaml`
recorded; the simulator's ground truth is that config's `simulation:` section (copied below, or
read from the session's config when a session folder is given).
"""

import sys
from pathlib import Path

import numpy as np

import handeye

HERE = Path(__file__).resolve().parent


def transform(rotation_vector, translation):
    """4x4 from a rotation vector (rad) and a translation (m), as the config writes poses."""
    r = np.asarray(rotation_vector, dtype=float)
    theta = np.linalg.norm(r)
    k = r / theta
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * K @ K
    T[:3, 3] = translation
    return T


# configs/sim-cell.yaml, `simulation:` (the transforms the calibration must find).
SIM_CELL_TRUTH = {
    "T_flange_camera": transform([0.021, -0.016, 1.561], [0.0312, -0.0694, 0.0447]),
    "T_base_target": transform([0.012, -0.018, 0.297], [0.5034, -0.1467, 0.0021]),
}


def main():
    if len(sys.argv) > 1:
        session = handeye.Session(sys.argv[1])
        samples, truth = session.samples, session.truth
    else:
        session = None
        samples, truth = handeye.read_dataset(HERE / "sim-cell-samples.yaml"), SIM_CELL_TRUTH

    calibration = handeye.calibrate(
        samples["T_base_flange"], samples["T_camera_target"], samples["setup"], ids=samples["ids"]
    )
    print(f"{len(samples['ids'])} samples, {samples['setup']}")
    print(calibration.summary())
    print(calibration.verdict)
    for name, T in calibration.transforms.items():
        sigma = calibration.sigma[name]
        R = T[:3, :3] @ truth[name][:3, :3].T
        angle = np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))
        distance = 1e3 * np.linalg.norm(T[:3, 3] - truth[name][:3, 3])
        print(
            f"{name}: error {distance:.3f} mm, {angle:.4f}° against the simulator's ground truth "
            f"(1-sigma {sigma['translation_mm']:.3f} mm, {sigma['rotation_deg']:.4f}°)"
        )
    if session is not None:
        refined = session.solve(space="reprojection")
        print(f"reprojection space: {refined.reprojection['reprojection_rms_px']:.3f} px RMS, verdict {refined.verdict.level}")


if __name__ == "__main__":
    main()
