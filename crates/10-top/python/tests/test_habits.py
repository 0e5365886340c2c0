"""The habits of an OpenCV user (issue #42), each against the exact call a cv2 script writes:
rotation vectors in degrees are refused (as in a YAML file), a verdict that is not GOOD warns,
every method drops and names outliers, millimetres are taken when said so, the wrong call shapes
name the right call, and the namespace holds only the package's names."""

import warnings

import numpy as np
import pytest

import handeye
from conftest import as_matrix, opencv_inputs
from synth import cell, errors, inverse, rotation, transform


def quiet_cell(seed, n=20):
    """A cell whose answer is GOOD: low board-pose noise (0.02°, 0.1 mm)."""
    return cell(seed, n=n, rotation_sigma_deg=0.02, translation_sigma_mm=0.1)


def with_outliers(camera, indices=(3, 11)):
    """Gross outliers: the board pose of each sample in `indices` rotated 5° and 3° and moved
    30 mm and 50 mm (a misdetection, a wrong pairing)."""
    bad = camera.copy()
    for i, (deg, mm) in zip(indices, [(5.0, 30.0), (3.0, 50.0)]):
        bad[i] = transform([np.radians(deg), 0, 0], [mm * 1e-3, 0, 0]) @ bad[i]
    return bad


# --- rotation vectors in degrees ------------------------------------------------------------


def test_rotation_vectors_in_degrees_are_refused_where_opencv_answers_silently(cv2):
    """The cv2 script's rvecs (cv2.Rodrigues) converted with np.degrees by mistake: OpenCV
    answers far from the truth without a word; handeye refuses with the YAML's message."""
    flange, camera, truth, _ = quiet_cell(40)
    R_g, t_g, R_t, t_t = opencv_inputs(flange, camera)
    rvec_g = [np.degrees(cv2.Rodrigues(R)[0]) for R in R_g]
    rvec_t = [cv2.Rodrigues(R)[0] for R in R_t]
    R_cv, t_cv = cv2.calibrateHandEye(rvec_g, t_g, rvec_t, t_t)
    rot, trans = errors(as_matrix(R_cv, t_cv), truth)
    assert trans > 10.0, f"OpenCV's answer from degrees is {trans:.1f} mm off: the case is not a silent wrong answer"
    with pytest.raises(handeye.InputError, match=r"R_gripper2base\[0\]: rotation vector \[.*\] is .* long, more than 2π: it looks like degrees, but a rotation_vector is axis × angle in radians; write it in radians") as error:
        handeye.calibrateHandEye(rvec_g, t_g, rvec_t, t_t)
    assert "np.radians" in str(error.value)
    # The camera side too, and the robot-world call.
    rvec_t_deg = [np.degrees(v) for v in rvec_t]
    with pytest.raises(handeye.InputError, match=r"R_target2cam\[\d+\]: rotation vector .* looks like degrees"):
        handeye.calibrateHandEye([cv2.Rodrigues(R)[0] for R in R_g], t_g, rvec_t_deg, t_t)
    base2gripper = [inverse(T) for T in flange]
    with pytest.raises(handeye.InputError, match=r"R_base2gripper\[\d+\]: rotation vector .* looks like degrees"):
        handeye.calibrateRobotWorldHandEye(
            rvec_t, t_t, [np.degrees(cv2.Rodrigues(T[:3, :3])[0]) for T in base2gripper], [T[:3, 3:4] for T in base2gripper]
        )


def test_the_same_rotation_vectors_in_radians_are_taken(cv2):
    flange, camera, truth, _ = quiet_cell(40)
    R_g, t_g, R_t, t_t = opencv_inputs(flange, camera)
    rvec_g = [cv2.Rodrigues(R)[0] for R in R_g]
    rvec_t = [cv2.Rodrigues(R)[0] for R in R_t]
    R, t = handeye.calibrateHandEye(rvec_g, t_g, rvec_t, t_t)
    rot, trans = errors(as_matrix(R, t), truth)
    assert rot < 0.05 and trans < 0.5


