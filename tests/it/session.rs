//! The simulated cell end to end: rendered frames, real detection, the real solver, the session
//! driver with its records, faults, resume and replay.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use handeye::cell::{self, PreparedCell};
use handeye::session::{self, SessionError, SessionEvent, SessionFolder, SessionOutcome};
use handeye::setup::CellTransforms;

use crate::util;

use util::{pose_error_mm_deg, repo};

fn config_variant(dir: &Path, base: &str, edits: &[(&str, &str)]) -> PathBuf {
    util::config_variant(dir, base, base, edits)
}

fn run(prepared: &PreparedCell, folder: &SessionFolder) -> Result<SessionOutcome, SessionError> {
    let plan = prepared.report.validated().expect("plan passes its checks");
    if folder.read_manifest().is_err() {
        folder.write_manifest(&prepared.manifest(&plan)).unwrap();
    }
    let mut hardware = prepared.open_hardware().unwrap();
    let setup = prepared.session_setup(folder.clone(), plan, Arc::new(AtomicBool::new(false)));
    session::run_session(
        setup,
        hardware.robot.as_mut(),
        hardware.camera.as_mut(),
        &mut |_e: SessionEvent| {},
    )
}

fn assert_recovers_truth(solved: &session::SolvedSession, truth: &CellTransforms) {
    let [(camera_key, camera_mount), (target_key, target_mount)] = solved.calibration.unknowns();
    for (key, estimate, truth) in [
        (camera_key, camera_mount, truth.camera_mount),
        (target_key, target_mount, truth.target_mount),
    ] {
        let (mm, deg) = pose_error_mm_deg(&estimate, &truth);
        eprintln!("{key}: {mm:.3} mm, {deg:.4} deg from the truth");
        assert!(
            mm < 0.5 && deg < 0.05,
            "{key}: {mm:.3} mm, {deg:.4}° (limits 0.5 mm, 0.05°)"
        );
    }
}

fn full_run(config: &Path, out: &Path) -> (PreparedCell, SessionFolder, session::SolvedSession) {
    let prepared = cell::prepare(config).unwrap();
    assert!(prepared.report.ok(), "{}", prepared.report);
    let folder = SessionFolder::create(out).unwrap();
    let outcome = run(&prepared, &folder).unwrap();
    assert_eq!(
        outcome.accepted.len(),
        prepared.plan.waypoints.len(),
        "skipped: {:?}",
        outcome.skipped
    );
    let solved = session::solve_folder(&folder, &prepared.solve_inputs()).unwrap();
    (prepared, folder, solved)
}

#[test]
fn eye_in_hand_sim_cell_recovers_the_ground_truth() {
    let dir = tempfile::tempdir().unwrap();
    let config = repo().join("configs/sim-cell.yaml");
    let (prepared, folder, solved) = full_run(&config, &dir.path().join("s"));
    assert_recovers_truth(&solved, prepared.config.simulation.as_ref().unwrap());
    assert!(folder.result_path().is_file());
    // Every pose left its frame and record on disk.
    for i in 0..prepared.plan.waypoints.len() {
        assert!(folder.root().join(format!("frames/{i:03}.png")).is_file());
        assert!(folder.root().join(format!("poses/{i:03}.yaml")).is_file());
    }

    eprintln!(
        "{}\n{}",
        solved.summary,
        solved.compare_with_truth(prepared.config.simulation.as_ref().unwrap())
    );
    // Replay re-detects the saved frames and reproduces the result (both answers).
    let (dataset, visits) = session::replay::redetect(
        &folder,
        &prepared.board,
        &prepared.camera_model,
        prepared.detector_options(),
        prepared.config.session.max_reprojection_rms_px,
    )
    .unwrap();
    let again = handeye::solve::solve(
        dataset.setup,
        &dataset.pairs,
        &prepared.config.solver.to_options(),
    )
    .unwrap();
    let again_both = session::solve_session(
        dataset.setup,
        &dataset.pairs,
        &visits,
        Some((&prepared.board, &prepared.camera_model)),
        &prepared.config,
    )
    .unwrap();
    assert!(again_both.reprojection.is_some());
    // The replayed pose-space answer equals the run's; so does the reprojection answer when the
    // run's solve space computed one.
    let reprojection_pairs = solved.reprojection.is_some().then(|| {
        again_both
            .calibration
            .unknowns()
            .into_iter()
            .zip(solved.calibration.unknowns())
    });
    let pairs = again
        .unknowns()
        .into_iter()
        .zip(solved.pose_space.unknowns())
        .chain(
            again_both
                .pose_space
                .unknowns()
                .into_iter()
                .zip(solved.pose_space.unknowns()),
        )
        .chain(reprojection_pairs.into_iter().flatten());
    for ((key, a), (_, b)) in pairs {
        let (a, b) = (&a, &b);
        let (mm, deg) = pose_error_mm_deg(a, b);
        assert!(
            mm < 1e-6 && deg < 1e-6,
            "replay of {key} differs by {mm} mm, {deg}°"
        );
    }
}

