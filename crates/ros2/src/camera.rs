//! `camera.backend: ros2`: frames from a ROS 2 camera node's `sensor_msgs/Image` (mono8, mono16,
//! rgb8, bgr8, bayer) or `CompressedImage` topic, read best effort (the sensor-data QoS camera
//! drivers publish with), and its `CameraInfo` checked against the cell's intrinsics.
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
}

struct Newest {
    pixels: Pixels,
    stamp: SystemTime,
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
        // Only the newest message is kept (undecoded): memory is one frame whatever the rate.
        let frames = if options.compressed {
            newest_of(
                link.subscribe::<CompressedImage>(&topic, sensor_data_qos())
                    .map_err(err)?,
                |msg| Newest {
                    stamp: msg.header.stamp.to_system(),
                    pixels: Pixels::Compressed(msg),
                },
            )
        } else {
            newest_of(
                link.subscribe::<Image>(&topic, sensor_data_qos())
                    .map_err(err)?,
                |msg| Newest {
                    stamp: msg.header.stamp.to_system(),
                    pixels: Pixels::Raw(msg),
                },
            )
        };
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
    /// publishes is named before the arm moves, not after the first move (issue #39).
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
        if newest.is_some() {
            return Ok(());
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
        let heard = if heard.is_empty() {
            "no image topic is heard on this domain".to_string()
        } else {
            format!("image topics heard on this domain: {}", heard.join(", "))
        };
        Err(open_error(format!(
            "no image on {} within {:.1} s, nothing has moved: is the camera node running, on this domain id, publishing sensor_msgs/{kind} under that name? ({heard})",
            self.options.image_topic,
            self.options.timeout.as_secs_f64(),
        )))
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

/// The reader of an image topic: each message read becomes the slot's newest frame.
fn newest_of<M>(sub: ros2_client::Subscription<M>, newest: fn(M) -> Newest) -> FramesReader
where
    M: serde::de::DeserializeOwned + Send + Sync + 'static,
{
    Box::new(move |slot: Arc<Slot>| -> ReaderFuture {
        Box::pin(async move {
            sub.async_stream()
                .for_each(|m| {
                    store(&slot, m.map(|(msg, _)| newest(msg)));
                    futures::future::ready(())
                })
                .await
        })
    })
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
        let deadline = Instant::now() + self.options.timeout;
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
                let heard = newest.as_ref().map(|n| n.stamp);
                return Err(CameraError::Backend(
                    format!(
                        "no frame on {} stamped after the arm settled within {:.1} s ({})",
                        self.options.image_topic,
                        self.options.timeout.as_secs_f64(),
                        match heard {
                            Some(s) => format!(
                                "the newest is stamped {:.3} s before: is the camera node's clock in step with this machine's?",
                                not_before_wall.duration_since(s).unwrap_or_default().as_secs_f64()
                            ),
                            None => "none heard at all: is the camera node running, on this domain id, with this topic name?".into(),
                        }
                    )
                    .into(),
                ));
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
