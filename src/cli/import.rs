//! `handeye import <format> ... -o dataset.yaml`: other tools' hand-eye data into our dataset
//! form (`T_base_flange`, `T_camera_target` pairs). The library does the reading
//! (`handeye::formats::import`); this file maps arguments and prints what was found.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};

use handeye::camera_model::CameraModel;
use handeye::config::{
    CameraConfig, CellConfig, ConfigFile, DetectorConfig, LimitsConfig, PlanConfig, RobotConfig,
    SessionConfig, SolverConfig, WorkspaceConfig,
};
use handeye::dataset::Dataset;
use handeye::formats::bag::{import_bag, BagOptions};
use handeye::formats::import::{
    import_csv_pairs, import_csv_two_files, import_moveit_json, import_visp, CsvOptions,
    CsvPoseForm, VispOptions,
};
use handeye::geometry::PoseYaml;
use handeye::robot::recorded::save_recorded_poses;
use handeye::setup::Setup;
use handeye::vision::{DetectorOptions, Target};

/// The cell layout on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SetupArg {
    /// Camera on the flange, target fixed.
    #[value(name = "eye_in_hand", alias = "eye-in-hand")]
    EyeInHand,
    /// Camera fixed, target on the flange.
    #[value(name = "eye_to_hand", alias = "eye-to-hand")]
    EyeToHand,
}

impl From<SetupArg> for Setup {
    fn from(s: SetupArg) -> Setup {
        match s {
            SetupArg::EyeInHand => Setup::EyeInHand,
            SetupArg::EyeToHand => Setup::EyeToHand,
        }
    }
}

/// Import other tools' data as a dataset file (T_base_flange, T_camera_target pairs).
#[derive(Debug, Args)]
pub struct ImportArgs {
    #[command(subcommand)]
    format: ImportFormat,
}

#[derive(Debug, Subcommand)]
enum ImportFormat {
    /// ViSP hand-eye data: `*_pose_rPe_<N>.yaml` + `*image-<N>.png` + vpXmlParserCamera XML.
    ///
    /// `*_pose_rPe_<N>.yaml` holds T_base_flange (ViSP's rMe: the end-effector in the robot base)
    /// as [tx, ty, tz, θux, θuy, θuz] (m, axis-angle rad). T_camera_target is measured by
    /// detecting the board (--target) in each image with the folder's intrinsics. Also writes the
    /// intrinsics as camera_info YAML and the poses as a recorded-poses file, so the folder can run
    /// as a session (robot backend `recorded`, camera backend `files`).
    Visp(VispArgs),
    /// MoveIt Calibration pose-sample JSON: [[T_base_flange, T_camera_target], ...] as 4x4
    /// row-major matrices in metres (effector_wrt_world, object_wrt_sensor).
    Moveit(MoveitArgs),
    /// Plain CSV: a pose is `tx,ty,tz,qx,qy,qz,qw` (--form quaternion) or UR's `x,y,z,rx,ry,rz`
    /// (--form rotvec, rotation vector rad); metres unless --mm.
    ///
    /// One file: each row holds T_base_flange then T_camera_target (14 or 12 numbers). Two files
    /// (--camera-poses): FILE holds T_base_flange per row, the camera file T_camera_target per
    /// row, paired by row order. `#` lines and blank lines are skipped; a first row without
    /// numbers is a header.
    Csv(CsvArgs),
    /// A ROS 2 bag (MCAP or sqlite3 .db3): /tf + /tf_static, images and camera_info into a
    /// session folder (see docs/ros2-bags.md).
    ///
    /// T_base_flange is chained from --base to --flange in the TF tree at each image stamp
    /// (interpolated, never extrapolated). Stop-and-go (default): the sharpest frame of each
    /// interval where the flange stood still. --continuous: a frame every --spacing seconds,
    /// with the camera-to-robot clock offset given (--time-offset S) or estimated (auto). The
    /// frames and poses are run as a recorded cell into -o, an ordinary session folder (replay,
    /// report, verify, solve work on it); nothing is left behind if the import fails.
    Bag(BagArgs),
}

