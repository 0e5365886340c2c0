//! Annotated frames for people. [`annotate`] (`handeye detect`): detected tag outlines, corners
//! (corner 0 marked), ids, the board's axes at `T_camera_target` (x red, y green, z blue, drawn
//! through the lens model) and the reprojection RMS; for ChArUco boards and chessboards the
//! labelled corners (corner 0 red). [`PredictionMarks`]: where an answer predicts the board
//! beside the corners detected, drawn into the frame made smaller ([`prediction`], the console's
//! live view) or over its [`preview`] (the report's frames). Depends on
//! `vision::{target, detect, pnp, draw, shrink}` and `camera_model`.

use image::{GrayImage, Rgb, RgbImage};
use nalgebra::{Point2, Point3};

use handeye_core::geometry::Pose;

use super::detect::BoardDetection;
use super::draw;
use super::pnp::BoardPose;
use super::target::Target;
use handeye_core::camera_model::CameraModel;

/// Draws the detection (and the pose, if any) over a colour copy of the frame.
pub fn annotate(
    image: &GrayImage,
    board: &Target,
    camera: &CameraModel,
    detection: &BoardDetection,
    pose: Option<&BoardPose>,
) -> RgbImage {
    let mut out = RgbImage::from_fn(image.width(), image.height(), |x, y| {
        let v = image.get_pixel(x, y)[0];
        Rgb([v, v, v])
    });
    let thickness = 1 + image.width() / 1000;
    for tag in &detection.tags {
        let c = tag.corners_px;
        for k in 0..4 {
            draw::line(&mut out, c[k], c[(k + 1) % 4], thickness, Rgb([0, 220, 0]));
        }
        for (k, corner) in c.iter().enumerate() {
            let colour = if k == 0 {
                Rgb([255, 0, 0])
            } else {
                Rgb([255, 220, 0])
            };
            draw::cross(&mut out, *corner, 4.0, colour);
        }
        let centre = Point2::from((c[0].coords + c[1].coords + c[2].coords + c[3].coords) / 4.0);
        let edge = (c[1] - c[0]).norm();
        let scale = ((edge / 40.0).round() as u32).clamp(1, 6);
        let label = tag.id.to_string();
        let half_width = draw::text_width(&label, scale) as f64 / 2.0;
        draw::text(
            &mut out,
            (centre.x - half_width).round() as i64,
            (centre.y - 2.5 * scale as f64).round() as i64,
            scale,
            &label,
            Rgb([0, 160, 255]),
        );
    }
    for (id, pixel) in &detection.points {
        let colour = if *id == 0 {
            Rgb([255, 0, 0])
        } else {
            Rgb([0, 220, 0])
        };
        draw::cross(&mut out, *pixel, 4.0, colour);
    }
    let text_scale = 1 + image.width() / 400;
    if let Some(pose) = pose {
        let e = board.extent();
        let length = match board.aprilgrid() {
            Some(b) => (3.0 * b.tag_size()).min(b.pitch() * b.cols().max(2) as f64),
            None => 0.4 * (e.max.x - e.min.x).min(e.max.y - e.min.y),
        };
        let axes = [
            (Point3::new(length, 0.0, 0.0), Rgb([255, 0, 0])),
            (Point3::new(0.0, length, 0.0), Rgb([0, 255, 0])),
            (Point3::new(0.0, 0.0, length), Rgb([0, 80, 255])),
        ];
        for (end, colour) in axes {
            // Subdivide so the axis bends with the lens like the board does.
            let mut previous: Option<Point2<f64>> = None;
            for i in 0..=20 {
                let point = Point3::from(end.coords * (i as f64 / 20.0));
                let pixel = camera.project(&(pose.camera_from_target * point));
                if let (Some(a), Some(b)) = (previous, pixel) {
                    draw::line(&mut out, a, b, thickness + 1, colour);
                }
                previous = pixel;
            }
        }
        let tags = match board.aprilgrid() {
            Some(_) => format!("tags {} ", pose.tags_used),
            None => String::new(),
        };
        let summary = format!(
            "{tags}corners {} rms {:.3} px{}",
            pose.corners_used,
            pose.rms_px,
            if pose.is_ambiguous() {
                " AMBIGUOUS"
            } else {
                ""
            }
        );
        draw::text(&mut out, 8, 8, text_scale, &summary, Rgb([255, 255, 0]));
    } else {
        let summary = format!("features {} - no pose", detection.feature_count());
        draw::text(&mut out, 8, 8, text_scale, &summary, Rgb([255, 80, 80]));
    }
    out
}

