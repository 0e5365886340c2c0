//! The cameras of a cell: a `cameras:` list, or the one-camera form read as a list of one.
//!
//! ```yaml
//! target: targets/aprilgrid-6x6.yaml            # the board fixed in the cell (eye-in-hand cameras)
//! flange_target: targets/aprilgrid-6x6.yaml     # the board on the flange (eye-to-hand cameras); default: target
//! cameras:
//!   - name: wrist
//!     setup: eye_in_hand
//!     intrinsics: cameras/sim-1280x720.yaml
//!     camera: {backend: sim, seed: 11}
//!     nominal: {translation: [0.03, -0.07, 0.04], rotation_vector: [0, 0, 1.5708]}  # T_flange_cam_wrist
//!   - name: left
//!     setup: eye_to_hand
//!     ...                                           # nominal: T_base_cam_left
//! nominal: {T_base_target: ..., T_flange_target: ...}   # the boards, one per setup present
//! robot, plan, limits, workspace, detector, solver, session, verdict: shared by every camera
//! ```
//!
//! Each camera is validated by the same rules with the shared sections, its own keys, and the
//! board of its setup as the second unknown ([`camera_views`]), so every range and cross-field
//! check holds for each camera and an error names the camera (`cameras[1] (`left`): ...`).
//! The plan is planned for the first eye-in-hand camera (the first camera when none is): the
//! others capture at the same poses whenever they see their board.

use std::collections::BTreeMap;
use std::path::Path;

use super::schema::{CameraFile, ConfigFile, SimulationFile, MAX_CAMERAS};
use super::ConfigError;
use handeye_core::geometry::PoseYaml;
use handeye_core::setup::Setup;

fn name_is_valid(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 32
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
}

/// One camera of a cell as the validation rules see it: its name (`None` in the one-camera
/// form) and the one-camera config of it (its setup, board, lens, backend and mount, and the
/// shared sections).
pub(super) struct CameraView {
    /// Its name in the `cameras:` list.
    pub name: Option<String>,
    /// The cell as this camera sees it, in the one-camera form.
    pub config: ConfigFile,
}

/// Every camera of `raw`: the `cameras:` list checked (1 to [`MAX_CAMERAS`], names unique and
/// usable as frame names, the top-level `nominal` holding the boards only), or the one-camera
/// form as a list of one (its `setup` and `camera` required).
pub(super) fn camera_views(raw: &ConfigFile, file: &Path) -> Result<Vec<CameraView>, ConfigError> {
    let inconsistent = |key: &str, problem: String| ConfigError::Inconsistent {
        file: file.to_path_buf(),
        key: key.to_string(),
        problem,
    };
    let Some(cameras) = &raw.cameras else {
        for (key, given) in [
            ("setup", raw.setup.is_some()),
            ("camera", raw.camera.is_some()),
        ] {
            if !given {
                return Err(inconsistent(
                    key,
                    format!("missing: a cell of one camera gives its `{key}` at the top level (a cell of several gives each camera its own in a `cameras:` list)"),
                ));
            }
        }
        if raw.flange_target.is_some() {
            return Err(inconsistent(
                "flange_target",
                "only a `cameras:` list has a second board: a cell of one camera names its board in `target`".into(),
            ));
        }
        return Ok(vec![CameraView {
            name: None,
            config: raw.clone(),
        }]);
    };
    for (key, given) in [
        ("setup", raw.setup.is_some()),
        ("intrinsics", raw.intrinsics.is_some()),
        ("camera", raw.camera.is_some()),
    ] {
        if given {
            return Err(inconsistent(
                key,
                format!("with a `cameras:` list, each camera gives its own `{key}`: move it into the camera it belongs to"),
            ));
        }
    }
    if cameras.is_empty() {
        return Err(inconsistent(
            "cameras",
            "the list is empty: give at least one camera (or use the one-camera form)".into(),
        ));
    }
    if cameras.len() > MAX_CAMERAS {
        return Err(inconsistent(
            "cameras",
            format!(
                "{} cameras: at most {MAX_CAMERAS} in one cell (each holds its frames and a detector in memory at every pose, tens of MB at 1280x720; issue #40 measured 101 cameras at 5.5 GB after one pose): split the cell into runs of fewer cameras",
                cameras.len()
            ),
        ));
    }
    let mut seen = std::collections::BTreeSet::new();
    for (index, camera) in cameras.iter().enumerate() {
        let key = format!("cameras[{index}].name");
        if !name_is_valid(&camera.name) {
            return Err(inconsistent(
                &key,
                format!(
                    "`{}` is not a camera name: use 1 to 32 lower-case letters, digits or `_` (it becomes the frame `cam_<name>`)",
                    camera.name
                ),
            ));
        }
        if !seen.insert(camera.name.as_str()) {
            return Err(inconsistent(
                &key,
                format!("`{}` names two cameras: names must be unique", camera.name),
            ));
        }
    }
    if let Some(key) = raw
        .nominal
        .keys()
        .find(|k| *k != "T_base_target" && *k != "T_flange_target")
    {
        return Err(inconsistent(
            &format!("nominal.{key}"),
            "a several-camera cell's top-level `nominal` holds the boards only (`T_base_target`, `T_flange_target`); each camera's mount is its own `nominal`".into(),
        ));
    }
    cameras
        .iter()
        .enumerate()
        .map(|(index, camera)| {
            let config = one_camera(raw, camera).map_err(|(key, problem)| ConfigError::Camera {
                index,
                name: camera.name.clone(),
                source: Box::new(inconsistent(&key, problem)),
            })?;
            Ok(CameraView {
                name: Some(camera.name.clone()),
                config,
            })
        })
        .collect()
}

