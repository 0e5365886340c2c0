//! Exporters: the two solved unknowns of a result file written in the forms other tools read.
//!
//! | format   | what is written                                                                  |
//! |----------|----------------------------------------------------------------------------------|
//! | `ros2`   | one `ros2 run tf2_ros static_transform_publisher` command per unknown, and a Python launch snippet with the same two publishers |
//! | `urdf`   | one fixed `<joint>` per unknown (`<origin xyz rpy>`; URDF rpy = fixed-axis roll about x, then pitch about y, then yaw about z) |
//! | `ur`     | UR pose literals `p[x, y, z, rx, ry, rz]` (m, rotation vector rad): `set_tcp(..)` for a flange mount, a plain pose for a base mount |
//! | `json`   | an object keyed by `T_a_b`, each with parent, child, translation, quaternion (x, y, z, w), rotation vector and the 4x4 matrix |
//! | `opencv` | OpenCV FileStorage YAML (`%YAML:1.0`) with one `!!opencv-matrix` 4x4 (`dt: d`) per unknown |
//!
//! Every form carries `T_parent_child`: the transform that maps points in the child frame into
//! the parent frame (a ROS/TF transform from `frame_id` = parent to `child_frame_id` = child, a URDF
//! joint from parent link to child link). Numbers are printed with Rust's shortest round-trip
//! formatting, so nothing is lost to printing. The camera frame is the optical frame (x right,
//! y down, z forward): name its ROS id accordingly (`*_optical_frame`).
//!
//! Refusals: frame ids must follow ROS's naming rules ([`validate_frame_id`]: they are pasted
//! into shell command lines, Python, XML and URScript), and every ROS 2 command line is
//! shell-quoted anyway (`shlex`). A transform that is not finite or lies farther than
//! `geometry::MAX_TRANSLATION_M` from its parent is refused rather than exported.
//! Depends on `geometry`, `setup::Setup` and `setup::CellTransforms` only; writes no files.

use std::fmt::Write as _;

use serde_json::json;

use handeye_core::geometry::{
    check_translation, rotvec, to_matrix4_rows, Pose, TranslationProblem,
};
use handeye_core::setup::{is_ur_base_link, ur_base_link_from_base, CellTransforms};
use handeye_core::setup::{RobotFrames, Setup};
use handeye_records::result::{CellResult, NamedTransform};

/// Why a result cannot be exported.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// A frame id that is not a valid ROS frame id.
    #[error("{role} frame id {id:?}: {problem}")]
    FrameId {
        /// Which frame (`base`, `flange`, `camera`, `target`; or `parent` / `child` of a transform a
        /// several-camera result names).
        role: &'static str,
        /// The id as given.
        id: String,
        /// Which rule it breaks.
        problem: FrameIdProblem,
    },
    /// A transform with an implausible translation (in the message, so not a `#[source]`).
    #[error("{key}: translation {problem}: refusing to export it")]
    Translation {
        /// `T_a_b` of the transform.
        key: String,
        /// What is wrong.
        problem: TranslationProblem,
    },
    /// A transform whose rotation is not a finite unit quaternion.
    #[error("{key}: rotation quaternion (x, y, z, w) {quaternion:?} is not a finite unit quaternion: refusing to export it")]
    Rotation {
        /// `T_a_b` of the transform.
        key: String,
        /// The quaternion as found.
        quaternion: [f64; 4],
    },
    /// A form that cannot hold this result (a several-camera result as UR literals).
    #[error("{0}")]
    Unsupported(String),
}

/// The ROS naming rules a frame id breaks ([`validate_frame_id`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FrameIdProblem {
    /// Empty.
    #[error("a frame id must not be empty")]
    Empty,
    /// Longer than [`MAX_FRAME_ID_LEN`].
    #[error("longer than {MAX_FRAME_ID_LEN} characters")]
    TooLong,
    /// A character other than ASCII letters, digits, `_` and `/`.
    #[error(
        "character {0:?} is not allowed (ROS frame ids use ASCII letters, digits, `_` and `/`)"
    )]
    Character(char),
    /// Starts with `/` (tf2 refuses a leading slash).
    #[error("must not start with `/` (tf2 frame ids are relative)")]
    LeadingSlash,
    /// Ends with `/`, or holds `//`.
    #[error("must not end with `/` or contain `//`")]
    EmptySegment,
    /// A `/`-separated part starts with a digit.
    #[error("each `/`-separated part must start with a letter or `_`, not a digit")]
    LeadingDigit,
}

