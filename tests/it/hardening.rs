//! Regression tests for issue #13's input-hardening findings, each with the exact reproduction:
//! tiny images that crashed the C detector, a closed stdout, absurd translations, ViSP XML
//! comments, trailing junk after MoveIt JSON, shell metacharacters in frame ids, and a failed
//! ViSP import's partial outputs.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use handeye_core::geometry::{pose_from_rotvec, Pose};
use handeye_core::setup::{self, CellTransforms, PosePair, Setup};
use handeye_formats::export::{export, validate_frame_id, ExportFormat, FrameIdProblem, FrameIds};
use handeye_formats::import::{
    import_csv_pairs, import_moveit_json, read_visp_camera_xml, read_visp_pose, CsvOptions,
    CsvPoseForm,
};
use handeye_records::dataset::Dataset;
use handeye_vision::{Board, DetectorOptions, TagDetector, TargetError};
use image::GrayImage;
use nalgebra::{Translation3, UnitQuaternion, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::util;
use util::handeye;
use util::repo;

fn board_6x6() -> Board {
    Board::load(&repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap()
}

fn noise(width: u32, height: u32, seed: u64) -> GrayImage {
    let mut rng = StdRng::seed_from_u64(seed);
    GrayImage::from_fn(width, height, |_, _| image::Luma([rng.random::<u8>()]))
}

fn options(decimation: f32) -> DetectorOptions {
    DetectorOptions {
        decimation,
        ..DetectorOptions::default()
    }
}

// ---------------------------------------------------------------------------------------------
// #13.4: the detector on tiny images

#[test]
fn issue13_tiny_images_are_refused_before_the_c_detector_and_it_survives() {
    let board = board_6x6();
    // The issue's reproductions: 1×1, 2000×1, and 1280×3 at decimation 2 (all crashed the
    // process); 1280×3 at decimation 1 too (fewer rows than one threshold tile).
    for (width, height, decimation) in [
        (1, 1, 2.0),
        (2000, 1, 2.0),
        (1280, 3, 2.0),
        (1280, 3, 1.0),
        (1, 1, 1.0),
    ] {
        let detector = TagDetector::spawn(&board, options(decimation)).unwrap();
        let error = detector
            .detect(&noise(width, height, 1))
            .expect_err("a tiny image must be refused");
        assert!(
            matches!(error, TargetError::ImageTooSmall { width: w, height: h, .. } if (w, h) == (width, height)),
            "{width}x{height} at {decimation}: {error}"
        );
        let message = error.to_string();
        assert!(
            message.contains(&format!("{width}x{height} px"))
                && message.contains(&format!("decimation {decimation}")),
            "{message}"
        );
        // The same detector still works afterwards.
        let blank = GrayImage::from_pixel(640, 480, image::Luma([200]));
        assert!(detector.detect(&blank).unwrap().tags.is_empty());
    }
}

#[test]
fn issue13_every_size_the_detector_accepts_is_searched_without_crashing() {
    // The smallest accepted images at each decimation and blur, and all their neighbours: a
    // crash here kills the whole test binary, so passing means the size check is sufficient.
    let board = board_6x6();
    for decimation in [1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 16.0] {
        for quad_sigma in [0.0f32, 0.8, -0.8, 4.0] {
            let detector = TagDetector::spawn(
                &board,
                DetectorOptions {
                    decimation,
                    quad_sigma,
                    threads: 1,
                    ..DetectorOptions::default()
                },
            )
            .unwrap();
            let mut accepted = 0;
            for width in (1..=140).chain([240, 255, 256, 257, 258]) {
                for height in [
                    1, 2, 3, 4, 5, 7, 8, 9, 11, 12, 13, 15, 16, 17, 24, 31, 64, 129, 256, 257,
                ] {
                    match detector.detect(&noise(width, height, (width * 1000 + height) as u64)) {
                        Ok(_) => accepted += 1,
                        Err(TargetError::ImageTooSmall { .. }) => {}
                        Err(other) => panic!("{width}x{height}: {other}"),
                    }
                }
            }
            assert!(accepted > 0, "decimation {decimation}: nothing accepted");
            // A camera-sized image is always accepted.
            detector.detect(&noise(640, 480, 7)).unwrap();
        }
    }
}

#[test]
fn issue13_absurd_decimation_is_refused_at_spawn() {
    let board = board_6x6();
    for decimation in [1_000_000.0, 17.0, 0.5, f32::NAN, f32::INFINITY] {
        let error = TagDetector::spawn(&board, options(decimation)).unwrap_err();
        assert!(
            error
                .to_string()
                .contains("decimation: expected a value in [1, 16]"),
            "{decimation}: {error}"
        );
    }
    let error = TagDetector::spawn(
        &board,
        DetectorOptions {
            quad_sigma: 1e9,
            ..DetectorOptions::default()
        },
    )
    .unwrap_err();
    assert!(error.to_string().contains("quad_sigma"), "{error}");
}

#[test]
fn issue13_detect_cli_with_huge_decimation_or_a_1x1_image_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let tiny = dir.path().join("tiny.png");
    noise(1, 1, 3).save(&tiny).unwrap();
    let intrinsics = repo().join("configs/cameras/sim-1280x720.yaml");
    let run = |extra: &[&str]| {
        let output = handeye()
            .arg("detect")
            .arg(&tiny)
            .arg("--board")
            .arg(repo().join("configs/targets/aprilgrid-6x6.yaml"))
            .arg("--intrinsics")
            .arg(&intrinsics)
            .args(extra)
            .output()
            .unwrap();
        (
            output.status.code(),
            String::from_utf8_lossy(&output.stderr).to_string(),
        )
    };
    let (code, stderr) = run(&["--decimation", "1000000"]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("decimation: expected a value in [1, 16], found 1000000"),
        "{stderr}"
    );
    let (code, stderr) = run(&[]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("tiny.png") && stderr.contains("1x1 px is too small"),
        "{stderr}"
    );
}

// ---------------------------------------------------------------------------------------------
// Shared fixtures

/// Known mounts of an eye-in-hand cell.
fn truth() -> CellTransforms {
    CellTransforms {
        setup: Setup::EyeInHand,
        camera_mount: Pose::from_parts(
            Translation3::new(0.03, -0.05, 0.09),
            UnitQuaternion::from_euler_angles(0.1, -0.2, 1.4),
        ),
        target_mount: Pose::from_parts(
            Translation3::new(0.7, 0.1, 0.02),
            UnitQuaternion::from_euler_angles(3.1, 0.05, -0.4),
        ),
    }
}

/// Exact pose pairs of [`truth`] from ten diverse flange poses.
fn exact_pairs() -> Vec<PosePair> {
    let m = truth();
    (0..10)
        .map(|k| {
            let k = k as f64;
            let base_from_flange = pose_from_rotvec(
                Vector3::new(0.4 + 0.03 * k, -0.2 + 0.04 * k, 0.5 - 0.01 * k),
                Vector3::new(0.6 * (k * 1.3).sin(), 0.5 * (k * 0.7).cos(), 0.35 * k),
            );
            PosePair::new(
                base_from_flange,
                setup::predict(m.setup, &m.camera_mount, &m.target_mount, &base_from_flange),
            )
        })
        .collect()
}

fn write_dataset(dir: &Path) -> PathBuf {
    let path = dir.join("samples.yaml");
    Dataset {
        setup: Setup::EyeInHand,
        pairs: exact_pairs(),
    }
    .save(&path)
    .unwrap();
    path
}

/// Runs the binary with its stdout closed before it writes anything (the reader of
/// `handeye … | head -1` gone), returning the exit code and stderr.
fn run_with_stdout_closed(command: &mut Command) -> (Option<i32>, String) {
    let mut child = command
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Close the read end at once: every write the child makes fails with EPIPE.
    drop(child.stdout.take());
    let output = child.wait_with_output().unwrap();
    (
        output.status.code(),
        String::from_utf8_lossy(&output.stderr).to_string(),
    )
}

fn stderr_of(command: &mut Command) -> (Option<i32>, String) {
    let output = command.output().unwrap();
    (
        output.status.code(),
        String::from_utf8_lossy(&output.stderr).to_string(),
    )
}

// ---------------------------------------------------------------------------------------------
// #13.5: stdout closed

#[test]
fn issue13_closed_stdout_ends_quietly_and_solve_still_writes_its_result() {
    let dir = tempfile::tempdir().unwrap();
    let samples = write_dataset(dir.path());
    let result = dir.path().join("result.yaml");
    let (code, stderr) =
        run_with_stdout_closed(handeye().arg("solve").arg(&samples).arg("-o").arg(&result));
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        !stderr.contains("Broken pipe") && !stderr.contains("panicked"),
        "{stderr}"
    );
    let mounts = handeye_records::result::ResultFile::load_mounts(&result).unwrap();
    let error =
        (mounts.camera_mount.translation.vector - truth().camera_mount.translation.vector).norm();
    assert!(error < 1e-6, "result written and right: {error} m");
}

