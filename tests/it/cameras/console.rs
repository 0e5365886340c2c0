//! The live console of a several-camera run: `handeye run --console` of the three-camera cell,
//! its event stream read by a WebSocket client we did not write (tokio-tungstenite): the cell
//! names every camera, every camera's record of every pose arrives named with its residual, the
//! plan table gets the planner camera's records only (once per pose), and the cell's verdict
//! and every camera's verdict end it; the page served has the cameras' table. A hand-guided
//! session of the same cell captures with every camera at each view and solves them all.

use std::time::Duration;

use crate::util;
use handeye_solve::verdict::Basis;

#[test]
fn the_console_shows_every_camera_of_a_several_camera_run_by_name() {
    let dir = tempfile::tempdir().unwrap();
    // Slow moves, so the page is connected while the run goes on (the history covers the rest).
    let config = super::three_cameras(
        dir.path(),
        &[
            ("count: 20", "count: 6"),
            ("move_duration_s: 0.0", "move_duration_s: 0.3"),
        ],
    );
    let session = dir.path().join("session");
    let (config_s, session_s) = (config.display().to_string(), session.display().to_string());
    let mut live = util::live::Live::start(
        &[
            "run",
            "--config",
            &config_s,
            "--output",
            &session_s,
            "--console",
            "127.0.0.1:0",
        ],
        dir.path(),
    );
    let url = live.url();
    let (authority, query) = url
        .strip_prefix("http://")
        .and_then(|rest| rest.split_once('/'))
        .expect("an http URL with the secret");
    let page = crate::console::http_get(authority.parse().unwrap(), &format!("/{query}"));
    assert!(
        page.contains("id=\"cameras\"") && page.contains("camera_pose(e)"),
        "the page has no cameras' table"
    );
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let events: Vec<serde_json::Value> = runtime.block_on(async {
        use futures_util::StreamExt;
        use tokio_tungstenite::tungstenite::Message;
        let (mut ws, _) = tokio_tungstenite::connect_async(util::console_socket(&url))
            .await
            .expect("connects");
        let mut events = Vec::new();
        while let Ok(Some(Ok(message))) =
            tokio::time::timeout(Duration::from_secs(60), ws.next()).await
        {
            if let Message::Text(text) = message {
                events.push(serde_json::from_str(&text).unwrap());
            }
        }
        events
    });
    let (ok, out) = live.finish();
    assert!(ok, "the run failed:\n{out}");
    let cell = of_type(&events, "cell").next().expect("a cell event");
    assert_eq!(
        cell["cameras"],
        serde_json::json!(["wrist", "left", "right"]),
        "{cell}"
    );
    for name in ["wrist", "left", "right"] {
        let records: Vec<_> = of_type(&events, "camera_pose")
            .filter(|e| e["camera"] == name)
            .collect();
        let poses: std::collections::BTreeSet<u64> = records
            .iter()
            .map(|e| e["plan_index"].as_u64().unwrap())
            .collect();
        assert_eq!(
            poses.len(),
            6,
            "{name}: a record of every pose: {records:?}"
        );
        let captured: Vec<f64> = records
            .iter()
            .filter(|e| e["state"] == "captured")
            .map(|e| e["rms_px"].as_f64().expect("a captured record's residual"))
            .collect();
        assert!(captured.len() >= 4, "{name}: {records:?}");
        assert!(
            captured.iter().all(|rms| *rms > 0.0 && *rms < 1.0),
            "{name}: {captured:?}"
        );
    }
    // The plan table is the planner camera's: one final record per pose, not one per camera.
    let plan_rows: Vec<u64> = of_type(&events, "pose")
        .filter(|e| e["state"] != "retry")
        .map(|e| e["plan_index"].as_u64().unwrap())
        .collect();
    assert_eq!(plan_rows, (0..6).collect::<Vec<_>>());
    let finished = of_type(&events, "finished")
        .next()
        .expect("a finished event");
    // The cell's verdict as result.yaml has it, with every camera's (6 poses: CHECK, too few
    // samples for GOOD).
    let result = super::read_result(&session);
    assert_eq!(
        finished["verdict"],
        result.verdict.as_ref().unwrap().level.word(),
        "{finished}"
    );
    let summary = finished["summary"].as_str().unwrap();
    for camera in &result.cameras {
        assert!(
            summary.contains(&format!(
                "{}: {}",
                camera.name,
                camera.verdict.as_ref().unwrap().level
            )),
            "{summary}"
        );
    }
}