#[test]
fn eye_to_hand_sim_cell_recovers_the_ground_truth() {
    let dir = tempfile::tempdir().unwrap();
    let config = repo().join("configs/sim-cell-eye-to-hand.yaml");
    let (prepared, _, solved) = full_run(&config, &dir.path().join("s"));
    assert_recovers_truth(&solved, prepared.config.simulation.as_ref().unwrap());
}

#[test]
fn hidden_board_poses_are_retried_then_skipped_and_the_run_still_succeeds() {
    let dir = tempfile::tempdir().unwrap();
    // 14 poses: grabs 0..13 are the first pass; grab 3 and 8 are hidden, and so is grab 14, the
    // retry of pose 3 (retries come after the pass, in order) — so pose 3 is skipped and pose 8
    // succeeds on its retry.
    let config = config_variant(
        dir.path(),
        "sim-cell.yaml",
        &[
            ("count: 20", "count: 14"),
            ("seed: 11", "seed: 11\n  hide_board_in_grabs: [3, 8, 14]"),
        ],
    );
    let prepared = cell::prepare(&config).unwrap();
    let folder = SessionFolder::create(&dir.path().join("s")).unwrap();
    let outcome = run(&prepared, &folder).unwrap();
    assert_eq!(
        outcome.skipped.iter().map(|(i, _)| *i).collect::<Vec<_>>(),
        vec![3]
    );
    assert!(
        outcome.skipped[0].1.to_lowercase().contains("no tag")
            || outcome.skipped[0].1.to_lowercase().contains("not found"),
        "reason: {}",
        outcome.skipped[0].1
    );
    assert_eq!(outcome.accepted.len(), 13);
    assert!(outcome.accepted.contains(&8));
    let solved = session::solve_folder(&folder, &prepared.solve_inputs()).unwrap();
    let [(_, camera_mount), _] = solved.calibration.unknowns();
    let (mm, deg) = pose_error_mm_deg(
        &camera_mount,
        &prepared.config.simulation.unwrap().camera_mount,
    );
    assert!(mm < 1.0 && deg < 0.1, "{mm} mm {deg}°");
}

