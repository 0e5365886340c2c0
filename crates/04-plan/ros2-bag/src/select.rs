//! Which frames of the image stream become samples, and at which robot time.
//!
//! The camera and the robot stamp with different clocks: `offset = camera stamp − robot stamp`
//! of the same instant, so an image stamped `t` was taken when TF says `t − offset`.
//!
//! * Stop-and-go: a frame is *stationary* when, over `window` around its robot time, the flange
//!   moved slower than both speed thresholds (`T_base_flange` at `t − w/2`, `t`, `t + w/2`).
//!   Consecutive stationary frames at the same place form an interval (frames further apart
//!   than standing allows start a new one: a camera that sends frames only at the stops); its
//!   sharpest frame (variance of the Laplacian) is the sample, the others are reported as not the
//!   sharpest.
//! * Continuous: every frame at least `spacing` after the previous sample is a sample. The
//!   offset matters there (the flange moves), so it can be estimated: the board is detected in
//!   those frames with the camera_info intrinsics, and the offset is the one whose pose pairs fit
//!   a hand-eye calibration best (closed-form solve, residual of the predicted board positions),
//!   found on a 5 ms grid over `±max` and refined by golden-section search to 0.05 ms.
//!
//! Frames whose TF lookup fails (a TF gap, or outside the TF stream) are skipped with the reason.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use ::image::{GrayImage, ImageBuffer, Luma};

use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_core::setup::PosePair;
use handeye_solve::{solve, Method, SolveOptions};
use handeye_vision::{estimate_board_pose, TargetDetector};

use super::storage::{Location, MessageAt};
use super::tf::TfBuffer;
use super::{BagError, BagOptions, BagSample};
use handeye_ros2::cdr;
use handeye_ros2::image::{compressed_lie, compressed_to_gray, raw_lies, raw_to_gray, ImageLie};
use handeye_ros2::msg::{CompressedImage, Image};
use handeye_vision::sharpness::{sharpness, sharpness_at};

/// The decimation a standing interval's frames are ranked at ([`sharpness_at`]): 4×4 blocks, about
/// half the work of [`sharpness`]'s 2×2; the winner alone is scored with [`sharpness`].
const RANKING_BLOCK: usize = 4;

/// How the arm moved while the bag was recorded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Motion {
    /// It stopped at each view: one sample per stationary interval.
    StopAndGo,
    /// It moved continuously: one sample every `spacing_s` seconds.
    Continuous {
        /// Seconds between samples.
        spacing_s: f64,
    },
}

/// The camera-to-robot clock offset: given, or estimated from the data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OffsetChoice {
    /// A known offset, s (camera stamp − robot stamp).
    Fixed(f64),
    /// Estimated within `±max_s` (continuous motion and intrinsics needed).
    Estimate {
        /// The search range, s.
        max_s: f64,
    },
}

/// How frames are chosen.
#[derive(Debug, Clone, PartialEq)]
pub struct SelectOptions {
    /// Stop-and-go or continuous.
    pub motion: Motion,
    /// The window over which a frame must be still, s.
    pub window_s: f64,
    /// Largest flange speed still counted as standing, m/s.
    pub max_speed_m_s: f64,
    /// Largest flange rotation speed still counted as standing, rad/s.
    pub max_speed_rad_s: f64,
    /// Largest spacing of two TF samples to interpolate between, s.
    pub max_tf_gap_s: f64,
    /// The clock offset.
    pub offset: OffsetChoice,
}

impl Default for SelectOptions {
    fn default() -> Self {
        SelectOptions {
            motion: Motion::StopAndGo,
            window_s: 0.2,
            max_speed_m_s: 0.002,
            max_speed_rad_s: 0.2f64.to_radians(),
            max_tf_gap_s: 0.1,
            offset: OffsetChoice::Fixed(0.0),
        }
    }
}

/// Why a frame was not taken.
#[derive(Debug, Clone, PartialEq)]
pub enum SkipReason {
    /// The flange moved (speeds over the window).
    Moving {
        /// mm/s.
        speed_mm_s: f64,
        /// deg/s.
        speed_deg_s: f64,
    },
    /// The TF chain could not be looked up at its time.
    TfGap(String),
    /// Stationary, but another frame of its interval is sharper.
    NotSharpest,
    /// Continuous mode: too close to the previous sample.
    BetweenSamples,
}

