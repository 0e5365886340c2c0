//! ROS 2 bags in, calibration samples out: what `handeye import bag` reads.
//!
//! Reads both rosbag2 storage formats (MCAP, sqlite3 `.db3`) without a ROS installation, decodes
//! `tf2_msgs/TFMessage`, `sensor_msgs/Image`, `sensor_msgs/CompressedImage` and
//! `sensor_msgs/CameraInfo` into `handeye-ros2`'s messages with its CDR codec (the one the live
//! graph uses), chains the TF tree from the base to the flange at each image stamp, and picks the
//! frames to calibrate from: the sharpest frame of each interval where the arm stood still
//! (stop-and-go), or frames at a fixed spacing while it moved (continuous, with the
//! camera-to-robot clock offset given or estimated from the data). Every frame not taken is
//! reported with why (moving, TF gap, ...).
//!
//! A bag that contradicts itself is refused where that makes a pose or the pairing of frames
//! with poses ambiguous, and warned about ([`BagWarning`]) where it does not: the TF tree's
//! contradictions (see `tf`), image stamps going back, a `nanosec` of a second or more (refused
//! when the message is decoded), sqlite3 rows of unknown topics, storage files `metadata.yaml`
//! names outside the bag folder (not read), image headers that contradict their data (a format
//! label of another codec, data past the last row, a big-endian flag on single bytes; see
//! `handeye_ros2::image::ImageLie`). docs/ros2-bags.md has the table.
//!
//! The bag is streamed, never held: its memory does not grow with its length ([`import_bag`]
//! reads it twice, message by message). A memory limit too small for the import's own room is an
//! error ([`BagError::OutOfMemory`]), not an abort.
//!
//! The samples (image, `T_base_flange`) and the intrinsics go to the caller, which writes them as
//! an ordinary session through the recorded-cell path (`handeye_session::cell::bag`); this crate
//! writes nothing. Each chosen frame is handed over the moment it is chosen ([`import_bag_to`])
//! and not kept, so the import's memory does not grow with the number of samples either: a few
//! decoded frames are alive at once ([`BagImport::frames_held_at_once`]).
//!
//! Modules: `storage` (the two storage formats; `mcap_index`, an MCAP file's index), `tf` (the TF
//! buffer), `select` (stationary intervals, sharpness, the clock offset). Sits beside
//! `handeye-ros2` (the messages, their CDR form, pixels to grey, `CameraInfo` to a camera model)
//! and uses `core`, `solve` (the offset estimate) and `vision` (board detection for it,
//! sharpness).

mod mcap_index;
pub mod select;
#[cfg(test)]
mod select_tests;
pub mod storage;
#[cfg(test)]
mod storage_tests;
pub mod tf;

use std::path::{Path, PathBuf};

use ::image::GrayImage;

use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_core::notice::{Notice, NoticeKind};
use handeye_core::setup::Setup;
use handeye_ros2::cdr::{self, CdrError};
use handeye_ros2::msg::{CameraInfo, TfMessage};
use handeye_vision::{DetectorOptions, Target};

pub use select::{Motion, OffsetChoice, OffsetEstimate, SelectOptions, Skip, SkipReason};
pub use storage::{BagFormat, TopicInfo};
pub use tf::{TfError, TfIssue, TfWarning};