#[test]
fn protective_stop_keeps_the_data_and_resume_finishes() {
    let dir = tempfile::tempdir().unwrap();
    let config = config_variant(
        dir.path(),
        "sim-cell.yaml",
        &[
            ("count: 20", "count: 12"),
            ("seed: 7", "seed: 7\n  protective_stop_after_moves: 5"),
        ],
    );
    let prepared = cell::prepare(&config).unwrap();
    let out = dir.path().join("s");
    let folder = SessionFolder::create(&out).unwrap();
    let error = run(&prepared, &folder).unwrap_err();
    let message = error.to_string();
    assert!(matches!(error, SessionError::Robot { .. }), "{message}");
    assert!(message.contains("--resume"), "{message}");
    let kept = folder.read_visits().unwrap();
    assert_eq!(kept.len(), 5, "the five poses before the stop are on disk");

    // The person clears the stop; resuming (a fresh process: new robot, no fault) finishes the plan.
    let config = config_variant(dir.path(), "sim-cell.yaml", &[("count: 20", "count: 12")]);
    let prepared = cell::prepare(&config).unwrap();
    let folder = SessionFolder::open(&out).unwrap();
    let outcome = run(&prepared, &folder).unwrap();
    assert_eq!(outcome.visited_now, 7);
    assert_eq!(outcome.accepted, (0..12).collect::<Vec<_>>());
    let dataset = handeye::dataset::Dataset::load(&folder.samples_path()).unwrap();
    assert_eq!(dataset.pairs.len(), 12);
}

/// Ctrl-C during a move stops the arm there and then (not at the end of the move), keeps every
/// sample, and the run resumes.
#[test]
fn a_stop_request_ends_the_move_in_progress_and_resume_finishes() {
    let dir = tempfile::tempdir().unwrap();
    let config = config_variant(
        dir.path(),
        "sim-cell.yaml",
        &[
            ("count: 20", "count: 8"),
            ("move_duration_s: 0.0", "move_duration_s: 1.0"),
        ],
    );
    let prepared = cell::prepare(&config).unwrap();
    let out = dir.path().join("s");
    let folder = SessionFolder::create(&out).unwrap();
    let plan = prepared.report.validated().unwrap();
    folder.write_manifest(&prepared.manifest(&plan)).unwrap();
    let mut hardware = prepared.open_hardware().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let setup = prepared.session_setup(folder.clone(), plan, stop.clone());
    // Ctrl-C 0.4 s into the third move (moves take 1 s each).
    let mut pressed_at = None;
    let error = session::run_session(
        setup,
        hardware.robot.as_mut(),
        hardware.camera.as_mut(),
        &mut |e: SessionEvent| {
            if let SessionEvent::Moving { plan_index: 2 } = e {
                let stop = stop.clone();
                pressed_at = Some(std::time::Instant::now() + Duration::from_millis(400));
                std::thread::spawn(move || {
                    std::thread::sleep(Duration::from_millis(400));
                    stop.store(true, std::sync::atomic::Ordering::SeqCst);
                });
            }
        },
    )
    .unwrap_err();
    let reaction = pressed_at.unwrap().elapsed();
    assert!(
        matches!(error, SessionError::Interrupted { plan_index: 2, .. }),
        "{error}"
    );
    // The 1 s move was cut short: the run ended well before the move's remaining 0.6 s.
    assert!(
        reaction < Duration::from_millis(400),
        "{reaction:?} after Ctrl-C"
    );
    assert_eq!(
        folder.read_visits().unwrap().len(),
        2,
        "the two poses before are kept"
    );

    let config = config_variant(dir.path(), "sim-cell.yaml", &[("count: 20", "count: 8")]);
    let prepared = cell::prepare(&config).unwrap();
    let outcome = run(&prepared, &SessionFolder::open(&out).unwrap()).unwrap();
    assert_eq!(outcome.visited_now, 6);
    assert_eq!(outcome.accepted, (0..8).collect::<Vec<_>>());
}