#[test]
fn issue13_closed_stdout_in_plan_check_and_detect_ends_quietly() {
    let dir = tempfile::tempdir().unwrap();
    let config = util::config_variant(dir.path(), "sim-cell.yaml", "cell.yaml", &[]);
    let (code, stderr) =
        run_with_stdout_closed(handeye().args(["plan", "check", "--config"]).arg(&config));
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        !stderr.contains("Broken pipe") && !stderr.contains("panicked"),
        "{stderr}"
    );

    let frame = dir.path().join("blank.png");
    GrayImage::from_pixel(1280, 720, image::Luma([180]))
        .save(&frame)
        .unwrap();
    let out = dir.path().join("detections.yaml");
    let (code, stderr) = run_with_stdout_closed(
        handeye()
            .arg("detect")
            .arg(&frame)
            .arg("--board")
            .arg(repo().join("configs/targets/aprilgrid-6x6.yaml"))
            .arg("--intrinsics")
            .arg(repo().join("configs/cameras/sim-1280x720.yaml"))
            .arg("-o")
            .arg(&out),
    );
    assert!(
        !stderr.contains("Broken pipe") && !stderr.contains("panicked"),
        "{stderr}"
    );
    assert_ne!(code, Some(101), "{stderr}");
    assert!(out.exists(), "detect still wrote its results");
}

