//! AprilTag detection of a board's tags, on a dedicated thread.
//!
//! The C detector (`apriltag::Detector`) is not `Send`, so [`TagDetector::spawn`] builds it on
//! its own thread and [`TagDetector::detect`] sends each image over a channel and gets plain
//! data back; the handle is `Send + Sync`. Detections are filtered against the board: ids not
//! on the board, ids seen twice (both copies dropped) and hamming distances above the
//! threshold are rejected and reported.
//!
//! Boards printed with Kalibr's corner squares (every tag corner an X-junction) take two extra
//! steps on the detector thread: the quad search sees a tone-remapped copy of the frame in
//! which tags and squares do not merge ([`separate_x_junctions`]), and each tag corner is then
//! refined to the X-junction's saddle point on the original frame (`vision::xcorner`), which is
//! more precise than the detector's edge fit. Boards without the squares are searched, decoded
//! and edge-fitted on the frame smoothed by the 5-tap binomial kernel ([`binomial_blur`] twice):
//! sensor noise otherwise breaks the quad search's threshold image into hundreds of small
//! clusters, each fitted and rejected in turn (most of the detection time), and a symmetric blur
//! does not move a straight edge.
//!
//! Pixel convention: the C library puts pixel centres at `i + 0.5`; this project (OpenCV, ROS,
//! Kalibr) puts them at integers. The conversion (subtract 0.5 px) happens here, in
//! [`to_project_pixels`], and nowhere else. The C calls themselves are in `vision::ffi`, which
//! also refuses images too small for the detector. Depends on `vision::board`,
//! `vision::family`, `vision::ffi`, `vision::xcorner`.

use std::path::Path;
use std::sync::mpsc;
use std::thread::JoinHandle;

use image::GrayImage;
use nalgebra::{Point2, Point3};

use super::board::Board;
use super::family::TagFamily;
use super::ffi;
use super::regrid::Grid;
use super::xcorner;
use super::TargetError;
use handeye_core::setup::CornerObservation;

/// Largest accepted quad decimation: beyond it the quad search sees a thumbnail in which no
/// tag a camera can resolve survives (and the C code truncates the factor to an `int`).
pub const MAX_DECIMATION: f32 = 16.0;
/// Largest accepted `|quad_sigma|`, px: the blur kernel (4σ wide) must stay far narrower than
/// any image the detector accepts.
pub const MAX_QUAD_SIGMA: f32 = 4.0;

/// Detector settings.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectorOptions {
    /// Quad decimation: 2 halves the resolution of the quad search (corners are still refined
    /// at full resolution); as accurate as 1 on these tag sizes and ~4x faster.
    pub decimation: f32,
    /// Worker threads inside the C detector.
    pub threads: u8,
    /// Extra Gaussian blur sigma of the C detector's quad search (0 = none, negative sharpens),
    /// px. It adds to the fixed pre-filter every frame gets first (a 5-tap binomial twice for
    /// boards without corner squares, the X-junction separation for Kalibr's squares).
    pub quad_sigma: f32,
    /// Highest accepted hamming distance (bit errors corrected); 0-2.
    pub max_hamming: u32,
    /// Search again at full resolution where the tags found say a missing tag is (small or
    /// blurred tags the quad search missed; `vision::regrid`).
    pub second_pass: bool,
    /// Frames detected at once, each by a detector of its own on a thread of its own (`-j`):
    /// `None` is one per core (at most four), fewer when the memory limits leave room for fewer
    /// ([`TargetDetector::memory_needed`](crate::TargetDetector::memory_needed)).
    pub jobs: Option<usize>,
}

impl Default for DetectorOptions {
    fn default() -> Self {
        DetectorOptions {
            decimation: 2.0,
            threads: 1,
            quad_sigma: 0.0,
            max_hamming: 1,
            second_pass: true,
            jobs: None,
        }
    }
}

/// Prepares the allocator for the memory limits the process runs under, before detector
/// threads start: under `ulimit -v`, one allocator arena for all threads (see the C binding's
/// note: per-thread arenas reserve address space the C detector then lacks). Called by every
/// memory check of the detection; harmless to call again.
pub fn fit_allocator_to_limits() {
    ffi::fit_allocator_to_limits();
}

