//! Pose space against reprojection space on the same rendered frames; resume from the records;
//! locks and sessions whose every pose was rejected.

use super::*;

/// Summed errors of both unknowns against the truth over seeded runs of the demo cell with the
/// given config edits, on the same frames: `[pose space, reprojection]` × `(mm, °)`.
fn both_spaces_over_seeds(
    seeds: std::ops::RangeInclusive<u64>,
    edits: &[(&str, &str)],
) -> [(f64, f64); 2] {
    let mut sums = [(0.0, 0.0); 2];
    for seed in seeds {
        let dir = tempfile::tempdir().unwrap();
        let (camera_seed, robot_seed, plan_seed) = (
            format!("seed: {}", 10 + seed),
            format!("seed: {}", 20 + seed),
            format!("seed: {seed}}}"),
        );
        let mut all = vec![
            ("seed: 11", camera_seed.as_str()),
            ("seed: 7", robot_seed.as_str()),
            ("seed: 1}", plan_seed.as_str()),
        ];
        all.extend_from_slice(edits);
        let config = config_variant(dir.path(), "sim-cell.yaml", &all);
        let prepared = cell::prepare(&config).unwrap();
        assert_eq!(
            prepared.config.solver.space,
            handeye_config::SolveSpace::Reprojection
        );
        let folder = SessionFolder::create(&dir.path().join("s")).unwrap();
        run(&prepared, &folder).unwrap();
        let solved = handeye_records::solve_folder(&folder, &prepared.solve_inputs()).unwrap();
        assert!(solved.reprojection.is_some());
        let truth = prepared.config.camera().simulation.unwrap();
        for (sum, answer) in sums
            .iter_mut()
            .zip([&solved.pose_space, &solved.calibration])
        {
            for (estimate, truth) in [
                (answer.camera_mount, truth.camera_mount),
                (answer.target_mount, truth.target_mount),
            ] {
                let (mm, deg) = pose_error_mm_deg(&estimate, &truth);
                sum.0 += mm;
                sum.1 += deg;
            }
        }
    }
    sums
}

/// Issue 8's comparison on rendered frames, the demo cell (the default solve space, the noise
/// estimated from the residuals), on the same frames: the fit over every corner, weighing each
/// robot pose by what the residuals show, is closer to the truth than the pose-space answer.
/// With the board printed without Kalibr's corner squares (edge-fitted corners, the regime issue
/// 8 measured: 0.88x translation, 0.82x rotation over these 16 seeds, per seed 0.55x-1.38x) it
/// must win by 5 %; with the squares (saddle-point corners, about 4x less corner noise, so the
/// arm's repeatability dominates both answers) the two come close in translation — measured
/// 0.966x / 0.775x — and the reprojection answer must still be no worse.
#[test]
fn reprojection_space_beats_pose_space_in_the_demo_cell() {
    for (board, margin) in [
        ("aprilgrid-6x6-no-corner-squares.yaml", 0.95),
        ("aprilgrid-6x6.yaml", 1.0),
    ] {
        let [pose, reprojection] = both_spaces_over_seeds(1..=16, &[("aprilgrid-6x6.yaml", board)]);
        let ratio = (reprojection.0 / pose.0, reprojection.1 / pose.1);
        eprintln!(
            "demo cell ({board}), 16 seeds, summed errors of both unknowns: pose space {:.3} mm {:.4}°, reprojection {:.3} mm {:.4}°, ratio {:.3} / {:.3}",
            pose.0, pose.1, reprojection.0, reprojection.1, ratio.0, ratio.1
        );
        assert!(
            ratio.0 < margin && ratio.1 < margin,
            "{board}: reprojection / pose-space error ratio {:.3} mm, {:.3}° (margin: < {margin} each)",
            ratio.0,
            ratio.1
        );
    }
}

/// The same where the corner noise dominates (an exact arm, a noisy sensor, 14 poses): measured
/// 0.50x translation, 0.63x rotation over these 4 seeds.
#[test]
fn reprojection_space_beats_pose_space_on_the_same_rendered_frames_when_pixels_dominate() {
    let [pose, reprojection] = both_spaces_over_seeds(
        1..=4,
        &[
            ("count: 20", "count: 14"),
            ("repeatability_mm: 0.02", "repeatability_mm: 0.0"),
            ("repeatability_deg: 0.002", "repeatability_deg: 0.0"),
            ("noise_sigma: 2.0", "noise_sigma: 8.0"),
        ],
    );
    let ratio = (reprojection.0 / pose.0, reprojection.1 / pose.1);
    eprintln!(
        "pixel noise dominating, 4 seeds: pose space {:.3} mm {:.4}°, reprojection {:.3} mm {:.4}°, ratio {:.3} / {:.3}",
        pose.0, pose.1, reprojection.0, reprojection.1, ratio.0, ratio.1
    );
    assert!(
        ratio.0 < 0.75 && ratio.1 < 0.9,
        "reprojection / pose-space error ratio {:.3} mm, {:.3}° (margin: < 0.75, < 0.9)",
        ratio.0,
        ratio.1
    );
}