/// The plan check saw the moves in plan order from the assumed start; each move is checked again
/// from where the arm really stands right before it is sent. An arm left (say, after a stop and
/// some jogging) where the straight joint move to the next pose would sweep the flange out of
/// the workspace box: the move is refused, nothing moves, the folder is kept for a resume.
#[test]
fn a_move_that_would_leave_the_workspace_box_from_where_the_arm_stands_is_not_sent() {
    let dir = tempfile::tempdir().unwrap();
    let config = config_variant(dir.path(), "sim-cell.yaml", &[("count: 20", "count: 6")]);
    let prepared = cell::prepare(&config).unwrap();
    let plan = prepared.report.validated().unwrap();
    let folder = SessionFolder::create(&dir.path().join("s")).unwrap();
    folder.write_manifest(&prepared.manifest(&plan)).unwrap();
    let mut hardware = prepared.open_hardware().unwrap();
    // Shoulder lowered: the flange hangs below the table top (the box starts at z = 5 cm).
    let jogged = [0.0, 0.6, 0.0, 0.0, 0.0, 0.0];
    let flange = prepared.arm.forward(&jogged).translation.vector;
    assert!(flange.z < 0.05, "{flange:?}");
    hardware
        .robot
        .move_joints(&jogged, &prepared.config.limits)
        .unwrap();
    let setup = prepared.session_setup(folder.clone(), plan, Arc::new(AtomicBool::new(false)));
    let error = session::run_session(
        setup,
        hardware.robot.as_mut(),
        hardware.camera.as_mut(),
        &mut |_| {},
    )
    .unwrap_err();
    let message = error.to_string();
    assert!(
        matches!(error, SessionError::UnsafeMove { plan_index: 0, .. }),
        "{message}"
    );
    assert!(
        message.contains("workspace box") && message.contains("--resume"),
        "{message}"
    );
    assert_eq!(
        hardware.robot.joint_positions().unwrap(),
        jogged,
        "nothing moved"
    );
    assert!(folder.read_visits().unwrap().is_empty());
}

#[test]
fn a_plan_rotating_about_one_axis_is_refused_before_any_motion() {
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("coaxial.yaml");
    // Six views straight above the board, differing only by roll about the optical axis.
    let mut text = String::from("waypoints:\n");
    for roll in [-25, -15, -5, 5, 15, 25] {
        text += &format!(
            "  - look_at: {{distance: 0.6, azimuth_deg: 0, elevation_deg: 90, roll_deg: {roll}}}\n"
        );
    }
    std::fs::write(&plan, text).unwrap();
    let config = config_variant(
        dir.path(),
        "sim-cell.yaml",
        &[("generate: {count: 20, distance: [0.55, 0.75], max_tilt_deg: 30, max_roll_deg: 20, seed: 1}", &format!("file: {}", plan.display()))],
    );
    let prepared = cell::prepare(&config).unwrap();
    assert!(!prepared.report.ok());
    assert!(prepared.report.validated().is_none());
    let table = prepared.report.to_string();
    assert!(table.contains("plan REJECTED"), "{table}");
    assert!(table.to_lowercase().contains("axis"), "{table}");
}

#[test]
fn an_unreachable_pose_is_reported_with_its_index() {
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("far.yaml");
    std::fs::write(
        &plan,
        "waypoints:\n\
         - look_at: {distance: 0.6, azimuth_deg: 0, elevation_deg: 80}\n\
         - look_at: {distance: 0.6, azimuth_deg: 120, elevation_deg: 65, roll_deg: 20}\n\
         - T_base_flange: {translation: [3.0, 0.0, 0.5], rotation_vector: [3.14159, 0, 0]}\n\
         - look_at: {distance: 0.6, azimuth_deg: 240, elevation_deg: 65, roll_deg: -20}\n",
    )
    .unwrap();
    let config = config_variant(
        dir.path(),
        "sim-cell.yaml",
        &[("generate: {count: 20, distance: [0.55, 0.75], max_tilt_deg: 30, max_roll_deg: 20, seed: 1}", &format!("file: {}", plan.display()))],
    );
    let prepared = cell::prepare(&config).unwrap();
    let bad: Vec<usize> = prepared
        .report
        .poses
        .iter()
        .filter(|p| !p.problems.is_empty())
        .map(|p| p.index)
        .collect();
    assert_eq!(bad, vec![2], "{}", prepared.report);
    assert!(prepared.report.poses[2]
        .problems
        .iter()
        .any(|p| p.contains("unreachable")));
}