/// Why a bag could not be imported. Every message names the bag and the topic, frame or field.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// A file of the bag could not be read.
    #[error("{}: cannot read", path.display())]
    Read {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// Not a bag, or a damaged one.
    #[error("{}: {problem}", path.display())]
    Storage {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// A topic asked for is not in the bag.
    #[error("{}: no topic `{topic}` ({role}); the bag has: {}", path.display(), list(available))]
    NoTopic {
        /// The bag.
        path: PathBuf,
        /// The topic asked for.
        topic: String,
        /// What it was asked for (`--image`, `--camera-info`, TF).
        role: &'static str,
        /// The topics present, with their types.
        available: Vec<String>,
    },
    /// A topic has a type this import cannot read in that role.
    #[error("{}: topic `{topic}` is a {found}, expected {expected}", path.display())]
    TopicType {
        /// The bag.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// Its type.
        found: String,
        /// The types accepted.
        expected: &'static str,
    },
    /// A message could not be decoded.
    #[error("{}: topic `{topic}`, message {index} (stamp {stamp_ns} ns)", path.display())]
    Message {
        /// The bag.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// 0-based index among the topic's messages.
        index: usize,
        /// The bag's receive time of the message, ns.
        stamp_ns: i64,
        /// What was wrong.
        #[source]
        source: MessageError,
    },
    /// The TF tree cannot give `T_base_flange` at all (a frame is missing or not connected).
    #[error("{}: TF", path.display())]
    Tf {
        /// The bag.
        path: PathBuf,
        /// What is missing.
        #[source]
        source: Box<TfError>,
    },
    /// The camera_info cannot become our camera model (or is not the images' size).
    #[error("{}: topic `{topic}`: {problem}; leave out --camera-info and the intrinsics are estimated from the frames", path.display())]
    CameraInfo {
        /// The bag.
        path: PathBuf,
        /// The camera_info topic.
        topic: String,
        /// What is wrong.
        problem: String,
    },
    /// No frame could be used.
    #[error("{}: {problem}", path.display())]
    NothingUsable {
        /// The bag.
        path: PathBuf,
        /// Why, with the counts of skipped frames.
        problem: String,
    },
    /// Image stamps go back in time by more than the allowed TF gap.
    #[error(
        "{}: topic `{topic}`: image stamps go back in time {count} time(s); message {index} is stamped {} after {} ({:.3} ms back, more than the {max_back_ms} ms --max-tf-gap-ms allows): the camera clock went back (a restart, a looped playback), so frames cannot be paired with poses by stamp; expected stamps that only increase (split the bag at message {index})",
        path.display(),
        tf::stamp_text(*to_ns),
        tf::stamp_text(*from_ns),
        (*from_ns - *to_ns) as f64 * 1e-6
    )]
    StampsBack {
        /// The bag.
        path: PathBuf,
        /// The image topic.
        topic: String,
        /// Steps back in all.
        count: usize,
        /// 0-based index of the message of the largest step back.
        index: usize,
        /// The stamp before it, ns.
        from_ns: i64,
        /// Its stamp, ns.
        to_ns: i64,
        /// The largest step back allowed, ms.
        max_back_ms: f64,
    },
    /// A step of the import does not fit the memory limits the process runs under.
    #[error(transparent)]
    Memory(#[from] handeye_core::memory::NotEnoughMemory),
    /// A thread of the import could not start (memory named when a limit is the cause).
    #[error("{0}")]
    ThreadStart(String),
    /// The bag (or a part of it) does not fit in the memory the process may use.
    #[error("not enough memory to read {} ({} MB): {problem}", path.display(), bytes.div_ceil(1 << 20))]
    OutOfMemory {
        /// The file.
        path: PathBuf,
        /// Its size, bytes.
        bytes: u64,
        /// What could not be allocated, and what to do.
        problem: String,
    },
    /// The caller could not take a chosen frame (writing it failed); its error names the file.
    #[error(transparent)]
    Output(Box<dyn std::error::Error + Send + Sync>),
    /// The clock offset could not be estimated.
    #[error("{}: estimating the camera-to-robot clock offset: {problem}", path.display())]
    Offset {
        /// The bag.
        path: PathBuf,
        /// Why.
        problem: String,
    },
}