// ---------------------------------------------------------------------------------------------
// #13.7: huge finite values

#[test]
fn issue13_a_1e300_translation_in_a_dataset_is_refused_naming_file_sample_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let samples = write_dataset(dir.path());
    let mut raw: handeye_records::dataset::DatasetYaml =
        serde_yaml_ng::from_str(&std::fs::read_to_string(&samples).unwrap()).unwrap();
    raw.samples[4].camera_from_target.translation = Some(vec![1e300, 0.0, 0.2]);
    std::fs::write(&samples, serde_yaml_ng::to_string(&raw).unwrap()).unwrap();
    let result = dir.path().join("result.yaml");
    let (code, stderr) = stderr_of(handeye().arg("solve").arg(&samples).arg("-o").arg(&result));
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("samples.yaml")
            && stderr.contains("samples[4].T_camera_target.translation")
            && stderr.contains("1e300")
            && stderr.contains("100 m"),
        "{stderr}"
    );
    assert!(!result.exists());
}

#[test]
fn issue13_importers_refuse_a_1e300_translation() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // CSV: one row, rotation-vector form.
    let csv = d.join("poses.csv");
    std::fs::write(&csv, "0.4,0.1,0.5,0,0,0,0.01,0.02,1e300,0,0,0\n").unwrap();
    let e = import_csv_pairs(
        &csv,
        &CsvOptions {
            form: CsvPoseForm::RotationVector,
            millimetres: false,
        },
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("poses.csv") && e.contains("line 1, T_camera_target") && e.contains("1e300"),
        "{e}"
    );
    // CSV in millimetres: 500 m after scaling is still refused.
    std::fs::write(&csv, "500000,0,0,0,0,0,0,0,0.5,0,0,0\n").unwrap();
    let e = import_csv_pairs(
        &csv,
        &CsvOptions {
            form: CsvPoseForm::RotationVector,
            millimetres: true,
        },
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("line 1, T_base_flange") && e.contains("500 m"),
        "{e}"
    );
    // MoveIt JSON.
    let identity = |t: f64| format!("[[1,0,0,{t}],[0,1,0,0],[0,0,1,0],[0,0,0,1]]");
    let json = d.join("samples.json");
    std::fs::write(&json, format!("[[{}, {}]]", identity(1e300), identity(0.5))).unwrap();
    let e = import_moveit_json(&json).unwrap_err().to_string();
    assert!(
        e.contains("samples.json")
            && e.contains("sample 0 ([0][0], T_base_flange)")
            && e.contains("1e300"),
        "{e}"
    );
    // ViSP pose vector.
    let visp = d.join("arm_pose_rPe_1.yaml");
    std::fs::write(
        &visp,
        "rows: 6\ncols: 1\ndata:\n  - [1e300]\n  - [0]\n  - [0.4]\n  - [3.1]\n  - [0]\n  - [0]\n",
    )
    .unwrap();
    let e = read_visp_pose(&visp).unwrap_err().to_string();
    assert!(
        e.contains("arm_pose_rPe_1.yaml") && e.contains("1e300"),
        "{e}"
    );
}