/// The stack of a thread std starts (2 MiB) and its guard page, bytes.
pub(crate) const THREAD_STACK_BYTES: u64 = (2 << 20) + 4096;

/// Bytes per frame pixel the detector thread holds besides the C detector: the frame it was
/// sent, the two binomial passes (16-bit rows, then the 8-bit result, twice) or the X-junction
/// copy, with a margin for the second pass's crops.
const RUST_BYTES_PER_PIXEL: u64 = 8;

/// The memory one AprilTag detector needs at most at a `width`x`height` frame, bytes: the C
/// detector's working memory (`ffi::detector_bytes`), the frame copies of its thread, and the
/// stacks of that thread and of the worker that feeds it.
pub(crate) fn tag_detector_bytes(
    board: &Board,
    options: &DetectorOptions,
    width: u32,
    height: u32,
) -> u64 {
    ffi::detector_bytes(
        board.family(),
        width,
        height,
        options.decimation,
        options.max_hamming,
    ) + RUST_BYTES_PER_PIXEL * u64::from(width) * u64::from(height)
        + 2 * THREAD_STACK_BYTES
}

/// A detector option out of range: the field, the value and what is accepted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: expected {expected}, found {found}")]
pub struct DetectorOptionsError {
    /// The option (`decimation`, `threads`, `quad_sigma`, `max_hamming`).
    pub field: &'static str,
    /// The value given.
    pub found: String,
    /// What is accepted.
    pub expected: String,
}

impl DetectorOptions {
    /// Accepted `decimation` (see [`MAX_DECIMATION`]).
    pub const DECIMATION: std::ops::RangeInclusive<f32> = 1.0..=MAX_DECIMATION;
    /// Accepted `threads`: one. The AprilTag C library this build links (apriltag-sys 0.3)
    /// predates upstream's fix of a race in its worker pool (AprilRobotics/apriltag PR #339):
    /// with more threads the detector can crash the whole process — seen about once in a few
    /// thousand frames (`tests/it/fuzz.rs`, `crash_detector_worker_pool_race`). Detection already
    /// runs on its own thread, overlapping the arm's moves.
    pub const THREADS: std::ops::RangeInclusive<u8> = 1..=1;
    /// Accepted `quad_sigma`, px (negative sharpens; see [`MAX_QUAD_SIGMA`]): a stronger blur
    /// erases the tags, and its kernel must stay far narrower than any accepted image.
    pub const QUAD_SIGMA: std::ops::RangeInclusive<f32> = -MAX_QUAD_SIGMA..=MAX_QUAD_SIGMA;
    /// Accepted `max_hamming`: the decode table for 3 or more corrected bits takes gigabytes,
    /// and they accept false tags.
    pub const MAX_HAMMING: std::ops::RangeInclusive<u32> = 0..=2;

    /// Checks every option against its accepted range.
    pub fn validate(&self) -> Result<(), DetectorOptionsError> {
        fn bad<T: std::fmt::Display>(
            field: &'static str,
            found: T,
            range: &std::ops::RangeInclusive<T>,
        ) -> Result<(), DetectorOptionsError> {
            Err(DetectorOptionsError {
                field,
                found: found.to_string(),
                expected: format!("a value in [{}, {}]", range.start(), range.end()),
            })
        }
        // `contains` is false for NaN, so a NaN is refused too.
        if !Self::DECIMATION.contains(&self.decimation) {
            return bad("decimation", self.decimation, &Self::DECIMATION);
        }
        if !Self::THREADS.contains(&self.threads) {
            return Err(DetectorOptionsError {
                field: "threads",
                found: self.threads.to_string(),
                expected: "1 (more threads can crash the AprilTag library this build links: a race in its worker pool)".to_string(),
            });
        }
        if !Self::QUAD_SIGMA.contains(&self.quad_sigma) {
            return bad("quad_sigma", self.quad_sigma, &Self::QUAD_SIGMA);
        }
        if !Self::MAX_HAMMING.contains(&self.max_hamming) {
            return bad("max_hamming", self.max_hamming, &Self::MAX_HAMMING);
        }
        Ok(())
    }
}

/// One accepted tag in an image.
#[derive(Debug, Clone, PartialEq)]
pub struct TagObservation {
    /// Tag id (on the board).
    pub id: u32,
    /// Bits corrected while decoding.
    pub hamming: u32,
    /// The detector's decision margin (higher is more confident).
    pub decision_margin: f32,
    /// Border-square corners, px, project convention (centres at integers), in the order of
    /// [`Board::tag_corners_in_target`].
    pub corners_px: [Point2<f64>; 4],
}