fn library_run(
    config: Option<&Path>,
    target: cell::run::SessionTarget,
) -> Result<cell::run::CellRun, cell::run::RunError> {
    cell::run::run(
        &cell::run::RunRequest {
            config: config.map(Path::to_path_buf),
            target,
            motion_confirmed: false,
            accept_changed: false,
            stop: Arc::new(AtomicBool::new(false)),
            jobs: None,
        },
        cell::run::Strategy::Planned,
        &mut util::QuietObserver,
    )
}

fn copy_session(from: &Path, to: &Path) {
    for sub in ["", "poses", "frames"] {
        std::fs::create_dir_all(to.join(sub)).unwrap();
        for entry in std::fs::read_dir(from.join(sub)).unwrap() {
            let entry = entry.unwrap();
            if entry.path().is_file() && entry.file_name() != ".lock" {
                std::fs::copy(entry.path(), to.join(sub).join(entry.file_name())).unwrap();
            }
        }
    }
}

fn sample_ids(folder: &Path) -> Vec<String> {
    handeye_records::dataset::Dataset::load(&folder.join("samples.yaml"))
        .unwrap()
        .pairs
        .iter()
        .map(|p| p.id.clone().unwrap())
        .collect()
}

/// Issue #13 item 8: a resume checks the committed records — a phantom plan index, a second
/// record of one pose and an invalid rotation are refused naming the record file (not the
/// frame); a sample without a pose record is dropped when the resume rebuilds `samples.yaml`
/// (and a solve before that says the two disagree).
#[test]
fn resume_checks_the_records_and_rebuilds_the_samples_from_them() {
    let dir = tempfile::tempdir().unwrap();
    let config = config_variant(dir.path(), "sim-cell.yaml", &[("count: 20", "count: 6")]);
    let original = dir.path().join("s");
    let done = library_run(
        Some(&config),
        cell::run::SessionTarget::New(original.clone()),
    )
    .unwrap();
    drop(done);
    let all: Vec<String> = (0..6).map(|i| format!("pose-{i:03}")).collect();
    assert_eq!(sample_ids(&original), all);
    let resume = |name: &str| {
        library_run(
            None,
            cell::run::SessionTarget::Resume(dir.path().join(name)),
        )
        .err()
        .map(|e| format!("{:#}", anyhow::Error::from(e)))
    };

    // A phantom record: plan index 999 of a 6-pose plan.
    copy_session(&original, &dir.path().join("phantom"));
    let text = std::fs::read_to_string(original.join("poses/003.yaml")).unwrap();
    std::fs::write(
        dir.path().join("phantom/poses/999.yaml"),
        text.replace("plan_index: 3", "plan_index: 999"),
    )
    .unwrap();
    let message = resume("phantom").expect("a phantom record is refused");
    assert!(
        message.contains("poses/999.yaml")
            && message.contains("plan_index")
            && message.contains("not a pose of the session's plan"),
        "{message}"
    );

    // A duplicate: pose 3's record also under pose 4's name.
    copy_session(&original, &dir.path().join("duplicate"));
    std::fs::write(dir.path().join("duplicate/poses/004.yaml"), &text).unwrap();
    let message = resume("duplicate").expect("a duplicate record is refused");
    assert!(
        message.contains("poses/004.yaml")
            && message.contains("does not match the record's file name"),
        "{message}"
    );

    // A zero quaternion in pose 5's record is blamed on that record.
    copy_session(&original, &dir.path().join("zero"));
    let record = dir.path().join("zero/poses/005.yaml");
    let mut yaml: serde_yaml_ng::Value =
        serde_yaml_ng::from_str(&std::fs::read_to_string(&record).unwrap()).unwrap();
    let pose = yaml
        .get_mut("T_base_flange")
        .unwrap()
        .as_mapping_mut()
        .unwrap();
    pose.remove("rotation_vector");
    pose.insert(
        "quaternion".into(),
        serde_yaml_ng::from_str("{w: 0.0, x: 0.0, y: 0.0, z: 0.0}").unwrap(),
    );
    std::fs::write(&record, serde_yaml_ng::to_string(&yaml).unwrap()).unwrap();
    let message = resume("zero").expect("a zero quaternion is refused");
    assert!(
        message.contains("poses/005.yaml") && message.contains("quaternion"),
        "{message}"
    );
    assert!(!message.contains("frames/005.png"), "{message}");
    let prepared = cell::prepare(&config).unwrap();
    let replay = cell::replay::redetect(
        &SessionFolder::open(&dir.path().join("zero")).unwrap(),
        &prepared.camera().board,
        &prepared.camera().camera_model,
        prepared.detector_options(),
        1.0,
    )
    .err()
    .unwrap()
    .to_string();
    assert!(replay.contains("poses/005.yaml"), "{replay}");

    // A sample without a pose record: the record of pose 5 is gone, samples.yaml still has it.
    let orphan = dir.path().join("orphan");
    copy_session(&original, &orphan);
    std::fs::remove_file(orphan.join("poses/005.yaml")).unwrap();
    let message = handeye_records::solve_folder(
        &SessionFolder::open(&orphan).unwrap(),
        &prepared.solve_inputs(),
    )
    .err()
    .expect("samples.yaml and the records disagree")
    .to_string();
    assert!(
        message.contains("pose-005") && message.contains("--resume"),
        "{message}"
    );
    // The resume revisits pose 5 and the samples hold every pose once.
    let resumed = library_run(None, cell::run::SessionTarget::Resume(orphan.clone())).unwrap();
    assert_eq!(resumed.outcome.visited_now, 1);
    assert_eq!(sample_ids(&orphan), all);
}