#[derive(Debug, Args)]
struct Common {
    /// The cell layout the data comes from (the sources do not say).
    #[arg(long, value_enum)]
    setup: SetupArg,
    /// Write the dataset here.
    #[arg(short = 'o', long)]
    output: PathBuf,
}

#[derive(Debug, Args)]
struct VispArgs {
    /// The ViSP data folder.
    folder: PathBuf,
    /// Board YAML the images show (e.g. configs/targets/single-tag36h11-id10.yaml).
    #[arg(long)]
    target: PathBuf,
    /// Intrinsics (camera_info or Kalibr YAML) instead of the folder's XML.
    #[arg(long)]
    intrinsics: Option<PathBuf>,
    /// Where to write the intrinsics as camera_info YAML (default: <output stem>-camera.yaml).
    #[arg(long)]
    camera_info_out: Option<PathBuf>,
    /// Where to write the recorded T_base_flange poses (default: <output stem>-poses.yaml).
    #[arg(long)]
    poses_out: Option<PathBuf>,
    /// Also write a cell config that replays the folder as a session (robot backend `recorded`,
    /// camera backend `files`): `handeye run --config <it>`.
    #[arg(long)]
    cell_out: Option<PathBuf>,
    /// Skip images where the board is not found instead of failing.
    #[arg(long)]
    skip_unfound: bool,
    /// Quad decimation of the detector (1 = full resolution, at most 16).
    #[arg(long, default_value_t = 1.0)]
    decimation: f32,
    #[command(flatten)]
    common: Common,
}

#[derive(Debug, Args)]
struct MoveitArgs {
    /// The pose-sample JSON file.
    file: PathBuf,
    #[command(flatten)]
    common: Common,
}

/// CSV pose form on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum FormArg {
    /// tx,ty,tz,qx,qy,qz,qw
    Quaternion,
    /// x,y,z,rx,ry,rz (UR)
    Rotvec,
}

#[derive(Debug, Args)]
struct CsvArgs {
    /// The CSV file (both poses per row, or T_base_flange only with --camera-poses).
    file: PathBuf,
    /// A second CSV holding T_camera_target per row, paired with FILE by row order.
    #[arg(long)]
    camera_poses: Option<PathBuf>,
    /// How each pose is written.
    #[arg(long, value_enum)]
    form: FormArg,
    /// Translations are in millimetres.
    #[arg(long)]
    mm: bool,
    #[command(flatten)]
    common: Common,
}

#[derive(Debug, Args)]
struct BagArgs {
    /// The bag: a folder with metadata.yaml, or one .mcap / .db3 file.
    bag: PathBuf,
    /// The robot base frame in the TF tree.
    #[arg(long, default_value = "base")]
    base: String,
    /// The flange frame in the TF tree.
    #[arg(long, default_value = "tool0")]
    flange: String,
    /// The image topic (sensor_msgs/Image or sensor_msgs/CompressedImage).
    #[arg(long)]
    image: String,
    /// The camera_info topic (plumb_bob); without it the intrinsics are estimated from the
    /// frames.
    #[arg(long)]
    camera_info: Option<String>,
    /// Board YAML the images show (e.g. configs/targets/single-tag36h11-id10.yaml).
    #[arg(long, alias = "target")]
    board: PathBuf,
    /// The cell layout (a bag does not say).
    #[arg(long, value_enum, default_value = "eye_in_hand")]
    setup: SetupArg,
    /// The arm moved continuously: take a frame every --spacing seconds instead of the
    /// sharpest frame of each stop.
    #[arg(long)]
    continuous: bool,
    /// Continuous mode: seconds between samples (0.01 to 60).
    #[arg(long, default_value_t = 0.5)]
    spacing: f64,
    /// Camera clock minus robot clock, seconds (-5 to 5), or `auto` to estimate it (needs
    /// --continuous and --camera-info).
    #[arg(long, default_value = "0")]
    time_offset: String,
    /// `--time-offset auto`: search range ± seconds (0.001 to 5).
    #[arg(long, default_value_t = 0.2)]
    max_offset: f64,
    /// Stop-and-go: the flange must stay still this long around a frame, seconds (0.01 to 10).
    #[arg(long, default_value_t = 0.2)]
    still_window: f64,
    /// Stop-and-go: largest speed still counted as standing, mm/s (0.001 to 1000).
    #[arg(long, default_value_t = 2.0)]
    max_speed_mm_s: f64,
    /// Stop-and-go: largest rotation speed still counted as standing, deg/s (0.001 to 100).
    #[arg(long, default_value_t = 0.2)]
    max_speed_deg_s: f64,
    /// Largest spacing of two TF messages to interpolate between, ms (0.1 to 10000).
    #[arg(long, default_value_t = 100.0)]
    max_tf_gap_ms: f64,
    /// Quad decimation of the detector (1 = full resolution, at most 16).
    #[arg(long, default_value_t = 1.0)]
    decimation: f32,
    /// The session folder to create (must not exist, or be empty).
    #[arg(short = 'o', long)]
    output: PathBuf,
}

