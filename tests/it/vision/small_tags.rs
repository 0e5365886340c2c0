//! Issue #29: small, blurred tags (a board seen by a 640×480 camera, defocus or motion blur).
//! The second pass looks again at full resolution where the grid says a missing tag is; on the
//! real photos (tests/it/aprilgrid_photos.rs) it finds tags the first pass missed. Here, on
//! rendered frames with known truth, it must only add: every tag of the first pass kept, and
//! every tag found in view, at its place (a tag found in the wrong place or with the wrong id
//! would show in the corner errors).

use super::*;

fn vga_camera() -> CameraModel {
    CameraModel {
        width: 640,
        height: 480,
        fx: 525.0,
        fy: 524.3,
        cx: 319.2,
        cy: 241.6,
        distortion: Distortion::RadTan {
            k1: -0.08,
            k2: 0.04,
            p1: 0.0003,
            p2: -0.0002,
            k3: 0.0,
        },
    }
}

#[test]
fn issue29_the_second_pass_on_small_blurred_tags_adds_only_tags_that_are_there() {
    let board = board_6x6();
    let camera = vga_camera();
    let first_only = TagDetector::spawn(
        &board,
        DetectorOptions {
            second_pass: false,
            ..DetectorOptions::default()
        },
    )
    .unwrap();
    let both = TagDetector::spawn(&board, DetectorOptions::default()).unwrap();

    let mut rng = StdRng::seed_from_u64(29);
    let (mut in_view, mut found_first, mut found_both) = (0usize, 0usize, 0usize);
    let mut squared_errors = Vec::new();
    for frame in 0..16 {
        let truth = random_view(&board, &camera, &mut rng, 0.5, 0.7, 45.0);
        let options = RenderOptions {
            noise_sigma: 2.0,
            blur_sigma_px: 1.2 + 0.1 * (frame % 6) as f64,
            ..RenderOptions::default()
        };
        let image = render(&board, &camera, &truth, &options, &mut rng);
        let truth_corners = reproject(&board, &camera, &truth);
        in_view += truth_corners.len();
        let first = first_only.detect(&image).unwrap();
        let second = both.detect(&image).unwrap();
        found_first += first.tags.len();

        found_both += second.tags.len();
        // The second pass only adds: every tag of the first pass is still there.
        for tag in &first.tags {
            assert!(second.tags.iter().any(|t| t.id == tag.id), "frame {frame}");
        }
        for tag in &second.tags {
            let (_, expected) = truth_corners
                .iter()
                .find(|(id, _)| *id == tag.id)
                .unwrap_or_else(|| panic!("frame {frame}: tag {} is not in view", tag.id));
            for (corner, expected) in tag.corners_px.iter().zip(expected) {
                squared_errors.push((corner - expected).norm_squared());
            }
        }
    }
    let share = |n: usize| 100.0 * n as f64 / in_view as f64;
    let rms = (squared_errors.iter().sum::<f64>() / squared_errors.len() as f64).sqrt();
    let largest = squared_errors.iter().fold(0.0f64, |m, e| m.max(e.sqrt()));
    println!(
        "{in_view} tags in view: first pass {found_first} ({:.1} %), with the second pass \
         {found_both} ({:.1} %); corner error RMS {rms:.3} px, largest {largest:.3} px",
        share(found_first),
        share(found_both)
    );
    // Measured: 271 of 576 without the second pass, 274 with it (272 before it retried with the
    // crop sharpened). Blur, not size, is what loses these tags (the full-resolution quad search
    // finds fewer still: 226): the second pass is a safety net here, and must never add a tag
    // that is not there.
    assert!(found_both >= found_first);
    assert!(rms < 0.25 && largest < 1.0, "{rms:.3} px, {largest:.3} px");
}
