//! Real data in, results out: the ViSP and MoveIt importers on the public data sets (import →
//! detection → solve, and the same ViSP frames as an image-folder session), the exporters
//! parsed back, and bad input of every kind as a clear error naming the file and row.
//!
//! The data sets live in `../shared/datasets` beside the crate (see its README); tests that
//! need them print why and return when it is absent (`util::dataset`).

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use nalgebra::{Matrix3, Matrix4, Quaternion, Translation3, UnitQuaternion, Vector3};

use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::{pose_from_rotvec, Pose};
use handeye_formats::export::{export, ExportFormat, FrameIds};
use handeye_formats::import::{
    import_csv_pairs, import_csv_two_files, import_moveit_json, import_visp, read_visp_camera_xml,
    read_visp_pose, scan_visp_folder, CsvOptions, CsvPoseForm, ImportError, VispOptions,
};
use handeye_records::result::ResultFile;
use handeye_records::SessionFolder;
use handeye_robot::recorded::save_recorded_poses;
use handeye_session::cell;

use handeye_core::setup::{self, CellTransforms, PosePair, Setup};
use handeye_session::verify::leave_one_out;
use handeye_solve::{self as solve, Calibration, NoiseModel, SolveOptions};
use handeye_vision::{Board, DetectorOptions};

use crate::util;
use util::{dataset, pose_error_mm_deg, repo};

fn tag_board() -> Board {
    Board::load(&repo().join("configs/targets/single-tag36h11-id10.yaml")).unwrap()
}

/// Solver settings for a lone 48 mm tag seen from ~0.6 m: its pose is good to a few tenths of
/// a degree and a couple of millimetres.
fn visp_solve_options() -> SolveOptions {
    SolveOptions {
        noise: NoiseModel {
            rotation_sigma_rad: 0.5f64.to_radians(),
            translation_sigma_m: 2e-3,
        },
        ..SolveOptions::default()
    }
}

#[test]
fn visp_eye_to_hand_imports_detects_and_solves_with_small_residuals() {
    let Some(folder) = dataset("visp_franka_data-eye-to-hand") else {
        return;
    };
    let imported = import_visp(
        &folder,
        &VispOptions {
            setup: Setup::EyeToHand,
            board: tag_board().into(),
            camera: None,
            detector: DetectorOptions::default(),
            skip_unfound: false,
        },
    )
    .unwrap();
    // The XML's intrinsics, as the README gives them.
    assert_eq!((imported.camera.width, imported.camera.height), (640, 480));
    assert!((imported.camera.fx - 607.5931396484375).abs() < 1e-9);
    assert!((imported.camera.cy - 243.255_294_799_804_7).abs() < 1e-9);
    assert_eq!(imported.frames.len(), 8);
    assert_eq!(imported.dataset.pairs.len(), 8);
    for f in &imported.frames {
        let rms = f.rms_px.unwrap();
        assert!(rms < 1.0, "{}: board RMS {rms} px", f.files.image.display());
    }
    // The pose vector of sample 1 is T_base_flange as written (README: m and axis-angle rad).
    let first = &imported.dataset.pairs[0].base_from_flange;
    assert!(
        (first.translation.vector - Vector3::new(0.719437, -0.0332613, 0.412152)).norm() < 1e-12
    );

    let options = visp_solve_options();
    let cal = solve::solve(Setup::EyeToHand, &imported.dataset.pairs, &options).unwrap();
    eprintln!("{}", cal.summary());
    let r = &cal.residuals;
    // Per-pose residuals of a lone tag: a couple of degrees and millimetres at most.
    assert!(
        r.rotation_max_deg < 3.0 && r.translation_max_mm < 8.0,
        "residuals: rotation max {:.3}°, translation max {:.2} mm",
        r.rotation_max_deg,
        r.translation_max_mm
    );
    // The camera sits in front of the arm, about 1 m from the base, looking back at it.
    let camera_in_base = cal.camera_mount.translation.vector;
    assert!(
        (0.5..1.5).contains(&camera_in_base.norm()),
        "{camera_in_base:?}"
    );

    let loo = leave_one_out(Setup::EyeToHand, &imported.dataset.pairs, &options).unwrap();
    eprintln!("{}", loo.table());
    let (rot_rms, trans_rms) = (loo.summary.rotation_rms_deg, loo.summary.translation_rms_mm);
    // Seven poses predict the eighth to a few degrees and about a centimetre.
    assert!(
        rot_rms < 5.0 && trans_rms < 20.0,
        "leave-one-out RMS {rot_rms:.3}°, {trans_rms:.2} mm"
    );
}

