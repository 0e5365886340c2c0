//! Dataset and result files: round trips through the solver, every malformed-input case with its
//! clear error (file + YAML path + problem), and the `handeye solve` command end to end.

use std::path::Path;
use std::process::Command;

use handeye_core::geometry::{Pose, PoseYaml};
use handeye_core::setup::{predict, Setup};
use handeye_records::dataset::{Dataset, FileError};
use handeye_records::result::ResultFile;
use nalgebra::{Translation3, UnitQuaternion, Vector3};

/// A valid eye-in-hand dataset text of 6 noise-free samples with diverse rotations, and its truth.
fn dataset_text() -> (String, Pose, Pose) {
    let camera_mount = Pose::from_parts(
        Translation3::new(0.03, -0.05, 0.08),
        UnitQuaternion::from_euler_angles(0.1, -0.2, 1.6),
    );
    let target_mount = Pose::from_parts(
        Translation3::new(0.6, 0.1, -0.02),
        UnitQuaternion::from_euler_angles(3.1, 0.05, -0.4),
    );
    let mut text = String::from("setup: eye_in_hand\nsamples:\n");
    for k in 0..6 {
        let axis = [Vector3::x(), Vector3::y(), Vector3::z()][k % 3];
        let base_from_flange = Pose::from_parts(
            Translation3::new(0.4 + 0.02 * k as f64, -0.1 * k as f64, 0.3),
            UnitQuaternion::from_euler_angles(3.0, 0.1, 0.2)
                * UnitQuaternion::from_scaled_axis(axis * (0.3 + 0.05 * k as f64)),
        );
        let camera_from_target = predict(
            Setup::EyeInHand,
            &camera_mount,
            &target_mount,
            &base_from_flange,
        );
        let yaml = |p: &Pose| serde_yaml_ng::to_string(&PoseYaml::from_pose(p)).unwrap();
        let indent = |s: String| {
            s.lines()
                .map(|l| format!("      {l}\n"))
                .collect::<String>()
        };
        text += &format!(
            "  - id: pose-{k}\n    T_base_flange:\n{}    T_camera_target:\n{}",
            indent(yaml(&base_from_flange)),
            indent(yaml(&camera_from_target))
        );
    }
    (text, camera_mount, target_mount)
}

fn load_error(text: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cell-samples.yaml");
    std::fs::write(&path, text).unwrap();
    let e: FileError = Dataset::load(&path).unwrap_err();
    e.to_string()
}

#[test]
fn valid_dataset_loads_and_solves() {
    let (text, camera_mount, _) = dataset_text();
    let dataset = Dataset::parse(&text, Path::new("x.yaml")).unwrap();
    assert_eq!(dataset.pairs.len(), 6);
    assert_eq!(dataset.pairs[2].id.as_deref(), Some("pose-2"));
    let cal = handeye_solve::solve(dataset.setup, &dataset.pairs, &Default::default()).unwrap();
    assert!(cal.camera_mount.rotation.angle_to(&camera_mount.rotation) < 1e-9);
}