impl std::fmt::Display for SkipReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SkipReason::Moving {
                speed_mm_s,
                speed_deg_s,
            } => write!(f, "moving ({speed_mm_s:.2} mm/s, {speed_deg_s:.3} deg/s)"),
            SkipReason::TfGap(why) => write!(f, "{why}"),
            SkipReason::NotSharpest => f.write_str("not the sharpest of its stationary interval"),
            SkipReason::BetweenSamples => f.write_str("between samples"),
        }
    }
}

impl SkipReason {
    /// A short name for counting (`moving`, `tf gap`, ...).
    pub fn kind(&self) -> &'static str {
        match self {
            SkipReason::Moving { .. } => "moving",
            SkipReason::TfGap(_) => "tf gap",
            SkipReason::NotSharpest => "not sharpest",
            SkipReason::BetweenSamples => "between samples",
        }
    }
}

/// A frame not taken.
#[derive(Debug, Clone, PartialEq)]
pub struct Skip {
    /// Its header stamp (camera clock), ns.
    pub stamp_ns: i64,
    /// Why.
    pub reason: SkipReason,
}

/// The offset used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OffsetEstimate {
    /// camera stamp − robot stamp, s.
    pub offset_s: f64,
    /// Whether it was estimated (else given).
    pub estimated: bool,
    /// Frames with a board pose the estimate used.
    pub frames_used: usize,
    /// RMS of the predicted board positions at the offset, mm (estimate only).
    pub residual_mm: Option<f64>,
}

/// An image message not read yet: its header stamp and where it is.
pub(crate) struct ImageRef {
    pub(crate) stamp_ns: i64,
    /// 0-based index among the topic's messages (receive order).
    pub(crate) index: usize,
    pub(crate) location: Location,
}

/// Pass 2: the image messages read again from the bag, one at a time, and counted.
pub(crate) struct Frames<'b> {
    pub(crate) reader: MessageAt<'b>,
    pub(crate) compressed: bool,
    /// Frames decoded so far.
    pub(crate) decoded: usize,
    /// Threads that read, decode and score frames at once (what the memory limits allow).
    pub(crate) workers: usize,
    /// The decoded frames alive at once.
    pub(crate) held: FrameCount,
    /// What the decoded messages' headers said that their data contradicts.
    pub(crate) lies: ImageLies,
}

/// The lies of the image messages decoded ([`ImageLie`]), by kind: how many messages told it,
/// and the first one's lie and 0-based index on the topic. Noted by pass 2's workers at once.
#[derive(Debug, Default)]
pub(crate) struct ImageLies(std::sync::Mutex<BTreeMap<&'static str, (usize, ImageLie, usize)>>);

impl ImageLies {
    fn note(&self, lie: ImageLie, index: usize) {
        let mut lies = self.0.lock().unwrap_or_else(|p| p.into_inner());
        match lies.get_mut(lie.kind()) {
            // Workers decode out of order: the first is the lowest index.
            Some(seen) => {
                seen.0 += 1;
                if index < seen.2 {
                    (seen.1, seen.2) = (lie, index);
                }
            }
            None => {
                lies.insert(lie.kind(), (1, lie, index));
            }
        }
    }

    /// (messages, the first one's lie, its index) per kind, in kind order.
    pub(crate) fn into_counts(self) -> Vec<(usize, ImageLie, usize)> {
        self.0
            .into_inner()
            .unwrap_or_else(|p| p.into_inner())
            .into_values()
            .collect()
    }
}

/// How many decoded frames are alive at once, and the most there were: what keeps the import's
/// memory flat is that this stays a few frames (each worker's frame and best, the interval's
/// best, the sample being handed on), whatever the number of samples or frames.
#[derive(Debug, Default)]
pub(crate) struct FrameCount {
    now: AtomicUsize,
    peak: AtomicUsize,
}

impl FrameCount {
    /// `image`, counted until it is dropped.
    fn hold(&self, image: GrayImage) -> Held<'_> {
        let now = self.now.fetch_add(1, Ordering::SeqCst) + 1;
        self.peak.fetch_max(now, Ordering::SeqCst);
        Held { image, count: self }
    }

    /// The most decoded frames that were alive at once.
    pub(crate) fn peak(&self) -> usize {
        self.peak.load(Ordering::SeqCst)
    }
}