/// The one-camera config of `camera` in `cell`: its own keys, the board of its setup and the
/// shared sections. Errors: (YAML path, problem) of a board the setup needs but `nominal` or
/// `simulation` lacks.
fn one_camera(cell: &ConfigFile, camera: &CameraFile) -> Result<ConfigFile, (String, String)> {
    let (mount_key, board_key) = camera.setup.unknown_names();
    let board = |section: &str, poses: &BTreeMap<String, PoseYaml>| {
        poses.get(board_key).cloned().ok_or_else(|| {
            (
                format!("{section}.{board_key}"),
                format!(
                    "camera `{}` is {} and sees the board at {board_key}: give it in `{section}`",
                    camera.name, camera.setup
                ),
            )
        })
    };
    let nominal = BTreeMap::from([
        (mount_key.to_string(), camera.nominal.clone()),
        (board_key.to_string(), board("nominal", &cell.nominal)?),
    ]);
    let simulation = match (&camera.simulation, &cell.simulation) {
        (Some(mount), Some(boards)) => Some(SimulationFile {
            arm_errors: boards.arm_errors.clone(),
            transforms: BTreeMap::from([
                (mount_key.to_string(), mount.clone()),
                (board_key.to_string(), board("simulation", &boards.transforms)?),
            ]),
        }),
        (None, None) => None,
        (Some(_), None) => {
            return Err((
                "simulation".into(),
                format!(
                    "camera `{}` has a simulated mount but the cell gives no simulated boards: add `simulation: {{{board_key}: ...}}`",
                    camera.name
                ),
            ))
        }
        (None, Some(_)) => {
            return Err((
                format!("cameras.{}.simulation", camera.name),
                "the cell simulates its boards: give this camera's simulated mount too".into(),
            ))
        }
    };
    let target = match camera.setup {
        Setup::EyeInHand => cell.target.clone(),
        Setup::EyeToHand => cell
            .flange_target
            .clone()
            .unwrap_or_else(|| cell.target.clone()),
    };
    Ok(ConfigFile {
        setup: Some(camera.setup),
        target,
        flange_target: None,
        intrinsics: Some(camera.intrinsics.clone()),
        robot: cell.robot.clone(),
        camera: Some(camera.camera.clone()),
        cameras: None,
        nominal,
        simulation,
        plan: cell.plan.clone(),
        limits: cell.limits,
        workspace: cell.workspace,
        detector: cell.detector,
        solver: cell.solver.clone(),
        session: cell.session,
        verdict: cell.verdict,
    })
}