/// Writes the files a recorded ViSP session needs into `dir`: camera_info, recorded poses and a
/// cell config whose camera reads `frames`. Returns the config path.
fn recorded_cell(dir: &Path, visp: &Path, frames: &Path) -> PathBuf {
    let scan = scan_visp_folder(visp).unwrap();
    let camera = read_visp_camera_xml(scan.camera_xml.as_ref().unwrap()).unwrap();
    camera.save_camera_info(&dir.join("camera.yaml")).unwrap();
    let poses: Vec<Pose> = scan
        .samples
        .iter()
        .map(|s| read_visp_pose(&s.pose_file).unwrap())
        .collect();
    save_recorded_poses(&poses, &dir.join("poses.yaml")).unwrap();
    let config = format!(
        "setup: eye_to_hand\n\
         target: {board}\n\
         intrinsics: camera.yaml\n\
         robot: {{backend: recorded, poses: poses.yaml}}\n\
         camera: {{backend: files, folder: {frames}}}\n\
         nominal:\n  \
           T_base_camera: {{translation: [0.95, -0.05, 0.48], rotation_vector: [-1.1, -1.1, 1.3]}}\n  \
           T_flange_target: {{translation: [0.02, -0.03, -0.08], rotation_vector: [1.2, 1.2, 1.2]}}\n\
         workspace: {{min: [-1.5, -1.5, -0.5], max: [1.5, 1.5, 1.5]}}\n\
         detector: {{decimate: 1, threads: 1, max_hamming: 0}}\n\
         solver: {{method: refined, rotation_sigma_deg: 0.5, translation_sigma_mm: 2.0, drop_outliers: false}}\n\
         session: {{settle_s: 0.0, max_reprojection_rms_px: 1.0}}\n",
        board = repo()
            .join("configs/targets/single-tag36h11-id10.yaml")
            .display(),
        frames = frames.display(),
    );
    let path = dir.join("cell.yaml");
    std::fs::write(&path, config).unwrap();
    path
}

#[test]
fn visp_eye_to_hand_as_a_folder_session_gives_the_same_answer() {
    let Some(visp) = dataset("visp_franka_data-eye-to-hand") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let config = recorded_cell(dir.path(), &visp, &visp);
    let prepared = cell::prepare(&config).unwrap();
    let plan = prepared.report.validated().expect("recorded poses pass");
    assert_eq!(plan.len(), 8);

    let folder = SessionFolder::create(&dir.path().join("session")).unwrap();
    folder.write_manifest(&prepared.manifest(0, &plan)).unwrap();
    let mut hardware = prepared.open_hardware().unwrap();
    let outcome = handeye_session::run_session(
        prepared.session_setup(folder.clone(), plan, Arc::new(AtomicBool::new(false))),
        hardware.robot.as_mut(),
        &mut [hardware.cameras[0].as_mut()],
        &mut |_| {},
    )
    .unwrap();
    assert_eq!(outcome.accepted, (0..8).collect::<Vec<_>>());
    let solved = handeye_records::solve_folder(&folder, &prepared.solve_inputs()).unwrap();

    // The import path with the same detector and solver settings.
    let imported = import_visp(
        &visp,
        &VispOptions {
            setup: Setup::EyeToHand,
            board: prepared.camera().board.clone(),
            camera: Some(prepared.camera().camera_model),
            detector: prepared.detector_options(),
            skip_unfound: false,
        },
    )
    .unwrap();
    let direct = solve::solve(
        Setup::EyeToHand,
        &imported.dataset.pairs,
        &prepared.config.solver.to_options(),
    )
    .unwrap();
    let same = |a: &Calibration, b: &Calibration| {
        for (x, y) in [
            (a.camera_mount, b.camera_mount),
            (a.target_mount, b.target_mount),
        ] {
            let (mm, deg) = pose_error_mm_deg(&x, &y);
            // The session stores poses in YAML (shortest round-trip floats): the same answer to
            // far below any physical meaning.
            assert!(deg < 1e-6 && mm < 1e-6, "{deg}° {mm} mm apart");
        }
    };
    // The pose-space answer is the import path's; the default reprojection answer refines it.
    same(&solved.pose_space, &direct);
    eprintln!("{}", solved.summary);
    // The default reprojection solve on real frames: the noise estimate puts the misfit where it
    // belongs — the arm's recorded poses (~1 mm here), not the sub-pixel corners — and the
    // answer reprojects no worse than the pose-space one on the recorded poses.
    let reprojection = solved.reprojection.as_ref().unwrap();
    let summary = solved.reprojection_summary().unwrap();
    assert!(reprojection.noise_estimated);
    assert!(
        reprojection.pixel_sigma_px < 1.0,
        "{}",
        reprojection.pixel_sigma_px
    );
    assert!(summary.corrected_rms_px.unwrap() < 1.0);
    assert!(summary.reprojection_rms_px <= summary.pose_space_rms_px);
}