#[test]
fn issue13_export_refuses_an_absurd_result() {
    // The library: a translation of 1e300 m and a NaN rotation are refused, not printed.
    let mut m = truth();
    m.camera_mount.translation.vector.x = 1e300;
    let e = export(&m, ExportFormat::Ros2, &FrameIds::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("T_flange_camera") && e.contains("1e300"), "{e}");
    let mut m = truth();
    m.target_mount.rotation =
        UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(f64::NAN, 0.0, 0.0, 0.0));
    let e = export(&m, ExportFormat::Json, &FrameIds::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("T_base_target") && e.contains("not a finite unit quaternion"),
        "{e}"
    );

    // The CLI: a result file edited to hold 1e300 is refused with exit 1 and nothing printed.
    let dir = tempfile::tempdir().unwrap();
    let samples = write_dataset(dir.path());
    let result = dir.path().join("result.yaml");
    let (code, stderr) = stderr_of(handeye().arg("solve").arg(&samples).arg("-o").arg(&result));
    assert_eq!(code, Some(0), "{stderr}");
    let text = std::fs::read_to_string(&result).unwrap();
    let mut value: serde_yaml_ng::Value = serde_yaml_ng::from_str(&text).unwrap();
    value["T_flange_camera"]["translation"][0] = serde_yaml_ng::Value::from(1e300);
    std::fs::write(&result, serde_yaml_ng::to_string(&value).unwrap()).unwrap();
    let output = handeye()
        .args(["export", "--format", "ros2"])
        .arg(&result)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(output.stdout.is_empty());
    assert!(
        stderr.contains("result.yaml") && stderr.contains("1e300"),
        "{stderr}"
    );
}

// ---------------------------------------------------------------------------------------------
// #13.8: parsers

const VISP_XML: &str = r#"<?xml version="1.0"?>
<root>
  <!-- <camera><image_width>1</image_width></camera> -->
  <camera>
    <name>Camera</name>
    <image_width>640</image_width>
    <image_height>480</image_height>
    <!-- an old calibration: <model><type>perspectiveProjWithDistortion</type><px>1</px></model> -->
    <model>
      <type>perspectiveProjWithDistortion</type>
      <!-- <px>1</px> -->
      <px>600.5</px>
      <py><!-- 2 -->601</py>
      <u0>320.5</u0>
      <v0>240</v0>
      <kud>-0.1</kud>
      <kdu>0.1</kdu>
    </model>
  </camera>
</root>
"#;

#[test]
fn issue13_visp_xml_values_inside_comments_are_ignored() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("camera.xml");
    std::fs::write(&path, VISP_XML).unwrap();
    let m = read_visp_camera_xml(&path).unwrap();
    assert_eq!(
        (m.width, m.height, m.fx, m.fy, m.cx, m.cy),
        (640, 480, 600.5, 601.0, 320.5, 240.0)
    );
    // Not XML at all (unclosed element): a parse error naming the file.
    std::fs::write(&path, "<root><camera><px>600</camera></root>").unwrap();
    let e = read_visp_camera_xml(&path).unwrap_err().to_string();
    assert!(
        e.contains("camera.xml") && e.contains("not a ViSP vpXmlParserCamera XML"),
        "{e}"
    );
}

