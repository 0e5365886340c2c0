//! The image-folder camera: frames recorded elsewhere (another robot, another tool, an earlier
//! run) served in plan order, so they go through the same session code as a live camera.
//!
//! Frame order: the folder's image files (`.png`, `.jpg`, `.jpeg`, `.pgm`, `.bmp`... whatever the
//! `image` crate decodes here: PNG and JPEG) sorted by [`natural_cmp`] of their file names, so
//! `frame-2.png` comes before `frame-10.png`; other files are ignored. Frame `i` belongs to plan
//! pose `i`. Without a [`FrameSelector`] each grab serves the next frame; with one, each grab
//! serves the frame of the pose the selector names (so a retried pose gets its own frame again).
//! Colour images are converted to grey by luma. `captured_at` is the grab time: a recorded frame
//! is by definition taken at its pose, so it is never stale.
//! Depends only on `camera` and `image`.

use std::cmp::Ordering;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering as AtomicOrdering};
use std::sync::Arc;
use std::time::Instant;

use super::{Camera, CameraError, Frame, PngFile};
use handeye_core::camera_model::CameraModel;

/// Image file extensions the folder camera serves (lower case).
pub const FRAME_EXTENSIONS: [&str; 3] = ["png", "jpg", "jpeg"];

/// Compares file names so that embedded numbers sort by value (`image-2` before `image-10`);
/// runs of non-digits compare as text. This is the frame order of the image-folder camera.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut a, mut b) = (a, b);
    loop {
        match (a.chars().next(), b.chars().next()) {
            (None, None) => return Ordering::Equal,
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(x), Some(y)) if x.is_ascii_digit() && y.is_ascii_digit() => {
                let da = a.len() - a.trim_start_matches(|c: char| c.is_ascii_digit()).len();
                let db = b.len() - b.trim_start_matches(|c: char| c.is_ascii_digit()).len();
                let (na, nb) = (&a[..da], &b[..db]);
                let (ta, tb) = (na.trim_start_matches('0'), nb.trim_start_matches('0'));
                let order = ta
                    .len()
                    .cmp(&tb.len())
                    .then_with(|| ta.cmp(tb))
                    .then_with(|| na.len().cmp(&nb.len()));
                if order != Ordering::Equal {
                    return order;
                }
                a = &a[da..];
                b = &b[db..];
            }
            (Some(x), Some(y)) => {
                if x != y {
                    return x.cmp(&y);
                }
                a = &a[x.len_utf8()..];
                b = &b[y.len_utf8()..];
            }
        }
    }
}

/// The image files of `folder` in frame order (natural sort of the file names).
pub fn list_frames(folder: &Path) -> Result<Vec<PathBuf>, CameraError> {
    let entries = std::fs::read_dir(folder).map_err(|e| {
        CameraError::Open(format!(
            "cannot read the frame folder {}: {e}",
            folder.display()
        ))
    })?;
    let mut frames: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_file()
                && p.extension()
                    .and_then(|e| e.to_str())
                    .is_some_and(|e| FRAME_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
        })
        .collect();
    frames.sort_by(|a, b| {
        let name = |p: &PathBuf| {
            p.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default()
        };
        natural_cmp(&name(a), &name(b))
    });
    Ok(frames)
}

/// Which plan pose the arm is at, shared between the robot side (which sets it on each move) and
/// the folder camera (which serves that pose's frame).
#[derive(Debug, Clone, Default)]
pub struct FrameSelector(Arc<AtomicUsize>);

impl FrameSelector {
    /// Names plan pose `index` as the current one.
    pub fn select(&self, index: usize) {
        self.0.store(index, AtomicOrdering::SeqCst);
    }

    /// The current plan pose.
    pub fn current(&self) -> usize {
        self.0.load(AtomicOrdering::SeqCst)
    }
}

/// A camera that serves the images of a folder.
pub struct FilesCamera {
    folder: PathBuf,
    frames: Vec<PathBuf>,
    model: CameraModel,
    next: usize,
    selector: Option<FrameSelector>,
}

impl FilesCamera {
    /// Opens `folder`; `model` are the intrinsics the frames were taken with. An empty folder is
    /// an error.
    pub fn open(folder: &Path, model: CameraModel) -> Result<FilesCamera, CameraError> {
        let frames = list_frames(folder)?;
        if frames.is_empty() {
            return Err(CameraError::Open(format!(
                "the frame folder {} holds no images ({})",
                folder.display(),
                FRAME_EXTENSIONS.join(", ")
            )));
        }
        Ok(FilesCamera {
            folder: folder.to_path_buf(),
            frames,
            model,
            next: 0,
            selector: None,
        })
    }

    /// Serves the frame of the pose `selector` names instead of the next one.
    pub fn with_selector(mut self, selector: FrameSelector) -> FilesCamera {
        self.selector = Some(selector);
        self
    }

    /// The frames, in order.
    pub fn frames(&self) -> &[PathBuf] {
        &self.frames
    }

    /// Checks that there is a frame for each of `poses` plan poses.
    pub fn require_frames(&self, poses: usize) -> Result<(), CameraError> {
        if self.frames.len() < poses {
            return Err(CameraError::TooFewFrames {
                folder: self.folder.clone(),
                frames: self.frames.len(),
                poses,
            });
        }
        Ok(())
    }
}