/// Why a detection was not used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RejectReason {
    /// The id is not on the board.
    NotOnBoard,
    /// The id was detected more than once.
    Duplicate,
    /// Too many corrected bits.
    Hamming,
}

/// A detection that was dropped, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct RejectedTag {
    /// The decoded id.
    pub id: u32,
    /// Bits corrected.
    pub hamming: u32,
    /// Why it was dropped.
    pub reason: RejectReason,
}

/// The board's tags found in one image.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardDetection {
    /// Accepted tags, by id.
    pub tags: Vec<TagObservation>,
    /// Rejected detections.
    pub rejected: Vec<RejectedTag>,
    /// Labelled chessboard corners `(corner id, pixel)` of a ChArUco board or a chessboard,
    /// by id (empty for an aprilgrid, whose corners are in `tags`).
    pub points: Vec<(u32, Point2<f64>)>,
    /// Width of the image searched, px.
    pub image_width: u32,
    /// Height of the image searched, px.
    pub image_height: u32,
}

impl BoardDetection {
    /// Every detected corner as recorded: `[tag id, corner, u, v]` for an aprilgrid's tags,
    /// `[corner id, 0, u, v]` for ChArUco and chessboard corners.
    pub fn observations(&self) -> Vec<CornerObservation> {
        let tags = self.tags.iter().flat_map(|t| {
            (0u8..)
                .zip(&t.corners_px)
                .map(move |(corner, c)| CornerObservation {
                    tag_id: t.id,
                    corner,
                    pixel: *c,
                })
        });
        let points = self.points.iter().map(|(id, pixel)| CornerObservation {
            tag_id: *id,
            corner: 0,
            pixel: *pixel,
        });
        tags.chain(points).collect()
    }

    /// Tags (aprilgrid) or corners (ChArUco, chessboard) found.
    pub fn feature_count(&self) -> usize {
        self.tags.len() + self.points.len()
    }

    /// `(point_in_target, pixel)` pairs for every accepted corner, tag by tag in corner order.
    pub fn correspondences(&self, board: &Board) -> Vec<(Point3<f64>, Point2<f64>)> {
        self.tags
            .iter()
            .filter_map(|tag| Some((board.tag_corners_in_target(tag.id)?, tag.corners_px)))
            .flat_map(|(points, pixels)| points.into_iter().zip(pixels))
            .collect()
    }
}

/// A raw detection as it leaves the detector thread.
struct RawDetection {
    id: u32,
    hamming: u32,
    decision_margin: f32,
    corners_px: [Point2<f64>; 4],
}

type Job = (
    GrayImage,
    mpsc::Sender<Result<Vec<RawDetection>, TargetError>>,
);

/// A handle to an AprilTag detector living on its own thread.
pub struct TagDetector {
    jobs: Option<mpsc::Sender<Job>>,
    thread: Option<JoinHandle<()>>,
    board: Board,
    options: DetectorOptions,
}

impl std::fmt::Debug for TagDetector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TagDetector")
            .field("family", &self.board.family())
            .field("options", &self.options)
            .finish()
    }
}