#[test]
fn every_malformed_input_names_file_path_and_problem() {
    let (text, _, _) = dataset_text();
    // Each case: (edit of the valid text, expected fragments of the message).
    let first_quaternion = text.find("quaternion:").unwrap();
    let cases: Vec<(String, Vec<&str>)> = vec![
        (
            text.replacen("T_camera_target:", "T_camera_targt:", 1),
            vec![
                "cell-samples.yaml",
                "samples[0]",
                "unknown field `T_camera_targt`",
            ],
        ),
        (
            text.replacen("setup: eye_in_hand", "setup: eye_on_hand", 1),
            vec!["cell-samples.yaml", "setup", "eye_on_hand"],
        ),
        (
            text.replacen("setup: eye_in_hand\n", "", 1),
            vec!["cell-samples.yaml", "missing field `setup`"],
        ),
        (
            text.replacen("  - id: pose-3\n", "  - id: pose-3\n    weight: 0\n", 1),
            vec![
                "cell-samples.yaml",
                "samples[3].weight",
                "weight 0 must be a positive",
            ],
        ),
        (
            text.replacen(
                "  - id: pose-3\n",
                "  - id: pose-3\n    view_sigma: {rotation_deg: -0.01, translation_mm: 0.2}\n",
                1,
            ),
            vec![
                "cell-samples.yaml",
                "samples[3].view_sigma",
                "expected two positive figures (rotation_deg, translation_mm), got -0.01 and 0.2",
            ],
        ),
        (
            text.replacen(
                "  - id: pose-3\n",
                "  - id: pose-3\n    view_sigma: {rotation_deg: 0.01}\n",
                1,
            ),
            vec![
                "cell-samples.yaml",
                "samples[3]",
                "missing field `translation_mm`",
            ],
        ),
        (
            // Scale every quaternion component of sample 0's robot pose: norm far from 1.
            format!(
                "{}quaternion: {{w: 0.5, x: 0.5, y: 0.5, z: 0.1}}\n{}",
                &text[..first_quaternion],
                skip_quaternion(&text[first_quaternion..])
            ),
            vec![
                "cell-samples.yaml",
                "samples[0].T_base_flange.quaternion",
                "quaternion norm is 0.8",
            ],
        ),
        (
            text.replacen(
                "      translation:",
                "      rotation_vector: [0, 0, 0]\n      translation:",
                1,
            ),
            vec![
                "cell-samples.yaml",
                "samples[0].T_base_flange",
                "2 rotation keys given",
            ],
        ),
        (
            text.replacen(
                "      translation:\n      - ",
                "      translation:\n      - .nan\n      - ",
                1,
            ),
            vec![
                "cell-samples.yaml",
                "samples[0].T_base_flange.translation",
                "expected 3 numbers, found 4",
            ],
        ),
        (
            replace_nth_translation(&text, 5, "      translation: [0.1, .nan, 0.2]\n"),
            vec![
                "cell-samples.yaml",
                "samples[2].T_camera_target.translation",
                "not finite",
            ],
        ),
        (
            format!(
                "{}matrix: [[1, 0.2, 0], [0, 1, 0], [0, 0, 1]]\n{}",
                &text[..first_quaternion],
                skip_quaternion(&text[first_quaternion..])
            ),
            vec![
                "cell-samples.yaml",
                "samples[0].T_base_flange.matrix",
                "not a rotation matrix",
            ],
        ),
        (
            text.replacen("translation:", "translatoin:", 1),
            vec![
                "cell-samples.yaml",
                "samples[0].T_base_flange",
                "unknown field `translatoin`",
            ],
        ),
        (
            "setup: eye_in_hand\nsamples: {a: 1}\n".to_string(),
            vec!["cell-samples.yaml", "samples", "expected a sequence"],
        ),
    ];
    for (case, expected) in cases {
        let message = load_error(&case);
        for fragment in expected {
            assert!(
                message.contains(fragment),
                "expected {fragment:?} in {message:?}"
            );
        }
    }
    let missing = Dataset::load(Path::new("/no/such/dir/samples.yaml")).unwrap_err();
    assert!(missing
        .to_string()
        .contains("/no/such/dir/samples.yaml: cannot read"));
}

/// Drops the quaternion block (its `quaternion:` line and the 4 component lines) at the start.
fn skip_quaternion(rest: &str) -> String {
    rest.splitn(6, '\n').nth(5).unwrap().to_string()
}

/// Replaces the `n`-th (0-based) `translation:` block (its line and 3 item lines).
fn replace_nth_translation(text: &str, n: usize, with: &str) -> String {
    let start = text.match_indices("      translation:").nth(n).unwrap().0;
    let rest = &text[start..];
    let end = rest
        .splitn(5, '\n')
        .take(4)
        .map(|l| l.len() + 1)
        .sum::<usize>();
    format!("{}{}{}", &text[..start], with, &rest[end..])
}

