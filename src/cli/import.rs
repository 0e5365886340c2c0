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
    let (camera_key, target_key) = setup.unknown_names();
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
    // The workspace box is not used by a recorded robot; it spans the recorded poses ± 0.5 m.
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for f in &imported.frames {
        let t = f.base_from_flange.translation.vector;
        for k in 0..3 {
            lo[k] = lo[k].min(t[k] - 0.5);
            hi[k] = hi[k].max(t[k] + 0.5);
        }
    }
    let folder = canonical(folder)?;
    let config = ConfigFile {
        setup,
        target: canonical(target)?,
        intrinsics: Some(absolute(camera_info)?),
        robot: RobotConfig::Recorded {
            poses: absolute(poses)?,
            repeatability_mm: None,
            repeatability_deg: None,
        },
        camera: CameraConfig::Files {
            folder: folder.clone(),
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
            decimate: 1.0,
            ..DetectorConfig::default()
        },
        solver: SolverConfig::default(),
        session: SessionConfig::default(),
        verdict: Default::default(),
    };
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