/// A decoded frame, counted in its [`FrameCount`] while it lives.
pub(crate) struct Held<'c> {
    pub(crate) image: GrayImage,
    count: &'c FrameCount,
}

impl Drop for Held<'_> {
    fn drop(&mut self) {
        self.count.now.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Where each chosen frame goes the moment it is chosen (in stamp order): the sample and its
/// image, which is dropped on return.
pub(crate) type Sink<'s> = dyn FnMut(&BagSample, &GrayImage) -> Result<(), BagError> + 's;

pub(crate) struct Selected {
    pub(crate) samples: Vec<BagSample>,
    pub(crate) skipped: Vec<Skip>,
    pub(crate) offset: OffsetEstimate,
}

/// The frame read from the bag and turned grey; its message is dropped on return.
fn decode<'f>(
    path: &Path,
    topic: &str,
    image: &ImageRef,
    frames: &'f mut Frames<'_>,
) -> Result<Held<'f>, BagError> {
    let data = frames.reader.data(image.location)?;
    frames.decoded += 1;
    let gray = to_gray(path, topic, image, frames.compressed, &data, &frames.lies)?;
    Ok(frames.held.hold(owned(gray)))
}

/// A frame's grey pixels: lent by its message (a packed `mono8` image, the usual case: nothing
/// is copied to rank it) or made from it (other encodings, compressed frames).
type Gray<'m> = ImageBuffer<Luma<u8>, Cow<'m, [u8]>>;

/// The frame as an image of its own (a copy only of lent pixels).
fn owned(gray: Gray<'_>) -> GrayImage {
    let (width, height) = gray.dimensions();
    GrayImage::from_raw(width, height, gray.into_raw().into_owned())
        .expect("the same pixels, the same size")
}

/// A frame's message turned grey, its header's lies about its data noted in `lies`.
fn to_gray<'m>(
    path: &Path,
    topic: &str,
    image: &ImageRef,
    compressed: bool,
    data: &'m [u8],
    lies: &ImageLies,
) -> Result<Gray<'m>, BagError> {
    let wrap = |source: super::MessageError| BagError::Message {
        path: path.to_path_buf(),
        topic: topic.to_string(),
        index: image.index,
        stamp_ns: image.stamp_ns,
        source,
    };
    let (width, height, pixels) = if compressed {
        let c = cdr::decode::<CompressedImage>(data).map_err(|e| wrap(e.into()))?;
        if let Some(lie) = compressed_lie(&c) {
            lies.note(lie, image.index);
        }
        let gray = compressed_to_gray(&c).map_err(|e| wrap(super::MessageError::Pixels(e)))?;
        let (width, height) = gray.dimensions();
        (width, height, Cow::Owned(gray.into_raw()))
    } else {
        let r = cdr::decode::<Image<&[u8]>>(data).map_err(|e| wrap(e.into()))?;
        for lie in raw_lies(&r) {
            lies.note(lie, image.index);
        }
        let pixels = match packed_mono8(&r) {
            Some(pixels) => Cow::Borrowed(pixels),
            None => Cow::Owned(
                raw_to_gray(&r)
                    .map_err(|e| wrap(super::MessageError::Pixels(e)))?
                    .into_raw(),
            ),
        };
        (r.width, r.height, pixels)
    };
    Ok(ImageBuffer::from_raw(width, height, pixels).expect("width × height pixels, checked"))
}

/// The pixels of a `mono8` image whose rows are packed (`step` = `width`, the usual case): the
/// frame as it is (every other form is left to [`raw_to_gray`], which copies and checks it).
pub(crate) fn packed_mono8<'m>(raw: &Image<&'m [u8]>) -> Option<&'m [u8]> {
    let pixels = raw.width as usize * raw.height as usize;
    let data = raw.data;
    let packed = matches!(raw.encoding.as_str(), "mono8" | "8UC1")
        && raw.step == raw.width
        && pixels > 0
        && data.len() >= pixels;
    packed.then(|| &data[..pixels])
}

pub(crate) fn seconds_to_ns(s: f64) -> i64 {
    (s * 1e9).round() as i64
}