/// `value` within `[lo, hi]`, or an error naming the option.
fn in_range(option: &str, value: f64, lo: f64, hi: f64) -> anyhow::Result<f64> {
    anyhow::ensure!(
        value.is_finite() && (lo..=hi).contains(&value),
        "{option} {value}: expected a number from {lo} to {hi}"
    );
    Ok(value)
}

fn bag_options(a: &BagArgs) -> anyhow::Result<BagOptions> {
    use handeye::formats::bag::{Motion, OffsetChoice, SelectOptions};
    anyhow::ensure!(
        (1.0..=16.0).contains(&a.decimation),
        "--decimation {}: expected 1 to 16",
        a.decimation
    );
    let offset = match a.time_offset.trim() {
        "auto" => OffsetChoice::Estimate {
            max_s: in_range("--max-offset", a.max_offset, 0.001, 5.0)?,
        },
        text => {
            let s: f64 = text.parse().map_err(|_| {
                anyhow::anyhow!("--time-offset `{text}`: expected seconds (e.g. 0.035) or `auto`")
            })?;
            OffsetChoice::Fixed(in_range("--time-offset", s, -5.0, 5.0)?)
        }
    };
    let board = Target::load(&a.board)?;
    Ok(BagOptions {
        base_frame: a.base.clone(),
        flange_frame: a.flange.clone(),
        image_topic: a.image.clone(),
        camera_info_topic: a.camera_info.clone(),
        tf_topics: vec!["/tf".into(), "/tf_static".into()],
        tf_static_topics: vec!["/tf_static".into()],
        select: SelectOptions {
            motion: if a.continuous {
                Motion::Continuous {
                    spacing_s: in_range("--spacing", a.spacing, 0.01, 60.0)?,
                }
            } else {
                Motion::StopAndGo
            },
            window_s: in_range("--still-window", a.still_window, 0.01, 10.0)?,
            max_speed_m_s: in_range("--max-speed-mm-s", a.max_speed_mm_s, 0.001, 1000.0)? * 1e-3,
            max_speed_rad_s: in_range("--max-speed-deg-s", a.max_speed_deg_s, 0.001, 100.0)?
                .to_radians(),
            max_tf_gap_s: in_range("--max-tf-gap-ms", a.max_tf_gap_ms, 0.1, 10_000.0)? * 1e-3,
            offset,
        },
        setup: a.setup.into(),
        board,
        detector: DetectorOptions {
            decimation: a.decimation,
            ..DetectorOptions::default()
        },
    })
}

/// What `import bag` records about itself in `<session>/import/bag-import.yaml`.
#[derive(serde::Serialize)]
struct BagImportRecord {
    bag: PathBuf,
    format: String,
    image_topic: String,
    images: usize,
    time_offset_s: f64,
    time_offset_estimated: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    time_offset_residual_mm: Option<f64>,
    samples: Vec<BagSampleRecord>,
    skipped: Vec<BagSkipRecord>,
    /// What is wrong with the bag but did not stop the import.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    warnings: Vec<BagWarningRecord>,
}

