//! The right advice for the commonest real mistakes (issue #30): a board printed at another
//! scale than its file says, intrinsics that are not this camera's (the shipped placeholder, fx
//! 8 % off), an answer far from the nominal mount, degrees in a rotation vector and a tag size in
//! centimetres. Each mistake is made in the simulated cell (`camera: {target: …, intrinsics: …}`
//! renders the board and lens as they really are while the cell's files say otherwise), the
//! verdict must name that cause with its numbers, and the fix it names (`handeye replay DIR
//! --config fixed.yaml`) must then give GOOD.

use std::path::{Path, PathBuf};
use std::process::Output;

use handeye_records::result::ResultFile;
use handeye_solve::verdict::{Basis, Level, Verdict};

use crate::util::{self, config_variant, handeye, repo, run_cell};

fn text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// `configs/targets/aprilgrid-6x6.yaml` with `tagSize: <size>`, written to `dir/<name>`.
fn board_with_tag_size(dir: &Path, name: &str, size: f64) -> PathBuf {
    let text = std::fs::read_to_string(repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap();
    assert!(text.contains("tagSize: 0.04\n"));
    let path = dir.join(name);
    std::fs::write(
        &path,
        text.replace("tagSize: 0.04\n", &format!("tagSize: {size}\n")),
    )
    .unwrap();
    path
}

/// The sim cell with `poses` poses whose camera really sees `edits` (camera-section lines such as
/// `target: printed.yaml`), the cell's files unchanged.
fn cell_with(dir: &Path, name: &str, poses: usize, edits: &[(&str, &str)]) -> PathBuf {
    let count = format!("count: {poses}");
    let mut all: Vec<(&str, &str)> = vec![("count: 20", &count)];
    all.extend_from_slice(edits);
    config_variant(dir, "sim-cell.yaml", name, &all)
}

/// `handeye replay SESSION --config CONFIG`: its output, and the verdict it wrote.
fn replay(session: &Path, config: &Path) -> (String, Verdict) {
    let out = handeye()
        .arg("replay")
        .arg(session)
        .arg("--config")
        .arg(config)
        .output()
        .unwrap();
    let printed = text(&out);
    assert!(out.status.success(), "{printed}");
    let result = ResultFile::load(&session.join("replay-result.yaml")).unwrap();
    (printed, result.verdict.expect("replay writes a verdict"))
}

/// A board printed at `scale` of its file's size: the run's verdict names the scale (within
/// 0.5 % of the truth) and the fix; the replay with the measured tagSize is GOOD.
fn wrong_board_size(scale: f64, name: &str) {
    let dir = tempfile::tempdir().unwrap();
    let printed = board_with_tag_size(dir.path(), "printed.yaml", 0.04 * scale);
    let camera_target = format!("  target: {}\n  noise_sigma: 2.0", printed.display());
    let config = cell_with(
        dir.path(),
        "cell.yaml",
        16,
        &[("  noise_sigma: 2.0", &camera_target)],
    );
    let session = dir.path().join(name);
    let run = run_cell(&config, &session);
    let verdict = run
        .solved
        .as_ref()
        .unwrap()
        .verdict
        .clone()
        .expect("a verdict");
    eprintln!("{}", verdict.terminal_lines());
    assert_eq!(
        verdict.basis,
        Basis::BoardScale,
        "{}",
        verdict.terminal_lines()
    );
    assert!(
        verdict.level >= Level::Check,
        "{}",
        verdict.terminal_lines()
    );
    let fitted = verdict.figures.board_scale.expect("the fitted scale");
    eprintln!(
        "board printed at {scale}: fitted scale {fitted:.4} ± {:.4}",
        verdict.figures.board_scale_sigma.unwrap()
    );
    assert!(
        (fitted / scale - 1.0).abs() < 0.005,
        "fitted {fitted}, true {scale}"
    );
    let factor = format!("{fitted:.3}×");
    assert!(verdict.reason.contains(&factor), "{}", verdict.reason);
    assert!(verdict.reason.contains("printed at"), "{}", verdict.reason);
    let replay_command = format!("handeye replay {} --config", session.display());
    assert!(
        verdict.next_action.contains("tagSize") && verdict.next_action.contains(&replay_command),
        "{}",
        verdict.next_action
    );

    // The cell model wrote the board file with the estimated size into the session (#38), and it
    // reads as a board.
    let written = session.join("board.yaml");
    handeye_vision::Target::load(&written).expect("the corrected board file reads");
    let text = std::fs::read_to_string(&written).unwrap();
    let tag_size: f64 = text
        .lines()
        .find_map(|l| l.strip_prefix("tagSize:"))
        .and_then(|rest| rest.split('#').next())
        .and_then(|v| v.trim().parse().ok())
        .expect("tagSize in the corrected board file");
    assert!(
        (tag_size / (0.04 * scale) - 1.0).abs() < 0.005,
        "corrected tagSize {tag_size}, true {}",
        0.04 * scale
    );

    // The report shows the cell model's choice from the verdict: the explanation chosen, the
    // others with their BIC gap, the scale against the file's with its 1-sigma, the file written.
    let page = handeye_report::session::write_run_report(&run).unwrap();
    let report = std::fs::read_to_string(page).unwrap();
    let model = verdict.figures.cell_model.as_ref().expect("the cell model");
    let scale_row = model
        .estimates
        .iter()
        .find(|e| e.parameter == "scale")
        .map(|e| format!("{:.4} ± {:.4}", e.estimate, e.sigma))
        .unwrap();
    for expected in [
        "Cell model: the data choose <span data-key=\"cell_model.chosen\">board scale free</span>",
        "BIC above the chosen",
        "<td>files as given</td>",
        &scale_row,
        &format!("Corrected file written: <code>{}</code>", written.display()),
    ] {
        assert!(report.contains(expected), "{expected:?} not in the report");
    }

    // The fix: the cell's board file with the measured tag size, replayed.
    let fixed_board = board_with_tag_size(dir.path(), "measured.yaml", 0.04 * scale);
    let board_line = format!("target: {}", fixed_board.display());
    let fixed = config_variant(
        dir.path(),
        "sim-cell.yaml",
        "fixed.yaml",
        &[(
            &format!(
                "target: {}",
                repo().join("configs/targets/aprilgrid-6x6.yaml").display()
            ),
            &board_line,
        )],
    );
    // The run ends here, as `handeye run` exits: its lock goes with it (a replay of a session a
    // run still holds is refused, issue #44).
    drop(run);
    let (printed_out, after) = replay(&session, &fixed);
    eprintln!("{printed_out}");
    assert_eq!(after.level, Level::Good, "{}", after.terminal_lines());
    let after_scale = after.figures.board_scale.expect("the fitted scale");
    assert!((after_scale - 1.0).abs() < 0.005, "{after_scale}");
}

#[test]
fn a_board_printed_5_percent_small_is_named_with_its_scale_and_the_fix_is_good() {
    wrong_board_size(0.95, "small");
}

#[test]
fn a_board_printed_5_percent_large_is_named_with_its_scale_and_the_fix_is_good() {
    wrong_board_size(1.05, "large");
}

/// The sim cell as shipped keeps GOOD, with a fitted board scale of 1 within 0.5 %.
#[test]
fn a_board_of_the_right_size_is_not_called_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let config = util::sim_cell(dir.path(), 12);
    let run = run_cell(&config, &dir.path().join("session"));
    let verdict = run.solved.as_ref().unwrap().verdict.clone().unwrap();
    assert_eq!(verdict.level, Level::Good, "{}", verdict.terminal_lines());
    let s = verdict.figures.board_scale.unwrap();
    assert!((s - 1.0).abs() < 0.005, "{s}");
}

