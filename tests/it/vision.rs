//! Vision chain end to end: rendered frames with known truth through detection and PnP, the
//! real ViSP eye-to-hand frames, and bad input.

use std::path::Path;

use handeye_camera::render::{render, RenderOptions};
use handeye_core::camera_model::{CameraModel, Distortion};
use handeye_core::geometry::Pose;
use handeye_vision::detect::load_gray_image;
use handeye_vision::{
    estimate_board_pose, reproject, Board, DetectorOptions, TagDetector, TargetError,
};
use nalgebra::{Point3, Translation3, UnitQuaternion, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::util;
use util::{dataset, repo};

fn board_6x6() -> Board {
    Board::load(&repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap()
}

fn radtan_camera() -> CameraModel {
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

fn equidistant_camera() -> CameraModel {
    CameraModel {
        width: 1280,
        height: 720,
        fx: 780.0,
        fy: 779.2,
        cx: 638.9,
        cy: 359.4,
        distortion: Distortion::Equidistant {
            k1: 0.05,
            k2: -0.02,
            k3: 0.004,
            k4: -0.001,
        },
    }
}

/// A random view of the board: distance in `[near, far]` m, tilt up to `max_tilt_deg` about a
/// random in-plane axis, any roll within ±30°, with every tag corner at least 20 px inside the
/// image.
fn random_view(
    board: &Board,
    camera: &CameraModel,
    rng: &mut StdRng,
    near: f64,
    far: f64,
    max_tilt_deg: f64,
) -> Pose {
    let extent = board.extent();
    let middle = (extent.min.coords + extent.max.coords) / 2.0;
    let centre = Point3::new(middle.x, middle.y, 0.0);
    loop {
        let distance = rng.random_range(near..far);
        let tilt = rng.random_range(0.0..max_tilt_deg).to_radians();
        let axis_angle = rng.random_range(0.0..std::f64::consts::TAU);
        let axis = Vector3::new(axis_angle.cos(), axis_angle.sin(), 0.0);
        let roll = rng.random_range(-30.0f64..30.0).to_radians();
        // Facing the camera: target z towards the camera, target y up in the image.
        let facing = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        let rotation = facing
            * UnitQuaternion::from_scaled_axis(axis * tilt)
            * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), roll);
        let offset = Vector3::new(
            rng.random_range(-0.2..0.2) * distance,
            rng.random_range(-0.1..0.1) * distance,
            distance,
        );
        let pose = Pose::from_parts(
            Translation3::from(offset - rotation * centre.coords),
            rotation,
        );
        let inside = board.tags().iter().all(|tag| {
            tag.corners_in_target.iter().all(|corner| {
                camera.project(&(pose * corner)).is_some_and(|p| {
                    p.x > 20.0
                        && p.y > 20.0
                        && p.x < camera.width as f64 - 20.0
                        && p.y < camera.height as f64 - 20.0
                })
            })
        });
        if inside {
            return pose;
        }
    }
}

struct FrameResult {
    tags_found: usize,
    corner_squared_errors: Vec<f64>,
    rotation_error_deg: f64,
    translation_error_m: f64,
}

fn run_frame(
    board: &Board,
    camera: &CameraModel,
    detector: &TagDetector,
    truth: &Pose,
    rng: &mut StdRng,
) -> FrameResult {
    let options = RenderOptions {
        noise_sigma: 2.0,
        blur_sigma_px: 0.6,
        ..RenderOptions::default()
    };
    let image = render(board, camera, truth, &options, rng);
    let detection = detector.detect(&image).unwrap();
    let truth_corners = reproject(board, camera, truth);
    let mut corner_squared_errors = Vec::new();
    for tag in &detection.tags {
        let (_, expected) = truth_corners.iter().find(|(id, _)| *id == tag.id).unwrap();
        for (found, expected) in tag.corners_px.iter().zip(expected) {
            corner_squared_errors.push((found - expected).norm_squared());
        }
    }
    let pose = estimate_board_pose(board, camera, &detection).unwrap();
    FrameResult {
        tags_found: detection.tags.len(),
        corner_squared_errors,
        rotation_error_deg: pose
            .camera_from_target
            .rotation
            .angle_to(&truth.rotation)
            .to_degrees(),
        translation_error_m: (pose.camera_from_target.translation.vector
            - truth.translation.vector)
            .norm(),
    }
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

/// Renders `frames` random views and checks the project's floors: every tag found, corner
/// RMS ≤ 0.1 px, and (for views near 0.6 m) median pose error ≤ 0.05° / 0.3 mm.
fn check_rendered_frames(camera: CameraModel, seed: u64) {
    let board = board_6x6();
    let detector = TagDetector::spawn(&board, DetectorOptions::default()).unwrap();
    let mut rng = StdRng::seed_from_u64(seed);
    let mut all_corners = Vec::new();
    // Range coverage: a few frames across 0.4-0.9 m with tilts up to 50°.
    for _ in 0..3 {
        let truth = random_view(&board, &camera, &mut rng, 0.4, 0.9, 50.0);
        let result = run_frame(&board, &camera, &detector, &truth, &mut rng);
        assert_eq!(result.tags_found, 36, "at {:?}", truth.translation);
        all_corners.extend(result.corner_squared_errors);
    }
    // Accuracy at 0.6 m: median over several poses.
    let mut rotation_errors = Vec::new();
    let mut translation_errors = Vec::new();
    for _ in 0..9 {
        let truth = random_view(&board, &camera, &mut rng, 0.55, 0.65, 50.0);
        let result = run_frame(&board, &camera, &detector, &truth, &mut rng);
        assert_eq!(result.tags_found, 36);
        all_corners.extend(result.corner_squared_errors);
        rotation_errors.push(result.rotation_error_deg);
        translation_errors.push(result.translation_error_m);
    }
    let corner_rms = (all_corners.iter().sum::<f64>() / all_corners.len() as f64).sqrt();
    let rotation = median(rotation_errors);
    let translation = median(translation_errors);
    eprintln!(
        "{:?}: corner RMS {corner_rms:.4} px, median pose error {rotation:.4} deg / {:.3} mm",
        camera.distortion,
        translation * 1e3
    );
    assert!(corner_rms <= 0.1, "corner RMS {corner_rms} px > 0.1 px");
    assert!(
        rotation <= 0.05,
        "median rotation error {rotation} deg > 0.05 deg"
    );
    assert!(
        translation <= 0.0003,
        "median translation error {translation} m > 0.3 mm"
    );
}

#[test]
fn rendered_frames_radtan_meet_detection_and_pose_floors() {
    check_rendered_frames(radtan_camera(), 11);
}

#[test]
fn rendered_frames_equidistant_meet_detection_and_pose_floors() {
    check_rendered_frames(equidistant_camera(), 12);
}

#[test]
fn visp_eye_to_hand_frames_find_tag_10_in_all_eight() {
    let Some(folder) = dataset("visp_franka_data-eye-to-hand") else {
        return;
    };
    let board = Board::load(&repo().join("configs/targets/single-tag36h11-id10.yaml")).unwrap();
    let camera =
        CameraModel::load(&repo().join("tests/data/visp_franka_camera_info.yaml")).unwrap();
    let detector = TagDetector::spawn(&board, DetectorOptions::default()).unwrap();
    for n in 1..=8 {
        let image = load_gray_image(&folder.join(format!("franka_image-{n}.png"))).unwrap();
        let detection = detector.detect(&image).unwrap();
        assert_eq!(detection.tags.len(), 1, "image {n}: {detection:?}");
        assert_eq!(detection.tags[0].id, 10);
        let pose = estimate_board_pose(&board, &camera, &detection).unwrap();
        let distance = pose.camera_from_target.translation.vector.norm();
        eprintln!(
            "franka_image-{n}: reprojection RMS {:.3} px, distance {:.3} m, ambiguity ratio {:.2}",
            pose.rms_px,
            distance,
            pose.ambiguity.unwrap_or(0.0)
        );
        // Four corners, six pose parameters: a real tag fits to well under a pixel.
        assert!(pose.rms_px < 1.0, "image {n}: RMS {} px", pose.rms_px);
        assert!((0.1..3.0).contains(&distance), "image {n}: {distance} m");
        assert_eq!(pose.tags_used, 1);
        assert!(pose.ambiguity.is_some());
    }
}

#[test]
fn corrupt_and_missing_images_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let corrupt = dir.path().join("frame.png");
    std::fs::write(&corrupt, b"\x89PNG\r\n\x1a\nthis is not a png").unwrap();
    let error = load_gray_image(&corrupt).unwrap_err();
    assert!(matches!(error, TargetError::Image { .. }), "{error}");
    assert!(error.to_string().contains("frame.png"), "{error}");
    let error = load_gray_image(&dir.path().join("missing.png")).unwrap_err();
    assert!(matches!(error, TargetError::Io { .. }), "{error}");
}

#[test]
fn wrong_intrinsics_file_is_a_clear_error() {
    // A board file is not intrinsics.
    let error = CameraModel::load(&repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap_err();
    let message = error.to_string();
    assert!(
        message.contains("aprilgrid-6x6.yaml") && message.contains("camera_matrix"),
        "{message}"
    );
    let error = CameraModel::load(&repo().join("tests/data/no-such-camera.yaml")).unwrap_err();
    assert!(error.to_string().contains("no-such-camera.yaml"), "{error}");
}

#[test]
fn zero_tag_board_is_refused() {
    let error = Board::from_yaml_str(
        "target_type: aprilgrid\ntagCols: 3\ntagRows: 0\ntagSize: 0.04\ntagSpacing: 0.25\n",
        Path::new("empty.yaml"),
    )
    .unwrap_err();
    let message = error.to_string();
    assert!(
        message.contains("empty.yaml") && message.contains("at least one tag"),
        "{message}"
    );
}

#[test]
fn image_size_disagreeing_with_intrinsics_and_no_tag_visible_are_reported() {
    let board = board_6x6();
    let camera = radtan_camera();
    let detector = TagDetector::spawn(&board, DetectorOptions::default()).unwrap();
    let mut rng = StdRng::seed_from_u64(3);
    let truth = random_view(&board, &camera, &mut rng, 0.5, 0.7, 30.0);
    let image = render(&board, &camera, &truth, &RenderOptions::default(), &mut rng);
    let detection = detector.detect(&image).unwrap();
    let small_camera = CameraModel {
        width: 640,
        height: 480,
        ..camera
    };
    let error = estimate_board_pose(&board, &small_camera, &detection).unwrap_err();
    assert!(
        matches!(
            error,
            TargetError::ImageSizeMismatch {
                image_width: 1280,
                camera_width: 640,
                ..
            }
        ),
        "{error}"
    );
    // Board behind the camera: the frame shows only background.
    let behind = Pose::from_parts(Translation3::new(0.0, 0.0, -0.6), truth.rotation);
    let empty = render(
        &board,
        &camera,
        &behind,
        &RenderOptions::default(),
        &mut rng,
    );
    let detection = detector.detect(&empty).unwrap();
    assert!(detection.tags.is_empty());
    let error = estimate_board_pose(&board, &camera, &detection).unwrap_err();
    assert!(matches!(error, TargetError::NoTagsFound { .. }), "{error}");
}

#[test]
fn tags_not_on_the_board_are_rejected() {
    let board = board_6x6();
    let camera = radtan_camera();
    let mut rng = StdRng::seed_from_u64(5);
    let truth = random_view(&board, &camera, &mut rng, 0.5, 0.6, 20.0);
    let image = render(&board, &camera, &truth, &RenderOptions::default(), &mut rng);
    // A 2x2 board with ids 20-23 and the same tags: only those four are accepted.
    let small =
        Board::aprilgrid(2, 2, 0.04, 0.25, handeye_vision::TagFamily::Tag36h11, 20, 2).unwrap();
    let detector = TagDetector::spawn(&small, DetectorOptions::default()).unwrap();
    let detection = detector.detect(&image).unwrap();
    let ids: Vec<u32> = detection.tags.iter().map(|t| t.id).collect();
    assert_eq!(ids, vec![20, 21, 22, 23]);
    assert_eq!(detection.rejected.len(), 32);
}

#[test]
fn cli_detect_and_target_render_work_end_to_end() {
    let dir = tempfile::tempdir().unwrap();
    let board = board_6x6();
    let camera = radtan_camera();
    let mut rng = StdRng::seed_from_u64(21);
    let truth = random_view(&board, &camera, &mut rng, 0.55, 0.65, 30.0);
    let frame = render(&board, &camera, &truth, &RenderOptions::default(), &mut rng);
    let frame_path = dir.path().join("frame.png");
    frame.save(&frame_path).unwrap();
    let intrinsics = dir.path().join("camera.yaml");
    camera.save_camera_info(&intrinsics).unwrap();
    let corrupt = dir.path().join("corrupt.png");
    std::fs::write(&corrupt, b"not an image").unwrap();
    let results = dir.path().join("poses.yaml");
    let annotated = dir.path().join("annotated");
    let exe = env!("CARGO_BIN_EXE_handeye");
    let output = std::process::Command::new(exe)
        .arg("detect")
        .arg("--board")
        .arg(repo().join("configs/targets/aprilgrid-6x6.yaml"))
        .arg("--intrinsics")
        .arg(&intrinsics)
        .arg(&frame_path)
        .arg("-o")
        .arg(&results)
        .arg("--annotate")
        .arg(&annotated)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        stdout.contains("tags found (36)") && stdout.contains("T_camera_target"),
        "{stdout}"
    );
    assert!(annotated.join("frame-annotated.png").is_file());
    let written: serde_yaml_ng::Value =
        serde_yaml_ng::from_str(&std::fs::read_to_string(&results).unwrap()).unwrap();
    let translation: Vec<f64> = written[0]["T_camera_target"]["translation"]
        .as_sequence()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let error = (Vector3::from_vec(translation) - truth.translation.vector).norm();
    assert!(error < 0.001, "written T_camera_target off by {error} m");

    // A corrupt image fails the command with the file named.
    let output = std::process::Command::new(exe)
        .arg("detect")
        .arg("--board")
        .arg(repo().join("configs/targets/aprilgrid-6x6.yaml"))
        .arg("--intrinsics")
        .arg(&intrinsics)
        .arg(&corrupt)
        .output()
        .unwrap();
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("corrupt.png"));

    // Intrinsics for another image size stop the run with both sizes named.
    let small = dir.path().join("small.yaml");
    CameraModel {
        width: 640,
        height: 480,
        ..camera
    }
    .save_camera_info(&small)
    .unwrap();
    let output = std::process::Command::new(exe)
        .arg("detect")
        .arg("--board")
        .arg(repo().join("configs/targets/aprilgrid-6x6.yaml"))
        .arg("--intrinsics")
        .arg(&small)
        .arg(&frame_path)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("1280x720") && stderr.contains("640x480"),
        "{stderr}"
    );

    // Printable boards: SVG written, unknown extension refused.
    let svg = dir.path().join("board.svg");
    let status = std::process::Command::new(exe)
        .args(["target", "render", "--board"])
        .arg(repo().join("configs/targets/aprilgrid-6x6.yaml"))
        .arg("-o")
        .arg(&svg)
        .status()
        .unwrap();
    assert!(status.success());
    assert!(std::fs::read_to_string(&svg).unwrap().starts_with("<svg"));
    let output = std::process::Command::new(exe)
        .args(["target", "render", "--board"])
        .arg(repo().join("configs/targets/aprilgrid-6x6.yaml"))
        .arg("-o")
        .arg(dir.path().join("board.bmp"))
        .output()
        .unwrap();
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains(".png or .svg"));
}

