//! The joint solve on a synthetic three-camera cell: every mount back from a perturbed start,
//! the noise estimated per camera, a camera without enough views named, a board pose that is not
//! finite refused.

use super::*;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

fn pose(t: [f64; 3], r: [f64; 3]) -> Pose {
    Pose::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_scaled_axis(Vector3::new(r[0], r[1], r[2])),
    )
}

fn noisy(p: &Pose, rng: &mut rand::rngs::StdRng, sr: f64, st: f64) -> Pose {
    let n = Normal::new(0.0, 1.0).unwrap();
    let mut d = SVector::<f64, 6>::zeros();
    for k in 0..3 {
        d[k] = n.sample(rng) * sr;
        d[k + 3] = n.sample(rng) * st;
    }
    perturb(p, &d)
}

/// A wrist camera and two fixed cameras; returns the data, the truth (mounts, boards).
fn three_cameras(seed: u64) -> (CamerasData, Vec<Pose>, Pose, Pose) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mounts = vec![
        pose([0.03, -0.07, 0.04], [0.02, -0.01, 1.56]),
        pose([0.5, 0.1, 1.6], [3.1, 0.05, 0.0]),
        pose([0.5, -0.3, 1.6], [3.1, -0.05, 0.02]),
    ];
    let fixed = pose([0.5, -0.15, 0.0], [0.01, -0.02, 0.3]);
    let flange_board = pose([0.0, -0.1, -0.05], [3.1, 0.0, 0.0]);
    let setups = [Setup::EyeInHand, Setup::EyeToHand, Setup::EyeToHand];
    let noise = NoiseModel {
        rotation_sigma_rad: 0.05f64.to_radians(),
        translation_sigma_m: 0.3e-3,
    };
    let flanges: Vec<Pose> = (0..20)
        .map(|_| {
            pose(
                [
                    rng.random_range(0.3..0.7),
                    rng.random_range(-0.4..0.1),
                    rng.random_range(0.5..0.8),
                ],
                [
                    std::f64::consts::PI + rng.random_range(-0.5..0.5),
                    rng.random_range(-0.5..0.5),
                    rng.random_range(-0.5..0.5),
                ],
            )
        })
        .collect();
    let mut observations = Vec::new();
    for (i, f) in flanges.iter().enumerate() {
        for (c, setup) in setups.iter().enumerate() {
            let board = if *setup == Setup::EyeInHand {
                fixed
            } else {
                flange_board
            };
            let truth = predict(*setup, &mounts[c], &board, f);
            observations.push(CamerasObservation {
                camera: c,
                pose: i,
                camera_from_target: noisy(
                    &truth,
                    &mut rng,
                    noise.rotation_sigma_rad,
                    noise.translation_sigma_m,
                ),
                weight: 1.0,
            });
        }
    }
    let cameras = ["wrist", "left", "right"]
        .iter()
        .zip(setups)
        .map(|(name, setup)| CameraSpec {
            name: name.to_string(),
            setup,
            noise: NoiseModel::default(),
        })
        .collect();
    (
        CamerasData {
            cameras,
            base_from_flange: flanges,
            observations,
        },
        mounts,
        fixed,
        flange_board,
    )
}

fn start_near(mounts: &[Pose], fixed: Pose, flange: Pose) -> CamerasStart {
    let off = pose([0.004, -0.003, 0.002], [0.01, -0.008, 0.012]);
    CamerasStart {
        camera_mounts: mounts.iter().map(|m| m * off).collect(),
        base_from_target: Some(fixed * off),
        flange_from_target: Some(flange * off),
    }
}