/// What was wrong with one message.
#[derive(Debug, thiserror::Error)]
pub enum MessageError {
    /// Malformed CDR.
    #[error(transparent)]
    Cdr(#[from] CdrError),
    /// Pixels that cannot be turned into a grey image.
    #[error("{0}")]
    Pixels(String),
}

/// Something wrong with a bag that does not make the poses ambiguous: the bag is imported and
/// this is reported (printed, and recorded in the session's `import/bag-import.yaml`).
#[derive(Debug, Clone, PartialEq)]
pub enum BagWarning {
    /// The TF data contradicts itself off the chain `--base` → `--flange`, or too little to
    /// change a pose.
    Tf(Box<TfWarning>),
    /// Image stamps going back in time (receive order), by less than the allowed TF gap.
    ImageStampsBack {
        /// The image topic.
        topic: String,
        /// Steps back in all.
        count: usize,
        /// 0-based index of the message of the largest step back.
        index: usize,
        /// The stamp before it, ns.
        from_ns: i64,
        /// Its stamp, ns.
        to_ns: i64,
    },
    /// sqlite3 rows whose topic id is in no topic: their messages are lost.
    UnknownTopicRows(storage::UnknownTopicRows),
    /// Image messages whose header contradicts their data, read all the same (one warning per
    /// kind of lie).
    ImageLie {
        /// The image topic.
        topic: String,
        /// The first such message's lie.
        lie: handeye_ros2::image::ImageLie,
        /// Its 0-based index on the topic.
        index: usize,
        /// How many of the messages decoded tell it.
        count: usize,
        /// How many messages were decoded.
        decoded: usize,
    },
    /// `metadata.yaml` names storage files outside the bag's folder: they are not read.
    FilesOutsideBag(storage::FilesOutside),
}

impl BagWarning {
    /// The warning as a notice of the session imported from `bag` (`result.yaml`'s `notices:`
    /// and the report's findings): a warning, since the answer was made from data that lied
    /// about itself and a person should look before using it. The message names the bag and the
    /// kind of lie, then what [`Display`](std::fmt::Display) says.
    pub fn notice(&self, bag: &Path) -> Notice {
        Notice::warning(
            NoticeKind::BagWarning,
            format!("ROS 2 bag {} ({}): {self}", bag.display(), self.kind()),
        )
    }

    /// A short name for counting and tests.
    pub fn kind(&self) -> &'static str {
        match self {
            BagWarning::Tf(w) => w.issue.kind(),
            BagWarning::ImageStampsBack { .. } => "image stamps going back",
            BagWarning::UnknownTopicRows(_) => "rows of unknown topics",
            BagWarning::ImageLie { lie, .. } => lie.kind(),
            BagWarning::FilesOutsideBag(_) => "files outside the bag",
        }
    }
}

impl std::fmt::Display for BagWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BagWarning::Tf(w) => write!(f, "TF: {w}"),
            BagWarning::ImageStampsBack {
                topic,
                count,
                index,
                from_ns,
                to_ns,
            } => write!(
                f,
                "topic `{topic}`: image stamps go back in time {count} time(s), by up to {:.3} ms (message {index} is stamped {} after {}); within the allowed TF gap, so the frames are used in stamp order",
                (from_ns - to_ns) as f64 * 1e-6,
                tf::stamp_text(*to_ns),
                tf::stamp_text(*from_ns)
            ),
            BagWarning::UnknownTopicRows(rows) => write!(
                f,
                "{rows}; their messages are ignored (at most {:.0} % of the rows may be lost before the bag is refused)",
                storage::UNKNOWN_TOPIC_ROWS_REFUSED * 100.0
            ),
            BagWarning::ImageLie {
                topic,
                lie,
                index,
                count,
                decoded,
            } => write!(
                f,
                "topic `{topic}`: {count} of the {decoded} image(s) decoded say what their data is not: message {index} has {lie}"
            ),
            BagWarning::FilesOutsideBag(outside) => write!(f, "{outside}"),
        }
    }
}

fn list(items: &[String]) -> String {
    if items.is_empty() {
        "no topics".into()
    } else {
        items.join(", ")
    }
}