# --- the verdict as a warning ---------------------------------------------------------------


def noisy_cell():
    """A cell whose answer is not GOOD: 1° / 5 mm board-pose noise for a 1 mm / 0.1° goal."""
    return cell(41, n=20, rotation_sigma_deg=1.0, translation_sigma_mm=5.0)


def test_a_verdict_that_is_not_good_warns_once_per_call_with_its_reason_and_next_step():
    flange, camera, _, _ = noisy_cell()
    R_g, t_g, R_t, t_t = opencv_inputs(flange, camera)
    for call in [
        lambda: handeye.calibrateHandEye(R_g, t_g, R_t, t_t),
        lambda: handeye.calibrate(flange, camera),
    ]:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            call()
        found = [w for w in caught if issubclass(w.category, handeye.CalibrationWarning)]
        assert len(found) == 1, [str(w.message) for w in caught]
        warning = found[0]
        assert issubclass(warning.category, UserWarning)
        verdict = warning.message.verdict
        assert verdict.level in ("CHECK", "REDO")
        text = str(warning.message)
        assert verdict.reason in text and verdict.next_action in text and verdict.level in text
        # It points at the caller's line, not into the package.
        assert warning.filename == __file__, warning.filename


def test_a_good_verdict_is_silent_and_verdict_false_skips_the_check():
    flange, camera, _, _ = quiet_cell(42)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cal = handeye.calibrate(flange, camera)
        assert cal.verdict.level == "GOOD", cal.verdict.reason
        handeye.calibrateHandEye(*opencv_inputs(flange, camera))
        noisy_flange, noisy_camera, _, _ = noisy_cell()
        cal = handeye.calibrate(noisy_flange, noisy_camera, verdict=False)
    assert cal.verdict.level != "GOOD"  # still there when read


def test_errors_stay_exceptions_and_do_not_warn():
    flange, camera, _, _ = quiet_cell(42)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(handeye.InputError, match=r"2 pose pairs given") as error:
            handeye.calibrateHandEye(*opencv_inputs(flange[:2], camera[:2]))
    assert error.value.verdict.level == "REDO"


def test_the_warning_can_be_made_an_error():
    flange, camera, _, _ = noisy_cell()
    with warnings.catch_warnings():
        warnings.simplefilter("error", handeye.CalibrationWarning)
        with pytest.raises(handeye.CalibrationWarning):
            handeye.calibrate(flange, camera)


# --- every method drops and names outliers --------------------------------------------------


def board_flipped(camera, indices=(3, 11)):
    """The board of the samples in `indices` seen turned 180° about its normal (a symmetric
    board's classic misdetection): the outliers DANIILIDIS kept before, 100° and a metre off."""
    bad = camera.copy()
    for i in indices:
        bad[i] = bad[i] @ transform([0, 0, np.pi], [0, 0, 0])
    return bad


