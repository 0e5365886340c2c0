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

    /// The (parent, child) frames of the two unknowns, in the order of [`Setup::unknown_names`]
    /// (`T_parent_child` maps points of the child frame into the parent's).
    pub fn unknown_frames(self) -> [(&'static str, &'static str); 2] {
        match self {
            Setup::EyeInHand => [("flange", "camera"), ("base", "target")],
            Setup::EyeToHand => [("base", "camera"), ("flange", "target")],
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
    /// Relative weight of this sample (> 0, 1 by default): its inverse variance relative to the
    /// noise model's, so it multiplies its squared residuals in the fit and its whitened residual
    /// (outlier tests) is scaled by its square root.
    pub weight: f64,
    /// Optional name of the sample, carried into messages.
    pub id: Option<String>,
    /// How precisely its view fixes `T_camera_target` (from the board pose estimate), when
    /// known: the solve weights each sample by it relative to the typical view
    /// (`handeye_solve::view_weighted`).
    pub view_sigma: Option<ViewSigma>,
}

/// How precisely one view fixed its board pose: the 1-sigma of its `T_camera_target` from the
/// pose estimate's covariance (the view's geometry, how many corners, how far, how oblique, at
/// the frame's own corner noise, which grows as the tags shrink in the image). A far board seen
/// by a few tags at the image's edge gives a pose several times noisier than a near, whole
/// board: a solve that takes every `T_camera_target` as equally good lets such views pull the
/// answer, or calls them outliers.
///
/// Checked when read: a figure that is not positive and finite is an error naming where it is
/// (a bad one would otherwise weigh its sample as a typical view without a word).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ViewSigmaFields")]
pub struct ViewSigma {
    /// Rotation, degrees (the root of the covariance's rotation trace).
    pub rotation_deg: f64,
    /// Translation of the target origin in the camera frame, mm.
    pub translation_mm: f64,
}

/// [`ViewSigma`] as written, before its check.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ViewSigmaFields {
    rotation_deg: f64,
    translation_mm: f64,
}

impl TryFrom<ViewSigmaFields> for ViewSigma {
    type Error = String;

    fn try_from(fields: ViewSigmaFields) -> Result<ViewSigma, String> {
        ViewSigma::new(fields.rotation_deg, fields.translation_mm)
    }
}

impl ViewSigma {
    /// A view's precision, checked: both figures finite and positive, else what was expected
    /// and what was given (the one check of a file's `view_sigma` and of Python's
    /// `view_sigmas`).
    pub fn new(rotation_deg: f64, translation_mm: f64) -> Result<ViewSigma, String> {
        let sigma = ViewSigma {
            rotation_deg,
            translation_mm,
        };
        if sigma.is_valid() {
            Ok(sigma)
        } else {
            Err(format!(
                "expected two positive figures (rotation_deg, translation_mm), got {rotation_deg} and {translation_mm}"
            ))
        }
    }

    /// Both figures finite and positive.
    pub fn is_valid(&self) -> bool {
        [self.rotation_deg, self.translation_mm]
            .iter()
            .all(|v| v.is_finite() && *v > 0.0)
    }
}

impl PosePair {
    /// A pair with weight 1 and no id.
    pub fn new(base_from_flange: Pose, camera_from_target: Pose) -> Self {
        PosePair {
            base_from_flange,
            camera_from_target,
            weight: 1.0,
            id: None,
            view_sigma: None,
        }
    }
}

/// The frames the robot's flange poses were read in: each `T_base_flange` is the pose of
/// `flange` in `base` as the arm's driver names them, so every `base`-side answer is in `base`.
/// The UR controller reports in its own `base` and `tool0` (the default, and what a result that
/// does not say means); an arm under ROS 2 in the TF frames its config names.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotFrames {
    /// The frame the poses are in (`T_base_flange`'s `base`).
    pub base: String,
    /// The flange frame.
    pub flange: String,
}

impl Default for RobotFrames {
    /// The UR controller's `base` and `tool0`.
    fn default() -> Self {
        RobotFrames {
            base: "base".into(),
            flange: "tool0".into(),
        }
    }
}

/// True when a base frame id names the UR ROS driver's `base_link` (also under a prefix, e.g.
/// `ur/base_link`): that frame is the controller's `base` turned 180° about z.
pub fn is_ur_base_link(base_id: &str) -> bool {
    base_id.rsplit('/').next() == Some("base_link")
}