/// How to import a bag.
#[derive(Debug, Clone)]
pub struct BagOptions {
    /// The robot base frame (`base`, or `base_link`).
    pub base_frame: String,
    /// The flange frame (`tool0`, or `flange`).
    pub flange_frame: String,
    /// The image topic (`sensor_msgs/Image` or `sensor_msgs/CompressedImage`).
    pub image_topic: String,
    /// The camera_info topic; `None`: none (the intrinsics are estimated later).
    pub camera_info_topic: Option<String>,
    /// The TF topics (`/tf`, `/tf_static`).
    pub tf_topics: Vec<String>,
    /// The TF topics that hold static transforms.
    pub tf_static_topics: Vec<String>,
    /// Which frames to take and how.
    pub select: SelectOptions,
    /// Eye-in-hand or eye-to-hand (for the offset estimate's hand-eye solve).
    pub setup: Setup,
    /// The board (for the offset estimate).
    pub board: Target,
    /// Detector settings (for the offset estimate).
    pub detector: DetectorOptions,
}

/// One frame chosen for calibration (its image went to the caller as it was chosen:
/// [`import_bag_to`]).
#[derive(Debug, Clone)]
pub struct BagSample {
    /// The image's header stamp (camera clock), ns.
    pub image_stamp_ns: i64,
    /// The same instant on the robot (TF) clock, ns: `image_stamp_ns - offset`.
    pub robot_stamp_ns: i64,
    /// `T_base_flange` at `robot_stamp_ns`, interpolated.
    pub base_from_flange: Pose,
    /// [`handeye_vision::sharpness`]: Laplacian over gradient energy, about 2 for sharp edges,
    /// lower with blur.
    pub sharpness: f64,
}

/// A bag imported.
#[derive(Debug, Clone)]
pub struct BagImport {
    /// Which storage format it was.
    pub format: BagFormat,
    /// The chosen frames, in stamp order.
    pub samples: Vec<BagSample>,
    /// Every frame not chosen, with why.
    pub skipped: Vec<Skip>,
    /// Images on the image topic.
    pub images: usize,
    /// Images whose pixels were read and decoded (the frames the selection looked at: the
    /// stationary ones, or the sampled ones; never a frame rejected from its stamp and the TF).
    pub decoded: usize,
    /// Intrinsics from camera_info, when a topic was given.
    pub camera: Option<CameraModel>,
    /// The camera-to-robot clock offset used (s), and how it was found.
    pub offset: OffsetEstimate,
    /// What is wrong with the bag but did not stop the import.
    pub warnings: Vec<BagWarning>,
    /// The most decoded frames that were alive at once (pass 2's workers' frames and bests, the
    /// frame being handed over): a few, whatever the number of samples.
    pub frames_held_at_once: usize,
}

/// A frame as [`import_bag_to`] hands it over, the moment it is chosen.
#[derive(Debug, Clone, Copy)]
pub struct ChosenFrame<'a> {
    /// Its number: 0, 1, ... in stamp order.
    pub index: usize,
    /// Where and when it was taken.
    pub sample: &'a BagSample,
    /// Its 8-bit grey image, dropped when the sink returns (its size checked against the
    /// camera_info's).
    pub image: &'a GrayImage,
    /// The camera_info's intrinsics, when the bag has them (the same for every frame; known
    /// before the first frame is chosen, so a sink can measure the board in each frame as it
    /// comes).
    pub camera: Option<&'a CameraModel>,
}