/// Picks the frames (see the module docs); each chosen frame goes to `sink` as it is chosen, in
/// stamp order, and is not kept.
pub(crate) fn select(
    path: &Path,
    images: &[ImageRef],
    frames: &mut Frames<'_>,
    tf: &TfBuffer,
    camera: Option<&CameraModel>,
    options: &BagOptions,
    sink: &mut Sink<'_>,
) -> Result<Selected, BagError> {
    let o = &options.select;
    let mut tf = tf.clone();
    tf.set_max_gap_ns(seconds_to_ns(o.max_tf_gap_s));
    let mut order: Vec<usize> = (0..images.len()).collect();
    order.sort_by_key(|&i| images[i].stamp_ns);
    let lookup = |robot_ns: i64| tf.lookup(&options.base_frame, &options.flange_frame, robot_ns);
    let topic = options.image_topic.as_str();

    let offset = match (o.offset, o.motion) {
        (OffsetChoice::Fixed(s), _) => OffsetEstimate {
            offset_s: s,
            estimated: false,
            frames_used: 0,
            residual_mm: None,
        },
        (OffsetChoice::Estimate { .. }, Motion::StopAndGo) => {
            return Err(BagError::Offset {
                path: path.to_path_buf(),
                problem: "needs continuous motion (--continuous): frames taken while the arm stands still do not depend on the offset".into(),
            })
        }
        (OffsetChoice::Estimate { max_s }, Motion::Continuous { spacing_s }) => {
            let camera = camera.ok_or_else(|| BagError::Offset {
                path: path.to_path_buf(),
                problem: "needs the intrinsics (--camera-info) to measure board poses".into(),
            })?;
            estimate_offset(
                path, images, frames, &order, &tf, camera, options, spacing_s, max_s,
            )?
        }
    };
    let offset_ns = seconds_to_ns(offset.offset_s);
    let mut samples = Vec::new();
    let mut skipped = Vec::new();
    match o.motion {
        Motion::Continuous { spacing_s } => {
            let spacing = seconds_to_ns(spacing_s);
            let mut last: Option<i64> = None;
            for &i in &order {
                let image = &images[i];
                if last.is_some_and(|l| image.stamp_ns - l < spacing) {
                    skipped.push(Skip {
                        stamp_ns: image.stamp_ns,
                        reason: SkipReason::BetweenSamples,
                    });
                    continue;
                }
                let robot = image.stamp_ns - offset_ns;
                match lookup(robot) {
                    Ok(base_from_flange) => {
                        let gray = decode(path, topic, image, frames)?;
                        last = Some(image.stamp_ns);
                        let sample = BagSample {
                            image_stamp_ns: image.stamp_ns,
                            robot_stamp_ns: robot,
                            base_from_flange,
                            sharpness: sharpness(&gray.image),
                        };
                        sink(&sample, &gray.image)?;
                        samples.push(sample);
                    }
                    Err(e) => skipped.push(Skip {
                        stamp_ns: image.stamp_ns,
                        reason: SkipReason::TfGap(e.to_string()),
                    }),
                }
            }
        }
        Motion::StopAndGo => {
            let standing = StopAndGo {
                path,
                topic,
                images,
                offset_ns,
                sink,
            };
            standing.run(&order, frames, &tf, options, &mut samples, &mut skipped)?;
        }
    }
    skipped.sort_by_key(|s| s.stamp_ns);
    // Handed on in stamp order already (the frames are walked in it).
    debug_assert!(samples
        .windows(2)
        .all(|p| p[0].image_stamp_ns <= p[1].image_stamp_ns));
    Ok(Selected {
        samples,
        skipped,
        offset,
    })
}

/// Stop-and-go: the sharpest frame of each stationary interval, handed to the sink when its
/// interval closes.
struct StopAndGo<'a, 's> {
    path: &'a Path,
    topic: &'a str,
    images: &'a [ImageRef],
    offset_ns: i64,
    sink: &'a mut Sink<'s>,
}

