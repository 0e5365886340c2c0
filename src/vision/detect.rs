//! AprilTag detection of a board's tags, on a dedicated thread.
//!
//! The C detector (`apriltag::Detector`) is not `Send`, so [`TagDetector::spawn`] builds it on
//! its own thread and [`TagDetector::detect`] sends each image over a channel and gets plain
//! data back; the handle is `Send + Sync`. Detections are filtered against the board: ids not
//! on the board, ids seen twice (both copies dropped) and hamming distances above the
//! threshold are rejected and reported.
//!
//! Pixel convention: the C library puts pixel centres at `i + 0.5`; this project (OpenCV, ROS,
//! Kalibr) puts them at integers. The conversion (subtract 0.5 px) happens here, in
//! [`to_project_pixels`], and nowhere else. Depends on `vision::board`, `vision::family`.

use std::path::Path;
use std::sync::mpsc;
use std::thread::JoinHandle;

use apriltag::{Detector, Image};
use apriltag_sys as sys;
use image::GrayImage;
use nalgebra::{Point2, Point3};

use super::board::Board;
use super::family::TagFamily;
use super::TargetError;

/// Detector settings.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectorOptions {
    /// Quad decimation: 2 halves the resolution of the quad search (corners are still refined
    /// at full resolution); as accurate as 1 on these tag sizes and ~4x faster.
    pub decimation: f32,
    /// Worker threads inside the C detector.
    pub threads: u8,
    /// Gaussian blur sigma applied before the quad search (0 = none), px.
    pub quad_sigma: f32,
    /// Highest accepted hamming distance (bit errors corrected); 0-2.
    pub max_hamming: u32,
}

impl Default for DetectorOptions {
    fn default() -> Self {
        DetectorOptions {
            decimation: 2.0,
            threads: 2,
            quad_sigma: 0.0,
            max_hamming: 1,
        }
    }
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
    /// Accepted `decimation`: beyond 8 the quad search misses all but huge tags.
    pub const DECIMATION: std::ops::RangeInclusive<f32> = 1.0..=8.0;
    /// Accepted `threads`.
    pub const THREADS: std::ops::RangeInclusive<u8> = 1..=64;
    /// Accepted `quad_sigma`, px: a stronger blur erases the tags and slows every frame.
    pub const QUAD_SIGMA: std::ops::RangeInclusive<f32> = 0.0..=10.0;
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
            return bad("threads", self.threads, &Self::THREADS);
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
    /// Width of the image searched, px.
    pub image_width: u32,
    /// Height of the image searched, px.
    pub image_height: u32,
}

