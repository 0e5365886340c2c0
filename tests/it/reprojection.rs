//! Reprojection-space refinement against known truth: the simulated cell's transforms and camera,
//! board corners projected through the true chain with seeded pixel noise and a seeded robot
//! repeatability error, the same frames solved in pose space (PnP per frame, then the refined
//! `A = X·B·Y` solver) and in reprojection space.

use nalgebra::{Matrix3, Point2, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::{pose_from_rotvec, Pose};
use handeye_core::notice::NoticeKind;
use handeye_core::setup::{PosePair, Setup};
use handeye_solve::intrinsics::{calibrate_from_scratch, zhang_intrinsics};
use handeye_solve::{
    self as solve, refine_reprojection, reprojection_errors, Corner, Frame, NoiseModel,
    ReprojectionCalibration, ReprojectionOptions, RobotPrior, SolveError, SolveOptions,
};
use handeye_vision::pnp::estimate_pose_from_points;
use handeye_vision::Board;

use crate::util;
use util::{dataset, pose_error_mm_deg, repo};

fn board() -> Board {
    Board::load(&repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap()
}

fn sim_camera() -> CameraModel {
    CameraModel::load(&repo().join("configs/cameras/sim-1280x720.yaml")).unwrap()
}

/// The sim cell's ground truth (configs/sim-cell.yaml, `simulation:`).
fn truth() -> (Pose, Pose) {
    (
        pose_from_rotvec(
            Vector3::new(0.0312, -0.0694, 0.0447),
            Vector3::new(0.021, -0.016, 1.561),
        ),
        pose_from_rotvec(
            Vector3::new(0.5034, -0.1467, 0.0021),
            Vector3::new(0.012, -0.018, 0.297),
        ),
    )
}

struct Scenario {
    frames: Vec<Frame>,
    pairs: Vec<PosePair>,
}

/// `T_camera_target` of a camera on a cap above the board centre looking at it.
fn view(rng: &mut StdRng, max_tilt_deg: f64, fronto_parallel: bool) -> Pose {
    let centre = Vector3::new(0.145, 0.145, 0.0);
    let distance = rng.random_range(0.45..0.65);
    let roll = rng.random_range(-0.4..0.4);
    let (position, look_at) = if fronto_parallel {
        let shift = Vector3::new(
            rng.random_range(-0.1..0.1),
            rng.random_range(-0.06..0.06),
            0.0,
        );
        (centre + shift + Vector3::z() * distance, centre + shift)
    } else {
        let tilt = rng.random_range(0.3..1.0) * max_tilt_deg.to_radians();
        let azimuth = rng.random_range(0.0..std::f64::consts::TAU);
        let direction = Vector3::new(
            tilt.sin() * azimuth.cos(),
            tilt.sin() * azimuth.sin(),
            tilt.cos(),
        );
        (centre + direction * distance, centre)
    };
    let z = (look_at - position).normalize();
    let reference = if z.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let x = (reference - z * z.dot(&reference)).normalize();
    let y = z.cross(&x);
    let target_from_camera_rotation =
        Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]))
            * Rotation3::from_axis_angle(&Vector3::z_axis(), roll);
    let target_from_camera = Pose::from_parts(
        Translation3::from(position),
        UnitQuaternion::from_rotation_matrix(&target_from_camera_rotation),
    );
    target_from_camera.inverse()
}