impl StopAndGo<'_, '_> {
    /// Walks the frames in stamp `order`: each stationary or skipped with why; a run of
    /// stationary frames at one place is an interval, closed by the first frame that is not.
    fn run(
        mut self,
        order: &[usize],
        frames: &mut Frames<'_>,
        tf: &TfBuffer,
        options: &BagOptions,
        samples: &mut Vec<BagSample>,
        skipped: &mut Vec<Skip>,
    ) -> Result<(), BagError> {
        let o = &options.select;
        let lookup =
            |robot_ns: i64| tf.lookup(&options.base_frame, &options.flange_frame, robot_ns);
        let half = seconds_to_ns(o.window_s / 2.0);
        let h = o.window_s / 2.0;
        // Each frame: Some(pose) when stationary; intervals are runs of stationary frames.
        let mut interval: Vec<(usize, Pose)> = Vec::new();
        for &i in order {
            let image = &self.images[i];
            let robot = image.stamp_ns - self.offset_ns;
            let poses =
                lookup(robot - half).and_then(|a| Ok((a, lookup(robot)?, lookup(robot + half)?)));
            let reason = match poses {
                Err(e) => SkipReason::TfGap(e.to_string()),
                Ok((a, b, c)) => {
                    let v = (a.translation.vector - b.translation.vector)
                        .norm()
                        .max((b.translation.vector - c.translation.vector).norm())
                        / h;
                    let w = a
                        .rotation
                        .angle_to(&b.rotation)
                        .max(b.rotation.angle_to(&c.rotation))
                        / h;
                    if v <= o.max_speed_m_s && w <= o.max_speed_rad_s {
                        // A camera that sends frames only at the stops (triggered by the
                        // driver) gives consecutive stationary frames of different stops:
                        // the arm moved between them although no frame saw it move.
                        if interval
                            .last()
                            .is_some_and(|(_, last)| moved_between(last, &b, o))
                        {
                            self.close(&mut interval, frames, samples, skipped)?;
                        }
                        interval.push((i, b));
                        continue;
                    }
                    SkipReason::Moving {
                        speed_mm_s: v * 1e3,
                        speed_deg_s: w.to_degrees(),
                    }
                }
            };
            self.close(&mut interval, frames, samples, skipped)?;
            skipped.push(Skip {
                stamp_ns: image.stamp_ns,
                reason,
            });
        }
        self.close(&mut interval, frames, samples, skipped)
    }

    /// The interval's sharpest frame becomes a sample (handed to the sink, then dropped); the
    /// others are skipped as not the sharpest.
    fn close(
        &mut self,
        interval: &mut Vec<(usize, Pose)>,
        frames: &mut Frames<'_>,
        samples: &mut Vec<BagSample>,
        skipped: &mut Vec<Skip>,
    ) -> Result<(), BagError> {
        if interval.is_empty() {
            return Ok(());
        }
        let images = self.images;
        let (best, sharpness, image) = sharpest(self.path, self.topic, images, interval, frames)?;
        for (k, (i, _)) in interval.iter().enumerate() {
            if k != best {
                skipped.push(Skip {
                    stamp_ns: images[*i].stamp_ns,
                    reason: SkipReason::NotSharpest,
                });
            }
        }
        let (i, pose) = interval[best];
        let sample = BagSample {
            image_stamp_ns: images[i].stamp_ns,
            robot_stamp_ns: images[i].stamp_ns - self.offset_ns,
            base_from_flange: pose,
            sharpness,
        };
        (self.sink)(&sample, &image.image)?;
        drop(image);
        samples.push(sample);
        interval.clear();
        Ok(())
    }
}

