#!/usr/bin/env python3
"""The call overhead of handeye.calibrate (issue #28): timeit of `handeye.calibrate` on N = 20
samples against the Rust solve of the same samples (criterion, `benches/overhead.rs`).

    python bench/overhead.py --write-dataset   # writes bench/n20.yaml (seeded: the same file)
    cargo bench -p handeye-python --bench overhead   # the Rust figure
    python bench/overhead.py                   # the Python figure (build the wheel --release)

Both solve the same numbers: the Rust bench reads bench/n20.yaml, this script makes the same
arrays from the same seed (and checks that they are the file's). The figure is a benchmark, not
a timed test: the times depend on the machine; the ratio is the point (target: within 1.5x).
"""

import argparse
import sys
import timeit
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
from synth import cell, write_dataset  # noqa: E402

DATASET = HERE / "n20.yaml"
SEED = 20


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write-dataset", action="store_true", help=f"write {DATASET.name} and stop")
    parser.add_argument("--repeat", type=int, default=15)
    args = parser.parse_args()
    flange, camera, _, _ = cell(SEED, n=20)
    if args.write_dataset:
        write_dataset(DATASET, "eye_in_hand", flange, camera)
        print(f"wrote {DATASET}")
        return
    import handeye

    read = handeye.read_dataset(DATASET)
    # The file holds the same numbers (read back through a quaternion: equal to round-off).
    assert np.allclose(read["T_base_flange"], flange, atol=1e-12, rtol=0) and np.allclose(
        read["T_camera_target"], camera, atol=1e-12, rtol=0
    ), (
        f"{DATASET} is not the seeded data set: run with --write-dataset"
    )
    calls = {
        # verdict=False: the solve alone, as the Rust bench (the default also judges the answer,
        # one held-out solve per sample).
        "handeye.calibrate (N=20)": lambda: handeye.calibrate(flange, camera, verdict=False),
        "  + all results read": lambda: touch(handeye.calibrate(flange, camera, verdict=False)),
    }
    for name, call in calls.items():
        timer = timeit.Timer(call)
        number, _ = timer.autorange()
        times = np.array(timer.repeat(repeat=args.repeat, number=number)) / number
        print(
            f"{name:28s} median {np.median(times) * 1e6:8.1f} µs, best {times.min() * 1e6:8.1f} µs "
            f"per call ({args.repeat} x {number} calls)"
        )


def touch(calibration):
    """Reads every figure but the verdict (which solves N more times on purpose)."""
    return (
        calibration.transforms,
        calibration.sigma,
        calibration.residuals,
        calibration.notices,
        calibration.noise,
    )


if __name__ == "__main__":
    main()