/// `handeye plan check --config CONFIG`: (exit code, all output).
fn plan_check(config: &Path) -> (Option<i32>, String) {
    let out = handeye()
        .args(["plan", "check", "--config"])
        .arg(config)
        .output()
        .unwrap();
    (out.status.code(), text(&out))
}

/// `rotation_vector: [0, 0, -90]` (degrees where radians belong) is refused when the config is
/// read, naming the file, the field and the two ways to write it; the same turn as `rpy_deg` is
/// read.
#[test]
fn degrees_in_a_rotation_vector_are_refused_at_load_and_rpy_deg_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let nominal =
        "T_flange_camera: {translation: [0.03, -0.07, 0.04], rotation_vector: [0.0, 0.0, 1.5708]}";
    let config = config_variant(
        dir.path(),
        "sim-cell.yaml",
        "degrees.yaml",
        &[(
            nominal,
            "T_flange_camera: {translation: [0.03, -0.07, 0.04], rotation_vector: [0, 0, 90]}",
        )],
    );
    let (code, out) = plan_check(&config);
    assert_eq!(code, Some(1), "{out}");
    for expected in [
        config.display().to_string().as_str(),
        "nominal.T_flange_camera.rotation_vector",
        "rotation vector [0, 0, 90] is 90.0 long, more than 2π: it looks like degrees",
        "radians ([0.0000, 0.0000, 1.5708])",
        "`rpy_deg: [roll, pitch, yaw]`",
    ] {
        assert!(out.contains(expected), "{expected:?} not in {out}");
    }
    assert!(!out.contains("panicked"), "{out}");
    let config = config_variant(
        dir.path(),
        "sim-cell.yaml",
        "rpy.yaml",
        &[(
            nominal,
            "T_flange_camera: {translation: [0.03, -0.07, 0.04], rpy_deg: [0, 0, 90]}",
        )],
    );
    let loaded = handeye_config::CellConfig::load(&config).unwrap();
    let angle = loaded.camera().nominal.camera_mount.rotation.scaled_axis();
    assert!((angle - nalgebra::Vector3::new(0.0, 0.0, 90f64.to_radians())).norm() < 1e-12);
}