/// `handeye console` of the three-camera cell: a hand-guided session, driven over the console's
/// WebSocket as a person would (go to the suggested view, capture), grabs with every camera at
/// each capture and records into each camera's folder. Stopped after five captures, every
/// camera's records are kept, and `handeye run --resume ROOT` continues it by hand on the console;
/// finished, it solves every camera jointly (each mount within 0.5 mm / 0.05° of the simulator's
/// truth, as a planned run's, no right file blamed) and keeps the captures as the taught plan.
#[test]
fn a_hand_guided_session_of_three_cameras_captures_with_every_camera() {
    let dir = tempfile::tempdir().unwrap();
    let config = super::three_cameras(dir.path(), &[]);
    let session = dir.path().join("session");
    let session_s = session.display().to_string();
    let mut live = util::live::Live::console(&config, &session, dir.path());
    let url = live.url();
    let runtime = util::live::runtime();
    // Five captures, then STOP: every camera's records are kept.
    runtime.block_on(async {
        let mut page = util::live::Page::open(&url).await;
        crate::manual::capture_views(&mut page, 5).await;
        page.send("stop").await;
        page.next("ended").await;
    });
    let (ok, out) = live.finish();
    assert!(
        !ok && out.contains(&format!("handeye run --resume {session_s}")),
        "a stopped session says how to resume:\n{out}"
    );
    for name in ["wrist", "left", "right"] {
        let manifest = handeye_records::SessionFolder::open(&session.join("cameras").join(name))
            .and_then(|f| f.read_manifest())
            .unwrap();
        assert_eq!(manifest.plan.len(), 5, "{name}: the captures so far");
    }
    // `handeye run --resume ROOT` sees a hand-guided session and serves the console again:
    // seven more, finish.
    let captures = 12;
    let mut live = util::live::Live::start(
        &["run", "--resume", &session_s, "--console", "127.0.0.1:0"],
        dir.path(),
    );
    let url = live.url();
    let finished = runtime.block_on(async {
        let mut page = util::live::Page::open(&url).await;
        crate::manual::capture_and_finish(&mut page, captures - 5).await
    });
    let (ok, out) = live.finish();
    assert!(ok, "the resumed hand-guided session failed:\n{out}");
    let result = super::read_result(&session);
    assert_eq!(
        finished["verdict"],
        result.verdict.as_ref().unwrap().level.word(),
        "{finished}"
    );
    let truth = super::truth(&config);
    for camera in &result.cameras {
        let folder = session.join("cameras").join(&camera.name);
        let manifest = handeye_records::SessionFolder::open(&folder)
            .and_then(|f| f.read_manifest())
            .unwrap();
        assert_eq!(
            manifest.plan.len(),
            captures,
            "{}: its manifest holds every capture",
            camera.name
        );
        assert!(camera.samples >= 6, "{}: {camera:?}", camera.name);
        let joint = camera.joint.as_ref().expect("solved jointly");
        let (_, true_mount) = truth.iter().find(|(name, _)| *name == joint.name).unwrap();
        let (translation_mm, rotation_deg) = util::pose_error_mm_deg(&joint.pose, true_mount);
        println!(
            "{}: {} samples, {rotation_deg:.4}° {translation_mm:.3} mm from the truth (1-sigma {:.3} mm), {}: {}",
            camera.name,
            camera.samples,
            joint.sigma.unwrap().translation_mm,
            camera.verdict.as_ref().unwrap().level,
            camera.verdict.as_ref().unwrap().reason
        );
        assert!(
            rotation_deg < 0.05 && translation_mm < 0.5,
            "{}: {rotation_deg}° {translation_mm} mm",
            camera.name
        );
        // Every file is right: none is blamed (the views were suggested by the cell's planner for
        // the three cameras at once, and 12 captures give the fixed cameras' own cell models
        // fewer kinds of view than a planned run's 20).
        let blamed = std::iter::once(camera.verdict.as_ref().unwrap().basis)
            .chain(
                camera
                    .verdict
                    .as_ref()
                    .unwrap()
                    .also
                    .iter()
                    .map(|f| f.basis),
            )
            .any(|basis| {
                matches!(
                    basis,
                    Basis::Intrinsics | Basis::BoardScale | Basis::IntrinsicsAndBoard
                )
            });
        assert!(
            !blamed,
            "{}: {}",
            camera.name,
            camera.verdict.as_ref().unwrap().reason
        );
    }
    let planner = session.join("cameras").join(&result.cameras[0].name);
    let taught =
        handeye_plan::Plan::load(&planner.join("taught-plan.yaml")).expect("the taught plan");
    assert_eq!(taught.waypoints.len(), captures);
}

/// A camera that stops delivering frames during a hand-guided session of three cameras (unplugged
/// at the third capture, `HANDEYE_FAULT`) is named, its captures until then kept and solved, and
/// the others go on capturing, as in a planned run.
#[test]
fn a_camera_lost_during_a_hand_guided_session_is_named_and_the_others_go_on() {
    let dir = tempfile::tempdir().unwrap();
    let config = super::three_cameras(dir.path(), &[]);
    let session = dir.path().join("session");
    let mut live = util::live::Live::spawn(
        util::live::console_command(&config, &session, dir.path())
            .env("HANDEYE_FAULT", "camera-lost:left:2"),
    );
    let url = live.url();
    util::live::runtime().block_on(async {
        let mut page = util::live::Page::open(&url).await;
        crate::manual::capture_and_finish(&mut page, 8).await
    });
    let (ok, out) = live.finish();
    assert!(ok, "the session failed:\n{out}");
    assert!(
        out.contains("camera `left` stopped delivering frames at plan pose 2"),
        "{out}"
    );
    let result = super::read_result(&session);
    let samples = |name: &str| {
        result
            .cameras
            .iter()
            .find(|c| c.name == name)
            .unwrap()
            .samples
    };
    assert!(samples("left") <= 2, "{:?}", result.cameras);
    assert_eq!(samples("wrist"), 8, "{:?}", result.cameras);
    assert!(samples("right") >= 6, "{:?}", result.cameras);
    let failures = std::fs::read_to_string(session.join("failures.yaml")).unwrap();
    assert!(failures.contains("camera: left"), "{failures}");
}

/// The events of one type, in order.
fn of_type<'a>(
    events: &'a [serde_json::Value],
    kind: &'a str,
) -> impl Iterator<Item = &'a serde_json::Value> {
    events.iter().filter(move |e| e["type"] == kind)
}
