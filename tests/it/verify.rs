//! `verify` in the simulated cell: holdout poses recorded with rendered frames, compared with
//! the prediction of a result; its errors must agree with the known error of that result
//! against the simulator's truth. And leave-one-out on a dataset finds a corrupted sample.

use std::path::PathBuf;

use handeye_core::geometry::{pose_from_rotvec, Pose};
use handeye_core::setup::{self, CellTransforms, PosePair, Setup};
use handeye_plan::GenerateSpec;
use handeye_session::cell;
use handeye_session::verify;
use handeye_solve::SolveOptions;
use nalgebra::Vector3;

use crate::util;

fn holdout(
    camera_mount: &Pose,
    target_mount: &Pose,
    dir: &std::path::Path,
) -> verify::Verification {
    let config = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("configs/sim-cell.yaml");
    let spec = GenerateSpec {
        count: 6,
        seed: 4242,
        ..cell::prepare(&config)
            .unwrap()
            .config
            .plan
            .generate
            .unwrap()
    };
    let calibration = CellTransforms {
        setup: Setup::EyeInHand,
        camera_mount: *camera_mount,
        target_mount: *target_mount,
    };
    let mut checked = verify::holdout(
        &util::new_run(&config, dir),
        &[("camera".to_string(), calibration)],
        None,
        &spec,
        &mut util::QuietObserver,
    )
    .unwrap();
    assert_eq!(checked.len(), 1);
    checked.remove(0).1
}

#[test]
fn holdout_errors_agree_with_the_known_error_of_the_result() {
    let config = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("configs/sim-cell.yaml");
    let truth = cell::prepare(&config)
        .unwrap()
        .config
        .camera()
        .simulation
        .unwrap();
    let dir = tempfile::tempdir().unwrap();

    // The true transforms: what is left is the measurement noise of a rendered board pose.
    let exact = holdout(
        &truth.camera_mount,
        &truth.target_mount,
        &dir.path().join("exact"),
    );
    eprintln!("{}", exact.table());
    assert!(
        exact.summary.poses >= 5,
        "{} holdout poses",
        exact.summary.poses
    );
    assert!(
        exact.summary.translation_rms_mm < 0.3 && exact.summary.rotation_rms_deg < 0.03,
        "with the true transforms: {:?}",
        exact.summary
    );

    // A result that is 2 mm and 0.3° off in T_flange_camera: each pose's error must be what that
    // known error predicts (camera of the true cell vs the wrong one), up to the noise above.
    let wrong_camera = truth.camera_mount
        * pose_from_rotvec(
            Vector3::new(0.002, 0.0, 0.0),
            Vector3::new(0.3f64.to_radians(), 0.0, 0.0),
        );
    let off = holdout(&wrong_camera, &truth.target_mount, &dir.path().join("off"));
    eprintln!("{}", off.table());
    let samples =
        handeye_records::dataset::Dataset::load(&dir.path().join("off/samples.yaml")).unwrap();
    for (e, pair) in off.poses.iter().zip(&samples.pairs) {
        let with_truth = truth.camera_from_target(&pair.base_from_flange);
        let with_result = setup::predict(
            Setup::EyeInHand,
            &wrong_camera,
            &truth.target_mount,
            &pair.base_from_flange,
        );
        let expected_mm =
            (with_result.translation.vector - with_truth.translation.vector).norm() * 1e3;
        let expected_deg = with_result
            .rotation
            .angle_to(&with_truth.rotation)
            .to_degrees();
        assert!(
            (e.translation_mm - expected_mm).abs() < 0.3,
            "pose {}: verify {:.3} mm, known error {:.3} mm",
            e.index,
            e.translation_mm,
            expected_mm
        );
        assert!(
            (e.rotation_deg - expected_deg).abs() < 0.03,
            "pose {}: verify {:.4}°, known error {:.4}°",
            e.index,
            e.rotation_deg,
            expected_deg
        );
        assert!(
            expected_mm > 1.0,
            "the perturbation must show: {expected_mm} mm"
        );
    }
}

