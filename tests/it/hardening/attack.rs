//! Issue #25: the last holes found by attack. Every refusal names the file, the key and the value.

use super::*;

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// A `camera_info` YAML of a 1280x720 camera with these camera matrix numbers and coefficients.
fn camera_info(k: &str, d: &str) -> String {
    format!(
        "image_width: 1280\nimage_height: 720\ncamera_name: c\ncamera_matrix:\n  rows: 3\n  cols: 3\n  \
         data: [{k}]\ndistortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n  \
         data: [{d}]\n"
    )
}

const K_SIM: &str = "800.0, 0.0, 641.3, 0.0, 800.0, 358.7, 0.0, 0.0, 1.0";

fn load_error(path: &Path) -> String {
    handeye_core::camera_model::CameraModel::load(path)
        .expect_err("must be refused")
        .to_string()
}

/// The sample ids of the dataset at `path`, replaced by `ids` (raw YAML scalars).
fn dataset_with_ids(dir: &Path, ids: &[&str]) -> PathBuf {
    let samples = write_dataset(dir);
    let mut text = std::fs::read_to_string(&samples).unwrap();
    for id in ids {
        text = text.replacen(
            "- T_base_flange:",
            &format!("- id: {id}\n  T_base_flange:"),
            1,
        );
    }
    std::fs::write(&samples, text).unwrap();
    samples
}

#[test]
fn issue25_a_duplicate_sample_id_in_a_dataset_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let samples = dataset_with_ids(dir.path(), &["pose-001", "pose-002", "pose-001"]);
    let (code, stderr) = stderr_of(handeye().arg("solve").arg(&samples));
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("samples.yaml")
            && stderr.contains("samples[2].id")
            && stderr.contains("pose-001")
            && stderr.contains("samples[0]")
            && stderr.contains("unique"),
        "{stderr}"
    );
}

#[test]
fn issue25_a_numeric_sample_id_is_refused_and_a_quoted_one_read_as_written() {
    let dir = tempfile::tempdir().unwrap();
    let samples = dataset_with_ids(dir.path(), &["pose-a", "7"]);
    let (code, stderr) = stderr_of(handeye().arg("solve").arg(&samples));
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("samples.yaml")
            && stderr.contains("samples[1].id")
            && stderr.contains("integer `7`")
            && stderr.contains("quote"),
        "{stderr}"
    );
    // Quoted, it is the text `07`, not the number 7.
    let samples = dataset_with_ids(dir.path(), &["pose-a", "\"07\""]);
    let dataset = Dataset::load(&samples).unwrap();
    assert_eq!(dataset.pairs[1].id.as_deref(), Some("07"));
}

/// A copy of the fuzz corpus's trimmed session (2 plan poses of `configs/sim-cell.yaml`, the
/// 6x6 aprilgrid) whose `poses/000.yaml` is edited by `edit`.
fn corpus_session(dir: &Path, edit: impl Fn(String) -> String) -> PathBuf {
    let session = dir.join("session");
    let source = repo().join("tests/fuzz-corpus/session");
    for sub in ["", "poses", "frames"] {
        std::fs::create_dir_all(session.join(sub)).unwrap();
        for entry in std::fs::read_dir(source.join(sub)).unwrap() {
            let entry = entry.unwrap();
            if entry.file_type().unwrap().is_file() {
                std::fs::copy(entry.path(), session.join(sub).join(entry.file_name())).unwrap();
            }
        }
    }
    let record = session.join("poses/000.yaml");
    let text = std::fs::read_to_string(&record).unwrap();
    std::fs::write(&record, edit(text)).unwrap();
    session
}

fn solve_session(session: &Path) -> (Option<i32>, String) {
    stderr_of(
        handeye()
            .arg("solve")
            .arg(session)
            .arg("--config")
            .arg(repo().join("configs/sim-cell.yaml"))
            .arg("-o")
            .arg(session.join("result-test.yaml")),
    )
}

#[test]
fn issue25_a_corner_recorded_twice_in_one_frame_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    // Tag 1 corner 0 appears a second time (its first line is `- - 1.0` then `  - 0.0`).
    let session = corpus_session(dir.path(), |text| {
        format!("{text}- - 1.0\n  - 0.0\n  - 600.0\n  - 560.0\n")
    });
    let (code, stderr) = solve_session(&session);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("poses/000.yaml")
            && stderr.contains("corners_px[8]")
            && stderr.contains("tag id 1 corner 0")
            && stderr.contains("twice")
            && stderr.contains("corners_px[4]"),
        "{stderr}"
    );
}

