//! Wrong files, right answer (issue #38): the cell's intrinsics or board file wrong by a mistake
//! whose class and magnitude are drawn at random (seeded), both setups; synthetic corners through
//! the true lens and board with pixel noise and the robot's repeatability, solved by the
//! single-camera session path (`handeye_records::solve_session`: PnP with the files as given, the
//! pose-space solve, the cell model, the reprojection answer, the verdict).
//!
//! Counted over the drawn cases: the verdict names exactly the wrong file(s); it blames an
//! innocent file without naming the guilty one in no case; it is GOOD with an answer outside
//! the accuracy asked in no case; with nothing wrong it is GOOD.

use std::path::PathBuf;

use nalgebra::{Matrix3, Point2, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

use handeye_config::CellConfig;
use handeye_core::camera_model::{CameraModel, Distortion};
use handeye_core::geometry::{pose_from_rotvec, Pose};
use handeye_core::setup::{CellTransforms, CornerObservation, PosePair, Setup};
use handeye_records::PoseVisit;
use handeye_solve::cell_model::GivenFile;
use handeye_solve::verdict::Level;
use handeye_vision::pnp::estimate_pose_from_points;
use handeye_vision::Target;

use crate::util::{pose_error_mm_deg, repo};

/// A mistake in the cell's files (the camera and board really are the shipped ones).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Mistake {
    Nothing,
    /// fx and fy both times these factors (together: equal).
    Focal(f64, f64),
    /// The principal point off by this, px.
    PrincipalPoint(f64, f64),
    /// No distortion in the file.
    DistortionDropped,
    /// The coefficients with their signs flipped.
    DistortionFlipped,
    /// Another lens's coefficients.
    AnotherLens,
    /// The board is this factor of the size its file says.
    Board(f64),
    /// The focal factor and the board factor together.
    LensAndBoard(f64, f64),
}

impl Mistake {
    pub(crate) fn wrong(self) -> Vec<GivenFile> {
        match self {
            Mistake::Nothing => vec![],
            Mistake::Board(_) => vec![GivenFile::Board],
            Mistake::LensAndBoard(..) => vec![GivenFile::Intrinsics, GivenFile::Board],
            _ => vec![GivenFile::Intrinsics],
        }
    }

