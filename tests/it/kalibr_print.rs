//! Kalibr-printed aprilgrids (black squares at every tag corner): frames drawn by an
//! independent renderer (tests/python/kalibr_render.py: numpy + OpenCV, tag bitmaps from
//! OpenCV's dictionary, the board laid out as `kalibr_create_target_pdf` draws it) with known
//! poses, detected by the library and compared with OpenCV's ArUco detector + solvePnP on the
//! same frames; the same board without the squares; and our own `target render` output read
//! back.
//!
//! The Python side needs numpy and opencv-python-headless (< 5): python3's own when it has
//! them (scripts/test.sh installs them), otherwise installed into a venv under the build's
//! temporary directory on first use. Without python3 the tests say so and skip; CI has it.

use std::path::{Path, PathBuf};
use std::process::Command;

use handeye_core::camera_model::{CameraModel, Distortion};
use handeye_core::geometry::Pose;
use handeye_vision::detect::load_gray_image;
use handeye_vision::{estimate_board_pose, Board, DetectorOptions, TagDetector, TagFamily};
use nalgebra::{Matrix4, Point2};
use sha2::{Digest, Sha256};

use crate::util;
use util::{pose_error_mm_deg, repo};

/// The camera of the rendered frames (plumb_bob = OpenCV's radial-tangential model).
fn camera() -> CameraModel {
    CameraModel {
        width: 1280,
        height: 720,
        fx: 912.4,
        fy: 910.8,
        cx: 641.7,
        cy: 361.2,
        distortion: Distortion::RadTan {
            k1: -0.12,
            k2: 0.08,
            p1: 0.0006,
            p2: -0.0004,
            k3: -0.02,
        },
    }
}

/// Kalibr's default print (`--tspace 0.3`) of a 6x6 tag36h11 grid with 4 cm tags.
const TAG_SIZE: f64 = 0.04;
const TAG_SPACING: f64 = 0.3;

fn board(corner_squares: bool) -> Board {
    Board::aprilgrid(6, 6, TAG_SIZE, TAG_SPACING, TagFamily::Tag36h11, 0, 2)
        .and_then(|b| b.with_corner_squares(corner_squares))
        .unwrap()
}

fn spec(corner_squares: bool, seed: u64) -> String {
    let c = camera();
    let Distortion::RadTan { k1, k2, p1, p2, k3 } = c.distortion else {
        unreachable!("the test camera is radtan")
    };
    format!(
        r#"{{"board": {{"cols": 6, "rows": 6, "tag_size": {TAG_SIZE}, "tag_spacing": {TAG_SPACING}, "corner_squares": {corner_squares}}},
 "camera": {{"width": {}, "height": {}, "fx": {}, "fy": {}, "cx": {}, "cy": {}, "dist": [{k1}, {k2}, {p1}, {p2}, {k3}]}},
 "frames": 8, "seed": {seed}, "near": 0.45, "far": 0.8, "max_tilt_deg": 40, "supersample": 3,
 "blur_sigma": 0.7, "noise_sigma": 2.0}}"#,
        c.width, c.height, c.fx, c.fy, c.cx, c.cy
    )
}

/// Renders the frames of `spec` (cached by the spec's and the script's content).
fn frames(python: &Path, spec: &str) -> PathBuf {
    let script = repo().join("tests/python/kalibr_render.py");
    let mut hash = Sha256::new();
    hash.update(spec.as_bytes());
    hash.update(std::fs::read(&script).unwrap());
    let key: String = hash.finalize()[..8]
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("kalibr-frames-{key}"));
    if !out.join("truth.json").exists() {
        let spec_file = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("spec-{key}.json"));
        std::fs::write(&spec_file, spec).unwrap();
        let status = Command::new(python)
            .arg(&script)
            .arg(&spec_file)
            .arg(&out)
            .status()
            .unwrap();
        assert!(status.success(), "{} failed", script.display());
    }
    out
}

fn pose_from(values: &serde_json::Value) -> Option<Pose> {
    let v: Vec<f64> = values
        .as_array()?
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let m = Matrix4::from_row_slice(&v);
    let rotation = nalgebra::Rotation3::from_matrix_unchecked(m.fixed_view::<3, 3>(0, 0).into());
    Some(Pose::from_parts(
        nalgebra::Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]),
        nalgebra::UnitQuaternion::from_rotation_matrix(&rotation),
    ))
}

