//! The live console of a several-camera run: `handeye run --console` of the three-camera cell,
//! its event stream read by a WebSocket client we did not write (tokio-tungstenite): the cell
//! names every camera, every camera's record of every pose arrives named with its residual, the
//! plan table gets the planner camera's records only (once per pose), and the cell's verdict
//! and every camera's verdict end it; the page served has the cameras' table.

use std::time::Duration;

use crate::util;

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
        result.verdict.level.word(),
        "{finished}"
    );
    let summary = finished["summary"].as_str().unwrap();
    for camera in &result.cameras {
        assert!(
            summary.contains(&format!("{}: {}", camera.name, camera.verdict.level)),
            "{summary}"
        );
    }
}

/// The events of one type, in order.
fn of_type<'a>(
    events: &'a [serde_json::Value],
    kind: &'a str,
) -> impl Iterator<Item = &'a serde_json::Value> {
    events.iter().filter(move |e| e["type"] == kind)
}
