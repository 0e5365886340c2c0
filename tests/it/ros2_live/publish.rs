//! `handeye publish`: the independent peer, joining late, reads the calibration back from the
//! latched `/tf_static` to 1e-9.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};

use handeye_formats::export::named_transforms;
use handeye_formats::FrameIds;
use handeye_records::result::ResultFile;

use super::{peer, python};
use crate::util::{handeye, repo, ros_domain, within};

fn result_file() -> std::path::PathBuf {
    repo().join("tests/fuzz-corpus/result/result.yaml")
}

#[test]
fn a_late_joiner_reads_the_published_calibration_from_tf_static() {
    let Some(python) = python() else { return };
    let domain = ros_domain();
    within(std::time::Duration::from_secs(120), move || {
        late_joiner_reads_back(domain, peer(&python, domain));
    });
}

/// `handeye publish` on `domain`; once the message is out, `peer` (a peer's command line up to
/// its subcommand) joins late with `tf-static` and must read the calibration back to 1e-9.
pub(super) fn late_joiner_reads_back(domain: u16, peer: Command) {
    let publisher = start_publisher(domain);
    assert_read_back(&read_while_published(peer, publisher, 2, 30));
}

/// What `peer` (a peer's command line up to its subcommand) reads of `/tf_static` as a late
/// joiner (`tf-static`, waiting up to `timeout_s` for `expect` transforms) while `publisher`
/// runs; the publisher is stopped after. The peer's JSON.
fn read_while_published(
    mut peer: Command,
    mut publisher: Child,
    expect: usize,
    timeout_s: u32,
) -> Vec<u8> {
    let out = peer
        .args(["tf-static", "--expect", &expect.to_string()])
        .args(["--timeout", &timeout_s.to_string()])
        .output()
        .expect("the peer runs");
    let _ = publisher.kill();
    let _ = publisher.wait();
    assert!(
        out.status.success(),
        "peer: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out.stdout
}

/// A peer's JSON read of `/tf_static` (`{"transforms": [{parent, child, translation,
/// quaternion_xyzw}]}`) against `result_file()`'s two transforms, to 1e-9.
fn assert_read_back(peer_stdout: &[u8]) {
    let read: serde_json::Value = serde_json::from_slice(peer_stdout).expect("peer JSON");
    let ids = FrameIds {
        base: "base_link".into(),
        flange: "tool0".into(),
        camera: "camera_optical_frame".into(),
        target: "calibration_target".into(),
        poses_in: "base".into(),
    };
    let mounts = ResultFile::load_mounts(&result_file()).unwrap();
    let want = named_transforms(&mounts, &ids);
    let got = read["transforms"].as_array().unwrap();
    assert_eq!(got.len(), 2);
    for w in &want {
        let g = got
            .iter()
            .find(|g| g["child"] == w.child.as_str())
            .unwrap_or_else(|| panic!("{} not read back: {read}", w.child));
        assert_eq!(g["parent"], w.parent.as_str());
        let t = w.parent_from_child.translation.vector;
        let q = w.parent_from_child.rotation.quaternion();
        let f = |v: &serde_json::Value, i: usize| v.as_array().unwrap()[i].as_f64().unwrap();
        for i in 0..3 {
            assert!(
                (f(&g["translation"], i) - t[i]).abs() < 1e-9,
                "{}: {g}",
                w.key
            );
        }
        let wq = [q.i, q.j, q.k, q.w];
        let same = (0..4).all(|i| (f(&g["quaternion_xyzw"], i) - wq[i]).abs() < 1e-9);
        let flipped = (0..4).all(|i| (f(&g["quaternion_xyzw"], i) + wq[i]).abs() < 1e-9);
        assert!(same || flipped, "{}: {g} vs {wq:?}", w.key);
    }
}

/// `handeye publish` of `result_file()` on `domain` (loopback), once it says the message is out.
fn start_publisher(domain: u16) -> Child {
    let (publisher, printed) = publish_until_latched(
        &result_file(),
        domain,
        &["--base-frame", "base_link", "--duration", "60"],
    );
    assert_eq!(printed.len(), 2, "{printed:?}");
    publisher
}

/// `handeye publish` of `result` on `domain` (loopback) with `extra` arguments, started only
/// once it says the message is out (a peer read then is a late joiner); the lines it printed
/// until then. The rest of its output is drained, so the pipe stays open while it runs.
fn publish_until_latched(
    result: &std::path::Path,
    domain: u16,
    extra: &[&str],
) -> (Child, Vec<String>) {
    let mut publisher = handeye()
        .arg("publish")
        .arg(result)
        .args([
            "--domain-id",
            &domain.to_string(),
            "--interface",
            "127.0.0.1",
        ])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("handeye publish");
    let mut lines = BufReader::new(publisher.stdout.take().unwrap()).lines();
    let printed: Vec<String> = lines
        .by_ref()
        .map_while(Result::ok)
        .take_while(|l| !l.starts_with("latched"))
        .collect();
    std::thread::spawn(move || lines.for_each(drop));
    (publisher, printed)
}

/// A several-camera result (#39) is published as one tree: every camera's mount and both boards
/// on /tf_static, each frame with one parent, read back by the independent peer to 1e-9 against
/// the result file; the camera-to-camera transforms (which would give a camera a second parent)
/// are not.
#[test]
fn a_several_camera_result_is_published_as_one_tree() {
    let Some(python) = python() else { return };
    let domain = ros_domain();
    let (_, session, _) = crate::cameras::shipped_run();
    let result_path = session.join("result.yaml");
    let result = crate::cameras::read_result(session);
    within(std::time::Duration::from_secs(300), move || {
        let (publisher, printed) =
            publish_until_latched(&result_path, domain, &["--duration", "90"]);
        // Three mounts and two boards.
        let mounts = result.cameras.iter().filter(|c| c.joint.is_some()).count();
        let expected = mounts + result.boards.len();
        assert_eq!((mounts, expected), (3, 5), "{printed:?}");
        let out = read_while_published(peer(&python, domain), publisher, expected, 60);
        let read: serde_json::Value = serde_json::from_slice(&out).expect("peer JSON");
        let got = read["transforms"].as_array().unwrap();
        assert_eq!(got.len(), expected, "{read}");
        let f = |v: &serde_json::Value, i: usize| v.as_array().unwrap()[i].as_f64().unwrap();
        for t in result
            .cameras
            .iter()
            .filter_map(|c| c.joint.as_ref())
            .chain(&result.boards)
        {
            // A camera `cam_<name>` is published as `camera_optical_frame_<name>`, a board by
            // its own name: matched by the translation, which names it unambiguously here.
            let want = t.pose.translation.vector;
            let g = got
                .iter()
                .find(|g| (0..3).all(|i| (f(&g["translation"], i) - want[i]).abs() < 1e-9))
                .unwrap_or_else(|| panic!("{} not read back to 1e-9: {read}", t.name));
            let q = t.pose.rotation.quaternion();
            let wq = [q.i, q.j, q.k, q.w];
            let same = (0..4).all(|i| (f(&g["quaternion_xyzw"], i) - wq[i]).abs() < 1e-9);
            let flipped = (0..4).all(|i| (f(&g["quaternion_xyzw"], i) + wq[i]).abs() < 1e-9);
            assert!(same || flipped, "{}: {g}", t.name);
        }
        // One parent per frame.
        for g in got {
            let parents = got.iter().filter(|o| o["child"] == g["child"]).count();
            assert_eq!(parents, 1, "{} has {parents} parents: {read}", g["child"]);
        }
    });
}
