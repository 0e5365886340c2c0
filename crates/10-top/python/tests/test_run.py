"""`handeye.run`: a cell run from Python through the library code `handeye run` calls, on the
simulated cell (configs/sim-cell.yaml): it recovers the simulator's truth, records what the CLI
records, reports progress as events, and Ctrl-C (a KeyboardInterrupt) mid-run keeps the samples
recorded so far in a session that resumes."""

import os
import signal
import threading
import warnings

import numpy as np
import pytest

import handeye
from conftest import REPO
from synth import errors, inverse, transform

CONFIG = REPO / "configs" / "sim-cell.yaml"
# The tolerance the Rust tests hold the simulated cell to (tests/it/bag_import.rs, boards.rs).
TOLERANCE_MM, TOLERANCE_DEG = 0.5, 0.05


def assert_truth_recovered(session):
    truth = session.truth
    assert set(truth) == {"T_flange_camera", "T_base_target"}
    for name, T in truth.items():
        rot, trans = errors(session.result.transforms[name], T)
        assert trans < TOLERANCE_MM and rot < TOLERANCE_DEG, f"{name}: {trans:.3f} mm, {rot:.4f}°"


def test_run_recovers_the_simulated_truth_with_progress_events(tmp_path):
    events = []
    with warnings.catch_warnings():
        warnings.simplefilter("error", handeye.CalibrationWarning)  # GOOD: no warning
        session = handeye.run(CONFIG, out=tmp_path / "session", progress=events.append)
    assert isinstance(session, handeye.Session) and session.path == tmp_path / "session"
    assert session.verdict.level == "GOOD", session.verdict.reason
    assert (session.path / "report.html").is_file(), "the run's report, as `handeye run` writes it"
    assert_truth_recovered(session)
    kinds = [e["event"] for e in events]
    assert kinds[:2] == ["plan_checked", "started"], kinds
    # The loop's end after its last record (notes about the run may follow).
    assert "ended" in kinds and kinds.index("ended") > len(kinds) - 1 - kinds[::-1].index("recorded"), kinds
    assert "poses" in events[1] and "report" in events[0]
    moving = [e for e in events if e["event"] == "moving"]
    assert moving and all(e["T_base_flange"].shape == (4, 4) for e in moving)
    accepted = [e for e in events if e["event"] == "recorded" and e["rejected"] is None]
    assert len(accepted) == len(session.samples["T_base_flange"])
    assert all(e["reprojection_rms_px"] < 1.0 and e["tags"] > 0 for e in accepted)


THREE_CAMERAS = REPO / "configs" / "sim-cell-three-cameras.yaml"


def test_a_cell_with_several_cameras_runs_to_its_joint_answer_and_report(tmp_path):
    """The three-camera simulated cell: `handeye.run` gives the session `out` names (not one
    camera's folder inside it), with the joint answer of every camera and board within the
    tolerance of the simulator's truth, each camera's own session, and the report the CLI
    writes; what is each camera's is refused at the cell's level, naming where it is."""
    out = tmp_path / "three"
    session = handeye.run(THREE_CAMERAS, out=out)
    assert session.path == out and session.setup is None
    assert list(session.cameras) == ["wrist", "left", "right"]
    joint = session.joint
    # The simulator's truth read from the config itself, not from what the run wrote.
    import yaml

    config = yaml.safe_load(THREE_CAMERAS.read_text())
    pose = lambda p: transform(p["rotation_vector"], p["translation"])  # noqa: E731
    mounts = {c["name"]: pose(c["simulation"]) for c in config["cameras"]}
    truth = {
        "T_flange_cam_wrist": mounts["wrist"],
        "T_base_cam_left": mounts["left"],
        "T_base_cam_right": mounts["right"],
        "T_base_target": pose(config["simulation"]["T_base_target"]),
        "T_flange_target": pose(config["simulation"]["T_flange_target"]),
        "T_cam_left_cam_right": inverse(mounts["left"]) @ mounts["right"],
    }
    assert set(joint["transforms"]) == set(truth) == set(joint["truth_error"])
    for name, T in truth.items():
        rot, trans = errors(joint["transforms"][name], T)
        assert trans < TOLERANCE_MM and rot < TOLERANCE_DEG, f"{name}: {trans:.3f} mm, {rot:.4f}°"
        # The run's own figure against the truth says the same.
        said = joint["truth_error"][name]
        assert abs(said["translation_mm"] - trans) < 1e-3 and abs(said["rotation_deg"] - rot) < 1e-4, (name, said, trans, rot)
    assert session.verdict.level == joint["verdict"].level == "GOOD", joint["verdict"].reason
    assert set(joint["verdicts"]) == {"wrist", "left", "right"}
    assert (out / "report.html").is_file()
    wrist = session.cameras["wrist"]
    assert wrist.setup == "eye_in_hand" and session.cameras["left"].setup == "eye_to_hand"
    assert len(wrist.samples["T_base_flange"]) == 20 and wrist.joint is None
    # Each camera's folder is a one-camera session of the same poses, solved alone with the
    # session's config as that camera sees it (its setup, board and lens): as `solve()` below
    # says to. It refused the listed config before.
    import warnings

    for name, key in (("wrist", "T_flange_camera"), ("left", "T_base_camera"), ("right", "T_base_camera")):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", handeye.CalibrationWarning)
            alone = session.cameras[name].solve()
        rot, trans = errors(alone.transforms[key], mounts[name])
        assert trans < 1.0 and rot < 0.1, f"{name} alone: {trans:.3f} mm, {rot:.4f}°"
    with pytest.raises(handeye.InputError, match=r'`solve\(\)` is each camera\'s, session.cameras\["wrist"\].solve\(\)'):
        session.solve()
    with pytest.raises(handeye.InputError, match=r'has 3 cameras \(wrist, left, right\): `result` is each camera\'s, session.cameras\["wrist"\].result; the joint answer is session.joint'):
        session.result
    assert handeye.Session(out).joint["transforms"].keys() == joint["transforms"].keys()
    # The cell's result.yaml is no one camera's Calibration: read_result says where it is read.
    with pytest.raises(handeye.InputError, match=r"a several-camera result: read it with handeye.Session\(.*three.*\), whose .joint"):
        handeye.read_result(out / "result.yaml")