/// `tagSize: 4` (centimetres) is refused when the board is read, before anything moves, naming
/// the board file, the key and the metres it likely means.
#[test]
fn a_tag_size_in_centimetres_is_refused_at_load() {
    let dir = tempfile::tempdir().unwrap();
    let board = dir.path().join("board-cm.yaml");
    let text = std::fs::read_to_string(repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap();
    std::fs::write(&board, text.replace("tagSize: 0.04\n", "tagSize: 4\n")).unwrap();
    let config = config_variant(
        dir.path(),
        "sim-cell.yaml",
        "cell.yaml",
        &[(
            &format!(
                "target: {}",
                repo().join("configs/targets/aprilgrid-6x6.yaml").display()
            ),
            &format!("target: {}", board.display()),
        )],
    );
    let (code, out) = plan_check(&config);
    assert_eq!(code, Some(1), "{out}");
    for expected in [
        format!("board file {}", board.display()),
        "`tagSize` must be the edge of a tag's black square in metres, 0.002–1 m, found 4 (that looks like centimetres: tagSize: 0.04 in metres)".to_string(),
    ] {
        assert!(out.contains(&expected), "{expected:?} not in {out}");
    }
    assert!(!out.contains("panicked"), "{out}");
}

/// A nominal mount 10 cm off the real one along the optical axis (a drawing of another bracket): the answer is right,
/// the verdict is CHECK with both values, and the replay with the nominal set right is GOOD.
#[test]
fn an_answer_10_cm_from_the_nominal_is_flagged_with_both_values() {
    let dir = tempfile::tempdir().unwrap();
    let nominal = "T_flange_camera: {translation: [0.03, -0.07, 0.04]";
    let config = cell_with(
        dir.path(),
        "cell.yaml",
        14,
        &[(
            nominal,
            "T_flange_camera: {translation: [0.03, -0.07, 0.14]",
        )],
    );
    let session = dir.path().join("session");
    let run = run_cell(&config, &session);
    let verdict = run.solved.as_ref().unwrap().verdict.clone().unwrap();
    // The run ends here, as `handeye run` exits: its lock goes with it (a replay of a
    // session a run still holds is refused, issue #44).
    drop(run);
    eprintln!("{}", verdict.terminal_lines());
    assert_eq!(
        (verdict.level, verdict.basis),
        (Level::Check, Basis::FarFromNominal),
        "{}",
        verdict.terminal_lines()
    );
    for expected in [
        // |[0.03, -0.07, 0.14] - truth [0.0312, -0.0694, 0.0447]| = 95.3 mm (along the optical
        // axis: the planned views stay centred on the board).
        "T_flange_camera is 95 mm and ",
        "nominal translation [0.030, -0.070, 0.140] m",
        "solved translation [0.031, -0.069, 0.04",
    ] {
        assert!(
            verdict.reason.contains(expected),
            "{expected:?} not in {}",
            verdict.reason
        );
    }
    assert!(
        verdict.next_action.contains(&format!(
            "handeye replay {} --config {}",
            session.display(),
            config.display()
        )),
        "{}",
        verdict.next_action
    );
    let fixed = cell_with(dir.path(), "fixed.yaml", 14, &[]);
    let (out, after) = replay(&session, &fixed);
    eprintln!("{out}");
    assert_eq!(after.level, Level::Good, "{}", after.terminal_lines());
}

// ---- intrinsics ------------------------------------------------------------------------------

/// The simulated lens's fx (`configs/cameras/sim-1280x720.yaml`), px.
const TRUE_FX: f64 = 800.0;

/// The sim cell (fixed plan of `poses`, so every visited frame stays in the folder) whose
/// `intrinsics:` is `lens` while its camera really has the simulated lens; `extra` edits after.
fn cell_with_lens(dir: &Path, name: &str, lens: &Path, extra: &[(&str, &str)]) -> PathBuf {
    let sim_lens = repo().join("configs/cameras/sim-1280x720.yaml");
    let cell_lens = format!("intrinsics: {}", sim_lens.display());
    let wrong_lens = format!("intrinsics: {}", lens.display());
    let camera_lens = format!("  intrinsics: {}\n  noise_sigma: 2.0", sim_lens.display());
    let mut edits: Vec<(&str, &str)> = vec![
        ("count: 20", "count: 14"),
        ("plan:\n", "plan:\n  adaptive: false\n"),
        (&cell_lens, &wrong_lens),
        ("  noise_sigma: 2.0", &camera_lens),
    ];
    edits.extend_from_slice(extra);
    config_variant(dir, "sim-cell.yaml", name, &edits)
}

/// The simulated lens with fx 8 % too long, written to `dir/fx8.yaml`.
fn lens_fx_8_percent_off(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(repo().join("configs/cameras/sim-1280x720.yaml")).unwrap();
    let from = "data: [800.0, 0.0, 641.3, 0.0, 800.0";
    assert!(text.contains(from));
    let path = dir.join("fx8.yaml");
    std::fs::write(
        &path,
        text.replace(from, "data: [864.0, 0.0, 641.3, 0.0, 800.0"),
    )
    .unwrap();
    path
}

/// A run of `config` into `session` that fails: its error, chain and all.
fn failed_run(config: &Path, session: &Path) -> String {
    match handeye_session::cell::run::run(
        &util::new_run(config, session),
        handeye_session::cell::run::Strategy::Planned,
        &mut util::QuietObserver,
    ) {
        Ok(_) => panic!("the run of {} succeeded", config.display()),
        Err(e) => {
            let mut message = e.to_string();
            let mut source = std::error::Error::source(&e);
            while let Some(s) = source {
                message.push_str(&format!(": {s}"));
                source = s.source();
            }
            message
        }
    }
}

/// The fix for intrinsics: the cell config with `intrinsics:` pointing at `lens`.
fn cell_with_intrinsics(dir: &Path, name: &str, lens: &Path) -> PathBuf {
    let sim_lens = repo().join("configs/cameras/sim-1280x720.yaml");
    config_variant(
        dir,
        "sim-cell.yaml",
        name,
        &[
            ("count: 20", "count: 14"),
            ("plan:\n", "plan:\n  adaptive: false\n"),
            (
                &format!("intrinsics: {}", sim_lens.display()),
                &format!("intrinsics: {}", lens.display()),
            ),
        ],
    )
}

/// The shipped placeholder lens file is refused before anything moves (no session folder),
/// naming the file and both fixes; `plan check` still checks views with it but warns; the fix
/// it names (drop `intrinsics:`, the run estimates them) is GOOD with fx within 0.5 %.
#[test]
fn the_placeholder_intrinsics_are_refused_before_the_arm_moves() {
    let dir = tempfile::tempdir().unwrap();
    let placeholder = repo().join("configs/cameras/CHANGE-ME-usb-camera-1280x720.yaml");
    let config = cell_with_lens(dir.path(), "cell.yaml", &placeholder, &[]);
    let session = dir.path().join("session");
    let message = failed_run(&config, &session);
    for expected in [
        placeholder.display().to_string(),
        "the intrinsics are the shipped placeholder (camera_name: CHANGE-ME-placeholder)".into(),
        "calibrate the camera".into(),
        format!("point `intrinsics:` in {}", config.display()),
        "or drop `intrinsics:` so the run estimates them".into(),
        "nothing was moved".into(),
    ] {
        assert!(message.contains(&expected), "{expected:?} not in {message}");
    }
    assert!(!session.exists(), "a session folder was made");
    let (code, out) = plan_check(&config);
    assert_eq!(code, Some(0), "{out}");
    assert!(
        out.contains("is the shipped placeholder (camera_name: CHANGE-ME-placeholder)")
            && out.contains("`handeye run` refuses it"),
        "{out}"
    );

    // The fix: no `intrinsics:`, estimated from the run.
    let text = std::fs::read_to_string(&config).unwrap();
    let fixed = dir.path().join("fixed.yaml");
    let line = format!("intrinsics: {}\n", placeholder.display());
    assert!(text.contains(&line));
    std::fs::write(&fixed, text.replace(&line, "")).unwrap();
    let run = run_cell(&fixed, &dir.path().join("fixed-session"));
    let verdict = run.solved.as_ref().unwrap().verdict.clone().unwrap();
    assert_eq!(verdict.level, Level::Good, "{}", verdict.terminal_lines());
    let fx = run.solved.as_ref().unwrap().estimated_camera.unwrap().fx;
    eprintln!("placeholder dropped: fx estimated {fx:.2} px (true {TRUE_FX})");
    assert!((fx / TRUE_FX - 1.0).abs() < 0.005, "fx {fx}");
}

/// Checks the advice for the lens with fx 8 % off, and that the estimate it wrote is the true
/// lens; returns the estimate's path.
fn assert_intrinsics_advice(text: &str, session: &Path, config: &Path, lens: &Path) -> PathBuf {
    let estimate = std::fs::canonicalize(session.join("camera_info.yaml"))
        .expect("the estimate is written into the session");
    for expected in [
        format!(
            "the intrinsics in {} do not fit this camera",
            lens.display()
        ),
        "fx in the file 864.0 px, estimated from this session 800.".into(),
        "(-7.4 %)".into(),
        format!(
            "set `intrinsics: {}` in {}",
            estimate.display(),
            config.display()
        ),
        format!(
            "`handeye replay {} --config {}`",
            session.display(),
            config.display()
        ),
    ] {
        assert!(text.contains(&expected), "{expected:?} not in {text}");
    }
    let estimated = handeye_core::camera_model::CameraModel::load(&estimate).unwrap();
    eprintln!(
        "fx 8 % off: estimated fx {:.2} fy {:.2} cx {:.2} cy {:.2} px (true 800, 800, 641.3, 358.7)",
        estimated.fx, estimated.fy, estimated.cx, estimated.cy
    );
    assert!(
        (estimated.fx / TRUE_FX - 1.0).abs() < 0.005,
        "{estimated:?}"
    );
    assert!((estimated.fy / 800.0 - 1.0).abs() < 0.005, "{estimated:?}");
    assert!((estimated.cx - 641.3).abs() < 2.0 && (estimated.cy - 358.7).abs() < 2.0);
    estimate
}

/// fx 8 % off: every frame's board RMS is far above the 1 px limit, so every pose is rejected;
/// the run's error says why with the numbers (not "check that the board is in view"), writes
/// the estimate into the session, and the replay with it is GOOD.
#[test]
fn intrinsics_8_percent_off_that_reject_every_pose_are_named_with_the_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let lens = lens_fx_8_percent_off(dir.path());
    let config = cell_with_lens(dir.path(), "cell.yaml", &lens, &[]);
    let session = dir.path().join("session");
    let message = failed_run(&config, &session);
    eprintln!("{message}");
    assert!(message.contains("every one rejected"), "{message}");
    assert!(
        !message.contains("check that the board is in view"),
        "{message}"
    );
    let estimate = assert_intrinsics_advice(&message, &session, &config, &lens);
    let fixed = cell_with_intrinsics(dir.path(), "fixed.yaml", &estimate);
    let (_, after) = replay(&session, &fixed);
    assert_eq!(after.level, Level::Good, "{}", after.terminal_lines());
}

