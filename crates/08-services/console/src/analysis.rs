//! The console's analysis thread: after each recorded pose it reads the pose's record and frame
//! back from the session folder (the run never waits for it), keeps the coverage (corners over a
//! 4x4 grid of the image, relative-rotation axes, board distances), solves the running estimate
//! in pose space with its 1-sigma, and renders the latest frame — detected corners in green, the
//! board reprojected at the current estimate in red — as a downscaled JPEG.
//!
//! Jobs queue on a channel and are coalesced: when the run is ahead, one batch updates the
//! coverage for every pose in it and renders only the newest frame.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{mpsc, Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use image::GrayImage;
use nalgebra::Point2;

use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::{relative_rotation_axis, Pose, MIN_AXIS_ANGLE_RAD};
use handeye_core::setup::{predict, PosePair, Setup};
use handeye_records::PoseVisit;
use handeye_session::SharedFrame;
use handeye_solve::{solve, Calibration, SolveOptions};
use handeye_vision::{annotate, draw, Target};

use super::events::{ConsoleEvent, PoseView, SigmaView};
use super::Publisher;

/// At most one frame per this: a person watching needs no more, and the run keeps the CPU.
const FRAME_EVERY: Duration = Duration::from_millis(1000);
/// At most one running estimate per this.
const SOLVE_EVERY: Duration = Duration::from_millis(1000);
/// Width of the frames sent to the page, px (larger frames are scaled down).
const FRAME_WIDTH: u32 = 640;
/// JPEG quality of those frames.
const JPEG_QUALITY: u8 = 70;
/// Relative-rotation axes kept for the sphere view (the newest).
const MAX_AXES: usize = 400;
/// Earlier poses each new pose is paired with for the axes.
const AXIS_PAIRS: usize = 24;

/// What the analysis needs to know of the cell.
#[derive(Clone)]
pub(crate) struct CellView {
    pub setup: Setup,
    pub board: Target,
    pub model: CameraModel,
    pub options: SolveOptions,
    /// The nominal mounts: the reprojection before the first estimate.
    pub nominal: (Pose, Pose),
}

/// Work for the thread.
pub(crate) enum Job {
    /// A pose record was written.
    Recorded(usize),
    /// A live view (manual sessions): the frame and the flange pose it was taken at.
    Preview(Arc<GrayImage>, Pose),
}

/// The newest recorded frame as the run took it, by plan index: rendered from memory rather than
/// decoded back from its PNG (the costly part). One slot, so frames never pile up in a queue
/// when the thread falls behind.
type FrameSlot = Arc<Mutex<Option<(usize, Arc<GrayImage>)>>>;

/// The thread and the way to it. Dropping it lets the thread finish its queue and joins it.
pub(crate) struct Analyst {
    jobs: Option<mpsc::Sender<Job>>,
    latest: FrameSlot,
    thread: Option<JoinHandle<()>>,
}

impl Analyst {
    /// Starts the thread for the session folder at `root`.
    pub(super) fn start(cell: CellView, root: PathBuf, publisher: Publisher) -> Analyst {
        let (jobs, rx) = mpsc::channel();
        let latest = FrameSlot::default();
        let slot = latest.clone();
        let thread = std::thread::Builder::new()
            .name("console-analysis".into())
            .spawn(move || {
                lower_priority();
                let mut state = State::new(cell, root, slot);
                let mut pending_frame: Option<FrameSource> = None;
                let mut pending_solve = false;
                let mut last_frame: Option<Instant> = None;
                let mut last_solve: Option<Instant> = None;
                loop {
                    let due = |last: Option<Instant>, every: Duration| {
                        last.map_or(Duration::ZERO, |t| every.saturating_sub(t.elapsed()))
                    };
                    let wait = match (pending_frame.is_some(), pending_solve) {
                        (false, false) => Duration::from_secs(3600),
                        (frame, solve) => {
                            let f = if frame {
                                due(last_frame, FRAME_EVERY)
                            } else {
                                Duration::MAX
                            };
                            let s = if solve {
                                due(last_solve, SOLVE_EVERY)
                            } else {
                                Duration::MAX
                            };
                            f.min(s)
                        }
                    };
                    let ended = match rx.recv_timeout(wait) {
                        Ok(job) => {
                            let batch: Vec<Job> =
                                std::iter::once(job).chain(rx.try_iter()).collect();
                            let (changed, newest) = state.ingest(batch);
                            if changed {
                                state.publish_coverage(&publisher);
                                pending_solve = true;
                            }
                            if newest.is_some() {
                                pending_frame = newest;
                            }
                            false
                        }
                        Err(mpsc::RecvTimeoutError::Timeout) => false,
                        Err(mpsc::RecvTimeoutError::Disconnected) => true,
                    };
                    // Rate limits keep this best-effort work small next to the run's; at the end
                    // whatever is pending is done at once.
                    if pending_solve && (ended || due(last_solve, SOLVE_EVERY).is_zero()) {
                        state.solve(&publisher);
                        pending_solve = false;
                        last_solve = Some(Instant::now());
                    }
                    // A frame for nobody is not rendered (decoding and encoding are the
                    // costly part); a page that connects later gets the next one.
                    if !publisher.watched() {
                        pending_frame = None;
                    }
                    if pending_frame.is_some() && (ended || due(last_frame, FRAME_EVERY).is_zero())
                    {
                        if let Some(jpeg) =
                            pending_frame.take().and_then(|f| state.render_source(f))
                        {
                            publisher.set_frame(jpeg);
                        }
                        last_frame = Some(Instant::now());
                    }
                    if ended {
                        break;
                    }
                }
            });
        match thread {
            Ok(thread) => Analyst {
                jobs: Some(jobs),
                latest,
                thread: Some(thread),
            },
            Err(e) => {
                // The run goes on without live frames.
                tracing::warn!("console: no analysis thread: {e}");
                Analyst {
                    jobs: None,
                    latest,
                    thread: None,
                }
            }
        }
    }