#[test]
fn issue25_a_corner_of_a_tag_not_on_the_board_is_refused_not_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let session = corpus_session(dir.path(), |text| {
        format!("{text}- - 9999.0\n  - 0.0\n  - 600.0\n  - 560.0\n")
    });
    let (code, stderr) = solve_session(&session);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("poses/000.yaml")
            && stderr.contains("corners_px[8]")
            && stderr.contains("tag id 9999")
            && stderr.contains("not on the board")
            && stderr.contains("tag ids 0 to 35"),
        "{stderr}"
    );
}

#[test]
fn issue25_two_visp_pose_files_with_one_number_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("visp");
    let out = dir.path().join("out");
    std::fs::create_dir_all(&folder).unwrap();
    std::fs::create_dir_all(&out).unwrap();
    blank_visp_folder(&folder);
    std::fs::copy(
        folder.join("arm_pose_rPe_1.yaml"),
        folder.join("arm_pose_rPe_01.yaml"),
    )
    .unwrap();
    let (code, stderr) = import_visp_cli(&folder, &out, &out.join("cell.yaml"));
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("visp")
            && stderr.contains("number 1")
            && stderr.contains("arm_pose_rPe_1.yaml")
            && stderr.contains("arm_pose_rPe_01.yaml"),
        "{stderr}"
    );
    assert_eq!(outputs_left(&out), Vec::<String>::new());
}

#[test]
fn issue25_absurd_distortion_is_refused_by_every_intrinsics_source() {
    use handeye_core::camera_model::{CameraModel, Distortion};
    let dir = tempfile::tempdir().unwrap();
    // ROS camera_info YAML.
    let path = write(
        dir.path(),
        "k1.yaml",
        &camera_info(K_SIM, "1e10, 0.0, 0.0, 0.0, 0.0"),
    );
    let e = load_error(&path);
    assert!(
        e.contains("k1.yaml")
            && e.contains("distortion k1")
            && e.contains("10000000000.0")
            && e.contains("scales a radius"),
        "{e}"
    );
    // Kalibr camchain.
    let path = write(
        dir.path(),
        "camchain.yaml",
        "cam0:\n  camera_model: pinhole\n  intrinsics: [461.6, 460.3, 363.0, 248.1]\n  \
         distortion_model: radtan\n  distortion_coeffs: [1e10, 0.0, 0.0, 0.0]\n  resolution: [752, 480]\n",
    );
    let e = load_error(&path);
    assert!(
        e.contains("camchain.yaml") && e.contains("distortion k1") && e.contains("10000000000.0"),
        "{e}"
    );
    // ViSP XML (`kud` is k1).
    let path = write(
        dir.path(),
        "cam.xml",
        "<root><camera><image_width>640</image_width><image_height>480</image_height><model>\
         <type>perspectiveProjWithDistortion</type><px>600</px><py>600</py><u0>320</u0><v0>240</v0>\
         <kud>1e10</kud><kdu>0</kdu></model></camera></root>",
    );
    let e = read_visp_camera_xml(&path).unwrap_err().to_string();
    assert!(
        e.contains("cam.xml") && e.contains("distortion k1") && e.contains("10000000000.0"),
        "{e}"
    );
    // A ROS 2 bag's camera_info message goes through the same check.
    let model = CameraModel {
        width: 1280,
        height: 720,
        fx: 800.0,
        fy: 800.0,
        cx: 640.0,
        cy: 360.0,
        distortion: Distortion::RadTan {
            k1: 1e10,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
            k3: 0.0,
        },
    };
    let e = model
        .validate(Path::new("camera_info"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("distortion k1") && e.contains("10000000000.0"),
        "{e}"
    );
    // A model that folds over inside the image (strong barrel k1 alone): refused, saying where.
    let path = write(
        dir.path(),
        "fold.yaml",
        &camera_info(K_SIM, "-0.9, 0.0, 0.0, 0.0, 0.0"),
    );
    let e = load_error(&path);
    assert!(
        e.contains("fold.yaml")
            && e.contains("distortion k1")
            && e.contains("-0.9")
            && e.contains("folds over"),
        "{e}"
    );
    // A huge tangential coefficient.
    let path = write(
        dir.path(),
        "p2.yaml",
        &camera_info(K_SIM, "0.0, 0.0, 0.0, 5.0, 0.0"),
    );
    let e = load_error(&path);
    assert!(e.contains("distortion p2") && e.contains("5.0"), "{e}");
}

#[test]
fn issue25_absurd_focal_length_or_principal_point_is_refused_at_load() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "fx.yaml",
        &camera_info(
            "1e300, 0.0, 641.3, 0.0, 800.0, 358.7, 0.0, 0.0, 1.0",
            "0.0, 0.0, 0.0, 0.0, 0.0",
        ),
    );
    // Through the binary, as the attack did: refused when the intrinsics are read, not later
    // as a board "not found".
    let frame = dir.path().join("blank.png");
    GrayImage::from_pixel(1280, 720, image::Luma([180]))
        .save(&frame)
        .unwrap();
    let (code, stderr) = stderr_of(
        handeye()
            .arg("detect")
            .arg(&frame)
            .arg("--board")
            .arg(repo().join("configs/targets/aprilgrid-6x6.yaml"))
            .arg("--intrinsics")
            .arg(&path),
    );
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("fx.yaml")
            && stderr.contains("`fx`")
            && stderr.contains("1e300")
            && stderr.contains("12.8 to 1280000 px")
            && !stderr.contains("not found"),
        "{stderr}"
    );
    for (name, k, key, value) in [
        (
            "fy.yaml",
            "800.0, 0.0, 641.3, 0.0, 0.5, 358.7, 0.0, 0.0, 1.0",
            "`fy`",
            "0.5",
        ),
        (
            "cx.yaml",
            "800.0, 0.0, 1e9, 0.0, 800.0, 358.7, 0.0, 0.0, 1.0",
            "`cx`",
            "1000000000.0",
        ),
        (
            "cy.yaml",
            "800.0, 0.0, 641.3, 0.0, 800.0, -5000.0, 0.0, 0.0, 1.0",
            "`cy`",
            "-5000.0",
        ),
    ] {
        let e = load_error(&write(
            dir.path(),
            name,
            &camera_info(k, "0.0, 0.0, 0.0, 0.0, 0.0"),
        ));
        assert!(
            e.contains(name) && e.contains(key) && e.contains(value),
            "{e}"
        );
    }
}