impl TagDetector {
    /// Starts a detector for `board`'s family and border on a new thread.
    pub fn spawn(board: &Board, options: DetectorOptions) -> Result<Self, TargetError> {
        options
            .validate()
            .map_err(|problem| TargetError::Detector {
                reason: problem.to_string(),
            })?;
        let (jobs, receiver) = mpsc::channel::<Job>();
        let (ready_tx, ready_rx) = mpsc::channel::<Result<(), String>>();
        let family = board.family();
        let border_bits = board.border_bits();
        let x_junctions = board.corner_squares().then(|| XJunctions {
            cells_across: board.layout().width_at_border as f64,
        });
        let thread_options = options.clone();
        let grid = options.second_pass.then(|| Grid::of(board));
        let thread = std::thread::Builder::new()
            .name("apriltag".to_string())
            .spawn(move || {
                detector_thread(
                    family,
                    border_bits,
                    x_junctions,
                    grid,
                    thread_options,
                    receiver,
                    ready_tx,
                )
            })
            .map_err(|error| TargetError::Detector {
                reason: handeye_core::memory::thread_start_error("the detector thread", &error),
            })?;
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(TagDetector {
                jobs: Some(jobs),
                thread: Some(thread),
                board: board.clone(),
                options,
            }),
            Ok(Err(reason)) => Err(TargetError::Detector { reason }),
            Err(_) => Err(TargetError::DetectorStopped),
        }
    }

    /// Detects the board's tags in a grey image (blocks until the detector thread answers).
    ///
    /// An image too small for the detector at this decimation (see
    /// [`TargetError::ImageTooSmall`]) is refused before it reaches the C code, and the detector
    /// stays usable.
    pub fn detect(&self, image: &GrayImage) -> Result<BoardDetection, TargetError> {
        // Checked here for an early answer, and again on the detector thread before the C call.
        ffi::check_image_size(
            image.width(),
            image.height(),
            self.options.decimation,
            self.options.quad_sigma,
        )?;
        let (reply_tx, reply_rx) = mpsc::channel();
        self.jobs
            .as_ref()
            .ok_or(TargetError::DetectorStopped)?
            .send((image.clone(), reply_tx))
            .map_err(|_| TargetError::DetectorStopped)?;
        let raw = reply_rx
            .recv()
            .map_err(|_| TargetError::DetectorStopped)??;
        Ok(filter(
            &self.board,
            &self.options,
            raw,
            image.width(),
            image.height(),
        ))
    }

    /// The board this detector looks for.
    pub fn board(&self) -> &Board {
        &self.board
    }
}