    /// A pose was recorded, with the frame as taken.
    pub(super) fn recorded(&self, index: usize, frame: &SharedFrame) {
        *self.latest.lock().unwrap_or_else(|e| e.into_inner()) = Some((index, frame.0.clone()));
        self.send(Job::Recorded(index));
    }

    /// Queues a job (never blocks).
    pub(super) fn send(&self, job: Job) {
        if let Some(jobs) = &self.jobs {
            let _ = jobs.send(job);
        }
    }
}

impl Drop for Analyst {
    fn drop(&mut self) {
        self.jobs.take();
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The frame to show next.
enum FrameSource {
    /// A recorded frame (plan index, file), its flange pose and its detected corners.
    File(usize, PathBuf, Pose, Vec<Point2<f64>>),
    /// A live view and its flange pose.
    Image(Arc<GrayImage>, Pose),
}

/// Makes the calling thread yield the CPU to the run's threads (Linux: its nice value 10 above
/// the process's, so it stays below the run's however the process was started); the console's
/// work is best-effort.
fn lower_priority() {
    // `None` is `who` 0: on Linux the calling thread alone. A failure just leaves the priority
    // as it was.
    #[cfg(target_os = "linux")]
    if let Ok(now) = rustix::process::getpriority_process(None) {
        let _ = rustix::process::setpriority_process(None, (now + 10).clamp(10, 19));
    }
}

struct Sample {
    base_from_flange: Pose,
    /// The solver's sample (its view's precision with it), when the board pose was accepted.
    pair: Option<PosePair>,
}

struct State {
    cell: CellView,
    root: PathBuf,
    latest: FrameSlot,
    accepted: BTreeMap<usize, Sample>,
    cells: [u32; 16],
    axes: Vec<[f64; 3]>,
    distance: Option<[f64; 2]>,
    estimate: Option<(Pose, Pose)>,
}

impl State {
    fn new(cell: CellView, root: PathBuf, latest: FrameSlot) -> State {
        State {
            cell,
            root,
            latest,
            accepted: BTreeMap::new(),
            cells: [0; 16],
            axes: Vec::new(),
            distance: None,
            estimate: None,
        }
    }

    /// Takes in a batch of jobs: whether the accepted samples changed, and the newest frame.
    fn ingest(&mut self, batch: Vec<Job>) -> (bool, Option<FrameSource>) {
        let mut changed = false;
        let mut newest: Option<FrameSource> = None;
        for job in batch {
            match job {
                Job::Recorded(index) => {
                    let file = self
                        .root
                        .join(handeye_records::SessionFolder::visit_name(index));
                    let visit: PoseVisit = match handeye_core::yaml_file::read_yaml(&file) {
                        Ok(visit) => visit,
                        Err(e) => {
                            tracing::warn!("console: {e}");
                            continue;
                        }
                    };
                    let corners: Vec<Point2<f64>> =
                        visit.corners_px.iter().map(|c| c.pixel).collect();
                    if visit.rejected.is_none() {
                        self.add(index, &corners, visit.base_from_flange, visit.sample());
                        changed = true;
                    }
                    // Decoding a frame costs more than the rest: only the newest is read.
                    newest = Some(FrameSource::File(
                        index,
                        self.root.join(&visit.frame),
                        visit.base_from_flange,
                        corners,
                    ));
                }
                Job::Preview(image, base_from_flange) => {
                    newest = Some(FrameSource::Image(image, base_from_flange));
                }
            }
        }
        (changed, newest)
    }

    fn publish_coverage(&self, publisher: &Publisher) {
        publisher.publish(&ConsoleEvent::Coverage {
            cells: self.cells,
            axes: self.axes.clone(),
            distance_m: self.distance,
        });
    }

    /// The JPEG of a frame to show.
    fn render_source(&self, source: FrameSource) -> Option<Vec<u8>> {
        match source {
            FrameSource::Image(image, base_from_flange) => {
                self.render(&image, &base_from_flange, &[])
            }
            FrameSource::File(index, path, base_from_flange, corners) => {
                let shared = self
                    .latest
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .as_ref()
                    .and_then(|(i, image)| (*i == index).then(|| image.clone()));
                if let Some(image) = shared {
                    return self.render(&image, &base_from_flange, &corners);
                }
                // A pose recorded before a resume: read back from its file.
                match image::open(&path) {
                    Ok(decoded) => self.render(&decoded.into_luma8(), &base_from_flange, &corners),
                    Err(e) => {
                        tracing::warn!("console: frame {}: {e}", path.display());
                        None
                    }
                }
            }
        }
    }

    fn add(
        &mut self,
        index: usize,
        corners: &[Point2<f64>],
        base_from_flange: Pose,
        pair: Option<PosePair>,
    ) {
        let (w, h) = (self.cell.model.width as f64, self.cell.model.height as f64);
        for c in corners {
            let col = ((c.x / w * 4.0).floor() as i64).clamp(0, 3) as usize;
            let row = ((c.y / h * 4.0).floor() as i64).clamp(0, 3) as usize;
            self.cells[row * 4 + col] += 1;
        }
        for earlier in self.accepted.values().rev().take(AXIS_PAIRS) {
            if let Some((axis, _)) = relative_rotation_axis(
                &earlier.base_from_flange.rotation,
                &base_from_flange.rotation,
                MIN_AXIS_ANGLE_RAD,
            ) {
                self.axes.push(axis.into());
            }
        }
        if self.axes.len() > MAX_AXES {
            let excess = self.axes.len() - MAX_AXES;
            self.axes.drain(..excess);
        }
        if let Some(c) = pair.as_ref().map(|p| &p.camera_from_target) {
            let d = c.translation.vector.norm();
            self.distance = Some(match self.distance {
                Some([lo, hi]) => [lo.min(d), hi.max(d)],
                None => [d, d],
            });
        }
        self.accepted.insert(
            index,
            Sample {
                base_from_flange,
                pair,
            },
        );
    }

    /// The running estimate of the accepted samples and how many there are: the run's samples as
    /// the run's solve weighs them (each view at its precision). None below three samples or
    /// when the solve refuses them.
    fn estimate(&self) -> Option<(Calibration, usize)> {
        let pairs: Vec<PosePair> = self
            .accepted
            .values()
            .filter_map(|s| s.pair.clone())
            .collect();
        if pairs.len() < 3 {
            return None;
        }
        let calibration = solve(self.cell.setup, &pairs, &self.cell.options).ok()?;
        Some((calibration, pairs.len()))
    }

    fn solve(&mut self, publisher: &Publisher) {
        let Some((calibration, samples)) = self.estimate() else {
            return;
        };
        self.estimate = Some((calibration.camera_mount, calibration.target_mount));
        publisher.publish(&ConsoleEvent::Estimate {
            samples,
            camera_mount: PoseView::of(&calibration.camera_mount),
            target_mount: PoseView::of(&calibration.target_mount),
            sigma: calibration.uncertainty.as_ref().map(|u| SigmaView {
                camera_mount_mm: u.camera_mount.translation_mm,
                camera_mount_deg: u.camera_mount.rotation_deg,
                target_mount_mm: u.target_mount.translation_mm,
                target_mount_deg: u.target_mount.rotation_deg,
            }),
        });
    }

    /// The frame, scaled down, with the detected corners and the board as the current estimate
    /// (or the nominal cell, before one) predicts it, as the report draws its frames
    /// (`annotate::prediction`).
    fn render(
        &self,
        image: &GrayImage,
        base_from_flange: &Pose,
        corners: &[Point2<f64>],
    ) -> Option<Vec<u8>> {
        let (camera_mount, target_mount) = self.estimate.unwrap_or(self.cell.nominal);
        let camera_from_target = predict(
            self.cell.setup,
            &camera_mount,
            &target_mount,
            base_from_flange,
        );
        let out = annotate::prediction(
            image,
            FRAME_WIDTH,
            &self.cell.board,
            &self.cell.model,
            &camera_from_target,
            corners.iter().copied(),
        )
        .ok()?;
        draw::jpeg(&out, JPEG_QUALITY).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_core::geometry::pose_from_rotvec;
    use handeye_core::setup::ViewSigma;
    use nalgebra::Vector3;
    use std::path::Path;

    fn configs() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../configs")
    }

    /// The console's running estimate is the run's pose-space answer of the same records: each
    /// view weighed by its recorded precision (a far view's noisy board pose counts for less),
    /// not every view alike.
    #[test]
    fn the_running_estimate_weighs_each_view_as_the_run_does() {
        let root = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(root.path().join("poses")).unwrap();
        let (camera_mount, target_mount) = (
            pose_from_rotvec(
                Vector3::new(0.03, -0.07, 0.04),
                Vector3::new(0.0, 0.0, 1.57),
            ),
            pose_from_rotvec(Vector3::new(0.5, -0.15, 0.0), Vector3::new(0.0, 0.0, 0.3)),
        );
        let mut pairs = Vec::new();
        for i in 0..10 {
            let a = i as f64;
            let flange = pose_from_rotvec(
                Vector3::new(0.45 + 0.02 * a, -0.1 + 0.015 * a, 0.6 + 0.01 * (a % 3.0)),
                Vector3::new(3.0 + 0.08 * (a % 4.0), 0.25 * (a % 3.0) - 0.25, 0.3 * a),
            );
            // Two far views, their board poses eight times noisier, and recorded so.
            let k = if i % 5 == 4 { 8.0 } else { 1.0 };
            let noise = pose_from_rotvec(
                Vector3::new(0.2, -0.3, 0.25) * (k * 1e-4 * (a - 4.5).signum()),
                Vector3::new(-0.3, 0.2, 0.1) * (k * 1e-4),
            );
            let seen = predict(Setup::EyeInHand, &camera_mount, &target_mount, &flange) * noise;
            let mut visit = PoseVisit::new(i, &flange, PathBuf::from(format!("frames/{i:03}.png")));
            visit.camera_from_target = Some(seen);
            visit.view_sigma = Some(ViewSigma {
                rotation_deg: 0.01 * k,
                translation_mm: 0.2 * k,
            });
            handeye_core::yaml_file::write_yaml(
                &visit,
                &root
                    .path()
                    .join(handeye_records::SessionFolder::visit_name(i)),
            )
            .unwrap();
            pairs.push(visit.sample().unwrap());
        }
        let options = SolveOptions {
            drop_outliers: false,
            ..SolveOptions::default()
        };
        let cell = CellView {
            setup: Setup::EyeInHand,
            board: Target::load(&configs().join("targets/aprilgrid-6x6.yaml")).unwrap(),
            model: CameraModel::load(&configs().join("cameras/sim-1280x720.yaml")).unwrap(),
            options: options.clone(),
            nominal: (camera_mount, target_mount),
        };
        let mut state = State::new(cell, root.path().to_path_buf(), FrameSlot::default());
        let (changed, _) = state.ingest((0..10).map(Job::Recorded).collect());
        assert!(changed);
        let (estimate, samples) = state.estimate().unwrap();
        assert_eq!(samples, 10);
        let run = solve(Setup::EyeInHand, &pairs, &options).unwrap();
        assert_eq!(estimate.camera_mount, run.camera_mount);
        assert_eq!(estimate.target_mount, run.target_mount);
        let every_view_alike = SolveOptions {
            weigh_views: false,
            ..options
        };
        let alike = solve(Setup::EyeInHand, &pairs, &every_view_alike).unwrap();
        let moved =
            (alike.camera_mount.translation.vector - run.camera_mount.translation.vector).norm();
        assert!(moved > 1e-6, "the far views change nothing: {moved} m");
    }
}