    pub(crate) fn class(self) -> &'static str {
        match self {
            Mistake::Nothing => "nothing",
            Mistake::Focal(a, b) if a == b => "focal together",
            Mistake::Focal(..) => "focal apart",
            Mistake::PrincipalPoint(..) => "principal point",
            Mistake::DistortionDropped => "distortion dropped",
            Mistake::DistortionFlipped => "distortion flipped",
            Mistake::AnotherLens => "another lens",
            Mistake::Board(_) => "board",
            Mistake::LensAndBoard(..) => "lens and board",
        }
    }

    /// Draws a class (nothing in one case of five) and its magnitude.
    pub(crate) fn draw(rng: &mut StdRng) -> Mistake {
        let sign = |rng: &mut StdRng| if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        let percent = |rng: &mut StdRng, lo: f64, hi: f64| sign(rng) * rng.random_range(lo..hi);
        match rng.random_range(0..10) {
            0 | 1 => Mistake::Nothing,
            2 => {
                let f = 1.0 + percent(rng, 0.02, 0.12);
                Mistake::Focal(f, f)
            }
            3 => Mistake::Focal(
                1.0 + percent(rng, 0.02, 0.12),
                1.0 + percent(rng, 0.0, 0.12),
            ),
            4 => {
                let size = rng.random_range(5.0..40.0);
                let angle = rng.random_range(0.0..std::f64::consts::TAU);
                Mistake::PrincipalPoint(size * angle.cos(), size * angle.sin())
            }
            5 => match rng.random_range(0..3) {
                0 => Mistake::DistortionDropped,
                1 => Mistake::DistortionFlipped,
                _ => Mistake::AnotherLens,
            },
            6 | 7 => Mistake::Board(1.0 + percent(rng, 0.02, 0.10)),
            8 => Mistake::LensAndBoard(
                1.0 + percent(rng, 0.02, 0.12),
                1.0 + percent(rng, 0.02, 0.10),
            ),
            _ => {
                if rng.random_bool(0.5) {
                    let size = rng.random_range(5.0..40.0);
                    Mistake::PrincipalPoint(size, -size / 2.0)
                } else {
                    Mistake::Focal(1.0 + percent(rng, 0.02, 0.12), 1.0)
                }
            }
        }
    }

    /// The intrinsics file with this mistake, from the true lens.
    pub(crate) fn lens_file(self, truth: &CameraModel) -> CameraModel {
        let mut file = *truth;
        match self {
            Mistake::Focal(a, b) => {
                file.fx *= a;
                file.fy *= b;
            }
            Mistake::LensAndBoard(a, _) => {
                file.fx *= a;
                file.fy *= a;
            }
            Mistake::PrincipalPoint(dx, dy) => {
                file.cx += dx;
                file.cy += dy;
            }
            Mistake::DistortionDropped => file.distortion = Distortion::None,
            Mistake::DistortionFlipped => {
                let flipped: Vec<f64> =
                    truth.distortion.coefficients().iter().map(|c| -c).collect();
                file.distortion = truth.distortion.with_coefficients(&flipped).unwrap();
            }
            Mistake::AnotherLens => {
                file.distortion = Distortion::RadTan {
                    k1: -0.28,
                    k2: 0.09,
                    p1: 0.0,
                    p2: 0.0,
                    k3: 0.0,
                }
            }
            _ => {}
        }
        file
    }

    /// The true board size as a factor of the file's.
    pub(crate) fn board_factor(self) -> f64 {
        match self {
            Mistake::Board(s) | Mistake::LensAndBoard(_, s) => s,
            _ => 1.0,
        }
    }
}

/// The true cell of `setup`: (camera mount, target mount).
fn truth(setup: Setup) -> (Pose, Pose) {
    match setup {
        // configs/sim-cell.yaml's `simulation:`.
        Setup::EyeInHand => (
            pose_from_rotvec(
                Vector3::new(0.0312, -0.0694, 0.0447),
                Vector3::new(0.021, -0.016, 1.561),
            ),
            pose_from_rotvec(
                Vector3::new(0.5034, -0.1467, 0.0021),
                Vector3::new(0.012, -0.018, 0.297),
            ),
        ),
        // A camera 1.2 m over the table looking down; the board on the flange.
        Setup::EyeToHand => (
            pose_from_rotvec(
                Vector3::new(0.55, -0.05, 1.2),
                Vector3::new(3.12, 0.04, 0.0),
            ),
            pose_from_rotvec(
                Vector3::new(-0.145, -0.145, 0.012),
                Vector3::new(0.01, -0.02, 0.2),
            ),
        ),
    }
}

/// `T_target_camera` of a camera at 0.45–0.75 m from the board, tilted up to 35° in a random
/// direction, looking at a point up to 12 cm off the board's centre (so the board moves about
/// the image), rolled ±0.5 rad.
fn target_from_camera(rng: &mut StdRng) -> Pose {
    let centre = Vector3::new(0.145, 0.145, 0.0);
    let distance = rng.random_range(0.45..0.75);
    let tilt = rng.random_range(0.2..1.0) * 35f64.to_radians();
    let azimuth = rng.random_range(0.0..std::f64::consts::TAU);
    let direction = Vector3::new(
        tilt.sin() * azimuth.cos(),
        tilt.sin() * azimuth.sin(),
        tilt.cos(),
    );
    let look_at = centre
        + Vector3::new(
            rng.random_range(-0.12..0.12),
            rng.random_range(-0.12..0.12),
            0.0,
        );
    let position = centre + direction * distance;
    let z = (look_at - position).normalize();
    let x = (Vector3::x() - z * z.dot(&Vector3::x())).normalize();
    let y = z.cross(&x);
    let rotation = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]))
        * Rotation3::from_axis_angle(&Vector3::z_axis(), rng.random_range(-0.5..0.5));
    Pose::from_parts(
        Translation3::from(position),
        UnitQuaternion::from_rotation_matrix(&rotation),
    )
}