@pytest.mark.parametrize("method", ["TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS"])
@pytest.mark.parametrize("outliers", [with_outliers, board_flipped])
def test_every_opencv_method_drops_and_names_two_outliers(method, outliers, cv2):
    """The README's 10 seeded cells (N = 20, 0.2° / 1 mm noise) with two gross outliers
    (samples 3 and 11): each of OpenCV's methods run by handeye names both, leaves them out (its
    answer is its own fit of the 18 other samples), and is far better than cv2's same method.
    How far each is from the refined answer is a figure of the class of such cells, not of ten:
    the next test."""
    ours, theirs = [], []
    for seed in range(10, 20):
        flange, camera, truth, _ = cell(seed, n=20)
        bad = outliers(camera)
        R, t, cal = handeye.calibrateHandEye(
            *opencv_inputs(flange, bad), method=getattr(handeye, f"CALIB_HAND_EYE_{method}"),
            verdict=False, return_calibration=True,
        )
        assert cal.dropped == [3, 11], (seed, cal.dropped)
        named = [n["message"] for n in cal.notices if n["kind"] == "dropped_outliers"]
        assert len(named) == 2 and "sample 3 " in named[0] and "sample 11 " in named[1], named
        keep = [i for i in range(20) if i not in (3, 11)]
        R_clean, t_clean = handeye.calibrateHandEye(
            *opencv_inputs(flange[keep], bad[keep]), method=getattr(handeye, f"CALIB_HAND_EYE_{method}"), verdict=False
        )
        assert np.max(np.abs(R - R_clean)) < 1e-9 and np.max(np.abs(t - t_clean)) < 1e-9, seed
        ours.append(errors(as_matrix(R, t), truth))
        R_cv, t_cv = cv2.calibrateHandEye(*opencv_inputs(flange, bad), method=getattr(cv2, f"CALIB_HAND_EYE_{method}"))
        theirs.append(errors(as_matrix(R_cv, t_cv), truth))
    ours, theirs = rms(ours), rms(theirs)
    print(
        f"\n{method} with 2 outliers ({outliers.__name__}), RMS over 10 cells: handeye {ours[0]:.3f}° {ours[1]:.2f} mm, "
        f"cv2 {theirs[0]:.3f}° {theirs[1]:.2f} mm"
    )
    assert ours[0] < theirs[0] and ours[1] < theirs[1], (ours, theirs)


def rms(rows):
    """Root mean square over the first axis (per column of `(rotation, translation)` rows)."""
    return np.sqrt(np.mean(np.square(rows), axis=0))


def log_rotation(R):
    """The rotation vector (rad) of a 3x3 rotation below 180°."""
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2
    s = np.linalg.norm(w)
    return w if s < 1e-15 else w / s * np.arctan2(s, (np.trace(R) - 1) / 2)


def rotation_from_rotations_alone(T_base_flange, T_camera_target, R_flange_camera, iterations=10):
    """The least-squares `R_flange_camera` of the board-pose rotations alone, the translations
    unused: Gauss-Newton over both rotations of `R_camera_target = R_camera_flange ·
    R_flange_base · R_base_target` (the noise is a rotation on the left, in the camera frame, as
    synth.cell draws it), from `R_flange_camera`. The best a method that takes the rotation from
    the rotations alone can do, whatever its algebra."""
    R_x = R_flange_camera.T
    R_y = T_base_flange[0, :3, :3] @ R_flange_camera @ T_camera_target[0, :3, :3]
    for _ in range(iterations):
        rows, residuals = [], []
        for F, C in zip(T_base_flange, T_camera_target):
            predicted = R_x @ F[:3, :3].T @ R_y
            residuals.append(log_rotation(C[:3, :3] @ predicted.T))
            # exp(dx)·R_x·R_Fᵀ·R_y·exp(dy) = exp(dx + predicted·dy)·predicted to first order.
            rows.append(np.hstack([np.eye(3), predicted]))
        step = np.linalg.lstsq(np.vstack(rows), np.concatenate(residuals), rcond=None)[0]
        R_x, R_y = rotation(step[:3]) @ R_x, R_y @ rotation(step[3:])
    return R_x.T


# Seeded cells of the class test below: enough that the RMS ratio is the class's, not a draw's.
# Daniilidis' ratio to the refined answer over the first 1000 cells: 1.80× / 1.80× (rotation /
# translation; the other methods 1.92× / 1.79×); over batches of 10 of them 1.0-2.9×, 45 % of
# the batches above 2× (seeds 10-19: 2.13×, the figure a 10-cell test measured); over batches
# of 200 1.75-1.89×.
CLASS_CELLS = range(400)