#[test]
fn tag_standard_41h12_board_renders_and_is_detected() {
    let board = Board::from_yaml_str(
        "target_type: aprilgrid\ntagCols: 3\ntagRows: 2\ntagSize: 0.04\ntagSpacing: 1.0\n\
         family: tagStandard41h12\nfirst_id: 100\nborder_bits: 1\n",
        Path::new("41h12.yaml"),
    )
    .unwrap();
    let camera = radtan_camera();
    let detector = TagDetector::spawn(&board, DetectorOptions::default()).unwrap();
    let mut rng = StdRng::seed_from_u64(41);
    for _ in 0..2 {
        let truth = random_view(&board, &camera, &mut rng, 0.45, 0.6, 35.0);
        let result = run_frame(&board, &camera, &detector, &truth, &mut rng);
        assert_eq!(result.tags_found, 6);
        let rms = (result.corner_squared_errors.iter().sum::<f64>()
            / result.corner_squared_errors.len() as f64)
            .sqrt();
        assert!(rms < 0.15, "corner RMS {rms} px");
        assert!(result.rotation_error_deg < 0.1 && result.translation_error_m < 0.001);
    }
}

/// Issue #29: `detect` on a folder works on every core, one detector per worker; its output is
/// the same, in the images' order, whatever the number of workers, and the first image that
/// fails (in that order) is the one named.
#[test]
fn detect_on_several_workers_gives_the_same_output_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let config = util::sim_cell(dir.path(), 6);
    let session = dir.path().join("s");
    util::run_cell(&config, &session);
    let mut frames: Vec<_> = std::fs::read_dir(session.join("frames"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    frames.sort();
    assert!(frames.len() >= 6);
    let detect = |jobs: &str, images: &[std::path::PathBuf], out: &Path| {
        util::handeye()
            .args(["detect", "-j", jobs, "--board"])
            .arg(repo().join("configs/targets/aprilgrid-6x6.yaml"))
            .arg("--intrinsics")
            .arg(repo().join("configs/cameras/sim-1280x720.yaml"))
            .args(images)
            .arg("-o")
            .arg(out)
            .output()
            .unwrap()
    };
    let (one, two) = (dir.path().join("one.yaml"), dir.path().join("two.yaml"));
    let a = detect("1", &frames, &one);
    let b = detect("2", &frames, &two);
    assert!(a.status.success() && b.status.success());
    assert_eq!(a.stdout, b.stdout, "the same lines in the same order");
    assert_eq!(
        std::fs::read_to_string(&one).unwrap(),
        std::fs::read_to_string(&two).unwrap()
    );
    // An unreadable image among them stops the command naming it (the first in order).
    let broken = dir.path().join("broken.png");
    std::fs::write(&broken, b"not a png").unwrap();
    let mut with_broken = frames.clone();
    with_broken.insert(2, broken);
    let c = detect("2", &with_broken, &dir.path().join("three.yaml"));
    let stderr = String::from_utf8_lossy(&c.stderr);
    assert!(!c.status.success());
    assert!(stderr.contains("broken.png"), "{stderr}");
    // The two images before it were printed, in order; nothing after it.
    let stdout = String::from_utf8_lossy(&c.stdout);
    let printed: Vec<&str> = stdout.lines().filter(|l| l.ends_with(".png:")).collect();
    assert_eq!(printed.len(), 2, "{stdout}");
}

mod small_tags;