#[derive(serde::Serialize)]
struct BagWarningRecord {
    kind: String,
    message: String,
}

#[derive(serde::Serialize)]
struct BagSampleRecord {
    frame: String,
    image_stamp_s: f64,
    robot_stamp_s: f64,
    sharpness: f64,
}

#[derive(serde::Serialize)]
struct BagSkipRecord {
    image_stamp_s: f64,
    reason: String,
}

/// Runs `import bag`: reads the bag, then runs its frames as a recorded cell into a staging
/// folder next to the output and renames it into place when everything succeeded.
fn import_bag_session(a: BagArgs) -> anyhow::Result<()> {
    use handeye::session::{self, SessionFolder, SessionManifest};
    let options = bag_options(&a)?;
    let out = absolute(&a.output)?;
    if out.exists() {
        let empty = out.is_dir()
            && std::fs::read_dir(&out)
                .with_context(|| format!("reading {}", out.display()))?
                .next()
                .is_none();
        anyhow::ensure!(
            empty,
            "{}: exists already; give a new session folder",
            out.display()
        );
    }
    // Staging folders of imports that were killed (kill -9, a power cut) are removed here; those
    // of imports still running beside this one are locked and left alone.
    if let Some(parent) = out.parent() {
        for leftover in session::remove_abandoned(parent, STAGING_TAG)? {
            match leftover {
                session::Leftover::Removed(path) => {
                    outln!("removed {} left by an import that was killed", leaf(&path))
                }
                session::Leftover::InUse(path, pid) => outln!(
                    "left {} alone: an import still running{} writes into it",
                    leaf(&path),
                    pid.map(|p| format!(" (pid {p})")).unwrap_or_default()
                ),
            }
        }
    }
    let imported = import_bag(&a.bag, &options).context("importing a ROS 2 bag")?;
    // Said first, so they are read whatever follows (even a refusal for too few frames).
    for w in &imported.warnings {
        eprintln!("warning: {}: {w}", a.bag.display());
    }
    let mut kinds: BTreeMap<&str, usize> = BTreeMap::new();
    for s in &imported.skipped {
        *kinds.entry(s.reason.kind()).or_default() += 1;
    }
    outln!(
        "{} ({}): {} images on {}; {} frames taken; skipped: {}",
        a.bag.display(),
        imported.format,
        imported.images,
        a.image,
        imported.samples.len(),
        if kinds.is_empty() {
            "none".to_string()
        } else {
            kinds
                .iter()
                .map(|(k, n)| format!("{n} {k}"))
                .collect::<Vec<_>>()
                .join(", ")
        }
    );
    for s in imported
        .skipped
        .iter()
        .filter(|s| s.reason.kind() == "tf gap")
        .take(3)
    {
        outln!("  frame at {:.3} s: {}", s.stamp_ns as f64 * 1e-9, s.reason);
    }
    let o = &imported.offset;
    if o.estimated {
        outln!(
            "camera-to-robot clock offset: {:+.2} ms (estimated from {} frames with the board; board position RMS {:.3} mm)",
            o.offset_s * 1e3,
            o.frames_used,
            o.residual_mm.unwrap_or(f64::NAN)
        );
    } else if o.offset_s != 0.0 {
        outln!(
            "camera-to-robot clock offset: {:+.2} ms (given)",
            o.offset_s * 1e3
        );
    }
    anyhow::ensure!(
        imported.samples.len() >= 3,
        "{}: only {} usable frames (a calibration needs at least 3 views): {}",
        a.bag.display(),
        imported.samples.len(),
        if a.continuous {
            "check --image, the TF frames and --spacing"
        } else {
            "did the arm stop at each view? (--max-speed-mm-s, --still-window; or --continuous)"
        }
    );

    // Stage everything next to the output; dropped (removed) on any error.
    let parent = out
        .parent()
        .ok_or_else(|| anyhow::anyhow!("{}: has no parent folder", out.display()))?;
    std::fs::create_dir_all(parent).with_context(|| format!("creating {}", parent.display()))?;
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "session".into());
    let staging = session::Staging::create(parent, &name, STAGING_TAG)
        .with_context(|| format!("creating a staging folder in {}", parent.display()))?;
    let stage = staging.path().to_path_buf();
    let folder = SessionFolder::create(&stage)?;
    let import_dir = stage.join("import");
    let images_dir = import_dir.join("images");
    std::fs::create_dir_all(&images_dir)
        .with_context(|| format!("creating {}", images_dir.display()))?;
    let mut samples = Vec::new();
    for (i, s) in imported.samples.iter().enumerate() {
        let file = images_dir.join(format!("{i:03}.png"));
        s.image
            .save(&file)
            .with_context(|| format!("writing {}", file.display()))?;
        samples.push(BagSampleRecord {
            frame: format!("import/images/{i:03}.png"),
            image_stamp_s: s.image_stamp_ns as f64 * 1e-9,
            robot_stamp_s: s.robot_stamp_ns as f64 * 1e-9,
            sharpness: s.sharpness,
        });
    }
    let poses: Vec<_> = imported
        .samples
        .iter()
        .map(|s| s.base_from_flange)
        .collect();
    save_recorded_poses(&poses, &import_dir.join("poses.yaml"))?;
    if let Some(camera) = &imported.camera {
        camera.save_camera_info(&import_dir.join("camera_info.yaml"))?;
    }
    std::fs::copy(&a.board, import_dir.join("target.yaml"))
        .with_context(|| format!("copying {}", a.board.display()))?;
    let setup: Setup = a.setup.into();
    let identity = handeye::geometry::Pose::identity();
    let config = recorded_cell(
        setup,
        RecordedFiles {
            target: PathBuf::from("target.yaml"),
            intrinsics: imported
                .camera
                .is_some()
                .then(|| PathBuf::from("camera_info.yaml")),
            poses: PathBuf::from("poses.yaml"),
            images: PathBuf::from("images"),
        },
        // Nominal transforms only feed a recorded cell's plan report; the solve needs none.
        (identity, identity),
        &poses,
        a.decimation,
    );
    let config_file = import_dir.join("cell.yaml");
    config.save(
        &config_file,
        &format!(
            "The recorded cell of the ROS 2 bag {} (written by `handeye import bag`)",
            absolute(&a.bag)?.display()
        ),
    )?;
    let mut cell = handeye::cell::prepare(&config_file).context("preparing the recorded cell")?;
    if !cell.report.ok() {
        anyhow::bail!(
            "the frames taken from {} cannot calibrate:\n{}",
            a.bag.display(),
            cell.report
        );
    }
    let start = cell.start_joints;
    let plan = cell
        .recheck_from(start)
        .map_err(|report| anyhow::anyhow!("the recorded plan fails its checks:\n{report}"))?;
    // The manifest names the files where they will be once the staging folder is renamed.
    let final_path = |p: &Path| match p.strip_prefix(&stage) {
        Ok(rel) => out.join(rel),
        Err(_) => p.to_path_buf(),
    };
    let mut inputs = cell.inputs()?;
    for input in &mut inputs {
        input.path = final_path(&std::fs::canonicalize(&input.path).unwrap_or(input.path.clone()));
    }
    folder.write_manifest(
        &SessionManifest::new(out.join("import").join("cell.yaml"), setup, &plan)
            .with_inputs(inputs),
    )?;
    let mut hardware = cell.open_hardware().context("opening the recorded cell")?;
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let session_setup = cell.session_setup(folder.clone(), plan, stop);
    let outcome = session::run_session(
        session_setup,
        hardware.robot.as_mut(),
        hardware.camera.as_mut(),
        &mut |_| {},
    )?;
    for (index, why) in &outcome.skipped {
        outln!(
            "  frame {index:03} ({:.3} s): board not found or rejected: {why}",
            imported.samples[*index].image_stamp_ns as f64 * 1e-9
        );
    }
    let solved = session::solve_folder(&folder, &cell.solve_inputs())?;
    let record = BagImportRecord {
        bag: absolute(&a.bag)?,
        format: imported.format.to_string(),
        image_topic: a.image.clone(),
        images: imported.images,
        time_offset_s: o.offset_s,
        time_offset_estimated: o.estimated,
        time_offset_residual_mm: o.residual_mm,
        samples,
        skipped: imported
            .skipped
            .iter()
            .map(|s| BagSkipRecord {
                image_stamp_s: s.stamp_ns as f64 * 1e-9,
                reason: s.reason.to_string(),
            })
            .collect(),
        warnings: imported
            .warnings
            .iter()
            .map(|w| BagWarningRecord {
                kind: w.kind().to_string(),
                message: w.to_string(),
            })
            .collect(),
    };
    let record_file = import_dir.join("bag-import.yaml");
    let text = serde_yaml_ng::to_string(&record).context("writing the import record")?;
    handeye::atomic_file::write_atomic(&record_file, text.as_bytes())
        .with_context(|| format!("writing {}", record_file.display()))?;
    drop(hardware);
    drop(folder);
    staging
        .commit(&out)
        .with_context(|| format!("moving the session into {}", out.display()))?;
    outln!(
        "session {}: {} samples accepted, {} skipped (board not found or rejected)",
        out.display(),
        outcome.accepted.len(),
        outcome.skipped.len()
    );
    // The solve ran in the staging folder; name the session where it is now.
    outln!(
        "{}",
        solved
            .summary
            .trim_end()
            .replace(&*stage.to_string_lossy(), &out.to_string_lossy())
    );
    if !imported.warnings.is_empty() {
        outln!(
            "the bag has {} warning(s) (printed above, recorded in {}): check them before using this answer",
            imported.warnings.len(),
            out.join("import/bag-import.yaml").display()
        );
    }
    outln!(
        "next: handeye report {0}   (or: handeye solve {0} --space reprojection, handeye replay {0})",
        out.display()
    );
    Ok(())
}