def test_every_opencv_method_with_two_outliers_is_within_2x_of_refined_over_the_class(cv2):
    """Each OpenCV method run by handeye on 400 seeded cells of the README's kind (N = 20,
    0.2° / 1 mm noise, samples 3 and 11 gross outliers): RMS error of `T_flange_camera` within
    2× of handeye's refined answer on the same data (the issue's bound), in rotation and in
    translation, and below cv2's same method. Measured (`pytest -s`): TSAI, PARK, HORAUD,
    ANDREFF 1.91× / 1.82×, DANIILIDIS 1.77× / 1.83× (refined 0.129°, 1.38 mm). TSAI, PARK,
    HORAUD and ANDREFF take the rotation from the rotations alone; their rotation is within 2 %
    of the least-squares rotation of the rotations alone (their algebra loses nothing there): the
    refined answer also reads the rotation off the translations, through the board's ~0.6 m
    lever arm, which is why they sit near 2×."""
    methods = ("TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS")
    ours, theirs = {m: [] for m in methods}, {m: [] for m in methods}
    refined, alone = [], []
    keep = [i for i in range(20) if i not in (3, 11)]
    for seed in CLASS_CELLS:
        flange, camera, truth, _ = cell(seed, n=20)
        bad = with_outliers(camera)
        inputs = opencv_inputs(flange, bad)
        for method in methods:
            R, t, cal = handeye.calibrateHandEye(
                *inputs, method=getattr(handeye, f"CALIB_HAND_EYE_{method}"), verdict=False, return_calibration=True
            )
            assert cal.dropped == [3, 11], (seed, method, cal.dropped)
            ours[method].append(errors(as_matrix(R, t), truth))
            R_cv, t_cv = cv2.calibrateHandEye(*inputs, method=getattr(cv2, f"CALIB_HAND_EYE_{method}"))
            theirs[method].append(errors(as_matrix(R_cv, t_cv), truth))
        refined.append(errors(handeye.calibrate(flange, bad, verdict=False).T_flange_camera, truth))
        R_alone = rotation_from_rotations_alone(flange[keep], camera[keep], as_matrix(R, t)[:3, :3])
        alone.append(errors(as_matrix(R_alone, truth[:3, 3:4]), truth)[0])
    refined, alone = rms(refined), float(rms(alone))
    print(
        f"\nover {len(CLASS_CELLS)} cells: refined {refined[0]:.3f}° {refined[1]:.2f} mm; rotation from the rotations "
        f"alone {alone:.3f}° = {alone / refined[0]:.2f}× refined's"
    )
    for method in methods:
        mine, cv = rms(ours[method]), rms(theirs[method])
        ratio = mine / refined
        print(f"{method}: {mine[0]:.3f}° {mine[1]:.2f} mm = {ratio[0]:.2f}× / {ratio[1]:.2f}×; cv2 {cv[0]:.3f}° {cv[1]:.2f} mm")
        assert ratio[0] <= 2.0 and ratio[1] <= 2.0, (method, ratio)
        assert mine[0] < cv[0] and mine[1] < cv[1], (method, mine, cv)
        if method != "DANIILIDIS":
            assert mine[0] <= 1.02 * alone, (method, mine[0], alone)


# --- units ----------------------------------------------------------------------------------


def on_a_binary_grid(T):
    """`T` with its translations rounded to 2^-30 m (~1 nm): numbers of at most 31 significant
    bits, so `1000 * t` is exact in float64 and the millimetre data are exactly the metre data
    ×1000. (With arbitrary doubles `1000 * t / 1000` can differ from `t` by an ulp, and the
    iterative solver's answer moves with such a difference by ~1e-10 of itself: the
    comparison would measure the solver's convergence, not the handling of units.)"""
    out = np.array(T, dtype=float)
    out[..., :3, 3] = np.round(out[..., :3, 3] * 2.0**30) / 2.0**30
    return out