/// Eye-in-hand frames: board corners seen through the true chain, pixel noise `pixel_sigma`,
/// the robot's reported pose off its true pose by `robot_sigma` (m, rad per axis).
fn scenario(
    seed: u64,
    count: usize,
    pixel_sigma: f64,
    robot_sigma: (f64, f64),
    fronto_parallel: bool,
) -> Scenario {
    let mut rng = StdRng::seed_from_u64(seed);
    let board = board();
    let camera = sim_camera();
    let (flange_from_camera, base_from_target) = truth();
    let pixel_noise = Normal::new(0.0, pixel_sigma).unwrap();
    let translation_noise = Normal::new(0.0, robot_sigma.0).unwrap();
    let rotation_noise = Normal::new(0.0, robot_sigma.1).unwrap();
    let mut frames = Vec::new();
    let mut pairs = Vec::new();
    while frames.len() < count {
        let camera_from_target = view(&mut rng, 35.0, fronto_parallel);
        let true_base_from_flange =
            base_from_target * camera_from_target.inverse() * flange_from_camera.inverse();
        let mut vector = || {
            Vector3::new(
                translation_noise.sample(&mut rng),
                translation_noise.sample(&mut rng),
                translation_noise.sample(&mut rng),
            )
        };
        let dt = vector();
        let dr = Vector3::new(
            rotation_noise.sample(&mut rng),
            rotation_noise.sample(&mut rng),
            rotation_noise.sample(&mut rng),
        );
        // Off the true pose the way the refinement models a robot's error: t + δt, R·exp(δθ).
        let reported = Pose::from_parts(
            Translation3::from(true_base_from_flange.translation.vector + dt),
            true_base_from_flange.rotation * UnitQuaternion::from_scaled_axis(dr),
        );
        let corners =
            util::seen_corners(&board, &camera, &camera_from_target, &pixel_noise, &mut rng);
        if corners.len() < 40 {
            continue;
        }
        let correspondences: Vec<(Point3<f64>, Point2<f64>)> = corners
            .iter()
            .map(|c| (c.point_in_target, c.pixel))
            .collect();
        let measured = estimate_pose_from_points(&camera, &correspondences, 36)
            .unwrap()
            .camera_from_target;
        let id = format!("pose-{:03}", frames.len());
        let mut pair = PosePair::new(reported, measured);
        pair.id = Some(id.clone());
        pairs.push(pair);
        frames.push(Frame {
            base_from_flange: reported,
            corners,
            id: Some(id),
        });
    }
    Scenario { frames, pairs }
}

/// Errors of (camera mount, target mount) against the truth: (mm, degrees) each.
fn errors(camera_mount: &Pose, target_mount: &Pose) -> [(f64, f64); 2] {
    let (c, t) = truth();
    [
        pose_error_mm_deg(camera_mount, &c),
        pose_error_mm_deg(target_mount, &t),
    ]
}

/// The config's default pose-space solver (`solver:` defaults in the cell config).
fn pose_options() -> SolveOptions {
    SolveOptions {
        noise: NoiseModel {
            rotation_sigma_rad: 0.05f64.to_radians(),
            translation_sigma_m: 0.3e-3,
        },
        ..SolveOptions::default()
    }
}

#[test]
fn reprojection_answer_is_closer_to_the_truth_than_the_pose_space_answer() {
    let mut pose_sum = 0.0;
    let mut reprojection_sum = 0.0;
    let seeds = [1u64, 2, 3, 4, 5, 6, 7, 8];
    for seed in seeds {
        let s = scenario(seed, 12, 0.3, (2e-5, 0.002f64.to_radians()), false);
        let pose = solve::solve(Setup::EyeInHand, &s.pairs, &pose_options()).unwrap();
        let camera = sim_camera();
        let reprojection = refine_reprojection(
            Setup::EyeInHand,
            &s.frames,
            &camera,
            &pose.camera_mount,
            &pose.target_mount,
            &ReprojectionOptions::default(),
        )
        .unwrap();
        let [(pc_mm, pc_deg), (pt_mm, pt_deg)] = errors(&pose.camera_mount, &pose.target_mount);
        let [(rc_mm, rc_deg), (rt_mm, rt_deg)] =
            errors(&reprojection.camera_mount, &reprojection.target_mount);
        // One score per answer: mm plus degrees scaled so 0.01° counts like 0.1 mm.
        let pose_score = pc_mm + pt_mm + 10.0 * (pc_deg + pt_deg);
        let reprojection_score = rc_mm + rt_mm + 10.0 * (rc_deg + rt_deg);
        eprintln!(
            "seed {seed}: pose space {pc_mm:.3} mm {pc_deg:.4}° / {pt_mm:.3} mm {pt_deg:.4}°; reprojection {rc_mm:.3} mm {rc_deg:.4}° / {rt_mm:.3} mm {rt_deg:.4}°; RMS {:.3} px (pose-space answer {:.3} px)",
            reprojection.errors.rms_px,
            reprojection_errors(Setup::EyeInHand, &s.frames, &camera, &pose.camera_mount, &pose.target_mount).rms_px
        );
        pose_sum += pose_score;
        reprojection_sum += reprojection_score;
        assert!(reprojection.converged);
    }
    let ratio = reprojection_sum / pose_sum;
    eprintln!(
        "error ratio reprojection / pose space over {} seeds: {ratio:.3}",
        seeds.len()
    );
    // Stated margin: at least 15 % closer to the truth on average over the seeds. (Measured
    // 0.780; it was 0.686 against the pose-space answer with fixed noise, before the pose space
    // estimated its noise from the residuals and got 12 % closer to the truth here itself.)
    assert!(ratio < 0.85, "ratio {ratio:.3}");
}

