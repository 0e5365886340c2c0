//! USB/UVC cameras through nokhwa (V4L2 on Linux), behind the `uvc` cargo feature.
//!
//! The nokhwa camera is not `Send`, so it lives on a thread of its own; [`UvcCamera`] talks to it
//! over channels (like the tag detector). Opening requests a resolution, pixel format and frame
//! rate (the closest the camera offers; the format actually granted is logged), then locks what
//! moves between poses and would spoil a calibration: auto exposure off with a fixed exposure,
//! auto gain off with a fixed gain, autofocus off with a fixed focus. A control the camera lacks
//! or refuses is reported with `tracing::warn!` — for focus loudly, since a refocus between
//! poses changes the intrinsics.
//!
//! Stale frames: V4L2 keeps a queue of filled buffers (nokhwa maps 4), so the first frames read
//! after the arm stops can predate the stop. `grab(not_before)` reads and drops
//! [`UvcOptions::stale_frames`] frames once `not_before` has passed, then returns the next one,
//! stamped with the time it was dequeued. Raw buffers are converted to grey by
//! `camera::decode`. Depends on `camera` and nokhwa only.

use std::sync::mpsc;
use std::time::{Duration, Instant};

use image::GrayImage;
use nokhwa::pixel_format::LumaFormat;
use nokhwa::utils::{
    ApiBackend, CameraFormat, CameraIndex, ControlValueSetter, FrameFormat, KnownCameraControl,
    RequestedFormat, RequestedFormatType, Resolution,
};

use super::decode::{to_gray, PixelFormat};
use super::{Camera, CameraError, Frame};
use handeye_core::camera_model::CameraModel;

/// V4L2 control ids (linux/v4l2-controls.h) nokhwa has no name for.
mod v4l2 {
    /// `V4L2_CID_EXPOSURE_AUTO` (menu: 1 = manual).
    pub(super) const EXPOSURE_AUTO: u128 = 0x009a_0901;
    /// `V4L2_CID_EXPOSURE_ABSOLUTE` (units of 100 µs).
    pub(super) const EXPOSURE_ABSOLUTE: u128 = 0x009a_0902;
    /// `V4L2_CID_FOCUS_ABSOLUTE`.
    pub(super) const FOCUS_ABSOLUTE: u128 = 0x009a_090a;
    /// `V4L2_CID_FOCUS_AUTO` (boolean).
    pub(super) const FOCUS_AUTO: u128 = 0x009a_090c;
    /// `V4L2_CID_AUTOGAIN` (boolean).
    pub(super) const AUTOGAIN: u128 = 0x0098_0912;
    /// `V4L2_CID_EXPOSURE_AUTO` value for manual exposure.
    pub(super) const EXPOSURE_MANUAL: i64 = 1;
}

/// Which camera to open.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum UvcDevice {
    /// By index (`/dev/video<N>` on Linux).
    Index(u32),
    /// By (part of) its name as `handeye camera list` shows it.
    Name(String),
}

/// How to open and drive a UVC camera.
#[derive(Debug, Clone, PartialEq)]
pub struct UvcOptions {
    /// The camera.
    pub device: UvcDevice,
    /// Requested width, px.
    pub width: u32,
    /// Requested height, px.
    pub height: u32,
    /// Requested pixel format.
    pub format: PixelFormat,
    /// Requested frame rate, frames/s.
    pub fps: u32,
    /// Fixed exposure, µs (auto exposure off); `None` leaves exposure alone.
    pub exposure_us: Option<u32>,
    /// Fixed gain in the camera's units (auto gain off); `None` leaves gain alone.
    pub gain: Option<i64>,
    /// Fixed focus in the camera's units (autofocus off); `None` only turns autofocus off.
    pub focus: Option<i64>,
    /// Frames dropped after `not_before` before one is used (the driver's queue depth).
    pub stale_frames: usize,
    /// Give up on a grab after this long.
    pub timeout: Duration,
}

impl Default for UvcOptions {
    fn default() -> Self {
        UvcOptions {
            device: UvcDevice::Index(0),
            width: 1280,
            height: 720,
            format: PixelFormat::Mjpeg,
            fps: 30,
            exposure_us: None,
            gain: None,
            focus: None,
            stale_frames: 4,
            timeout: Duration::from_secs(5),
        }
    }
}

/// A camera as the system lists it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UvcCameraInfo {
    /// Its index (as `--camera` takes it).
    pub index: String,
    /// Human name.
    pub name: String,
    /// Driver description.
    pub description: String,
}

fn backend_error(context: &str, e: impl std::fmt::Display) -> CameraError {
    CameraError::Open(format!("{context}: {e}"))
}

