//! Opening the USB/UVC camera a `camera: {backend: uvc}` config names: built only with the `uvc`
//! feature; without it, a clear error says the build lacks it. The session sees the `Camera`
//! trait either way.

use handeye_camera::Camera;
use handeye_config::UvcCamera;
use handeye_core::camera_model::CameraModel;

use super::CellError;

/// Opens the USB camera `config` describes with intrinsics `model` (the granted resolution must
/// be the intrinsics' size).
pub fn open_camera(config: &UvcCamera, model: CameraModel) -> Result<Box<dyn Camera>, CellError> {
    open(config, model)
}

#[cfg(not(feature = "uvc"))]
fn open(_: &UvcCamera, _: CameraModel) -> Result<Box<dyn Camera>, CellError> {
    Err(CellError::Backend(
        "camera backend `uvc` needs a handeye build with the `uvc` feature: `cargo build --release --features uvc` (needs libclang-dev)".into(),
    ))
}

#[cfg(feature = "uvc")]
fn open(config: &UvcCamera, model: CameraModel) -> Result<Box<dyn Camera>, CellError> {
    use handeye_camera::decode::PixelFormat;
    use handeye_camera::uvc::{UvcDevice, UvcOptions};
    let UvcCamera {
        device,
        width,
        height,
        pixel_format,
        fps,
        exposure_us,
        gain,
        focus,
        stale_frames,
    } = config;
    let options = UvcOptions {
        device: match device.parse::<u32>() {
            Ok(i) => UvcDevice::Index(i),
            Err(_) => UvcDevice::Name(device.clone()),
        },
        width: *width,
        height: *height,
        format: match pixel_format.as_str() {
            "yuyv" => PixelFormat::Yuyv,
            "gray" => PixelFormat::Gray,
            _ => PixelFormat::Mjpeg,
        },
        fps: *fps,
        exposure_us: *exposure_us,
        gain: *gain,
        focus: *focus,
        stale_frames: *stale_frames,
        ..UvcOptions::default()
    };
    let camera = handeye_camera::uvc::UvcCamera::open(&options, Some(model))
        .map_err(|e| CellError::Backend(format!("opening USB camera `{device}`: {e}")))?;
    Ok(Box::new(camera))
}