/// The tag of `import bag`'s staging folders: `.<session>.importing-XXXXXX`.
const STAGING_TAG: &str = "importing";

/// A path's last component, for messages.
fn leaf(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

fn sibling(output: &Path, suffix: &str) -> PathBuf {
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "dataset".into());
    output.with_file_name(format!("{stem}-{suffix}.yaml"))
}

fn save(dataset: &Dataset, output: &Path) -> anyhow::Result<()> {
    // The error names the file.
    dataset.save(output)?;
    outln!(
        "wrote {} samples ({}) to {}",
        dataset.pairs.len(),
        dataset.setup,
        output.display()
    );
    Ok(())
}

/// The canonical form of an existing path.
fn canonical(path: &Path) -> anyhow::Result<PathBuf> {
    std::fs::canonicalize(path).with_context(|| format!("resolving {}", path.display()))
}

/// The absolute form of a path that may not exist yet (an output about to be written).
fn absolute(path: &Path) -> anyhow::Result<PathBuf> {
    std::path::absolute(path).with_context(|| format!("resolving {}", path.display()))
}

/// The files one import writes. Until [`Outputs::commit`], dropping it (an error on the way)
/// removes every file it created, so a failed import leaves no partial outputs behind. (A file
/// that existed before is replaced atomically by each writer and cannot be restored; it is kept.)
#[derive(Default)]
struct Outputs {
    created: Vec<PathBuf>,
    committed: bool,
}