#[test]
fn malformed_configs_name_file_key_and_expectation() {
    let dir = tempfile::tempdir().unwrap();
    let cases: &[(&[(&str, &str)], &str)] = &[
        (&[("setup: eye_in_hand", "setup: eye_on_hand")], "setup"),
        (&[("noise_sigma: 2.0", "noise_sigm: 2.0")], "noise_sigm"),
        (
            &[("linear_speed: 0.25", "linear_speed: 3.0")],
            "limits.linear_speed",
        ),
        (&[("model: ur10e", "model: ur7")], "robot.model"),
        (
            &[("min: [-1.0, -1.0, 0.05]", "min: [-1.0, 2.0, 0.05]")],
            "workspace",
        ),
        (
            &[(
                "T_base_target: {translation: [0.5, -0.15, 0.0], rotation_vector: [0.0, 0.0, 0.3]}",
                "T_base_target: {translation: [0.5, -0.15], rotation_vector: [0.0, 0.0, 0.3]}",
            )],
            "nominal.T_base_target.translation: expected 3 numbers",
        ),
        (&[("count: 20", "count: 2")], "plan.generate"),
    ];
    for (edits, expected) in cases {
        let config = config_variant(dir.path(), "sim-cell.yaml", edits);
        let message = match cell::prepare(&config) {
            Ok(_) => panic!("{edits:?} was accepted"),
            Err(e) => format!("{e:#}"),
        };
        assert!(message.contains("sim-cell.yaml"), "{message}");
        assert!(message.contains(expected), "{edits:?}: {message}");
    }
}

#[test]
fn the_shipped_scripted_plan_passes_its_checks_in_the_demo_cell() {
    let dir = tempfile::tempdir().unwrap();
    let plan = repo().join("configs/plans/look-at-12.yaml");
    let config = config_variant(
        dir.path(),
        "sim-cell.yaml",
        &[("generate: {count: 20, distance: [0.55, 0.75], max_tilt_deg: 30, max_roll_deg: 20, seed: 1}", &format!("file: {}", plan.display()))],
    );
    let prepared = cell::prepare(&config).unwrap();
    assert_eq!(prepared.plan.waypoints.len(), 12);
    assert!(prepared.report.ok(), "{}", prepared.report);
}

#[test]
fn every_shipped_cell_config_loads_and_its_plan_passes_its_checks() {
    let mut checked = 0;
    for entry in std::fs::read_dir(repo().join("configs")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "yaml") {
            let prepared =
                cell::prepare(&path).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
            assert!(
                prepared.report.ok(),
                "{}:\n{}",
                path.display(),
                prepared.report
            );
            checked += 1;
        }
    }
    assert!(checked >= 4, "only {checked} configs found");
}

