//! `handeye camera list|snap`: check a USB/UVC camera setup (needs the `uvc` build feature;
//! without it both say so). Also the camera-opening helper `detect --camera --live` uses.

use std::path::PathBuf;

use clap::{Args, Subcommand, ValueEnum};

/// USB/UVC cameras.
#[derive(Debug, Args)]
pub(super) struct CameraArgs {
    #[command(subcommand)]
    command: CameraCommand,
}

#[derive(Debug, Subcommand)]
enum CameraCommand {
    /// List the cameras the system offers.
    List,
    /// Grab one grey frame and write it as PNG.
    Snap(SnapArgs),
}

/// Pixel format on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(super) enum PixelFormatArg {
    /// Motion JPEG.
    Mjpeg,
    /// YUYV 4:2:2.
    Yuyv,
    /// 8-bit grey.
    Gray,
}

/// Which camera and stream to open.
#[derive(Debug, Clone, Args)]
pub(super) struct StreamArgs {
    /// Camera index (/dev/video<N>) or (part of) its name.
    #[arg(long)]
    pub camera: Option<String>,
    /// Requested width, px.
    #[arg(long, default_value_t = 1280)]
    pub width: u32,
    /// Requested height, px.
    #[arg(long, default_value_t = 720)]
    pub height: u32,
    /// Requested pixel format.
    #[arg(long, value_enum, default_value_t = PixelFormatArg::Mjpeg)]
    pub pixel_format: PixelFormatArg,
    /// Requested frame rate, frames/s.
    #[arg(long, default_value_t = 30)]
    pub fps: u32,
    /// Fixed exposure, µs (auto exposure off).
    #[arg(long)]
    pub exposure_us: Option<u32>,
    /// Fixed gain, camera units (auto gain off).
    #[arg(long)]
    pub gain: Option<i64>,
    /// Fixed focus, camera units (autofocus is always turned off when possible).
    #[arg(long)]
    pub focus: Option<i64>,
}

#[derive(Debug, Args)]
struct SnapArgs {
    #[command(flatten)]
    stream: StreamArgs,
    /// The PNG to write.
    #[arg(short = 'o', long)]
    output: PathBuf,
}

/// Runs `handeye camera`.
pub(super) fn run(args: CameraArgs) -> anyhow::Result<()> {
    match args.command {
        CameraCommand::List => uvc::list(),
        CameraCommand::Snap(a) => uvc::snap(&a.stream, &a.output),
    }
}

#[cfg(not(feature = "uvc"))]
pub(super) mod uvc {
    //! Stand-ins when the build lacks the `uvc` feature.
    use super::StreamArgs;
    use handeye_core::camera_model::CameraModel;

    const MISSING: &str = "this handeye build lacks USB camera support: rebuild with `cargo build --release --features uvc` (needs libclang-dev)";

    /// Fails: this build has no USB camera support.
    pub(crate) fn ensure_available() -> anyhow::Result<()> {
        anyhow::bail!(MISSING)
    }

    /// `camera list`.
    pub(crate) fn list() -> anyhow::Result<()> {
        anyhow::bail!(MISSING)
    }
    /// `camera snap`.
    pub(crate) fn snap(_: &StreamArgs, _: &std::path::Path) -> anyhow::Result<()> {
        anyhow::bail!(MISSING)
    }
    /// Opens a live camera (never, in this build).
    pub(crate) fn open(
        _: &StreamArgs,
        _: Option<CameraModel>,
    ) -> anyhow::Result<Box<dyn handeye_camera::Camera>> {
        anyhow::bail!(MISSING)
    }
}

#[cfg(feature = "uvc")]
pub(super) mod uvc {
    //! The real thing.
    use anyhow::Context;

    use super::{PixelFormatArg, StreamArgs};
    use handeye_camera::decode::PixelFormat;
    use handeye_camera::uvc::{list_cameras, UvcCamera, UvcDevice, UvcOptions};
    use handeye_core::atomic_file::write_atomic;
    use handeye_core::camera_model::CameraModel;

    /// This build has USB camera support.
    pub(crate) fn ensure_available() -> anyhow::Result<()> {
        Ok(())
    }

    /// `camera list`.
    pub(crate) fn list() -> anyhow::Result<()> {
        let cameras = list_cameras()?;
        if cameras.is_empty() {
            outln!("no cameras found");
        }
        for c in cameras {
            outln!("{}: {} ({})", c.index, c.name, c.description);
        }
        Ok(())
    }

    fn options(stream: &StreamArgs) -> UvcOptions {
        let camera = stream.camera.clone().unwrap_or_else(|| "0".into());
        UvcOptions {
            device: match camera.parse::<u32>() {
                Ok(i) => UvcDevice::Index(i),
                Err(_) => UvcDevice::Name(camera),
            },
            width: stream.width,
            height: stream.height,
            format: match stream.pixel_format {
                PixelFormatArg::Mjpeg => PixelFormat::Mjpeg,
                PixelFormatArg::Yuyv => PixelFormat::Yuyv,
                PixelFormatArg::Gray => PixelFormat::Gray,
            },
            fps: stream.fps,
            exposure_us: stream.exposure_us,
            gain: stream.gain,
            focus: stream.focus,
            ..UvcOptions::default()
        }
    }

    /// Opens a live camera.
    pub(crate) fn open(
        stream: &StreamArgs,
        model: Option<CameraModel>,
    ) -> anyhow::Result<Box<dyn handeye_camera::Camera>> {
        Ok(Box::new(UvcCamera::open(&options(stream), model)?))
    }

    /// `camera snap`.
    pub(crate) fn snap(stream: &StreamArgs, output: &std::path::Path) -> anyhow::Result<()> {
        let mut camera = UvcCamera::open(&options(stream), None)?;
        let image = camera.snap()?;
        let mut png = Vec::new();
        image
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .context("encoding the frame")?;
        write_atomic(output, &png).with_context(|| format!("writing {}", output.display()))?;
        outln!(
            "wrote a {}x{} grey frame to {}",
            image.width(),
            image.height(),
            output.display()
        );
        Ok(())
    }
}