#[test]
fn recovers_every_mount_of_a_three_camera_rig_from_a_perturbed_start() {
    let (data, mounts, fixed, flange) = three_cameras(3);
    let answer = solve_cameras(
        &data,
        &start_near(&mounts, fixed, flange),
        &CamerasOptions::default(),
    )
    .unwrap();
    for (c, truth) in mounts.iter().enumerate() {
        let (deg, mm) = pose_error(&answer.camera_mounts[c], truth);
        let s = answer.camera_sigmas[c];
        // Within 4 sigma of the truth (and the sigma itself sub-mm).
        assert!(
            mm < 4.0 * s.translation_mm && deg < 4.0 * s.rotation_deg,
            "camera {c}: {mm} mm, {deg}° vs {s:?}"
        );
        assert!(s.translation_mm < 1.0, "{s:?}");
    }
    // The estimated noise is the simulated one (0.05°, 0.3 mm) within 25 %.
    for n in &answer.noise {
        assert!(
            (n.rotation_sigma_rad.to_degrees() / 0.05 - 1.0).abs() < 0.25,
            "{n:?}"
        );
        assert!(
            (n.translation_sigma_m * 1e3 / 0.3 - 1.0).abs() < 0.25,
            "{n:?}"
        );
    }
    assert_eq!(
        answer.relative.len(),
        1,
        "only the two fixed cameras have a fixed relative pose"
    );
    let rel = &answer.relative[0];
    let (deg, mm) = pose_error(&rel.pose, &(mounts[1].inverse() * mounts[2]));
    assert!(mm < 4.0 * rel.sigma.translation_mm && deg < 4.0 * rel.sigma.rotation_deg);
}

#[test]
fn a_camera_with_too_few_views_is_named() {
    let (mut data, mounts, fixed, flange) = three_cameras(1);
    data.observations.retain(|o| o.camera != 2 || o.pose < 2);
    let err = solve_cameras(
        &data,
        &start_near(&mounts, fixed, flange),
        &CamerasOptions::default(),
    )
    .unwrap_err();
    assert!(
        err.to_string()
            .contains("camera `right` saw the board at 2 poses"),
        "{err}"
    );
}

#[test]
fn a_board_pose_that_is_not_finite_is_an_error_not_a_nan_answer() {
    let (mut data, mounts, fixed, flange) = three_cameras(2);
    data.observations[7].camera_from_target.translation.vector.x = f64::NAN;
    let err = solve_cameras(
        &data,
        &start_near(&mounts, fixed, flange),
        &CamerasOptions::default(),
    )
    .unwrap_err();
    assert_eq!(err, CamerasError::NotFinite, "{err}");
}

/// An observation's weight is its inverse variance: a board pose 20 mm off at a millionth of the
/// weight (a thousand times the sigma: 0.07 of its own) leaves its camera's mount within 0.02 mm
/// of the solve without it (measured 0.013 mm: it still counts in the noise estimate's degrees
/// of freedom), where at full weight it pulls it 1.2 mm; and the weighted noise estimate is the
/// typical view's (within 5 % of the solve without it).
#[test]
fn an_observations_weight_is_its_inverse_variance() {
    let (mut data, mounts, fixed, flange) = three_cameras(5);
    let start = start_near(&mounts, fixed, flange);
    let options = CamerasOptions::default();
    let bad = data
        .observations
        .iter()
        .position(|o| o.camera == 1)
        .unwrap();
    let mut without = data.clone();
    without.observations.remove(bad);
    let clean = solve_cameras(&without, &start, &options).unwrap();
    let measured = data.observations[bad].camera_from_target;
    data.observations[bad].camera_from_target = Pose::from_parts(
        Translation3::from(measured.translation.vector + Vector3::new(0.02, 0.0, 0.0)),
        measured.rotation,
    );
    data.observations[bad].weight = 1e-6;
    let tiny = solve_cameras(&data, &start, &options).unwrap();
    data.observations[bad].weight = 1.0;
    let full = solve_cameras(&data, &start, &options).unwrap();
    let (_, moved) = pose_error(&tiny.camera_mounts[1], &clean.camera_mounts[1]);
    let (_, pulled) = pose_error(&full.camera_mounts[1], &clean.camera_mounts[1]);
    assert!(
        moved < 0.02 && pulled > 50.0 * moved,
        "{moved} mm vs {pulled} mm"
    );
    let ratio = tiny.noise[1].translation_sigma_m / clean.noise[1].translation_sigma_m;
    assert!((ratio - 1.0).abs() < 0.05, "{ratio}");
}