#[test]
fn leave_one_out_points_at_a_corrupted_sample() {
    let camera_mount = pose_from_rotvec(
        Vector3::new(0.03, -0.07, 0.04),
        Vector3::new(0.02, -0.01, 1.56),
    );
    let target_mount = pose_from_rotvec(Vector3::new(0.5, -0.15, 0.0), Vector3::new(0.0, 0.0, 0.3));
    let mut pairs = Vec::new();
    for k in 0..12 {
        let a = k as f64;
        let view = pose_from_rotvec(
            Vector3::new(0.05 * (a * 0.7).sin(), 0.05 * (a * 1.3).cos(), 0.6),
            Vector3::new(
                std::f64::consts::PI + 0.4 * (a * 0.9).sin(),
                0.4 * (a * 1.7).cos(),
                0.5 * (a * 0.5).sin(),
            ),
        );
        // T_base_flange = T_base_target · T_target_camera · T_camera_flange
        let robot = target_mount * view.inverse() * camera_mount.inverse();
        pairs.push(PosePair::new(robot, view));
    }
    // Sample 5's board pose is off by 5 mm (e.g. a bad detection).
    pairs[5].camera_from_target.translation.vector += Vector3::new(0.005, 0.0, 0.0);
    let options = SolveOptions::default();
    let v = verify::leave_one_out(Setup::EyeInHand, &pairs, &options).unwrap();
    let worst = v
        .poses
        .iter()
        .max_by(|a, b| a.translation_mm.total_cmp(&b.translation_mm))
        .unwrap();
    assert_eq!(worst.index, 5, "{}", v.table());
    // Predicted from the 11 clean samples, sample 5 is off by the full 5 mm.
    assert!((worst.translation_mm - 5.0).abs() < 0.05, "{}", v.table());
    // The solve of every sample flags it: listed and marked, left out of the summary as the
    // calibration's own held-out check leaves it out, and named by a CHECK.
    assert_eq!(v.outliers, [5], "{}", v.table());
    assert_eq!(v.summary.poses, 11);
    assert!(v.summary.translation_max_mm < 0.05, "{}", v.table());
    let table = v.table();
    assert_eq!(
        table.matches("outlier (not in the RMS)").count(),
        1,
        "{table}"
    );
    let (level, line) = v.verdict(&Default::default());
    assert_eq!(level, handeye_solve::verdict::Level::Check, "{line}");
    assert!(line.contains("sample 5 is flagged as an outlier"), "{line}");
}

/// `handeye verify --config --result`: a holdout session recorded through the one run, its
/// table printed and `verify.yaml` written; a result of the other setup refused before the arm
/// moves.
#[test]
fn the_verify_command_records_a_holdout_session_and_refuses_the_wrong_setup() {
    let dir = tempfile::tempdir().unwrap();
    let config = util::sim_cell(dir.path(), 8);
    let session = dir.path().join("session");
    let run = util::handeye()
        .args(["run", "--yes", "--config"])
        .arg(&config)
        .arg("--output")
        .arg(&session)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let holdout = dir.path().join("holdout");
    let verify = util::handeye()
        .args(["verify", "--poses", "4", "--config"])
        .arg(&config)
        .arg("--result")
        .arg(session.join("result.yaml"))
        .arg("--output")
        .arg(&holdout)
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&verify.stdout);
    assert!(
        verify.status.success(),
        "{out}{}",
        String::from_utf8_lossy(&verify.stderr)
    );
    assert!(
        out.contains("translation at the target RMS") && out.contains("holdout session"),
        "{out}"
    );
    // The verdict on the held-out errors, against the config's accuracy (1 mm, 0.1°): the sim
    // cell's calibration is GOOD.
    assert!(
        out.contains("verdict: GOOD — holdout error") && out.contains("asked for"),
        "{out}"
    );
    assert!(holdout.join("verify.yaml").is_file() && holdout.join("samples.yaml").is_file());

    let other = util::config_variant(dir.path(), "sim-cell-eye-to-hand.yaml", "other.yaml", &[]);
    let refused = util::handeye()
        .args(["verify", "--config"])
        .arg(&other)
        .arg("--result")
        .arg(session.join("result.yaml"))
        .arg("--output")
        .arg(dir.path().join("refused"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success());
    assert!(
        err.contains("eye_in_hand") && err.contains("eye_to_hand"),
        "{err}"
    );
    assert!(
        !dir.path().join("refused").exists(),
        "nothing is recorded for the wrong setup"
    );
}

/// A run of the shipped sim cell whose `key` file (`intrinsics` or `target`) is `wrong` while
/// the simulated camera renders with the shipped one (`shipped`), into `dir/session`: (config,
/// session, the result's verdict).
fn run_with_a_wrong_file(
    dir: &std::path::Path,
    key: &str,
    shipped: &std::path::Path,
    wrong: &std::path::Path,
) -> (PathBuf, PathBuf, handeye_solve::verdict::Verdict) {
    let given = format!("{key}: {}", shipped.display());
    let config = util::config_variant(
        dir,
        "sim-cell.yaml",
        "cell.yaml",
        &[
            (&given, &format!("{key}: {}", wrong.display())),
            (
                "camera:\n  backend: sim\n",
                &format!("camera:\n  backend: sim\n  {given}\n"),
            ),
        ],
    );
    let session = dir.join("session");
    let run = util::run_cli(&config, &session);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    let verdict = handeye_records::result::ResultFile::load(&session.join("result.yaml"))
        .unwrap()
        .verdict
        .expect("a verdict");
    (config, session, verdict)
}

