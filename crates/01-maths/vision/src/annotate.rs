//! Annotated frames for people. [`annotate`] (`handeye detect`): detected tag outlines, corners
//! (corner 0 marked), ids, the board's axes at `T_camera_target` (x red, y green, z blue, drawn
//! through the lens model) and the reprojection RMS; for ChArUco boards and chessboards the
//! labelled corners (corner 0 red). [`prediction`] (the report's frames, the console's live
//! view): the frame made smaller with the board where an answer predicts it beside the corners
//! detected. Depends on `vision::{target, detect, pnp, draw, shrink}` and `camera_model`.

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

/// The frame made smaller to at most `max_width` px wide (box filtered, [`box_shrink`]; a frame
/// already narrow enough keeps its size), with the board as `camera_from_target` places it
/// through `camera` in magenta (each tag's outline on an aprilgrid, a mark at each corner of a
/// ChArUco board or chessboard) and the `detected` corners (full-resolution pixels) as green
/// crosses: what an answer predicts beside what was measured. `camera` may be of another
/// resolution than the frame (a live view decoded smaller): its pixels are scaled to the
/// frame's. Lines and crosses are sized to read at full size and in a small grid alike. `Err`
/// says what failed (a frame of no pixels).
///
/// [`box_shrink`]: crate::shrink::box_shrink
pub fn prediction(
    grey: &GrayImage,
    max_width: u32,
    board: &Target,
    camera: &CameraModel,
    camera_from_target: &Pose,
    detected: impl IntoIterator<Item = Point2<f64>>,
) -> Result<RgbImage, String> {
    if grey.width() == 0 || grey.height() == 0 {
        return Err("a frame of no pixels".into());
    }
    let width = grey.width().clamp(1, max_width.max(1));
    let scale = f64::from(width) / f64::from(grey.width());
    let height = ((f64::from(grey.height()) * scale).round() as u32).max(1);
    let small = if width == grey.width() {
        std::borrow::Cow::Borrowed(grey)
    } else {
        std::borrow::Cow::Owned(crate::shrink::box_shrink(grey, width, height)?)
    };
    let stroke = if width >= 640 { 2 } else { 1 };
    let mut rgb = vec![0u8; 3 * small.as_raw().len()];
    for (pixel, &v) in rgb.chunks_exact_mut(3).zip(small.as_raw()) {
        pixel.fill(v);
    }
    let mut out =
        RgbImage::from_raw(small.width(), small.height(), rgb).expect("three bytes a pixel");
    // Pixel centres: full-resolution pixel u maps to (u + 0.5)·s − 0.5 in the smaller frame.
    let to_small =
        |p: Point2<f64>, s: f64| Point2::new((p.x + 0.5) * s - 0.5, (p.y + 0.5) * s - 0.5);
    let lens_scale = scale * f64::from(grey.width()) / f64::from(camera.width.max(1));
    let project = |p: &Point3<f64>| {
        camera
            .project(&(camera_from_target * p))
            .map(|pixel| to_small(pixel, lens_scale))
    };
    let magenta = Rgb([255, 0, 255]);
    match board.aprilgrid() {
        Some(grid) => {
            for tag in grid.tags() {
                let pixels: Vec<Option<Point2<f64>>> =
                    tag.corners_in_target.iter().map(project).collect();
                for k in 0..4 {
                    if let (Some(a), Some(b)) = (pixels[k], pixels[(k + 1) % 4]) {
                        draw::line(&mut out, a, b, stroke, magenta);
                    }
                }
            }
        }
        None => {
            for (_, _, p) in board.points() {
                if let Some(pixel) = project(&p) {
                    draw::cross(&mut out, pixel, 2.0, magenta);
                }
            }
        }
    }
    for c in detected {
        draw::cross(
            &mut out,
            to_small(c, scale),
            2.0 + 2.0 * f64::from(stroke),
            Rgb([0, 230, 0]),
        );
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
}