#[test]
fn folder_with_fewer_frames_than_poses_is_refused_naming_the_folder() {
    let Some(visp) = dataset("visp_franka_data-eye-to-hand") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames");
    std::fs::create_dir(&frames).unwrap();
    for n in 1..=7 {
        let name = format!("franka_image-{n}.png");
        std::fs::copy(visp.join(&name), frames.join(&name)).unwrap();
    }
    let config = recorded_cell(dir.path(), &visp, &frames);
    let prepared = cell::prepare(&config).unwrap();
    let message = match prepared.open_hardware() {
        Ok(_) => panic!("7 frames for 8 poses must not open"),
        Err(e) => e.to_string(),
    };
    assert!(
        message.contains(&frames.display().to_string())
            && message.contains("7 frames")
            && message.contains("8 poses"),
        "{message}"
    );
}

/// Eigen's `eulerAngles(0, 1, 2)`: R = Rx(a) Ry(b) Rz(c) with a in [0, π].
fn eigen_euler_xyz(r: &Matrix3<f64>) -> [f64; 3] {
    let a = (-r[(1, 2)]).atan2(r[(2, 2)]);
    let b = r[(0, 2)].atan2((r[(0, 0)].powi(2) + r[(0, 1)].powi(2)).sqrt());
    let c = (-r[(0, 1)]).atan2(r[(0, 0)]);
    let wrap = |x: f64| {
        (x + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI
    };
    if a < 0.0 {
        // The other branch: (a + π, π - b, c + π).
        [
            a + std::f64::consts::PI,
            wrap(std::f64::consts::PI - b),
            wrap(c + std::f64::consts::PI),
        ]
    } else {
        [a, b, c]
    }
}

#[test]
fn moveit_json_imports_and_solves_to_moveits_expected_camera_pose() {
    let Some(folder) = dataset("moveit_calibration_eye_to_hand") else {
        return;
    };
    let pairs = import_moveit_json(&folder.join("pose_samples.json")).unwrap();
    assert_eq!(pairs.len(), 50);
    let cal = solve::solve(Setup::EyeToHand, &pairs, &SolveOptions::default()).unwrap();
    let t = cal.camera_mount.translation.vector;
    let euler = eigen_euler_xyz(cal.camera_mount.rotation.to_rotation_matrix().matrix());
    let expected_t = Vector3::new(0.659, -0.249, 0.830);
    let expected_euler = Vector3::new(0.230, -2.540, 1.950);
    let euler = Vector3::from(euler);
    eprintln!("T_base_camera: t {t:?} m, Eigen eulerAngles(0,1,2) {euler:?} rad");
    // MoveIt's test: Eigen `isApprox(expected, 0.01)` on each vector, i.e. the difference is
    // within 1 % of the vector's norm: |a - b| <= 0.01 * min(|a|, |b|).
    let approx =
        |a: &Vector3<f64>, b: &Vector3<f64>| (a - b).norm() <= 0.01 * a.norm().min(b.norm());
    assert!(
        approx(&t, &expected_t),
        "translation {t:?} vs {expected_t:?}"
    );
    assert!(
        approx(&euler, &expected_euler),
        "Euler angles {euler:?} vs {expected_euler:?}"
    );
    // And the camera position to 3 mm per axis (MoveIt prints 3 decimals).
    assert!((t - expected_t).abs().max() < 3e-3, "{t:?}");
}

// ------------------------------------------------------------------------------------------
// Exporters, parsed back

fn mounts(setup: Setup) -> CellTransforms {
    CellTransforms {
        setup,
        camera_mount: Pose::from_parts(
            Translation3::new(0.6591, -0.2493, 0.8302),
            UnitQuaternion::from_euler_angles(0.23, -0.9, 1.95),
        ),
        target_mount: Pose::from_parts(
            Translation3::new(-0.0123, 0.0456, 0.0789),
            UnitQuaternion::from_euler_angles(2.9, 0.3, -1.2),
        ),
    }
}

/// The number after `flag` in a whitespace-separated command (`--x 0.1`).
fn after(words: &[&str], flag: &str) -> f64 {
    let i = words.iter().position(|w| *w == flag).unwrap();
    words[i + 1].parse().unwrap()
}

fn parse_ros2(text: &str) -> Vec<(String, String, Pose)> {
    text.lines()
        .filter(|l| l.starts_with("ros2 run tf2_ros static_transform_publisher"))
        .map(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            let q = Quaternion::new(
                after(&w, "--qw"),
                after(&w, "--qx"),
                after(&w, "--qy"),
                after(&w, "--qz"),
            );
            let pose = Pose::from_parts(
                Translation3::new(after(&w, "--x"), after(&w, "--y"), after(&w, "--z")),
                UnitQuaternion::from_quaternion(q),
            );
            let id = |flag: &str| {
                let i = w.iter().position(|x| *x == flag).unwrap();
                w[i + 1].to_string()
            };
            (id("--frame-id"), id("--child-frame-id"), pose)
        })
        .collect()
}