/// Asserts that a held-out run of `config` is refused before anything moves (exit 1, nothing
/// recorded), its error holding each of `named`; then that once `fix` has fixed the file as the
/// result says (returning the config to check with) it is GOOD.
fn holdout_refused_then_good(
    dir: &std::path::Path,
    session: &std::path::Path,
    config: &std::path::Path,
    named: &[&str],
    fix: impl FnOnce() -> PathBuf,
) {
    let wrong = dir.join("holdout-wrong");
    let refused = util::holdout_command(config, &session.join("result.yaml"), &wrong)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(1), "{stderr}");
    for expected in named.iter().chain(&["nothing was moved"]) {
        assert!(stderr.contains(expected), "{expected:?} not in {stderr}");
    }
    assert!(!wrong.exists(), "the refused check recorded a session");
    let checked = util::holdout_command(
        &fix(),
        &session.join("result.yaml"),
        &dir.join("holdout-fixed"),
    )
    .output()
    .unwrap();
    let stdout = String::from_utf8_lossy(&checked.stdout);
    assert!(
        checked.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&checked.stderr)
    );
    assert!(stdout.contains("verdict: GOOD — holdout error"), "{stdout}");
}

/// `verify --session` predicts each sample as the session's solve judged them, so its figure is
/// the run's held-out one: with an intrinsics file 8 % off in fx and fy (the simulated camera has
/// the shipped lens), the solve measures the board poses again with its estimate. The samples
/// as recorded (PnP with the wrong file) disagree by the file's error: verify called that REDO,
/// 4.9 mm, "a frame or robot pose recorded wrong", where the run's held-out figure was 0.05 mm.
/// A held-out run of that answer on the cell still giving the wrong file is refused before
/// anything moves, naming the file and the result's fix (it measured the fresh views with the
/// wrong file: REDO, 51 mm, "do not use this result"); with the file fixed as the result says,
/// it is GOOD.
#[test]
fn a_session_with_a_wrong_lens_file_is_verified_as_its_solve_judged_it() {
    let dir = tempfile::tempdir().unwrap();
    let shipped = util::repo().join("configs/cameras/sim-1280x720.yaml");
    let wrong = dir.path().join("wrong-lens.yaml");
    let text = std::fs::read_to_string(&shipped).unwrap();
    let off = "data: [864.0, 0.0, 641.3, 0.0, 864.0,";
    let lens = text.replace("data: [800.0, 0.0, 641.3, 0.0, 800.0,", off);
    assert!(lens.contains(off), "the shipped lens changed: {text}");
    std::fs::write(&wrong, lens).unwrap();
    let (config, session, verdict) =
        run_with_a_wrong_file(dir.path(), "intrinsics", &shipped, &wrong);
    assert_eq!(
        verdict.basis,
        handeye_solve::verdict::Basis::Intrinsics,
        "{}",
        verdict.reason
    );
    let held = verdict.figures.held_out.expect("the run's held-out figure");
    let stdout = util::succeeds(util::handeye().args(["verify", "--session"]).arg(&session));
    assert!(
        stdout.contains("measured them again with its estimate (intrinsics free)"),
        "{stdout}"
    );
    util::assert_leave_one_out_is_held_out(&stdout, &held);
    assert!(!stdout.contains("recorded wrong"), "{stdout}");

    // The fix the result names: the config's `intrinsics:` at the estimate it wrote.
    let fix = || {
        let fixed = dir.path().join("fixed.yaml");
        let text = std::fs::read_to_string(&config).unwrap().replace(
            &format!("intrinsics: {}", wrong.display()),
            &format!("intrinsics: {}", session.join("camera_info.yaml").display()),
        );
        std::fs::write(&fixed, text).unwrap();
        fixed
    };
    let named = format!(
        "the result found the intrinsics in {} wrong",
        wrong.display()
    );
    holdout_refused_then_good(
        dir.path(),
        &session,
        &config,
        &[&named, "camera_info.yaml"],
        fix,
    );
}

/// A held-out run of an answer that found the board file wrong (printed at 95 % of its file's
/// size) is refused before anything moves while the cell still gives that file as the session
/// recorded it (its sha256 in `session.yaml`): measured with it, the fresh views were REDO, 33 mm,
/// "do not use this result". With the file fixed in place it is GOOD.
#[test]
fn a_held_out_run_is_refused_while_the_cell_gives_the_board_file_its_answer_found_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let shipped = util::repo().join("configs/targets/aprilgrid-6x6.yaml");
    let board = dir.path().join("board.yaml");
    let text = std::fs::read_to_string(&shipped).unwrap();
    assert!(
        text.contains("tagSize: 0.04\n"),
        "the shipped board changed: {text}"
    );
    std::fs::write(&board, text.replace("tagSize: 0.04\n", "tagSize: 0.042\n")).unwrap();
    let (config, session, verdict) = run_with_a_wrong_file(dir.path(), "target", &shipped, &board);
    assert_eq!(
        verdict.basis,
        handeye_solve::verdict::Basis::BoardScale,
        "{}",
        verdict.reason
    );
    // Refused while the file is as the session recorded it; fixed in place, checked.
    let named = format!("the result found the board file {} wrong", board.display());
    let fix = || {
        std::fs::write(&board, &text).unwrap();
        config.clone()
    };
    holdout_refused_then_good(dir.path(), &session, &config, &[&named], fix);
}