/// Longest accepted frame id.
pub const MAX_FRAME_ID_LEN: usize = 256;

/// Checks a frame id against ROS's naming rules (ROS 2 names and tf2 frame ids): ASCII letters,
/// digits, `_` and `/`; no leading `/`, no empty `/`-separated part, no part starting with a
/// digit. Ids that pass are also safe, unquoted, in a shell word, a Python or XML string and
/// (with `/` replaced) a URScript name.
pub fn validate_frame_id(id: &str) -> Result<(), FrameIdProblem> {
    if id.is_empty() {
        return Err(FrameIdProblem::Empty);
    }
    if id.len() > MAX_FRAME_ID_LEN {
        return Err(FrameIdProblem::TooLong);
    }
    if let Some(c) = id
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '/'))
    {
        return Err(FrameIdProblem::Character(c));
    }
    if id.starts_with('/') {
        return Err(FrameIdProblem::LeadingSlash);
    }
    for part in id.split('/') {
        match part.chars().next() {
            None => return Err(FrameIdProblem::EmptySegment),
            Some(c) if c.is_ascii_digit() => return Err(FrameIdProblem::LeadingDigit),
            Some(_) => {}
        }
    }
    Ok(())
}

/// An export form.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportFormat {
    /// ROS 2 `static_transform_publisher` commands and a launch snippet.
    Ros2,
    /// A ROS 2 Python launch file that runs as written (`formats::ros2_launch`).
    Ros2Launch,
    /// URDF fixed-joint snippets.
    Urdf,
    /// UR pose literals `p[x, y, z, rx, ry, rz]`.
    Ur,
    /// JSON object.
    Json,
    /// OpenCV FileStorage YAML with 4x4 matrices.
    Opencv,
}

impl ExportFormat {
    /// Every format, in documentation order.
    pub const ALL: [ExportFormat; 6] = [
        ExportFormat::Ros2,
        ExportFormat::Ros2Launch,
        ExportFormat::Urdf,
        ExportFormat::Ur,
        ExportFormat::Json,
        ExportFormat::Opencv,
    ];

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ExportFormat::Ros2 => "ros2",
            ExportFormat::Ros2Launch => "ros2-launch",
            ExportFormat::Urdf => "urdf",
            ExportFormat::Ur => "ur",
            ExportFormat::Json => "json",
            ExportFormat::Opencv => "opencv",
        }
    }
}

/// The frame ids written for our four frames (ROS TF ids, URDF link names, JSON parent/child).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameIds {
    /// The robot base (the frame the robot reports `T_base_flange` in).
    pub base: String,
    /// The tool flange.
    pub flange: String,
    /// The camera's optical frame.
    pub camera: String,
    /// The board frame.
    pub target: String,
    /// The frame the result's robot poses were read in (its `robot_frames.base`; `base`, the
    /// UR controller's, when it does not say): a base-side transform is turned only when `base`
    /// names the other of the UR pair `base` / `base_link` ([`base_turn`]).
    pub poses_in: String,
}

impl FrameIds {
    /// The default ids for a result whose robot poses were read in `robot`'s frames: its base
    /// and flange, the default camera and board ids.
    pub fn of_robot(robot: &RobotFrames) -> FrameIds {
        FrameIds {
            base: robot.base.clone(),
            flange: robot.flange.clone(),
            poses_in: robot.base.clone(),
            ..FrameIds::default()
        }
    }

    /// Checks every id with [`validate_frame_id`].
    pub fn validate(&self) -> Result<(), ExportError> {
        for (role, id) in [
            ("base", &self.base),
            ("flange", &self.flange),
            ("camera", &self.camera),
            ("target", &self.target),
        ] {
            validate_frame_id(id).map_err(|problem| ExportError::FrameId {
                role,
                id: id.clone(),
                problem,
            })?;
        }
        Ok(())
    }
}

impl Default for FrameIds {
    /// ROS-Industrial / ur_robot_driver names: `base`, `tool0`, `camera_optical_frame`,
    /// `calibration_target`. (`base` is the frame the UR controller reports poses in; ROS
    /// `base_link` differs from it by 180° about z.)
    fn default() -> Self {
        FrameIds {
            base: "base".into(),
            flange: "tool0".into(),
            camera: "camera_optical_frame".into(),
            target: "calibration_target".into(),
            poses_in: "base".into(),
        }
    }
}

