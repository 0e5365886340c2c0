//! Issue #30: a camera that sends frames only while the arm stands (triggered by the driver, or a
//! recorder throttled to the stops) gives a stream where every frame is stationary. The frames of
//! two stops are neighbours in the stream; they used to form one interval, so 20 stops became
//! "only 1 usable frame".

use super::*;

#[test]
fn issue30_frames_only_at_the_stops_give_one_sample_per_stop() {
    let dir = tempfile::tempdir().unwrap();
    let board = Board::load(&board_path()).unwrap();
    let stops = 8;
    let trajectory = StopAndGo {
        views: views(stops, &board),
        stay: 0.6,
        travel: 1.0,
    };
    let period = trajectory.stay + trajectory.travel;
    // Frames well inside each stop (as a driver that triggers the camera once the arm settled
    // sends them): every frame of the bag is stationary over the whole window.
    let settled = |t: f64| (0.15..=trajectory.stay - 0.15).contains(&(t % period));
    let Some(bag) = make_bag_edited(
        dir.path(),
        "only-at-stops",
        &BagSpec {
            storage: "mcap",
            image_kind: "mono8",
            trajectory: &trajectory,
            fps: 10.0,
            tf_hz: 100.0,
            offset_s: 0.0,
            camera_info: true,
            render: &settled,
        },
        // No frame while moving: the bag holds only the stops' frames.
        |spec| {
            spec["images"]
                .as_array_mut()
                .unwrap()
                .retain(|image| !image[1].as_str().unwrap().ends_with("blank.gray"));
        },
    ) else {
        return;
    };
    let imported = handeye::formats::bag::import_bag(&bag, &sim_bag_options()).unwrap();
    assert_eq!(
        imported.samples.len(),
        stops,
        "one sample per stop; skipped: {:?}",
        imported
            .skipped
            .iter()
            .map(|s| s.reason.to_string())
            .collect::<Vec<_>>()
    );
    // Each sample stands where its stop is (not a pose of a neighbouring stop).
    for (sample, view) in imported.samples.iter().zip(&trajectory.views) {
        let (mm, deg) = pose_error_mm_deg(&sample.base_from_flange, view);
        assert!(mm < 1e-3 && deg < 1e-4, "{mm} mm {deg} deg");
    }
}
