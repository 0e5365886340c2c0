//! Cell config validation (issues #12 item 2b, #13 items 5, 6, 11): every finding reproduced
//! exactly, each now refused at load with a message naming the file, the YAML key, the value and
//! the accepted range — before any session folder exists or anything moves.

use std::path::{Path, PathBuf};

use handeye_config::{CellConfig, ConfigError, ConfigFile, RobotConfig, SolverMethod};

use crate::util;
use util::handeye;

/// `handeye run` on `config` with `--output <dir>/session`: it must fail without creating the
/// session folder; returns its stderr.
fn run_is_refused(dir: &Path, config: &Path) -> String {
    let session = dir.join("session");
    let output = handeye()
        .args(["run", "--yes", "--config"])
        .arg(config)
        .arg("--output")
        .arg(&session)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(
        !output.status.success(),
        "run accepted the config: {stderr}"
    );
    assert!(
        !session.exists(),
        "a session folder was created for a refused config: {stderr}"
    );
    stderr
}

/// The load error of `config`, as the CLI prints it (`{:#}`: the whole chain).
fn load_error(config: &Path) -> String {
    match CellConfig::load(config) {
        Ok(_) => panic!("{} loaded", config.display()),
        Err(e) => format!("{:#}", anyhow::Error::new(e)),
    }
}

/// Asserts the message names the file once, the key, the value and the range.
fn assert_names(message: &str, file: &Path, key: &str, value: &str, range: &str) {
    let file = file.display().to_string();
    assert_eq!(
        message.matches(&file).count(),
        1,
        "the file is named exactly once: {message}"
    );
    for part in [key, value, range] {
        assert!(message.contains(part), "no {part:?} in: {message}");
    }
}

fn sim_variant(dir: &Path, edits: &[(&str, &str)]) -> PathBuf {
    util::config_variant(dir, "sim-cell.yaml", "cell.yaml", edits)
}

/// #13 item 5: `settle_s: 1e300` panicked converting to a Duration, after the session folder
/// was created.
#[test]
fn huge_settle_time_is_refused_at_load() {
    let dir = tempfile::tempdir().unwrap();
    let config = sim_variant(dir.path(), &[("settle_s: 0.0", "settle_s: 1e300")]);
    let message = load_error(&config);
    assert_names(
        &message,
        &config,
        "session.settle_s",
        "found 1e300",
        "[0, 60] s",
    );
    assert!(matches!(
        CellConfig::load(&config),
        Err(ConfigError::OutOfRange { ref key, .. }) if key == "session.settle_s"
    ));
    let stderr = run_is_refused(dir.path(), &config);
    assert!(
        stderr.contains("session.settle_s") && !stderr.contains("panicked"),
        "{stderr}"
    );
}

/// #13 item 6: `generate: {count: 100000000}` allocated 6.4 GB and aborted.
#[test]
fn huge_generated_plan_is_refused_at_load() {
    let dir = tempfile::tempdir().unwrap();
    let config = sim_variant(dir.path(), &[("count: 20", "count: 100000000")]);
    let message = load_error(&config);
    assert_names(
        &message,
        &config,
        "plan.generate.count",
        "found 100000000",
        "[3, 1000]",
    );
    let stderr = run_is_refused(dir.path(), &config);
    assert!(stderr.contains("plan.generate.count"), "{stderr}");
}

/// #13 item 6: `blur_sigma_px: 1e6` rendered for minutes.
#[test]
fn huge_blur_is_refused_at_load() {
    let dir = tempfile::tempdir().unwrap();
    let config = sim_variant(
        dir.path(),
        &[("blur_sigma_px: 0.5", "blur_sigma_px: 1000000")],
    );
    let message = load_error(&config);
    assert_names(
        &message,
        &config,
        "camera.blur_sigma_px",
        "found 1e6",
        "[0, 10] px",
    );
    run_is_refused(dir.path(), &config);
}