/// Where [`import_bag_to`] hands each chosen frame, as it is chosen. An error stops the import
/// ([`BagError::Output`]).
pub type FrameSink<'s> =
    dyn FnMut(ChosenFrame<'_>) -> Result<(), Box<dyn std::error::Error + Send + Sync>> + 's;

/// What pass 1 keeps of a message.
enum Payload {
    Tf(Result<Vec<tf::EdgeSample>, CdrError>),
    Info(Box<Result<CameraInfo, CdrError>>),
    /// The header stamp only: the pixels are read again in pass 2 if the frame is looked at.
    Image(Result<i64, CdrError>),
}

struct Pass1 {
    /// Index into the wanted topics.
    topic: usize,
    log_time_ns: i64,
    location: storage::Location,
    payload: Payload,
}

/// The topics an import reads, found in the bag and of the types it reads.
struct WantedTopics {
    /// The image topic's images are `sensor_msgs/msg/CompressedImage`.
    compressed: bool,
    /// The camera_info topic, when one was given.
    info: Option<TopicInfo>,
}

/// The image, camera_info and TF topics of `options` in the bag's `topics`, each of its
/// expected type; a missing one is named with the topics the bag has. At least one TF topic
/// must exist (a missing /tf_static is normal: it may be in /tf).
fn wanted_topics(
    path: &Path,
    topics: &[TopicInfo],
    options: &BagOptions,
) -> Result<WantedTopics, BagError> {
    let find = |topic: &str, role: &'static str| -> Result<TopicInfo, BagError> {
        topics
            .iter()
            .find(|t| t.name == topic)
            .cloned()
            .ok_or_else(|| BagError::NoTopic {
                path: path.to_path_buf(),
                topic: topic.to_string(),
                role,
                available: topics
                    .iter()
                    .map(|t| format!("{} ({}, {} messages)", t.name, t.type_name, t.count))
                    .collect(),
            })
    };
    let image = find(&options.image_topic, "--image")?;
    let compressed = match image.type_name.as_str() {
        "sensor_msgs/msg/Image" => false,
        "sensor_msgs/msg/CompressedImage" => true,
        other => {
            return Err(BagError::TopicType {
                path: path.to_path_buf(),
                topic: image.name.clone(),
                found: other.to_string(),
                expected: "sensor_msgs/msg/Image or sensor_msgs/msg/CompressedImage",
            })
        }
    };
    let info = options
        .camera_info_topic
        .as_deref()
        .map(|t| find(t, "--camera-info"))
        .transpose()?;
    if let Some(info) = &info {
        expect_type(path, info, "sensor_msgs/msg/CameraInfo")?;
    }
    let tf_present: Vec<&TopicInfo> = options
        .tf_topics
        .iter()
        .filter_map(|name| topics.iter().find(|t| &t.name == name))
        .collect();
    if tf_present.is_empty() {
        find(
            options.tf_topics.first().map_or("/tf", |s| s.as_str()),
            "TF",
        )?;
    }
    for t in &tf_present {
        expect_type(path, t, "tf2_msgs/msg/TFMessage")?;
    }
    Ok(WantedTopics { compressed, info })
}

/// The lens of the first camera_info message, when a topic was given (it must hold one).
/// The frame size pass 2's memory is counted at when the bag has no camera_info: 1920x1080.
const UNKNOWN_FRAME_PIXELS: u64 = 1920 * 1080;

/// How many threads read, decode and score pass 2's frames: `-j` (the detector options' `jobs`)
/// or one per core (at most four), as many as the memory limits leave room for. Each holds a
/// window of one frame: its message (up to 3 bytes a pixel, or a compressed one decoded to
/// colour), its grey image and the sharpness filter's copy.
fn decoding_workers(camera: Option<&CameraModel>, options: &BagOptions) -> Result<usize, BagError> {
    let pixels = camera.map_or(UNKNOWN_FRAME_PIXELS, |c| {
        u64::from(c.width) * u64::from(c.height)
    });
    let window = 8 * pixels;
    let wanted = options
        .detector
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get().min(4)));
    let fit = handeye_core::memory::how_many_fit(
        |n| format!("reading the bag's frames with {n} thread(s)"),
        0,
        window,
        wanted,
    )?;
    if fit < wanted {
        tracing::warn!(
            "{fit} thread(s) read the bag's frames instead of {wanted}: the memory limit leaves room for {fit}"
        );
    }
    Ok(fit)
}

fn camera_of(
    path: &Path,
    info_topic: Option<&TopicInfo>,
    first: Option<&CameraInfo>,
) -> Result<Option<CameraModel>, BagError> {
    let Some(topic) = info_topic else {
        return Ok(None);
    };
    let problem = |problem: String| BagError::CameraInfo {
        path: path.to_path_buf(),
        topic: topic.name.clone(),
        problem,
    };
    let info = first.ok_or_else(|| problem("no message".into()))?;
    info.camera_model().map(Some).map_err(problem)
}