struct Case {
    setup: Setup,
    mistake: Mistake,
    /// The cell's lens file (with the mistake).
    lens: CameraModel,
    visits: Vec<PoseVisit>,
    pairs: Vec<PosePair>,
}

/// 14 views (each showing at least 100 of the board's 144 corners, as a planned view does) of the true board (`mistake.board_factor()` × the file's) through the true lens,
/// 0.25 px corner noise, the robot off by its repeatability (0.02 mm, 0.002° per axis); the
/// board poses by PnP with the files as given, as a run measures them.
fn case(seed: u64, setup: Setup, mistake: Mistake, board: &Target) -> Case {
    let mut rng = StdRng::seed_from_u64(seed);
    let true_lens = CameraModel::load(&repo().join("configs/cameras/sim-1280x720.yaml")).unwrap();
    let lens = mistake.lens_file(&true_lens);
    let scale = mistake.board_factor();
    let (camera_mount, target_mount) = truth(setup);
    let pixel_noise = Normal::new(0.0, 0.25).unwrap();
    let t_noise = Normal::new(0.0, 0.02e-3).unwrap();
    let r_noise = Normal::new(0.0, 0.002f64.to_radians()).unwrap();
    let mut visits = Vec::new();
    let mut pairs = Vec::new();
    while visits.len() < 14 {
        let camera_from_target = target_from_camera(&mut rng).inverse();
        let base_from_flange = match setup {
            Setup::EyeInHand => {
                target_mount * camera_from_target.inverse() * camera_mount.inverse()
            }
            Setup::EyeToHand => camera_mount * camera_from_target * target_mount.inverse(),
        };
        let mut v = |n: &Normal<f64>| {
            Vector3::new(n.sample(&mut rng), n.sample(&mut rng), n.sample(&mut rng))
        };
        let (dt, dr) = (v(&t_noise), v(&r_noise));
        let reported = Pose::from_parts(
            Translation3::from(base_from_flange.translation.vector + dt),
            base_from_flange.rotation * UnitQuaternion::from_scaled_axis(dr),
        );
        let mut corners_px = Vec::new();
        let mut correspondences = Vec::new();
        for (tag_id, corner, point) in board.points() {
            let seen = camera_from_target * nalgebra::Point3::from(point.coords * scale);
            let Some(pixel) = true_lens.project(&seen) else {
                continue;
            };
            let pixel = Point2::new(
                pixel.x + pixel_noise.sample(&mut rng),
                pixel.y + pixel_noise.sample(&mut rng),
            );
            if pixel.x < 20.0 || pixel.y < 20.0 || pixel.x > 1260.0 || pixel.y > 700.0 {
                continue;
            }
            corners_px.push(CornerObservation {
                tag_id,
                corner,
                pixel,
            });
            correspondences.push((point, pixel));
        }
        if corners_px.len() < 100 {
            continue;
        }
        let Ok(measured) = estimate_pose_from_points(&lens, &correspondences, 36) else {
            continue;
        };
        let plan_index = visits.len();
        let visit = PoseVisit {
            schema_version: handeye_core::yaml_file::SchemaVersion::CURRENT,
            plan_index,
            base_from_flange: reported,
            frame: PathBuf::from(format!("frames/{plan_index:03}.png")),
            camera_from_target: Some(measured.camera_from_target),
            reprojection_rms_px: Some(measured.rms_px),
            view_sigma: measured.view_sigma(),
            tags: corners_px.len() / 4,
            corners_px,
            rejected: None,
        };
        pairs.push(visit.sample().expect("a measured visit is a sample"));
        visits.push(visit);
    }
    Case {
        setup,
        mistake,
        lens,
        visits,
        pairs,
    }
}

