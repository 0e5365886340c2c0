//! `camera.backend: ros2`: frames from a ROS 2 camera node's `sensor_msgs/Image` (mono8, mono16,
//! rgb8, bgr8, bayer) or `CompressedImage` topic, read best effort (the sensor-data QoS camera
//! drivers publish with), and its `CameraInfo` checked against the cell's intrinsics.
//!
//! A message larger than any frame of the intrinsics' size can be ([`max_frame_bytes`]) is
//! refused as it arrives, its pixels dropped at once, and named with the topic, its size and the
//! bound: at open, before the arm moves, or at the pose whose frame it is (issue #40: 100 MB
//! frames were otherwise held, or never came through whole and read as a silent topic).
//!
//! A frame counts only if its header stamp is at or after the instant the session asks for
//! (the moment the arm settled, measured from `/joint_states`): a frame exposed while the arm
//! still moved is never used. Stamps are the camera node's clock; on one machine (or with
//! synchronised clocks, as ROS needs anyway) they compare with ours.

use std::sync::{Arc, Condvar, Mutex};
use std::thread;
use std::time::{Duration, Instant, SystemTime};

use futures::StreamExt;

use handeye_camera::{Camera, CameraError, Frame};
use handeye_core::camera_model::CameraModel;

use crate::image::{compressed_to_gray, raw_to_gray};
use crate::link::{sensor_data_qos, Ros2Link};
use crate::msg::{CameraInfo, CompressedImage, Image};

/// The camera's topics and timeout.
#[derive(Debug, Clone)]
pub struct CameraOptions {
    /// The image topic.
    pub image_topic: String,
    /// It carries `CompressedImage`.
    pub compressed: bool,
    /// The `CameraInfo` topic, checked against `model` at open.
    pub camera_info_topic: Option<String>,
    /// How long `grab` waits for a fresh frame; also the wait for the first message at open.
    pub timeout: Duration,
    /// The cell's intrinsics.
    pub model: CameraModel,
}

/// The newest message, undecoded (only the frame a grab takes is decoded).
enum Pixels {
    Raw(Image),
    Compressed(CompressedImage),
    /// Over [`max_frame_bytes`]: refused as it came, only what it was is kept.
    Oversized(Oversized),
}

/// A message refused for its size.
struct Oversized {
    /// The bytes of its pixels (`data`).
    bytes: usize,
    /// What it said it held: `10000x10000 mono8`, `jpeg`.
    held: String,
}

/// The widest pixel ROS's image encodings have: 8 bytes (`rgba16`, `64FC1`).
const WIDEST_PIXEL_BYTES: u64 = 8;

/// The most bytes a frame of `model`'s size can take in any encoding (`rgba16` with no row
/// padding beyond a byte a pixel): 7.4 MB for 1280x720 px. A compressed frame is never larger
/// than its raw form in practice, so the same bound holds for it.
pub fn max_frame_bytes(model: &CameraModel) -> u64 {
    u64::from(model.width) * u64::from(model.height) * WIDEST_PIXEL_BYTES
}

/// `bytes` in megabytes, as a person reads it.
fn megabytes(bytes: u64) -> String {
    format!("{:.1} MB", bytes as f64 / 1e6)
}

/// What a topic's message over the bound is called: its topic, size, what it held and the
/// bound.
fn oversized_reason(topic: &str, o: &Oversized, model: &CameraModel) -> String {
    format!(
        "the images on {topic} are {} ({}), over the {} a {}x{} px frame takes at most ({WIDEST_PIXEL_BYTES} bytes a pixel, the widest encoding)",
        megabytes(o.bytes as u64),
        o.held,
        megabytes(max_frame_bytes(model)),
        model.width,
        model.height,
    )
}

/// What to look at when a topic's frames are over the bound.
const OVERSIZED_CHECK: &str =
    "is this the camera the intrinsics are for, streaming at their resolution?";