/// #13 item 6: no upper bound on decimation.
#[test]
fn huge_decimation_is_refused_at_load() {
    let dir = tempfile::tempdir().unwrap();
    let config = sim_variant(dir.path(), &[("decimate: 2", "decimate: 100")]);
    let message = load_error(&config);
    assert_names(
        &message,
        &config,
        "detector.decimate",
        "found 100",
        "[1, 16]",
    );
    run_is_refused(dir.path(), &config);
}

/// #13 item 11: `detector.max_hamming: 5` named neither file nor key, after the folder was
/// created.
#[test]
fn max_hamming_out_of_range_names_file_and_key_before_any_folder() {
    let dir = tempfile::tempdir().unwrap();
    let config = sim_variant(dir.path(), &[("max_hamming: 0", "max_hamming: 5")]);
    let message = load_error(&config);
    assert_names(
        &message,
        &config,
        "detector.max_hamming",
        "found 5",
        "[0, 2]",
    );
    let stderr = run_is_refused(dir.path(), &config);
    assert!(
        stderr.contains("cell.yaml") && stderr.contains("detector.max_hamming"),
        "{stderr}"
    );
}

/// #13 item 11: garbage YAML said "expected struct RawConfig".
#[test]
fn a_document_that_is_not_a_mapping_gets_a_sentence() {
    let dir = tempfile::tempdir().unwrap();
    for (text, found) in [
        ("just some words\n", "found a string"),
        ("- robot\n- camera\n", "found a list"),
        ("42\n", "found a number"),
        ("", "found an empty document"),
    ] {
        let config = dir.path().join("cell.yaml");
        std::fs::write(&config, text).unwrap();
        let message = load_error(&config);
        assert!(
            message.starts_with(&format!(
                "{}: expected a mapping of config keys (setup, target, robot, camera",
                config.display()
            )) && message.ends_with(found),
            "{text:?}: {message}"
        );
        assert!(!message.contains("RawConfig"), "{message}");
        run_is_refused(dir.path(), &config);
    }
}

/// #12: a misspelled `solver.method` fell back silently to `refined`.
#[test]
fn misspelled_solver_method_is_an_error_listing_the_accepted_names() {
    let dir = tempfile::tempdir().unwrap();
    let config = sim_variant(dir.path(), &[("method: refined", "method: iteretive")]);
    let message = load_error(&config);
    assert!(
        message.contains("cell.yaml")
            && message.contains("solver.method")
            && message.contains("iteretive"),
        "{message}"
    );
    assert_eq!(message.matches("solver.method").count(), 1, "{message}");
    for name in ["`refined`", "`iterative`", "`closed-form`"] {
        assert!(message.contains(name), "{name} not listed: {message}");
    }
    run_is_refused(dir.path(), &config);
    // Both spellings of the closed form still load.
    for spelling in ["closed-form", "closed_form"] {
        let config = sim_variant(
            dir.path(),
            &[("method: refined", &format!("method: {spelling}"))],
        );
        let loaded = CellConfig::load(&config).unwrap();
        assert_eq!(loaded.solver.method, SolverMethod::ClosedForm);
        assert_eq!(
            loaded.solver.to_options().method,
            handeye_solve::Method::ClosedForm
        );
    }
}

/// #13 item 11: "must be a list of 9 numbers, found - 800.0" read as −800.
#[test]
fn yaml_values_in_messages_are_shown_in_flow_style() {
    let dir = tempfile::tempdir().unwrap();
    let lens = util::repo().join("configs/cameras/sim-1280x720.yaml");
    let text = std::fs::read_to_string(lens).unwrap().replace(
        "data: [800.0, 0.0, 641.3, 0.0, 800.0, 358.7, 0.0, 0.0, 1.0]",
        "data: [800.0]",
    );
    let bad_lens = dir.path().join("lens.yaml");
    std::fs::write(&bad_lens, text).unwrap();
    let config = sim_variant(
        dir.path(),
        &[(
            "intrinsics: ",
            &format!("intrinsics: {}\n# was: ", bad_lens.display()),
        )],
    );
    let message = match handeye_session::cell::prepare(&config) {
        Ok(_) => panic!("a 1-number camera matrix loaded"),
        Err(e) => format!("{:#}", anyhow::Error::new(e)),
    };
    assert!(
        message.contains("camera_matrix.data") && message.contains("found [800.0]"),
        "{message}"
    );
    assert!(!message.contains("- 800"), "{message}");
    run_is_refused(dir.path(), &config);
}

