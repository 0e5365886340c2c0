//! Monte Carlo over seeds (issue #27): the joint solve of the three-camera cell against each
//! camera solved alone and against chaining two single-camera answers, on the same samples, in
//! pose space and in pixel space.

use handeye_core::geometry::Pose;

use crate::util;

/// Monte Carlo over seeds, on the same samples: the joint solve's error in every mount is at
/// most the same camera solved alone (RMS over the seeds), strictly smaller for the fixed
/// cameras that share the flange board, and the fixed cameras' relative pose is more accurate
/// than chaining their two single-camera answers. The cell is the three-camera config's truth;
/// the flange poses are the robot poses the run visits (read from a run's folder would tie this
/// to rendering: instead 20 poses of the same spread); the board-pose noise is what the rendered
/// run estimates per camera (wrist at ~0.5 m, fixed cameras at ~0.7 m).
#[test]
fn joint_solve_beats_each_camera_alone_and_chaining_over_seeds() {
    use handeye_core::setup::{predict, Setup};
    use handeye_solve::cameras::{
        pose_error, solve_cameras, CamerasObservation, CamerasOptions, CamerasStart,
    };
    use rand::SeedableRng;
    use util::cameras::{board_pose_noise, cameras_data, jitter, nominal_start, wrist_views};

    let cell = util::cameras::three_cameras();
    let truth: Vec<_> = cell.cameras.iter().map(|c| c.simulation.unwrap()).collect();
    let setups: Vec<Setup> = truth.iter().map(|t| t.setup).collect();
    let seeds = 200;
    let cameras = truth.len();
    let (mut joint_sq, mut alone_sq) = (vec![0.0; cameras], vec![0.0; cameras]);
    let (mut relative_joint_sq, mut relative_chained_sq) = (0.0, 0.0);
    for seed in 0..seeds {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let flanges = wrist_views(&mut rng, 20);
        let mut observations = Vec::new();
        for (i, flange) in flanges.iter().enumerate() {
            for (c, t) in truth.iter().enumerate() {
                let (sr, st) = board_pose_noise(setups[c]);
                let exact = predict(t.setup, &t.camera_mount, &t.target_mount, flange);
                observations.push(CamerasObservation {
                    camera: c,
                    pose: i,
                    camera_from_target: exact * jitter(&mut rng, sr, st),
                    weight: 1.0,
                });
            }
        }
        let data = cameras_data(&cell, flanges, observations);
        // Both solves start from the same nominal (the config's), as a run without a prior would.
        let start = nominal_start(&cell);
        let joint = solve_cameras(&data, &start, &CamerasOptions::default()).unwrap();
        let mut alone_mounts = Vec::new();
        for c in 0..cameras {
            let one = CamerasStart {
                camera_mounts: vec![start.camera_mounts[c]],
                ..start.clone()
            };
            let alone = solve_cameras(&data.only(c), &one, &CamerasOptions::default()).unwrap();
            let (_, joint_mm) = pose_error(&joint.camera_mounts[c], &truth[c].camera_mount);
            let (_, alone_mm) = pose_error(&alone.camera_mounts[0], &truth[c].camera_mount);
            joint_sq[c] += joint_mm * joint_mm;
            alone_sq[c] += alone_mm * alone_mm;
            alone_mounts.push(alone.camera_mounts[0]);
        }
        let relative_truth = truth[1].camera_mount.inverse() * truth[2].camera_mount;
        let relative = &joint.relative[0];
        assert_eq!((relative.from, relative.to), (1, 2));
        let (_, mm) = pose_error(&relative.pose, &relative_truth);
        relative_joint_sq += mm * mm;
        let (_, mm) = pose_error(
            &(alone_mounts[1].inverse() * alone_mounts[2]),
            &relative_truth,
        );
        relative_chained_sq += mm * mm;
    }
    let rms = |sq: f64| (sq / seeds as f64).sqrt();
    for c in 0..cameras {
        let (joint, alone) = (rms(joint_sq[c]), rms(alone_sq[c]));
        println!(
            "{}: mount translation RMS error joint {joint:.4} mm, alone {alone:.4} mm ({:.0} % lower)",
            cell.cameras[c].name,
            100.0 * (1.0 - joint / alone)
        );
        // Never worse (to the precision of the fit); the wrist camera is the only eye-in-hand
        // one, so in pose space it shares nothing and equals its own solve.
        assert!(
            joint <= alone * 1.001,
            "{}: joint {joint} mm > alone {alone} mm",
            cell.cameras[c].name
        );
        if setups[c] == Setup::EyeToHand {
            assert!(
                joint < 0.95 * alone,
                "{}: sharing the flange board must help: {joint} vs {alone}",
                cell.cameras[c].name
            );
        }
    }
    let (joint, chained) = (rms(relative_joint_sq), rms(relative_chained_sq));
    println!("T_cam_left_cam_right translation RMS error: joint {joint:.4} mm, chained {chained:.4} mm ({:.0} % lower)", 100.0 * (1.0 - joint / chained));
    assert!(
        joint < 0.9 * chained,
        "joint {joint} mm vs chained {chained} mm"
    );
}

