//! CSV and bad input.

use super::*;

#[test]
fn csv_one_file_and_two_files_import_the_poses_written() {
    let dir = tempfile::tempdir().unwrap();
    let one = dir.path().join("pairs.csv");
    std::fs::write(
        &one,
        "# robot then camera\n\
         tx,ty,tz,qx,qy,qz,qw,tx,ty,tz,qx,qy,qz,qw\n\
         0.1,0.2,0.3,0,0,0.7071068,0.7071068,0,0,0.5,1,0,0,0\n\
         \n\
         0.4,0.5,0.6,0,0,0,1,0.01,0.02,0.6,0,1,0,0\n",
    )
    .unwrap();
    let pairs = import_csv_pairs(
        &one,
        &CsvOptions {
            form: CsvPoseForm::Quaternion,
            millimetres: false,
        },
    )
    .unwrap();
    assert_eq!(pairs.len(), 2);
    assert_eq!(pairs[0].id.as_deref(), Some("line-3"));
    let expected = Pose::from_parts(
        Translation3::new(0.1, 0.2, 0.3),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2),
    );
    // 7-digit quaternion: the rotation is good to 1e-7 rad.
    assert!(
        pairs[0]
            .base_from_flange
            .rotation
            .angle_to(&expected.rotation)
            < 1e-6
    );
    assert!((pairs[0].camera_from_target.rotation.angle() - std::f64::consts::PI).abs() < 1e-12);

    // Two files in UR form, millimetres.
    let robot = dir.path().join("robot.csv");
    let camera = dir.path().join("camera.csv");
    std::fs::write(
        &robot,
        "x,y,z,rx,ry,rz\n100,200,300,0,0,1.5\n-50,0,10,0.1,0.2,0.3\n",
    )
    .unwrap();
    std::fs::write(&camera, "1,2,3,0,3,0\n4,5,6,0,0,0\n").unwrap();
    let pairs = import_csv_two_files(
        &robot,
        &camera,
        &CsvOptions {
            form: CsvPoseForm::RotationVector,
            millimetres: true,
        },
    )
    .unwrap();
    assert_eq!(pairs.len(), 2);
    assert_same(
        &pairs[1].base_from_flange,
        &pose_from_rotvec(Vector3::new(-0.05, 0.0, 0.01), Vector3::new(0.1, 0.2, 0.3)),
        "robot row 2",
    );
    assert_same(
        &pairs[0].camera_from_target,
        &pose_from_rotvec(
            Vector3::new(0.001, 0.002, 0.003),
            Vector3::new(0.0, 3.0, 0.0),
        ),
        "camera row 1",
    );
}

fn message(e: ImportError) -> String {
    e.to_string()
}

#[test]
fn csv_with_a_bad_row_names_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("poses.csv");
    let options = CsvOptions {
        form: CsvPoseForm::RotationVector,
        millimetres: false,
    };
    std::fs::write(
        &path,
        "x,y,z,rx,ry,rz,x,y,z,rx,ry,rz\n0,0,0,0,0,0,0,0,1,0,0,0\n0,0,0,0,abc,0,0,0,1,0,0,0\n",
    )
    .unwrap();
    let e = message(import_csv_pairs(&path, &options).unwrap_err());
    assert!(
        e.contains("poses.csv: line 3") && e.contains("column 5") && e.contains("`abc`"),
        "{e}"
    );
    std::fs::write(&path, "0,0,0,0,0,0,0,0,1,0,0,0\n0,0,0,0,0,0,0,0,1\n").unwrap();
    let e = message(import_csv_pairs(&path, &options).unwrap_err());
    assert!(
        e.contains("poses.csv: line 2") && e.contains("9 fields, expected 12"),
        "{e}"
    );
    // A quaternion that is not unit length.
    std::fs::write(&path, "0,0,0,0,0,0,2,0,0,1,0,0,0,1\n").unwrap();
    let e = message(
        import_csv_pairs(
            &path,
            &CsvOptions {
                form: CsvPoseForm::Quaternion,
                millimetres: false,
            },
        )
        .unwrap_err(),
    );
    assert!(
        e.contains("line 1") && e.contains("T_base_flange") && e.contains("norm 2"),
        "{e}"
    );
    // Paired files with different row counts.
    let other = dir.path().join("camera.csv");
    std::fs::write(&path, "0,0,0,0,0,0\n0,0,0,0,0,0\n").unwrap();
    std::fs::write(&other, "0,0,0,0,0,0\n").unwrap();
    let e = message(import_csv_two_files(&path, &other, &options).unwrap_err());
    assert!(
        e.contains("camera.csv") && e.contains("1 data rows") && e.contains("has 2"),
        "{e}"
    );
}

