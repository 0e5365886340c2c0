//! The session folder: everything a run records, written as it is taken so a crash loses nothing.
//!
//! ```text
//! <session>/
//!   .lock               the PID of the process running the session (see `lock`)
//!   session.yaml        what was run: config file, setup, the resolved plan (joints and poses),
//!                       the sha256 of every input file
//!   poses/007.yaml      one record per visited plan pose: measured T_base_flange, detection, board pose
//!   frames/007.png      the frame grabbed at that pose
//!   previews/007.jpg    that frame as a page shows it (grey JPEG, shrunk by a whole factor to
//!                       at most 960 px wide), made where the frame was in memory for detection
//!                       so the report does not decode it again
//!                       (the first `annotate::MAX_FRAMES_SHOWN` poses, as many as a page shows)
//!   samples.yaml        the solver's dataset (only poses whose board pose was accepted), id "pose-007"
//!                       (without intrinsics: written by the solve, board poses by PnP with the
//!                       estimated camera_info.yaml)
//!   result.yaml         the calibration, when solved
//! ```
//! Every file is written with [`write_atomic`], so a reader never sees half a file.
//!
//! The folder is a small write-ahead log. A pose is committed by its record `poses/NNN.yaml`
//! (written after its frame); `samples.yaml` is derived data, rewritten after each accepted
//! pose and rebuilt from the committed records whenever a run starts or resumes, so a crash
//! between a record and the samples file (or a full disk then) loses nothing and doubles
//! nothing. Records are checked when read: the file name, the `plan_index` inside it and the
//! plan in `session.yaml` must agree, and each pose must be a valid rigid transform.
//!
//! Creating or resuming a session takes the folder's lock and removes the temporary files a
//! killed writer left behind. Depends on `dataset`, `geometry`, `robot` (joint type), `vision`
//! (the board a record's corners are checked against) and the ground floor.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use handeye_core::atomic_file::{
    is_temp_name, remove_stale_temp_files, write_atomic, RemovedTemp, TempScope,
};
use handeye_core::geometry::{serde_pose, Pose};
use handeye_core::notice::Notice;
use handeye_core::setup::{CornerObservation, PosePair, Setup, ViewSigma};
use handeye_core::yaml_file::{read_yaml, symlink_loop, write_yaml};
use handeye_robot::{Joints, MAX_JOINTS};

/// A solved session's answer, at its root (one camera's or a several-camera cell's: read it
/// with [`CellResult::load`](crate::result::CellResult::load)).
pub const RESULT_FILE: &str = "result.yaml";
use handeye_vision::Target;

/// Where a growing plan keeps the rejected records whose index the next pose reuses.
const REJECTED_DIR: &str = "rejected";

use super::inputs::InputFile;
use super::lock::{live_run, LiveRun, SessionLock, LOCK_FILE};
use handeye_core::yaml_file::SchemaVersion;

use super::SessionError;

/// What the session is running, written once at the start; `--resume` reads it back.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionManifest {
    /// The layout version of this file ([`SchemaVersion`]; absent in files written before it).
    #[serde(default = "SchemaVersion::unversioned")]
    pub schema_version: SchemaVersion,
    /// The cell config the session was started with.
    pub config: PathBuf,
    /// Eye-in-hand or eye-to-hand.
    pub setup: Setup,
    /// The validated plan, in visiting order.
    pub plan: Vec<PlannedPose>,
    /// The input files (config, board, intrinsics, plan) with the sha256 of their bytes; a
    /// resume refuses changed inputs. Absent in sessions recorded before hashes were kept.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub inputs: Vec<InputFile>,
    /// A hand-guided session (`handeye console`, `plan: manual`): its plan is the captures so
    /// far, and a resume continues it by hand.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub manual: bool,
}

impl SessionManifest {
    /// The manifest of a session of `config` (path) visiting `plan` (flange pose, joints).
    pub fn new(config: PathBuf, setup: Setup, plan: &[(Pose, Joints)]) -> SessionManifest {
        SessionManifest {
            schema_version: SchemaVersion::CURRENT,
            config,
            setup,
            plan: plan
                .iter()
                .map(|(pose, q)| PlannedPose {
                    base_from_flange: *pose,
                    joints_deg: q.iter().map(|v| v.to_degrees()).collect(),
                })
                .collect(),
            inputs: Vec::new(),
            manual: false,
        }
    }