/// Issue #13 item 8: when every pose is rejected the run says so, with the reasons, instead of
/// "samples.yaml: cannot read: No such file".
#[test]
fn every_pose_rejected_says_so_instead_of_a_missing_samples_file() {
    let dir = tempfile::tempdir().unwrap();
    let config = config_variant(
        dir.path(),
        "sim-cell.yaml",
        &[
            ("count: 20", "count: 6"),
            (
                "seed: 11",
                "seed: 11\n  hide_board_in_grabs: [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11]",
            ),
            // Every pose of the plan (generated plans are adaptive by default).
            ("plan:\n", "plan:\n  adaptive: false\n"),
        ],
    );
    let error = library_run(
        Some(&config),
        cell::run::SessionTarget::New(dir.path().join("s")),
    )
    .err()
    .expect("nothing to solve");
    let message = error.to_string();
    assert!(
        matches!(
            error,
            cell::run::RunError::Session(SessionError::NoSamples { visited: 6, .. })
        ),
        "{message}"
    );
    assert!(
        message.contains("every one rejected") && message.contains("pose 0: "),
        "{message}"
    );
    assert!(!message.contains("cannot read"), "{message}");
}

/// Issue #13 item 2, in one process: a folder a run holds cannot be created or resumed again
/// until that run lets go.
#[test]
fn a_session_folder_in_use_is_locked_until_released() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("s");
    let first = SessionFolder::create(&root).unwrap();
    assert!(first.is_locked());
    let pid = std::process::id().to_string();
    for error in [
        SessionFolder::create(&root).unwrap_err(),
        SessionFolder::resume(&root).unwrap_err(),
    ] {
        let message = error.to_string();
        assert!(matches!(error, SessionError::Locked { .. }), "{message}");
        assert!(message.contains(&pid), "{message}");
    }
    let clone = first.clone();
    drop(first);
    assert!(
        matches!(
            SessionFolder::create(&root),
            Err(SessionError::Locked { .. })
        ),
        "a clone keeps the lock"
    );
    drop(clone);
    // Released: a new run may use the (still empty) folder.
    SessionFolder::create(&root).unwrap();
}

/// Session, sample and result files carry `schema_version: 1`; files without it (written before)
/// still load; a file of a newer version is refused, by the library and the binary, with a
/// message that says so instead of a misreading.
#[test]
fn files_carry_a_schema_version_and_a_newer_one_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let config = util::sim_cell(dir.path(), 8);
    let out = dir.path().join("session");
    let run = util::run_cell(&config, &out);
    drop(run);
    for file in [
        "session.yaml",
        "poses/000.yaml",
        "samples.yaml",
        "result.yaml",
    ] {
        let text = std::fs::read_to_string(out.join(file)).unwrap();
        assert!(
            text.lines().any(|l| l == "schema_version: 1"),
            "{file} holds no schema_version:\n{text}"
        );
    }
    // Without the key (as every file written before it): read as version 1.
    let unversioned = |file: &str| {
        let path = out.join(file);
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::write(&path, text.replace("schema_version: 1\n", "")).unwrap();
    };
    for file in [
        "session.yaml",
        "poses/000.yaml",
        "samples.yaml",
        "result.yaml",
    ] {
        unversioned(file);
    }
    let folder = SessionFolder::open(&out).unwrap();
    assert_eq!(folder.read_manifest().unwrap().plan.len(), 8);
    assert!(!folder.read_visits().unwrap().is_empty());
    handeye_records::dataset::Dataset::load(&folder.samples_path()).unwrap();
    handeye_records::result::ResultFile::load_mounts(&out.join("result.yaml")).unwrap();
    drop(folder);
    // A newer version: refused, naming the file and the version.
    let newer = |file: &str| {
        let path = out.join(file);
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::write(&path, format!("schema_version: 2\n{text}")).unwrap();
    };
    newer("result.yaml");
    let export = util::handeye()
        .arg("export")
        .arg(out.join("result.yaml"))
        .args(["--format", "json"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&export.stderr);
    assert!(!export.status.success(), "a newer result was exported");
    assert!(
        stderr.contains("result.yaml")
            && stderr.contains("schema_version 2")
            && stderr.contains("newer handeye"),
        "{stderr}"
    );
    newer("session.yaml");
    let resume = util::handeye()
        .args(["run", "--resume"])
        .arg(&out)
        .arg("--yes")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&resume.stderr);
    assert!(!resume.status.success(), "a newer session was resumed");
    assert!(
        stderr.contains("session.yaml") && stderr.contains("schema_version 2"),
        "{stderr}"
    );
}