/// Median relative-motion errors (degrees, mm) over every pair of frames both estimates
/// cover: `T_ci_cj` from the estimates against the truth.
fn relative_motion_errors(truth: &[Pose], estimate: &[Option<Pose>]) -> (f64, f64) {
    let (mut deg, mut mm) = (Vec::new(), Vec::new());
    for i in 0..truth.len() {
        for j in i + 1..truth.len() {
            let (Some(a), Some(b)) = (&estimate[i], &estimate[j]) else {
                continue;
            };
            let true_motion = truth[i] * truth[j].inverse();
            let motion = a * b.inverse();
            let (e_mm, e_deg) = pose_error_mm_deg(&motion, &true_motion);
            deg.push(e_deg);
            mm.push(e_mm);
        }
    }
    assert!(!deg.is_empty(), "no pair of frames with poses");
    (median(&mut deg), median(&mut mm))
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(|a, b| a.total_cmp(b));
    values[values.len() / 2]
}

/// What the library and OpenCV made of a frame set.
#[derive(Debug)]
struct Comparison {
    visible: usize,
    ours_found: usize,
    opencv_found: usize,
    /// Median relative-motion error, ours: degrees, mm.
    ours: (f64, f64),
    /// The same for OpenCV.
    opencv: (f64, f64),
    /// Mean corner error against the projected truth, px.
    ours_corner_px: f64,
}