def test_units_mm_answers_the_metre_answer_times_1000():
    flange, camera, _, _ = cell(43, n=20)
    flange, camera = on_a_binary_grid(flange), on_a_binary_grid(camera)
    mm = lambda T: np.concatenate([T[:, :3, :3], 1000 * T[:, :3, 3:]], axis=2)  # noqa: E731
    flange_mm = np.array([np.vstack([m, [0, 0, 0, 1]]) for m in mm(flange)])
    camera_mm = np.array([np.vstack([m, [0, 0, 0, 1]]) for m in mm(camera)])
    metres = handeye.calibrate(flange, camera, verdict=False)
    millimetres = handeye.calibrate(flange_mm, camera_mm, units="mm", verdict=False)
    assert metres.units == "m" and millimetres.units == "mm"
    for name in ("T_flange_camera", "T_base_target"):
        a, b = getattr(metres, name), getattr(millimetres, name)
        assert np.max(np.abs(b[:3, :3] - a[:3, :3])) < 1e-9, name
        assert np.max(np.abs(b[:3, 3] - 1000 * a[:3, 3])) < 1e-9, name
    assert np.max(np.abs(millimetres.predict(flange_mm)[:, :3, 3] - 1000 * metres.predict(flange)[:, :3, 3])) < 1e-9
    assert millimetres.sigma["T_flange_camera"]["translation_mm"] == pytest.approx(
        metres.sigma["T_flange_camera"]["translation_mm"], rel=1e-6
    )
    cov_m, cov_mm = metres.covariance, millimetres.covariance
    assert np.allclose(cov_mm[3:6, 3:6], 1e6 * cov_m[3:6, 3:6], rtol=1e-6, atol=0)
    assert np.allclose(cov_mm[:3, :3], cov_m[:3, :3], rtol=1e-6, atol=0)


def test_units_mm_through_the_opencv_shaped_calls_as_opencv_answers_in_mm(cv2):
    """With every input in mm OpenCV answers in mm (the same answer ×1000); handeye does the
    same with units="mm", and without it refuses with a message that names units="mm"."""
    flange, camera, _, _ = cell(44, n=20)
    flange, camera = on_a_binary_grid(flange), on_a_binary_grid(camera)
    R_g, t_g, R_t, t_t = opencv_inputs(flange, camera)
    t_g_mm, t_t_mm = [1000 * t for t in t_g], [1000 * t for t in t_t]
    R_cv, t_cv = cv2.calibrateHandEye(R_g, t_g, R_t, t_t, method=cv2.CALIB_HAND_EYE_TSAI)
    R_cv_mm, t_cv_mm = cv2.calibrateHandEye(R_g, t_g_mm, R_t, t_t_mm, method=cv2.CALIB_HAND_EYE_TSAI)
    assert np.allclose(t_cv_mm, 1000 * t_cv, atol=1e-6) and np.allclose(R_cv_mm, R_cv, atol=1e-9)
    R, t = handeye.calibrateHandEye(R_g, t_g, R_t, t_t, verdict=False)
    R_mm, t_mm = handeye.calibrateHandEye(R_g, t_g_mm, R_t, t_t_mm, units="mm", verdict=False)
    assert np.max(np.abs(t_mm - 1000 * t)) < 1e-9 and np.max(np.abs(R_mm - R)) < 1e-9
    with pytest.raises(handeye.InputError, match=r'millimetres given as metres.*units="mm"'):
        handeye.calibrateHandEye(R_g, t_g_mm, R_t, t_t_mm)
    # Robot-world: both translations in mm.
    base2gripper = [on_a_binary_grid(inverse(T)) for T in flange]
    R_b = [T[:3, :3] for T in base2gripper]
    t_b = [T[:3, 3:4] for T in base2gripper]
    out = handeye.calibrateRobotWorldHandEye(R_t, t_t, R_b, t_b, verdict=False)
    out_mm = handeye.calibrateRobotWorldHandEye(R_t, t_t_mm, R_b, [1000 * t for t in t_b], units="mm", verdict=False)
    for i in (1, 3):
        assert np.max(np.abs(out_mm[i] - 1000 * out[i])) < 1e-9


