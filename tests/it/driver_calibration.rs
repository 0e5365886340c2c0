//! The camera driver's own calibration against the config's intrinsics file (issue #39): a ROS 2
//! run keeps the `CameraInfo` the driver published in the session
//! (`camera_info_from_topic.yaml`), and a file that differs from it is a finding of the verdict
//! — with which of the two the board's corners fit better.
//!
//! The class, not a point: the lens mistakes are drawn at random (seeded) from the classes and
//! ranges of `cell_model.rs` (fx and fy together or apart, the principal point, distortion
//! dropped, flipped or another lens's), once as a stale file beside a driver publishing the
//! truth, once as a driver publishing the stale calibration beside a true file. The recorded
//! session is the simulated cell's (no ROS 2 graph needed: the driver's calibration is a file in
//! the session); each case is `handeye replay --config` of it.

use std::path::Path;

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use handeye_core::camera_model::CameraModel;
use handeye_core::notice::{NoticeKind, Severity};
use handeye_records::result::ResultFile;
use handeye_records::solve::DRIVER_CALIBRATION_FILE;
use handeye_solve::cell_model::GivenFile;
use handeye_solve::verdict::{Level, Verdict};

use crate::cell_model::Mistake;
use crate::util::{config_variant, handeye, repo, run_cell};

const DIFFER: &str = "differ from the calibration the camera driver publishes";
const DRIVER_BETTER: &str = "fit the driver's better";
const FILE_BETTER: &str = "fit the file better";

/// The replayed result of `session` with `config`, written under `out`; what the replay said
/// when it refused (every pose rejected by the config's lens).
fn replay(session: &Path, config: &Path, out: &Path) -> Result<ResultFile, String> {
    let result = out.join("result.yaml");
    let replay = handeye()
        .arg("replay")
        .arg(session)
        .arg("--config")
        .arg(config)
        .arg("-o")
        .arg(&result)
        .output()
        .unwrap();
    if !replay.status.success() {
        return Err(String::from_utf8_lossy(&replay.stderr).into_owned());
    }
    Ok(ResultFile::load(&result).unwrap())
}

/// The verdict's reason and every further finding, one per line.
fn findings(verdict: &Verdict) -> String {
    std::iter::once(verdict.reason.as_str())
        .chain(verdict.also.iter().map(|f| f.reason.as_str()))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn a_file_that_differs_from_the_drivers_calibration_is_a_finding_whichever_lens_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let config = config_variant(dir.path(), "sim-cell.yaml", "cell.yaml", &[]);
    let session = dir.path().join("session");
    run_cell(&config, &session);
    let truth = CameraModel::load(&repo().join("configs/cameras/sim-1280x720.yaml")).unwrap();
    let kept = session.join(DRIVER_CALIBRATION_FILE);

    // The driver publishing exactly the file: nothing to say.
    truth.save_camera_info(&kept).unwrap();
    let same = replay(&session, &config, &dir.path().join("same")).unwrap();
    assert!(
        !same
            .notices
            .iter()
            .any(|n| n.kind == NoticeKind::DriverCalibration),
        "{:?}",
        same.notices
    );
    assert_eq!(same.verdict.as_ref().unwrap().level, Level::Good);

    let mut rng = StdRng::seed_from_u64(39);
    let mut cases = 0;
    let (mut stale_file_named, mut stale_driver_named) = (0, 0);
    // Ten lens mistakes of the class, then the small end of the principal point's range (each
    // parameter under 1 % of the width, the tolerance the parameters are listed by).
    let mut mistakes = std::iter::from_fn(|| Some(Mistake::draw(&mut rng)))
        .filter(|m| m.wrong() == [GivenFile::Intrinsics])
        .take(10)
        .collect::<Vec<_>>();
    let angle = rng.random_range(0.0..std::f64::consts::TAU);
    let size = rng.random_range(5.0..10.0);
    mistakes.push(Mistake::PrincipalPoint(
        size * angle.cos(),
        size * angle.sin(),
    ));
    for mistake in mistakes {
        cases += 1;
        let stale = mistake.lens_file(&truth);
        let case = dir.path().join(format!("case-{cases}"));
        std::fs::create_dir_all(&case).unwrap();

        // A stale file while the driver publishes the camera's calibration: never GOOD, the
        // difference named, and never the driver blamed.
        truth.save_camera_info(&kept).unwrap();
        let stale_file = case.join("stale.yaml");
        stale.save_camera_info(&stale_file).unwrap();
        let stale_config = config_variant(
            &case,
            "sim-cell.yaml",
            "stale-cell.yaml",
            &[(
                &format!(
                    "intrinsics: {}",
                    repo().join("configs/cameras/sim-1280x720.yaml").display()
                ),
                &format!("intrinsics: {}", stale_file.display()),
            )],
        );
        // A file so far off that it rejects every pose (or all but too few to solve) stops
        // the replay: its error then says it.
        let said = match replay(&session, &stale_config, &case.join("stale-file")) {
            Ok(result) => {
                let verdict = result.verdict.unwrap();
                assert_ne!(
                    verdict.level,
                    Level::Good,
                    "{mistake:?}: {}",
                    findings(&verdict)
                );
                format!("{}: {}", verdict.level, findings(&verdict))
            }
            Err(refused) => {
                assert!(
                    refused.contains("every one rejected")
                        || refused.contains("that its intrinsics let through"),
                    "{refused}"
                );
                format!("refused: {refused}")
            }
        };
        println!("{} ({mistake:?}), stale file: {said}", mistake.class());
        assert!(said.contains(DIFFER), "{mistake:?}: {said}");
        assert!(!said.contains(FILE_BETTER), "{mistake:?}: {said}");
        stale_file_named += usize::from(said.contains(DRIVER_BETTER));

        // The driver publishing the stale calibration beside a true file: the answer is the true
        // file's; the driver is never preferred; the difference is named (information when the
        // corners tell the file fits better, a CHECK finding when they cannot tell).
        stale.save_camera_info(&kept).unwrap();
        let result = replay(&session, &config, &case.join("stale-driver")).unwrap();
        let verdict = result.verdict.unwrap();
        let notice = result
            .notices
            .iter()
            .find(|n| n.kind == NoticeKind::DriverCalibration)
            .unwrap_or_else(|| panic!("{mistake:?}: no notice in {:?}", result.notices));
        println!(
            "{} ({mistake:?}), stale driver: {} — {}",
            mistake.class(),
            verdict.level,
            notice.message
        );
        assert!(notice.message.contains(DIFFER), "{}", notice.message);
        assert!(
            !notice.message.contains(DRIVER_BETTER),
            "{}",
            notice.message
        );
        if notice.severity == Severity::Info {
            assert!(notice.message.contains(FILE_BETTER), "{}", notice.message);
            assert_eq!(verdict.level, Level::Good, "{}", findings(&verdict));
            stale_driver_named += 1;
        } else {
            assert_eq!(verdict.level, Level::Check, "{}", findings(&verdict));
        }
    }
    println!(
        "of {cases} lens mistakes: the driver's fits better named {stale_file_named} times (stale file), the file's {stale_driver_named} times (stale driver)"
    );
    // Most of the class is told apart; the rest is "cannot tell", never the wrong lens.
    assert!(stale_file_named >= cases - 2 && stale_driver_named >= cases - 2);
}
