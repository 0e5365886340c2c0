//! Issue #19, items 3: translations in the wrong unit are refused with a message naming the
//! unit, an answer with both inputs inverted is flagged (also against the nominal transforms),
//! and none of it fires on real cells: the MoveIt and ViSP sets in `../shared/datasets` (skipped
//! with a printed reason when absent) and the sim cells of `configs/`.

use std::process::Command;

use handeye_config::CellConfig;
use handeye_core::geometry::Pose;
use handeye_core::notice::NoticeKind;
use handeye_core::setup::{CellTransforms, PosePair, Setup};
use handeye_formats::import::{import_moveit_json, import_visp, VispOptions};
use handeye_plan::check::board_centre;
use handeye_plan::generate;
use handeye_records::dataset::Dataset;
use handeye_solve::diagnostics::{check_against_nominal, check_units, unit_scale};
use handeye_solve::{self as solve, AxbyData, NoiseModel, SolveError, SolveOptions, UnitsProblem};
use handeye_vision::{Board, DetectorOptions};
use nalgebra::{Translation3, UnitQuaternion, Vector3};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use crate::util;
use util::{dataset, repo};

/// The sim cells of `configs/` with their ground truth.
const SIM_CELLS: [&str; 4] = [
    "sim-cell.yaml",
    "sim-cell-eye-to-hand.yaml",
    "sim-cell-no-intrinsics.yaml",
    "sim-cell-ur-mock.yaml",
];

struct SimCell {
    name: &'static str,
    truth: CellTransforms,
    nominal: CellTransforms,
    pairs: Vec<PosePair>,
}

/// A sim cell's generated plan on its true transforms: the flange poses the plan would visit
/// and the board poses the camera would see there, with 0.2° / 1 mm of board-pose noise.
fn sim_cell(name: &'static str, seed: u64) -> SimCell {
    let config = CellConfig::load(&repo().join("configs").join(name)).unwrap();
    let truth = config.camera().simulation.unwrap();
    let board = Board::load(&config.camera().target).unwrap();
    let centre = board_centre(&board.clone().into());
    let spec = config.plan.generate.as_ref().unwrap();
    let mut rng = StdRng::seed_from_u64(seed);
    let rotation = Normal::new(0.0, 0.2f64.to_radians()).unwrap();
    let translation = Normal::new(0.0, 1e-3).unwrap();
    let pairs = generate(spec)
        .iter()
        .map(|view| {
            let base_from_flange =
                truth.base_from_flange_for_view(&view.target_from_camera(&centre));
            let mut draw = |d: &Normal<f64>| {
                Vector3::new(d.sample(&mut rng), d.sample(&mut rng), d.sample(&mut rng))
            };
            let noise = Pose::from_parts(
                Translation3::from(draw(&translation)),
                UnitQuaternion::from_scaled_axis(draw(&rotation)),
            );
            PosePair::new(
                base_from_flange,
                noise * truth.camera_from_target(&base_from_flange),
            )
        })
        .collect();
    SimCell {
        name,
        truth,
        nominal: config.camera().nominal,
        pairs,
    }
}

fn scaled(pairs: &[PosePair], robot: f64, camera: f64) -> Vec<PosePair> {
    pairs
        .iter()
        .map(|p| {
            let mut q = p.clone();
            q.base_from_flange.translation.vector *= robot;
            q.camera_from_target.translation.vector *= camera;
            q
        })
        .collect()
}

fn both_inverted(pairs: &[PosePair]) -> Vec<PosePair> {
    pairs
        .iter()
        .map(|p| PosePair {
            base_from_flange: p.base_from_flange.inverse(),
            camera_from_target: p.camera_from_target.inverse(),
            ..p.clone()
        })
        .collect()
}

fn units_problem(setup: Setup, pairs: &[PosePair]) -> (UnitsProblem, String) {
    match solve::solve(setup, pairs, &SolveOptions::default()) {
        Err(e @ SolveError::ImplausibleUnits { .. }) => {
            let text = e.to_string();
            let SolveError::ImplausibleUnits { problem } = e else {
                unreachable!()
            };
            (problem, text)
        }
        other => panic!("expected ImplausibleUnits, got {other:?}"),
    }
}

/// The answer is fine: no units error, no swapped-answer flag, and the scale fit says metres.
fn assert_plausible(what: &str, setup: Setup, pairs: &[PosePair], options: &SolveOptions) {
    let fit = unit_scale(&AxbyData::new(setup, pairs)).unwrap();
    eprintln!(
        "{what}: robot/camera scale {:.4} ± {:.4}, translation RMS {:.2} mm scaled, {:.2} mm as given",
        fit.scale,
        fit.sigma,
        fit.scaled_rms_m * 1e3,
        fit.given_rms_m * 1e3
    );
    assert!((fit.scale - 1.0).abs() < 0.1, "{what}: scale {fit:?}");
    check_units(setup, pairs).unwrap_or_else(|e| panic!("{what}: {e}"));
    let cal = solve::solve(setup, pairs, options).unwrap_or_else(|e| panic!("{what}: {e}"));
    assert!(
        !cal.notices
            .iter()
            .any(|w| w.kind == NoticeKind::ImplausibleTransform),
        "{what}: {:?}",
        cal.notices
    );
}