#[test]
fn cli_solve_writes_a_result_that_reads_back() {
    let (text, camera_mount, target_mount) = dataset_text();
    let dir = tempfile::tempdir().unwrap();
    let samples = dir.path().join("samples.yaml");
    // Into a folder that does not exist yet: `solve -o` makes it, whatever it solves (a samples
    // file, one camera's session, a several-camera one).
    let output = dir.path().join("answers/result.yaml");
    std::fs::write(&samples, &text).unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_handeye"))
        .args([
            "solve",
            samples.to_str().unwrap(),
            "-o",
            output.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(
        stdout.contains("T_flange_camera:") && stdout.contains("residuals:"),
        "{stdout}"
    );
    let result = ResultFile::load(&output).unwrap();
    let mounts = result.mounts(&output).unwrap();
    assert_eq!(mounts.setup, Setup::EyeInHand);
    assert!(
        mounts
            .camera_mount
            .rotation
            .angle_to(&camera_mount.rotation)
            < 1e-9
    );
    assert!(
        (mounts.target_mount.translation.vector - target_mount.translation.vector).norm() < 1e-9
    );
    assert_eq!(result.residuals.samples.len(), 6);
    assert!(result.uncertainty.is_some());
    let written = std::fs::read_to_string(&output).unwrap();
    for key in [
        "T_flange_camera:",
        "T_base_target:",
        "rotation_vector:",
        "quaternion:",
        "uncertainty:",
        "residuals:",
        "outliers:",
        "solver:",
        "method: refined",
        "converged: true",
    ] {
        assert!(written.contains(key), "{key} missing from result");
    }

    // --method closed-form works too.
    let run = Command::new(env!("CARGO_BIN_EXE_handeye"))
        .args([
            "solve",
            samples.to_str().unwrap(),
            "--method",
            "closed-form",
        ])
        .output()
        .unwrap();
    assert!(run.status.success());

    // Another writer's file into a folder that does not exist: the error names the folder (it
    // named the write's temporary file, `.calibration.urdf.XXXXXX.handeye-tmp`).
    let missing = dir.path().join("no-such-folder");
    let run = Command::new(env!("CARGO_BIN_EXE_handeye"))
        .arg("export")
        .arg(&output)
        .args(["--format", "urdf", "-o"])
        .arg(missing.join("calibration.urdf"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!("the folder {} does not exist", missing.display()))
            && !stderr.contains("handeye-tmp"),
        "{stderr}"
    );
    assert!(!missing.exists());
}

#[test]
fn cli_solve_failure_exits_non_zero_and_writes_nothing() {
    let (text, _, _) = dataset_text();
    // Keep only the first two samples: too few.
    let cut = text.match_indices("  - id:").nth(2).unwrap().0;
    let dir = tempfile::tempdir().unwrap();
    let samples = dir.path().join("samples.yaml");
    let output = dir.path().join("result.yaml");
    std::fs::write(&samples, &text[..cut]).unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_handeye"))
        .args([
            "solve",
            samples.to_str().unwrap(),
            "-o",
            output.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(!run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stderr.contains("2 pose pairs given, at least 3"),
        "{stderr}"
    );
    assert!(!output.exists());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);

    let run = Command::new(env!("CARGO_BIN_EXE_handeye"))
        .args(["solve", samples.to_str().unwrap(), "--method", "magic"])
        .output()
        .unwrap();
    assert!(!run.status.success());
}

#[test]
fn result_with_the_wrong_unknowns_is_refused() {
    let (text, _, _) = dataset_text();
    let dataset = Dataset::parse(&text, Path::new("x.yaml")).unwrap();
    let cal = handeye_solve::solve(dataset.setup, &dataset.pairs, &Default::default()).unwrap();
    let mut file = ResultFile::from_calibration(&cal, &dataset.pairs);
    file.setup = Setup::EyeToHand;
    let e = file.mounts(Path::new("r.yaml")).unwrap_err().to_string();
    assert!(
        e.contains("r.yaml: T_flange_camera: not an unknown of setup eye_to_hand"),
        "{e}"
    );
}