/// `newest`, or what it was when its pixels exceed `bound` bytes (dropped here, at once).
fn bounded(newest: Newest, bound: u64) -> Newest {
    let (bytes, held) = match &newest.pixels {
        Pixels::Raw(m) => (
            m.data.len(),
            format!("{}x{} {}", m.width, m.height, m.encoding),
        ),
        Pixels::Compressed(m) => (m.data.len(), m.format.clone()),
        Pixels::Oversized(_) => return newest,
    };
    if bytes as u64 <= bound {
        return newest;
    }
    Newest {
        pixels: Pixels::Oversized(Oversized { bytes, held }),
        ..newest
    }
}

struct Newest {
    pixels: Pixels,
    stamp: SystemTime,
    /// When it came.
    received: Instant,
}

#[derive(Default)]
struct Slot {
    newest: Mutex<Option<Newest>>,
    info: Mutex<Option<CameraInfo>>,
    changed: Condvar,
}

/// The ROS 2 camera.
pub struct Ros2Camera {
    options: CameraOptions,
    slot: Arc<Slot>,
    _stop_reader: smol::channel::Sender<()>,
    link: Ros2Link,
}

fn open_error(what: String) -> CameraError {
    CameraError::Open(what)
}

impl Ros2Camera {
    /// Subscribes; waits (up to the timeout) for the first frame and, when configured, the
    /// camera_info, whose size must be the intrinsics' size.
    pub fn open(link: &Ros2Link, options: CameraOptions) -> Result<Ros2Camera, CameraError> {
        let slot = Arc::new(Slot::default());
        let (stop_tx, stop_rx) = smol::channel::bounded::<()>(1);
        let topic = options.image_topic.clone();
        let err = |e: crate::Ros2Error| open_error(e.to_string());
        let info_sub = match &options.camera_info_topic {
            Some(t) => Some(
                link.subscribe::<CameraInfo>(t, sensor_data_qos())
                    .map_err(err)?,
            ),
            None => None,
        };
        // Only the newest message is kept (undecoded), in DDS's cache as in the slot: memory is
        // a frame or two whatever the rate, and a refused frame's size at most.
        let bound = max_frame_bytes(&options.model);
        let frames = if options.compressed {
            newest_of::<CompressedImage>(link, &topic, bound, |msg| Newest {
                stamp: msg.header.stamp.to_system(),
                received: Instant::now(),
                pixels: Pixels::Compressed(msg),
            })
        } else {
            newest_of::<Image>(link, &topic, bound, |msg| Newest {
                stamp: msg.header.stamp.to_system(),
                received: Instant::now(),
                pixels: Pixels::Raw(msg),
            })
        }
        .map_err(err)?;
        spawn_reader(slot.clone(), stop_rx, frames, info_sub)?;
        let camera = Ros2Camera {
            options,
            slot,
            _stop_reader: stop_tx,
            link: link.clone(),
        };
        camera.check_info()?;
        camera.check_frames()?;
        Ok(camera)
    }