/// The turn from the frame the robot poses were read in (`poses_in`) to the exported base frame
/// `base`: the UR ROS driver's `base_link` is the controller's `base` turned 180° about z, so
/// a result in `base` exported under `base_link`, or one read in `base_link` exported under
/// `base`, is turned; `None` when both name the same side (a result read in `base_link` and
/// exported under it is not turned a second time).
pub fn base_turn(poses_in: &str, base: &str) -> Option<Pose> {
    let is_ur_base = |id: &str| id.rsplit('/').next() == Some("base");
    let turned = if is_ur_base_link(poses_in) {
        is_ur_base(base)
    } else {
        is_ur_base_link(base)
    };
    turned.then(ur_base_link_from_base)
}

/// One exported transform: `T_parent_child` under the frame ids it is published with (a
/// result's `NamedTransform` is the same transform in the result's own frame names, with its
/// 1-sigma).
#[derive(Debug, Clone, PartialEq)]
pub struct FramedTransform {
    /// Our name, `T_a_b` in the result's frame names (`T_flange_camera`, `T_base_cam_left`, ...).
    pub key: String,
    /// The parent frame id (frame `a`).
    pub parent: String,
    /// The child frame id (frame `b`).
    pub child: String,
    /// `T_parent_child`.
    pub parent_from_child: Pose,
}

impl FramedTransform {
    /// `T_parent_child` between frames as result files name them (`base`, `flange`, `camera`,
    /// `cam_<name>`, `target`), under the ids `ids` gives them: `camera` is the camera id,
    /// `cam_<name>` the camera id with `_<name>` (every camera's optical frame distinct), the
    /// board on the flange the target id with `_flange` when the cell has boards on both sides.
    /// A transform whose parent is the robot base is expressed in the frame the base id names:
    /// turned 180° about z between the UR pair `base` / `base_link` ([`base_turn`]).
    pub fn with_ids(
        parent: &str,
        child: &str,
        parent_from_child: Pose,
        ids: &FrameIds,
        two_boards: bool,
    ) -> FramedTransform {
        let flange_board = two_boards && parent == "flange" && child == "target";
        let id = |frame: &str| match frame {
            "base" => ids.base.clone(),
            "flange" => ids.flange.clone(),
            "camera" => ids.camera.clone(),
            "target" if flange_board => format!("{}_flange", ids.target),
            "target" => ids.target.clone(),
            camera => format!(
                "{}_{}",
                ids.camera,
                camera.strip_prefix("cam_").unwrap_or(camera)
            ),
        };
        let parent_from_child = match base_turn(&ids.poses_in, &ids.base) {
            Some(turn) if parent == "base" => turn * parent_from_child,
            _ => parent_from_child,
        };
        FramedTransform {
            key: format!("T_{parent}_{child}"),
            parent: id(parent),
            child: id(child),
            parent_from_child,
        }
    }
}

/// The two unknowns of a solved one-camera cell with their frame ids: camera mount first, target
/// mount second (see [`FramedTransform::with_ids`]).
pub fn named_transforms(mounts: &CellTransforms, ids: &FrameIds) -> [FramedTransform; 2] {
    let (camera_parent, target_parent) = match mounts.setup {
        Setup::EyeInHand => ("flange", "base"),
        Setup::EyeToHand => ("base", "flange"),
    };
    [
        FramedTransform::with_ids(camera_parent, "camera", mounts.camera_mount, ids, false),
        FramedTransform::with_ids(target_parent, "target", mounts.target_mount, ids, false),
    ]
}

/// What a cell's export is of: the header of every form names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportedCell {
    /// One camera in this setup: the tree is its two unknowns, camera mount first.
    One(Setup),
    /// A cell with this many cameras: the tree is every camera's mount and the boards.
    Cameras(usize),
}

impl std::fmt::Display for ExportedCell {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ExportedCell::One(setup) => write!(f, "({setup})"),
            ExportedCell::Cameras(n) => write!(f, "of a cell with {n} cameras"),
        }
    }
}

/// Every transform of a solved cell as the export forms write it.
#[derive(Debug, Clone, PartialEq)]
pub struct Exported {
    /// What the cell is.
    pub cell: ExportedCell,
    /// The transforms a TF tree holds (one parent per frame): every camera's mount and every
    /// board's.
    pub tree: Vec<FramedTransform>,
    /// Transforms the tree implies (camera to camera): written where a form holds them without
    /// giving a frame a second parent (as comments in the ROS 2 and URDF forms).
    pub implied: Vec<FramedTransform>,
}

