//! Inputs that crashed something, kept in tests/fuzz-corpus/crashes/, each replayed by a test of
//! its fix.

use super::*;

fn crash_input(name: &str) -> PathBuf {
    corpus().join("crashes").join(name)
}

#[test]
fn crash_detector_on_a_1x1_image() {
    detect_without_crash(&crash_input("detector-1x1.png"));
}

#[test]
fn crash_detector_on_a_2000x1_image() {
    detect_without_crash(&crash_input("detector-2000x1.png"));
}

fn detect_without_crash(path: &Path) {
    let board = Board::load(&repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap();
    let detector = TagDetector::spawn(&board, DetectorOptions::default()).unwrap();
    let image = load_gray_image(path).unwrap();
    match detector.detect(&image) {
        Ok(d) => assert!(d.tags.is_empty(), "no tag fits in {path:?}"),
        Err(e) => assert!(!e.to_string().is_empty()),
    }
}

/// Found by fuzzing: importing the corpus's (valid) ViSP folder over and over with two detector
/// threads crashed the process now and then (SIGSEGV after 1,200 to 3,500 imports). The C
/// library's worker pool (apriltag-sys 0.3.0, `common/workerpool.c`) adds tasks without its mutex
/// while freshly started workers may already read the task array, and a worker keeps a pointer
/// into that array after unlocking (upstream fixed it in AprilRobotics/apriltag PR #339). The
/// fix here: more than one detector thread is refused, with the reason, wherever options enter.
#[test]
fn crash_detector_worker_pool_race_more_threads_are_refused() {
    let folder = corpus().join("visp_folder");
    let options = VispOptions {
        setup: handeye_core::setup::Setup::EyeToHand,
        board: Board::load(&repo().join("configs/targets/aprilgrid-2x2-example.yaml"))
            .unwrap()
            .into(),
        camera: None,
        detector: DetectorOptions {
            threads: 2,
            ..DetectorOptions::default()
        },
        skip_unfound: false,
    };
    let error = import_visp(&folder, &options).unwrap_err();
    // The whole chain, as the CLI prints it.
    let message = chain(&error);
    assert!(
        message.contains("threads") && message.contains("worker pool"),
        "{message}"
    );
    let board = Board::load(&repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap();
    let refused = TagDetector::spawn(
        &board,
        DetectorOptions {
            threads: 2,
            ..DetectorOptions::default()
        },
    );
    assert!(refused.is_err(), "two detector threads must be refused");
}

#[test]
fn crash_config_settle_1e300() {
    // It used to load and then panic turning 1e300 s into a `Duration`; the config's bounds now
    // refuse it, naming the key.
    let path = crash_input("config-settle-1e300.yaml");
    let message = chain(&CellConfig::load(&path).unwrap_err());
    assert!(message.contains("session.settle_s"), "{message}");
}
