"""Call time of handeye's `calibrate` and `calibrateHandEye` against `cv2.calibrateHandEye` on
the same seeded synthetic cells (tests/synth.py: 0.2° / 1 mm board-pose noise), N = 20 and 200,
as the issue #42 table asks; timeit, median and best of the repeats, ms.

    python crates/10-top/python/bench/vs_opencv.py            # after installing the wheel (release
                                                       # build for figures worth quoting)

`calibrate` and `calibrateHandEye` run as a cv2 user calls them (the default: the verdict is
computed too, one held-out solve per sample, up to 100) and with `verdict=False` (the solve
alone, what cv2 does); `calibrateHandEye` with the lists of (3, 3) rotations and (3, 1)
translations cv2 takes, `calibrate` with the (N, 4, 4) stacks.
"""

import statistics
import sys
import timeit
from pathlib import Path

import cv2

import handeye

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from synth import cell  # noqa: E402


def time_ms(call, number, repeat):
    times = timeit.repeat(call, number=number, repeat=repeat)
    per_call = [1e3 * t / number for t in times]
    return statistics.median(per_call), min(per_call)


def main():
    print("| N | call | median ms | best ms |")
    print("|---|---|---|---|")
    for n, number, repeat in [(20, 5, 15), (200, 1, 9)]:
        flange, camera, _, _ = cell(7, n=n)
        R_g = [T[:3, :3].copy() for T in flange]
        t_g = [T[:3, 3:4].copy() for T in flange]
        R_t = [T[:3, :3].copy() for T in camera]
        t_t = [T[:3, 3:4].copy() for T in camera]
        calls = [
            ("handeye.calibrate", lambda: handeye.calibrate(flange, camera)),
            ("handeye.calibrate(verdict=False)", lambda: handeye.calibrate(flange, camera, verdict=False)),
            ("handeye.calibrateHandEye", lambda: handeye.calibrateHandEye(R_g, t_g, R_t, t_t)),
            ("handeye.calibrateHandEye(verdict=False)", lambda: handeye.calibrateHandEye(R_g, t_g, R_t, t_t, verdict=False)),
        ]
        calls += [
            (f"cv2.calibrateHandEye {name}", lambda m=getattr(cv2, f"CALIB_HAND_EYE_{name}"): cv2.calibrateHandEye(R_g, t_g, R_t, t_t, method=m))
            for name in ("TSAI", "DANIILIDIS")
        ]
        for name, call in calls:
            call()  # warm up (and any warning once)
            median, best = time_ms(call, number, repeat)
            print(f"| {n} | {name} | {median:.3f} | {best:.3f} |")


if __name__ == "__main__":
    import warnings

    warnings.simplefilter("ignore", handeye.CalibrationWarning)
    main()
