//! Hand-guided sessions resume, replay and report like any other (issue #15): a session made with
//! `handeye console` on the simulated cell, driven over the console's WebSocket by a client we
//! did not write (tokio-tungstenite) — go to the suggested view, capture — is stopped part-way
//! with its samples kept; a resume after the board file changed is refused naming the board,
//! both from `handeye console --resume` and `handeye run --resume`; with the file restored,
//! `handeye run --resume` continues it by hand on the console to a GOOD verdict; `replay` and
//! `report` then work on it unchanged. No browser is needed.

use crate::util;

use std::path::{Path, PathBuf};
use std::process::Stdio;

use util::live::{runtime, Live, Page};

/// Sends the arm to the suggested view and captures there until `n` captures were accepted
/// (the checks' messages go into the failure when they are not).
pub(crate) async fn capture_views(page: &mut Page, n: usize) {
    let (mut accepted, mut tries) = (0, 0);
    let mut messages = Vec::new();
    while accepted < n {
        tries += 1;
        assert!(
            tries <= 3 * n,
            "{n} captures were not accepted in {} tries: {messages:#?}",
            3 * n
        );
        page.send("go_to_suggestion").await;
        let moved = page.next("check").await;
        messages.push(moved["message"].as_str().unwrap_or_default().to_string());
        assert_eq!(moved["ok"], true, "the move to the suggestion: {moved}");
        page.send("capture").await;
        let check = page.next("check").await;
        messages.push(check["message"].as_str().unwrap_or_default().to_string());
        if check["ok"] == true {
            accepted += 1;
        }
    }
}

/// [`capture_views`], then Finish: the `finished` event (the verdict).
pub(crate) async fn capture_and_finish(page: &mut Page, n: usize) -> serde_json::Value {
    capture_views(page, n).await;
    page.send("finish").await;
    page.next("finished").await
}

/// The simulated cell with its 20 generated views as the candidates suggested, its board a
/// copy in `dir` (so the test can change it).
fn cell(dir: &Path) -> (PathBuf, PathBuf) {
    let configs = util::repo().join("configs");
    let board = dir.join("board.yaml");
    std::fs::copy(configs.join("targets/aprilgrid-6x6.yaml"), &board).unwrap();
    let config = util::config_variant(
        dir,
        "sim-cell.yaml",
        "cell.yaml",
        &[(
            &format!("target: {}/targets/aprilgrid-6x6.yaml", configs.display()),
            &format!("target: {}", board.display()),
        )],
    );
    (config, board)
}

/// Runs `handeye args` in `cwd` to its end, with no input: its success and everything it printed.
fn run_to_end(args: &[&str], cwd: &Path) -> (bool, String) {
    let out = util::handeye()
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .output()
        .expect("handeye runs");
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    (out.status.success(), text)
}

/// Accepted pose records in the session.
fn accepted_records(session: &Path) -> usize {
    handeye_records::SessionFolder::open(session)
        .and_then(|f| f.read_visits())
        .expect("the records read")
        .iter()
        .filter(|v| v.rejected.is_none() && v.camera_from_target.is_some())
        .count()
}

#[test]
fn a_hand_guided_session_stops_resumes_by_hand_to_good_and_replays_and_reports() {
    let dir = tempfile::tempdir().unwrap();
    let (config, board) = cell(dir.path());
    let session = dir.path().join("manual");
    let session_s = session.display().to_string();
    let rt = runtime();

    // 1. A new hand-guided session: four captures at suggested views, then STOP.
    let mut live = Live::console(&config, &session, dir.path());
    let url = live.url();
    rt.block_on(async {
        let mut page = Page::open(&url).await;
        capture_views(&mut page, 4).await;
        // As a page does: STOP, and the page stays until the run has ended.
        page.send("stop").await;
        page.next("ended").await;
    });
    let (ok, out) = live.finish();
    assert!(!ok, "a stopped session exits with an error:\n{out}");
    assert!(
        out.contains("interrupted") && out.contains(&format!("handeye run --resume {session_s}")),
        "the stop says how to resume:\n{out}"
    );
    assert_eq!(accepted_records(&session), 4, "the samples are kept");
    let manifest = handeye_records::SessionFolder::open(&session)
        .and_then(|f| f.read_manifest())
        .unwrap();
    assert!(
        manifest.manual,
        "the manifest marks the session hand-guided"
    );
    assert_eq!(manifest.plan.len(), 4, "its plan is the accepted captures");

    // 2. The board file changed: both resumes refuse, naming it, before anything is opened.
    let original = std::fs::read(&board).unwrap();
    std::fs::write(&board, [original.as_slice(), b"# edited\n"].concat()).unwrap();
    for args in [
        vec!["console", "--resume", &session_s, "--addr", "127.0.0.1:0"],
        vec!["run", "--resume", &session_s, "--console", "127.0.0.1:0"],
    ] {
        let (ok, text) = run_to_end(&args, dir.path());
        assert!(!ok, "{args:?} resumed with a changed board:\n{text}");
        assert!(
            text.contains("changed since the session was recorded")
                && text.contains(&format!("target {}", board.display())),
            "{args:?}: the refusal names the board file:\n{text}"
        );
        assert_eq!(
            accepted_records(&session),
            4,
            "{args:?} touched the samples"
        );
    }
    std::fs::write(&board, &original).unwrap();

    // 3. `handeye run --resume` continues it by hand on the console: six more, finish, GOOD.
    let mut live = Live::start(
        &["run", "--resume", &session_s, "--console", "127.0.0.1:0"],
        dir.path(),
    );
    let url = live.url();
    let verdict = rt.block_on(async {
        let mut page = Page::open(&url).await;
        // The earlier captures show as captured again.
        let mut captured = std::collections::BTreeSet::new();
        while captured.len() < 4 {
            let pose = page.next("pose").await;
            if pose["state"] == "captured" {
                captured.insert(pose["plan_index"].as_u64());
            }
        }
        capture_and_finish(&mut page, 6).await
    });
    let (ok, out) = live.finish();
    assert!(ok, "the resumed session did not finish:\n{out}");
    assert!(
        out.contains("a hand-guided session: hand-guided capture on the console"),
        "run --resume went to the manual flow:\n{out}"
    );
    assert_eq!(verdict["verdict"], "GOOD", "{verdict}\n{out}");
    assert_eq!(accepted_records(&session), 10);
    let samples = handeye_records::dataset::Dataset::load(&session.join("samples.yaml")).unwrap();
    assert_eq!(
        samples.pairs.len(),
        10,
        "samples.yaml holds both runs' captures"
    );
    assert!(session.join("result.yaml").is_file());

    // 4. Replay and report work on it as on any session.
    let (ok, text) = run_to_end(&["replay", &session_s], dir.path());
    assert!(ok, "replay failed:\n{text}");
    assert!(text.contains("GOOD"), "the replay's verdict:\n{text}");
    let (ok, text) = run_to_end(&["report", &session_s], dir.path());
    assert!(ok, "report failed:\n{text}");
    assert!(
        std::fs::read_dir(&session)
            .unwrap()
            .filter_map(Result::ok)
            .any(|e| e.file_name().to_string_lossy().ends_with(".html")),
        "no HTML report in the session:\n{text}"
    );
}