/// The sharpest frame of a stationary interval: its position in `interval`, its sharpness and
/// the frame (the first of equally sharp ones). The frames are ranked on a decimated view
/// ([`RANKING_BLOCK`]) and only the winner is scored with [`sharpness`]. One worker per core
/// reads, decodes and ranks the frames, a few at a time, each keeping only its best so far, so
/// memory stays a few frames whatever the interval's length. A frame the bag can read where it
/// is (an indexed MCAP file) is read by the worker; otherwise this thread reads the bag in order
/// and hands the worker the message.
fn sharpest<'f>(
    path: &Path,
    topic: &str,
    images: &[ImageRef],
    interval: &[(usize, Pose)],
    frames: &'f mut Frames<'_>,
) -> Result<(usize, f64, Held<'f>), BagError> {
    type Best<'h> = Option<(f64, usize, Held<'h>)>;
    // Sharper wins; of equally sharp frames the earlier one.
    fn wins(best: &Best<'_>, score: f64, k: usize) -> bool {
        best.as_ref()
            .is_none_or(|b| score > b.0 || (score == b.0 && k < b.1))
    }
    fn keep<'h>(best: &mut Best<'h>, candidate: (f64, usize, Held<'h>)) {
        if wins(best, candidate.0, candidate.1) {
            *best = Some(candidate);
        }
    }
    /// A frame for a worker: read it where it is, or its message read already.
    enum Job {
        Read,
        Message(Vec<u8>),
    }
    let workers = frames.workers.clamp(1, interval.len().max(1));
    let Frames {
        reader,
        compressed,
        decoded,
        held,
        lies,
        ..
    } = frames;
    let held: &'f FrameCount = held;
    let lies: &ImageLies = lies;
    let bag = reader.bag();
    let compressed = *compressed;
    let mut best: Best<'f> = None;
    // The first error in the interval's order (a worker's or the reading's).
    let mut failed: Option<(usize, BagError)> = None;
    let (to_workers, jobs) = std::sync::mpsc::sync_channel::<(usize, Job)>(workers);
    let jobs = std::sync::Mutex::new(jobs);
    std::thread::scope(|scope| {
        let mut scorers = Vec::with_capacity(workers);
        for _ in 0..workers {
            let jobs = &jobs;
            let started = std::thread::Builder::new().spawn_scoped(
                scope,
                move || -> (Best<'f>, Option<(usize, BagError)>) {
                    let mut best: Best<'f> = None;
                    // The message being ranked: one buffer, read into frame after frame.
                    let mut message = Vec::new();
                    while let Ok(Ok((k, job))) = jobs.lock().map(|j| j.recv()) {
                        let image = &images[interval[k].0];
                        let read = match job {
                            Job::Message(data) => {
                                message = data;
                                Ok(())
                            }
                            Job::Read => bag.read_direct_into(image.location, &mut message),
                        };
                        // Ranked on the pixels where they lie in the message; only a frame
                        // that beats this worker's best so far is copied out and kept.
                        let ranked = read.and_then(|()| {
                            let gray = to_gray(path, topic, image, compressed, &message, lies)?;
                            let score = sharpness_at(&gray, RANKING_BLOCK);
                            Ok(wins(&best, score, k).then(|| (score, owned(gray))))
                        });
                        match ranked {
                            Ok(Some((score, gray))) => keep(&mut best, (score, k, held.hold(gray))),
                            Ok(None) => {}
                            // Later frames are still taken so the reader is not blocked.
                            Err(e) => return (best, Some((k, e))),
                        }
                    }
                    (best, None)
                },
            );
            match started {
                Ok(scorer) => scorers.push(scorer),
                // Those that started go on: fewer threads, the same frames.
                Err(_) if !scorers.is_empty() => break,
                Err(e) => {
                    let what = "a thread to read the bag's frames";
                    failed = Some((
                        0,
                        BagError::ThreadStart(handeye_core::memory::thread_start_error(what, &e)),
                    ));
                    return;
                }
            }
        }
        for (k, (i, _)) in interval.iter().enumerate() {
            let location = images[*i].location;
            let job = if location.direct() {
                Ok(Job::Read)
            } else {
                reader.data(location).map(Job::Message)
            };
            match job {
                Ok(job) => {
                    *decoded += 1;
                    if to_workers.send((k, job)).is_err() {
                        break;
                    }
                }
                Err(e) => {
                    failed = Some((k, e));
                    break;
                }
            }
        }
        drop(to_workers);
        for scorer in scorers {
            // A scorer only decodes and computes a number: it cannot panic short of a bug.
            if let Ok((candidate, error)) = scorer.join() {
                if let Some(candidate) = candidate {
                    keep(&mut best, candidate);
                }
                if let Some((k, e)) = error {
                    if failed.as_ref().is_none_or(|(f, _)| k < *f) {
                        failed = Some((k, e));
                    }
                }
            }
        }
    });
    if let Some((_, e)) = failed {
        return Err(e);
    }
    let (_, k, image) = best.ok_or_else(|| BagError::Message {
        path: path.to_path_buf(),
        topic: topic.to_string(),
        index: images[interval[0].0].index,
        stamp_ns: images[interval[0].0].stamp_ns,
        source: super::MessageError::Pixels("no frame of the interval could be scored".into()),
    })?;
    Ok((k, sharpness(&image.image), image))
}

/// Whether two stationary frames stand at different stops: the flange is further apart than
/// standing allows over one window (the speed thresholds times the window).
fn moved_between(before: &Pose, after: &Pose, o: &SelectOptions) -> bool {
    let moved_m = (before.translation.vector - after.translation.vector).norm();
    let turned_rad = before.rotation.angle_to(&after.rotation);
    moved_m > o.max_speed_m_s * o.window_s || turned_rad > o.max_speed_rad_s * o.window_s
}

