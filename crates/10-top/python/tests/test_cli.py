"""The same answers as the CLI on the same data, to 1e-9: `handeye solve` on a dataset file
and on a session folder, against `handeye.calibrate` and `handeye.Session(...).solve` on the
same samples. The CLI's result file is read with PyYAML (not with handeye)."""

import re

import numpy as np
import pytest

import handeye
from synth import cell, record_matrix, write_dataset

TOL = 1e-9


def close(a, b, what):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape, what
    assert np.allclose(a, b, rtol=0, atol=TOL, equal_nan=True), f"{what}: {a} vs {b}"


def compare(calibration, result, pairs_count):
    """Every figure of a Calibration against the CLI's result file (a parsed YAML dict)."""
    assert calibration.setup == result["setup"]
    for name, matrix in calibration.transforms.items():
        close(matrix, record_matrix(result[name]), name)
    if result.get("uncertainty"):
        for name, sigma in calibration.sigma.items():
            for key in ("rotation_deg", "translation_mm", "rotation_axes_deg", "translation_axes_mm"):
                close(sigma[key], result["uncertainty"][name][key], f"sigma {name}.{key}")
        close(calibration.covariance, result["uncertainty"]["covariance"], "covariance")
    r = calibration.residuals
    for key in ("rotation_rms_deg", "rotation_max_deg", "translation_rms_mm", "translation_max_mm"):
        close(r[key], result["residuals"][key], key)
    samples = result["residuals"]["samples"]
    assert len(samples) == pairs_count
    for key in ("rotation_deg", "translation_mm", "normalised"):
        cli = [np.nan if s[key] is None else s[key] for s in samples]
        close(r[key], cli, f"per-sample {key}")
    assert calibration.outliers == result["outliers"]
    assert calibration.solver["method"] == result["solver"]["method"]
    assert calibration.solver["iterations"] == result["solver"]["iterations"]
    assert [n["message"] for n in calibration.notices] == [n["message"] for n in result["notices"]]
    if result.get("noise") is not None:
        for key in ("rotation_sigma_deg", "translation_sigma_mm"):
            close(calibration.noise[key], result["noise"][key], f"noise {key}")
    verdict = calibration.verdict
    assert verdict.level.lower() == result["verdict"]["level"]
    assert verdict.reason == result["verdict"]["reason"]
    assert verdict.next_action == result["verdict"]["next_action"]
    held_out = result["verdict"]["figures"].get("held_out")
    if held_out:
        for key in ("translation_rms_mm", "rotation_rms_deg", "working_distance_mm"):
            close(verdict.figures["held_out"][key], held_out[key], f"held-out {key}")


@pytest.mark.parametrize(
    "setup,method,seed",
    [("eye_in_hand", "refined", 1), ("eye_to_hand", "refined", 2), ("eye_in_hand", "tsai", 3), ("eye_in_hand", "iterative", 4)],
)
def test_calibrate_matches_cli_solve_on_a_dataset_file(cli, yaml, tmp_path, setup, method, seed):
    flange, camera, _, _ = cell(seed, n=20, setup=setup)
    ids = [f"p{i:02d}" for i in range(len(flange))]
    dataset = tmp_path / "samples.yaml"
    write_dataset(dataset, setup, flange, camera, ids)
    out = tmp_path / "result.yaml"
    cli("solve", dataset, "-o", out, "--method", method)
    result = yaml.safe_load(out.read_text())

    calibration = handeye.calibrate(flange, camera, setup, method=method, ids=ids)
    compare(calibration, result, len(flange))
    assert calibration.ids == ids

    # The file Calibration.save writes is the CLI's, number for number.
    mine = tmp_path / "mine.yaml"
    calibration.save(mine)
    saved = yaml.safe_load(mine.read_text())
    compare(calibration, saved, len(flange))
    assert saved.keys() == result.keys()