impl Exported {
    /// The export of a session's result, one camera or several: every camera's mount (from the
    /// joint solve; a cell of one camera, its answer's) and the boards in the tree, the
    /// camera-to-camera transforms implied by them. A camera left out of the joint solve has no
    /// mount to export.
    pub fn of(result: &CellResult, ids: &FrameIds) -> Exported {
        let two_boards = result.boards.len() > 1;
        let named = |t: &NamedTransform| {
            FramedTransform::with_ids(&t.parent, &t.child, t.pose, ids, two_boards)
        };
        Exported {
            cell: match result.cameras.as_slice() {
                [only] => ExportedCell::One(only.setup),
                cameras => ExportedCell::Cameras(cameras.len()),
            },
            tree: result
                .cameras
                .iter()
                .filter_map(|c| c.joint.as_ref())
                .chain(&result.boards)
                .map(named)
                .collect(),
            implied: result.camera_to_camera.iter().map(named).collect(),
        }
    }

    /// The export of a one-camera cell's two unknowns given as poses (the same as
    /// [`Exported::of`] its result).
    pub fn one(mounts: &CellTransforms, ids: &FrameIds) -> Exported {
        Exported {
            cell: ExportedCell::One(mounts.setup),
            tree: named_transforms(mounts, ids).to_vec(),
            implied: Vec::new(),
        }
    }

    /// Checks the frame ids ([`FrameIds::validate`]) and that every transform is finite and
    /// within `geometry::MAX_TRANSLATION_M`.
    pub fn check(&self, ids: &FrameIds) -> Result<(), ExportError> {
        ids.validate()?;
        for t in self.tree.iter().chain(&self.implied) {
            // A several-camera result names its own frames (`cam_<name>`), and a result file is
            // text anyone can edit: every id is pasted into shell, Python, XML and URScript.
            for (role, id) in [("parent", &t.parent), ("child", &t.child)] {
                validate_frame_id(id).map_err(|problem| ExportError::FrameId {
                    role,
                    id: id.clone(),
                    problem,
                })?;
            }
            check_translation(&t.parent_from_child.translation.vector).map_err(|problem| {
                ExportError::Translation {
                    key: t.key.clone(),
                    problem,
                }
            })?;
            let q = t.parent_from_child.rotation.into_inner();
            if !(q.coords.iter().all(|v| v.is_finite()) && (q.norm() - 1.0).abs() < 1e-6) {
                return Err(ExportError::Rotation {
                    key: t.key.clone(),
                    quaternion: [q.i, q.j, q.k, q.w],
                });
            }
        }
        Ok(())
    }

    /// The text of the export in `format` (check it first with [`Exported::check`]).
    pub fn text(&self, format: ExportFormat) -> Result<String, ExportError> {
        Ok(match (format, self.cell) {
            (ExportFormat::Ros2, _) => ros2(self),
            (ExportFormat::Ros2Launch, _) => super::ros2_launch::launch_file(self.cell, &self.tree),
            (ExportFormat::Urdf, _) => urdf(self),
            (ExportFormat::Ur, ExportedCell::One(setup)) => ur(setup, &self.tree),
            (ExportFormat::Ur, ExportedCell::Cameras(_)) => {
                return Err(ExportError::Unsupported(
                    "`ur` holds the two transforms of a one-camera cell (one TCP); a cell with several cameras exports as ros2, urdf or opencv (or ros2-launch, json)".into(),
                ))
            }
            (ExportFormat::Json, _) => json_text(self),
            (ExportFormat::Opencv, _) => opencv(self),
        })
    }
}

/// The text of a one-camera cell's `mounts` in `format`, after [`Exported::check`].
pub fn export(
    mounts: &CellTransforms,
    format: ExportFormat,
    ids: &FrameIds,
) -> Result<String, ExportError> {
    let exported = Exported::one(mounts, ids);
    exported.check(ids)?;
    exported.text(format)
}

/// One POSIX shell command line, each word quoted where the shell would otherwise interpret
/// it (validated frame ids and numbers never need it; the quoting is a second guard).
fn shell_line(words: &[String]) -> String {
    // Only a NUL byte cannot be quoted, and validated ids and numbers hold none; an empty
    // line is visibly broken rather than silently shorter.
    shlex::try_join(words.iter().map(String::as_str)).unwrap_or_default()
}