#[test]
fn sim_cell_without_intrinsics_estimates_them_and_the_cell() {
    let dir = tempfile::tempdir().unwrap();
    let lens = repo().join("configs/cameras/sim-1280x720.yaml");
    // The shipped config: sim-cell.yaml with the lens moved from `intrinsics` to the simulator.
    let prepared = cell::prepare(&repo().join("configs/sim-cell-no-intrinsics.yaml")).unwrap();
    assert!(!prepared.intrinsics_known);
    // The generated views push the board across the image for the intrinsics; the same plan
    // with the intrinsics known keeps the board centred.
    let coverage = |report: &handeye::plan::check::PlanReport| {
        report.intrinsics.as_ref().unwrap().coverage_percent
    };
    let centred = cell::prepare(&repo().join("configs/sim-cell.yaml")).unwrap();
    eprintln!(
        "image coverage: {:.0} % spread, {:.0} % centred",
        coverage(&prepared.report),
        coverage(&centred.report)
    );
    assert!(coverage(&prepared.report) >= 90.0);
    assert!(coverage(&prepared.report) > coverage(&centred.report));
    let folder = SessionFolder::create(&dir.path().join("s")).unwrap();
    let outcome = run(&prepared, &folder).unwrap();
    assert_eq!(outcome.accepted.len(), prepared.plan.waypoints.len());
    // No intrinsics during the run: corners recorded, no board pose estimated.
    let visits = folder.read_visits().unwrap();
    assert!(visits
        .iter()
        .all(|v| v.camera_from_target.is_none() && !v.corners_px.is_empty()));
    let solved = session::solve_folder(&folder, &prepared.solve_inputs()).unwrap();
    eprintln!(
        "{}\n{}",
        solved.summary,
        solved.compare_with_truth(prepared.config.simulation.as_ref().unwrap())
    );
    let truth_camera = handeye::camera_model::CameraModel::load(&lens).unwrap();
    let written =
        handeye::camera_model::CameraModel::load(&folder.root().join("camera_info.yaml")).unwrap();
    let estimated = solved.estimated_camera.unwrap();
    for (name, found, written, truth) in [
        ("fx", estimated.fx, written.fx, truth_camera.fx),
        ("fy", estimated.fy, written.fy, truth_camera.fy),
        ("cx", estimated.cx, written.cx, truth_camera.cx),
        ("cy", estimated.cy, written.cy, truth_camera.cy),
    ] {
        // The bar: within 0.2 % or 0.5 px; the file holds what was found.
        assert!(
            (found - truth).abs() <= (0.002 * truth).max(0.5),
            "{name}: {found:.3} px, truth {truth:.3} px"
        );
        assert!((found - written).abs() < 1e-9);
    }
    // Rendered corners with known intrinsics fit to ~0.09 px RMS; estimated ones must match that.
    let rms = solved.reprojection.as_ref().unwrap().errors.rms_px;
    assert!(rms < 0.12, "reprojection RMS {rms:.4} px");
    assert_recovers_truth(&solved, prepared.config.simulation.as_ref().unwrap());
    assert!(folder.result_path().is_file());
    let summary: session::solve::ReprojectionSummary = serde_yaml_ng::from_str(
        &std::fs::read_to_string(folder.root().join("reprojection.yaml")).unwrap(),
    )
    .unwrap();
    assert!(summary.intrinsics_estimated);
    assert_eq!(summary.frames.len(), prepared.plan.waypoints.len());
    eprintln!(
        "reprojection RMS: pose space {:.4} px, reprojection {:.4} px (corrected robot poses {:.4} px)",
        summary.pose_space_rms_px,
        summary.reprojection_rms_px,
        summary.corrected_rms_px.unwrap()
    );
    // On the recorded robot poses the two answers are level (the arm's noise, not the answer,
    // sets that figure: 0.0905 vs 0.0906 px with edge-fitted corners; 0.0593 vs 0.0623 px with
    // the saddle-point corners of Kalibr's corner squares, where the fit trades a little of it for
    // the robot poses' weights); with the poses corrected the fit is below both.
    assert!(summary.reprojection_rms_px <= 1.10 * summary.pose_space_rms_px);
    assert!(summary.corrected_rms_px.unwrap() < summary.pose_space_rms_px);
}

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
            handeye::config::SolveSpace::Reprojection
        );
        let folder = SessionFolder::create(&dir.path().join("s")).unwrap();
        run(&prepared, &folder).unwrap();
        let solved = session::solve_folder(&folder, &prepared.solve_inputs()).unwrap();
        assert!(solved.reprojection.is_some());
        let truth = prepared.config.simulation.unwrap();
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
        },
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
    handeye::dataset::Dataset::load(&folder.join("samples.yaml"))
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
    let replay = session::replay::redetect(
        &SessionFolder::open(&dir.path().join("zero")).unwrap(),
        &prepared.board,
        &prepared.camera_model,
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
    let message = session::solve_folder(
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