impl Camera for FilesCamera {
    fn grab(&mut self, _not_before: Instant) -> Result<Frame, CameraError> {
        let index = match &self.selector {
            Some(selector) => selector.current(),
            None => {
                self.next += 1;
                self.next - 1
            }
        };
        let path = self
            .frames
            .get(index)
            .ok_or_else(|| CameraError::TooFewFrames {
                folder: self.folder.clone(),
                frames: self.frames.len(),
                poses: index + 1,
            })?;
        let unreadable = |reason: String| CameraError::Frame {
            path: path.display().to_string(),
            reason,
        };
        let bytes = std::fs::read(path).map_err(|e| unreadable(e.to_string()))?;
        let reader = image::ImageReader::new(std::io::Cursor::new(&bytes))
            .with_guessed_format()
            .map_err(|e| unreadable(e.to_string()))?;
        let is_png = reader.format() == Some(image::ImageFormat::Png);
        let decoded = reader.decode().map_err(|e| unreadable(e.to_string()))?;
        // A grey 8-bit PNG holds exactly the frame's pixels: its bytes can be stored as they are.
        let png = (is_png && decoded.color() == image::ColorType::L8).then(|| PngFile {
            path: path.clone(),
            bytes,
        });
        let image = decoded.into_luma8();
        if (image.width(), image.height()) != (self.model.width, self.model.height) {
            return Err(CameraError::Frame {
                path: path.display().to_string(),
                reason: format!(
                    "{}x{} px, but the intrinsics are for {}x{} px",
                    image.width(),
                    image.height(),
                    self.model.width,
                    self.model.height
                ),
            });
        }
        Ok(Frame {
            image,
            captured_at: Instant::now(),
            png,
        })
    }

    fn model(&self) -> &CameraModel {
        &self.model
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_core::camera_model::Distortion;

    #[test]
    fn natural_order_sorts_numbers_by_value() {
        let mut names = vec![
            "img-10.png",
            "img-2.png",
            "img-1.png",
            "a.png",
            "img-02.png",
        ];
        names.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            names,
            [
                "a.png",
                "img-1.png",
                "img-2.png",
                "img-02.png",
                "img-10.png"
            ]
        );
    }

    fn model(width: u32, height: u32) -> CameraModel {
        CameraModel {
            width,
            height,
            fx: 100.0,
            fy: 100.0,
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
            distortion: Distortion::None,
        }
    }

    #[test]
    fn serves_frames_in_natural_order_and_by_selector() {
        let dir = tempfile::tempdir().unwrap();
        // Frame k is a 4x3 image filled with grey level k, named so that text order differs.
        for k in [1u8, 2, 10] {
            image::GrayImage::from_pixel(4, 3, image::Luma([k]))
                .save(dir.path().join(format!("f-{k}.png")))
                .unwrap();
        }
        std::fs::write(dir.path().join("notes.txt"), "not a frame").unwrap();
        let mut camera = FilesCamera::open(dir.path(), model(4, 3)).unwrap();
        assert_eq!(camera.frames().len(), 3);
        let grey = |c: &mut FilesCamera| c.grab(Instant::now()).unwrap().image.get_pixel(0, 0)[0];
        assert_eq!(
            [grey(&mut camera), grey(&mut camera), grey(&mut camera)],
            [1, 2, 10]
        );
        let e = camera.grab(Instant::now()).unwrap_err().to_string();
        assert!(e.contains("3 frames") && e.contains("4 poses"), "{e}");

        let selector = FrameSelector::default();
        let mut camera = FilesCamera::open(dir.path(), model(4, 3))
            .unwrap()
            .with_selector(selector.clone());
        selector.select(2);
        assert_eq!(grey(&mut camera), 10);
        assert_eq!(grey(&mut camera), 10, "a retried pose gets its frame again");
        selector.select(0);
        assert_eq!(grey(&mut camera), 1);
        let e = camera.require_frames(5).unwrap_err().to_string();
        assert!(
            e.contains(&dir.path().display().to_string())
                && e.contains("3 frames")
                && e.contains("5 poses"),
            "{e}"
        );

        let mut wrong_size = FilesCamera::open(dir.path(), model(8, 3)).unwrap();
        let e = wrong_size.grab(Instant::now()).unwrap_err().to_string();
        assert!(e.contains("f-1.png") && e.contains("4x3"), "{e}");
    }

    #[test]
    fn hands_on_the_file_of_a_grey_png_and_of_no_other_frame() {
        let dir = tempfile::tempdir().unwrap();
        let grey = image::GrayImage::from_fn(4, 3, |x, y| image::Luma([(10 * x + y) as u8]));
        grey.save(dir.path().join("0.png")).unwrap();
        let colour = image::RgbImage::from_pixel(4, 3, image::Rgb([10, 200, 30]));
        colour.save(dir.path().join("1.png")).unwrap();
        let mut camera = FilesCamera::open(dir.path(), model(4, 3)).unwrap();
        let frame = camera.grab(Instant::now()).unwrap();
        let file = std::fs::read(dir.path().join("0.png")).unwrap();
        let png = frame.png.expect("a grey PNG hands on its file");
        assert_eq!(png.bytes, file);
        assert_eq!(png.path, dir.path().join("0.png"));
        assert_eq!(frame.image, grey);
        // A colour frame is served grey: its file does not hold those pixels.
        let frame = camera.grab(Instant::now()).unwrap();
        assert_eq!(frame.png, None);
        assert_eq!(frame.image, image::DynamicImage::from(colour).into_luma8());
    }
}