/// The shell command that publishes `parent_from_child` on `/tf_static` (`tf2_ros`'
/// `static_transform_publisher`), its words quoted for a POSIX shell.
fn static_publisher_command(parent: &str, child: &str, parent_from_child: &Pose) -> String {
    let (p, q) = (
        parent_from_child.translation.vector,
        parent_from_child.rotation,
    );
    let mut words: Vec<String> = ["ros2", "run", "tf2_ros", "static_transform_publisher"]
        .iter()
        .map(|w| w.to_string())
        .collect();
    for (flag, value) in [
        ("--x", p.x),
        ("--y", p.y),
        ("--z", p.z),
        ("--qx", q.i),
        ("--qy", q.j),
        ("--qz", q.k),
        ("--qw", q.w),
    ] {
        words.push(flag.to_string());
        words.push(value.to_string());
    }
    for (flag, id) in [("--frame-id", parent), ("--child-frame-id", child)] {
        words.push(flag.to_string());
        words.push(id.to_string());
    }
    shell_line(&words)
}

/// A URDF fixed joint holding `parent_from_child` (rpy fixed-axis), under a comment naming it.
fn urdf_joint(name: &str, parent: &str, child: &str, parent_from_child: &Pose) -> String {
    let p = parent_from_child.translation.vector;
    let (roll, pitch, yaw) = parent_from_child.rotation.euler_angles();
    format!(
        "<!-- {name} -->\n<joint name=\"{parent}_to_{child}_joint\" type=\"fixed\">\n  <parent link=\"{parent}\"/>\n  <child link=\"{child}\"/>\n  <origin xyz=\"{} {} {}\" rpy=\"{roll} {pitch} {yaw}\"/>\n</joint>",
        p.x, p.y, p.z
    )
}

/// An OpenCV FileStorage 4x4 matrix `name` (row-major, metres) with its frame ids.
fn opencv_matrix(name: &str, parent: &str, child: &str, parent_from_child: &Pose) -> String {
    let data: Vec<String> = to_matrix4_rows(parent_from_child)
        .iter()
        .flatten()
        .map(|v| format!("{v:e}"))
        .collect();
    format!(
        "{name}: !!opencv-matrix\n   rows: 4\n   cols: 4\n   dt: d\n   data: [ {} ]\n{name}_parent: \"{parent}\"\n{name}_child: \"{child}\"",
        data.join(", ")
    )
}

/// The line naming an implied transform in a tree form, where publishing it would give its
/// child a second parent.
fn implied_comment(t: &FramedTransform) -> String {
    let (p, q) = (
        t.parent_from_child.translation.vector,
        t.parent_from_child.rotation,
    );
    format!(
        "{} (implied by the transforms above; not published: {} already has a parent): xyz [{}, {}, {}], quaternion xyzw [{}, {}, {}, {}]",
        t.key, t.child, p.x, p.y, p.z, q.i, q.j, q.k, q.w
    )
}

fn ros2(exported: &Exported) -> String {
    let mut out = format!(
        "# handeye calibration {}: static transforms for ROS 2 (tf2_ros).\n\
         # Each publishes T_parent_child: frame-id = parent, child-frame-id = child.\n",
        exported.cell
    );
    for t in &exported.tree {
        let _ = writeln!(
            out,
            "# {}\n{}",
            t.key,
            static_publisher_command(&t.parent, &t.child, &t.parent_from_child)
        );
    }
    for t in &exported.implied {
        let _ = writeln!(out, "# {}", implied_comment(t));
    }
    out.push_str(
        "\n# Launch snippet (Python launch file):\n\
         from launch import LaunchDescription\n\
         from launch_ros.actions import Node\n\n\n\
         def generate_launch_description():\n    return LaunchDescription([\n",
    );
    for t in &exported.tree {
        let (p, q) = (
            t.parent_from_child.translation.vector,
            t.parent_from_child.rotation,
        );
        let name = t.key.to_lowercase();
        let _ = writeln!(
            out,
            "        Node(\n            package='tf2_ros',\n            executable='static_transform_publisher',\n            name='handeye_{name}',\n            arguments=['--x', '{}', '--y', '{}', '--z', '{}',\n                       '--qx', '{}', '--qy', '{}', '--qz', '{}', '--qw', '{}',\n                       '--frame-id', '{}', '--child-frame-id', '{}'],\n        ),",
            p.x, p.y, p.z, q.i, q.j, q.k, q.w, t.parent, t.child
        );
    }
    out.push_str("    ])\n");
    out
}