#[test]
fn intrinsics_from_scratch_recover_the_camera_and_the_cell() {
    let s = scenario(21, 20, 0.2, (0.0, 0.0), false);
    let truth_camera = sim_camera();
    let scratch = calibrate_from_scratch(
        Setup::EyeInHand,
        &s.frames,
        truth_camera.width,
        truth_camera.height,
        &pose_options(),
        &ReprojectionOptions::default(),
    )
    .unwrap();
    let (pose, joint) = (scratch.pose_space, scratch.joint);
    let c = joint.camera;
    eprintln!(
        "fx {:.3} fy {:.3} cx {:.3} cy {:.3} dist {:?}; RMS {:.4} px; pose-space start {:?}",
        c.fx,
        c.fy,
        c.cx,
        c.cy,
        c.distortion_coefficients(),
        joint.errors.rms_px,
        errors(&pose.camera_mount, &pose.target_mount)
    );
    for (name, found, truth) in [
        ("fx", c.fx, truth_camera.fx),
        ("fy", c.fy, truth_camera.fy),
        ("cx", c.cx, truth_camera.cx),
        ("cy", c.cy, truth_camera.cy),
    ] {
        // The bar: within 0.2 % or 0.5 px.
        let ok = (found - truth).abs() <= (0.002 * truth).max(0.5);
        assert!(ok, "{name}: {found:.3} px, truth {truth:.3} px");
    }
    // Per-corner error norm of 2-D Gaussian noise σ: RMS σ·√2; the fit absorbs a little.
    let expected = 0.2 * 2f64.sqrt();
    assert!(
        joint.errors.rms_px > 0.85 * expected && joint.errors.rms_px < 1.1 * expected,
        "RMS {:.4} px, noise level {expected:.4} px",
        joint.errors.rms_px
    );
    for (mm, deg) in errors(&joint.camera_mount, &joint.target_mount) {
        assert!(mm < 0.5 && deg < 0.05, "{mm:.3} mm, {deg:.4}°");
    }
    let sigma = joint.intrinsics_sigma_px.unwrap();
    assert!(sigma.iter().all(|s| *s > 0.0 && *s < 2.0), "{sigma:?}");
}

#[test]
fn fronto_parallel_frames_are_refused_for_intrinsics() {
    let s = scenario(5, 10, 0.2, (0.0, 0.0), true);
    let error = zhang_intrinsics(&s.frames, 1280, 720).unwrap_err();
    match &error {
        SolveError::DegenerateIntrinsics { max_tilt_deg, .. } => {
            assert!(*max_tilt_deg < 3.0, "{error}")
        }
        other => panic!("expected DegenerateIntrinsics, got {other}"),
    }
    let message = error.to_string();
    assert!(message.contains("tilted by 20–45°"), "{message}");
}

#[test]
fn robot_corrections_absorb_repeatability_error() {
    // A robot worse than its spec by far (0.3 mm, 0.03°): with the prior at that level, the
    // corrections soak the pose errors up and the unknowns stay close.
    let sigma = (0.3e-3, 0.03f64.to_radians());
    let s = scenario(8, 12, 0.2, sigma, false);
    let camera = sim_camera();
    let pose = solve::solve(Setup::EyeInHand, &s.pairs, &pose_options()).unwrap();
    let plain = refine_reprojection(
        Setup::EyeInHand,
        &s.frames,
        &camera,
        &pose.camera_mount,
        &pose.target_mount,
        &ReprojectionOptions::default(),
    )
    .unwrap();
    let corrected = refine_reprojection(
        Setup::EyeInHand,
        &s.frames,
        &camera,
        &pose.camera_mount,
        &pose.target_mount,
        &ReprojectionOptions {
            robot_prior: Some(RobotPrior {
                translation_sigma_m: sigma.0,
                rotation_sigma_rad: sigma.1,
            }),
            ..ReprojectionOptions::default()
        },
    )
    .unwrap();
    eprintln!(
        "plain RMS {:.3} px {:?}; corrected RMS {:.3} px {:?}",
        plain.errors.rms_px,
        errors(&plain.camera_mount, &plain.target_mount),
        corrected.errors.rms_px,
        errors(&corrected.camera_mount, &corrected.target_mount)
    );
    assert_eq!(corrected.corrected_base_from_flange.len(), s.frames.len());
    // More parameters always fit the pixels better; what matters is the unknowns: the plain
    // solve pushes the robot error into them (~5 + 2 mm here), the corrected one keeps them
    // near the truth (~0.4 + 0.4 mm). Stated margin: at least 3x closer in summed translation.
    let summed_mm = |e: [(f64, f64); 2]| e[0].0 + e[1].0;
    let plain_mm = summed_mm(errors(&plain.camera_mount, &plain.target_mount));
    let corrected_mm = summed_mm(errors(&corrected.camera_mount, &corrected.target_mount));
    assert!(
        3.0 * corrected_mm < plain_mm,
        "corrected {corrected_mm:.3} mm vs plain {plain_mm:.3} mm (summed translation error)"
    );
    for (mm, deg) in errors(&corrected.camera_mount, &corrected.target_mount) {
        assert!(mm < 1.0 && deg < 0.1, "{mm:.3} mm, {deg:.4}°");
    }
}