impl BoardDetection {
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

type Job = (GrayImage, mpsc::Sender<Result<Vec<RawDetection>, String>>);

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
        let thread_options = options.clone();
        let thread = std::thread::Builder::new()
            .name("apriltag".to_string())
            .spawn(move || detector_thread(family, border_bits, thread_options, receiver, ready_tx))
            .map_err(|error| TargetError::Detector {
                reason: format!("cannot start the detector thread: {error}"),
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
    pub fn detect(&self, image: &GrayImage) -> Result<BoardDetection, TargetError> {
        let (reply_tx, reply_rx) = mpsc::channel();
        self.jobs
            .as_ref()
            .ok_or(TargetError::DetectorStopped)?
            .send((image.clone(), reply_tx))
            .map_err(|_| TargetError::DetectorStopped)?;
        let raw = reply_rx
            .recv()
            .map_err(|_| TargetError::DetectorStopped)?
            .map_err(|reason| TargetError::Detector { reason })?;
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
        image_width,
        image_height,
    }
}

/// The one place the AprilTag library's pixel convention (centres at `i + 0.5`) becomes the
/// project's (centres at integers).
fn to_project_pixels(corners: [[f64; 2]; 4]) -> [Point2<f64>; 4] {
    corners.map(|[x, y]| Point2::new(x - 0.5, y - 0.5))
}

/// Owns the C family struct the detector points at; frees it after the detector.
struct OwnedFamily {
    family: TagFamily,
    ptr: *mut sys::apriltag_family_t,
}

impl OwnedFamily {
    fn create(family: TagFamily, border_bits: u32) -> Result<Self, String> {
        // SAFETY: the create functions return a fresh heap family or NULL (checked below).
        let ptr = unsafe {
            match family {
                TagFamily::Tag36h11 => sys::tag36h11_create(),
                TagFamily::TagStandard41h12 => sys::tagStandard41h12_create(),
            }
        };
        if ptr.is_null() {
            return Err(format!("cannot allocate the {} family", family.name()));
        }
        let owned = OwnedFamily { family, ptr };
        match border_bits {
            1 => {}
            2 => {
                // SAFETY: ptr is a valid family we own exclusively; bit_x / bit_y hold nbits
                // entries. Kalibr's layout has the same codes with a border one cell wider on
                // each side: the border square grows by 2 cells and the data moves in by 1.
                unsafe {
                    let f = &mut *owned.ptr;
                    if f.reversed_border {
                        return Err(format!("{} has no 2-cell-border layout", family.name()));
                    }
                    f.width_at_border += 2;
                    f.total_width += 2;
                    for i in 0..f.nbits as usize {
                        *f.bit_x.add(i) = (*f.bit_x.add(i)).wrapping_add(1);
                        *f.bit_y.add(i) = (*f.bit_y.add(i)).wrapping_add(1);
                    }
                }
            }
            other => return Err(format!("border_bits must be 1 or 2, found {other}")),
        }
        Ok(owned)
    }
}

impl Drop for OwnedFamily {
    fn drop(&mut self) {
        // SAFETY: ptr came from the matching create function and is freed exactly once, after
        // the detector that referenced it was destroyed (see detector_thread's drop order).
        unsafe {
            match self.family {
                TagFamily::Tag36h11 => sys::tag36h11_destroy(self.ptr),
                TagFamily::TagStandard41h12 => sys::tagStandard41h12_destroy(self.ptr),
            }
        }
    }
}

fn build_detector(family: &OwnedFamily, options: &DetectorOptions) -> Result<Detector, String> {
    // SAFETY: apriltag_detector_create returns a fresh detector or NULL (checked); adding the
    // family stores the pointer, which outlives the detector (dropped after it). Detector
    // takes ownership of the detector pointer and destroys it on drop.
    let mut detector = unsafe {
        let raw = sys::apriltag_detector_create();
        if raw.is_null() {
            return Err("apriltag_detector_create failed".to_string());
        }
        // The quick-decode table grows steeply with corrected bits; 2 covers max_hamming ≤ 2.
        sys::apriltag_detector_add_family_bits(raw, family.ptr, options.max_hamming.max(1) as i32);
        Detector::from_raw(raw)
    };
    detector.set_decimation(options.decimation);
    detector.set_thread_number(options.threads.max(1));
    detector.set_sigma(options.quad_sigma);
    detector.set_refine_edges(true);
    Ok(detector)
}

fn detector_thread(
    family: TagFamily,
    border_bits: u32,
    options: DetectorOptions,
    jobs: mpsc::Receiver<Job>,
    ready: mpsc::Sender<Result<(), String>>,
) {
    let owned_family = match OwnedFamily::create(family, border_bits) {
        Ok(f) => f,
        Err(reason) => {
            let _ = ready.send(Err(reason));
            return;
        }
    };
    let mut detector = match build_detector(&owned_family, &options) {
        Ok(d) => d,
        Err(reason) => {
            let _ = ready.send(Err(reason));
            return;
        }
    };
    let _ = ready.send(Ok(()));
    while let Ok((image, reply)) = jobs.recv() {
        let detections = detect_once(&mut detector, &image);
        let _ = reply.send(detections);
    }
    drop(detector);
    drop(owned_family);
}

fn detect_once(detector: &mut Detector, image: &GrayImage) -> Result<Vec<RawDetection>, String> {
    let (width, height) = (image.width() as usize, image.height() as usize);
    if width == 0 || height == 0 {
        return Err(format!("empty image ({width}x{height} px)"));
    }
    let mut buffer = Image::zeros_with_alignment(width, height, 96)
        .map_err(|error| format!("cannot allocate a {width}x{height} detector image: {error}"))?;
    let stride = buffer.stride();
    let data = buffer.as_slice_mut();
    for (y, row) in image.as_raw().chunks_exact(width).enumerate() {
        data[y * stride..y * stride + width].copy_from_slice(row);
    }
    Ok(detector
        .detect(&buffer)
        .into_iter()
        .map(|d| RawDetection {
            id: d.id() as u32,
            hamming: d.hamming() as u32,
            decision_margin: d.decision_margin(),
            corners_px: to_project_pixels(d.corners()),
        })
        .collect())
}

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
        assert!(error.to_string().contains("empty image"), "{error}");
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
                "decimation: expected a value in [1, 8], found 100",
            ),
            (
                DetectorOptions {
                    decimation: f32::NAN,
                    ..default.clone()
                },
                "decimation: expected a value in [1, 8], found NaN",
            ),
            (
                DetectorOptions {
                    threads: 0,
                    ..default.clone()
                },
                "threads: expected a value in [1, 64], found 0",
            ),
            (
                DetectorOptions {
                    quad_sigma: 1e6,
                    ..default.clone()
                },
                "quad_sigma: expected a value in [0, 10], found 1000000",
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