/// A malformed pose's problem was printed twice by `{:#}` (message and source).
#[test]
fn a_bad_pose_is_reported_once() {
    let dir = tempfile::tempdir().unwrap();
    let config = sim_variant(
        dir.path(),
        &[(
            "T_flange_camera: {translation: [0.03, -0.07, 0.04]",
            "T_flange_camera: {translation: [0.03, -0.07]",
        )],
    );
    let message = load_error(&config);
    assert_eq!(
        message.matches("expected 3 numbers").count(),
        1,
        "{message}"
    );
    assert_names(
        &message,
        &config,
        "nominal.T_flange_camera.translation",
        "found 2",
        "3 numbers",
    );
}

/// Every numeric key has a range, checked at load with the key named (one out-of-range value
/// per key, on the sim and the real-cell configs).
#[test]
fn every_numeric_key_is_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let sim = [
        (
            "start_joints_deg: [0, -90",
            "start_joints_deg: [720, -90",
            "robot.start_joints_deg[0]",
            "found 720",
            "[-360, 360] °",
        ),
        (
            "move_duration_s: 0.0",
            "move_duration_s: 3600",
            "robot.move_duration_s",
            "found 3600",
            "[0, 60] s",
        ),
        (
            "repeatability_mm: 0.02",
            "repeatability_mm: -0.02",
            "robot.repeatability_mm",
            "found -0.02",
            "[0, 10] mm",
        ),
        (
            "repeatability_deg: 0.002",
            "repeatability_deg: 90",
            "robot.repeatability_deg",
            "found 90",
            "[0, 5] °",
        ),
        (
            "seed: 7",
            "seed: 7\n  protective_stop_after_moves: 100000000",
            "robot.protective_stop_after_moves",
            "found 100000000",
            "[0, 1e6] moves",
        ),
        (
            "noise_sigma: 2.0",
            "noise_sigma: 300",
            "camera.noise_sigma",
            "found 300",
            "[0, 64] grey levels",
        ),
        (
            "seed: 11",
            "seed: 11\n  hide_board_in_grabs: [1, 5000000]",
            "camera.hide_board_in_grabs[1]",
            "found 5000000",
            "[0, 1e6]",
        ),
        (
            "count: 20",
            "count: 2",
            "plan.generate.count",
            "found 2",
            "[3, 1000]",
        ),
        (
            "distance: [0.55, 0.75]",
            "distance: [0.55, 75000]",
            "plan.generate.distance",
            "found [0.55, 75000]",
            "far <= 10",
        ),
        (
            "max_tilt_deg: 30",
            "max_tilt_deg: 95",
            "plan.generate.max_tilt_deg",
            "found 95",
            "(0, 80)",
        ),
        (
            "max_roll_deg: 20",
            "max_roll_deg: 270",
            "plan.generate.max_roll_deg",
            "found 270",
            "[0, 180]",
        ),
        (
            "seed: 1}",
            "seed: 1, image_spread: 2}",
            "plan.generate.image_spread",
            "found 2",
            "[0, 1]",
        ),
        (
            "seed: 1}",
            "seed: 1}\n  target_uncertainty_mm: 0",
            "plan.target_uncertainty_mm",
            "found 0",
            "(0, 100] mm",
        ),
        (
            "linear_speed: 0.25",
            "linear_speed: 25",
            "limits.linear_speed",
            "found 25",
            "(0, 0.5] m/s",
        ),
        (
            "linear_acceleration: 1.0",
            "linear_acceleration: 1e3",
            "limits.linear_acceleration",
            "found 1000",
            "(0, 2] m/s²",
        ),
        (
            "joint_speed_deg: 60",
            "joint_speed_deg: 600",
            "limits.joint_speed_deg",
            "found 600",
            "(0, 90] °/s",
        ),
        (
            "joint_acceleration_deg: 120",
            "joint_acceleration_deg: 0",
            "limits.joint_acceleration_deg",
            "found 0",
            "(0, 180] °/s²",
        ),
        (
            "min: [-1.0, -1.0, 0.05]",
            "min: [-1.0, -1000, 0.05]",
            "workspace.min[1]",
            "found -1000",
            "[-10, 10] m",
        ),
        (
            "max: [1.2, 1.0, 1.3]",
            "max: [1.2, 1.0, .inf]",
            "workspace.max[2]",
            "found inf",
            "[-10, 10] m",
        ),
        (
            "threads: 1",
            "threads: 200",
            "detector.threads",
            "found 200",
            "a race in its worker pool",
        ),
        (
            "rotation_sigma_deg: 0.02",
            "rotation_sigma_deg: 45",
            "solver.rotation_sigma_deg",
            "found 45",
            "(0, 10] °",
        ),
        (
            "translation_sigma_mm: 0.2",
            "translation_sigma_mm: 0",
            "solver.translation_sigma_mm",
            "found 0",
            "(0, 100] mm",
        ),
        (
            "space: reprojection}",
            "space: reprojection, pixel_sigma_px: .nan}",
            "solver.pixel_sigma_px",
            "found NaN",
            "(0, 10] px",
        ),
        (
            "max_reprojection_rms_px: 1.0",
            "max_reprojection_rms_px: 1e9",
            "session.max_reprojection_rms_px",
            "found 1e9",
            "(0, 100] px",
        ),
        (
            "image_margin_px: 20",
            "image_margin_px: -5",
            "session.image_margin_px",
            "found -5",
            "[0, 1000] px",
        ),
    ];
    let real = [
        (
            "connect_timeout_s: 5",
            "connect_timeout_s: 86400",
            "robot.connect_timeout_s",
            "found 86400",
            "(0, 120] s",
        ),
        (
            "repeatability_mm: 0.03",
            "repeatability_mm: 0",
            "robot.repeatability_mm",
            "found 0",
            "(0, 10] mm",
        ),
        (
            "repeatability_deg: 0.003",
            "repeatability_deg: 30",
            "robot.repeatability_deg",
            "found 30",
            "(0, 5] °",
        ),
        (
            "width: 1280",
            "width: 0",
            "camera.width",
            "found 0",
            "[1, 16384] px",
        ),
        (
            "height: 720",
            "height: 100000",
            "camera.height",
            "found 100000",
            "[1, 16384] px",
        ),
        (
            "fps: 30",
            "fps: 5000",
            "camera.fps",
            "found 5000",
            "[1, 1000] frames/s",
        ),
        (
            "exposure_us: 8000",
            "exposure_us: 0",
            "camera.exposure_us",
            "found 0",
            "[1, 1e7] µs",
        ),
        (
            "focus: 0",
            "focus: 9999999",
            "camera.focus",
            "found 9999999",
            "[-1e6, 1e6] camera units",
        ),
        (
            "focus: 0",
            "focus: 0\n  gain: -9999999",
            "camera.gain",
            "found -9999999",
            "[-1e6, 1e6] camera units",
        ),
        (
            "focus: 0",
            "focus: 0\n  stale_frames: 1000",
            "camera.stale_frames",
            "found 1000",
            "[0, 100] frames",
        ),
        (
            "settle_s: 0.5",
            "settle_s: -1",
            "session.settle_s",
            "found -1",
            "[0, 60] s",
        ),
    ];
    for (base, cases) in [
        ("sim-cell.yaml", &sim[..]),
        ("ur-usb-camera-eye-in-hand.yaml", &real[..]),
    ] {
        for (from, to, key, value, range) in cases {
            let config = util::config_variant(dir.path(), base, "cell.yaml", &[(from, to)]);
            let message = load_error(&config);
            assert_names(&message, &config, key, value, range);
        }
    }
}