#[test]
fn files_in_the_wrong_format_are_named() {
    let dir = tempfile::tempdir().unwrap();
    // A CSV given to the MoveIt importer.
    let csv = dir.path().join("pairs.csv");
    std::fs::write(&csv, "0,0,0,0,0,0\n").unwrap();
    let e = message(import_moveit_json(&csv).unwrap_err());
    assert!(e.contains("pairs.csv") && e.contains("not a MoveIt"), "{e}");
    // JSON of the wrong shape: a 3x4 matrix in sample 1.
    let json = dir.path().join("samples.json");
    let eye = "[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]";
    std::fs::write(
        &json,
        format!("[[{eye},{eye}],[{eye},[[1,0,0,0],[0,1,0,0],[0,0,1,0]]]]"),
    )
    .unwrap();
    let e = message(import_moveit_json(&json).unwrap_err());
    assert!(e.contains("samples.json") && e.contains("[1][1]"), "{e}");
    // A sample whose matrix is not a rigid transform.
    std::fs::write(
        &json,
        format!("[[{eye},[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,1,1]]]]"),
    )
    .unwrap();
    let e = message(import_moveit_json(&json).unwrap_err());
    assert!(
        e.contains("samples.json: sample 0") && e.contains("T_camera_target"),
        "{e}"
    );
    // JSON given as a ViSP pose file, YAML given as ViSP intrinsics.
    let e = message(read_visp_pose(&json).unwrap_err());
    assert!(
        e.contains("samples.json") && e.contains("not a ViSP pose vector"),
        "{e}"
    );
    let yaml = dir.path().join("camera.yaml");
    std::fs::write(&yaml, "image_width: 640\n").unwrap();
    let e = message(read_visp_camera_xml(&yaml).unwrap_err());
    assert!(
        e.contains("camera.yaml") && e.contains("vpXmlParserCamera"),
        "{e}"
    );
    // A ViSP pose vector with five values.
    let pose = dir.path().join("x_pose_rPe_1.yaml");
    std::fs::write(
        &pose,
        "rows: 5\ncols: 1\ndata:\n  - [0]\n  - [0]\n  - [0]\n  - [0]\n  - [0]\n",
    )
    .unwrap();
    let e = message(read_visp_pose(&pose).unwrap_err());
    assert!(
        e.contains("x_pose_rPe_1.yaml") && e.contains("rows 5"),
        "{e}"
    );
}

#[test]
fn visp_frame_without_the_board_is_an_error_naming_the_image() {
    // A ViSP-style folder (no data set needed): two poses, the second image blank.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
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
        image::GrayImage::from_pixel(64, 48, image::Luma([200u8]))
            .save(d.join(format!("arm_image-{n}.png")))
            .unwrap();
    }
    let options = VispOptions {
        setup: Setup::EyeInHand,
        board: tag_board().into(),
        camera: None,
        detector: DetectorOptions::default(),
        skip_unfound: false,
    };
    let e = message(import_visp(d, &options).unwrap_err());
    assert!(
        e.contains("arm_image-1.png")
            && e.contains("board not found")
            && e.contains("arm_pose_rPe_1.yaml"),
        "{e}"
    );
    // With skipping on, both frames are reported skipped and nothing is imported.
    let imported = import_visp(
        d,
        &VispOptions {
            skip_unfound: true,
            ..options.clone()
        },
    )
    .unwrap();
    assert!(imported.dataset.pairs.is_empty());
    assert!(imported.frames.iter().all(|f| f.skipped.is_some()));
    // A pose file without its image.
    std::fs::remove_file(d.join("arm_image-2.png")).unwrap();
    let e = message(import_visp(d, &options).unwrap_err());
    assert!(
        e.contains("arm_pose_rPe_2.yaml") && e.contains("no image"),
        "{e}"
    );
    // Intrinsics given explicitly must match the image size.
    let wrong = CameraModel {
        width: 640,
        height: 480,
        ..read_visp_camera_xml(&d.join("cam.xml")).unwrap()
    };
    std::fs::remove_file(d.join("arm_pose_rPe_2.yaml")).unwrap();
    let e = message(
        import_visp(
            d,
            &VispOptions {
                camera: Some(wrong),
                ..options
            },
        )
        .unwrap_err(),
    );
    assert!(e.contains("arm_image-1.png") && e.contains("64x48"), "{e}");
}

