//! Annotated frames for people: detected tag outlines, corners (corner 0 marked), ids, the
//! board's axes at `T_camera_target` (x red, y green, z blue, drawn through the lens model)
//! and the reprojection RMS; for ChArUco boards and chessboards the labelled corners (corner 0
//! red). Depends on `vision::{target, detect, pnp, draw}` and
//! `camera_model`.

use image::{GrayImage, Rgb, RgbImage};
use nalgebra::{Point2, Point3};

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