/// Image stamps in receive order: a small step back is delivery order (the frames are sorted by
/// stamp; a warning); a large one, past the TF gap interpolated across, is a camera clock that
/// went back, and pairing by stamp fails (an error).
fn image_stamps_back(
    path: &Path,
    images: &[select::ImageRef],
    options: &BagOptions,
) -> Result<Option<BagWarning>, BagError> {
    let max_back_ns = select::seconds_to_ns(options.select.max_tf_gap_s);
    let mut back: Option<(usize, i64, i64)> = None;
    let mut back_count = 0;
    for pair in images.windows(2) {
        let (before, after) = (pair[0].stamp_ns, pair[1].stamp_ns);
        if after < before {
            back_count += 1;
            if back.is_none_or(|(_, f, t)| before - after > f - t) {
                back = Some((pair[1].index, before, after));
            }
        }
    }
    let Some((index, from_ns, to_ns)) = back else {
        return Ok(None);
    };
    if from_ns - to_ns > max_back_ns {
        return Err(BagError::StampsBack {
            path: path.to_path_buf(),
            topic: options.image_topic.clone(),
            count: back_count,
            index,
            from_ns,
            to_ns,
            max_back_ms: options.select.max_tf_gap_s * 1e3,
        });
    }
    Ok(Some(BagWarning::ImageStampsBack {
        topic: options.image_topic.clone(),
        count: back_count,
        index,
        from_ns,
        to_ns,
    }))
}

/// What the bag's storage says that does not stop the import: `metadata.yaml` naming files
/// outside the folder, sqlite3 rows of unknown topics (refused above
/// [`storage::UNKNOWN_TOPIC_ROWS_REFUSED`] of the rows).
fn storage_warnings(bag: &storage::Bag) -> Result<Vec<BagWarning>, BagError> {
    let mut warnings: Vec<BagWarning> = bag
        .files_outside()
        .cloned()
        .map(BagWarning::FilesOutsideBag)
        .into_iter()
        .collect();
    for rows in bag.unknown_topic_rows()? {
        if rows.fraction() > storage::UNKNOWN_TOPIC_ROWS_REFUSED {
            return Err(BagError::Storage {
                path: rows.file.clone(),
                problem: format!(
                    "damaged sqlite3 bag: {rows}; more than {:.0} % of the rows lost (they may be the frames or TF the calibration needs); expected every row to name a topic of table `topics`",
                    storage::UNKNOWN_TOPIC_ROWS_REFUSED * 100.0
                ),
            });
        }
        warnings.push(BagWarning::UnknownTopicRows(rows));
    }
    Ok(warnings)
}

/// Reads a bag and picks the frames to calibrate from, without their images: [`import_bag_to`]
/// with a sink that drops them.
pub fn import_bag(path: &Path, options: &BagOptions) -> Result<BagImport, BagError> {
    import_bag_to(path, options, &mut |_| Ok(()))
}

