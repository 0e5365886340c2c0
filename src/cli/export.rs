//! `handeye export <result.yaml> --format ros2|urdf|ur|json|opencv`: the two solved unknowns in
//! the forms other tools read (`handeye::formats::export`), printed or written atomically.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, ValueEnum};

use handeye::atomic_file::write_atomic_reporting;
use handeye::formats::{export, ExportError, ExportFormat, FrameIds};
use handeye::result::ResultFile;

/// Export form on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum FormatArg {
    /// ROS 2 static_transform_publisher commands + a launch snippet.
    Ros2,
    /// URDF fixed <joint> snippets (origin xyz + rpy).
    Urdf,
    /// UR pose literals p[x, y, z, rx, ry, rz].
    Ur,
    /// JSON (translation, quaternion xyzw, rotation vector, 4x4 matrix).
    Json,
    /// OpenCV FileStorage YAML with 4x4 matrices.
    Opencv,
}

/// Export a result file's two transforms. Every form holds T_parent_child (points in the child
/// frame mapped into the parent frame): eye_in_hand T_flange_camera and T_base_target,
/// eye_to_hand T_base_camera and T_flange_target. Frame ids follow ROS naming: ASCII letters,
/// digits, `_` and `/` (no leading `/`, no part starting with a digit).
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
    /// Frame id of the robot base (the frame T_base_flange is reported in). `base_link` (the
    /// UR ROS driver's, `base` turned 180° about z) exports the base-side transform turned to
    /// match.
    #[arg(long, default_value = "base")]
    base_frame: String,
    /// Frame id of the flange.
    #[arg(long, default_value = "tool0")]
    flange_frame: String,
    /// Frame id of the camera's optical frame (x right, y down, z forward).
    #[arg(long, default_value = "camera_optical_frame")]
    camera_frame: String,
    /// Frame id of the board.
    #[arg(long, default_value = "calibration_target")]
    target_frame: String,
}

/// Runs `handeye export`.
pub(super) fn run(args: ExportArgs) -> anyhow::Result<()> {
    let ids = FrameIds {
        base: args.base_frame,
        flange: args.flange_frame,
        camera: args.camera_frame,
        target: args.target_frame,
    };
    // Checked before anything is read or written, with the flag in the message.
    ids.validate().map_err(|e| {
        let flag = match &e {
            ExportError::FrameId { role, .. } => format!("--{role}-frame"),
            _ => "a frame flag".to_string(),
        };
        anyhow::Error::new(e).context(format!("{flag} is not a ROS frame id"))
    })?;
    let format = match args.format {
        FormatArg::Ros2 => ExportFormat::Ros2,
        FormatArg::Urdf => ExportFormat::Urdf,
        FormatArg::Ur => ExportFormat::Ur,
        FormatArg::Json => ExportFormat::Json,
        FormatArg::Opencv => ExportFormat::Opencv,
    };
    if export::is_ur_base_link(&ids.base) {
        eprintln!(
            "note: {} is the UR ROS driver's base_link (base turned 180° about z): the base-side transform is exported in it",
            ids.base
        );
    }
    // A several-camera result (`cameras:`): every camera's mount, the boards, camera to camera.
    if let Ok(text) = std::fs::read_to_string(&args.result) {
        if let Ok(rig) = serde_yaml_ng::from_str::<handeye::cell::rig::RigResultFile>(&text) {
            let text = handeye::formats::export_rig::export_rig(&rig, format, &ids)
                .with_context(|| format!("exporting {}", args.result.display()))?;
            return write_or_print(&args.output, format, &text);
        }
    }
    let mounts = ResultFile::load_mounts(&args.result)?;
    let text = export(&mounts, format, &ids)
        .with_context(|| format!("exporting {}", args.result.display()))?;
    write_or_print(&args.output, format, &text)
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