/// The quoted value of `name="..."` in an XML line.
fn attribute<'a>(text: &'a str, name: &str) -> &'a str {
    let start = text.find(&format!("{name}=\"")).unwrap() + name.len() + 2;
    &text[start..start + text[start..].find('"').unwrap()]
}

fn parse_urdf(text: &str) -> Vec<(String, String, Pose)> {
    text.split("<joint ")
        .skip(1)
        .map(|joint| {
            let numbers = |s: &str| -> Vec<f64> {
                s.split_whitespace().map(|v| v.parse().unwrap()).collect()
            };
            let xyz = numbers(attribute(joint, "xyz"));
            let rpy = numbers(attribute(joint, "rpy"));
            // URDF: R = Rz(yaw) Ry(pitch) Rx(roll), written independently of nalgebra's Euler helper.
            let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rpy[2])
                * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), rpy[1])
                * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), rpy[0]);
            let parent = attribute(&joint[joint.find("<parent").unwrap()..], "link").to_string();
            let child = attribute(&joint[joint.find("<child").unwrap()..], "link").to_string();
            (
                parent,
                child,
                Pose::from_parts(Translation3::new(xyz[0], xyz[1], xyz[2]), rotation),
            )
        })
        .collect()
}

fn parse_ur(text: &str) -> Vec<Pose> {
    let code: String = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .collect::<Vec<_>>()
        .join("\n");
    let text = code.as_str();
    text.match_indices("p[")
        .map(|(i, _)| {
            let inner = &text[i + 2..i + text[i..].find(']').unwrap()];
            let v: Vec<f64> = inner
                .split(',')
                .map(|x| x.trim().parse().unwrap())
                .collect();
            pose_from_rotvec(
                Vector3::new(v[0], v[1], v[2]),
                Vector3::new(v[3], v[4], v[5]),
            )
        })
        .collect()
}