fn urdf(exported: &Exported) -> String {
    let mut out = format!(
        "<!-- handeye calibration {}. Each fixed joint holds T_parent_child; rpy is fixed-axis\n     roll (x), pitch (y), yaw (z): R = Rz(yaw) Ry(pitch) Rx(roll). Add the child links if\n     your URDF lacks them. -->\n",
        exported.cell
    );
    for t in &exported.tree {
        let _ = writeln!(
            out,
            "{}",
            urdf_joint(&t.key, &t.parent, &t.child, &t.parent_from_child)
        );
    }
    for t in &exported.implied {
        let _ = writeln!(out, "<!-- {} -->", implied_comment(t));
    }
    out
}

/// The UR pose literal `p[x, y, z, rx, ry, rz]` of a pose (m, rotation vector in rad).
pub fn ur_pose_literal(pose: &Pose) -> String {
    let p = pose.translation.vector;
    let r = rotvec(&pose.rotation);
    format!("p[{}, {}, {}, {}, {}, {}]", p.x, p.y, p.z, r.x, r.y, r.z)
}

fn ur(setup: Setup, transforms: &[FramedTransform]) -> String {
    let mut out = format!(
        "# handeye calibration ({setup}) as UR pose literals p[x, y, z, rx, ry, rz] (m, rotation vector rad).\n"
    );
    for (i, t) in transforms.iter().enumerate() {
        let literal = ur_pose_literal(&t.parent_from_child);
        let is_flange_mount = match setup {
            Setup::EyeInHand => i == 0,
            Setup::EyeToHand => i == 1,
        };
        if is_flange_mount {
            let _ = writeln!(
                out,
                "# {}: a TCP offset from the flange (Installation > TCP, or in a program):\nset_tcp({literal})",
                t.key
            );
        } else {
            let _ = writeln!(
                out,
                "# {}: a pose in the robot base frame (e.g. a plane or point feature):\n{}_{} = {literal}",
                t.key,
                // URScript names take no `/`.
                t.parent.replace('/', "_"),
                t.child.replace('/', "_")
            );
        }
    }
    out
}

fn json_value(exported: &Exported) -> serde_json::Value {
    let mut object = serde_json::Map::new();
    match exported.cell {
        ExportedCell::One(setup) => object.insert("setup".into(), json!(setup.name())),
        ExportedCell::Cameras(n) => object.insert("cameras".into(), json!(n)),
    };
    for t in exported.tree.iter().chain(&exported.implied) {
        let p = t.parent_from_child.translation.vector;
        let q = t.parent_from_child.rotation;
        let r = rotvec(&q);
        object.insert(
            t.key.clone(),
            json!({
                "parent": t.parent,
                "child": t.child,
                "translation": [p.x, p.y, p.z],
                "quaternion": {"x": q.i, "y": q.j, "z": q.k, "w": q.w},
                "rotation_vector": [r.x, r.y, r.z],
                "matrix": to_matrix4_rows(&t.parent_from_child),
            }),
        );
    }
    serde_json::Value::Object(object)
}

fn json_text(exported: &Exported) -> String {
    let mut text = serde_json::to_string_pretty(&json_value(exported))
        .expect("a JSON value always serialises");
    text.push('\n');
    text
}

