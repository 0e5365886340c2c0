//! Regression tests for issue #13's input-hardening findings, each with the exact reproduction:
//! tiny images that crashed the C detector, a closed stdout, absurd translations, ViSP XML
//! comments, trailing junk after MoveIt JSON, shell metacharacters in frame ids, and a failed
//! ViSP import's partial outputs.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use handeye::vision::{Board, DetectorOptions, TagDetector, TargetError};
use image::GrayImage;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

mod util;
use util::repo;

fn handeye() -> Command {
    Command::new(env!("CARGO_BIN_EXE_handeye"))
}

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
                .contains("decimation must be between 1 and 16"),
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
            .arg("--target")
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
        stderr.contains("decimation must be between 1 and 16, found 1000000"),
        "{stderr}"
    );
    let (code, stderr) = run(&[]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("tiny.png") && stderr.contains("1x1 px is too small"),
        "{stderr}"
    );
}