/// `T_base_link_base` of the UR ROS driver: `base_link` is `base` turned 180° about z (the
/// controller reports `T_base_flange` in `base`, so a transform exported under `base_link` must
/// be turned too, or it lands on the wrong side of the robot).
pub fn ur_base_link_from_base() -> Pose {
    Pose::from_parts(
        nalgebra::Translation3::identity(),
        nalgebra::UnitQuaternion::from_axis_angle(
            &nalgebra::Vector3::z_axis(),
            std::f64::consts::PI,
        ),
    )
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
    /// The flange pose that puts the camera at `target_from_camera` relative to the board.
    pub fn base_from_flange_for_view(&self, target_from_camera: &Pose) -> Pose {
        match self.setup {
            // T_base_flange = T_base_target · T_target_camera · T_camera_flange
            Setup::EyeInHand => {
                self.target_mount * target_from_camera * self.camera_mount.inverse()
            }
            // T_base_flange = T_base_camera · T_camera_target · T_target_flange
            Setup::EyeToHand => {
                self.camera_mount * target_from_camera.inverse() * self.target_mount.inverse()
            }
        }
    }

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

/// One detected board corner: which corner of the board it is and where it was seen.
///
/// Board-agnostic identity: for an aprilgrid `tag_id` is the tag and `corner` its corner
/// (0 bottom-left, 1 bottom-right, 2 top-right, 3 top-left, counter-clockwise seen from +z).
/// For a ChArUco board `tag_id` is OpenCV's ChArUco corner id, for a chessboard the inner
/// corner's index (row-major from the top-left inner corner as printed), and `corner` is 0
/// (see `vision::target`).
/// Pixels follow OpenCV's convention (pixel centres at integers). In files it is the compact
/// list `[tag id, corner, u, v]` — read and written here only, so every reader validates it the
/// same way.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerObservation {
    /// The tag (aprilgrid) the corner belongs to; the corner id (ChArUco, chessboard).
    pub tag_id: u32,
    /// Which corner of the tag, 0..=3 (aprilgrid); 0 (ChArUco, chessboard).
    pub corner: u8,
    /// Where it was seen, px.
    pub pixel: nalgebra::Point2<f64>,
}

impl Serialize for CornerObservation {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        [
            f64::from(self.tag_id),
            f64::from(self.corner),
            self.pixel.x,
            self.pixel.y,
        ]
        .serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for CornerObservation {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let [id, corner, u, v] = <[f64; 4]>::deserialize(deserializer)?;
        let whole = |x: f64, max: f64| x >= 0.0 && x.fract() == 0.0 && x <= max;
        if !whole(id, f64::from(u32::MAX))
            || !whole(corner, 3.0)
            || !u.is_finite()
            || !v.is_finite()
        {
            return Err(D::Error::custom(format_args!(
                "expected [tag id, corner 0..3, u px, v px] with a whole tag id, a whole corner \
                 index and finite pixels, found [{id}, {corner}, {u}, {v}]"
            )));
        }
        Ok(CornerObservation {
            tag_id: id as u32,
            corner: corner as u8,
            pixel: nalgebra::Point2::new(u, v),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_unknowns_frames_are_their_names() {
        for setup in [Setup::EyeInHand, Setup::EyeToHand] {
            let (camera, target) = setup.unknown_names();
            let names: Vec<String> = setup
                .unknown_frames()
                .iter()
                .map(|(parent, child)| format!("T_{parent}_{child}"))
                .collect();
            assert_eq!(names, [camera, target]);
        }
    }

    #[test]
    fn a_corner_reads_back_as_written_in_the_compact_form() {
        let corner = CornerObservation {
            tag_id: 17,
            corner: 3,
            pixel: nalgebra::Point2::new(640.25, 359.5),
        };
        let text = serde_yaml_ng::to_string(&corner).unwrap();
        assert_eq!(
            serde_yaml_ng::from_str::<Vec<f64>>(&text).unwrap(),
            vec![17.0, 3.0, 640.25, 359.5]
        );
        assert_eq!(
            serde_yaml_ng::from_str::<CornerObservation>(&text).unwrap(),
            corner
        );
    }

    #[test]
    fn a_malformed_corner_is_refused_with_what_was_expected() {
        for bad in [
            "[1.5, 0, 1, 2]",
            "[-1, 0, 1, 2]",
            "[1, 4, 1, 2]",
            "[1, 0, .nan, 2]",
            "[1, 0, 1]",
        ] {
            let err = serde_yaml_ng::from_str::<CornerObservation>(bad).unwrap_err();
            assert!(
                err.to_string().contains("expected") || err.to_string().contains("length"),
                "{bad}: {err}"
            );
        }
    }
}
