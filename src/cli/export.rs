//! `handeye export <result.yaml> --format ros2|urdf|ur|json|opencv`: the solved transforms (a
//! one-camera cell's two unknowns, or every camera's mount and the boards of a cell with several)
//! in the forms other tools read (`handeye_formats::export`), printed or written atomically;
//! `--format ur-calibration|dh-table|arm-urdf`: the arm's model the solve estimated
//! (`handeye_formats::{ur_calibration, arm_model}`).

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, ValueEnum};

use handeye_core::atomic_file::write_atomic_reporting;
use handeye_core::yaml_file::FileError;
use handeye_formats::export::{self, Exported};
use handeye_formats::ExportFormat;

use super::camera_link::{hang_camera, CameraLinkArgs, DomainArgs};
use handeye_records::result::CellResult;
use handeye_records::result::ResultFile;

/// Export form on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum FormatArg {
    /// ROS 2 static_transform_publisher commands + a launch snippet.
    Ros2,
    /// A ROS 2 Python launch file that runs as written (`ros2 launch ./FILE.launch.py`).
    Ros2Launch,
    /// URDF fixed <joint> snippets (origin xyz + rpy).
    Urdf,
    /// UR pose literals p[x, y, z, rx, ry, rz].
    Ur,
    /// JSON (translation, quaternion xyzw, rotation vector, 4x4 matrix).
    Json,
    /// OpenCV FileStorage YAML with 4x4 matrices.
    Opencv,
    /// ur_robot_driver's kinematics calibration YAML (as ur_calibration writes it) of the arm's
    /// model the solve estimated (`solver.kinematics`).
    UrCalibration,
    /// The arm's estimated model as a plain DH table (a, d, alpha, theta_offset per joint; m, rad).
    DhTable,
    /// The arm's estimated model as a standalone URDF of its chain (base → ur_description's six
    /// joints → tool0), for robot_state_publisher or an IK solver. (`urdf` is the transforms.)
    ArmUrdf,
}

/// Export a result file's two transforms. Every form holds T_parent_child (points in the child
/// frame mapped into the parent frame): eye_in_hand T_flange_camera and T_base_target,
/// eye_to_hand T_base_camera and T_flange_target. `ur-calibration`, `dh-table` and `arm-urdf`
/// export the arm's model the solve estimated instead (the result's `kinematics:` section).
#[derive(Debug, Args)]
pub(super) struct ExportArgs {
    /// The result YAML written by `handeye solve` or `handeye run`.
    result: PathBuf,
    /// The output form.
    #[arg(long, value_enum)]
    format: FormatArg,
    /// Write here instead of printing.
    #[arg(short = 'o', long)]
    output: Option<PathBuf>,
    #[command(flatten)]
    frames: super::frames::FrameArgs,
    /// With `ros2-launch` and --camera-link: where the camera driver's chain is read.
    #[command(flatten)]
    domain: DomainArgs,
    #[command(flatten)]
    link: CameraLinkArgs,
}

/// Runs `handeye export`.
pub(super) fn run(args: ExportArgs) -> anyhow::Result<()> {
    let format = match args.format {
        // The arm's model, not the transforms: its own form.
        FormatArg::UrCalibration | FormatArg::DhTable | FormatArg::ArmUrdf => {
            return export_arm_model(&args)
        }
        FormatArg::Ros2 => ExportFormat::Ros2,
        FormatArg::Ros2Launch => ExportFormat::Ros2Launch,
        FormatArg::Urdf => ExportFormat::Urdf,
        FormatArg::Ur => ExportFormat::Ur,
        FormatArg::Json => ExportFormat::Json,
        FormatArg::Opencv => ExportFormat::Opencv,
    };
    let mut exported = exported_result(&args.result, args.frames)?;
    if args.link.camera_link.is_some() {
        anyhow::ensure!(
            format == ExportFormat::Ros2Launch,
            "--camera-link applies to --format ros2-launch only"
        );
        let folder = args.result.parent().unwrap_or(std::path::Path::new("."));
        let topic = "/tf_static";
        let heard = match args.link.assumes_chain() {
            true => None,
            false => Some(match args.link.recorded_chain(folder)? {
                Some(recorded) => recorded,
                None => (
                    read_graph(&args.domain, &args.link, topic)?,
                    topic.to_string(),
                ),
            }),
        };
        let (tree, from) = heard.unzip();
        hang_camera(
            &mut exported,
            &args.link,
            tree.as_ref(),
            from.as_deref().unwrap_or(topic),
        )?;
    }
    let text = exported
        .text(format)
        .with_context(|| format!("exporting {}", args.result.display()))?;
    write_or_print(&args.output, format, &text)
}