/// Variance component estimation: started 5x off on every sigma, the fit finds the corner noise
/// and the robot's repeatability the frames were made with, and weighs by them.
#[test]
fn noise_estimation_recovers_the_pixel_noise_and_the_robot_repeatability() {
    let (pixel_sigma, robot_sigma) = (0.15, (0.05e-3, 0.005f64.to_radians()));
    let camera = sim_camera();
    let mut wrong_sum = 0.0;
    let mut estimated_sum = 0.0;
    for seed in 30..34 {
        let s = scenario(seed, 20, pixel_sigma, robot_sigma, false);
        let pose = solve::solve(Setup::EyeInHand, &s.pairs, &pose_options()).unwrap();
        let wrong = ReprojectionOptions {
            pixel_sigma_px: pixel_sigma * 5.0,
            robot_prior: Some(RobotPrior {
                translation_sigma_m: robot_sigma.0 / 5.0,
                rotation_sigma_rad: robot_sigma.1 / 5.0,
            }),
            ..ReprojectionOptions::default()
        };
        let refine = |options: &ReprojectionOptions| {
            refine_reprojection(
                Setup::EyeInHand,
                &s.frames,
                &camera,
                &pose.camera_mount,
                &pose.target_mount,
                options,
            )
            .unwrap()
        };
        let fixed = refine(&wrong);
        let estimated = refine(&ReprojectionOptions {
            estimate_noise: true,
            ..wrong.clone()
        });
        let prior = estimated.robot_prior.unwrap();
        eprintln!(
            "seed {seed}: estimated {:.4} px, {:.4} mm, {:.5}° (truth {pixel_sigma} px, {} mm, {}°)",
            estimated.pixel_sigma_px,
            prior.translation_sigma_m * 1e3,
            prior.rotation_sigma_rad.to_degrees(),
            robot_sigma.0 * 1e3,
            robot_sigma.1.to_degrees()
        );
        assert!((estimated.pixel_sigma_px / pixel_sigma - 1.0).abs() < 0.1);
        for ratio in [
            prior.translation_sigma_m / robot_sigma.0,
            prior.rotation_sigma_rad / robot_sigma.1,
        ] {
            assert!(
                (0.6..1.6).contains(&ratio),
                "robot sigma {ratio:.2}x the truth"
            );
        }
        assert!(estimated.converged);
        let total = |c: &ReprojectionCalibration| -> f64 {
            errors(&c.camera_mount, &c.target_mount)
                .iter()
                .map(|e| e.0)
                .sum()
        };
        wrong_sum += total(&fixed);
        estimated_sum += total(&estimated);
    }
    eprintln!("summed translation error: wrong fixed sigmas {wrong_sum:.4} mm, estimated {estimated_sum:.4} mm");
    assert!(estimated_sum < wrong_sum);
}

