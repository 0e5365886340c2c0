"""The solver releases the GIL: calls from several threads give the answers one thread gives,
and reading one Calibration's verdict from several threads at once neither deadlocks nor
disagrees."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np

import handeye
from synth import cell


def test_threads_get_the_single_thread_answers():
    data = [cell(seed, n=12)[:2] for seed in range(30, 36)]
    alone = [handeye.calibrate(f, c).camera_mount for f, c in data]
    with ThreadPoolExecutor(4) as pool:
        together = list(pool.map(lambda fc: handeye.calibrate(*fc).camera_mount, data))
    for a, b in zip(alone, together):
        assert np.array_equal(a, b)


def test_one_verdict_read_from_many_threads():
    flange, camera, _, _ = cell(40, n=12)
    calibration = handeye.calibrate(flange, camera)
    with ThreadPoolExecutor(4) as pool:
        reasons = list(pool.map(lambda _: calibration.verdict.reason, range(8)))
    assert len(set(reasons)) == 1
    assert reasons[0] == handeye.calibrate(flange, camera).verdict.reason