// ------------------------------------------------------------------------------------------
// Units

#[test]
fn robot_poses_in_millimetres_are_refused_naming_millimetres() {
    for name in ["sim-cell.yaml", "sim-cell-eye-to-hand.yaml"] {
        let c = sim_cell(name, 1);
        let setup = c.truth.setup;
        let (problem, text) = units_problem(setup, &scaled(&c.pairs, 1000.0, 1.0));
        assert!(
            matches!(&problem, UnitsProblem::FlangeTooFar { unit, .. } if unit == "millimetres"),
            "{name}: {problem:?}"
        );
        assert!(
            text.contains("millimetres") && text.contains("T_base_flange"),
            "{text}"
        );
    }
}

#[test]
fn unit_mistakes_within_the_size_limits_are_caught_by_the_scale_fit() {
    let c = sim_cell("sim-cell.yaml", 2);
    let setup = c.truth.setup;
    // A cell a tenth of the size (flange 5–10 cm from the base: the size checks cannot tell).
    let small = scaled(&c.pairs, 0.1, 0.1);
    // Robot translations in inches.
    let (problem, text) = units_problem(setup, &scaled(&small, 1.0 / 0.0254, 1.0));
    match problem {
        UnitsProblem::ScaleMismatch { scale, .. } => {
            assert!((scale - 0.0254).abs() < 0.002, "{scale}")
        }
        other => panic!("expected ScaleMismatch, got {other:?}"),
    }
    assert!(
        text.contains("robot translations are 39.") && text.contains("inches"),
        "{text}"
    );
    // Camera translations in centimetres (the board 6–8 "m" away: under the size limit).
    let (problem, text) = units_problem(setup, &scaled(&small, 1.0, 100.0));
    match problem {
        UnitsProblem::ScaleMismatch { scale, .. } => {
            assert!((scale / 100.0 - 1.0).abs() < 0.05, "{scale}")
        }
        other => panic!("expected ScaleMismatch, got {other:?}"),
    }
    assert!(
        text.contains("camera translations")
            && text.contains("centimetres")
            && text.contains("board size"),
        "{text}"
    );
    // A factor of 10 (say robot in mm and camera in cm) is no single unit: said as a factor.
    let (problem, text) = units_problem(setup, &scaled(&small, 10.0, 1.0));
    match problem {
        UnitsProblem::ScaleMismatch { scale, .. } => assert!((scale - 0.1).abs() < 0.01, "{scale}"),
        other => panic!("expected ScaleMismatch, got {other:?}"),
    }
    assert!(
        text.contains("10.0 times too large") && text.contains("other than metres"),
        "{text}"
    );
}

#[test]
fn robot_poses_in_centimetres_name_every_unit_that_fits() {
    // Flange 0.4–1 m from the base: ×100 could be centimetres, or (0.9–2.5 m) inches.
    let c = sim_cell("sim-cell.yaml", 7);
    let (problem, text) = units_problem(c.truth.setup, &scaled(&c.pairs, 100.0, 1.0));
    match &problem {
        UnitsProblem::FlangeTooFar { unit, median_m, .. } => {
            eprintln!("median {median_m} m: {unit}");
            assert!(
                unit.contains("centimetres") && !unit.contains("millimetres"),
                "{unit}"
            )
        }
        other => panic!("expected FlangeTooFar, got {other:?}"),
    }
    assert!(text.contains("give T_base_flange in metres"), "{text}");
}

#[test]
fn camera_poses_in_millimetres_are_refused_naming_the_board_size() {
    let c = sim_cell("sim-cell.yaml", 6);
    let (problem, text) = units_problem(c.truth.setup, &scaled(&c.pairs, 1.0, 1000.0));
    assert!(
        matches!(&problem, UnitsProblem::TargetTooFar { unit, .. } if unit == "millimetres"),
        "{problem:?}"
    );
    assert!(text.contains("board size"), "{text}");
}