impl Drop for TagDetector {
    fn drop(&mut self) {
        // Closing the channel ends the thread's loop; join so the C detector is freed.
        self.jobs.take();
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn filter(
    board: &Board,
    options: &DetectorOptions,
    raw: Vec<RawDetection>,
    image_width: u32,
    image_height: u32,
) -> BoardDetection {
    let mut tags = Vec::new();
    let mut rejected = Vec::new();
    let mut counts = std::collections::HashMap::new();
    for detection in &raw {
        *counts.entry(detection.id).or_insert(0usize) += 1;
    }
    for detection in raw {
        let reason = if board.tag(detection.id).is_none() {
            Some(RejectReason::NotOnBoard)
        } else if detection.hamming > options.max_hamming {
            Some(RejectReason::Hamming)
        } else if counts[&detection.id] > 1 {
            // Two tags with one id means a reflection or a second board: neither is trustworthy.
            Some(RejectReason::Duplicate)
        } else {
            None
        };
        match reason {
            Some(reason) => rejected.push(RejectedTag {
                id: detection.id,
                hamming: detection.hamming,
                reason,
            }),
            None => tags.push(TagObservation {
                id: detection.id,
                hamming: detection.hamming,
                decision_margin: detection.decision_margin,
                corners_px: detection.corners_px,
            }),
        }
    }
    tags.sort_by_key(|t| t.id);
    BoardDetection {
        tags,
        rejected,
        points: Vec::new(),
        image_width,
        image_height,
    }
}

/// The one place the AprilTag library's pixel convention (centres at `i + 0.5`) becomes the
/// project's (centres at integers).
fn to_project_pixels(corners: [[f64; 2]; 4]) -> [Point2<f64>; 4] {
    corners.map(|[x, y]| Point2::new(x - 0.5, y - 0.5))
}

fn detector_thread(
    family: TagFamily,
    border_bits: u32,
    x_junctions: Option<XJunctions>,
    grid: Option<Grid>,
    options: DetectorOptions,
    jobs: mpsc::Receiver<Job>,
    ready: mpsc::Sender<Result<(), String>>,
) {
    let raw_options = ffi::RawOptions {
        decimation: options.decimation,
        threads: options.threads,
        quad_sigma: options.quad_sigma,
        max_hamming: options.max_hamming,
    };
    let mut detector = match ffi::OwnedFamily::create(family, border_bits)
        .and_then(|family| ffi::DetectorHandle::new(family, &raw_options))
    {
        Ok(d) => d,
        Err(reason) => {
            let _ = ready.send(Err(reason));
            return;
        }
    };
    let _ = ready.send(Ok(()));
    while let Ok((image, reply)) = jobs.recv() {
        // The C detector checks none of its allocations: what it may take at this frame's size
        // is made sure of first, so a limit reached is this error, never a crash.
        let (width, height) = (image.width(), image.height());
        let needed = ffi::detector_bytes(
            family,
            width,
            height,
            options.decimation,
            options.max_hamming,
        ) + RUST_BYTES_PER_PIXEL * u64::from(width) * u64::from(height);
        let what = format!("the AprilTag detector at {width}x{height}");
        if let Err(e) = handeye_core::memory::probe(&what, needed, " or use `-j 1`") {
            let _ = reply.send(Err(TargetError::Memory(e)));
            continue;
        }
        let searched = match &x_junctions {
            Some(_) => separate_x_junctions(&image),
            None => binomial_blur(&binomial_blur(&image)),
        };
        let detections = detector.detect(&searched).map(|tags| {
            let mut found: Vec<RawDetection> = tags
                .into_iter()
                .map(|t| RawDetection {
                    id: t.id,
                    hamming: t.hamming,
                    decision_margin: t.decision_margin,
                    corners_px: to_project_pixels(t.corners),
                })
                .collect();
            if let Some(grid) = &grid {
                let first: Vec<(u32, [Point2<f64>; 4])> = found
                    .iter()
                    .filter(|d| d.hamming <= options.max_hamming)
                    .map(|d| (d.id, d.corners_px))
                    .collect();
                found.extend(
                    grid.refind(&mut detector, &searched, &first, to_project_pixels)
                        .into_iter()
                        .map(|t| RawDetection {
                            id: t.id,
                            hamming: t.hamming,
                            decision_margin: t.decision_margin,
                            corners_px: t.corners_px,
                        }),
                );
            }
            if let Some(x) = &x_junctions {
                for d in &mut found {
                    x.refine(&image, &mut d.corners_px);
                }
            }
            found
        });
        let _ = reply.send(detections);
    }
}

/// A board printed with Kalibr's corner squares: every tag corner is an X-junction.
#[derive(Debug, Clone, Copy)]
struct XJunctions {
    /// Cells across a tag's black square (`width_at_border`).
    cells_across: f64,
}

impl XJunctions {
    /// Moves each corner that is an X-junction to its saddle point in `image` (the unmodified
    /// frame), with a window of 1.5 cells measured along the shorter of the corner's two edges
    /// (a tilted tag's cells are narrower one way): inside the tag's 2-cell black border and
    /// the corner square, so no other edge enters the fit. Corners that are not X-junctions
    /// (a square cut off by the image edge, glare) keep the detector's edge-fitted estimate.
    fn refine(&self, image: &GrayImage, corners: &mut [Point2<f64>; 4]) {
        let original = *corners;
        // Cell size at each corner, px, along the shorter of its two edges.
        let cell_px: [f64; 4] = std::array::from_fn(|k| {
            let before = (original[k] - original[(k + 3) % 4]).norm();
            let after = (original[(k + 1) % 4] - original[k]).norm();
            (before.min(after) / self.cells_across).max(1.0)
        });
        let saddle_near = |k: usize, start: Point2<f64>| {
            let half_window = (1.5 * cell_px[k])
                .round()
                .clamp(2.0, f64::from(xcorner::MAX_HALF_WINDOW_PX))
                as u32;
            let saddle = xcorner::refine_saddle(image, start, half_window)?;
            // A quad that half-merged with a square can put its corner a cell off; the next
            // other X-junction (a data cell's, the square's far corner) is 2 cells away.
            ((saddle - start).norm() <= cell_px[k].max(2.0)
                && xcorner::is_x_junction(image, saddle, cell_px[k].max(2.0), X_JUNCTION_CONTRAST))
            .then_some(saddle)
        };
        let mut refined = [false; 4];
        for k in 0..4 {
            if let Some(saddle) = saddle_near(k, original[k]) {
                corners[k] = saddle;
                refined[k] = true;
            }
        }
        // A corner the detector put too far off for the fit to start from: start instead where
        // the other three (refined) corners put it, completing the parallelogram.
        for k in 0..4 {
            if refined[k] || refined.iter().filter(|&&r| r).count() < 3 {
                continue;
            }
            let predicted = Point2::from(
                corners[(k + 3) % 4].coords + corners[(k + 1) % 4].coords
                    - corners[(k + 2) % 4].coords,
            );
            if let Some(saddle) = saddle_near(k, predicted) {
                corners[k] = saddle;
                refined[k] = true;
            }
        }
    }
}

/// Smallest grey-level difference between the bright and dark sectors of an X-junction.
const X_JUNCTION_CONTRAST: f64 = 12.0;

/// The frame the quad search sees when the board has corner squares. The AprilTag detector
/// thresholds each pixel halfway between the darkest and brightest grey around it; where a
/// tag's black square touches a corner square the pixels are that mid grey, and whichever
/// way they fall the tag and the square often become one black region without a quad. Here
/// each pixel is remapped inside its local range `[lo, hi]` (the same 24-px neighbourhood the
/// detector's 4-px tiles of the half-size image span) by a concave curve that sends
/// [`SEPARATION_LEVEL`] of the range to its middle: the detector then effectively cuts at that
/// level, the X-junction pixels fall on the white side, tags and squares separate, while
/// every cell darker than that level (all but the faintest) stays black. Flat patches (range
/// under [`MIN_SEPARATION_RANGE`] grey levels) are left alone, so noise is not amplified.
/// Only the quad search and decoding see this frame; corners are refined on the original.
fn separate_x_junctions(image: &GrayImage) -> GrayImage {
    const TILE: usize = 8;
    let (w, h) = (image.width() as usize, image.height() as usize);
    let (tw, th) = (w.div_ceil(TILE), h.div_ceil(TILE));
    let raw = image.as_raw();
    let mut tile_lo = vec![255u8; tw * th];
    let mut tile_hi = vec![0u8; tw * th];
    for y in 0..h {
        let row = &raw[y * w..(y + 1) * w];
        let tiles = (y / TILE) * tw..;
        for ((chunk, lo), hi) in row
            .chunks(TILE)
            .zip(&mut tile_lo[tiles.clone()])
            .zip(&mut tile_hi[tiles])
        {
            let (chunk_lo, chunk_hi) = chunk
                .iter()
                .fold((255u8, 0u8), |(l, h), &v| (l.min(v), h.max(v)));
            *lo = (*lo).min(chunk_lo);
            *hi = (*hi).max(chunk_hi);
        }
    }
    // Each tile's range over its 3x3 tile neighbourhood.
    let mut lo = vec![255u8; tw * th];
    let mut hi = vec![0u8; tw * th];
    for ty in 0..th {
        for tx in 0..tw {
            let k = ty * tw + tx;
            for ny in ty.saturating_sub(1)..(ty + 2).min(th) {
                for nx in tx.saturating_sub(1)..(tx + 2).min(tw) {
                    lo[k] = lo[k].min(tile_lo[ny * tw + nx]);
                    hi[k] = hi[k].max(tile_hi[ny * tw + nx]);
                }
            }
        }
    }
    let remap = separation_remap();
    let mut out = binomial_blur(image);
    let buffer: &mut [u8] = &mut out;
    for (y, row) in buffer.chunks_exact_mut(w).enumerate() {
        let tiles = (y / TILE) * tw..;
        for ((chunk, &l), &h) in row.chunks_mut(TILE).zip(&lo[tiles.clone()]).zip(&hi[tiles]) {
            let range = h - l;
            if u32::from(range) < MIN_SEPARATION_RANGE {
                continue;
            }
            let curve = &remap[usize::from(range)];
            for v in chunk {
                // The smoothed pixel lies inside its 3x3 tile neighbourhood's range.
                *v = l + curve[usize::from(*v - l)];
            }
        }
    }
    out
}

/// [`separate_x_junctions`]' remap of a pixel `d` grey levels above its neighbourhood's darkest
/// inside a range of `r` levels, `remap[r][d]` (`d ≤ r`): the concave curve `t^p` with
/// `SEPARATION_LEVEL^p = 1/2` over the range, in integers (one table look-up a pixel).
fn separation_remap() -> &'static [[u8; 256]; 256] {
    static REMAP: std::sync::OnceLock<Box<[[u8; 256]; 256]>> = std::sync::OnceLock::new();
    REMAP.get_or_init(|| {
        let p = 0.5f64.ln() / SEPARATION_LEVEL.ln();
        let curve: Vec<u32> = (0..=255u32)
            .map(|t| (255.0 * (t as f64 / 255.0).powf(p)).round() as u32)
            .collect();
        let mut remap = Box::new([[0u8; 256]; 256]);
        for (r, levels) in remap.iter_mut().enumerate().skip(1) {
            let r = r as u32;
            for (d, out) in levels.iter_mut().enumerate().take(r as usize + 1) {
                // d·255/r rounded down, then the curve scaled back to the range.
                let t = d as u32 * 255 / r;
                *out = (r * curve[t as usize] / 255) as u8;
            }
        }
        remap
    })
}

/// The frame smoothed by the 3x3 binomial kernel (`[1 2 1]/4` each way, sigma ≈ 0.7 px),
/// edge pixels repeated. A pixel-sharp frame (a board file rendered straight to an image)
/// has X-junctions exactly on pixel corners, where the quad search fails on some tags; a
/// camera's own blur is at least this much anyway. Applied twice (`[1 4 6 4 1]/16`, sigma ≈ 1
/// px) to a frame of a board without corner squares, before the AprilTag detector: measured on
/// the Kalibr-style frames of tests/it/kalibr_print.rs (no squares), the corner error drops from
/// 0.062 to 0.050 px and the detection takes a third of the instructions.
fn binomial_blur(image: &GrayImage) -> GrayImage {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let raw = image.as_raw();
    // Rows: [1 2 1] with the edge pixels repeated.
    let mut rows = vec![0u16; w * h];
    for (src, dst) in raw.chunks_exact(w).zip(rows.chunks_exact_mut(w)) {
        if w < 2 {
            dst[0] = 4 * src[0] as u16;
            continue;
        }
        dst[0] = 3 * src[0] as u16 + src[1] as u16;
        dst[w - 1] = 3 * src[w - 1] as u16 + src[w - 2] as u16;
        for (((d, &l), &c), &r) in dst[1..w - 1]
            .iter_mut()
            .zip(&src[..w - 2])
            .zip(&src[1..w - 1])
            .zip(&src[2..])
        {
            *d = l as u16 + 2 * c as u16 + r as u16;
        }
    }
    // Columns, over whole rows at a time.
    let mut out = image.clone();
    let buffer: &mut [u8] = &mut out;
    for (y, dst) in buffer.chunks_exact_mut(w).enumerate() {
        let (up, down) = (y.saturating_sub(1), (y + 1).min(h - 1));
        let (up, mid, down) = (
            &rows[up * w..][..w],
            &rows[y * w..][..w],
            &rows[down * w..][..w],
        );
        for (((d, &a), &b), &c) in dst.iter_mut().zip(up).zip(mid).zip(down) {
            *d = ((a + 2 * b + c + 8) / 16) as u8;
        }
    }
    out
}

/// Fraction of the local black-to-white range at which the quad search effectively cuts on a
/// board with corner squares (the detector itself cuts at 0.5). Measured: on Kalibr prints
/// rendered independently (tests/it/kalibr_print.rs, 8 frames at 0.45-0.8 m) every tag is found
/// from 0.1 to 0.3, 275 of 288 at 0.35, 106 at 0.5; on our renderer's frames tilted up to 50°
/// (tests/it/vision.rs) every tag from 0.1 to 0.2, one missed at 0.25. The lower the level, the
/// more a faint small data cell risks turning white: 0.2 is the highest level that works on both.
const SEPARATION_LEVEL: f64 = 0.2;
/// Local ranges narrower than this (grey levels) are flat paper or noise and left as they are.
const MIN_SEPARATION_RANGE: u32 = 10;

/// Reads an image file as 8-bit grey (colour is converted by luma).
pub fn load_gray_image(path: &Path) -> Result<GrayImage, TargetError> {
    let reader = image::ImageReader::open(path)
        .map_err(|source| TargetError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .with_guessed_format()
        .map_err(|source| TargetError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    let decoded = reader.decode().map_err(|source| TargetError::Image {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(decoded.into_luma8())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raw(id: u32, hamming: u32) -> RawDetection {
        RawDetection {
            id,
            hamming,
            decision_margin: 50.0,
            corners_px: [Point2::origin(); 4],
        }
    }

    #[test]
    fn filter_rejects_foreign_ids_duplicates_and_high_hamming() {
        let board = Board::aprilgrid(2, 2, 0.04, 0.25, TagFamily::Tag36h11, 4, 1).unwrap();
        let options = DetectorOptions::default();
        let detections = vec![
            raw(5, 0),
            raw(3, 0),
            raw(6, 0),
            raw(6, 0),
            raw(7, 2),
            raw(4, 1),
        ];
        let result = filter(&board, &options, detections, 640, 480);
        let ids: Vec<u32> = result.tags.iter().map(|t| t.id).collect();
        assert_eq!(ids, vec![4, 5]);
        let reasons: Vec<(u32, RejectReason)> =
            result.rejected.iter().map(|r| (r.id, r.reason)).collect();
        assert_eq!(
            reasons,
            vec![
                (3, RejectReason::NotOnBoard),
                (6, RejectReason::Duplicate),
                (6, RejectReason::Duplicate),
                (7, RejectReason::Hamming),
            ]
        );
    }

    #[test]
    fn the_separation_remap_keeps_each_range_and_cuts_it_at_the_separation_level() {
        let remap = separation_remap();
        for r in 1..=255usize {
            let curve = &remap[r];
            // The range's ends stay where they are; inside it the curve only rises.
            assert_eq!((curve[0], usize::from(curve[r])), (0, r), "range {r}");
            assert!(curve[..=r].windows(2).all(|w| w[0] <= w[1]), "range {r}");
            // SEPARATION_LEVEL of the range goes to its middle (within the integer steps).
            let at_level = f64::from(curve[(SEPARATION_LEVEL * r as f64).round() as usize]);
            let middle = r as f64 / 2.0;
            assert!(
                (at_level - middle).abs() <= 1.0 + 0.02 * r as f64,
                "range {r}: {at_level} for {middle}"
            );
        }
    }

    #[test]
    fn library_corners_move_half_a_pixel_to_the_project_convention() {
        let corners = to_project_pixels([[10.5, 20.5], [11.0, 20.5], [11.0, 21.0], [10.5, 21.0]]);
        assert_eq!(corners[0], Point2::new(10.0, 20.0));
        assert_eq!(corners[2], Point2::new(10.5, 20.5));
    }

    #[test]
    fn empty_image_is_a_clear_error_and_the_detector_survives_it() {
        let board = Board::aprilgrid(1, 1, 0.04, 0.25, TagFamily::Tag36h11, 0, 1).unwrap();
        let detector = TagDetector::spawn(&board, DetectorOptions::default()).unwrap();
        let error = detector.detect(&GrayImage::new(0, 0)).unwrap_err();
        assert!(error.to_string().contains("0x0 px is too small"), "{error}");
        let blank = GrayImage::from_pixel(64, 48, image::Luma([128]));
        assert!(detector.detect(&blank).unwrap().tags.is_empty());
    }

    #[test]
    fn options_out_of_range_are_refused_naming_the_option() {
        let board = Board::aprilgrid(1, 1, 0.04, 0.25, TagFamily::Tag36h11, 0, 1).unwrap();
        let default = DetectorOptions::default();
        default.validate().unwrap();
        let cases = [
            (
                DetectorOptions {
                    decimation: 100.0,
                    ..default.clone()
                },
                "decimation: expected a value in [1, 16], found 100",
            ),
            (
                DetectorOptions {
                    decimation: f32::NAN,
                    ..default.clone()
                },
                "decimation: expected a value in [1, 16], found NaN",
            ),
            (
                DetectorOptions {
                    threads: 0,
                    ..default.clone()
                },
                "threads: expected 1 (more threads can crash the AprilTag library this build links: a race in its worker pool), found 0",
            ),
            (
                DetectorOptions {
                    quad_sigma: 1e6,
                    ..default.clone()
                },
                "quad_sigma: expected a value in [-4, 4], found 1000000",
            ),
            (
                DetectorOptions {
                    max_hamming: 5,
                    ..default.clone()
                },
                "max_hamming: expected a value in [0, 2], found 5",
            ),
        ];
        for (options, expected) in cases {
            assert_eq!(options.validate().unwrap_err().to_string(), expected);
            let error = TagDetector::spawn(&board, options).unwrap_err().to_string();
            assert!(error.ends_with(expected), "{error}");
        }
    }

    #[test]
    fn detector_handle_is_send_and_sync() {
        fn check<T: Send + Sync>() {}
        check::<TagDetector>();
    }
}