/// The cameras the system offers.
pub fn list_cameras() -> Result<Vec<UvcCameraInfo>, CameraError> {
    let cameras =
        nokhwa::query(ApiBackend::Auto).map_err(|e| backend_error("listing cameras", e))?;
    Ok(cameras
        .into_iter()
        .map(|c| UvcCameraInfo {
            index: c.index().to_string(),
            name: c.human_name(),
            description: c.description().to_string(),
        })
        .collect())
}

fn frame_format(format: PixelFormat) -> FrameFormat {
    match format {
        PixelFormat::Mjpeg => FrameFormat::MJPEG,
        PixelFormat::Yuyv => FrameFormat::YUYV,
        PixelFormat::Gray => FrameFormat::GRAY,
        PixelFormat::Rgb => FrameFormat::RAWRGB,
    }
}

fn pixel_format(format: FrameFormat) -> Option<PixelFormat> {
    match format {
        FrameFormat::MJPEG => Some(PixelFormat::Mjpeg),
        FrameFormat::YUYV => Some(PixelFormat::Yuyv),
        FrameFormat::GRAY => Some(PixelFormat::Gray),
        FrameFormat::RAWRGB => Some(PixelFormat::Rgb),
        FrameFormat::NV12 | FrameFormat::RAWBGR => None,
    }
}

type Reply = Result<(GrayImage, Instant), CameraError>;

/// A USB/UVC camera.
pub struct UvcCamera {
    requests: Option<mpsc::Sender<(Instant, mpsc::Sender<Reply>)>>,
    worker: Option<std::thread::JoinHandle<()>>,
    model: CameraModel,
    timeout: Duration,
}

impl UvcCamera {
    /// Opens the camera, sets its format and locks its controls. `model` are its intrinsics
    /// (their size must be the granted resolution); without them (snapping a frame to check a
    /// setup) a nominal pinhole of the granted size stands in.
    pub fn open(
        options: &UvcOptions,
        model: Option<CameraModel>,
    ) -> Result<UvcCamera, CameraError> {
        let index = match &options.device {
            UvcDevice::Index(i) => CameraIndex::Index(*i),
            UvcDevice::Name(name) => {
                let wanted = name.to_lowercase();
                let found = list_cameras()?
                    .into_iter()
                    .find(|c| c.name.to_lowercase().contains(&wanted))
                    .ok_or_else(|| {
                        CameraError::Open(format!(
                            "no camera named like `{name}` (see `handeye camera list`)"
                        ))
                    })?;
                match found.index.parse::<u32>() {
                    Ok(i) => CameraIndex::Index(i),
                    Err(_) => CameraIndex::String(found.index),
                }
            }
        };
        let (open_tx, open_rx) = mpsc::channel::<Result<(u32, u32), CameraError>>();
        let (request_tx, request_rx) = mpsc::channel::<(Instant, mpsc::Sender<Reply>)>();
        let timeout = options.timeout;
        let options = options.clone();
        let worker = std::thread::Builder::new()
            .name("uvc-camera".into())
            .spawn(move || {
                let mut camera = match open_on_thread(index, &options) {
                    Ok(camera) => {
                        let r = camera.resolution();
                        let _ = open_tx.send(Ok((r.width(), r.height())));
                        camera
                    }
                    Err(e) => {
                        let _ = open_tx.send(Err(e));
                        return;
                    }
                };
                for (not_before, reply) in request_rx {
                    let _ = reply.send(grab_on_thread(
                        &mut camera,
                        not_before,
                        options.stale_frames,
                    ));
                }
                let _ = camera.stop_stream();
            })
            .map_err(|e| backend_error("starting the camera thread", e))?;
        let (width, height) = open_rx
            .recv()
            .map_err(|_| CameraError::Open("the camera thread stopped while opening".into()))??;
        let model = model.unwrap_or(CameraModel {
            width,
            height,
            fx: width as f64,
            fy: width as f64,
            cx: (width as f64 - 1.0) / 2.0,
            cy: (height as f64 - 1.0) / 2.0,
            distortion: handeye_core::camera_model::Distortion::None,
        });
        if (width, height) != (model.width, model.height) {
            return Err(CameraError::Open(format!(
                "the camera delivers {width}x{height} px but the intrinsics are for {}x{} px",
                model.width, model.height
            )));
        }
        Ok(UvcCamera {
            requests: Some(request_tx),
            worker: Some(worker),
            model,
            timeout,
        })
    }

    /// One grey frame exposed after now (for `camera snap` and live detection).
    pub fn snap(&mut self) -> Result<GrayImage, CameraError> {
        Ok(self.grab(Instant::now())?.image)
    }
}

impl Drop for UvcCamera {
    fn drop(&mut self) {
        self.requests.take();
        if let Some(worker) = self.worker.take() {
            let _ = worker.join();
        }
    }
}