#[test]
fn issue25_camera_info_rows_and_cols_must_agree_with_the_data() {
    let dir = tempfile::tempdir().unwrap();
    let good = camera_info(K_SIM, "0.0, 0.0, 0.0, 0.0, 0.0");
    for (name, text, key, value) in [
        (
            "matrix-rows.yaml",
            good.replacen("rows: 3\n  cols: 3", "rows: 2\n  cols: 3", 1),
            "camera_matrix.rows",
            "found 2",
        ),
        (
            "coefficient-cols.yaml",
            good.replace("cols: 5", "cols: 4"),
            "distortion_coefficients.data",
            "4 numbers (rows 1 x cols 4)",
        ),
        (
            "projection.yaml",
            format!(
                "{good}projection_matrix:\n  rows: 3\n  cols: 4\n  data: [800.0, 0.0, 641.3, 0.0, 0.0, 800.0, 358.7, 0.0, 0.0]\n"
            ),
            "projection_matrix.data",
            "12 numbers",
        ),
        (
            "width.yaml",
            format!("{good}width: 640\n"),
            "`width`",
            "found 640",
        ),
    ] {
        let e = load_error(&write(dir.path(), name, &text));
        assert!(
            e.contains(name) && e.contains(key) && e.contains(value),
            "{name}: {e}"
        );
    }
    // The camera matrix's data of another length than rows x cols.
    let e = load_error(&write(
        dir.path(),
        "matrix-data.yaml",
        &camera_info(
            "800.0, 0.0, 641.3, 0.0, 800.0, 358.7, 0.0, 0.0",
            "0.0, 0.0, 0.0, 0.0, 0.0",
        ),
    ));
    assert!(
        e.contains("matrix-data.yaml")
            && e.contains("camera_matrix.data")
            && e.contains("9 numbers"),
        "{e}"
    );
}

#[test]
fn issue25_a_file_both_camera_info_and_kalibr_is_refused_as_ambiguous() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!(
        "{}cam0:\n  camera_model: pinhole\n  intrinsics: [461.6, 460.3, 363.0, 248.1]\n  \
         distortion_model: radtan\n  distortion_coeffs: [0.0, 0.0, 0.0, 0.0]\n  resolution: [752, 480]\n",
        camera_info(K_SIM, "0.0, 0.0, 0.0, 0.0, 0.0")
    );
    let e = load_error(&write(dir.path(), "both.yaml", &text));
    assert!(
        e.contains("both.yaml")
            && e.contains("both a ROS camera_info")
            && e.contains("camera_matrix")
            && e.contains("image_width")
            && e.contains("keys cam0"),
        "{e}"
    );
}

#[test]
fn issue25_garbage_intrinsics_say_what_the_file_is_not() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = StdRng::seed_from_u64(25);
    let bytes: Vec<u8> = (0..512).map(|_| rng.random::<u8>()).collect();
    let path = dir.path().join("random.bin");
    std::fs::write(&path, bytes).unwrap();
    let e = load_error(&path);
    assert!(
        e.contains("random.bin") && e.contains("not a ROS camera_info or Kalibr camchain YAML"),
        "{e}"
    );
    for (name, text, says) in [
        ("docs.yaml", "a: 1\n---\nb: 2\n", "several YAML documents"),
        ("text.yaml", "just some notes\n", "a line of text"),
        ("keys.yaml", "fx: 800\nfy: 800\n", "the keys fx, fy"),
        (
            "broken.yaml",
            "a: [1, 2\n",
            "not a ROS camera_info or Kalibr camchain YAML",
        ),
    ] {
        let e = load_error(&write(dir.path(), name, text));
        assert!(
            e.contains(name) && e.contains(says) && !e.contains("more than one document"),
            "{name}: {e}"
        );
    }
}