    /// Waits (up to the timeout) for a first frame on the image topic, so a topic nobody
    /// publishes is named before the arm moves, not after the first move (issue #39), and so is
    /// one whose frames are over the size bound (#40).
    fn check_frames(&self) -> Result<(), CameraError> {
        let deadline = Instant::now() + self.options.timeout;
        let mut newest = self.slot.newest.lock().unwrap_or_else(|p| p.into_inner());
        while newest.is_none() && Instant::now() < deadline {
            newest = self
                .slot
                .changed
                .wait_timeout(newest, Duration::from_millis(50))
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
        let topic = &self.options.image_topic;
        match newest.as_ref().map(|n| &n.pixels) {
            Some(Pixels::Oversized(o)) => {
                return Err(open_error(format!(
                    "{}: refused, nothing has moved; {OVERSIZED_CHECK}",
                    oversized_reason(topic, o, &self.options.model)
                )))
            }
            Some(_) => return Ok(()),
            None => {}
        }
        let kind = if self.options.compressed {
            "CompressedImage"
        } else {
            "Image"
        };
        // The image topics heard on the domain: the one meant is usually among them.
        let heard: Vec<String> = self
            .link
            .heard_topics()
            .into_iter()
            .filter(|(_, ty)| {
                ty == "sensor_msgs/msg/Image" || ty == "sensor_msgs/msg/CompressedImage"
            })
            .map(|(name, ty)| format!("{name} ({ty})"))
            .collect();
        let written = heard.iter().any(|h| h.starts_with(&format!("{topic} (")));
        let heard = if heard.is_empty() {
            "no image topic is heard on this domain".to_string()
        } else {
            format!("image topics heard on this domain: {}", heard.join(", "))
        };
        if written {
            // A writer of the topic is there, yet no message came whole. DDS hands over only
            // whole messages, so their size is not known here; far too large ones are what
            // never arrive (their fragments are lost on the way).
            return Err(open_error(format!(
                "no whole image on {topic} within {:.1} s although a writer of it is on the graph, nothing has moved: either it sends nothing (a camera not streaming, or waiting for a trigger) or its frames are too large to come through whole (far over {}, the most a {}x{} px frame takes: a camera at another resolution than the intrinsics', or a node sending oversized messages) ({heard})",
                self.options.timeout.as_secs_f64(),
                megabytes(max_frame_bytes(&self.options.model)),
                self.options.model.width,
                self.options.model.height,
            )));
        }
        Err(open_error(format!(
            "no image on {topic} within {:.1} s, nothing has moved: is the camera node running, on this domain id, publishing sensor_msgs/{kind} under that name? ({heard})",
            self.options.timeout.as_secs_f64(),
        )))
    }

    /// What a grab that waited its timeout without a frame stamped after `not_before` says,
    /// given the newest message heard: one over the size bound is named as such (later ones
    /// of that size may not have come whole), an old one points at the clocks.
    /// `waiting_since`: when the grab began to wait.
    fn no_fresh_frame(
        &self,
        newest: Option<&Newest>,
        not_before: SystemTime,
        waiting_since: Instant,
    ) -> CameraError {
        let topic = &self.options.image_topic;
        let waited = self.options.timeout.as_secs_f64();
        if let Some(Newest {
            pixels: Pixels::Oversized(o),
            ..
        }) = newest
        {
            return CameraError::Frame {
                path: topic.clone(),
                reason: format!(
                    "no whole frame stamped after the arm settled within {waited:.1} s, and the last message heard was refused: {}; {OVERSIZED_CHECK}",
                    oversized_reason(topic, o, &self.options.model)
                ),
            };
        }
        let why = match newest {
            // Frames keep coming, stamped before: the clocks.
            Some(n) if n.received >= waiting_since => format!(
                "the newest is stamped {:.3} s before: is the camera node's clock in step with this machine's?",
                not_before.duration_since(n.stamp).unwrap_or_default().as_secs_f64()
            ),
            // None came whole while waiting: DDS hands over only whole messages, so frames
            // grown too large to arrive look like frames that stopped.
            Some(n) => format!(
                "none came whole while waiting, the last {:.1} s before the arm settled: the camera node stopped, or its frames grew too large to come through whole (far over {}, the most a {}x{} px frame takes)",
                not_before.duration_since(n.stamp).unwrap_or_default().as_secs_f64(),
                megabytes(max_frame_bytes(&self.options.model)),
                self.options.model.width,
                self.options.model.height,
            ),
            None => "none heard at all: is the camera node running, on this domain id, with this topic name?".into(),
        };
        CameraError::Backend(
            format!(
                "no frame on {topic} stamped after the arm settled within {waited:.1} s ({why})"
            )
            .into(),
        )
    }

    fn check_info(&self) -> Result<(), CameraError> {
        let Some(topic) = &self.options.camera_info_topic else {
            return Ok(());
        };
        let deadline = Instant::now() + self.options.timeout;
        let mut info = self.slot.info.lock().unwrap_or_else(|p| p.into_inner());
        while info.is_none() && Instant::now() < deadline {
            info = self
                .slot
                .changed
                .wait_timeout(info, Duration::from_millis(50))
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
        let Some(info) = info.as_ref() else {
            return Err(open_error(format!(
                "no message on {topic} within {:.1} s (is the camera node running, on this domain id?)",
                self.options.timeout.as_secs_f64()
            )));
        };
        let m = &self.options.model;
        if (info.width, info.height) != (m.width, m.height) {
            return Err(open_error(format!(
                "{topic} says the images are {}x{} px but the config's intrinsics are for {}x{} px: calibrate the camera at the resolution the node streams, or set the node's resolution",
                info.width, info.height, m.width, m.height
            )));
        }
        let (fx, fy) = (info.k[0], info.k[4]);
        if fx > 0.0 && ((fx - m.fx).abs() > 0.02 * m.fx || (fy - m.fy).abs() > 0.02 * m.fy) {
            tracing::warn!(
                "{topic}: fx, fy = {fx:.1}, {fy:.1} px differ from the config's intrinsics ({:.1}, {:.1} px) by more than 2 %; the config's are used",
                m.fx,
                m.fy
            );
        }
        Ok(())
    }
}

type ReaderFuture = std::pin::Pin<Box<dyn std::future::Future<Output = ()> + Send>>;
type FramesReader = Box<dyn FnOnce(Arc<Slot>) -> ReaderFuture + Send>;

/// How long the image reader waits for a whole message before it makes its DDS reader anew.
/// RustDDS reassembles a fragmented message in a buffer of the message's full size, made on its
/// first fragment, and keeps up to 128 unfinished ones per writer until 10 s pass without a
/// fragment: frames too large to come whole over best effort (100 MB ones) held half a gigabyte
/// within the 5 s a camera waits at open. A new reader starts with no buffer; a healthy camera
/// (a whole frame at least every 2 s) never sees this happen, and a frame of the bound, 7.4 MB,
/// comes whole well within it even at 100 Mbit/s.
const REASSEMBLY_WINDOW: Duration = Duration::from_secs(2);

/// The reader of an image topic: each message read becomes the slot's newest frame, or the
/// record of one refused when its pixels exceed `bound` bytes. After the first refused message
/// the topic's reader is dropped (its frames are not taken in any more, only the record stays to
/// name the topic to every grab), and a reader that has had nothing whole for
/// [`REASSEMBLY_WINDOW`] is made anew (dropping what it was reassembling): memory stays bounded
/// whatever arrives on the topic.
fn newest_of<M>(
    link: &Ros2Link,
    topic: &str,
    bound: u64,
    newest: fn(M) -> Newest,
) -> Result<FramesReader, crate::Ros2Error>
where
    M: crate::msg::RosType + serde::de::DeserializeOwned + Send + Sync + 'static,
{
    let first = link.subscribe_newest::<M>(topic, sensor_data_qos())?;
    let (link, topic) = (link.clone(), topic.to_string());
    Ok(Box::new(move |slot: Arc<Slot>| -> ReaderFuture {
        Box::pin(async move {
            let mut sub = first;
            while let ReaderEnd::Stale = read_whole(&sub, &slot, bound, newest).await {
                // The old reader goes first, with its unfinished buffers.
                drop(sub);
                sub = match link.subscribe_newest::<M>(&topic, sensor_data_qos()) {
                    Ok(sub) => sub,
                    Err(e) => {
                        tracing::warn!(
                            "ROS 2 camera: a new reader of {topic} could not be made: {e}"
                        );
                        return;
                    }
                };
            }
            // `sub` (the DDS reader) goes with this future: after a refused frame the topic's
            // frames are no longer taken in.
        })
    }))
}

/// Why [`read_whole`] stopped reading.
enum ReaderEnd {
    /// Nothing came whole for [`REASSEMBLY_WINDOW`].
    Stale,
    /// A message over the bound came (recorded in the slot), or the reader ended.
    Done,
}

/// Reads `sub` into `slot` until a message over `bound` comes or nothing whole comes for
/// [`REASSEMBLY_WINDOW`].
async fn read_whole<M>(
    sub: &ros2_client::Subscription<M>,
    slot: &Slot,
    bound: u64,
    newest: fn(M) -> Newest,
) -> ReaderEnd
where
    M: serde::de::DeserializeOwned + 'static,
{
    let mut stream = std::pin::pin!(sub.async_stream());
    loop {
        let next = futures::future::select(
            stream.next(),
            Box::pin(smol::Timer::after(REASSEMBLY_WINDOW)),
        )
        .await;
        let m = match next {
            futures::future::Either::Left((Some(m), _)) => m,
            futures::future::Either::Left((None, _)) => return ReaderEnd::Done,
            futures::future::Either::Right(_) => return ReaderEnd::Stale,
        };
        let m = m.map(|(msg, _)| bounded(newest(msg), bound));
        let refused = matches!(&m, Ok(n) if matches!(n.pixels, Pixels::Oversized(_)));
        store(slot, m);
        if refused {
            tracing::info!("ROS 2 camera: a frame over the size bound came; no more are read");
            return ReaderEnd::Done;
        }
    }
}

fn spawn_reader(
    slot: Arc<Slot>,
    stop: smol::channel::Receiver<()>,
    frames: FramesReader,
    info: Option<ros2_client::Subscription<CameraInfo>>,
) -> Result<(), CameraError> {
    thread::Builder::new()
        .name("ros2-camera".into())
        .spawn(move || {
            let info_slot = slot.clone();
            let info_task = async move {
                match info {
                    Some(sub) => {
                        sub.async_stream()
                            .for_each(|m| {
                                if let Ok((msg, _)) = m {
                                    *info_slot.info.lock().unwrap_or_else(|p| p.into_inner()) =
                                        Some(msg);
                                    info_slot.changed.notify_all();
                                }
                                futures::future::ready(())
                            })
                            .await
                    }
                    None => futures::future::pending::<()>().await,
                }
            };
            let all = futures::future::join(frames(slot), info_task);
            smol::block_on(futures::future::select(
                Box::pin(all),
                Box::pin(stop.recv()),
            ));
        })
        .map(|_| ())
        .map_err(|e| open_error(format!("cannot start the ROS 2 camera reader: {e}")))
}

fn store(slot: &Slot, message: ros2_client::ReadResult<Newest>) {
    match message {
        Ok(newest) => {
            *slot.newest.lock().unwrap_or_else(|p| p.into_inner()) = Some(newest);
            slot.changed.notify_all();
        }
        Err(e) => tracing::warn!("ROS 2 camera: a frame could not be read: {e:?}"),
    }
}

/// `instant` on the wall clock.
fn wall_clock(instant: Instant) -> SystemTime {
    let now = Instant::now();
    let wall = SystemTime::now();
    if instant <= now {
        wall - (now - instant)
    } else {
        wall + (instant - now)
    }
}

/// `stamp` on our monotonic clock.
fn monotonic(stamp: SystemTime) -> Instant {
    let now = Instant::now();
    match SystemTime::now().duration_since(stamp) {
        Ok(ago) => now.checked_sub(ago).unwrap_or(now),
        Err(ahead) => now + ahead.duration(),
    }
}

impl Camera for Ros2Camera {
    fn grab(&mut self, not_before: Instant) -> Result<Frame, CameraError> {
        let not_before_wall = wall_clock(not_before);
        let waiting_since = Instant::now();
        let deadline = waiting_since + self.options.timeout;
        let mut newest = self.slot.newest.lock().unwrap_or_else(|p| p.into_inner());
        loop {
            if let Some(n) = newest.take_if(|n| n.stamp >= not_before_wall) {
                drop(newest);
                let after = n.stamp.duration_since(not_before_wall).unwrap_or_default();
                tracing::info!(
                    target: "handeye_ros2::latency",
                    "frame stamped {:.1} ms after the arm settled",
                    after.as_secs_f64() * 1e3
                );
                let topic = &self.options.image_topic;
                let image = match &n.pixels {
                    Pixels::Raw(m) => raw_to_gray(m),
                    Pixels::Compressed(m) => compressed_to_gray(m),
                    Pixels::Oversized(o) => Err(format!(
                        "{}: refused; {OVERSIZED_CHECK}",
                        oversized_reason(topic, o, &self.options.model)
                    )),
                }
                .map_err(|reason| CameraError::Frame {
                    path: topic.clone(),
                    reason,
                })?;
                let m = &self.options.model;
                if image.dimensions() != (m.width, m.height) {
                    return Err(CameraError::Frame {
                        path: topic.clone(),
                        reason: format!(
                            "the frame is {}x{} px but the intrinsics are for {}x{} px",
                            image.width(),
                            image.height(),
                            m.width,
                            m.height
                        ),
                    });
                }
                return Ok(Frame {
                    image,
                    captured_at: monotonic(n.stamp),
                    png: None,
                });
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(self.no_fresh_frame(newest.as_ref(), not_before_wall, waiting_since));
            }
            newest = self
                .slot
                .changed
                .wait_timeout(newest, (deadline - now).min(Duration::from_millis(100)))
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }

    fn model(&self) -> &CameraModel {
        &self.options.model
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::Header;

    fn raw(width: u32, height: u32, encoding: &str, bytes: usize) -> Newest {
        Newest {
            stamp: SystemTime::UNIX_EPOCH,
            received: Instant::now(),
            pixels: Pixels::Raw(Image {
                header: Header::default(),
                height,
                width,
                encoding: encoding.into(),
                is_bigendian: 0,
                step: width,
                data: vec![0; bytes],
            }),
        }
    }

    fn model(width: u32, height: u32) -> CameraModel {
        let mut m = CameraModel::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../../configs/cameras/sim-1280x720.yaml"),
        )
        .unwrap();
        (m.width, m.height) = (width, height);
        m
    }

    /// Every message up to the bound passes whole, whatever its encoding; one byte over it is
    /// refused with its size and what it held, raw or compressed.
    #[test]
    fn messages_over_the_frame_bound_are_refused_with_their_size() {
        let m = model(1280, 720);
        let bound = max_frame_bytes(&m);
        assert_eq!(bound, 1280 * 720 * 8);
        for (encoding, bytes) in [("mono8", 1280 * 720), ("rgba16", bound as usize)] {
            let kept = bounded(raw(1280, 720, encoding, bytes), bound);
            assert!(matches!(kept.pixels, Pixels::Raw(ref i) if i.data.len() == bytes));
        }
        for bytes in [bound as usize + 1, 10_000 * 10_000] {
            let refused = bounded(raw(10_000, 10_000, "mono8", bytes), bound);
            let Pixels::Oversized(o) = &refused.pixels else {
                panic!("{bytes} bytes kept")
            };
            assert_eq!((o.bytes, o.held.as_str()), (bytes, "10000x10000 mono8"));
        }
        let jpeg = Newest {
            stamp: SystemTime::UNIX_EPOCH,
            received: Instant::now(),
            pixels: Pixels::Compressed(CompressedImage {
                header: Header::default(),
                format: "jpeg".into(),
                data: vec![0; bound as usize + 1],
            }),
        };
        assert!(
            matches!(bounded(jpeg, bound).pixels, Pixels::Oversized(ref o) if o.held == "jpeg")
        );
        let o = Oversized {
            bytes: 100_000_000,
            held: "10000x10000 mono8".into(),
        };
        let reason = oversized_reason("/image_raw", &o, &m);
        assert!(
            reason.contains(
                "/image_raw are 100.0 MB (10000x10000 mono8), over the 7.4 MB a 1280x720 px frame"
            ),
            "{reason}"
        );
    }
}