/// The shipped configs load unchanged; their numbers sit inside the ranges.
#[test]
fn shipped_configs_load() {
    let configs = util::repo().join("configs");
    let mut loaded = 0;
    for entry in std::fs::read_dir(&configs).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "yaml") {
            // One schema: a config of one camera or several (`cameras:`) loads as one CellConfig.
            let config = CellConfig::load(&path).unwrap_or_else(|e| panic!("{e:#}"));
            assert!(!config.cameras.is_empty());
            assert_eq!(config.settle().as_secs_f64(), config.session.settle_s);
            loaded += 1;
        }
    }
    assert!(loaded >= 5, "only {loaded} configs found");
}

/// #12: configs are written through serde: a written config loads back to the same shape, and
/// one that would not load is not written.
#[test]
fn configs_written_through_serde_load_back() {
    let dir = tempfile::tempdir().unwrap();
    let source = util::config_variant(dir.path(), "sim-cell.yaml", "source.yaml", &[]);
    let text = std::fs::read_to_string(&source).unwrap();
    let shape = ConfigFile::parse(&text, &source).unwrap();
    let written = dir.path().join("written.yaml");
    shape
        .save(&written, "A copy of the demo cell\nwritten by a test")
        .unwrap();
    let back = std::fs::read_to_string(&written).unwrap();
    assert!(
        back.starts_with("# A copy of the demo cell\n# written by a test\n"),
        "{back}"
    );
    assert_eq!(ConfigFile::parse(&back, &written).unwrap(), shape);
    let (a, b) = (
        CellConfig::load(&source).unwrap(),
        CellConfig::load(&written).unwrap(),
    );
    assert_eq!(
        a.camera().nominal.camera_mount,
        b.camera().nominal.camera_mount
    );
    assert_eq!(a.plan, b.plan);
    assert_eq!(a.solver, b.solver);
    assert!(matches!(b.robot, RobotConfig::Sim(_)));

    let mut broken = shape.clone();
    broken.workspace.min[0] = 5.0;
    let refused = dir.path().join("refused.yaml");
    let e = format!(
        "{:#}",
        anyhow::Error::new(broken.save(&refused, "").unwrap_err())
    );
    assert!(
        e.contains("refusing to write") && e.contains("workspace") && e.contains("min[0] = 5"),
        "{e}"
    );
    assert!(!refused.exists());
}