fn parse_json(text: &str, key: &str) -> (String, String, Pose, Pose) {
    let v: serde_json::Value = serde_json::from_str(text).unwrap();
    let t = &v[key];
    let f = |x: &serde_json::Value| x.as_f64().unwrap();
    let m = Matrix4::from_fn(|r, c| f(&t["matrix"][r][c]));
    let from_matrix = Pose::from_parts(
        Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]),
        UnitQuaternion::from_matrix(&m.fixed_view::<3, 3>(0, 0).into_owned()),
    );
    let q = &t["quaternion"];
    let from_quaternion = Pose::from_parts(
        Translation3::new(
            f(&t["translation"][0]),
            f(&t["translation"][1]),
            f(&t["translation"][2]),
        ),
        UnitQuaternion::from_quaternion(Quaternion::new(
            f(&q["w"]),
            f(&q["x"]),
            f(&q["y"]),
            f(&q["z"]),
        )),
    );
    (
        t["parent"].as_str().unwrap().to_string(),
        t["child"].as_str().unwrap().to_string(),
        from_matrix,
        from_quaternion,
    )
}

fn parse_opencv(text: &str, key: &str) -> Pose {
    assert!(text.starts_with("%YAML:1.0\n---\n"), "FileStorage header");
    let start = text.find(&format!("{key}: !!opencv-matrix")).unwrap();
    let block = &text[start..];
    assert!(block.contains("rows: 4") && block.contains("cols: 4") && block.contains("dt: d"));
    let data = &block[block.find("data: [").unwrap() + 7..block.find(']').unwrap()];
    let v: Vec<f64> = data.split(',').map(|x| x.trim().parse().unwrap()).collect();
    assert_eq!(v.len(), 16);
    let m = Matrix4::from_row_slice(&v);
    Pose::from_parts(
        Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]),
        UnitQuaternion::from_matrix(&m.fixed_view::<3, 3>(0, 0).into_owned()),
    )
}

fn assert_same(a: &Pose, b: &Pose, what: &str) {
    let rotation = a.rotation.angle_to(&b.rotation);
    let translation = (a.translation.vector - b.translation.vector).norm();
    assert!(
        rotation < 1e-9 && translation < 1e-9,
        "{what}: {rotation:e} rad, {translation:e} m apart"
    );
}

#[test]
fn every_export_format_parses_back_to_the_same_transforms() {
    let ids = FrameIds::default();
    for setup in [Setup::EyeInHand, Setup::EyeToHand] {
        let m = mounts(setup);
        let (camera_key, target_key) = setup.unknown_names();
        let (camera_parent, target_parent) = match setup {
            Setup::EyeInHand => ("tool0", "base"),
            Setup::EyeToHand => ("base", "tool0"),
        };
        let expected = [
            (
                camera_key,
                camera_parent,
                "camera_optical_frame",
                m.camera_mount,
            ),
            (
                target_key,
                target_parent,
                "calibration_target",
                m.target_mount,
            ),
        ];

        let ros = parse_ros2(&export(&m, ExportFormat::Ros2, &ids).unwrap());
        let ros_text = export(&m, ExportFormat::Ros2, &ids).unwrap();
        assert!(ros_text.contains("def generate_launch_description():"));
        let urdf = parse_urdf(&export(&m, ExportFormat::Urdf, &ids).unwrap());
        let ur = parse_ur(&export(&m, ExportFormat::Ur, &ids).unwrap());
        let json = export(&m, ExportFormat::Json, &ids).unwrap();
        let opencv = export(&m, ExportFormat::Opencv, &ids).unwrap();
        assert_eq!((ros.len(), urdf.len(), ur.len()), (2, 2, 2));
        for (k, (key, parent, child, pose)) in expected.iter().enumerate() {
            assert_eq!((ros[k].0.as_str(), ros[k].1.as_str()), (*parent, *child));
            assert_same(&ros[k].2, pose, &format!("ros2 {key}"));
            assert_eq!((urdf[k].0.as_str(), urdf[k].1.as_str()), (*parent, *child));
            assert_same(&urdf[k].2, pose, &format!("urdf {key}"));
            assert_same(&ur[k], pose, &format!("ur {key}"));
            let (jp, jc, from_matrix, from_quaternion) = parse_json(&json, key);
            assert_eq!((jp.as_str(), jc.as_str()), (*parent, *child));
            assert_same(&from_matrix, pose, &format!("json matrix {key}"));
            assert_same(&from_quaternion, pose, &format!("json quaternion {key}"));
            assert_same(&parse_opencv(&opencv, key), pose, &format!("opencv {key}"));
        }
    }
}