impl Outputs {
    /// Runs `write`, which writes `path`, and remembers `path` if it is new.
    fn write(
        &mut self,
        path: &Path,
        write: impl FnOnce() -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        let existed = path.exists();
        let result = write();
        if !existed && path.exists() {
            self.created.push(path.to_path_buf());
        }
        result
    }

    /// Keeps every file written.
    fn commit(mut self) {
        self.committed = true;
    }
}

impl Drop for Outputs {
    fn drop(&mut self) {
        if self.committed {
            return;
        }
        for path in &self.created {
            match std::fs::remove_file(path) {
                Ok(()) => tracing::warn!("removed {} (the import failed)", path.display()),
                Err(e) => tracing::warn!(
                    "the import failed and {} could not be removed: {e}",
                    path.display()
                ),
            }
        }
    }
}

/// Where a recorded cell's files are (relative paths are read from the config's folder).
struct RecordedFiles {
    target: PathBuf,
    intrinsics: Option<PathBuf>,
    poses: PathBuf,
    images: PathBuf,
}

/// The config of a recorded cell that replays imported frames: the flange poses
/// `base_from_flange` (as in `files.poses`) with the images of a folder camera. `nominal` (camera mount, target mount) only feeds the
/// plan report; the workspace box, which a recorded robot does not use, spans the recorded
/// flange positions ± 0.5 m; nothing moves, so nothing settles.
fn recorded_cell(
    setup: Setup,
    files: RecordedFiles,
    (camera_mount, target_mount): (handeye::geometry::Pose, handeye::geometry::Pose),
    base_from_flange: &[handeye::geometry::Pose],
    decimate: f32,
) -> ConfigFile {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in base_from_flange {
        let t = p.translation.vector;
        for k in 0..3 {
            lo[k] = lo[k].min(t[k] - 0.5);
            hi[k] = hi[k].max(t[k] + 0.5);
        }
    }
    let (camera_key, target_key) = setup.unknown_names();
    ConfigFile {
        setup,
        target: files.target,
        intrinsics: files.intrinsics,
        robot: RobotConfig::Recorded {
            poses: files.poses,
            repeatability_mm: None,
            repeatability_deg: None,
        },
        camera: CameraConfig::Files {
            folder: files.images,
        },
        nominal: BTreeMap::from([
            (camera_key.to_string(), PoseYaml::from_pose(&camera_mount)),
            (target_key.to_string(), PoseYaml::from_pose(&target_mount)),
        ]),
        simulation: None,
        plan: PlanConfig::default(),
        limits: LimitsConfig::default(),
        workspace: WorkspaceConfig { min: lo, max: hi },
        detector: DetectorConfig {
            decimate,
            ..DetectorConfig::default()
        },
        solver: SolverConfig::default(),
        session: SessionConfig {
            settle_s: 0.0,
            ..SessionConfig::default()
        },
        verdict: Default::default(),
    }
}