def test_mixed_units_are_still_refused_with_units_mm(cv2):
    """units="mm" with the robot in mm but the board poses still in metres: the solver's units
    check names the mismatch, where OpenCV answers it silently, wrong in either unit."""
    flange, camera, truth, _ = cell(45, n=20)
    flange_mm = flange.copy()
    flange_mm[:, :3, 3] *= 1000
    R_g, t_g, R_t, t_t = opencv_inputs(flange_mm, camera)
    R_cv, t_cv = cv2.calibrateHandEye(R_g, t_g, R_t, t_t)
    as_metres = errors(as_matrix(R_cv, t_cv), truth)[1]
    as_mm = errors(as_matrix(R_cv, t_cv / 1000), truth)[1]
    assert min(as_metres, as_mm) > 10.0, (as_metres, as_mm)
    message = r"translations are not in metres: robot and camera translations disagree in scale.*\(read with units=\"mm\", converted to metres: give every translation, robot and camera, in mm\)"
    with pytest.raises(handeye.InputError, match=message):
        handeye.calibrate(flange_mm, camera, units="mm")
    with pytest.raises(handeye.InputError, match=message):
        handeye.calibrateHandEye(R_g, t_g, R_t, t_t, units="mm")
    with pytest.raises(handeye.InputError, match=r"units `cm`: expected `m`"):
        handeye.calibrate(flange, camera, units="cm")


# --- the wrong call shapes ------------------------------------------------------------------


def test_calibrate_given_the_four_lists_of_calibrateHandEye_names_it():
    flange, camera, _, _ = quiet_cell(46)
    R_g, t_g, R_t, t_t = opencv_inputs(flange, camera)
    with pytest.raises(TypeError, match=r"handeye\.calibrateHandEye\(R_gripper2base, t_gripper2base, R_target2cam, t_target2cam\)") as error:
        handeye.calibrate(R_g, t_g, R_t, t_t)
    assert "(N, 4, 4)" in str(error.value) and "4 positional arguments" in str(error.value)
    with pytest.raises(TypeError, match=r"calibrateHandEye"):
        handeye.calibrate(R_g, t_g, R_t)


def test_calibrate_given_rotation_translation_pairs_names_calibrateHandEye():
    flange, camera, _, _ = quiet_cell(46)
    R_g, t_g, R_t, t_t = opencv_inputs(flange, camera)
    with pytest.raises(handeye.InputError, match=r"T_base_flange must be an \(N, 4, 4\) array .* found a list of pairs \(T_base_flange\[0\] holds two arrays, \(3, 3\) and \(3, 1\).*handeye\.calibrateHandEye\(R_gripper2base"):
        handeye.calibrate(list(zip(R_g, t_g)), list(zip(R_t, t_t)))
    # Stacked 3x3 rotations alone, or 3x4 [R|t]: the shape and the same pointer.
    with pytest.raises(handeye.InputError, match=r"found shape \(20, 3, 3\); calibrate takes two \(N, 4, 4\) stacks.*calibrateHandEye"):
        handeye.calibrate(np.array(R_g), camera)
    with pytest.raises(handeye.InputError, match=r"found shape \(20, 3, 4\).*calibrateHandEye"):
        handeye.calibrate(flange[:, :3], camera)


# --- the namespace --------------------------------------------------------------------------


def test_the_namespace_holds_the_package_names_only():
    public = [name for name in dir(handeye) if not name.startswith("_")]
    assert sorted(public) == sorted(handeye.__all__), set(public) ^ set(handeye.__all__)
    for name in ("np", "Optional", "Sequence"):
        assert name not in dir(handeye)
    assert issubclass(handeye.CalibrationWarning, UserWarning)
