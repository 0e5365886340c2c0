"""Bad input raises a clear ValueError (handeye.InputError), never a crash of the interpreter:
wrong shapes, NaN, non-rigid matrices, millimetres, refused solves, bad options."""

import subprocess
import sys

import numpy as np
import pytest

import handeye
from synth import cell


@pytest.fixture(scope="module")
def data():
    flange, camera, _, _ = cell(3, n=12)
    return flange, camera


def raises(match, *args, **kwargs):
    with pytest.raises(ValueError, match=match) as error:
        handeye.calibrate(*args, **kwargs)
    assert isinstance(error.value, handeye.InputError)
    assert isinstance(error.value, handeye.HandeyeError)
    return error.value


def test_wrong_shapes(data):
    flange, camera = data
    raises(r"T_base_flange must be an \(N, 4, 4\) array .* found shape \(12, 3, 4\)", flange[:, :3], camera)
    raises(r"T_camera_target must be an \(N, 4, 4\) array .* found shape \(4, 4\)", flange, camera[0])
    raises(r"found shape \(12, 16\)", flange.reshape(12, 16), camera)
    raises(r"T_base_flange has 12 poses but T_camera_target has 11", flange, camera[:11])
    raises(r"T_base_flange must be an \(N, 4, 4\) array", "not an array", camera)
    raises(r"T_base_flange must be an \(N, 4, 4\) array", [[1, 2], [3]], camera)
    raises(r"ids has 2 entries for 12 samples", flange, camera, ids=["a", "b"])


def test_nan_and_infinity(data):
    flange, camera = data
    for bad, where in [(np.nan, (2, 0, 0)), (np.inf, (5, 1, 3)), (-np.inf, (0, 2, 2))]:
        broken = flange.copy()
        broken[where] = bad
        raises(rf"T_base_flange\[{where[0]}\].*not finite", broken, camera)
    broken = camera.copy()
    broken[7, 0, 3] = np.nan
    raises(r"T_camera_target\[7\].*not finite", flange, broken)


def test_non_rigid_matrices(data):
    flange, camera = data
    sheared = flange.copy()
    sheared[3, 0, 1] += 0.05
    raises(r"T_base_flange\[3\]\.matrix: not a rotation matrix", sheared, camera)
    scaled = camera.copy()
    scaled[1, :3, :3] *= 1.01
    raises(r"T_camera_target\[1\]\.matrix: not a rotation matrix", flange, scaled)
    mirrored = flange.copy()
    mirrored[0, :3, 0] *= -1
    raises(r"T_base_flange\[0\]\.matrix: not a rotation matrix: .* det = -1", mirrored, camera)
    projective = flange.copy()
    projective[4, 3, 0] = 0.1
    raises(r"T_base_flange\[4\]: the last row of a homogeneous transform must be \[0, 0, 0, 1\]", projective, camera)


def test_millimetres(data):
    flange, camera = data
    mm = flange.copy()
    mm[:, :3, 3] *= 1000
    raises(r"T_base_flange\[0\]\.translation: .* from the origin.*millimetres given as metres", mm, camera)
    # A few hundred mm read as metres is under the 100 m bound: the solver's units check names it.
    small = flange.copy()
    small[:, :3, 3] *= 100  # centimetres
    error = raises(r"not in metres", small, camera)
    assert error.verdict is not None and error.verdict.level == "REDO"


def test_refused_solves_carry_a_redo_verdict(data):
    flange, camera = data
    error = raises(r"2 pose pairs given, at least 3 are needed", flange[:2], camera[:2])
    assert error.verdict.level == "REDO" and "refused" in error.verdict.reason
    # Rotations all about one axis.
    from synth import transform, inverse

    X = transform([0.1, 0.2, 0.3], [0.02, 0.03, 0.05])
    Y = transform([0, 0, 0.4], [0.6, 0.1, 0.0])
    coaxial = np.array([transform([0, 0, 0.3 * k], [0.5, 0.01 * k, 0.5]) for k in range(8)])
    seen = np.array([inverse(X) @ inverse(F) @ Y for F in coaxial])
    raises(r"rotations are all about nearly one axis", coaxial, seen)


def test_bad_options(data):
    flange, camera = data
    raises(r"setup `hand_in_eye`", flange, camera, "hand_in_eye")
    raises(r"unknown method `magic`, expected one of", flange, camera, method="magic")
    raises(r"rotation_sigma_deg = -1: must be a value in", flange, camera, rotation_sigma_deg=-1)
    raises(r"robust `l1`", flange, camera, robust="l1")
    raises(r"robust_scale = NaN: must be a positive number", flange, camera, robust_scale=float("nan"))
    raises(r"sample 2: weight", flange, camera, weights=[1.0, 1.0, -1.0] + [1.0] * 9)