fn open_on_thread(index: CameraIndex, options: &UvcOptions) -> Result<nokhwa::Camera, CameraError> {
    let requested =
        RequestedFormat::new::<LumaFormat>(RequestedFormatType::Closest(CameraFormat::new(
            Resolution::new(options.width, options.height),
            frame_format(options.format),
            options.fps,
        )));
    let mut camera = nokhwa::Camera::new(index.clone(), requested)
        .map_err(|e| backend_error(&format!("opening camera {index}"), e))?;
    let granted = camera.camera_format();
    if pixel_format(granted.format()).is_none() {
        return Err(CameraError::Open(format!(
            "camera {index} granted pixel format {} which handeye does not decode (use mjpeg, yuyv or gray)",
            granted.format()
        )));
    }
    tracing::info!("camera {index}: {granted}");
    lock_controls(&mut camera, options);
    camera
        .open_stream()
        .map_err(|e| backend_error(&format!("starting the stream of camera {index}"), e))?;
    Ok(camera)
}

fn lock_controls(camera: &mut nokhwa::Camera, options: &UvcOptions) {
    let mut set = |what: &str, id: KnownCameraControl, value: ControlValueSetter| {
        camera.set_camera_control(id, value).map_err(|e| {
            tracing::warn!("cannot set {what}: {e}");
        })
    };
    if let Some(us) = options.exposure_us {
        let manual = set(
            "manual exposure",
            KnownCameraControl::Other(v4l2::EXPOSURE_AUTO),
            ControlValueSetter::Integer(v4l2::EXPOSURE_MANUAL),
        );
        let fixed = set(
            "the exposure time",
            KnownCameraControl::Other(v4l2::EXPOSURE_ABSOLUTE),
            ControlValueSetter::Integer((us as i64 / 100).max(1)),
        );
        if manual.is_err() || fixed.is_err() {
            tracing::warn!("exposure is not locked: brightness may change between poses");
        }
    }
    if let Some(gain) = options.gain {
        let _ = set(
            "auto gain off",
            KnownCameraControl::Other(v4l2::AUTOGAIN),
            ControlValueSetter::Boolean(false),
        );
        let _ = set(
            "the gain",
            KnownCameraControl::Gain,
            ControlValueSetter::Integer(gain),
        );
    }
    let autofocus_off = set(
        "autofocus off",
        KnownCameraControl::Other(v4l2::FOCUS_AUTO),
        ControlValueSetter::Boolean(false),
    );
    let focus_fixed = match options.focus {
        Some(focus) => set(
            "the focus",
            KnownCameraControl::Other(v4l2::FOCUS_ABSOLUTE),
            ControlValueSetter::Integer(focus),
        ),
        None => Ok(()),
    };
    if autofocus_off.is_err() || focus_fixed.is_err() {
        tracing::warn!(
            "focus could not be locked: if this camera refocuses between poses its intrinsics change and the calibration is spoiled; use a fixed-focus camera or lock focus with v4l2-ctl"
        );
    }
}

fn grab_on_thread(camera: &mut nokhwa::Camera, not_before: Instant, stale_frames: usize) -> Reply {
    if let Some(wait) = not_before.checked_duration_since(Instant::now()) {
        std::thread::sleep(wait);
    }
    // Buffers queued before `not_before` may hold frames exposed before it: drop a queue's worth.
    for _ in 0..stale_frames {
        camera
            .frame_raw()
            .map_err(|e| backend_error("reading a frame", e))?;
    }
    let buffer = camera
        .frame()
        .map_err(|e| backend_error("reading a frame", e))?;
    let dequeued = Instant::now();
    let resolution = buffer.resolution();
    let format = pixel_format(buffer.source_frame_format()).ok_or_else(|| {
        CameraError::Open(format!(
            "unsupported pixel format {}",
            buffer.source_frame_format()
        ))
    })?;
    let image = to_gray(
        format,
        resolution.width(),
        resolution.height(),
        buffer.buffer(),
    )
    .map_err(|e| CameraError::Frame {
        path: "uvc stream".into(),
        reason: e.to_string(),
    })?;
    Ok((image, dequeued))
}

impl Camera for UvcCamera {
    fn grab(&mut self, not_before: Instant) -> Result<Frame, CameraError> {
        let (reply_tx, reply_rx) = mpsc::channel();
        self.requests
            .as_ref()
            .ok_or_else(|| CameraError::Open("the camera is closed".into()))?
            .send((not_before, reply_tx))
            .map_err(|_| CameraError::Open("the camera thread stopped".into()))?;
        let wait = not_before
            .checked_duration_since(Instant::now())
            .unwrap_or_default()
            + self.timeout;
        let (image, captured_at) = match reply_rx.recv_timeout(wait) {
            Ok(reply) => reply?,
            Err(_) => return Err(CameraError::Timeout(self.timeout)),
        };
        Ok(Frame {
            image,
            captured_at,
            png: None,
        })
    }

    fn model(&self) -> &CameraModel {
        &self.model
    }
}
