//! Real photographs of printed Kalibr aprilgrids: the calibration frames the `aprilgrid` crate
//! tests with (powei-lin/aprilgrid-rs, `tests/data/*.png` and `data/*.png`: TUM-VI and EuRoC
//! frames, phone photos of grids on a monitor), read from `../shared/datasets/aprilgrid_photos`
//! (or `$HANDEYE_DATASETS/aprilgrid_photos`) under their own file names:
//! handeye must find at least 95 % of the tags in view, never fewer than OpenCV's ArUco detector
//! (set up for Kalibr's 2-cell border) on any frame, and every tag it reports must sit where
//! its grid neighbours say it should (a misread id would not).
//!
//! Skips with a printed reason when the data set is absent; the OpenCV side needs python3 with
//! numpy and opencv-python-headless (scripts/test.sh installs them).

use std::path::Path;
use std::process::Command;

use handeye_vision::detect::load_gray_image;
use handeye_vision::{Board, DetectorOptions, TagDetector, TagFamily};
use nalgebra::Point2;

use crate::util;

/// One photograph: its file and the grids in it (columns, rows, id of the first tag). Every
/// tag of every grid is in view.
struct Photo {
    file: &'static str,
    grids: &'static [(u32, u32, u32)],
}

const PHOTOS: &[Photo] = &[
    Photo {
        file: "TUM_VI.png",
        grids: &[(6, 6, 0)],
    },
    Photo {
        file: "1520525725372653511.png",
        grids: &[(6, 6, 0)],
    },
    Photo {
        file: "r45.png",
        grids: &[(6, 6, 0)],
    },
    Photo {
        file: "right.png",
        grids: &[(6, 6, 0)],
    },
    Photo {
        file: "top.png",
        grids: &[(6, 6, 0)],
    },
    Photo {
        file: "top_right.png",
        grids: &[(6, 6, 0)],
    },
    Photo {
        file: "EuRoC.png",
        grids: &[(6, 6, 0)],
    },
    Photo {
        file: "iphone.png",
        grids: &[(11, 6, 0)],
    },
    Photo {
        file: "two_boards.png",
        grids: &[(6, 6, 0), (6, 6, 36)],
    },
];

/// Counts OpenCV's tag36h11 detections with ids in `0..=max_id`, one line `file count` each.
const OPENCV_COUNT: &str = r#"
import sys, cv2, numpy as np
params = cv2.aruco.DetectorParameters()
params.markerBorderBits = 2  # Kalibr prints a 2-cell black border
params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
detector = cv2.aruco.ArucoDetector(
    cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11), params)
folder, max_id = sys.argv[1], int(sys.argv[2])
for name in sys.argv[3:]:
    image = cv2.imread(folder + "/" + name, cv2.IMREAD_UNCHANGED)
    if image.dtype == np.uint16:
        image = (image / 257).astype(np.uint8)
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    _, ids, _ = detector.detectMarkers(image)
    found = set() if ids is None else {int(i) for i in ids.flatten() if i <= max_id}
    print(name, len(found))
"#;