def test_opencv_shaped_calls_refuse_bad_input(data):
    flange, camera = data
    R = [T[:3, :3] for T in flange]
    t = [T[:3, 3:4] for T in flange]
    Rc = [T[:3, :3] for T in camera]
    tc = [T[:3, 3:4] for T in camera]
    with pytest.raises(ValueError, match=r"R_gripper2base\[0\]: expected a 3x3 rotation matrix"):
        handeye.calibrateHandEye([np.ones((2, 2))] + R[1:], t, Rc, tc)
    with pytest.raises(ValueError, match=r"R_target2cam has 12 entries but t_target2cam has 11"):
        handeye.calibrateHandEye(R, t, Rc, tc[:11])
    with pytest.raises(ValueError, match=r"R_gripper2base\[1\]: not a rotation matrix"):
        handeye.calibrateHandEye([R[0], 2 * R[1]] + R[2:], t, Rc, tc)
    with pytest.raises(ValueError, match=r"t_gripper2base\[0\]: value is not finite|not finite"):
        handeye.calibrateHandEye(R, [np.full((3, 1), np.nan)] + t[1:], Rc, tc)
    with pytest.raises(ValueError, match=r"method 9"):
        handeye.calibrateHandEye(R, t, Rc, tc, method=9)
    with pytest.raises(ValueError, match=r"millimetres given as metres|not in metres"):
        handeye.calibrateHandEye(R, [1000 * v for v in t], Rc, tc)


def test_bad_images_and_files(tmp_path):
    board = handeye.Board.aprilgrid(6, 6, 0.04, 0.25)
    with pytest.raises(ValueError, match=r"8-bit grey .* found shape \(20, 20\) of float64"):
        handeye.detect(np.zeros((20, 20)), board)
    with pytest.raises(ValueError, match=r"found shape \(20, 20, 4\)"):
        handeye.detect(np.zeros((20, 20, 4), np.uint8), board)
    with pytest.raises(ValueError, match=r"image must be a numpy array"):
        handeye.detect([[0, 1], [2, 3]], board)
    with pytest.raises(ValueError, match=r"too small for the AprilTag detector"):
        handeye.detect(np.zeros((3, 3), np.uint8), board)
    with pytest.raises(ValueError, match=r"tagSize"):
        handeye.Board.aprilgrid(6, 6, -0.04, 0.25)
    with pytest.raises(ValueError, match=r"fx"):
        handeye.Camera(640, 480, -5.0, 500.0, 320.0, 240.0)
    with pytest.raises(OSError, match=r"cannot read") as error:
        handeye.Board.load(tmp_path / "missing.yaml")
    assert isinstance(error.value, handeye.FileError)
    with pytest.raises(OSError, match=r"cannot read"):
        handeye.read_dataset(tmp_path / "missing.yaml")
    (tmp_path / "bad.yaml").write_text("setup: eye_in_hand\nsamples: [{T_base_flange: 3}]\n")
    with pytest.raises(ValueError, match=r"bad.yaml"):
        handeye.read_dataset(tmp_path / "bad.yaml")
    with pytest.raises(ValueError, match=r"is not a session folder"):
        handeye.Session(tmp_path)


def test_the_interpreter_survives_every_bad_call():
    """Every bad call above in a fresh interpreter, which must exit normally (no abort, no
    segfault): exit code 0 and every call reported as an exception."""
    script = r"""
import numpy as np, handeye
calls = [
    lambda: handeye.calibrate(np.zeros((5, 4, 4)), np.zeros((5, 4, 4))),
    lambda: handeye.calibrate(np.full((5, 4, 4), np.nan), np.full((5, 4, 4), np.nan)),
    lambda: handeye.calibrate(np.zeros((0, 4, 4)), np.zeros((0, 4, 4))),
    lambda: handeye.calibrate(np.eye(4)[None].repeat(3, 0), np.eye(4)[None].repeat(3, 0)),
    lambda: handeye.calibrate(np.eye(4)[None].repeat(30, 0) * 1e308, np.eye(4)[None].repeat(30, 0)),
    lambda: handeye.detect(np.zeros((0, 0), np.uint8), handeye.Board.aprilgrid(2, 2, 0.04, 0.3)),
    lambda: handeye.detect(np.zeros((1, 100000), np.uint8), handeye.Board.charuco(5, 7, 0.04, 0.03)),
    lambda: handeye.Camera(0, 0, 1, 1, 0, 0),
    lambda: handeye.read_result("/"),
]
for call in calls:
    try:
        result = call()
        print("returned", type(result).__name__)
    except Exception as error:
        print("raised", type(error).__name__)
"""
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    expected = ["raised InputError"] * 6 + [
        # A 1-pixel-high strip holds no board: a detection with no corners, and the reason.
        "returned Detection",
        "raised InputError",
        "raised FileError",
    ]
    assert run.stdout.splitlines() == expected, run.stdout