/// What one case came to.
#[derive(Debug)]
struct Outcome {
    mistake: Mistake,
    setup: Setup,
    level: Level,
    blamed: Vec<GivenFile>,
    ambiguous: bool,
    /// Worst error of the two transforms against the truth: mm, degrees.
    error: (f64, f64),
    reason: String,
}

fn solve_case(c: &Case, config: &CellConfig, board: &Target) -> Outcome {
    let mut config = config.clone();
    config.camera_mut().setup = c.setup;
    let (camera_mount, target_mount) = truth(c.setup);
    config.camera_mut().nominal = CellTransforms {
        setup: c.setup,
        camera_mount,
        target_mount,
    };
    let solved = handeye_records::solve_session(
        c.setup,
        &c.pairs,
        &c.visits,
        Some((board, &c.lens)),
        &config,
    )
    .unwrap();
    let verdict = solved.verdict.clone().unwrap();
    let model = &solved
        .cell_model
        .as_ref()
        .expect("the cell model ran")
        .summary;
    let e1 = pose_error_mm_deg(&solved.calibration.camera_mount, &camera_mount);
    let e2 = pose_error_mm_deg(&solved.calibration.target_mount, &target_mount);
    Outcome {
        mistake: c.mistake,
        setup: c.setup,
        level: verdict.level,
        blamed: if verdict.basis == handeye_solve::verdict::Basis::WithinAccuracy {
            Vec::new()
        } else {
            model.blamed()
        },
        ambiguous: model.ambiguous,
        error: (e1.0.max(e2.0), e1.1.max(e2.1)),
        reason: format!(
            "{}\n{:?}\n{}",
            verdict.terminal_lines(),
            model.candidates,
            solved
                .pose_space
                .notices
                .iter()
                .map(|n| n.message.as_str())
                .collect::<Vec<_>>()
                .join("\n")
        ),
    }
}