/// The same lens file in an adaptive run (#38): a growing plan reuses the index of a rejected
/// pose, so its records were overwritten and the one left was too few to estimate the lens
/// from ("check that the board is in view"); the rejected records are kept aside
/// (`rejected/`) and the error names the intrinsics with the numbers and the estimate.
#[test]
fn intrinsics_8_percent_off_that_reject_every_pose_of_an_adaptive_plan_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let lens = lens_fx_8_percent_off(dir.path());
    let config = cell_with_lens(
        dir.path(),
        "cell.yaml",
        &lens,
        &[("  adaptive: false\n", "")],
    );
    let session = dir.path().join("session");
    let message = failed_run(&config, &session);
    eprintln!("{message}");
    assert!(
        !message.contains("check that the board is in view"),
        "{message}"
    );
    assert_intrinsics_advice(&message, &session, &config, &lens);
}

/// fx 8 % off with a board RMS limit loose enough to keep the frames: the verdict is REDO on
/// the intrinsics (not "record more poses"), with the numbers; the replay with the estimate is
/// GOOD.
#[test]
fn intrinsics_8_percent_off_are_the_verdicts_reason() {
    let dir = tempfile::tempdir().unwrap();
    let lens = lens_fx_8_percent_off(dir.path());
    let config = cell_with_lens(
        dir.path(),
        "cell.yaml",
        &lens,
        &[(
            "max_reprojection_rms_px: 1.0",
            "max_reprojection_rms_px: 20.0",
        )],
    );
    let session = dir.path().join("session");
    let run = run_cell(&config, &session);
    let verdict = run.solved.as_ref().unwrap().verdict.clone().unwrap();
    // The run ends here, as `handeye run` exits: its lock goes with it (a replay of a
    // session a run still holds is refused, issue #44).
    drop(run);
    eprintln!("{}", verdict.terminal_lines());
    assert_eq!(
        (verdict.level, verdict.basis),
        (Level::Redo, Basis::Intrinsics),
        "{}",
        verdict.terminal_lines()
    );
    let text = format!("{}\n{}", verdict.reason, verdict.next_action);
    let estimate = assert_intrinsics_advice(&text, &session, &config, &lens);
    let fixed = cell_with_intrinsics(dir.path(), "fixed.yaml", &estimate);
    let (_, after) = replay(&session, &fixed);
    assert_eq!(after.level, Level::Good, "{}", after.terminal_lines());
}
