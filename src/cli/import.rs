//! `handeye import <format> ... -o dataset.yaml`: other tools' hand-eye data into our dataset
//! form (`T_base_flange`, `T_camera_target` pairs). The library does the reading
//! (`handeye_formats::import`); this file maps arguments and prints what was found.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};

use handeye_config::{recorded_cell, CellConfig, RecordedFiles};
use handeye_core::camera_model::CameraModel;
use handeye_core::setup::Setup;
use handeye_formats::import::{
    import_csv_pairs, import_csv_two_files, import_moveit_json, import_visp, CsvOptions,
    CsvPoseForm, VispOptions,
};
use handeye_records::dataset::Dataset;
use handeye_robot::recorded::save_recorded_poses;
use handeye_ros2_bag::BagOptions;
use handeye_session::cell::bag::{import_bag_session, BagNote, BagSessionRequest};
use handeye_vision::{DetectorOptions, Target};

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
pub(super) struct ImportArgs {
    #[command(subcommand)]
    format: ImportFormat,
}

#[derive(Debug, Subcommand)]
enum ImportFormat {
    /// ViSP hand-eye data: `*_pose_rPe_<N>.yaml` + `*image-<N>.png` + vpXmlParserCamera XML.
    ///
    /// `*_pose_rPe_<N>.yaml` holds T_base_flange (ViSP's rMe: the end-effector in the robot base)
    /// as [tx, ty, tz, θux, θuy, θuz] (m, axis-angle rad). T_camera_target is measured by
    /// detecting the board (--board) in each image with the folder's intrinsics. Also writes the
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
    #[arg(long = "board", alias = "target")]
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
    /// The camera_info topic (plumb_bob or equidistant); without it the intrinsics are estimated from the
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
    /// Quad decimation of the detector, as a cell's `detector.decimate` and `handeye detect`:
    /// 2 searches the quads at half resolution, the corners are still refined at full
    /// resolution; 1 (full resolution, this import's default before) when tags far away or
    /// small are not found at half.
    #[arg(long, default_value_t = 2.0)]
    decimation: f32,
    /// Frames decoded and detected at once, each by a thread of its own (default: one per core,
    /// at most four, fewer when the memory limit leaves room for fewer).
    #[arg(short = 'j', long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=64))]
    jobs: Option<usize>,
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
    use handeye_ros2_bag::{Motion, OffsetChoice, SelectOptions};
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
            jobs: a.jobs,
            ..DetectorOptions::default()
        },
    })
}

/// Runs `import bag`: the library imports the bag into a session; this prints what it says.
fn import_bag(a: BagArgs) -> anyhow::Result<()> {
    let request = BagSessionRequest {
        options: bag_options(&a)?,
        bag: a.bag,
        board_file: a.board,
        decimation: a.decimation,
        continuous: a.continuous,
        output: a.output,
    };
    let say = &mut |note| match note {
        BagNote::Line(line) => outln!("{line}"),
        BagNote::Warning(warning) => eprintln!("warning: {warning}"),
    };
    let imported = import_bag_session(&request, say, &super::run::run_report)?;
    let out = imported.folder.display();
    outln!(
        "session {out}: {} samples accepted, {} skipped (board not found or rejected)",
        imported.accepted,
        imported.skipped
    );
    outln!("{}", imported.summary);
    if imported.warnings > 0 {
        outln!(
            "the bag has {} warning(s) (printed above, recorded in {} and among the notices of {}): check them before using this answer",
            imported.warnings,
            imported.folder.join("import/bag-import.yaml").display(),
            imported.folder.join("result.yaml").display()
        );
    }
    // The report the run's tail wrote, as after `handeye run`.
    match &imported.report {
        Ok(report) => {
            outln!("report:  {}", report.display());
            outln!(
                "{}",
                super::run::next_step(
                    imported.solved.verdict.as_ref(),
                    &imported.folder.join("result.yaml"),
                    super::run::Stack::Ros2
                )
            );
        }
        Err(e) => {
            eprintln!("warning: the report could not be written: {e}");
            outln!("next: handeye replay {out}");
        }
    }
    Ok(())
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

/// The recorded-cell config for an imported ViSP folder: only when the folder's frames (natural
/// order) are exactly the imported images, since the folder camera serves every image in it.
/// Built before anything is written, so a refusal leaves no files behind.
fn cell_text(
    cell_out: &Path,
    folder: &Path,
    target: &Path,
    camera_info: &Path,
    poses: &Path,
    imported: &handeye_formats::import::VispImport,
) -> anyhow::Result<String> {
    let frames = handeye_camera::files::list_frames(folder)?;
    let paired: Vec<&PathBuf> = imported.frames.iter().map(|f| &f.files.image).collect();
    anyhow::ensure!(
        frames.iter().collect::<Vec<_>>() == paired,
        "{}: the folder's images in natural order are not exactly the paired ViSP images, so a folder camera would pair them wrongly; no cell config written",
        folder.display()
    );
    let setup = imported.dataset.setup;
    // Nominal transforms from a quick solve (they only feed the plan report of a recorded cell).
    let (camera_mount, target_mount) = match handeye_solve::solve(
        setup,
        &imported.dataset.pairs,
        &handeye_solve::SolveOptions::default(),
    ) {
        Ok(c) => (c.camera_mount, c.target_mount),
        Err(_) => (
            handeye_core::geometry::Pose::identity(),
            handeye_core::geometry::Pose::identity(),
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
            // ViSP's robot poses are in the arm's base, named as the controller does.
            frames: handeye_core::setup::RobotFrames::default(),
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
pub(super) fn run(args: ImportArgs) -> anyhow::Result<()> {
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
                            Some(r) if r > handeye_vision::pnp::AMBIGUITY_WARN_RATIO =>
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
                    handeye_core::atomic_file::write_atomic(cell_out, text.as_bytes())
                        .with_context(|| format!("writing {}", cell_out.display()))
                })?;
                outln!("wrote a recorded-cell config to {}", cell_out.display());
            }
            outputs.commit();
            Ok(())
        }
        ImportFormat::Bag(a) => import_bag(a),
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