#[test]
fn issue13_moveit_json_with_trailing_junk_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("samples.json");
    let identity = "[[1,0,0,0.1],[0,1,0,0],[0,0,1,0],[0,0,0,1]]";
    let good = format!("[[{identity}, {identity}]]");
    std::fs::write(&path, format!("{good}\n")).unwrap();
    assert_eq!(import_moveit_json(&path).unwrap().len(), 1);
    for junk in ["]", "garbage", "[[1]]", "{}"] {
        std::fs::write(&path, format!("{good}{junk}")).unwrap();
        let e = import_moveit_json(&path).unwrap_err().to_string();
        assert!(
            e.contains("samples.json") && e.contains("text after the array"),
            "{junk}: {e}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// #13.9: shell injection through frame ids

#[test]
fn issue13_shell_metacharacters_in_a_frame_id_are_refused_by_the_cli() {
    let dir = tempfile::tempdir().unwrap();
    let samples = write_dataset(dir.path());
    let result = dir.path().join("result.yaml");
    let (code, stderr) = stderr_of(handeye().arg("solve").arg(&samples).arg("-o").arg(&result));
    assert_eq!(code, Some(0), "{stderr}");
    let output = handeye()
        .args([
            "export",
            "--format",
            "ros2",
            "--base-frame",
            "base;touch${IFS}x;$(id)",
        ])
        .arg(&result)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(output.stdout.is_empty(), "nothing to paste");
    assert!(
        stderr.contains("--base-frame") && stderr.contains("';' is not allowed"),
        "{stderr}"
    );
    // A namespaced id is fine and comes out as one shell word.
    let output = handeye()
        .args(["export", "--format", "ros2", "--base-frame", "robot1/base"])
        .arg(&result)
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(0));
    let text = String::from_utf8_lossy(&output.stdout);
    // Eye-in-hand: the second command publishes T_base_target.
    let line = text
        .lines()
        .filter(|l| l.starts_with("ros2 run"))
        .nth(1)
        .unwrap();
    let words = shlex::split(line).unwrap();
    let at = words.iter().position(|w| w == "--frame-id").unwrap();
    assert_eq!(words[at + 1], "robot1/base", "{line}");
}

#[test]
fn issue13_frame_ids_follow_ros_naming_rules() {
    for good in [
        "base",
        "tool0",
        "camera_optical_frame",
        "robot1/base_link",
        "_private",
        "a/b/c",
    ] {
        assert_eq!(validate_frame_id(good), Ok(()), "{good}");
    }
    let cases = [
        ("", FrameIdProblem::Empty),
        ("base;touch${IFS}x;$(id)", FrameIdProblem::Character(';')),
        ("base link", FrameIdProblem::Character(' ')),
        ("base'", FrameIdProblem::Character('\'')),
        ("bäse", FrameIdProblem::Character('ä')),
        ("/base", FrameIdProblem::LeadingSlash),
        ("base/", FrameIdProblem::EmptySegment),
        ("a//b", FrameIdProblem::EmptySegment),
        ("0base", FrameIdProblem::LeadingDigit),
        ("robot/1base", FrameIdProblem::LeadingDigit),
    ];
    for (id, problem) in cases {
        assert_eq!(validate_frame_id(id), Err(problem), "{id:?}");
    }
    assert_eq!(
        validate_frame_id(&"a".repeat(257)),
        Err(FrameIdProblem::TooLong)
    );
    // The library refuses them too (not only the CLI).
    let ids = FrameIds {
        camera: "cam$(id)".into(),
        ..FrameIds::default()
    };
    let e = export(&truth(), ExportFormat::Ros2, &ids)
        .unwrap_err()
        .to_string();
    assert!(e.contains("camera frame id") && e.contains("'$'"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// #13.10: a failed `import visp --cell-out` leaves nothing behind

/// A ViSP-style folder with blank frames (imported with --skip-unfound).
fn blank_visp_folder(d: &Path) {
    std::fs::write(
        d.join("cam.xml"),
        "<root><camera><image_width>64</image_width><image_height>48</image_height><model><type>perspectiveProjWithoutDistortion</type><px>60</px><py>60</py><u0>32</u0><v0>24</v0></model></camera></root>",
    )
    .unwrap();
    for n in 1..=2 {
        std::fs::write(
            d.join(format!("arm_pose_rPe_{n}.yaml")),
            "rows: 6\ncols: 1\ndata:\n  - [0.5]\n  - [0]\n  - [0.4]\n  - [3.1]\n  - [0]\n  - [0]\n",
        )
        .unwrap();
        GrayImage::from_pixel(64, 48, image::Luma([200u8]))
            .save(d.join(format!("arm_image-{n}.png")))
            .unwrap();
    }
}

fn import_visp_cli(folder: &Path, out: &Path, cell_out: &Path) -> (Option<i32>, String) {
    stderr_of(
        handeye()
            .args(["import", "visp"])
            .arg(folder)
            .arg("--board")
            .arg(repo().join("configs/targets/single-tag36h11-id10.yaml"))
            .args(["--setup", "eye_in_hand", "--skip-unfound", "-o"])
            .arg(out.join("dataset.yaml"))
            .arg("--cell-out")
            .arg(cell_out),
    )
}

fn outputs_left(out: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn issue13_failed_import_visp_cell_out_leaves_no_partial_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("visp");
    let out = dir.path().join("out");
    std::fs::create_dir_all(&folder).unwrap();
    std::fs::create_dir_all(&out).unwrap();
    blank_visp_folder(&folder);

    // The cell config cannot be written (its folder does not exist): the dataset, intrinsics
    // and poses written before it are removed again.
    let (code, stderr) = import_visp_cli(&folder, &out, &dir.path().join("missing/cell.yaml"));
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("cell.yaml"), "{stderr}");
    assert_eq!(outputs_left(&out), Vec::<String>::new(), "{stderr}");

    // An image without a pose: the folder camera would pair frames wrongly, so no cell config;
    // refused before anything is written.
    GrayImage::from_pixel(64, 48, image::Luma([200u8]))
        .save(folder.join("zz_extra.png"))
        .unwrap();
    let (code, stderr) = import_visp_cli(&folder, &out, &out.join("cell.yaml"));
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("no cell config written"), "{stderr}");
    assert_eq!(outputs_left(&out), Vec::<String>::new(), "{stderr}");

    // The same import succeeding writes all four files.
    std::fs::remove_file(folder.join("zz_extra.png")).unwrap();
    let (code, stderr) = import_visp_cli(&folder, &out, &out.join("cell.yaml"));
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(
        outputs_left(&out),
        [
            "cell.yaml",
            "dataset-camera.yaml",
            "dataset-poses.yaml",
            "dataset.yaml"
        ]
    );
}

#[test]
fn issue13_replay_of_a_session_with_a_1x1_frame_skips_that_frame_and_solves() {
    let dir = tempfile::tempdir().unwrap();
    let config = util::config_variant(
        dir.path(),
        "sim-cell.yaml",
        "cell.yaml",
        &[("count: 20", "count: 8")],
    );
    let session = dir.path().join("session");
    let (code, stderr) = stderr_of(
        handeye()
            .args(["run", "--config"])
            .arg(&config)
            .arg("--output")
            .arg(&session),
    );
    assert_eq!(code, Some(0), "{stderr}");
    // The frame of pose 2 becomes a single pixel (it used to crash the C detector).
    GrayImage::from_pixel(1, 1, image::Luma([0]))
        .save(session.join("frames/002.png"))
        .unwrap();
    let output = handeye().arg("replay").arg(&session).output().unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(0), "{stdout}\n{stderr}");
    assert!(
        stdout
            .lines()
            .any(|l| l.contains("pose   2") && l.contains("1x1 px is too small")),
        "{stdout}"
    );
    assert!(session.join("replay-result.yaml").exists());
    // With `-o` elsewhere the replay writes nothing into the session.
    let recorded = util::folder_bytes(&session);
    let elsewhere = dir.path().join("replayed.yaml");
    let output = handeye()
        .arg("replay")
        .arg(&session)
        .arg("-o")
        .arg(&elsewhere)
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(0));
    assert!(elsewhere.is_file() && dir.path().join("replay-report.html").is_file());
    assert_eq!(
        util::folder_bytes(&session),
        recorded,
        "replay -o wrote into the session"
    );
}

mod attack;