/// The recorded-cell config for an imported ViSP folder: only when the folder's frames (natural
/// order) are exactly the imported images, since the folder camera serves every image in it.
/// Built before anything is written, so a refusal leaves no files behind.
fn cell_text(
    cell_out: &Path,
    folder: &Path,
    target: &Path,
    camera_info: &Path,
    poses: &Path,
    imported: &handeye::formats::import::VispImport,
) -> anyhow::Result<String> {
    let frames = handeye::camera::files::list_frames(folder)?;
    let paired: Vec<&PathBuf> = imported.frames.iter().map(|f| &f.files.image).collect();
    anyhow::ensure!(
        frames.iter().collect::<Vec<_>>() == paired,
        "{}: the folder's images in natural order are not exactly the paired ViSP images, so a folder camera would pair them wrongly; no cell config written",
        folder.display()
    );
    let setup = imported.dataset.setup;
    // Nominal transforms from a quick solve (they only feed the plan report of a recorded cell).
    let (camera_mount, target_mount) = match handeye::solve::solve(
        setup,
        &imported.dataset.pairs,
        &handeye::solve::SolveOptions::default(),
    ) {
        Ok(c) => (c.camera_mount, c.target_mount),
        Err(_) => (
            handeye::geometry::Pose::identity(),
            handeye::geometry::Pose::identity(),
        ),
    };
    let folder = canonical(folder)?;
    let base_from_flange: Vec<_> = imported.frames.iter().map(|f| f.base_from_flange).collect();
    let config = recorded_cell(
        setup,
        RecordedFiles {
            target: canonical(target)?,
            intrinsics: Some(absolute(camera_info)?),
            poses: absolute(poses)?,
            images: folder.clone(),
        },
        (camera_mount, target_mount),
        &base_from_flange,
        1.0,
    );
    let header = format!(
        "Replays the ViSP folder {} as a session: handeye run --config <this file>",
        folder.display()
    );
    // Checked to load back as a valid cell config before anything is written.
    let text = config.to_yaml(&header, cell_out)?;
    CellConfig::parse(&text, cell_out).with_context(|| {
        format!(
            "{}: the cell config built for the import",
            cell_out.display()
        )
    })?;
    Ok(text)
}