/// Is the reprojection answer's 1-sigma honest (it is what the result file reports by default)?
/// 300 sessions of 12 frames with the demo cell's noise (0.1 px corners, 0.02 mm / 0.002° robot),
/// the solver told 3x too much of both and estimating the real figures: the true error over the
/// reported sigma, per axis of each unknown, must fall within 1 sigma ~68.3 % and within 3 sigma
/// ≥ 98.5 % of the time (900 samples per quantity: ±5 % allows for the binomial scatter and the
/// correlated axes of one session).
#[test]
fn reprojection_sigma_covers_the_true_error() {
    let (pixel_sigma, robot_sigma) = (0.1, (0.02e-3, 0.002f64.to_radians()));
    let camera = sim_camera();
    let (camera_truth, target_truth) = truth();
    let options = ReprojectionOptions {
        pixel_sigma_px: 3.0 * pixel_sigma,
        robot_prior: Some(RobotPrior {
            translation_sigma_m: 3.0 * robot_sigma.0,
            rotation_sigma_rad: 3.0 * robot_sigma.1,
        }),
        estimate_noise: true,
        ..ReprojectionOptions::default()
    };
    // [camera rotation, camera translation, target rotation, target translation]: (≤1σ, ≤3σ, n).
    let mut counts = [(0usize, 0usize, 0usize); 4];
    for seed in 0..300 {
        let s = scenario(1000 + seed, 12, pixel_sigma, robot_sigma, false);
        let pose = solve::solve(Setup::EyeInHand, &s.pairs, &pose_options()).unwrap();
        let r = refine_reprojection(
            Setup::EyeInHand,
            &s.frames,
            &camera,
            &pose.camera_mount,
            &pose.target_mount,
            &options,
        )
        .unwrap();
        let u = r.uncertainty.expect("a covariance");
        for (k, (estimate, truth)) in [
            (r.camera_mount, camera_truth),
            (r.target_mount, target_truth),
        ]
        .iter()
        .enumerate()
        {
            // The covariance's perturbation: R_est = exp(δθ)·R_true, t_est = t_true + δt.
            let d_theta = (estimate.rotation * truth.rotation.inverse()).scaled_axis();
            let d_t = estimate.translation.vector - truth.translation.vector;
            for axis in 0..3 {
                let row = 6 * k + axis;
                for (q, error, variance) in [
                    (2 * k, d_theta[axis], u.covariance[(row, row)]),
                    (2 * k + 1, d_t[axis], u.covariance[(row + 3, row + 3)]),
                ] {
                    let z = (error / variance.sqrt()).abs();
                    counts[q].0 += usize::from(z <= 1.0);
                    counts[q].1 += usize::from(z <= 3.0);
                    counts[q].2 += 1;
                }
            }
        }
    }
    let names = [
        "T_flange_camera rotation",
        "T_flange_camera translation",
        "T_base_target rotation",
        "T_base_target translation",
    ];
    for (name, (one, three, n)) in names.iter().zip(counts) {
        let (p1, p3) = (one as f64 / n as f64, three as f64 / n as f64);
        eprintln!(
            "{name}: within 1 sigma {:.1} %, within 3 sigma {:.1} % ({n} axis samples)",
            100.0 * p1,
            100.0 * p3
        );
        assert!(
            (p1 - 0.683).abs() < 0.05,
            "{name}: {:.1} % within 1 sigma",
            100.0 * p1
        );
        assert!(p3 >= 0.985, "{name}: {:.1} % within 3 sigma", 100.0 * p3);
    }
}

#[test]
fn a_frame_with_a_wrong_robot_pose_is_flagged() {
    let mut s = scenario(9, 12, 0.2, (0.0, 0.0), false);
    // Frame 4's robot pose is 5 mm off: its corners all move by several pixels.
    s.frames[4].base_from_flange =
        pose_from_rotvec(Vector3::new(0.005, 0.0, 0.0), Vector3::zeros())
            * s.frames[4].base_from_flange;
    let (c, t) = truth();
    let result = refine_reprojection(
        Setup::EyeInHand,
        &s.frames,
        &sim_camera(),
        &c,
        &t,
        &ReprojectionOptions::default(),
    )
    .unwrap();
    assert_eq!(
        result.outlier_frames,
        vec![4],
        "{:?}",
        result.errors.frame_rms_px
    );
    assert!(result
        .notices
        .iter()
        .any(|w| w.message.contains("pose-004")));
}

