//! Issue #30: an imported session names itself where it ends (not its staging folder); and a
//! camera that sends frames only while the arm stands (triggered by the driver, or a
//! recorder throttled to the stops) gives a stream where every frame is stationary. The frames of
//! two stops are neighbours in the stream; they used to form one interval, so 20 stops became
//! "only 1 usable frame".

use super::*;

/// A bag of `stops` stops whose frames are all taken well inside each stop (as a driver that
/// triggers the camera once the arm settled sends them): every frame is stationary over the whole
/// window. With the trajectory's views.
fn stops_only_bag(dir: &Path, stops: usize) -> Option<(PathBuf, Vec<Pose>)> {
    let trajectory = StopAndGo::through_views(stops, 0.6, 1.0);
    let period = trajectory.stay + trajectory.travel;
    let settled = |t: f64| (0.15..=trajectory.stay - 0.15).contains(&(t % period));
    let bag = make_bag_edited(
        dir,
        "only-at-stops",
        &BagSpec {
            fps: 10.0,
            tf_hz: 100.0,
            ..BagSpec::of(&trajectory, &settled)
        },
        // No frame while moving: the bag holds only the stops' frames.
        |spec| {
            spec["images"]
                .as_array_mut()
                .unwrap()
                .retain(|image| !image[1].as_str().unwrap().ends_with("blank.gray"));
        },
    )?;
    Some((bag, trajectory.views))
}

#[test]
fn issue30_frames_only_at_the_stops_give_one_sample_per_stop() {
    let dir = tempfile::tempdir().unwrap();
    let stops = 8;
    let Some((bag, views)) = stops_only_bag(dir.path(), stops) else {
        return;
    };
    let imported = handeye_ros2_bag::import_bag(&bag, &sim_bag_options()).unwrap();
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
    for (sample, view) in imported.samples.iter().zip(&views) {
        let (mm, deg) = pose_error_mm_deg(&sample.base_from_flange, view);
        assert!(mm < 1e-3 && deg < 1e-4, "{mm} mm {deg} deg");
    }
}

/// The import solves in a staging folder renamed at the end: advice that names the session
/// (here the board printed at another scale: "... then `handeye replay DIR --config ...`") names
/// it where it is, in result.yaml as on the terminal.
#[test]
fn advice_in_an_imported_session_names_the_session_where_it_ends() {
    let dir = tempfile::tempdir().unwrap();
    let Some((bag, _)) = stops_only_bag(dir.path(), 10) else {
        return;
    };
    // A board file 5 % larger than the print (tagSize 0.042 for 0.04 m tags).
    let board = dir.path().join("board-off.yaml");
    std::fs::write(
        &board,
        std::fs::read_to_string(board_path())
            .unwrap()
            .replace("tagSize: 0.04\n", "tagSize: 0.042\n"),
    )
    .unwrap();
    let out = dir.path().join("session");
    let run = handeye()
        .args(["import", "bag"])
        .arg(&bag)
        .args(["--base", "base_link", "--flange", "tool0"])
        .args(["--image", "/camera/image_raw"])
        .args(["--camera-info", "/camera/camera_info", "--board"])
        .arg(&board)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    let log = text(&run);
    assert!(run.status.success(), "{log}");
    let result = std::fs::read_to_string(out.join("result.yaml")).unwrap();
    assert!(
        result.contains("tagSize"),
        "the print-scale advice: {result}"
    );
    assert!(
        result.contains(&format!("handeye replay {}", out.display())),
        "{result}"
    );
    assert!(!result.contains(".importing"), "{result}");
}