/// The size, px, of a `width`×`height` frame shown at most `max_width` wide ([`prediction`],
/// [`preview`]): the frame shrunk by the smallest whole factor that brings it within
/// `max_width` (its own size when narrow enough), the height rounded. A whole factor makes each
/// shown pixel the mean of a square of frame pixels (1280 → 640, 1920 → 960): no pixel split
/// between two, and fewer pixels to scale and code than the largest fractional size (coding
/// and shrinking the pictures of a 200-frame 1280 x 720 import took 15.6 % of its CPU at 960 px
/// wide, 6.3 % at 640, in profiles).
pub fn shown_size(width: u32, height: u32, max_width: u32) -> (u32, u32) {
    let width = width.max(1);
    let factor = width.div_ceil(max_width.max(1));
    let scaled = |side: u32| ((f64::from(side) / f64::from(factor)).round() as u32).max(1);
    (scaled(width), scaled(height))
}

/// Largest width of a frame on a page, px (the report's grid shows it small, a click full
/// size); narrower frames keep their size.
pub const PREVIEW_WIDTH: u32 = 960;
/// JPEG quality of a frame on a page (a page of 20 frames stays a few MB).
pub const PREVIEW_QUALITY: u8 = 80;
/// Most frames a page shows of one camera: a long recording's frames would make a page of a
/// hundred megabytes or more (1,000 samples: 83 MB of JPEG; three cameras: 197 MB) that no
/// browser shows well and no reader pages through. Past it, the report draws the half whose
/// board lies farthest from where the answer predicts it (the frames a reader wants to open) and
/// the others evenly through the session; every frame stays in the session folder. A run makes
/// the [`preview`]s of this many frames: which of a longer session's are drawn depends on its
/// answer, and a preview made for each of a thousand frames would cost more than drawing the
/// shown ones from their frames.
pub const MAX_FRAMES_SHOWN: usize = 200;

/// A frame as a page shows it: grey JPEG at most `max_width` wide ([`shown_size`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Preview {
    /// The JPEG file's bytes.
    pub jpeg: Vec<u8>,
    /// Its size, px.
    pub width: u32,
    /// Its size, px.
    pub height: u32,
}

/// `grey` made smaller to at most `max_width` px wide (box filtered, [`box_shrink`]) and coded
/// as grey JPEG at `quality`: the picture under a page's marks ([`PredictionMarks`]). A run makes
/// it once, where the frame is decoded for detection (the session's `previews/NNN.jpg`), so a
/// page drawn later neither decodes the frame again nor codes colour planes for a few lines.
/// `Err` says what failed (a frame of no pixels).
///
/// [`box_shrink`]: crate::shrink::box_shrink
pub fn preview(grey: &GrayImage, max_width: u32, quality: u8) -> Result<Preview, String> {
    let small = shown(grey, max_width)?;
    Ok(Preview {
        jpeg: draw::grey_jpeg(&small, quality)?,
        width: small.width(),
        height: small.height(),
    })
}

/// `grey` at most `max_width` wide ([`shown_size`]), box filtered; borrowed when narrow enough.
fn shown(grey: &GrayImage, max_width: u32) -> Result<std::borrow::Cow<'_, GrayImage>, String> {
    if grey.width() == 0 || grey.height() == 0 {
        return Err("a frame of no pixels".into());
    }
    let (width, height) = shown_size(grey.width(), grey.height(), max_width);
    Ok(if width == grey.width() {
        std::borrow::Cow::Borrowed(grey)
    } else {
        std::borrow::Cow::Owned(crate::shrink::box_shrink(grey, width, height)?)
    })
}