#[test]
fn exports_match_hand_checked_fixtures() {
    // 90° about z, then 0.1, 0.2, 0.3 m: quaternion (0, 0, sin 45°, cos 45°), rotation vector
    // (0, 0, π/2), rpy (0, 0, π/2), matrix rows [0 -1 0 .1] [1 0 0 .2] [0 0 1 .3].
    let quarter = Pose::from_parts(
        Translation3::new(0.1, 0.2, 0.3),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2),
    );
    let m = CellTransforms {
        setup: Setup::EyeInHand,
        camera_mount: quarter,
        target_mount: Pose::identity(),
    };
    let ids = FrameIds {
        base: "world".into(),
        flange: "flange".into(),
        camera: "cam".into(),
        target: "board".into(),
        poses_in: "base".into(),
    };
    let ur = export(&m, ExportFormat::Ur, &ids).unwrap();
    assert!(
        ur.contains("set_tcp(p[0.1, 0.2, 0.3, 0, 0, 1.5707963267948966])"),
        "{ur}"
    );
    let ros = export(&m, ExportFormat::Ros2, &ids).unwrap();
    let words: Vec<&str> = ros
        .lines()
        .find(|l| l.starts_with("ros2 "))
        .unwrap()
        .split_whitespace()
        .collect();
    assert!((after(&words, "--qz") - 0.5f64.sqrt()).abs() < 1e-15);
    assert!((after(&words, "--qw") - 0.5f64.sqrt()).abs() < 1e-15);
    assert!(
        ros.contains("--frame-id flange --child-frame-id cam"),
        "{ros}"
    );
    let urdf = export(&m, ExportFormat::Urdf, &ids).unwrap();
    let rpy: Vec<f64> = attribute(&urdf[urdf.find("<origin").unwrap()..], "rpy")
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(rpy[0].abs() < 1e-15 && rpy[1].abs() < 1e-15);
    assert!((rpy[2] - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
    let opencv = export(&m, ExportFormat::Opencv, &ids).unwrap();
    let back = parse_opencv(&opencv, "T_flange_camera").to_homogeneous();
    let expected = Matrix4::new(
        0.0, -1.0, 0.0, 0.1, 1.0, 0.0, 0.0, 0.2, 0.0, 0.0, 1.0, 0.3, 0.0, 0.0, 0.0, 1.0,
    );
    assert!((back - expected).abs().max() < 1e-15, "{back}");
}

#[test]
fn export_reads_a_saved_result_file() {
    // Exact pairs from known mounts, solved, saved, read back and exported: the chain the CLI runs.
    let truth = mounts(Setup::EyeToHand);
    let pairs: Vec<PosePair> = (0..6)
        .map(|k| {
            let k = k as f64;
            let base_from_flange = pose_from_rotvec(
                Vector3::new(0.4 + 0.05 * k, -0.1 * k, 0.5),
                Vector3::new(0.5 * (k * 1.3).sin(), 0.6 * (k * 0.7).cos(), 0.4 * k),
            );
            PosePair::new(
                base_from_flange,
                setup::predict(
                    Setup::EyeToHand,
                    &truth.camera_mount,
                    &truth.target_mount,
                    &base_from_flange,
                ),
            )
        })
        .collect();
    let cal = solve::solve(Setup::EyeToHand, &pairs, &SolveOptions::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("result.yaml");
    ResultFile::from_calibration(&cal, &pairs)
        .save(&path)
        .unwrap();
    // Messages are kept under `notices:`; a file from before the key's rename (`warnings:`)
    // still reads them.
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("\nnotices:") && !text.contains("\nwarnings:"));
    let written = ResultFile::load(&path).unwrap().notices;
    assert!(!written.is_empty(), "the solve's notices are written");
    let old = dir.path().join("old.yaml");
    std::fs::write(&old, text.replace("\nnotices:", "\nwarnings:")).unwrap();
    assert_eq!(ResultFile::load(&old).unwrap().notices, written);
    let loaded = ResultFile::load_mounts(&path).unwrap();
    let json = export(&loaded, ExportFormat::Json, &FrameIds::default()).unwrap();
    let (_, _, camera, _) = parse_json(&json, "T_base_camera");
    assert_same(&camera, &cal.camera_mount, "json from the result file");
    let (mm, deg) = pose_error_mm_deg(&camera, &truth.camera_mount);
    assert!(
        deg < 1e-6 && mm < 1e-6,
        "exact data solved to {deg}°, {mm} mm"
    );
}

/// A one-camera result read as its cell's answer (`CellResult`, what `handeye export` reads)
/// exports exactly what its two unknowns do, in every form, for both setups and under the UR
/// ROS driver's `base_link` (the turned base), and saves as the same file; a file with no
/// verdict (a solve not judged) or no uncertainty (the iterative method) reads, its cell then
/// without them.
#[test]
fn a_one_camera_result_read_as_the_cells_exports_its_two_unknowns() {
    use handeye_formats::export::Exported;
    use handeye_records::result::CellResult;
    use handeye_solve::Method;
    let dir = tempfile::tempdir().unwrap();
    for (setup, method) in [
        (Setup::EyeInHand, Method::Refined),
        (Setup::EyeToHand, Method::Refined),
        (Setup::EyeInHand, Method::Iterative),
    ] {
        let truth = mounts(setup);
        let pairs: Vec<PosePair> = (0..8)
            .map(|k| {
                let k = f64::from(k);
                let base_from_flange = pose_from_rotvec(
                    Vector3::new(0.4 + 0.05 * k, -0.1 * k, 0.5),
                    Vector3::new(0.5 * (k * 1.3).sin(), 0.6 * (k * 0.7).cos(), 0.4 * k),
                );
                let seen = setup::predict(
                    setup,
                    &truth.camera_mount,
                    &truth.target_mount,
                    &base_from_flange,
                );
                PosePair::new(base_from_flange, seen)
            })
            .collect();
        let options = SolveOptions {
            method,
            ..SolveOptions::default()
        };
        let cal = solve::solve(setup, &pairs, &options).unwrap();
        let path = dir.path().join(format!("{setup}-{method:?}.yaml"));
        ResultFile::from_calibration(&cal, &pairs)
            .save(&path)
            .unwrap();
        let file = ResultFile::load(&path).unwrap();
        let cell = CellResult::load(&path).unwrap();
        assert_eq!(cell.only_camera(), Some(&file));
        // Saved, the cell of one camera is its camera's file again, byte for byte.
        let again = dir.path().join("again.yaml");
        cell.save(&again).unwrap();
        assert_eq!(
            std::fs::read(&again).unwrap(),
            std::fs::read(&path).unwrap()
        );
        assert!(cell.verdict.is_none() && cell.cameras[0].verdict.is_none());
        let refined = method == Method::Refined;
        assert_eq!(
            cell.variance_factor.is_some(),
            refined,
            "{setup} {method:?}"
        );
        let [camera_key, board_key] = [setup.unknown_names().0, setup.unknown_names().1];
        let named: Vec<&str> = cell.transforms().map(|t| t.name.as_str()).collect();
        assert_eq!(named, [camera_key, board_key]);
        assert!(cell.transforms().all(|t| t.sigma.is_some() == refined));
        let mounts = file.mounts(&path).unwrap();
        for ids in [
            FrameIds::default(),
            FrameIds {
                base: "base_link".into(),
                ..FrameIds::default()
            },
        ] {
            let (of_cell, of_mounts) = (Exported::of(&cell, &ids), Exported::one(&mounts, &ids));
            assert_eq!(of_cell, of_mounts, "{setup} under {}", ids.base);
            for format in ExportFormat::ALL {
                assert_eq!(
                    of_cell.text(format).unwrap(),
                    of_mounts.text(format).unwrap(),
                    "{format:?}"
                );
            }
        }
    }
}

mod csv;