    /// The same manifest recording `inputs` (see [`InputFile`]).
    pub fn with_inputs(mut self, inputs: Vec<InputFile>) -> SessionManifest {
        self.inputs = inputs;
        self
    }

    /// The same manifest marked as a hand-guided session.
    pub fn hand_guided(mut self) -> SessionManifest {
        self.manual = true;
        self
    }
}

/// One validated plan pose: where the flange goes and the joints that reach it.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannedPose {
    /// Target flange pose.
    #[serde(rename = "T_base_flange", with = "serde_pose")]
    pub base_from_flange: Pose,
    /// The joint solution the arm moves to, degrees, base joint first (six on a UR, up to
    /// seven on an arm driven over ROS 2).
    #[serde(deserialize_with = "joint_angles")]
    pub joints_deg: Vec<f64>,
}

impl PlannedPose {
    /// The joints, radians.
    pub fn joints(&self) -> Joints {
        Joints::from_fn(self.joints_deg.len(), |i| self.joints_deg[i].to_radians())
    }
}

/// `joints_deg`: one to [`MAX_JOINTS`] finite angles.
fn joint_angles<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
    let angles = Vec::<f64>::deserialize(d)?;
    if !(1..=MAX_JOINTS).contains(&angles.len()) {
        return Err(serde::de::Error::invalid_length(
            angles.len(),
            &"one to seven joint angles",
        ));
    }
    if angles.iter().any(|a| !a.is_finite()) {
        return Err(serde::de::Error::custom("a joint angle is not finite"));
    }
    Ok(angles)
}

/// What happened at one plan pose.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseVisit {
    /// The layout version of this file ([`SchemaVersion`]; absent in files written before it).
    #[serde(default = "SchemaVersion::unversioned")]
    pub schema_version: SchemaVersion,
    /// Index in the plan.
    pub plan_index: usize,
    /// The flange pose the robot reported after settling.
    #[serde(rename = "T_base_flange", with = "serde_pose")]
    pub base_from_flange: Pose,
    /// The frame, relative to the session folder.
    pub frame: PathBuf,
    /// Board pose in the camera, when the board was found and accepted.
    #[serde(
        rename = "T_camera_target",
        with = "serde_pose::option",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub camera_from_target: Option<Pose>,
    /// Board reprojection RMS, px.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reprojection_rms_px: Option<f64>,
    /// How precisely the view fixes the board pose (the 1-sigma of its board pose); absent in
    /// records written before it, whose samples then count as typical views. Checked when read.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub view_sigma: Option<ViewSigma>,
    /// Tags used for the board pose.
    #[serde(default)]
    pub tags: usize,
    /// Detected corners, each `[tag id, corner index, u, v]` in the file (pixels, OpenCV
    /// convention); checked when read.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub corners_px: Vec<CornerObservation>,
    /// Why the pose gave no sample, if it did not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rejected: Option<String>,
}

/// Paths of one session folder, and — when created or resumed for a run — its lock, held until
/// the last clone is dropped.
#[derive(Debug, Clone)]
pub struct SessionFolder {
    root: PathBuf,
    /// Where the folder will be once its writer moves it there (an import's staging folder is
    /// renamed into place at the end): the path the result's advice names.
    shown_as: Option<PathBuf>,
    lock: Option<Arc<SessionLock>>,
    /// The run recording the folder when it was opened to read (see [`SessionFolder::open`]).
    live: Option<LiveRun>,
    notes: Vec<String>,
}

/// A new session folder's default path: `parent/<prefix>YYYY-MM-DD_HH-MM-SS` of `now` in UTC,
/// with `-2`, `-3`, ... appended when a folder of that name exists already.
pub fn dated_session_path(parent: &Path, prefix: &str, now: std::time::SystemTime) -> PathBuf {
    // humantime's RFC 3339 form `YYYY-MM-DDTHH:MM:SSZ`, made safe for a folder name.
    let stamp = humantime::format_rfc3339_seconds(now)
        .to_string()
        .trim_end_matches('Z')
        .replace('T', "_")
        .replace(':', "-");
    let name = format!("{prefix}{stamp}");
    let first = parent.join(&name);
    if !first.exists() {
        return first;
    }
    (2u32..)
        .map(|n| parent.join(format!("{name}-{n}")))
        .find(|p| !p.exists())
        .unwrap_or(first)
}