fn compare(board: &Board, dir: &Path) -> Comparison {
    let truth_file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap();
    let camera = camera();
    let detector = TagDetector::spawn(board, DetectorOptions::default()).unwrap();
    let (mut truth, mut ours, mut opencv) = (Vec::new(), Vec::new(), Vec::new());
    let (mut visible, mut ours_found, mut opencv_found) = (0, 0, 0);
    let (mut corner_error, mut corners) = (0.0, 0);
    for frame in truth_file["frames"].as_array().unwrap() {
        let image = load_gray_image(&dir.join(frame["file"].as_str().unwrap())).unwrap();
        let true_pose = pose_from(&frame["camera_from_target"]).unwrap();
        let seen: Vec<u64> = frame["visible"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        visible += seen.len();
        opencv_found += frame["opencv_ids"].as_array().unwrap().len();
        let detection = detector.detect(&image).unwrap();
        ours_found += detection
            .tags
            .iter()
            .filter(|t| seen.contains(&(t.id as u64)))
            .count();
        for tag in &detection.tags {
            let points = board.tag_corners_in_target(tag.id).unwrap();
            for (point, pixel) in points.iter().zip(tag.corners_px) {
                let projected: Point2<f64> = camera.project(&(true_pose * point)).unwrap();
                corner_error += (projected - pixel).norm();
                corners += 1;
            }
        }
        ours.push(
            estimate_board_pose(board, &camera, &detection)
                .ok()
                .map(|p| p.camera_from_target),
        );
        opencv.push(pose_from(&frame["opencv_camera_from_target"]));
        truth.push(true_pose);
    }
    Comparison {
        visible,
        ours_found,
        opencv_found,
        ours: relative_motion_errors(&truth, &ours),
        opencv: relative_motion_errors(&truth, &opencv),
        ours_corner_px: corner_error / corners.max(1) as f64,
    }
}

fn check(name: &str, board: &Board, c: &Comparison) {
    eprintln!(
        "{name}: handeye found {}/{} visible tags, OpenCV {}/{}; relative motion median \
         handeye {:.4}° / {:.3} mm, OpenCV {:.4}° / {:.3} mm; handeye corner error {:.3} px \
         (corner squares: {})",
        c.ours_found,
        c.visible,
        c.opencv_found,
        c.visible,
        c.ours.0,
        c.ours.1,
        c.opencv.0,
        c.opencv.1,
        c.ours_corner_px,
        board.corner_squares()
    );
    assert!(
        c.ours_found as f64 >= 0.95 * c.visible as f64,
        "{name}: {} of {} visible tags found",
        c.ours_found,
        c.visible
    );
    assert!(
        c.ours.0 <= c.opencv.0 && c.ours.1 <= c.opencv.1,
        "{name}: relative motion {:?} (deg, mm) is worse than OpenCV's {:?}",
        c.ours,
        c.opencv
    );
}

#[test]
fn kalibr_print_with_corner_squares_is_found_and_beats_opencv() {
    let Some(python) = util::python_with_opencv() else {
        return;
    };
    let board = board(true);
    let dir = frames(&python, &spec(true, 7));
    let c = compare(&board, &dir);
    check("Kalibr print with corner squares", &board, &c);
}

#[test]
fn the_same_board_without_corner_squares_is_still_found_and_beats_opencv() {
    let Some(python) = util::python_with_opencv() else {
        return;
    };
    let board = board(false);
    let dir = frames(&python, &spec(false, 7));
    let c = compare(&board, &dir);
    check("the board without corner squares", &board, &c);
}

/// The board file's `target render` PNG (with the corner squares, as Kalibr prints) read back:
/// every tag found, each corner where the page geometry puts it (known scale, y down; only the
/// page offset is unknown) to 0.1 px, though the image is pixel-sharp (no camera blur). With
/// `--no-corner-squares` the squares are gone.
#[test]
fn our_target_render_with_corner_squares_is_detected_back() {
    let dir = tempfile::tempdir().unwrap();
    let target = repo().join("configs/targets/aprilgrid-6x6.yaml");
    let board = Board::load(&target).unwrap();
    assert!(
        board.corner_squares(),
        "Kalibr files default to the squares"
    );
    // 254 dpi = 10 px/mm: every edge of this board (4 cm tags, 1 cm gaps) falls on a pixel
    // boundary, so the page geometry is exact in the image.
    let dpi = 254.0;
    let px_per_m = dpi / 0.0254;
    let render = |name: &str, extra: &[&str]| {
        let png = dir.path().join(name);
        let output = util::handeye()
            .args(["target", "render", "--board"])
            .arg(&target)
            .arg("-o")
            .arg(&png)
            .args(["--dpi", "254"])
            .args(extra)
            .output()
            .unwrap();
        assert!(output.status.success(), "{output:?}");
        load_gray_image(&png).unwrap()
    };
    let image = render("board.png", &[]);
    let detector = TagDetector::spawn(&board, DetectorOptions::default()).unwrap();
    let detection = detector.detect(&image).unwrap();
    assert_eq!(detection.tags.len(), 36, "{:?}", detection.rejected);
    // Page pixel of a target point, up to the page offset: x right, y down, centres at integers.
    let page = |p: &nalgebra::Point3<f64>| Point2::new(p.x * px_per_m, -p.y * px_per_m);
    let pairs: Vec<(Point2<f64>, Point2<f64>)> = detection
        .tags
        .iter()
        .flat_map(|tag| {
            let points = board.tag_corners_in_target(tag.id).unwrap();
            points.map(|p| page(&p)).into_iter().zip(tag.corners_px)
        })
        .collect();
    let offset = pairs
        .iter()
        .map(|(model, found)| found - model)
        .sum::<nalgebra::Vector2<f64>>()
        / pairs.len() as f64;
    let worst = pairs
        .iter()
        .map(|(model, found)| (found - (model + offset)).norm())
        .fold(0.0, f64::max);
    eprintln!("target render PNG at {dpi} dpi: 36/36 tags, worst corner off by {worst:.4} px");
    assert!(
        worst < 0.1,
        "worst corner {worst} px from the page geometry"
    );

    // The pixel at the middle of the square between tags 0, 1, 6 and 7 is black with the
    // squares and white without.
    let square = board.corner_square_origins()[8];
    let g = board.corner_square_size();
    let middle = page(&nalgebra::Point3::new(
        square.x + g / 2.0,
        square.y + g / 2.0,
        0.0,
    )) + offset;
    let at = |image: &image::GrayImage| {
        image.get_pixel(middle.x.round() as u32, middle.y.round() as u32)[0]
    };
    assert_eq!(at(&image), 0);
    let plain = render("plain.png", &["--no-corner-squares"]);
    assert_eq!(at(&plain), 255);
    let plain_board = board.clone().with_corner_squares(false).unwrap();
    let detector = TagDetector::spawn(&plain_board, DetectorOptions::default()).unwrap();
    assert_eq!(detector.detect(&plain).unwrap().tags.len(), 36);
}