def test_a_list_of_one_camera_is_read_as_the_one_camera_session(tmp_path):
    """The simulated cell written as a `cameras:` list of one camera runs to the answer of its
    one-camera form, to the bit, and its session (`rig.yaml` at `out`) reads as that camera's:
    samples, result, verdict and `solve()` (issue #37: the old form read as a list of one)."""
    import yaml

    config = yaml.safe_load(CONFIG.read_text())
    for key in ("target", "intrinsics"):
        config[key] = str(CONFIG.parent / config[key])
    config["plan"]["generate"]["count"] = 8
    one = tmp_path / "one.yaml"
    one.write_text(yaml.safe_dump(config))
    listed = dict(config)
    listed["cameras"] = [{
        "name": "wrist",
        "setup": listed.pop("setup"),
        "intrinsics": listed.pop("intrinsics"),
        "camera": listed.pop("camera"),
        "nominal": listed["nominal"].pop("T_flange_camera"),
        "simulation": listed["simulation"].pop("T_flange_camera"),
    }]
    (tmp_path / "listed.yaml").write_text(yaml.safe_dump(listed))
    theirs = handeye.run(one, out=tmp_path / "one")
    ours = handeye.run(tmp_path / "listed.yaml", out=tmp_path / "listed")
    assert ours.path == tmp_path / "listed" and (ours.path / "rig.yaml").is_file()
    assert ours.setup == "eye_in_hand" and ours.verdict.level == theirs.verdict.level == "GOOD"
    for key in ("T_base_flange", "T_camera_target"):
        assert np.array_equal(ours.samples[key], theirs.samples[key]), key
    for name, T in theirs.result.transforms.items():
        assert np.array_equal(ours.result.transforms[name], T), name
    assert_truth_recovered(ours)
    assert (ours.path / "result.yaml").read_bytes() == (theirs.path / "result.yaml").read_bytes()
    assert np.array_equal(ours.solve().transforms["T_flange_camera"], theirs.solve().transforms["T_flange_camera"])


def test_run_records_and_solves_what_the_cli_does(sim_session, tmp_path):
    """The same config through `handeye run` (the sim_session fixture) and `handeye.run`: the
    same samples and the same answer (the simulator is seeded)."""
    ours = handeye.run(CONFIG, out=tmp_path / "session")
    theirs = handeye.Session(sim_session)
    for key in ("T_base_flange", "T_camera_target"):
        assert np.array_equal(ours.samples[key], theirs.samples[key]), key
    for name, T in theirs.result.transforms.items():
        assert np.max(np.abs(ours.result.transforms[name] - T)) < 1e-9, name
    assert ours.verdict.level == theirs.verdict.level and ours.verdict.reason == theirs.verdict.reason