/// Runs `count` drawn cases from `seed` and checks the counts of the module doc.
fn drawn_cases(seed: u64, count: usize) {
    let board = Target::load(&repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap();
    let mut config = CellConfig::load(&repo().join("configs/sim-cell.yaml")).unwrap();
    // A new user's solver settings: the board-pose noise estimated from the residuals (the sim
    // cell's config gives sigmas tuned to its rendered frames).
    config.solver.rotation_sigma_deg = None;
    config.solver.translation_sigma_mm = None;
    let accuracy = config.verdict.accuracy();
    let mut rng = StdRng::seed_from_u64(seed);
    let mut outcomes = Vec::new();
    for k in 0..count {
        let setup = if k % 2 == 0 {
            Setup::EyeInHand
        } else {
            Setup::EyeToHand
        };
        let mistake = Mistake::draw(&mut rng);
        let c = case(rng.random(), setup, mistake, &board);
        let o = solve_case(&c, &config, &board);
        eprintln!(
            "case {k:3} {:>11} {:<18} {:?}: {} blamed {:?}{} error {:.3} mm {:.4}°",
            o.setup.to_string(),
            o.mistake.class(),
            o.mistake,
            o.level,
            o.blamed,
            if o.ambiguous { " (ambiguous)" } else { "" },
            o.error.0,
            o.error.1,
        );
        outcomes.push(o);
    }
    let drawn: Vec<Drawn> = outcomes
        .into_iter()
        .map(|o| Drawn {
            label: format!("{:?} {:?}", o.setup, o.mistake),
            mistake: o.mistake,
            level: o.level,
            blamed: o.blamed,
            error: Some(o.error),
            said: o.reason,
        })
        .collect();
    check_counts(&format!("{count} cases"), &drawn, accuracy);
}

/// One drawn case as issue #38 counts it.
#[derive(Debug)]
pub(crate) struct Drawn {
    /// The case, for the print of one counted against.
    pub label: String,
    /// The mistake drawn.
    pub mistake: Mistake,
    /// The verdict.
    pub level: Level,
    /// The files the verdict (or the run's error) names.
    pub blamed: Vec<GivenFile>,
    /// Worst error of the two transforms against the truth: mm, degrees (`None`: no answer).
    pub error: Option<(f64, f64)>,
    /// What was said.
    pub said: String,
}

/// Issue #38's counts over drawn cases, printed and asserted: the wrong file named in ≥ 95 %,
/// the other file blamed in none, GOOD with an answer outside the accuracy in none, a corrected
/// answer (CHECK) outside the accuracy in none, and nothing wrong GOOD in ≥ 95 %.
pub(crate) fn check_counts(
    label: &str,
    cases: &[Drawn],
    accuracy: handeye_solve::verdict::Accuracy,
) {
    let outside = |o: &Drawn| {
        o.error
            .is_none_or(|(mm, deg)| mm > accuracy.translation_mm || deg > accuracy.rotation_deg)
    };
    let wrong: Vec<&Drawn> = cases
        .iter()
        .filter(|o| o.mistake != Mistake::Nothing)
        .collect();
    let right = wrong
        .iter()
        .filter(|o| o.blamed == o.mistake.wrong())
        .count();
    let misblamed: Vec<&Drawn> = cases
        .iter()
        .filter(|o| {
            let truth = o.mistake.wrong();
            o.blamed.iter().any(|f| !truth.contains(f))
                && !truth.iter().any(|f| o.blamed.contains(f))
        })
        .collect();
    let good_but_wrong: Vec<&Drawn> = cases
        .iter()
        .filter(|o| o.level == Level::Good && outside(o))
        .collect();
    let nothing: Vec<&Drawn> = cases
        .iter()
        .filter(|o| o.mistake == Mistake::Nothing)
        .collect();
    let nothing_good = nothing.iter().filter(|o| o.level == Level::Good).count();
    let corrected_outside: Vec<&Drawn> = wrong
        .iter()
        .copied()
        .filter(|o| o.level == Level::Check && outside(o))
        .collect();
    eprintln!(
        "{label}: wrong file named right in {right} of {}; blamed the other file in {}; GOOD outside the accuracy in {}; nothing wrong GOOD in {nothing_good} of {}; corrected (CHECK) with the answer outside the accuracy in {}",
        wrong.len(),
        misblamed.len(),
        good_but_wrong.len(),
        nothing.len(),
        corrected_outside.len(),
    );
    for o in cases.iter().filter(|o| {
        o.blamed != o.mistake.wrong() || (o.mistake == Mistake::Nothing && o.level != Level::Good)
    }) {
        eprintln!("--- {}:\n{}", o.label, o.said);
    }
    assert!(
        misblamed.is_empty(),
        "blamed the other file: {misblamed:#?}"
    );
    assert!(
        good_but_wrong.is_empty(),
        "GOOD and wrong: {good_but_wrong:#?}"
    );
    // Where the views determine the wrong quantity the answer uses the estimate: within the
    // accuracy asked.
    assert!(
        corrected_outside.is_empty(),
        "CHECK with the corrected answer outside the accuracy: {corrected_outside:#?}"
    );
    assert!(
        right as f64 >= 0.95 * wrong.len() as f64,
        "the wrong file named in {right} of {}",
        wrong.len()
    );
    assert!(
        nothing_good as f64 >= 0.95 * nothing.len() as f64,
        "nothing wrong GOOD in {nothing_good} of {}",
        nothing.len()
    );
}

/// A seeded draw small enough for every `cargo test`.
#[test]
fn a_wrong_file_drawn_at_random_is_named_and_a_right_one_is_good() {
    drawn_cases(38, 40);
}

/// The full draw of issue #38 (≥ 100 cases, another seed): `cargo test --test it -- --ignored
/// cell_model::` (about two minutes in a debug build).
#[test]
#[ignore = "160 drawn cases: minutes in a debug build"]
fn a_hundred_and_sixty_wrong_files_drawn_at_random() {
    drawn_cases(3838, 160);
}
