//! #40: a camera topic carrying frames far larger than the intrinsics' size (the peer's
//! `--huge-images MB`: mono8 frames 10000 px wide, once a second, written beside a healthy
//! action server). They are refused naming the image topic, the size seen and the bound —
//! before anything moves, or at the pose whose frame it is, keeping the poses before — and never
//! read as an action server that does not answer (how 100 MB frames were reported).

use std::path::Path;
use std::process::{Output, Stdio};
use std::time::Duration;

use super::cell::{cell, fails_then_resumes_with, run_cell, text, Peer};
use super::python;
use crate::util::{handeye, ros_domain, within};

/// The bound of the simulated cell's 1280x720 px camera: 8 bytes a pixel.
const BOUND: &str = "over the 7.4 MB a 1280x720 px frame takes at most";

/// Runs `config` on `domain` against a peer streaming `megabytes` MB frames from the start; the
/// log, after checking that the run failed, nothing moved and no action server was blamed.
fn refused_before_anything_moves(
    python: &std::path::PathBuf,
    domain: u16,
    config: &Path,
    megabytes: &str,
) -> String {
    let peer = Peer::start(python, domain, &["--huge-images", megabytes]);
    let out = run_cell(config, &config.with_file_name("session"));
    refused(&peer, &out)
}

/// The log of a run against `peer` streaming huge frames, after checking that the run failed,
/// nothing moved and no action server was blamed.
fn refused(peer: &Peer, out: &Output) -> String {
    let log = text(out);
    eprintln!("{log}");
    assert!(!out.status.success(), "{log}");
    assert!(
        !peer.events("huge_image").is_empty(),
        "the peer wrote no huge image:\n{log}"
    );
    assert!(log.contains("nothing has moved"), "{log}");
    assert!(
        !log.contains("action server"),
        "blamed the action server:\n{log}"
    );
    assert!(peer.events("goal").is_empty(), "a goal was sent:\n{log}");
    log
}

/// The simulated camera at a quarter of its size (320x180 px, the same field of view): its
/// bound, 0.46 MB, lies below frames that DDS delivers whole even on a loaded machine (one of
/// 8 MB, just over the full size's bound, was seen not to arrive whole within 5 s), so the size
/// seen is what is checked. The intrinsics file is `dir/quarter.yaml`; no camera_info topic
/// (the peer's says 1280x720).
fn quarter_size_cell(dir: &Path, domain: u16) -> std::path::PathBuf {
    let quarter = dir.join("quarter.yaml");
    std::fs::write(
        &quarter,
        "image_width: 320\nimage_height: 180\ncamera_name: sim-quarter\ncamera_matrix: {rows: 3, cols: 3, data: [200.0, 0.0, 160.3, 0.0, 200.0, 89.7, 0.0, 0.0, 1.0]}\ndistortion_model: plumb_bob\ndistortion_coefficients: {rows: 1, cols: 5, data: [-0.08, 0.05, 0.0004, -0.0006, 0.0]}\n",
    )
    .unwrap();
    let full = format!(
        "{}/cameras/sim-1280x720.yaml",
        crate::util::repo().join("configs").display()
    );
    cell(
        dir,
        domain,
        &[
            (full.as_str(), quarter.to_str().unwrap()),
            ("  camera_info_topic: /camera_info\n", ""),
        ],
    )
}

/// Frames just over the bound and five times over it, whole when they arrive: refused at open
/// with the topic, the size each had, what it held and the bound.
#[test]
fn frames_over_the_size_bound_are_refused_naming_the_topic_before_anything_moves() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(300), move || {
        for (domain, megabytes, held) in [
            (ros_domain(), "1", "10000x100"),
            (ros_domain(), "2.5", "10000x250"),
        ] {
            let dir = tempfile::tempdir().unwrap();
            let config = quarter_size_cell(dir.path(), domain);
            let log = refused_before_anything_moves(&python, domain, &config, megabytes);
            let said = format!(
                "the images on /image_raw are {:.1} MB ({held} mono8), over the 0.5 MB a 320x180 px frame takes at most (8 bytes a pixel, the widest encoding): refused, nothing has moved",
                megabytes.parse::<f64>().unwrap()
            );
            assert!(log.contains(&said), "expected {said:?} in:\n{log}");
        }
    });
}