impl SessionFolder {
    /// Creates a new session folder and takes its lock. The folder may exist when it holds
    /// nothing of a session: empty, or what a run killed before writing `session.yaml` left
    /// (its lock, empty [`RECORD_FOLDERS`], temporary files).
    pub fn create(root: &Path) -> Result<SessionFolder, SessionError> {
        if holds_a_session(root)? {
            return Err(SessionError::FolderExists(root.to_path_buf()));
        }
        crate::create_dir(root)?;
        let folder = SessionFolder::locked(root)?;
        // Another run may have started in it between the first look and the lock.
        if holds_a_session(root)? {
            return Err(SessionError::FolderExists(root.to_path_buf()));
        }
        for sub in RECORD_FOLDERS {
            crate::create_dir(&root.join(sub))?;
        }
        Ok(folder)
    }

    /// Opens an existing session folder to read it (no lock). A run recording it is looked for
    /// first ([`live_run`]): before its first pose (no `session.yaml` yet) that is the error
    /// ([`SessionError::Recording`]: there is nothing to read, and nothing was left unfinished);
    /// after it, the folder opens and [`SessionFolder::live_run`] names the run, so what is read
    /// is said to be provisional.
    pub fn open(root: &Path) -> Result<SessionFolder, SessionError> {
        // The lock this process holds is its own run's (a run solving its folder at the end).
        let live = live_run(root)?.filter(|run| run.pid != Some(std::process::id()));
        if !root.join("session.yaml").is_file() {
            return Err(match live {
                Some(run) => SessionError::Recording {
                    run,
                    next: "it writes session.yaml before its first pose: nothing to read yet"
                        .to_string(),
                },
                None => SessionError::NotASession(root.to_path_buf()),
            });
        }
        Ok(SessionFolder {
            root: root.to_path_buf(),
            shown_as: None,
            lock: None,
            live,
            notes: Vec::new(),
        })
    }

    /// The run that was recording the folder when it was opened to read, if one was: what is
    /// read is the poses so far, and the run will add to them.
    pub fn live_run(&self) -> Option<&LiveRun> {
        self.live.as_ref()
    }

    /// Opens an existing session folder to continue it: takes its lock (refused while another
    /// process holds it; taken over, with a note, from a process that died) and removes the
    /// temporary files a killed run left behind.
    pub fn resume(root: &Path) -> Result<SessionFolder, SessionError> {
        if !root.is_dir() {
            return Err(SessionError::NotASession(root.to_path_buf()));
        }
        let folder = SessionFolder::locked(root)?;
        if !root.join("session.yaml").is_file() {
            return Err(SessionError::NotASession(root.to_path_buf()));
        }
        Ok(folder)
    }

    fn locked(root: &Path) -> Result<SessionFolder, SessionError> {
        let lock = SessionLock::acquire(root)?;
        let mut notes = Vec::new();
        if let Some(pid) = lock.stale_owner() {
            notes.push(format!(
                "{}: took over the lock of process {pid}, which ended without releasing it",
                lock.path().display()
            ));
        }
        let removed = remove_temp_files(root);
        if !removed.is_empty() {
            let bytes: u64 = removed.iter().map(|r| r.bytes).sum();
            let names: Vec<String> = removed
                .iter()
                .map(|r| {
                    r.path
                        .strip_prefix(root)
                        .unwrap_or(&r.path)
                        .display()
                        .to_string()
                })
                .collect();
            notes.push(format!(
                "{}: removed {} unfinished temporary file(s) ({:.0} kB) a killed run left behind: {}",
                root.display(),
                removed.len(),
                bytes as f64 / 1000.0,
                names.join(", ")
            ));
        }
        Ok(SessionFolder {
            root: root.to_path_buf(),
            shown_as: None,
            lock: Some(Arc::new(lock)),
            live: None,
            notes,
        })
    }