fn opencv(exported: &Exported) -> String {
    let mut out = String::from(
        "%YAML:1.0\n---\n# handeye calibration: 4x4 T_parent_child, row-major, metres.\n",
    );
    match exported.cell {
        ExportedCell::One(setup) => {
            let _ = writeln!(out, "setup: \"{setup}\"");
        }
        ExportedCell::Cameras(n) => {
            let _ = writeln!(out, "cameras: {n}");
        }
    }
    for t in exported.tree.iter().chain(&exported.implied) {
        let _ = writeln!(
            out,
            "{}",
            opencv_matrix(&t.key, &t.parent, &t.child, &t.parent_from_child)
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn mounts(setup: Setup) -> CellTransforms {
        CellTransforms {
            setup,
            camera_mount: Pose::from_parts(
                Translation3::new(0.05, -0.02, 0.11),
                UnitQuaternion::from_euler_angles(0.1, -0.2, 1.3),
            ),
            target_mount: Pose::from_parts(
                Translation3::new(0.8, 0.1, -0.03),
                UnitQuaternion::from_euler_angles(3.0, 0.4, -2.2),
            ),
        }
    }

    #[test]
    fn ur_literal_is_translation_and_rotation_vector() {
        let pose = Pose::from_parts(
            Translation3::new(0.1, 0.2, 0.3),
            UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.5)),
        );
        assert_eq!(ur_pose_literal(&pose), "p[0.1, 0.2, 0.3, 0, 0, 0.5]");
    }

    #[test]
    fn ur_base_link_exports_turn_the_base_side_transform_half_a_turn_about_z() {
        for setup in [Setup::EyeInHand, Setup::EyeToHand] {
            let m = mounts(setup);
            let plain = named_transforms(&m, &FrameIds::default());
            let ids = FrameIds {
                base: "base_link".into(),
                ..FrameIds::default()
            };
            let linked = named_transforms(&m, &ids);
            for (p, l) in plain.iter().zip(&linked) {
                if p.parent == "base" {
                    assert_eq!(l.parent, "base_link");
                    // A point of the child frame: x and y flip sign, z stays (180° about z).
                    let point = nalgebra::Point3::new(0.1, 0.2, 0.3);
                    let in_base = p.parent_from_child * point;
                    let in_base_link = l.parent_from_child * point;
                    assert!((in_base_link.x + in_base.x).abs() < 1e-12);
                    assert!((in_base_link.y + in_base.y).abs() < 1e-12);
                    assert!((in_base_link.z - in_base.z).abs() < 1e-12);
                } else {
                    assert_eq!(
                        l.parent_from_child, p.parent_from_child,
                        "flange side unchanged"
                    );
                }
            }
        }
        assert!(is_ur_base_link("ur/base_link"));
        assert!(!is_ur_base_link("base"));
        assert!(!is_ur_base_link("base_link_inertia"));
    }

    /// Poses read in `base_link` (a ROS 2 arm's TF, a bag's `--base base_link`) are exported
    /// under `base_link` as they are — never turned a second time — and under `base` turned back.
    #[test]
    fn a_result_read_in_base_link_is_turned_only_toward_base() {
        for setup in [Setup::EyeInHand, Setup::EyeToHand] {
            let m = mounts(setup);
            let in_link = |base: &str| FrameIds {
                base: base.into(),
                poses_in: "base_link".into(),
                ..FrameIds::default()
            };
            let kept = named_transforms(&m, &in_link("base_link"));
            let unturned = named_transforms(&m, &FrameIds::default());
            let back = named_transforms(&m, &in_link("base"));
            for ((k, u), b) in kept.iter().zip(&unturned).zip(&back) {
                assert_eq!(k.parent_from_child, u.parent_from_child, "{}", k.key);
                if k.parent == "base_link" {
                    let turned = ur_base_link_from_base() * k.parent_from_child;
                    assert!(
                        (b.parent_from_child.to_homogeneous() - turned.to_homogeneous()).norm()
                            < 1e-12
                    );
                } else {
                    assert_eq!(b.parent_from_child, k.parent_from_child);
                }
            }
        }
        assert!(base_turn("ur/base_link", "ur/base_link").is_none());
        assert!(base_turn("base", "world").is_none());
        assert!(base_turn("base", "ur/base_link").is_some());
    }

    #[test]
    fn frame_ids_follow_the_setup() {
        let ids = FrameIds::default();
        let [camera, target] = named_transforms(&mounts(Setup::EyeInHand), &ids);
        assert_eq!(
            (
                camera.key.as_str(),
                camera.parent.as_str(),
                camera.child.as_str()
            ),
            ("T_flange_camera", "tool0", "camera_optical_frame")
        );
        assert_eq!(
            (target.key.as_str(), target.parent.as_str()),
            ("T_base_target", "base")
        );
        let [camera, target] = named_transforms(&mounts(Setup::EyeToHand), &ids);
        assert_eq!(
            (camera.key.as_str(), camera.parent.as_str()),
            ("T_base_camera", "base")
        );
        assert_eq!(
            (target.key.as_str(), target.parent.as_str()),
            ("T_flange_target", "tool0")
        );
        let ur_text = export(&mounts(Setup::EyeToHand), ExportFormat::Ur, &ids).unwrap();
        assert!(ur_text.contains("set_tcp(p["), "{ur_text}");
        assert!(
            ur_text.contains("base_camera_optical_frame = p["),
            "{ur_text}"
        );
    }
}