/// `run_cell` (as `cell::run`) and the peak resident memory of the handeye process in bytes: its
/// `VmHWM` (the high-water mark so far) read from /proc every 20 ms while it runs.
fn run_cell_with_peak_memory(config: &Path, out: &Path) -> (Output, u64) {
    use std::io::Read as _;
    let mut child = handeye()
        .args(["run", "--yes", "--config"])
        .arg(config)
        .arg("-o")
        .arg(out)
        .env("HANDEYE_LOG", "warn,rustdds=off")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Drained as it runs: a full pipe would stall the run.
    let drain = |mut pipe: Box<dyn std::io::Read + Send>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            let _ = pipe.read_to_end(&mut bytes);
            bytes
        })
    };
    let stdout = drain(Box::new(child.stdout.take().unwrap()));
    let stderr = drain(Box::new(child.stderr.take().unwrap()));
    let status_file = format!("/proc/{}/status", child.id());
    let mut peak_kb = 0u64;
    let status = loop {
        if let Ok(text) = std::fs::read_to_string(&status_file) {
            let hwm = text
                .lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok());
            peak_kb = peak_kb.max(hwm.unwrap_or(0));
        }
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let output = Output {
        status,
        stdout: stdout.join().unwrap(),
        stderr: stderr.join().unwrap(),
    };
    (output, peak_kb * 1024)
}

/// 100 MB frames: best effort over DDS, such a frame may never come whole (its fragments are
/// lost), and only a whole message says its size. Either way the image topic is named as
/// what is wrong, before anything moves: refused with its size when one came whole, else as
/// a topic whose writer is there but whose frames do not come through, with the bound. The
/// camera waits 15 s for a frame: handeye's memory stays under 700 MB all the while (a whole
/// frame in DDS's cache and its decoded copy, and 2 s of half-reassembled ones; RustDDS kept
/// every half-reassembled 100 MB frame for 10 s, and 64 whole ones: 1.4 GB over 15 s before).
#[test]
#[ignore = "floods loopback DDS with 100 MB frames: beside the other live tests on a 2-core machine their peers miss their deadlines; run alone with --ignored"]
fn hundred_megabyte_frames_are_named_on_the_image_topic_not_the_action_server() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(200), move || {
        let dir = tempfile::tempdir().unwrap();
        let domain = ros_domain();
        let config = cell(
            dir.path(),
            domain,
            &[("frame_timeout_s: 5", "frame_timeout_s: 15")],
        );
        let peer = Peer::start(&python, domain, &["--huge-images", "100"]);
        let (out, peak) = run_cell_with_peak_memory(&config, &config.with_file_name("session"));
        let log = refused(&peer, &out);
        assert!(
            peak < 700_000_000,
            "handeye's peak resident memory was {:.0} MB:\n{log}",
            peak as f64 / 1e6
        );
        eprintln!("peak resident memory {:.0} MB", peak as f64 / 1e6);
        let refused = format!("the images on /image_raw are 100.0 MB (10000x10000 mono8), {BOUND}");
        let not_whole =
            "no whole image on /image_raw within 15.0 s although a writer of it is on the graph";
        assert!(
            log.contains(&refused) || (log.contains(not_whole) && log.contains("far over 7.4 MB")),
            "{log}"
        );
    });
}

/// Frames that turn huge mid-run (the camera switched once goal 4 has ended, the arm standing):
/// the run stops at that pose naming the image topic — refused with the size seen when a frame
/// came whole, else as frames grown too large to come through whole, with the bound (12 MB
/// frames over loopback came whole in two runs of three) — the poses before are kept, and a
/// resume against a healthy camera completes. The action
/// server gets 30 s to answer (a run beside a parallel build on the 2-core machine once saw the
/// peer's first goal answered after the shipped 10 s, which is not what this tests) and a frame
/// 15 s to come (the peer writes one a second; best effort loses some of them whole).
#[test]
#[ignore = "floods loopback DDS with 12 MB frames from goal 4 on: beside the other live tests on a 2-core machine their peers miss their deadlines; run alone with --ignored"]
fn frames_turning_huge_mid_run_are_refused_at_that_pose_and_resume_completes() {
    within(Duration::from_secs(400), || {
        fails_then_resumes_with(
            ros_domain(),
            &["--huge-images", "12", "--huge-images-from", "4"],
            &[
                ("connect_timeout_s: 10}", "connect_timeout_s: 30}"),
                // 15 chances for a 12 MB frame to come whole over best effort.
                ("frame_timeout_s: 5", "frame_timeout_s: 15"),
            ],
            &[
                "the images on /image_raw are 12.0 MB (10000x1200 mono8), over the 7.4 MB",
                "its frames grew too large to come through whole (far over 7.4 MB, the most a 1280x720 px frame takes)",
            ],
        )
    });
}
