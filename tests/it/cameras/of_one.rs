//! A cell of one camera is one shape in either form of its config: the one-camera form and a
//! `cameras:` list of one give the same answer, to the bit, and every command reads either
//! session alike (issue #37: the old form read as a list of one).

use std::path::{Path, PathBuf};

use handeye_records::result::CellResult;
use handeye_session::cell::cameras::camera_folder;

use super::util::{self, handeye};

/// `configs/sim-cell.yaml` (`poses` poses) in the one-camera form, and the same cell written as
/// a `cameras:` list of one camera named `wrist`.
fn both_forms(dir: &Path, poses: usize) -> (PathBuf, PathBuf) {
    let count = format!("count: {poses}");
    let one = util::config_variant(dir, "sim-cell.yaml", "one.yaml", &[("count: 20", &count)]);
    let intrinsics = util::repo().join("configs/cameras/sim-1280x720.yaml");
    let camera_block = "camera:\n  backend: sim\n  noise_sigma: 2.0            # grey levels\n  blur_sigma_px: 0.5\n  seed: 11\n";
    let list = format!(
        "cameras:\n  - name: wrist\n    setup: eye_in_hand\n    intrinsics: {}\n    camera: {{backend: sim, noise_sigma: 2.0, blur_sigma_px: 0.5, seed: 11}}\n    nominal: {{translation: [0.03, -0.07, 0.04], rotation_vector: [0.0, 0.0, 1.5708]}}\n    simulation: {{translation: [0.0312, -0.0694, 0.0447], rotation_vector: [0.021, -0.016, 1.561]}}\n",
        intrinsics.display()
    );
    let intrinsics_line = format!("intrinsics: {}\n", intrinsics.display());
    let listed = util::config_variant(
        dir,
        "sim-cell.yaml",
        "listed.yaml",
        &[
            ("count: 20", &count),
            ("setup: eye_in_hand\n", ""),
            (&intrinsics_line, ""),
            (camera_block, &list),
            ("  T_flange_camera: {translation: [0.03, -0.07, 0.04], rotation_vector: [0.0, 0.0, 1.5708]}\n", ""),
            ("  T_flange_camera: {translation: [0.0312, -0.0694, 0.0447], rotation_vector: [0.021, -0.016, 1.561]}\n", ""),
        ],
    );
    (one, listed)
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// What `handeye <args> <session>` prints, with the session's folder written as `SESSION`.
fn printed(args: &[&str], session: &Path) -> String {
    let stdout = util::succeeds(handeye().args(args).arg(session));
    stdout.replace(&session.display().to_string(), "SESSION")
}

/// The run of a `cameras:` list of one writes the answer the one-camera form writes, byte for
/// byte, at its root (where the run says it is, with its report) and in its camera's folder;
/// `solve`, `replay` and `verify --session` of its root read its camera's session and write and
/// print what they do for the one-camera form, and a held-out run checks it as it checks the
/// one-camera form's. Before, the list of one had a second, different answer at its root (the
/// joint solve of one camera), and the held-out run refused its config.
#[test]
fn a_list_of_one_camera_gives_the_one_camera_forms_answer_to_the_bit() {
    let dir = tempfile::tempdir().unwrap();
    let (one, listed) = both_forms(dir.path(), 10);
    let (one_out, listed_out) = (dir.path().join("one"), dir.path().join("listed"));
    util::succeeds(
        handeye()
            .args(["run", "--config"])
            .arg(&one)
            .arg("-o")
            .arg(&one_out),
    );
    let stdout = util::succeeds(
        handeye()
            .args(["run", "--config"])
            .arg(&listed)
            .arg("-o")
            .arg(&listed_out),
    );
    let answer = read(&one_out.join("result.yaml"));
    assert_eq!(
        read(&listed_out.join("result.yaml")),
        answer,
        "the root's answer"
    );
    let camera = camera_folder(&listed_out, "wrist");
    assert_eq!(
        read(&camera.join("result.yaml")),
        answer,
        "the camera's answer"
    );
    for said in [
        format!("result:  {}", listed_out.join("result.yaml").display()),
        format!("report:  {}", listed_out.join("report.html").display()),
    ] {
        assert!(stdout.contains(&said), "{said:?} not in:\n{stdout}");
    }
    assert!(listed_out.join("report.html").is_file());
    // The answer itself: within half a millimetre of the simulator's truth.
    let result = CellResult::load(&listed_out.join("result.yaml")).unwrap();
    let truth = handeye_config::CellConfig::load(&listed).unwrap().cameras[0]
        .simulation
        .unwrap();
    let mount = result.only_camera().unwrap().mounts(&listed_out).unwrap();
    let (mm, deg) = util::pose_error_mm_deg(&mount.camera_mount, &truth.camera_mount);
    assert!(
        mm < 0.5 && deg < 0.05,
        "{mm:.3} mm, {deg:.4}° from the truth"
    );

    // Every command given either session reads and prints the same.
    for args in [&["solve"][..], &["replay"], &["verify", "--session"]] {
        assert_eq!(
            printed(args, &listed_out),
            printed(args, &one_out),
            "handeye {args:?}"
        );
    }
    for written in ["result-reprojection.yaml", "replay-result.yaml"] {
        assert_eq!(
            read(&listed_out.join(written)),
            read(&one_out.join(written)),
            "{written}"
        );
    }
    // A held-out run on fresh views checks the list of one's answer as the one-camera form's.
    let holdout = |config: &Path, session: &Path| {
        let out = dir.path().join(format!(
            "holdout-{}",
            session.file_name().unwrap().to_string_lossy()
        ));
        let stdout = util::succeeds(
            handeye()
                .args(["verify", "--poses", "6", "--config"])
                .arg(config)
                .arg("--result")
                .arg(session.join("result.yaml"))
                .arg("-o")
                .arg(&out),
        );
        stdout
            .replace(&out.display().to_string(), "HOLDOUT")
            .replace(&session.display().to_string(), "SESSION")
    };
    assert_eq!(holdout(&listed, &listed_out), holdout(&one, &one_out));
    util::succeeds(handeye().arg("report").arg(&listed_out));
    assert!(read(&listed_out.join("report.html")).contains("T_flange_camera"));
}