/// Errors inside a `backend:`-tagged section (`robot`, `camera`) name the key, not just the
/// section; closed sets of names (backend, arm model, pixel format) list what is accepted.
#[test]
fn errors_inside_backend_sections_name_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &str, &str, &str, &[&str]); 7] = [
        (
            "sim-cell.yaml",
            "model: ur10e",
            "model: ur11e",
            "robot.model",
            &["`ur11e`", "`ur5e`", "`ur10e`"],
        ),
        (
            "sim-cell.yaml",
            "backend: sim\n  model",
            "backend: simm\n  model",
            "robot.backend",
            &["`simm`", "`sim`", "`ur`", "`recorded`"],
        ),
        (
            "sim-cell.yaml",
            "blur_sigma_px: 0.5",
            "blur_sigma_px: lots",
            "camera.blur_sigma_px",
            &["invalid type", "lots"],
        ),
        (
            "sim-cell.yaml",
            "seed: 11",
            "seed: 11\n  exposure_us: 100",
            "camera.exposure_us",
            &["unknown field"],
        ),
        (
            "ur-usb-camera-eye-in-hand.yaml",
            "pixel_format: mjpeg",
            "pixel_format: h264",
            "camera.pixel_format",
            &["`h264`", "`mjpeg`", "`yuyv`", "`gray`"],
        ),
        (
            "ur-usb-camera-eye-in-hand.yaml",
            "  host: 192.168.1.10",
            "  hots: 192.168.1.10",
            "robot.hots",
            &["unknown field `hots`", "`host`"],
        ),
        (
            "ur-usb-camera-eye-in-hand.yaml",
            "  host: 192.168.1.10 ",
            "",
            "robot",
            &["missing field `host`"],
        ),
    ];
    for (base, from, to, key, parts) in cases {
        let config = util::config_variant(dir.path(), base, "cell.yaml", &[(from, to)]);
        let message = load_error(&config);
        assert!(
            message.starts_with(&format!("{}: {key}: ", config.display())),
            "expected key {key}: {message}"
        );
        for part in parts {
            assert!(message.contains(part), "no {part:?} in: {message}");
        }
    }
}