/// The static transforms on the domain's `topic` (a camera driver's chain).
#[cfg(feature = "ros2")]
fn read_graph(
    domain: &DomainArgs,
    link: &CameraLinkArgs,
    topic: &str,
) -> anyhow::Result<handeye_ros2::listen::TfTree> {
    use handeye_ros2::link::{LinkOptions, Ros2Link};
    let ros2 = Ros2Link::open(LinkOptions {
        domain_id: domain.domain_id()?,
        interfaces: domain.interfaces.clone(),
        node_name: "handeye_export".into(),
    })?;
    Ok(handeye_ros2::tf_static::hear_static(
        &ros2,
        topic,
        link.tf_wait()?,
    )?)
}

/// Without ROS 2 in the build the graph cannot be read.
#[cfg(not(feature = "ros2"))]
fn read_graph(
    _domain: &DomainArgs,
    _link: &CameraLinkArgs,
    _topic: &str,
) -> anyhow::Result<handeye_ros2::listen::TfTree> {
    anyhow::bail!(
        "--camera-link reads the camera driver's chain from ROS 2, and this handeye was built without it: rebuild with `--features ros2`, pass --tf-from a session holding tf_static.yaml, or --optical-rotation-only to assume the chain"
    )
}

/// Every transform of a result file, one camera's (`handeye run`, `solve`) or several cameras'
/// (a `cameras:` cell), under the frame ids `frames` asks for (by default the frames the
/// result's robot poses were read in), checked for export.
pub(super) fn exported_result(
    result: &std::path::Path,
    frames: super::frames::FrameArgs,
) -> anyhow::Result<Exported> {
    // The result of a session a run is still recording is rewritten when the run ends.
    if let Some(folder) = result.parent() {
        super::say_if_live(folder)?;
    }
    // result.yaml is derived from the session's records: a layout this handeye does not write
    // (an older one's) is solved again, not converted.
    let solved = CellResult::load(result).map_err(|e| {
        let hint = matches!(e, FileError::Shape { .. }).then(|| {
            format!(
                "; if an older handeye wrote it, solve the session again: `handeye replay {} -o {}`",
                result.parent().unwrap_or(std::path::Path::new(".")).display(),
                result.display()
            )
        });
        anyhow::anyhow!("{e}{}", hint.unwrap_or_default())
    })?;
    // Which frames the robot poses are in (older results: the UR controller's `base`, `tool0`).
    let robot = solved.robot_frames();
    let ids = &frames.ids(&robot)?;
    if export::base_turn(&ids.poses_in, &ids.base).is_some() {
        eprintln!(
            "note: the robot poses of {} were read in `{}`; exported under `{}`, the UR pair's other frame (base_link is base turned 180° about z), the base-side transforms are turned to match",
            result.display(),
            ids.poses_in,
            ids.base
        );
    }
    let exported = Exported::of(&solved, ids);
    exported
        .check(ids)
        .with_context(|| format!("exporting {}", result.display()))?;
    Ok(exported)
}

/// `--format ur-calibration|dh-table|arm-urdf`: the arm's model of a result (its `kinematics:`
/// section).
fn export_arm_model(args: &ExportArgs) -> anyhow::Result<()> {
    use handeye_formats::{arm_model, ur_calibration};
    let result = ResultFile::load(&args.result)?;
    let kinematics = result.kinematics.as_ref().ok_or_else(|| {
        anyhow::anyhow!(
            "{}: no `kinematics:` section: the arm's model was not estimated (solve with `solver: {{kinematics: joint_offsets}}`)",
            args.result.display()
        )
    })?;
    let (name, text) = match args.format {
        FormatArg::DhTable => ("dh-table", arm_model::dh_table(kinematics)),
        FormatArg::ArmUrdf => ("arm-urdf", arm_model::arm_urdf(kinematics)),
        _ => (
            "ur-calibration",
            ur_calibration::ur_calibration_yaml(kinematics),
        ),
    };
    let text = text.with_context(|| format!("exporting {}", args.result.display()))?;
    match &args.output {
        Some(path) => {
            write_atomic_reporting(path, text.as_bytes())
                .with_context(|| format!("writing {}", path.display()))?;
            outln!("wrote {name} to {}", path.display());
        }
        None => out!("{text}"),
    }
    Ok(())
}

/// Writes `text` atomically to `output`, or prints it.
fn write_or_print(
    output: &Option<PathBuf>,
    format: ExportFormat,
    text: &str,
) -> anyhow::Result<()> {
    match output {
        Some(path) => {
            let removed = write_atomic_reporting(path, text.as_bytes())
                .with_context(|| format!("writing {}", path.display()))?;
            for r in removed {
                eprintln!(
                    "note: removed {} ({} bytes), the unfinished temporary file of an earlier \
                     export to {} that was killed",
                    r.path.display(),
                    r.bytes,
                    path.display()
                );
            }
            outln!("wrote {} to {}", format.name(), path.display());
        }
        None => out!("{text}"),
    }
    Ok(())
}