/// Reads a bag and picks the frames to calibrate from (see the module docs), handing each
/// chosen frame to `sink` as it is chosen (in stamp order; its size is checked against the
/// camera_info first). The bag is read twice, message by message, never whole: pass 1 reads the
/// TF, the camera_info and the image stamps; pass 2 reads and decodes only the frames the
/// selection looks at, a few at a time.
pub fn import_bag_to(
    path: &Path,
    options: &BagOptions,
    sink: &mut FrameSink<'_>,
) -> Result<BagImport, BagError> {
    let bag = storage::Bag::open(path)?;
    let mut wanted: Vec<String> = options.tf_topics.clone();
    wanted.push(options.image_topic.clone());
    if let Some(info) = &options.camera_info_topic {
        wanted.push(info.clone());
    }
    let WantedTopics {
        compressed,
        info: info_topic,
    } = wanted_topics(path, &bag.topics()?, options)?;

    let mut warnings = storage_warnings(&bag)?;
    // Pass 1: every message of the wanted topics, one at a time. TF and camera_info are decoded;
    // of an image only its header stamp is read and kept (with where it is, for pass 2), the
    // rest is checked when the frame is decoded. Processed in receive-time order afterwards, as
    // the recorder saw them.
    let mut reads: Vec<Pass1> = Vec::new();
    bag.for_each(&wanted, std::slice::from_ref(&options.image_topic), |m| {
        let payload = if m.topic == options.image_topic {
            Payload::Image(
                cdr::decode_header_stamp(m.data).and_then(|t| t.checked_ns("header.stamp")),
            )
        } else if Some(m.topic) == options.camera_info_topic.as_deref() {
            Payload::Info(Box::new(cdr::decode::<CameraInfo>(m.data).and_then(
                |info| {
                    info.header.stamp.checked_ns("header.stamp")?;
                    Ok(info)
                },
            )))
        } else {
            Payload::Tf(cdr::decode::<TfMessage>(m.data).and_then(|tf| tf::edge_samples(&tf)))
        };
        reads.push(Pass1 {
            topic: wanted.iter().position(|w| w == m.topic).unwrap_or(0),
            log_time_ns: m.log_time_ns,
            location: m.location,
            payload,
        });
        Ok(())
    })?;
    reads.sort_by_key(|r| r.log_time_ns);
    let mut buffer = tf::TfBuffer::default();
    let mut images = Vec::new();
    let mut infos = Vec::new();
    let mut per_topic = vec![0usize; wanted.len()];
    for r in reads {
        let index = per_topic[r.topic];
        per_topic[r.topic] += 1;
        let topic = &wanted[r.topic];
        let wrap = |source: MessageError| BagError::Message {
            path: path.to_path_buf(),
            topic: topic.clone(),
            index,
            stamp_ns: r.log_time_ns,
            source,
        };
        match r.payload {
            Payload::Image(stamp) => images.push((stamp, index, r.log_time_ns, r.location)),
            Payload::Info(info) => infos.push((*info).map_err(|e| wrap(e.into()))?),
            Payload::Tf(transforms) => {
                let is_static = options.tf_static_topics.contains(topic);
                for t in transforms.map_err(|e| wrap(e.into()))? {
                    let source = tf::TfSource {
                        topic: topic.clone(),
                        index,
                    };
                    buffer.add(t, is_static, source);
                }
            }
        }
    }
    buffer.finish();
    // The frames must be in the tree and connected before any frame is looked at.
    // A step back in time larger than the TF gap interpolated across is a clock that went back.
    let max_back_ns = select::seconds_to_ns(options.select.max_tf_gap_s);
    let tf_warnings = buffer
        .check(&options.base_frame, &options.flange_frame, max_back_ns)
        .map_err(|source| BagError::Tf {
            path: path.to_path_buf(),
            source: Box::new(source),
        })?;
    warnings.extend(tf_warnings.into_iter().map(|w| BagWarning::Tf(Box::new(w))));
    let camera = camera_of(path, info_topic.as_ref(), infos.first())?;
    let decoded = images
        .into_iter()
        .map(|(stamp, index, log_time_ns, location)| {
            stamp
                .map(|stamp_ns| select::ImageRef {
                    stamp_ns,
                    index,
                    location,
                })
                .map_err(|e| BagError::Message {
                    path: path.to_path_buf(),
                    topic: options.image_topic.clone(),
                    index,
                    stamp_ns: log_time_ns,
                    source: e.into(),
                })
        })
        .collect::<Result<Vec<_>, _>>()?;
    warnings.extend(image_stamps_back(path, &decoded, options)?);
    // Pass 2: the selection reads and decodes only the frames it looks at (see `select`).
    let mut frames = select::Frames {
        reader: bag.message_at(&options.image_topic),
        compressed,
        decoded: 0,
        workers: decoding_workers(camera.as_ref(), options)?,
        held: select::FrameCount::default(),
        lies: select::ImageLies::default(),
    };
    let mut taken = 0;
    let mut hand_on = |sample: &BagSample, image: &GrayImage| -> Result<(), BagError> {
        // The camera_info's size is the images' before anything is handed on.
        if let (Some(camera), 0) = (&camera, taken) {
            frame_size_check(path, camera, info_topic.as_ref(), options, image)?;
        }
        sink(ChosenFrame {
            index: taken,
            sample,
            image,
            camera: camera.as_ref(),
        })
        .map_err(BagError::Output)?;
        taken += 1;
        Ok(())
    };
    let selected = select::select(
        path,
        &decoded,
        &mut frames,
        &buffer,
        camera.as_ref(),
        options,
        &mut hand_on,
    )?;
    let decoded_count = frames.decoded;
    warnings.extend(image_lies(frames.lies, &options.image_topic, decoded_count));
    Ok(BagImport {
        format: bag.format(),
        samples: selected.samples,
        skipped: selected.skipped,
        images: decoded.len(),
        decoded: frames.decoded,
        frames_held_at_once: frames.held.peak(),
        camera,
        offset: selected.offset,
        warnings,
    })
}