def test_an_interrupt_from_the_progress_callback_keeps_the_samples_and_the_session_resumes(tmp_path):
    out = tmp_path / "session"
    accepted = []

    def progress(event):
        if event["event"] == "recorded" and event["rejected"] is None:
            accepted.append(event["plan_index"])
            if len(accepted) == 4:
                raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt, match=r"\(4 poses recorded\); the arm was stopped; .*handeye\.run\(resume=") as error:
        handeye.run(CONFIG, out=out, progress=progress)
    assert error.value.session_folder == out
    # The samples so far are on disk, unsolved, as after the CLI's Ctrl-C.
    kept = handeye.Session(out)
    ids = kept.samples["ids"]
    assert len(ids) == len(kept.samples["T_base_flange"]) == 4
    assert kept.result is None
    # ... and the session resumes to the end.
    session = handeye.run(resume=out)
    assert len(session.samples["T_base_flange"]) > 4
    assert session.samples["ids"][:4] == ids
    assert_truth_recovered(session)


def test_ctrl_c_while_the_cell_runs_stops_it_cleanly(tmp_path):
    """A real SIGINT, sent from another thread while the run holds no GIL (as Ctrl-C arrives):
    Python's handler runs from the progress path and the run stops with its samples kept."""
    out = tmp_path / "session"
    accepted = []
    sent = threading.Event()
    # Python's own Ctrl-C handler, whatever this process inherited: a shell that starts the
    # suite in the background without job control has SIGINT ignored, and Python then keeps it
    # ignored (the signal would be lost, not raised).
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)

    def interrupt():
        os.kill(os.getpid(), signal.SIGINT)
        sent.set()

    def progress(event):
        if event["event"] == "recorded" and event["rejected"] is None:
            accepted.append(event["plan_index"])
            if len(accepted) == 2:
                threading.Timer(0.0, interrupt).start()
                return
        # On a loaded machine the timer's thread may not have run before the (fast, simulated)
        # run ends: it must send the signal while the run goes on. Waiting lets it take the GIL.
        if len(accepted) >= 2 and not sent.is_set():
            sent.wait(5.0)

    try:
        with pytest.raises(KeyboardInterrupt) as error:
            handeye.run(CONFIG, out=out, progress=progress)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert error.value.session_folder == out
    # Stopped at the next event: a move (the samples are the ones seen) or the next record's
    # callback, interrupted before it counted the sample already written.
    recorded = len(handeye.Session(out).samples["T_base_flange"])
    assert recorded >= 2 and len(accepted) <= recorded <= len(accepted) + 1, (recorded, accepted)
    assert handeye.Session(out).result is None


def test_run_refuses_what_it_cannot_do(tmp_path):
    with pytest.raises(handeye.InputError, match=r"a new session needs a cell config"):
        handeye.run(out=tmp_path / "x")
    with pytest.raises(handeye.InputError, match=r"out and resume given"):
        handeye.run(CONFIG, out=tmp_path / "x", resume=tmp_path / "y")
    with pytest.raises(handeye.HandeyeError, match=r"running the cell: preparing the cell"):
        handeye.run(tmp_path / "missing.yaml", out=tmp_path / "x")


def strict_config(tmp_path):
    """configs/sim-cell.yaml asking for 0.001 mm and 0.0001°: a verdict that cannot be GOOD."""
    text = CONFIG.read_text()
    for key in ("target: ", "intrinsics: "):
        text = text.replace(f"\n{key}", f"\n{key}{CONFIG.parent}/", 1)
    path = tmp_path / "strict-cell.yaml"
    path.write_text(text + "\nverdict: {accuracy_mm: 0.001, accuracy_deg: 0.0001}\n")
    return path


def test_a_session_solve_and_a_run_whose_verdict_is_not_good_warn_once(sim_session, tmp_path):
    config = strict_config(tmp_path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cal = handeye.Session(sim_session).solve(space="pose", config=config)
        session = handeye.run(config, out=tmp_path / "session")
    found = [w for w in caught if issubclass(w.category, handeye.CalibrationWarning)]
    assert len(found) == 2, [str(w.message) for w in caught]
    for warning, verdict in zip(found, [cal.verdict, session.verdict]):
        assert verdict.level in ("CHECK", "REDO")
        assert warning.message.verdict.reason == verdict.reason and verdict.next_action in str(warning.message)
        assert "0.001 mm" in verdict.reason, verdict.reason
        assert warning.filename == __file__, warning.filename