/// The offset whose pose pairs fit a hand-eye calibration best (module docs).
#[allow(clippy::too_many_arguments)]
fn estimate_offset(
    path: &Path,
    images: &[ImageRef],
    frames: &mut Frames<'_>,
    order: &[usize],
    tf: &TfBuffer,
    camera: &CameraModel,
    options: &BagOptions,
    spacing_s: f64,
    max_s: f64,
) -> Result<OffsetEstimate, BagError> {
    let fail = |problem: String| BagError::Offset {
        path: path.to_path_buf(),
        problem,
    };
    let detector = TargetDetector::spawn(&options.board, options.detector.clone())
        .map_err(|e| fail(format!("starting the detector: {e}")))?;
    let max_ns = seconds_to_ns(max_s);
    let spacing = seconds_to_ns(spacing_s);
    let lookup = |ns: i64| tf.lookup(&options.base_frame, &options.flange_frame, ns);
    // Frames whose TF is there for every offset tried, with their board pose.
    let mut measured: Vec<(i64, Pose)> = Vec::new();
    let mut last: Option<i64> = None;
    for &i in order {
        let image = &images[i];
        if last.is_some_and(|l| image.stamp_ns - l < spacing) {
            continue;
        }
        if lookup(image.stamp_ns - max_ns).is_err() || lookup(image.stamp_ns + max_ns).is_err() {
            continue;
        }
        last = Some(image.stamp_ns);
        let gray = decode(path, &options.image_topic, image, frames)?;
        if let Ok(pose) = detector
            .detect(&gray.image)
            .and_then(|d| estimate_board_pose(&options.board, camera, &d))
        {
            measured.push((image.stamp_ns, pose.camera_from_target));
        }
    }
    if measured.len() < 6 {
        return Err(fail(format!(
            "only {} frames with the board and TF within ±{max_s} s; at least 6 are needed",
            measured.len()
        )));
    }
    let solve_options = SolveOptions {
        method: Method::ClosedForm,
        drop_outliers: false,
        covariance: false,
        check_conventions: false,
        ..SolveOptions::default()
    };
    // Mean squared miss of the predicted board positions (m²) at an offset (s).
    let cost = |offset_s: f64| -> f64 {
        let offset = seconds_to_ns(offset_s);
        let pairs: Option<Vec<PosePair>> = measured
            .iter()
            .map(|(stamp, camera_from_target)| {
                lookup(stamp - offset)
                    .ok()
                    .map(|a| PosePair::new(a, *camera_from_target))
            })
            .collect();
        let Some(pairs) = pairs else {
            return f64::INFINITY;
        };
        match solve(options.setup, &pairs, &solve_options) {
            Ok(c) => {
                pairs
                    .iter()
                    .map(|p| {
                        let predicted = c.predict_camera_from_target(&p.base_from_flange);
                        (predicted.translation.vector - p.camera_from_target.translation.vector)
                            .norm_squared()
                    })
                    .sum::<f64>()
                    / pairs.len() as f64
            }
            Err(_) => f64::INFINITY,
        }
    };
    let step = 0.005;
    let n = (max_s / step).ceil() as i64;
    let (mut best, mut best_cost) = (0.0, f64::INFINITY);
    for k in -n..=n {
        let s = (k as f64 * step).clamp(-max_s, max_s);
        let c = cost(s);
        if c < best_cost {
            (best, best_cost) = (s, c);
        }
    }
    if !best_cost.is_finite() {
        return Err(fail("no offset in the range gives a hand-eye solve".into()));
    }
    // Golden-section refinement around the best grid point.
    let (mut a, mut b) = ((best - step).max(-max_s), (best + step).min(max_s));
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
    let (mut f1, mut f2) = (cost(x1), cost(x2));
    while b - a > 5e-5 {
        if f1 < f2 {
            (b, x2, f2) = (x2, x1, f1);
            x1 = b - g * (b - a);
            f1 = cost(x1);
        } else {
            (a, x1, f1) = (x1, x2, f2);
            x2 = a + g * (b - a);
            f2 = cost(x2);
        }
    }
    let offset_s = (a + b) / 2.0;
    let residual = cost(offset_s);
    Ok(OffsetEstimate {
        offset_s,
        estimated: true,
        frames_used: measured.len(),
        residual_mm: Some(residual.sqrt() * 1e3),
    })
}