    /// What taking the folder over involved (a stale lock taken over, temporary files removed),
    /// for people to read.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Whether this handle holds the folder's lock.
    pub fn is_locked(&self) -> bool {
        self.lock.is_some()
    }

    /// The folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The same folder, to be moved to `path` by its writer when the run is done (a staging
    /// folder): what the session writes for people to act on (the verdict's advice, the
    /// summary) names `path`, and every file is still written under [`SessionFolder::root`].
    pub fn to_be_moved_to(mut self, path: &Path) -> SessionFolder {
        self.shown_as = Some(path.to_path_buf());
        self
    }

    /// Where the folder is for a person reading the result: [`SessionFolder::root`], or the
    /// path given to [`SessionFolder::to_be_moved_to`].
    pub fn shown_root(&self) -> &Path {
        self.shown_as.as_deref().unwrap_or(&self.root)
    }

    /// Where a person finds `path`: a file inside the folder under [`SessionFolder::shown_root`],
    /// any other as it is.
    pub fn shown(&self, path: &Path) -> PathBuf {
        match (&self.shown_as, path.strip_prefix(&self.root)) {
            (Some(shown), Ok(inside)) => shown.join(inside),
            _ => path.to_path_buf(),
        }
    }

    /// `session.yaml`.
    pub fn manifest_path(&self) -> PathBuf {
        self.root.join("session.yaml")
    }

    /// `samples.yaml`.
    pub fn samples_path(&self) -> PathBuf {
        self.root.join("samples.yaml")
    }

    /// `result.yaml`.
    pub fn result_path(&self) -> PathBuf {
        self.root.join(RESULT_FILE)
    }

    /// `import/notices.yaml`: what the session's input said about itself that its data do not
    /// show (a bag's tolerated lies, issue #40), written by the import before the run.
    pub fn input_notices_path(&self) -> PathBuf {
        self.root.join("import").join("notices.yaml")
    }

    /// Writes the notices the session's input carried ([`Self::input_notices_path`]); every
    /// solve of the session adds them to its answer's.
    pub fn save_input_notices(&self, notices: &[Notice]) -> Result<(), SessionError> {
        let path = self.input_notices_path();
        if let Some(dir) = path.parent() {
            crate::create_dir(dir)?;
        }
        self.write_yaml(&path, &notices)
    }

    /// The notices the session's input carried: none when the file is absent (a session not
    /// imported, or imported before it existed).
    pub fn input_notices(&self) -> Result<Vec<Notice>, SessionError> {
        let path = self.input_notices_path();
        if path.is_file() {
            self.read_yaml(&path)
        } else {
            Ok(Vec::new())
        }
    }

    /// Frame file of a plan pose, relative to the session folder.
    pub fn frame_name(plan_index: usize) -> PathBuf {
        PathBuf::from(format!("frames/{plan_index:03}.png"))
    }

    /// The preview of a frame file (`frames/007.png` → `previews/007.jpg`, beside `frames/` in
    /// the session or camera folder the frame is in); `None` for a name that is no frame file.
    pub fn preview_of(frame: &Path) -> Option<PathBuf> {
        let folder = frame.parent()?;
        if folder.file_name()? != "frames" {
            return None;
        }
        let stem = frame.file_stem()?;
        Some(
            folder
                .with_file_name("previews")
                .join(stem)
                .with_extension("jpg"),
        )
    }

    /// Writes the preview of the frame `frame_name` ([`Self::preview_of`]; `previews/` made when
    /// a session recorded before previews is resumed).
    pub fn write_preview(&self, frame_name: &Path, jpeg: &[u8]) -> Result<(), SessionError> {
        let Some(name) = Self::preview_of(frame_name) else {
            return Ok(());
        };
        if let Some(folder) = name.parent() {
            crate::create_dir(&self.root.join(folder))?;
        }
        self.write_file(&name, jpeg)
    }

    /// Record file of a plan pose, relative to the session folder.
    pub fn visit_name(plan_index: usize) -> PathBuf {
        PathBuf::from(format!("poses/{plan_index:03}.yaml"))
    }