#[test]
fn bad_input_is_a_clear_error() {
    let s = scenario(10, 3, 0.2, (0.0, 0.0), false);
    let (c, t) = truth();
    let options = ReprojectionOptions {
        pixel_sigma_px: -1.0,
        ..ReprojectionOptions::default()
    };
    let error = refine_reprojection(Setup::EyeInHand, &s.frames, &sim_camera(), &c, &t, &options)
        .unwrap_err();
    assert!(error.to_string().contains("pixel_sigma_px"), "{error}");
    let error = refine_reprojection(
        Setup::EyeInHand,
        &s.frames[..2],
        &sim_camera(),
        &c,
        &t,
        &ReprojectionOptions::default(),
    )
    .unwrap_err();
    assert!(
        matches!(error, SolveError::TooFewSamples { found: 2, .. }),
        "{error}"
    );
    let mut frames = s.frames.clone();
    frames[1].corners[0].pixel.x = f64::NAN;
    let error = refine_reprojection(
        Setup::EyeInHand,
        &frames,
        &sim_camera(),
        &c,
        &t,
        &ReprojectionOptions::default(),
    )
    .unwrap_err();
    assert!(error.to_string().contains("sample 1"), "{error}");
}

#[test]
fn visp_eye_to_hand_reprojection_is_no_worse_than_pose_space() {
    use handeye_vision::pnp::estimate_board_pose;
    use handeye_vision::{detect::load_gray_image, DetectorOptions, TagDetector};
    let Some(folder) = dataset("visp_franka_data-eye-to-hand") else {
        return;
    };
    let board = Board::load(&repo().join("configs/targets/single-tag36h11-id10.yaml")).unwrap();
    let camera =
        CameraModel::load(&repo().join("tests/data/visp_franka_camera_info.yaml")).unwrap();
    let detector = TagDetector::spawn(&board, DetectorOptions::default()).unwrap();
    let mut frames = Vec::new();
    let mut pairs = Vec::new();
    for n in 1..=8 {
        let image = load_gray_image(&folder.join(format!("franka_image-{n}.png"))).unwrap();
        let detection = detector.detect(&image).unwrap();
        let pose = estimate_board_pose(&board, &camera, &detection).unwrap();
        let robot = handeye_formats::import::read_visp_pose(
            &folder.join(format!("franka_pose_rPe_{n}.yaml")),
        )
        .unwrap();
        let id = format!("franka-{n}");
        let mut pair = PosePair::new(robot, pose.camera_from_target);
        pair.id = Some(id.clone());
        pairs.push(pair);
        frames.push(Frame {
            base_from_flange: robot,
            corners: detection
                .correspondences(&board)
                .into_iter()
                .map(|(point_in_target, pixel)| Corner {
                    point_in_target,
                    pixel,
                })
                .collect(),
            id: Some(id),
        });
    }
    // Real data with a lone small tag: noise levels as the default solver settings assume.
    let pose = solve::solve(Setup::EyeToHand, &pairs, &SolveOptions::default()).unwrap();
    let reprojection = refine_reprojection(
        Setup::EyeToHand,
        &frames,
        &camera,
        &pose.camera_mount,
        &pose.target_mount,
        &ReprojectionOptions::default(),
    )
    .unwrap();
    let before = reprojection_errors(
        Setup::EyeToHand,
        &frames,
        &camera,
        &pose.camera_mount,
        &pose.target_mount,
    );
    for (n, (a, b)) in before
        .frame_rms_px
        .iter()
        .zip(&reprojection.errors.frame_rms_px)
        .enumerate()
    {
        eprintln!(
            "franka-{}: reprojection RMS pose space {a:.3} px, reprojection space {b:.3} px",
            n + 1
        );
    }
    eprintln!(
        "overall: pose space {:.3} px (max {:.3}), reprojection space {:.3} px (max {:.3})",
        before.rms_px, before.max_px, reprojection.errors.rms_px, reprojection.errors.max_px
    );
    assert_eq!(reprojection.errors.frame_rms_px.len(), 8);
    assert!(reprojection
        .errors
        .frame_rms_px
        .iter()
        .all(|v| v.is_finite()));
    // The refinement starts at the pose-space answer and minimises this very error.
    assert!(
        reprojection.errors.rms_px <= before.rms_px * (1.0 + 1e-9),
        "reprojection {:.4} px vs pose space {:.4} px",
        reprojection.errors.rms_px,
        before.rms_px
    );
}