/// #12: `handeye import visp --cell-out` wrote its config with `format!`; now through serde,
/// and the written config loads as a recorded cell.
#[test]
fn imported_visp_folder_cell_config_is_written_through_serde_and_loads() {
    let Some(visp) = util::dataset("visp_franka_data-eye-to-hand") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let cell = dir.path().join("cell.yaml");
    let output = handeye()
        .args(["import", "visp"])
        .arg(&visp)
        .arg("--board")
        .arg(util::repo().join("configs/targets/single-tag36h11-id10.yaml"))
        .args(["--setup", "eye_to_hand", "-o"])
        .arg(dir.path().join("data.yaml"))
        .arg("--cell-out")
        .arg(&cell)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let text = std::fs::read_to_string(&cell).unwrap();
    assert!(text.starts_with("# Replays the ViSP folder "), "{text}");
    assert!(text.contains("joint_speed_deg: 30.0\n"), "{text}");
    let config = CellConfig::load(&cell).unwrap_or_else(|e| panic!("{e:#}"));
    assert!(matches!(config.robot, RobotConfig::Recorded(_)));
    assert!(matches!(
        config.camera().backend,
        handeye_config::CameraConfig::Files(ref files) if files.folder == std::fs::canonicalize(&visp).unwrap()
    ));
    assert_eq!(config.detector.decimate, 1.0);
    assert!(config.plan.file.is_none() && config.plan.generate.is_none());
}

/// A template copied elsewhere keeps its relative paths, which now point nowhere: the error
/// names the key, where the path was resolved and that paths are relative to the config's
/// folder (issue #30: it used to say only "cannot read").
#[test]
fn a_copied_config_whose_files_are_not_beside_it_says_paths_are_relative_to_it() {
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("my-cell.yaml");
    std::fs::copy(
        util::repo().join("configs/ur-usb-camera-eye-in-hand.yaml"),
        &copy,
    )
    .unwrap();
    let out = handeye()
        .args(["plan", "check", "--config"])
        .arg(&copy)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("my-cell.yaml: target: ")
            && err.contains("does not exist")
            && err.contains("relative to the config file's own folder")
            && err.contains(&dir.path().display().to_string()),
        "{err}"
    );
}

/// A UR model whose poses would be read in the driver's `base_link` (what RViz shows) is refused
/// at load naming the key and the fix: the plan, `nominal` and `workspace` of a UR model are in
/// the controller's `base`, and `base_link` is it turned 180° about z (issue #39: it ran to a
/// CHECK "179.8° from its nominal", and the export turned the answer a second time). Under a
/// prefix too; the default `base` loads.
#[test]
fn a_ur_model_read_in_base_link_is_refused_at_load_naming_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    for (frame, fix) in [
        ("base_link", "base_frame: base"),
        ("ur/base_link", "base_frame: ur/base"),
    ] {
        let config = util::config_variant(
            dir.path(),
            "ros2-sim-cell.yaml",
            "cell.yaml",
            &[("base_frame: base ", &format!("base_frame: {frame} "))],
        );
        let message = load_error(&config);
        assert!(
            message.contains("robot.base_frame")
                && message.contains(frame)
                && message.contains(fix)
                && message.contains("--base-frame"),
            "{message}"
        );
    }
    let config = util::config_variant(dir.path(), "ros2-sim-cell.yaml", "cell.yaml", &[]);
    let loaded = CellConfig::load(&config).unwrap();
    assert_eq!(loaded.robot.frames().base, "base");
}