    /// Record file of a plan pose in this folder.
    pub fn visit_path(&self, plan_index: usize) -> PathBuf {
        self.root.join(Self::visit_name(plan_index))
    }

    /// Writes the manifest.
    pub fn write_manifest(&self, manifest: &SessionManifest) -> Result<(), SessionError> {
        self.write_yaml(&self.manifest_path(), manifest)
    }

    /// Reads the manifest.
    pub fn read_manifest(&self) -> Result<SessionManifest, SessionError> {
        self.read_yaml(&self.manifest_path())
    }

    /// Records one visit.
    pub fn write_visit(&self, visit: &PoseVisit) -> Result<(), SessionError> {
        self.write_yaml(&self.visit_path(visit.plan_index), visit)
    }

    /// Keeps the rejected record of plan pose `plan_index` of a growing plan (adaptive,
    /// hand-guided) whose index the next pose reuses: copied to `rejected/NNN.yaml` (numbered in
    /// order), so the corners it saw still count when the session is checked for intrinsics that
    /// do not fit the frames (issue #38: an adaptive run whose every pose was rejected for its
    /// board reprojection kept one record, too few to estimate the lens from). Its frame is
    /// not kept (the next pose's overwrites it).
    pub fn keep_rejected_visit(&self, plan_index: usize) -> Result<(), SessionError> {
        let visit: PoseVisit = self.read_yaml(&self.visit_path(plan_index))?;
        let folder = self.root.join(REJECTED_DIR);
        crate::create_dir(&folder)?;
        let serial = std::fs::read_dir(&folder)
            .map_err(|source| SessionError::Io {
                path: folder.clone(),
                source,
            })?
            .filter(|e| {
                e.as_ref()
                    .is_ok_and(|e| e.path().extension().is_some_and(|x| x == "yaml"))
            })
            .count();
        self.write_yaml(&folder.join(format!("{serial:03}.yaml")), &visit)
    }

    /// The rejected records [`SessionFolder::keep_rejected_visit`] kept, in order (none for a
    /// fixed plan: its rejected records stay in `poses/`).
    pub fn read_rejected_visits(&self) -> Result<Vec<PoseVisit>, SessionError> {
        let folder = self.root.join(REJECTED_DIR);
        let Ok(entries) = std::fs::read_dir(&folder) else {
            return Ok(Vec::new());
        };
        let mut files: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "yaml"))
            .collect();
        files.sort();
        files
            .iter()
            .map(|file| {
                let visit: PoseVisit = self.read_yaml(file)?;
                visit.check_corners_unique(file)?;
                Ok(visit)
            })
            .collect()
    }

    /// All committed visits, in plan order, each checked: its file name, its `plan_index` and
    /// the plan in `session.yaml` (when there is one) agree, no plan pose has two records, its
    /// poses are valid transforms and its frame is on disk. An error names the record file.
    pub fn read_visits(&self) -> Result<Vec<PoseVisit>, SessionError> {
        let plan_len = if self.manifest_path().is_file() {
            Some(self.read_manifest()?.plan.len())
        } else {
            None
        };
        let folder = self.root.join("poses");
        let mut files: Vec<PathBuf> = match std::fs::read_dir(&folder) {
            Ok(entries) => entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "yaml"))
                .collect(),
            Err(source) => {
                return Err(SessionError::Io {
                    path: folder,
                    source,
                })
            }
        };
        files.sort();
        let mut visits: BTreeMap<usize, (PathBuf, PoseVisit)> = BTreeMap::new();
        for file in files {
            let record = |message: String| SessionError::Record {
                file: file.clone(),
                path: "plan_index".into(),
                message,
            };
            let visit: PoseVisit = self.read_yaml(&file)?;
            let named = file
                .file_stem()
                .and_then(|s| s.to_str())
                .and_then(|s| s.parse::<usize>().ok());
            if named != Some(visit.plan_index) {
                return Err(record(format!(
                    "{} does not match the record's file name (poses/NNN.yaml holds plan pose NNN)",
                    visit.plan_index
                )));
            }
            if let Some(len) = plan_len.filter(|len| visit.plan_index >= *len) {
                return Err(record(format!(
                    "{} is not a pose of the session's plan (session.yaml lists {len} poses, 0 to {})",
                    visit.plan_index,
                    len.saturating_sub(1)
                )));
            }
            visit.check_corners_unique(&file)?;
            let frame = self.root.join(&visit.frame);
            if !frame.is_file() {
                let message = match symlink_loop(&frame) {
                    Some(at) => format!(
                        "{}: symlink loop at {}",
                        visit.frame.display(),
                        at.display()
                    ),
                    None => format!("{} is not in the session folder", visit.frame.display()),
                };
                return Err(SessionError::Record {
                    file: file.clone(),
                    path: "frame".into(),
                    message,
                });
            }
            if let Some((other, _)) = visits.get(&visit.plan_index) {
                return Err(record(format!(
                    "{} is recorded twice, also in {}",
                    visit.plan_index,
                    other.display()
                )));
            }
            visits.insert(visit.plan_index, (file, visit));
        }
        Ok(visits.into_values().map(|(_, v)| v).collect())
    }

    /// Writes bytes atomically under the session folder.
    pub fn write_file(&self, relative: &Path, bytes: &[u8]) -> Result<(), SessionError> {
        let path = self.root.join(relative);
        write_atomic(&path, bytes).map_err(|source| SessionError::Io { path, source })
    }

    fn write_yaml<T: Serialize>(&self, path: &Path, value: &T) -> Result<(), SessionError> {
        Ok(write_yaml(value, path)?)
    }

    fn read_yaml<T: for<'de> Deserialize<'de>>(&self, path: &Path) -> Result<T, SessionError> {
        Ok(read_yaml(path)?)
    }
}