#[test]
fn recorded_robot_config_takes_its_plan_from_the_poses() {
    let dir = tempfile::tempdir().unwrap();
    let poses: Vec<Pose> = (0..4)
        .map(|k| {
            let k = k as f64;
            pose_from_rotvec(
                Vector3::new(0.5, 0.1 * k, 0.4),
                Vector3::new(3.0, 0.3 * k.sin(), 0.2 * k),
            )
        })
        .collect();
    save_recorded_poses(&poses, &dir.path().join("poses.yaml")).unwrap();
    let base = format!(
        "setup: eye_in_hand\ntarget: {}\nintrinsics: {}\nrobot: {{backend: recorded, poses: poses.yaml}}\ncamera: {{backend: files, folder: frames}}\nnominal:\n  T_flange_camera: {{translation: [0, 0, 0.05], rotation_vector: [0, 0, 0]}}\n  T_base_target: {{translation: [0.5, 0, 0], rotation_vector: [3.1, 0, 0]}}\nworkspace: {{min: [-1, -1, -1], max: [1, 1, 1]}}\n",
        repo().join("configs/targets/single-tag36h11-id10.yaml").display(),
        repo().join("tests/data/visp_franka_camera_info.yaml").display(),
    );
    let path = dir.path().join("cell.yaml");
    std::fs::write(&path, &base).unwrap();
    let prepared = cell::prepare(&path).unwrap();
    let plan = prepared.report.validated().unwrap();
    assert_eq!(plan.len(), 4);
    for (k, (pose, _)) in plan.iter().enumerate() {
        assert_same(pose, &poses[k], "recorded plan pose");
    }
    // No frame folder: opening says which folder.
    let e = match prepared.open_hardware() {
        Ok(_) => panic!("no frames folder"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("frames"), "{e}");
    // A plan source next to a recorded robot is refused.
    std::fs::write(&path, format!("{base}plan: {{file: plan.yaml}}\n")).unwrap();
    let e = match cell::prepare(&path) {
        Ok(_) => panic!("plan with a recorded robot"),
        Err(e) => e.to_string(),
    };
    assert!(
        e.contains("cell.yaml") && e.contains("leave out `plan`"),
        "{e}"
    );
}

#[test]
fn uvc_camera_config_is_validated_and_needs_the_feature() {
    let text = |pixel_format: &str| {
        format!(
            "setup: eye_in_hand\ntarget: t.yaml\nintrinsics: c.yaml\nrobot: {{backend: ur, host: 10.0.0.2}}\ncamera: {{backend: uvc, device: '0', width: 640, height: 480, pixel_format: {pixel_format}, exposure_us: 8000, focus: 0}}\nnominal:\n  T_flange_camera: {{translation: [0, 0, 0.05], rotation_vector: [0, 0, 0]}}\n  T_base_target: {{translation: [0.5, 0, 0], rotation_vector: [3.1, 0, 0]}}\nplan: {{file: plan.yaml}}\nworkspace: {{min: [-1, -1, -1], max: [1, 1, 1]}}\n"
        )
    };
    let config = handeye_config::CellConfig::parse(&text("yuyv"), Path::new("cell.yaml")).unwrap();
    assert!(matches!(
        &config.camera().backend,
        handeye_config::CameraConfig::Uvc(handeye_config::UvcCamera {
            width: 640,
            height: 480,
            stale_frames: 4,
            ..
        })
    ));
    let e = handeye_config::CellConfig::parse(&text("h264"), Path::new("cell.yaml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("cell.yaml: camera.pixel_format") && e.contains("h264"),
        "{e}"
    );
    let model = CameraModel::load(&repo().join("tests/data/visp_franka_camera_info.yaml")).unwrap();
    let handeye_config::CameraConfig::Uvc(usb) = &config.camera().backend else {
        panic!("a uvc camera")
    };
    let opened = cell::uvc::open_camera(usb, model);
    if cfg!(feature = "uvc") {
        // No camera exists on build machines: opening must fail cleanly, not panic.
        assert!(opened.is_err());
    } else {
        let e = opened.err().unwrap().to_string();
        assert!(e.contains("`uvc` feature"), "{e}");
    }
}