/// `robot.flange_pose` of a ROS 2 arm: absent reads `tf`, `joints` is read, `joints` without a
/// model (nothing to compute the flange with) is refused naming the key and the fix, and an
/// unknown value names what is expected.
#[test]
fn a_ros2_arms_flange_pose_source_is_read_and_checked() {
    use handeye_config::ros2::FlangePose;
    let dir = tempfile::tempdir().unwrap();
    let flange_pose = |edits: &[(&str, &str)]| {
        let config = util::config_variant(dir.path(), "ros2-sim-cell.yaml", "cell.yaml", edits);
        CellConfig::load(&config).map(|c| match c.robot {
            RobotConfig::Ros2(r) => r.flange_pose,
            _ => unreachable!("a ros2 arm"),
        })
    };
    assert_eq!(flange_pose(&[]).unwrap(), FlangePose::Tf);
    let joints = (
        "  flange_frame: tool0",
        "  flange_frame: tool0\n  flange_pose: joints",
    );
    assert_eq!(flange_pose(&[joints]).unwrap(), FlangePose::Joints);
    let message = flange_pose(&[
        joints,
        ("  model: ur10e", "  model: none\n  joint_ranges_deg: [[-360, 360], [-360, 360], [-180, 180], [-360, 360], [-360, 360], [-360, 360]]"),
    ])
    .unwrap_err()
    .to_string();
    assert!(
        message.contains("robot.flange_pose") && message.contains("give `model`"),
        "{message}"
    );
    let message = flange_pose(&[(
        "  flange_frame: tool0",
        "  flange_frame: tool0\n  flange_pose: fk",
    )])
    .unwrap_err()
    .to_string();
    assert!(
        message.contains("flange_pose") && message.contains("joints"),
        "{message}"
    );
}

/// #41: with the arm's own model estimated (`solver.kinematics: joint_offsets | dh`) a generated
/// plan visits every pose by default (the adaptive stop weighs the transforms only, and stops
/// where the offsets are barely determined); `plan.adaptive: true` still asks for the adaptive
/// plan, and without the key (`auto`) the default stays adaptive.
#[test]
fn estimating_the_arms_model_makes_a_generated_plan_fixed_unless_adaptive_is_asked_for() {
    let dir = tempfile::tempdir().unwrap();
    let adaptive_of = |edits: &[(&str, &str)]| {
        let path = sim_variant(dir.path(), edits);
        CellConfig::load(&path).unwrap().adaptive()
    };
    assert!(adaptive_of(&[]), "the shipped sim cell is adaptive");
    for model in ["joint_offsets", "dh"] {
        let key = format!("space: reprojection, kinematics: {model}}}");
        assert!(
            !adaptive_of(&[("space: reprojection}", &key)]),
            "{model}: adaptive by default"
        );
        assert!(
            adaptive_of(&[
                ("space: reprojection}", &key),
                ("plan:\n", "plan:\n  adaptive: true\n")
            ]),
            "{model}: plan.adaptive: true is not honoured"
        );
    }
}

/// `solver.weigh_views` (default true) weighs each sample by its view's precision; `false` is
/// the old form (every view alike), one key away.
#[test]
fn the_solver_weighs_views_by_default_and_every_view_alike_is_one_key_away() {
    let dir = tempfile::tempdir().unwrap();
    let shipped = CellConfig::load(&util::repo().join("configs/sim-cell.yaml")).unwrap();
    assert!(shipped.solver.weigh_views && shipped.solver.to_options().weigh_views);
    let config = sim_variant(
        dir.path(),
        &[(
            "drop_outliers: true",
            "drop_outliers: true, weigh_views: false",
        )],
    );
    let loaded = CellConfig::load(&config).unwrap();
    assert!(!loaded.solver.weigh_views && !loaded.solver.to_options().weigh_views);
}