/// Where an answer puts the board on a frame, beside the corners detected, in the pixels of the
/// frame as shown ([`shown_size`]; pixel centres at integers): what [`prediction`] draws into the
/// frame and a page draws over its [`preview`].
#[derive(Debug, Clone, PartialEq)]
pub struct PredictionMarks {
    /// The shown frame's size, px.
    pub size: (u32, u32),
    /// An aprilgrid's tag outlines where the answer puts them: each a segment of two ends.
    pub outlines: Vec<[Point2<f64>; 2]>,
    /// A ChArUco board's or chessboard's corners where the answer puts them.
    pub board_corners: Vec<Point2<f64>>,
    /// The corners detected.
    pub detected: Vec<Point2<f64>>,
}

impl PredictionMarks {
    /// The marks of a `frame_size` frame shown at most `max_width` wide: `board` placed at
    /// `camera_from_target` through `camera` (which may be of another resolution than the frame,
    /// a live view decoded smaller: its pixels are scaled to the frame's), and the `detected`
    /// corners (full-resolution pixels).
    pub fn of(
        frame_size: (u32, u32),
        max_width: u32,
        board: &Target,
        camera: &CameraModel,
        camera_from_target: &Pose,
        detected: impl IntoIterator<Item = Point2<f64>>,
    ) -> Self {
        let size = shown_size(frame_size.0, frame_size.1, max_width);
        let scale = f64::from(size.0) / f64::from(frame_size.0.max(1));
        // Pixel centres: full-resolution pixel u maps to (u + 0.5)·s − 0.5 in the smaller frame.
        let to_small =
            |p: Point2<f64>, s: f64| Point2::new((p.x + 0.5) * s - 0.5, (p.y + 0.5) * s - 0.5);
        let lens_scale = scale * f64::from(frame_size.0) / f64::from(camera.width.max(1));
        let project = |p: &Point3<f64>| {
            camera
                .project(&(camera_from_target * p))
                .map(|pixel| to_small(pixel, lens_scale))
        };
        let mut marks = PredictionMarks {
            size,
            outlines: Vec::new(),
            board_corners: Vec::new(),
            detected: detected.into_iter().map(|c| to_small(c, scale)).collect(),
        };
        match board.aprilgrid() {
            Some(grid) => {
                for tag in grid.tags() {
                    let pixels: Vec<Option<Point2<f64>>> =
                        tag.corners_in_target.iter().map(project).collect();
                    for k in 0..4 {
                        if let (Some(a), Some(b)) = (pixels[k], pixels[(k + 1) % 4]) {
                            marks.outlines.push([a, b]);
                        }
                    }
                }
            }
            None => {
                marks.board_corners = board
                    .points()
                    .into_iter()
                    .filter_map(|(_, _, p)| project(&p))
                    .collect();
            }
        }
        marks
    }

    /// Half the length of a cross's arms, px of the shown frame: a ChArUco board's or
    /// chessboard's predicted corner, and a detected corner (longer on a frame 640 px wide or
    /// more, whose lines are drawn 2 px wide). Sized to read at full size and in a small grid.
    pub fn cross_arms(&self) -> (f64, f64) {
        let detected = if self.size.0 >= 640 { 6.0 } else { 4.0 };
        (2.0, detected)
    }
}