/// The folders a session's records are written into, made with it.
const RECORD_FOLDERS: [&str; 3] = ["poses", "frames", "previews"];

/// Whether `root` holds anything of a session: anything but its lock file, temporary files and
/// empty [`RECORD_FOLDERS`] (what a run killed before `session.yaml` leaves).
fn holds_a_session(root: &Path) -> Result<bool, SessionError> {
    let entries = match std::fs::read_dir(root) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(false),
        // Not a folder (or unreadable): creating a session in it is refused.
        Err(_) => return Ok(true),
    };
    for entry in entries {
        let entry = entry.map_err(|source| SessionError::Io {
            path: root.to_path_buf(),
            source,
        })?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name == LOCK_FILE || is_temp_name(&name) {
            continue;
        }
        let path = entry.path();
        let empty_sub = RECORD_FOLDERS.contains(&name.as_ref())
            && path.is_dir()
            && std::fs::read_dir(&path).is_ok_and(|mut d| {
                d.all(|e| e.is_ok_and(|e| is_temp_name(&e.file_name().to_string_lossy())))
            });
        if !empty_sub {
            return Ok(true);
        }
    }
    Ok(false)
}

/// Removes the temporary files a killed writer left in the session folder and its
/// [`RECORD_FOLDERS`] (`atomic_file`'s sweep: only files whose writer's lock is gone); returns them. Called with the session's lock held, so earlier versions' unlocked temporary
/// files are a killed run's too.
fn remove_temp_files(root: &Path) -> Vec<RemovedTemp> {
    std::iter::once(root.to_path_buf())
        .chain(RECORD_FOLDERS.iter().map(|sub| root.join(sub)))
        .flat_map(|dir| remove_stale_temp_files(&dir, TempScope::OwnedFolder))
        .collect()
}

impl PoseVisit {
    /// The id of its sample in `samples.yaml` (`pose-NNN`), which ties the sample to the frame
    /// and the record.
    pub fn sample_id(&self) -> String {
        format!("pose-{:03}", self.plan_index)
    }

    /// The solver sample of the visit, when its board pose was accepted: the one form a
    /// recorded pose takes on its way to the solver (driver, replay and resume alike).
    pub fn sample(&self) -> Option<PosePair> {
        let camera_from_target = self.camera_from_target?;
        Some(PosePair {
            id: Some(self.sample_id()),
            view_sigma: self.view_sigma,
            ..PosePair::new(self.base_from_flange, camera_from_target)
        })
    }