/// With robot corrections on (the default), a frame whose recorded robot pose is far off would
/// be absorbed by its own correction, raise the estimated repeatability for every frame and pull
/// the answer: it is flagged instead, its correction runs free (it leaves the hand-eye fit) and
/// the answer and the estimated repeatability stay those of the other frames.
#[test]
fn a_far_off_robot_pose_is_flagged_and_left_out_with_corrections_on() {
    let robot_sigma = (0.02e-3, 0.002f64.to_radians());
    let mut s = scenario(9, 12, 0.1, robot_sigma, false);
    let recorded_error = 0.003;
    s.frames[4].base_from_flange =
        pose_from_rotvec(Vector3::new(recorded_error, 0.0, 0.0), Vector3::zeros())
            * s.frames[4].base_from_flange;
    let (c, t) = truth();
    let result = refine_reprojection(
        Setup::EyeInHand,
        &s.frames,
        &sim_camera(),
        &c,
        &t,
        &ReprojectionOptions {
            robot_prior: Some(RobotPrior {
                translation_sigma_m: robot_sigma.0,
                rotation_sigma_rad: robot_sigma.1,
            }),
            estimate_noise: true,
            ..ReprojectionOptions::default()
        },
    )
    .unwrap();
    let prior = result.robot_prior.unwrap();
    let errors = errors(&result.camera_mount, &result.target_mount);
    eprintln!(
        "flagged {:?}; estimated repeatability {:.4} mm; errors {errors:?}",
        result.outlier_frames,
        prior.translation_sigma_m * 1e3
    );
    assert_eq!(result.outlier_frames, vec![4]);
    assert!(result
        .notices
        .iter()
        .any(|w| w.kind == NoticeKind::RobotPoseOutliers && w.message.contains("pose-004")));
    let ratio = prior.translation_sigma_m / robot_sigma.0;
    assert!(
        (0.6..1.6).contains(&ratio),
        "repeatability {ratio:.2}x the truth"
    );
    // Its free correction finds the 3 mm the recorded pose is off.
    let found = (result.corrected_base_from_flange[4].translation.vector
        - s.frames[4].base_from_flange.translation.vector)
        .norm();
    assert!((found - recorded_error).abs() < 1e-4, "{found}");
    for (mm, deg) in errors {
        assert!(mm < 0.15 && deg < 0.01, "{mm:.3} mm, {deg:.4}°");
    }
}

/// Issue #30 (third finding): an arm that repeats better than configured (the mock UR
/// controller is perfectly repeatable) gets information, not a warning that makes the verdict
/// CHECK; robot poses that scatter far more than configured still get a warning.
#[test]
fn an_arm_better_than_configured_is_information_and_a_far_worse_one_a_warning() {
    use handeye_core::notice::Severity;
    let camera = sim_camera();
    let robot_notice = |robot_sigma: (f64, f64), configured: (f64, f64)| {
        let s = scenario(41, 16, 0.1, robot_sigma, false);
        let pose = solve::solve(Setup::EyeInHand, &s.pairs, &pose_options()).unwrap();
        let refined = refine_reprojection(
            Setup::EyeInHand,
            &s.frames,
            &camera,
            &pose.camera_mount,
            &pose.target_mount,
            &ReprojectionOptions {
                estimate_noise: true,
                robot_prior: Some(RobotPrior {
                    translation_sigma_m: configured.0,
                    rotation_sigma_rad: configured.1,
                }),
                ..ReprojectionOptions::default()
            },
        )
        .unwrap();
        let (truth_camera, _) = truth();
        let (mm, _) = pose_error_mm_deg(&refined.camera_mount, &truth_camera);
        let notice = refined
            .notices
            .iter()
            .find(|n| n.kind == NoticeKind::NoiseEstimate)
            .cloned()
            .unwrap_or_else(|| panic!("no robot-repeatability notice: {:#?}", refined.notices));
        (notice, mm)
    };
    // A perfect arm, configured at a UR's 0.03 mm / 0.003°.
    let (better, mm) = robot_notice((1e-9, 1e-9), (0.03e-3, 0.003f64.to_radians()));
    assert_eq!(better.severity, Severity::Info, "{better:?}");
    assert!(
        better.message.contains("repeats better than configured"),
        "{}",
        better.message
    );
    assert!(mm < 0.1, "the answer is good ({mm:.3} mm off)");
    // Poses scattered by 2 mm / 0.2°, configured at 0.01 mm / 0.001°.
    let (worse, _) = robot_notice(
        (2e-3, 0.2f64.to_radians()),
        (0.01e-3, 0.001f64.to_radians()),
    );
    assert_eq!(worse.severity, Severity::Warning, "{worse:?}");
    assert!(
        worse.message.contains("check the configured repeatability"),
        "{}",
        worse.message
    );
}