/// Monte Carlo over seeds in pixel space, on the same corners: the three-camera cell's truth and
/// lenses, the board's real corners projected through the true chain with 0.1 px noise (what the
/// rendered run estimates), the flange poses reported with the sim arm's repeatability (0.02 mm,
/// 0.002°). The joint pixel-space solve (every flange pose estimated once for all cameras) is at
/// least as accurate as each camera alone (the same solve with its corners only) in every mount,
/// and the fixed cameras' relative pose beats chaining their single-camera answers.
#[test]
fn joint_pixel_solve_beats_each_camera_alone_over_seeds() {
    use handeye_core::camera_model::CameraModel;
    use handeye_core::setup::predict;
    use handeye_solve::cameras::{
        pose_error, solve_cameras, solve_cameras_pixels, CamerasFrame, CamerasObservation,
        CamerasOptions, CamerasStart,
    };
    use handeye_vision::Target;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    use util::cameras::{cameras_data, jitter, nominal_start, wrist_views};

    let cell = util::cameras::three_cameras();
    let truth: Vec<_> = cell.cameras.iter().map(|c| c.simulation.unwrap()).collect();
    let models: Vec<CameraModel> = cell
        .cameras
        .iter()
        .map(|c| CameraModel::load(c.intrinsics.as_ref().unwrap()).unwrap())
        .collect();
    let boards: Vec<Vec<nalgebra::Point3<f64>>> = cell
        .cameras
        .iter()
        .map(|c| {
            Target::load(&c.target)
                .unwrap()
                .points()
                .into_iter()
                .map(|(_, _, p)| p)
                .collect()
        })
        .collect();
    let robot = cell.robot_repeatability();
    let pixel_sigma = 0.1;
    let seeds = 40;
    let cameras = truth.len();
    let (mut joint_sq, mut alone_sq) = (vec![0.0; cameras], vec![0.0; cameras]);
    let (mut relative_joint_sq, mut relative_chained_sq) = (0.0, 0.0);
    let options = CamerasOptions {
        robot_sigma: Some(robot),
        ..CamerasOptions::default()
    };
    for seed in 0..seeds {
        let mut rng = rand::rngs::StdRng::seed_from_u64(1000 + seed);
        let unit = Normal::new(0.0, 1.0).unwrap();
        let true_flanges = wrist_views(&mut rng, 20);
        let reported: Vec<Pose> = true_flanges
            .iter()
            .map(|f| f * jitter(&mut rng, robot.1, robot.0))
            .collect();
        let (mut observations, mut frames) = (Vec::new(), Vec::new());
        for (i, flange) in true_flanges.iter().enumerate() {
            for (c, t) in truth.iter().enumerate() {
                let camera_from_target = predict(t.setup, &t.camera_mount, &t.target_mount, flange);
                let corners: Vec<_> = boards[c]
                    .iter()
                    .filter_map(|p| {
                        let pixel = models[c].project(&(camera_from_target * p))?;
                        let noisy = pixel
                            + nalgebra::Vector2::new(unit.sample(&mut rng), unit.sample(&mut rng))
                                * pixel_sigma;
                        (noisy.x > 0.0 && noisy.y > 0.0 && noisy.x < 1279.0 && noisy.y < 719.0)
                            .then_some((*p, noisy))
                    })
                    .collect();
                if corners.len() < 20 {
                    continue;
                }
                // A board pose to start from (PnP's role in the run): near the truth.
                observations.push(CamerasObservation {
                    camera: c,
                    pose: i,
                    camera_from_target: camera_from_target * jitter(&mut rng, 0.001, 0.001),
                    weight: 1.0,
                });
                frames.push(CamerasFrame {
                    camera: c,
                    pose: i,
                    corners,
                    weight: 1.0,
                });
            }
        }
        let data = cameras_data(&cell, reported, observations);
        let start = nominal_start(&cell);
        let pose_space = solve_cameras(&data, &start, &CamerasOptions::default()).unwrap();
        let joint = solve_cameras_pixels(&data, &models, &frames, &pose_space, &options).unwrap();
        let mut alone_mounts = Vec::new();
        for c in 0..cameras {
            let one = CamerasStart {
                camera_mounts: vec![start.camera_mounts[c]],
                ..start.clone()
            };
            let only = data.only(c);
            let own_frames: Vec<CamerasFrame> = frames
                .iter()
                .filter(|f| f.camera == c)
                .map(|f| CamerasFrame {
                    camera: 0,
                    ..f.clone()
                })
                .collect();
            let alone_pose = solve_cameras(&only, &one, &CamerasOptions::default()).unwrap();
            let alone =
                solve_cameras_pixels(&only, &models[c..=c], &own_frames, &alone_pose, &options)
                    .unwrap();
            let (_, joint_mm) = pose_error(&joint.camera_mounts[c], &truth[c].camera_mount);
            let (_, alone_mm) = pose_error(&alone.camera_mounts[0], &truth[c].camera_mount);
            joint_sq[c] += joint_mm * joint_mm;
            alone_sq[c] += alone_mm * alone_mm;
            alone_mounts.push(alone.camera_mounts[0]);
        }
        let relative_truth = truth[1].camera_mount.inverse() * truth[2].camera_mount;
        let (_, mm) = pose_error(&joint.relative[0].pose, &relative_truth);
        relative_joint_sq += mm * mm;
        let (_, mm) = pose_error(
            &(alone_mounts[1].inverse() * alone_mounts[2]),
            &relative_truth,
        );
        relative_chained_sq += mm * mm;
    }
    let rms = |sq: f64| (sq / seeds as f64).sqrt();
    for c in 0..cameras {
        let (joint, alone) = (rms(joint_sq[c]), rms(alone_sq[c]));
        println!(
            "pixel space, {}: mount translation RMS error joint {joint:.4} mm, alone {alone:.4} mm ({:.0} % lower)",
            cell.cameras[c].name,
            100.0 * (1.0 - joint / alone)
        );
        assert!(
            joint <= alone * 1.001,
            "{}: joint {joint} mm > alone {alone} mm",
            cell.cameras[c].name
        );
    }
    let (joint, chained) = (rms(relative_joint_sq), rms(relative_chained_sq));
    println!("pixel space, T_cam_left_cam_right translation RMS error: joint {joint:.4} mm, chained {chained:.4} mm ({:.0} % lower)", 100.0 * (1.0 - joint / chained));
    assert!(joint < chained, "joint {joint} mm vs chained {chained} mm");
}
