//! Cell vocabulary, part of the ground floor: which layout a cell is ([`Setup`]), its two fixed
//! transforms ([`CellTransforms`]), one robot/camera observation ([`PosePair`]) and one detected
//! board corner ([`CornerObservation`]).
//!
//! Frames follow the project convention (`T_a_b` maps points in `b` into `a`; `a_from_b` in
//! code). Depends only on `geometry` and nalgebra; everything above may use it.

use serde::{Deserialize, Serialize};

use crate::geometry::Pose;

/// Which of the two cell layouts the data comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Setup {
    /// Camera on the flange, target fixed in the cell: unknowns `T_flange_camera`, `T_base_target`.
    EyeInHand,
    /// Camera fixed in the cell, target on the flange: unknowns `T_base_camera`, `T_flange_target`.
    EyeToHand,
}

impl Setup {
    /// The YAML name (`eye_in_hand` / `eye_to_hand`).
    pub fn name(self) -> &'static str {
        match self {
            Setup::EyeInHand => "eye_in_hand",
            Setup::EyeToHand => "eye_to_hand",
        }
    }

    /// The other setup.
    pub fn other(self) -> Setup {
        match self {
            Setup::EyeInHand => Setup::EyeToHand,
            Setup::EyeToHand => Setup::EyeInHand,
        }
    }

    /// YAML keys of the two unknowns: (camera mount, target mount).
    pub fn unknown_names(self) -> (&'static str, &'static str) {
        match self {
            Setup::EyeInHand => ("T_flange_camera", "T_base_target"),
            Setup::EyeToHand => ("T_base_camera", "T_flange_target"),
        }
    }

    /// `B` of `A = X·B·Y` for a robot pose: eye-in-hand `inv(T_base_flange)`, eye-to-hand
    /// `T_base_flange`.
    pub fn chain_b(self, base_from_flange: &Pose) -> Pose {
        match self {
            Setup::EyeInHand => base_from_flange.inverse(),
            Setup::EyeToHand => *base_from_flange,
        }
    }
}

impl std::fmt::Display for Setup {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One observation: where the robot said the flange was, and where the camera saw the target.
#[derive(Debug, Clone, PartialEq)]
pub struct PosePair {
    /// `T_base_flange` as the robot reports it.
    pub base_from_flange: Pose,
    /// `T_camera_target` as pose estimation (PnP) reports it.
    pub camera_from_target: Pose,
    /// Relative weight of this sample (> 0, 1 by default); multiplies its squared residuals.
    pub weight: f64,
    /// Optional name of the sample, carried into messages.
    pub id: Option<String>,
}

impl PosePair {
    /// A pair with weight 1 and no id.
    pub fn new(base_from_flange: Pose, camera_from_target: Pose) -> Self {
        PosePair {
            base_from_flange,
            camera_from_target,
            weight: 1.0,
            id: None,
        }
    }
}

/// The cell's two fixed transforms, named by setup: as known before calibrating (nominal, from a
/// drawing or a tape measure), as simulated (ground truth), or as solved and read back from a
/// result file. Plans turn views into flange poses with them (see `plan`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellTransforms {
    /// Which setup the cell is.
    pub setup: Setup,
    /// eye_in_hand: `T_flange_camera`; eye_to_hand: `T_base_camera`.
    pub camera_mount: Pose,
    /// eye_in_hand: `T_base_target`; eye_to_hand: `T_flange_target`.
    pub target_mount: Pose,
}

impl CellTransforms {
    /// The board pose the camera sees, `T_camera_target`, with the flange at `base_from_flange`.
    pub fn camera_from_target(&self, base_from_flange: &Pose) -> Pose {
        predict(
            self.setup,
            &self.camera_mount,
            &self.target_mount,
            base_from_flange,
        )
    }

    /// Both transforms with their YAML keys, camera mount first.
    pub fn unknowns(&self) -> [(&'static str, Pose); 2] {
        let (camera, target) = self.setup.unknown_names();
        [(camera, self.camera_mount), (target, self.target_mount)]
    }
}

/// `T_camera_target` predicted from the two unknowns and a robot pose, for either setup.
pub fn predict(
    setup: Setup,
    camera_mount: &Pose,
    target_mount: &Pose,
    base_from_flange: &Pose,
) -> Pose {
    camera_mount.inverse() * setup.chain_b(base_from_flange) * target_mount
}
