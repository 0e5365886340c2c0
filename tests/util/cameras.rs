//! Synthetic samples of the three-camera cell (`configs/sim-cell-three-cameras.yaml`), shared by
//! its Monte Carlo tests and its bench: the config, the wrist views, the board-pose noise a
//! rendered run estimates, and the joint problem from the config's nominal mounts.

use handeye_config::CellConfig;
use handeye_core::geometry::Pose;
use handeye_core::setup::Setup;
use handeye_solve::cameras::{CameraSpec, CamerasData, CamerasObservation, CamerasStart};
use handeye_solve::NoiseModel;
use nalgebra::{UnitQuaternion, Vector3};
use rand::rngs::StdRng;
use rand::Rng;
use rand_distr::{Distribution, Normal};

/// The three-camera config (wrist, left, right).
pub fn three_cameras() -> CellConfig {
    CellConfig::load(&super::repo().join("configs/sim-cell-three-cameras.yaml"))
        .expect("the three-camera config loads")
}

/// A random pose with Gaussian rotation (rad) and translation (m) per axis, rotation drawn first.
pub fn jitter(rng: &mut StdRng, rotation_sigma: f64, translation_sigma: f64) -> Pose {
    let unit = Normal::new(0.0, 1.0).expect("unit normal");
    let r = Vector3::from_fn(|_, _| unit.sample(rng) * rotation_sigma);
    let t = Vector3::from_fn(|_, _| unit.sample(rng) * translation_sigma);
    Pose::from_parts(t.into(), UnitQuaternion::from_scaled_axis(r))
}

/// `n` flange poses as the plan generates the wrist camera's views of the table board: the
/// flange 0.55–0.75 m above it, tilted up to about 30° (the fixed cameras see it from above).
pub fn wrist_views(rng: &mut StdRng, n: usize) -> Vec<Pose> {
    (0..n)
        .map(|_| {
            let t = Vector3::new(
                0.5 + rng.random_range(-0.15..0.15),
                -0.15 + rng.random_range(-0.15..0.15),
                rng.random_range(0.55..0.75),
            );
            let r = Vector3::new(
                std::f64::consts::PI + rng.random_range(-0.45..0.45),
                rng.random_range(-0.45..0.45),
                rng.random_range(-0.35..0.35),
            );
            Pose::from_parts(t.into(), UnitQuaternion::from_scaled_axis(r))
        })
        .collect()
}

/// The board-pose noise (rotation rad, translation m) the rendered run estimates: the wrist
/// camera at ~0.5 m, the fixed cameras at ~0.7 m.
pub fn board_pose_noise(setup: Setup) -> (f64, f64) {
    match setup {
        Setup::EyeInHand => (0.03f64.to_radians(), 0.15e-3),
        Setup::EyeToHand => (0.04f64.to_radians(), 0.35e-3),
    }
}

/// The joint problem's data: every camera of `cell` with the default noise model.
pub fn cameras_data(
    cell: &CellConfig,
    base_from_flange: Vec<Pose>,
    observations: Vec<CamerasObservation>,
) -> CamerasData {
    CamerasData {
        cameras: cell
            .cameras
            .iter()
            .map(|c| CameraSpec {
                name: c.name.clone(),
                setup: c.setup,
                noise: NoiseModel::default(),
            })
            .collect(),
        base_from_flange,
        observations,
    }
}

/// The start a run without a prior has: the config's nominal mounts (the wrist camera's board on
/// the table, the fixed cameras' board on the flange).
pub fn nominal_start(cell: &CellConfig) -> CamerasStart {
    CamerasStart {
        camera_mounts: cell
            .cameras
            .iter()
            .map(|c| c.nominal.camera_mount)
            .collect(),
        base_from_target: Some(cell.cameras[0].nominal.target_mount),
        flange_from_target: Some(cell.cameras[1].nominal.target_mount),
    }
}