fn opencv_counts(python: &Path, folder: &Path) -> Vec<usize> {
    let max_id = PHOTOS
        .iter()
        .flat_map(|p| p.grids)
        .map(|(cols, rows, first)| first + cols * rows - 1)
        .max()
        .unwrap();
    let output = Command::new(python)
        .arg("-c")
        .arg(OPENCV_COUNT)
        .arg(folder)
        .arg(max_id.to_string())
        .args(PHOTOS.iter().map(|p| p.file))
        .output()
        .expect("running python");
    assert!(
        output.status.success(),
        "OpenCV count failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let text = String::from_utf8(output.stdout).unwrap();
    let counts: Vec<usize> = text
        .lines()
        .map(|line| line.split_whitespace().nth(1).unwrap().parse().unwrap())
        .collect();
    assert_eq!(counts.len(), PHOTOS.len(), "OpenCV output: {text}");
    counts
}

/// The tags of one grid found in `image`, as (id, centre px), after checking that each tag
/// with both row neighbours found lies halfway between them (within 15 % of their distance):
/// a tag decoded with the wrong id would sit elsewhere.
fn found_tags(
    image: &image::GrayImage,
    file: &str,
    (cols, rows, first_id): (u32, u32, u32),
    second_pass: bool,
) -> Vec<(u32, Point2<f64>)> {
    let board = Board::aprilgrid(cols, rows, 0.04, 0.3, TagFamily::Tag36h11, first_id, 2)
        .and_then(|b| b.with_corner_squares(true))
        .unwrap();
    let options = DetectorOptions {
        second_pass,
        ..DetectorOptions::default()
    };
    let detector = TagDetector::spawn(&board, options).unwrap();
    let detection = detector.detect(image).unwrap();
    let centres: Vec<(u32, Point2<f64>)> = detection
        .tags
        .iter()
        .map(|t| {
            let sum = t
                .corners_px
                .iter()
                .fold(nalgebra::Vector2::zeros(), |s, c| s + c.coords);
            (t.id, Point2::from(sum / 4.0))
        })
        .collect();
    let centre = |id: u32| centres.iter().find(|(i, _)| *i == id).map(|(_, c)| *c);
    for &(id, middle) in &centres {
        let column = (id - first_id) % cols;
        if column == 0 || column == cols - 1 {
            continue;
        }
        if let (Some(left), Some(right)) = (centre(id - 1), centre(id + 1)) {
            let expected = Point2::from((left.coords + right.coords) / 2.0);
            let pitch = (right - left).norm() / 2.0;
            assert!(
                (middle - expected).norm() < 0.15 * pitch,
                "{file}: tag {id} at {middle:?} is not between its neighbours (expected \
                 {expected:?}, pitch {pitch:.1} px): a misread id?"
            );
        }
    }
    centres
}

#[test]
fn printed_kalibr_grids_in_real_photos_are_found_and_never_fewer_than_opencv() {
    let Some(folder) = util::dataset("aprilgrid_photos") else {
        return;
    };
    // handeye's own floor and id check need no Python; the comparison needs OpenCV.
    let opencv = util::python_with_opencv().map(|python| opencv_counts(&python, &folder));
    let (mut visible, mut ours_total, mut first_pass_total) = (0, 0, 0);
    let mut fewer = Vec::new();
    for (i, photo) in PHOTOS.iter().enumerate() {
        let image = load_gray_image(&folder.join(photo.file)).unwrap();
        let in_view: usize = photo.grids.iter().map(|(c, r, _)| (c * r) as usize).sum();
        let count = |second_pass: bool| -> usize {
            photo
                .grids
                .iter()
                .map(|&grid| found_tags(&image, photo.file, grid, second_pass).len())
                .sum()
        };
        let (ours, first_pass) = (count(true), count(false));
        // The second pass (`vision::regrid`) only adds tags.
        assert!(ours >= first_pass, "{}: {ours} < {first_pass}", photo.file);
        let theirs = opencv.as_ref().map(|counts| counts[i]);
        eprintln!(
            "{}: handeye {ours}/{in_view} (first pass alone {first_pass}), OpenCV {}",
            photo.file,
            theirs.map_or("not run".into(), |n| format!("{n}/{in_view}"))
        );
        visible += in_view;
        ours_total += ours;
        first_pass_total += first_pass;
        if let Some(theirs) = theirs.filter(|&theirs| ours < theirs) {
            fewer.push(format!("{} ({ours} < {theirs})", photo.file));
        }
    }
    let share = ours_total as f64 / visible as f64;
    eprintln!(
        "in all: handeye {ours_total}/{visible} ({:.1} %), OpenCV {}",
        100.0 * share,
        opencv.map_or("not run".into(), |counts| {
            let total: usize = counts.iter().sum();
            format!(
                "{total}/{visible} ({:.1} %)",
                100.0 * total as f64 / visible as f64
            )
        })
    );
    eprintln!("first pass alone: {first_pass_total}/{visible}");
    // Measured: 381 without the second pass, 385 with it (the fisheye frames' edge tags; 384 before
    // the second pass retried a missed tag with its crop sharpened).
    assert!(
        ours_total > first_pass_total,
        "the second pass finds tags the first misses on these photos"
    );
    assert!(
        share >= 0.95,
        "handeye found {ours_total} of {visible} tags in view ({:.1} %), want ≥ 95 %",
        100.0 * share
    );
    assert!(fewer.is_empty(), "fewer tags than OpenCV on: {fewer:?}");
}