#[cfg(unix)]
#[test]
fn issue25_symlink_loops_are_named_as_such() {
    use std::os::unix::fs::symlink;
    let dir = tempfile::tempdir().unwrap();
    // A frame of a session that is a link to itself.
    let session = corpus_session(dir.path(), |text| text);
    let frame = session.join("frames/000.png");
    std::fs::remove_file(&frame).unwrap();
    symlink("000.png", &frame).unwrap();
    let (code, stderr) = solve_session(&session);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("poses/000.yaml")
            && stderr.contains("symlink loop at")
            && stderr.contains("frames/000.png")
            && !stderr.contains("not in the session folder"),
        "{stderr}"
    );
    // Input files: a dataset and an intrinsics file behind a loop of two links.
    let a = dir.path().join("a");
    let b = dir.path().join("b");
    symlink(&b, &a).unwrap();
    symlink(&a, &b).unwrap();
    let (code, stderr) = stderr_of(handeye().arg("solve").arg(a.join("samples.yaml")));
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!("symlink loop at {}", a.display())),
        "{stderr}"
    );
    let e = load_error(&a);
    assert!(
        e.contains(&format!("symlink loop at {}", a.display())),
        "{e}"
    );
    // A board file and a ViSP folder behind the loop.
    let e = Board::load(&a).unwrap_err();
    assert!(
        format!("{:#}", anyhow::Error::new(e))
            .contains(&format!("symlink loop at {}", a.display())),
        "board"
    );
    let e = handeye_formats::import::scan_visp_folder(&a).unwrap_err();
    assert!(
        format!("{:#}", anyhow::Error::new(e))
            .contains(&format!("symlink loop at {}", a.display())),
        "visp folder"
    );
    // A session folder that is a loop.
    let (code, stderr) = stderr_of(handeye().arg("replay").arg(&a));
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("symlink loop at"), "{stderr}");
}

#[test]
fn issue25_export_removes_killed_runs_temp_files_and_spares_a_locked_one() {
    use fs4::FileExt;
    let dir = tempfile::tempdir().unwrap();
    let samples = write_dataset(dir.path());
    let result = dir.path().join("result.yaml");
    let (code, stderr) = stderr_of(handeye().arg("solve").arg(&samples).arg("-o").arg(&result));
    assert_eq!(code, Some(0), "{stderr}");
    let out = dir.path().join("tf.launch");
    // What two killed exports left, one killed export to another file (#40: it was left), and
    // one another export is still writing (it holds the lock).
    let suffix = handeye_core::atomic_file::TEMP_SUFFIX;
    let killed: Vec<PathBuf> = [
        ".tf.launch.K1lled",
        ".tf.launch.K2lled",
        ".other.urdf.K3lled",
    ]
    .iter()
    .map(|r| write(dir.path(), &format!("{r}{suffix}"), "half an export"))
    .collect();
    let live = write(
        dir.path(),
        &format!(".tf.launch.L1veXX{suffix}"),
        "being written",
    );
    let holder = std::fs::File::open(&live).unwrap();
    FileExt::try_lock(&holder).unwrap();
    let (code, stderr) = stderr_of(
        handeye()
            .arg("export")
            .arg(&result)
            .args(["--format", "ros2", "-o"])
            .arg(&out),
    );
    assert_eq!(code, Some(0), "{stderr}");
    for k in &killed {
        assert!(!k.exists(), "{} removed", k.display());
        assert!(
            stderr.contains(&format!("removed {}", k.display())),
            "named: {stderr}"
        );
    }
    assert!(live.exists(), "the locked one is left alone: {stderr}");
    assert!(!stderr.contains(&live.display().to_string()), "{stderr}");
    assert!(out.exists());
    // Its writer gone, the next export removes it too; nothing temporary is left.
    drop(holder);
    let (code, stderr) = stderr_of(
        handeye()
            .arg("export")
            .arg(&result)
            .args(["--format", "ros2", "-o"])
            .arg(&out),
    );
    assert_eq!(code, Some(0), "{stderr}");
    assert!(!live.exists() && stderr.contains("removed"), "{stderr}");
    assert!(
        std::fs::read_dir(dir.path()).unwrap().all(|e| !e
            .unwrap()
            .file_name()
            .to_string_lossy()
            .ends_with(suffix)),
        "no temporary file left"
    );
}