/// Runs `handeye import`.
pub fn run(args: ImportArgs) -> anyhow::Result<()> {
    match args.format {
        ImportFormat::Visp(a) => {
            let board = Target::load(&a.target)?;
            let camera = a.intrinsics.as_deref().map(CameraModel::load).transpose()?;
            anyhow::ensure!(
                a.decimation >= 1.0,
                "--decimation {} must be >= 1",
                a.decimation
            );
            let options = VispOptions {
                setup: a.common.setup.into(),
                board,
                camera,
                detector: DetectorOptions {
                    decimation: a.decimation,
                    ..DetectorOptions::default()
                },
                skip_unfound: a.skip_unfound,
            };
            let imported = import_visp(&a.folder, &options)
                .with_context(|| format!("importing ViSP data from {}", a.folder.display()))?;
            for f in &imported.frames {
                match (&f.skipped, f.rms_px) {
                    (Some(why), _) => outln!("{}: skipped: {why}", f.files.image.display()),
                    (None, Some(rms)) => outln!(
                        "{}: board RMS {rms:.3} px{}",
                        f.files.image.display(),
                        match f.ambiguity {
                            Some(r) if r > handeye::vision::pnp::AMBIGUITY_WARN_RATIO =>
                                format!(" (AMBIGUOUS lone tag, ratio {r:.2})"),
                            _ => String::new(),
                        }
                    ),
                    (None, None) => {}
                }
            }
            let info = a
                .camera_info_out
                .unwrap_or_else(|| sibling(&a.common.output, "camera"));
            let poses_out = a
                .poses_out
                .unwrap_or_else(|| sibling(&a.common.output, "poses"));
            // Everything that can be refused is decided before the first file is written.
            let cell = match &a.cell_out {
                Some(cell_out) => Some((
                    cell_out,
                    cell_text(cell_out, &a.folder, &a.target, &info, &poses_out, &imported)?,
                )),
                None => None,
            };
            let mut outputs = Outputs::default();
            outputs.write(&info, || {
                // The errors of these writers name their file.
                Ok(imported.camera.save_camera_info(&info)?)
            })?;
            outln!("wrote the intrinsics to {}", info.display());
            let poses: Vec<_> = imported.frames.iter().map(|f| f.base_from_flange).collect();
            outputs.write(&poses_out, || Ok(save_recorded_poses(&poses, &poses_out)?))?;
            outln!(
                "wrote the recorded T_base_flange poses to {}",
                poses_out.display()
            );
            outputs.write(&a.common.output, || {
                save(&imported.dataset, &a.common.output)
            })?;
            if let Some((cell_out, text)) = cell {
                outputs.write(cell_out, || {
                    handeye::atomic_file::write_atomic(cell_out, text.as_bytes())
                        .with_context(|| format!("writing {}", cell_out.display()))
                })?;
                outln!("wrote a recorded-cell config to {}", cell_out.display());
            }
            outputs.commit();
            Ok(())
        }
        ImportFormat::Bag(a) => import_bag_session(a),
        ImportFormat::Moveit(a) => {
            let pairs = import_moveit_json(&a.file)?;
            save(
                &Dataset {
                    setup: a.common.setup.into(),
                    pairs,
                },
                &a.common.output,
            )
        }
        ImportFormat::Csv(a) => {
            let options = CsvOptions {
                form: match a.form {
                    FormArg::Quaternion => CsvPoseForm::Quaternion,
                    FormArg::Rotvec => CsvPoseForm::RotationVector,
                },
                millimetres: a.mm,
            };
            let pairs = match &a.camera_poses {
                Some(camera) => import_csv_two_files(&a.file, camera, &options)?,
                None => import_csv_pairs(&a.file, &options)?,
            };
            save(
                &Dataset {
                    setup: a.common.setup.into(),
                    pairs,
                },
                &a.common.output,
            )
        }
    }
}