/// The frame made smaller to at most `max_width` px wide ([`shown_size`], box filtered), with
/// its [`PredictionMarks`] drawn in: the board as `camera_from_target` places it through
/// `camera` in magenta (each tag's outline on an aprilgrid, a mark at each corner of a ChArUco
/// board or chessboard) and the `detected` corners as green crosses — what an answer predicts
/// beside what was measured (the console's live view). Lines and crosses are sized to read at
/// full size and in a small grid alike. `Err` says what failed (a frame of no pixels).
pub fn prediction(
    grey: &GrayImage,
    max_width: u32,
    board: &Target,
    camera: &CameraModel,
    camera_from_target: &Pose,
    detected: impl IntoIterator<Item = Point2<f64>>,
) -> Result<RgbImage, String> {
    let small = shown(grey, max_width)?;
    let marks = PredictionMarks::of(
        (grey.width(), grey.height()),
        max_width,
        board,
        camera,
        camera_from_target,
        detected,
    );
    let stroke = if small.width() >= 640 { 2 } else { 1 };
    let (board_arm, detected_arm) = marks.cross_arms();
    let mut rgb = vec![0u8; 3 * small.as_raw().len()];
    for (pixel, &v) in rgb.chunks_exact_mut(3).zip(small.as_raw()) {
        pixel.fill(v);
    }
    let mut out =
        RgbImage::from_raw(small.width(), small.height(), rgb).expect("three bytes a pixel");
    let magenta = Rgb([255, 0, 255]);
    for [a, b] in &marks.outlines {
        draw::line(&mut out, *a, *b, stroke, magenta);
    }
    for &corner in &marks.board_corners {
        draw::cross(&mut out, corner, board_arm, magenta);
    }
    for &c in &marks.detected {
        draw::cross(&mut out, c, detected_arm, Rgb([0, 230, 0]));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::board::Board;
    use crate::TagFamily;
    use handeye_core::geometry::pose_from_rotvec;
    use nalgebra::Vector3;

    /// The crate's test lens, or the same lens at `scale` times its resolution.
    fn camera(scale: f64) -> CameraModel {
        let lens = crate::pnp::tests::camera();
        CameraModel {
            width: (f64::from(lens.width) * scale) as u32,
            height: (f64::from(lens.height) * scale) as u32,
            fx: lens.fx * scale,
            fy: lens.fy * scale,
            cx: lens.cx * scale,
            cy: lens.cy * scale,
            ..lens
        }
    }

    fn is_magenta(p: &Rgb<u8>) -> bool {
        p[0] > 200 && p[2] > 200 && p[1] < 60
    }

    fn is_green(p: &Rgb<u8>) -> bool {
        p[1] > 200 && p[0] < 60 && p[2] < 60
    }

    /// The board's tag corners land, outlined in magenta, where the lens puts them in the
    /// smaller frame, the detected corners as green crosses, whether the lens model is the
    /// frame's resolution or twice it.
    #[test]
    fn the_predicted_board_and_the_detected_corners_land_where_the_lens_puts_them() {
        let board = Target::Aprilgrid(
            Board::aprilgrid(6, 6, 0.04, 0.25, TagFamily::Tag36h11, 0, 1).unwrap(),
        );
        let camera_from_target = pose_from_rotvec(
            Vector3::new(-0.14, -0.1, 0.6),
            Vector3::new(0.2, -0.1, 0.05),
        );
        let grey = GrayImage::from_pixel(1280, 720, image::Luma([120]));
        let frame_lens = camera(1.0);
        for lens in [frame_lens, camera(2.0)] {
            let corners: Vec<Point2<f64>> = board
                .aprilgrid()
                .unwrap()
                .tags()
                .iter()
                .take(3)
                .filter_map(|t| frame_lens.project(&(camera_from_target * t.corners_in_target[0])))
                .collect();
            assert_eq!(corners.len(), 3);
            let out = prediction(
                &grey,
                640,
                &board,
                &lens,
                &camera_from_target,
                corners.clone(),
            )
            .unwrap();
            assert_eq!(out.dimensions(), (640, 360));
            let near = |at: Point2<f64>, test: fn(&Rgb<u8>) -> bool| {
                let (x0, y0) = ((at.x + 0.5) / 2.0 - 0.5, (at.y + 0.5) / 2.0 - 0.5);
                (-2i64..=2).any(|dy| {
                    (-2i64..=2).any(|dx| {
                        let (x, y) = (x0.round() as i64 + dx, y0.round() as i64 + dy);
                        x >= 0
                            && y >= 0
                            && out.get_pixel_checked(x as u32, y as u32).is_some_and(test)
                    })
                })
            };
            for tag in board.aprilgrid().unwrap().tags() {
                for p in tag.corners_in_target {
                    let pixel = frame_lens.project(&(camera_from_target * p)).unwrap();
                    assert!(near(pixel, is_magenta), "tag {} corner at {pixel}", tag.id);
                }
            }
            for c in &corners {
                assert!(near(*c, is_green), "detected corner at {c}");
            }
            // Far from the board the frame is its grey.
            assert_eq!(out.get_pixel(2, 2), &Rgb([120, 120, 120]));
        }
        let empty = GrayImage::new(0, 0);
        assert!(prediction(&empty, 640, &board, &frame_lens, &camera_from_target, []).is_err());
    }

    /// A frame is shown shrunk by the smallest whole factor that fits the width: each shown
    /// pixel a square of frame pixels; a narrow frame as it is.
    #[test]
    fn frames_are_shown_shrunk_by_a_whole_factor_within_the_width() {
        for ((width, height), max_width, shown) in [
            ((1280, 720), 960, (640, 360)),
            ((1920, 1080), 960, (960, 540)),
            ((1920, 1200), 960, (960, 600)),
            ((960, 540), 960, (960, 540)),
            ((640, 480), 960, (640, 480)),
            ((2448, 2048), 960, (816, 683)),
            ((1280, 720), 640, (640, 360)),
            ((1920, 1080), 640, (640, 360)),
            ((1, 1), 960, (1, 1)),
            ((0, 0), 960, (1, 1)),
        ] {
            assert_eq!(
                shown_size(width, height, max_width),
                shown,
                "{width}x{height} within {max_width}"
            );
        }
    }

    /// The marks a page draws over a preview are the lens's projections in the shown frame's
    /// pixels (centres at integers), exactly, whatever the lens model's resolution; the preview
    /// is the frame at that size, grey.
    #[test]
    fn marks_are_the_lens_projections_in_the_shown_frames_pixels_over_a_grey_preview() {
        let board = Target::Aprilgrid(
            Board::aprilgrid(6, 6, 0.04, 0.25, TagFamily::Tag36h11, 0, 1).unwrap(),
        );
        let camera_from_target = pose_from_rotvec(
            Vector3::new(-0.14, -0.1, 0.6),
            Vector3::new(0.2, -0.1, 0.05),
        );
        let frame_lens = camera(1.0);
        let (width, height) = (frame_lens.width, frame_lens.height);
        let scale = f64::from(shown_size(width, height, 960).0) / f64::from(width);
        let shown = |p: Point2<f64>| ((p.x + 0.5) * scale - 0.5, (p.y + 0.5) * scale - 0.5);
        let detected = [Point2::new(100.25, 200.75), Point2::new(0.0, 0.0)];
        // The doubled lens scales cx, cy without the half-pixel shift: a quarter pixel off.
        for (lens, tolerance) in [(frame_lens, 1e-6), (camera(2.0), 0.25 * scale)] {
            let marks = PredictionMarks::of(
                (width, height),
                960,
                &board,
                &lens,
                &camera_from_target,
                detected,
            );
            assert_eq!(marks.size, shown_size(width, height, 960));
            assert!(marks.board_corners.is_empty(), "an aprilgrid is outlined");
            let tags = board.aprilgrid().unwrap().tags();
            assert_eq!(marks.outlines.len(), 4 * tags.len());
            for (tag, sides) in tags.iter().zip(marks.outlines.chunks(4)) {
                for (k, [a, _]) in sides.iter().enumerate() {
                    let at = frame_lens
                        .project(&(camera_from_target * tag.corners_in_target[k]))
                        .unwrap();
                    let (x, y) = shown(at);
                    let off = (a.x - x).abs().max((a.y - y).abs());
                    assert!(off <= tolerance, "{a} vs {at}");
                }
            }
            for (mark, c) in marks.detected.iter().zip(detected) {
                assert_eq!((mark.x, mark.y), shown(c));
            }
        }
        let grey = GrayImage::from_fn(width, height, |x, _| image::Luma([(x % 256) as u8]));
        let made = preview(&grey, 960, 80).unwrap();
        let decoded = image::load_from_memory(&made.jpeg).unwrap();
        assert_eq!(decoded.color(), image::ColorType::L8);
        assert_eq!(
            (decoded.width(), decoded.height()),
            shown_size(width, height, 960)
        );
        assert_eq!((made.width, made.height), shown_size(width, height, 960));
        assert!(preview(&GrayImage::new(0, 0), 960, 80).is_err());
    }
}