/// The images' tolerated lies as warnings: each kind once, with its count among the `decoded`.
fn image_lies(
    lies: select::ImageLies,
    topic: &str,
    decoded: usize,
) -> impl Iterator<Item = BagWarning> + '_ {
    lies.into_counts()
        .into_iter()
        .map(move |(count, lie, index)| BagWarning::ImageLie {
            topic: topic.to_string(),
            lie,
            index,
            count,
            decoded,
        })
}

/// The camera_info's size must be the images'.
fn frame_size_check(
    path: &Path,
    camera: &CameraModel,
    info_topic: Option<&TopicInfo>,
    options: &BagOptions,
    image: &GrayImage,
) -> Result<(), BagError> {
    if (image.width(), image.height()) == (camera.width, camera.height) {
        return Ok(());
    }
    Err(BagError::CameraInfo {
        path: path.to_path_buf(),
        topic: info_topic.map(|t| t.name.clone()).unwrap_or_default(),
        problem: format!(
            "{}x{} px, but the images on `{}` are {}x{} px",
            camera.width,
            camera.height,
            options.image_topic,
            image.width(),
            image.height()
        ),
    })
}

fn expect_type(path: &Path, topic: &TopicInfo, expected: &'static str) -> Result<(), BagError> {
    if topic.type_name == expected {
        Ok(())
    } else {
        Err(BagError::TopicType {
            path: path.to_path_buf(),
            topic: topic.name.clone(),
            found: topic.type_name.clone(),
            expected,
        })
    }
}

#[cfg(test)]
mod camera_info_tests {
    use super::*;
    use handeye_core::camera_model::Distortion;

    fn info(model: &str, d: Vec<f64>) -> CameraInfo {
        CameraInfo {
            width: 640,
            height: 480,
            distortion_model: model.into(),
            d,
            k: [600.0, 0.0, 320.0, 0.0, 600.0, 240.0, 0.0, 0.0, 1.0],
            ..CameraInfo::default()
        }
    }

    /// A bag's camera_info reads as its driver's file does (a fisheye lens too); one that cannot
    /// be used says which topic and what to do instead: import without `--camera-info`.
    #[test]
    fn a_bags_camera_info_is_read_as_a_file_is_or_refused_with_the_way_round() {
        let topic = TopicInfo {
            name: "/camera/camera_info".into(),
            type_name: "sensor_msgs/msg/CameraInfo".into(),
            count: 1,
        };
        let path = Path::new("run.mcap");
        let fisheye = info("equidistant", vec![0.1, -0.02, 0.003, -0.0004]);
        let model = camera_of(path, Some(&topic), Some(&fisheye))
            .unwrap()
            .unwrap();
        assert!(matches!(model.distortion, Distortion::Equidistant { k1, .. } if k1 == 0.1));
        let mut binned = info("plumb_bob", vec![0.0; 5]);
        binned.binning_x = 2;
        let refused = camera_of(path, Some(&topic), Some(&binned))
            .unwrap_err()
            .to_string();
        for words in [
            "/camera/camera_info",
            "binning 2x0",
            "leave out --camera-info",
        ] {
            assert!(refused.contains(words), "{words:?} not in {refused}");
        }
    }
}