def test_explicit_noise_and_keep_outliers_match_the_cli(cli, yaml, tmp_path):
    flange, camera, _, _ = cell(5, n=15)
    camera[4] = camera[4] @ np.array([[1, 0, 0, 0.02], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    dataset = tmp_path / "samples.yaml"
    write_dataset(dataset, "eye_in_hand", flange, camera)
    out = tmp_path / "result.yaml"
    cli("solve", dataset, "-o", out, "--rotation-sigma-deg", "0.2", "--translation-sigma-mm", "1", "--keep-outliers")
    result = yaml.safe_load(out.read_text())
    calibration = handeye.calibrate(flange, camera, rotation_sigma_deg=0.2, translation_sigma_mm=1.0, keep_outliers=True)
    compare(calibration, result, len(flange))
    assert 4 in calibration.outliers


def test_read_dataset_and_read_result_give_the_files_numbers(cli, yaml, tmp_path):
    flange, camera, _, _ = cell(6, n=12)
    dataset = tmp_path / "samples.yaml"
    write_dataset(dataset, "eye_in_hand", flange, camera)
    read = handeye.read_dataset(dataset)
    assert read["setup"] == "eye_in_hand"
    close(read["T_base_flange"], flange, "T_base_flange")
    close(read["T_camera_target"], camera, "T_camera_target")
    out = tmp_path / "result.yaml"
    cli("solve", dataset, "-o", out)
    result = yaml.safe_load(out.read_text())
    back = handeye.read_result(out)
    for name, matrix in back.transforms.items():
        close(matrix, record_matrix(result[name]), name)
    assert back.verdict.reason == result["verdict"]["reason"]


@pytest.mark.parametrize("which", ["sim_session", "sim_session_eye_to_hand"])
def test_view_sigmas_weigh_the_samples_as_the_cli_weighs_them(cli, yaml, request, tmp_path, which):
    """A session records each view's precision with its sample; `read_dataset` gives it as
    `view_sigmas`, and `calibrate` given it answers what `handeye solve` answers of a dataset that
    records it. Without it (or with `weigh_views=False`) every view weighs alike, as
    `--every-view-alike`."""
    d = handeye.read_dataset(request.getfixturevalue(which) / "samples.yaml")
    sigmas = d["view_sigmas"]
    assert sigmas.shape == (len(d["ids"]), 2) and np.all(sigmas > 0), sigmas
    # The session's own numbers in the matrix form both sides read alike.
    args = (d["T_base_flange"], d["T_camera_target"], d["setup"])
    dataset = tmp_path / "samples.yaml"
    write_dataset(dataset, d["setup"], d["T_base_flange"], d["T_camera_target"], d["ids"], sigmas)
    solved = {}
    for flag in ([], ["--every-view-alike"]):
        out = tmp_path / f"result{len(flag)}.yaml"
        cli("solve", dataset, "-o", out, *flag)
        solved[bool(flag)] = yaml.safe_load(out.read_text())
    kwargs = dict(ids=d["ids"], weights=d["weights"], verdict=False)
    weighed = handeye.calibrate(*args, view_sigmas=sigmas, **kwargs)
    compare(weighed, solved[False], len(d["ids"]))
    for alike in (handeye.calibrate(*args, **kwargs), handeye.calibrate(*args, view_sigmas=sigmas, weigh_views=False, **kwargs)):
        compare(alike, solved[True], len(d["ids"]))
    # The two answers differ (by 9 µm and more), so the comparisons above tell them apart.
    differ = max(np.abs(weighed.transforms[n] - alike.transforms[n]).max() for n in weighed.transforms)
    assert differ > 1e3 * TOL, differ
    # A view of unknown precision (None or NaN) counts as a typical one; a bad figure is named.
    partly = [None if i % 3 == 0 else tuple(s) for i, s in enumerate(sigmas)]
    handeye.calibrate(*args, view_sigmas=partly, **kwargs)
    for bad, message in (((0.01, -0.2), "view_sigmas[4]: expected two positive figures (rotation_deg, translation_mm), got 0.01 and -0.2"), ((0.01,), "view_sigmas[4]")):
        rows = [tuple(s) for s in sigmas]
        rows[4] = bad
        with pytest.raises(handeye.InputError, match=re.escape(message)):
            handeye.calibrate(*args, view_sigmas=rows, **kwargs)
    with pytest.raises(handeye.InputError, match="view_sigmas has 3 entries"):
        handeye.calibrate(*args, view_sigmas=sigmas[:3], **kwargs)


def test_a_refused_solve_raises_the_cli_message(cli, tmp_path):
    flange, camera, _, _ = cell(7, n=2)
    dataset = tmp_path / "samples.yaml"
    write_dataset(dataset, "eye_in_hand", flange, camera)
    run = cli("solve", dataset, check=False)
    assert run.returncode != 0
    with pytest.raises(handeye.InputError) as error:
        handeye.calibrate(flange, camera)
    assert str(error.value) in run.stderr, run.stderr
    assert error.value.verdict.level == "REDO"
    assert f"verdict: REDO — {error.value.verdict.reason}" in run.stdout + run.stderr


@pytest.mark.parametrize("which", ["sim_session", "sim_session_eye_to_hand"])
def test_session_solve_matches_cli_solve_of_the_folder(cli, yaml, request, tmp_path, which):
    sim_session = request.getfixturevalue(which)
    session = handeye.Session(sim_session)
    for space in ("pose", "reprojection"):
        out = tmp_path / f"result-{space}.yaml"
        cli("solve", sim_session, "--space", space, "-o", out)
        result = yaml.safe_load(out.read_text())
        calibration = session.solve(space=space)
        pairs = len(session.samples["T_base_flange"])
        compare(calibration, result, pairs)
        if space == "reprojection":
            assert calibration.reprojection is not None
            assert calibration.reprojection["reprojection_rms_px"] < 0.5


def test_session_reads_what_the_run_wrote(yaml, sim_session):
    session = handeye.Session(sim_session)
    assert session.setup == "eye_in_hand"
    samples = yaml.safe_load((sim_session / "samples.yaml").read_text())["samples"]
    read = session.samples
    assert read["ids"] == [s["id"] for s in samples]
    for i, s in enumerate(samples):
        close(read["T_base_flange"][i], record_matrix(s["T_base_flange"]), f"T_base_flange[{i}]")
    result = yaml.safe_load((sim_session / "result.yaml").read_text())
    stored = session.result
    for name, matrix in stored.transforms.items():
        close(matrix, record_matrix(result[name]), name)
    assert session.verdict.level.lower() == result["verdict"]["level"]
    assert session.verdict.reason == result["verdict"]["reason"]
    # The simulated cell's ground truth, and the run's answer within a millimetre of it.
    truth = session.truth
    for name, matrix in stored.transforms.items():
        assert np.linalg.norm(matrix[:3, 3] - truth[name][:3, 3]) < 1e-3


@pytest.mark.parametrize(
    "text",
    [
        "setup: eye_in_hand\nsamples: [{T_base_flange: 3}]\n",
        "setup: hand_in_eye\nsamples: []\n",
        "setup: eye_in_hand\nsamples:\n  - T_base_flange: {translation: [0, 0, 0], quaternion: {w: 2, x: 0, y: 0, z: 0}}\n"
        "    T_camera_target: {translation: [0, 0, 1], rotation_vector: [0, 0, 0]}\n",
        "not: [a dataset\n",
    ],
)
def test_file_errors_have_the_cli_message(cli, tmp_path, text):
    dataset = tmp_path / "samples.yaml"
    dataset.write_text(text)
    run = cli("solve", dataset, check=False)
    assert run.returncode != 0
    with pytest.raises(handeye.InputError) as error:
        handeye.read_dataset(dataset)
    assert f"error: {error.value}" in run.stderr, (str(error.value), run.stderr)


def test_folder_errors_have_the_cli_message(cli, tmp_path):
    run = cli("solve", tmp_path, check=False)
    with pytest.raises(handeye.InputError) as error:
        handeye.Session(tmp_path)
    assert str(error.value) in run.stderr, (str(error.value), run.stderr)
    missing = tmp_path / "missing.yaml"
    run = cli("solve", missing, check=False)
    with pytest.raises(handeye.FileError) as error:
        handeye.read_dataset(missing)
    assert f"error: {error.value}" in run.stderr, (str(error.value), run.stderr)