    /// A visit with the robot pose and frame recorded and nothing measured yet.
    pub fn new(plan_index: usize, base_from_flange: &Pose, frame: PathBuf) -> Self {
        PoseVisit {
            schema_version: SchemaVersion::CURRENT,
            plan_index,
            base_from_flange: *base_from_flange,
            frame,
            camera_from_target: None,
            reprojection_rms_px: None,
            view_sigma: None,
            tags: 0,
            corners_px: Vec::new(),
            rejected: None,
        }
    }

    /// Refuses a record that lists one board point twice (`[tag id, corner, ..]` repeated): a
    /// detection keeps one observation per point (two tags with one id are dropped as a
    /// reflection or a second board), so a repeat is an edited or foreign record. `file` names
    /// the record in the error.
    pub fn check_corners_unique(&self, file: &Path) -> Result<(), SessionError> {
        let mut seen = std::collections::HashMap::new();
        for (i, c) in self.corners_px.iter().enumerate() {
            if let Some(first) = seen.insert((c.tag_id, c.corner), i) {
                return Err(SessionError::Record {
                    file: file.to_path_buf(),
                    path: format!("corners_px[{i}]"),
                    message: format!(
                        "tag id {} corner {} is recorded twice in this frame (also \
                         corners_px[{first}]): one observation per board point",
                        c.tag_id, c.corner
                    ),
                });
            }
        }
        Ok(())
    }

    /// Refuses a record with a corner the board does not have (a tag id outside the board's
    /// range, or a corner index it lacks), naming the id and the board's valid ids: the
    /// detector records only the board's points, so such a corner means the record belongs to
    /// another board (or was edited), and dropping it would hide that. `file` names the record.
    pub fn check_corners_on_board(&self, file: &Path, board: &Target) -> Result<(), SessionError> {
        for (i, c) in self.corners_px.iter().enumerate() {
            if board.observation_point(c).is_some() {
                continue;
            }
            let points = board.points();
            let low = points.iter().map(|p| p.0).min().unwrap_or(0);
            let high = points.iter().map(|p| p.0).max().unwrap_or(0);
            let corners = points.iter().map(|p| p.1).max().unwrap_or(0);
            let what = if board.aprilgrid().is_some() {
                "tag id"
            } else {
                "corner id"
            };
            return Err(SessionError::Record {
                file: file.to_path_buf(),
                path: format!("corners_px[{i}]"),
                message: format!(
                    "{what} {} corner {} is not on the board ({}: {what}s {low} to {high}, \
                     corners 0 to {corners}); was the session recorded with another board?",
                    c.tag_id,
                    c.corner,
                    board.describe()
                ),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_core::yaml_file::parse_yaml;

    const RECORD: &str = "plan_index: 3\nT_base_flange: {translation: [0.5, 0.0, 0.7], \
        quaternion: {w: 1.0, x: 0.0, y: 0.0, z: 0.0}}\nframe: frames/003.png\n";

    /// A pose record's `view_sigma` weighs its sample; a bad one must not pass for a typical
    /// view without a word.
    #[test]
    fn a_pose_records_view_sigma_is_checked_when_read() {
        let file = Path::new("session/poses/003.yaml");
        let good = format!("{RECORD}view_sigma: {{rotation_deg: 0.01, translation_mm: 0.2}}\n");
        let visit: PoseVisit = parse_yaml(&good, file).unwrap();
        assert_eq!(visit.view_sigma.unwrap().translation_mm, 0.2);
        let absent: PoseVisit = parse_yaml(RECORD, file).unwrap();
        assert!(absent.view_sigma.is_none());
        for bad in [
            "{rotation_deg: 0.01, translation_mm: -0.2}",
            "{rotation_deg: .nan, translation_mm: 0.2}",
            "{rotation_deg: 0.0, translation_mm: 0.2}",
            "{rotation_deg: 0.01}",
        ] {
            let text = format!("{RECORD}view_sigma: {bad}\n");
            let error = parse_yaml::<PoseVisit>(&text, file)
                .unwrap_err()
                .to_string();
            assert!(
                error.contains("session/poses/003.yaml") && error.contains("view_sigma"),
                "{bad}: {error}"
            );
        }
    }
}