#[test]
fn issue_19_millimetre_robot_poses_no_longer_solve() {
    // The issue's report: robot translations in mm, camera in m, exit 0 with a 105 m RMS.
    let c = sim_cell("sim-cell-eye-to-hand.yaml", 3);
    let mm = scaled(&c.pairs, 1000.0, 1.0);
    let options = SolveOptions {
        check_conventions: false,
        ..SolveOptions::default()
    };
    // Without the checks it "solves" with an absurd residual — the bug.
    let unchecked = solve::solve(c.truth.setup, &mm, &options).unwrap();
    assert!(
        unchecked.residuals.translation_rms_mm > 1e4,
        "{}",
        unchecked.residuals.translation_rms_mm
    );
    // With them (the default) it is refused, saying millimetres.
    let e = solve::solve(c.truth.setup, &mm, &SolveOptions::default()).unwrap_err();
    assert!(e.to_string().contains("millimetres"), "{e}");
}

#[test]
fn solve_cli_exits_non_zero_on_robot_inches_and_flags_both_inverted() {
    let dir = tempfile::tempdir().unwrap();
    let c = sim_cell("sim-cell.yaml", 8);
    let run = |pairs: Vec<PosePair>, name: &str| {
        let file = dir.path().join(name);
        Dataset {
            setup: c.truth.setup,
            pairs,
        }
        .save(&file)
        .unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_handeye"))
            .arg("solve")
            .arg(&file)
            .output()
            .unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stdout).to_string(),
            String::from_utf8_lossy(&out.stderr).to_string(),
        )
    };
    // Inches pass the loaders' 100 m limit; the solver refuses them.
    let (code, _, stderr) = run(scaled(&c.pairs, 1.0 / 0.0254, 1.0), "inches.yaml");
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("not in metres") && stderr.contains("inches"),
        "{stderr}"
    );
    let (code, stdout, stderr) = run(both_inverted(&c.pairs), "inverted.yaml");
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stdout.contains("both inputs inverted"), "{stdout}");
}

// ------------------------------------------------------------------------------------------
// Both inputs inverted

#[test]
fn both_inverted_inputs_are_flagged_and_recognised_against_the_nominal_cell() {
    for name in ["sim-cell.yaml", "sim-cell-eye-to-hand.yaml"] {
        let c = sim_cell(name, 4);
        let setup = c.truth.setup;
        let inverted = both_inverted(&c.pairs);
        // It fits as well as the truth: nothing in the residuals can tell.
        let cal = solve::solve(setup, &inverted, &SolveOptions::default())
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(
            cal.residuals.translation_rms_mm < 5.0,
            "{name}: {}",
            cal.summary()
        );
        // The answer is the swapped pair ...
        assert!(
            (cal.camera_mount.translation.vector - c.truth.target_mount.translation.vector).norm()
                < 0.01,
            "{name}: {}",
            cal.summary()
        );
        // ... and flagged as such.
        let flag = cal
            .notices
            .iter()
            .find(|w| w.kind == NoticeKind::ImplausibleTransform)
            .unwrap_or_else(|| panic!("{name}: not flagged: {:?}", cal.notices));
        assert!(
            flag.message.contains("both inputs inverted"),
            "{}",
            flag.message
        );
        // Against the nominal cell the swap is named; the correct answer is not flagged.
        let notice = check_against_nominal(&cal, &c.nominal, 0.1)
            .unwrap_or_else(|| panic!("{name}: nominal check silent"));
        assert!(notice.message.contains("swapped"), "{}", notice.message);
        let good = solve::solve(setup, &c.pairs, &SolveOptions::default()).unwrap();
        assert!(check_against_nominal(&good, &c.nominal, 0.1).is_none());
    }
}

// ------------------------------------------------------------------------------------------
// No false alarms

#[test]
fn sim_cells_pass_the_checks() {
    for name in SIM_CELLS {
        let c = sim_cell(name, 5);
        assert_plausible(c.name, c.truth.setup, &c.pairs, &SolveOptions::default());
    }
}

#[test]
fn moveit_real_data_passes_the_checks() {
    let Some(folder) = dataset("moveit_calibration_eye_to_hand") else {
        return;
    };
    let pairs = import_moveit_json(&folder.join("pose_samples.json")).unwrap();
    assert_plausible("MoveIt", Setup::EyeToHand, &pairs, &SolveOptions::default());
}

#[test]
fn visp_real_data_passes_the_checks() {
    let Some(folder) = dataset("visp_franka_data-eye-to-hand") else {
        return;
    };
    let imported = import_visp(
        &folder,
        &VispOptions {
            setup: Setup::EyeToHand,
            board: Board::load(&repo().join("configs/targets/single-tag36h11-id10.yaml"))
                .unwrap()
                .into(),
            camera: None,
            detector: DetectorOptions::default(),
            skip_unfound: false,
        },
    )
    .unwrap();
    let options = SolveOptions {
        noise: NoiseModel {
            rotation_sigma_rad: 0.5f64.to_radians(),
            translation_sigma_m: 2e-3,
        },
        ..SolveOptions::default()
    };
    assert_plausible(
        "ViSP eye-to-hand",
        Setup::EyeToHand,
        &imported.dataset.pairs,
        &options,
    );
}
