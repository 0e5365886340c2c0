//! Importing a 60 s ROS 2 bag with 30 fps 1280x720 `mono8` images (1.7 GB of pixels, MCAP
//! without chunk compression, as rosbag2 writes by default) and 125 Hz TF: the whole
//! `handeye import bag` command — reading, TF chaining, stationary detection and sharpness over
//! every standing frame, then the recorded-cell session (detection of the 20 chosen frames) and
//! the solve. Target: ≤ 10 s.
//!
//! The bag is written here with the `mcap` crate and the tree's one CDR codec
//! (`handeye_ros2::cdr`) into a temporary folder (the integration tests
//! use bags from the independent `rosbags` writer; this only needs the size). Frames while the arm
//! moves are a blank image: they are rejected as moving before being decoded, as real ones would
//! be.
//!
//! Printed once before criterion's rounds: the whole command on all cores and pinned to one
//! (`taskset -c 0`), each with its CPU time and peak RSS (GNU time), and the same bag read by the
//! pure-Python `rosbags` (every message deserialised; `benches/read_bag_rosbags.py`). Issue #29's
//! floors: peak RSS ≤ 300 MB, CPU ≤ 2× the Python reader's. `BAG_SECONDS=600` makes it a
//! 10-minute bag (16.6 GB on disk) measured once, without criterion's rounds.
//!
//! `cargo bench --bench bag -- --warm-up-time 1 --measurement-time 3`

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::Path;
use std::process::Command;

use criterion::Criterion;
use nalgebra::{Point3, Vector3};
use rand::SeedableRng;

use handeye_camera::render::{render_with_rays, PixelRays, RenderOptions};
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::{pose_from_rotvec, Pose};
use handeye_ros2::msg::{CameraInfo, Header, Image, TfMessage, Time, Transform, TransformStamped};
use handeye_ros2_bag::tf::interpolate;
use handeye_session::plan::lookat::LookAt;
use handeye_vision::{Board, Target};

#[path = "../tests/util/mod.rs"]
mod util;

/// A ROS 2 header stamped `ns` (nanoseconds since the epoch) in `frame`.
fn header(ns: i64, frame: &str) -> Header {
    Header {
        stamp: Time {
            sec: (ns / 1_000_000_000) as i32,
            nanosec: (ns % 1_000_000_000) as u32,
        },
        frame_id: frame.into(),
    }
}

/// A message in its serialised form, through the one CDR codec of the tree (`handeye_ros2::cdr`).
fn cdr<T: serde::Serialize>(message: &T) -> Vec<u8> {
    handeye_ros2::cdr::encode(message).expect("a ROS 2 message serialises")
}

/// A message of the bag to write: its bytes, or an image (stamp, view shown or moving).
enum Data {
    Bytes(Vec<u8>),
    Image(i64, Option<usize>),
}

/// The `sensor_msgs/msg/CameraInfo` message of `camera`, stamped `start`.
fn camera_info_message(camera: &CameraModel, start: i64) -> Vec<u8> {
    let d = camera.distortion_coefficients();
    cdr(&CameraInfo {
        header: header(start, "camera"),
        height: camera.height,
        width: camera.width,
        distortion_model: "plumb_bob".into(),
        d: (0..5).map(|i| d.get(i).copied().unwrap_or(0.0)).collect(),
        k: [
            camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0,
        ],
        ..CameraInfo::default()
    })
}

/// rosbag2's metadata.yaml of the bag's `events` on `topics` (name, type, channel id).
fn write_metadata(bag: &Path, events: &[(i64, u16, Data)], topics: [(&str, &str, u16); 3]) {
    // rosbag2's metadata.yaml, complete enough for `rosbags` (the Python reader compared with).
    let counts = topics.map(|(topic, ty, id)| {
        let count = events.iter().filter(|e| e.1 == id).count();
        format!("    - topic_metadata: {{name: {topic}, type: {ty}, serialization_format: cdr, offered_qos_profiles: ''}}\n      message_count: {count}\n")
    });
    let (first, last) = (events[0].0, events[events.len() - 1].0);
    std::fs::write(
        bag.join("metadata.yaml"),
        format!(
            "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: mcap\n  relative_file_paths: [bag_0.mcap]\n  duration: {{nanoseconds: {}}}\n  starting_time: {{nanoseconds_since_epoch: {first}}}\n  message_count: {}\n  topics_with_message_count:\n{}  compression_format: ''\n  compression_mode: ''\n  files:\n    - path: bag_0.mcap\n      starting_time: {{nanoseconds_since_epoch: {first}}}\n      duration: {{nanoseconds: {}}}\n      message_count: {}\n",
            last - first,
            events.len(),
            counts.concat(),
            last - first,
            events.len()
        ),
    )
    .unwrap();
}

/// The stops of a bag of `seconds` with `stops` stops (0: the default, 20 views of 1.55 s with
/// 1.5 s of travel between them, looped): how many distinct views, and how long the arm stands at
/// each and travels between two.
fn stop_layout(seconds: f64, stops: usize) -> (usize, f64, f64) {
    if stops == 0 {
        return (20, 1.55, 1.5);
    }
    // Each stop 60 % standing, 40 % travel; a stop must outlast the 0.2 s still window.
    let period = seconds / stops as f64;
    assert!(
        period * 0.6 > 0.25,
        "{stops} stops in {seconds} s leave {:.2} s per stop: too short to stand still",
        period
    );
    (stops, period * 0.6, period * 0.4)
}

fn write_bag(dir: &Path, seconds: f64, stops: usize) -> std::path::PathBuf {
    let repo = util::repo();
    let board = Board::load(&repo.join("configs/targets/aprilgrid-6x6.yaml")).unwrap();
    let camera = CameraModel::load(&repo.join("configs/cameras/sim-1280x720.yaml")).unwrap();
    let flange_from_camera = pose_from_rotvec(
        Vector3::new(0.0312, -0.0694, 0.0447),
        Vector3::new(0.021, -0.016, 1.561),
    );
    let base_from_target = pose_from_rotvec(
        Vector3::new(0.5034, -0.1467, 0.0021),
        Vector3::new(0.012, -0.018, 0.297),
    );
    let centre = Point3::new(0.145, 0.145, 0.0);
    let (n, stay, travel) = stop_layout(seconds, stops);
    let views: Vec<Pose> = (0..n)
        .map(|i| {
            let look = LookAt {
                distance: 0.6 + 0.05 * ((i % 3) as f64),
                azimuth_deg: 360.0 * i as f64 / n as f64,
                elevation_deg: 62.0 + 8.0 * ((i % 4) as f64),
                roll_deg: -20.0 + 13.0 * ((i % 4) as f64),
                board_in_image_deg: [0.0, 0.0],
            };
            base_from_target * look.target_from_camera(&centre) * flange_from_camera.inverse()
        })
        .collect();
    let rays = PixelRays::new(&camera);
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let frames: Vec<Vec<u8>> = views
        .iter()
        .map(|flange| {
            let camera_from_target = (flange * flange_from_camera).inverse() * base_from_target;
            render_with_rays(
                &board,
                &camera,
                &rays,
                &camera_from_target,
                &RenderOptions::default(),
                &mut rng,
            )
            .into_raw()
        })
        .collect();
    let blank = vec![110u8; (camera.width * camera.height) as usize];
    // The views in a loop (a bag longer than one pass, `BAG_SECONDS`, visits them again).
    let at = |t: f64| -> (Pose, Option<usize>) {
        let period = stay + travel;
        let k = (t / period).floor() as usize;
        let within = t - k as f64 * period;
        if within <= stay {
            return (views[k % n], Some(k % n));
        }
        let s = (within - stay) / travel;
        (
            interpolate(&views[k % n], &views[(k + 1) % n], s * s * (3.0 - 2.0 * s)),
            None,
        )
    };

    let bag = dir.join("bag");
    std::fs::create_dir_all(&bag).unwrap();

    let file = std::fs::File::create(bag.join("bag_0.mcap")).unwrap();
    let mut w = mcap::WriteOptions::new()
        .compression(None)
        .profile("ros2")
        .create(BufWriter::new(file))
        .unwrap();
    let mut channel = |topic: &str, ty: &str| {
        let schema = w.add_schema(ty, "ros2msg", b"").unwrap();
        w.add_channel(schema, topic, "cdr", &BTreeMap::new())
            .unwrap()
    };
    let tf = channel("/tf", "tf2_msgs/msg/TFMessage");
    let image = channel("/camera/image_raw", "sensor_msgs/msg/Image");
    let info = channel("/camera/camera_info", "sensor_msgs/msg/CameraInfo");
    let start: i64 = 1_700_000_000_000_000_000;
    // The image messages are made as they are written (a 10-minute bag does not fit in memory).
    let mut events: Vec<(i64, u16, Data)> = Vec::new();
    let duration = seconds;
    for k in 0..=(duration * 125.0) as i64 {
        let t = k as f64 / 125.0;
        let stamp = start + (t * 1e9).round() as i64;
        let message = TfMessage {
            transforms: vec![TransformStamped {
                header: header(stamp, "base"),
                child_frame_id: "tool0".into(),
                transform: Transform::from_pose(&at(t).0),
            }],
        };
        events.push((stamp, tf, Data::Bytes(cdr(&message))));
    }
    events.push((
        start,
        info,
        Data::Bytes(camera_info_message(&camera, start)),
    ));
    for i in 0..(duration * 30.0) as i64 {
        let t = i as f64 / 30.0;
        let stamp = start + (t * 1e9).round() as i64;
        events.push((stamp + 2_000_000, image, Data::Image(stamp, at(t).1)));
    }
    let image_message = |stamp: i64, view: Option<usize>| {
        let pixels = match view {
            Some(k) => &frames[k],
            None => &blank,
        };
        cdr(&Image {
            header: header(stamp, "camera"),
            height: camera.height,
            width: camera.width,
            encoding: "mono8".into(),
            is_bigendian: 0,
            step: camera.width,
            data: pixels.clone(),
        })
    };
    events.sort_by_key(|e| e.0);
    write_metadata(
        &bag,
        &events,
        [
            ("/tf", "tf2_msgs/msg/TFMessage", tf),
            ("/camera/image_raw", "sensor_msgs/msg/Image", image),
            ("/camera/camera_info", "sensor_msgs/msg/CameraInfo", info),
        ],
    );
    for (seq, (time, channel_id, data)) in events.into_iter().enumerate() {
        let data = match data {
            Data::Bytes(bytes) => bytes,
            Data::Image(stamp, view) => image_message(stamp, view),
        };
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id,
                sequence: seq as u32,
                log_time: time as u64,
                publish_time: time as u64,
            },
            &data,
        )
        .unwrap();
    }
    w.finish().unwrap();
    bag
}

/// `cmd` under GNU time (when it is there), its output and the time line.
fn timed(cmd: Command, label: &str) -> std::process::Output {
    let mut timed = if Path::new("/usr/bin/time").exists() {
        let mut c = Command::new("/usr/bin/time");
        c.args([
            "-f",
            &format!("{label}: %e s wall, %U s user, %S s system, %M kB peak RSS"),
        ])
        .arg(cmd.get_program())
        .args(cmd.get_args());
        c
    } else {
        cmd
    };
    let o = timed.output().unwrap();
    println!(
        "{label}:\n{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

fn import_command(bag: &Path, board: &Path, out: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_handeye"));
    c.args(["import", "bag"])
        .arg(bag)
        .args([
            "--base",
            "base",
            "--flange",
            "tool0",
            "--image",
            "/camera/image_raw",
        ])
        .args(["--camera-info", "/camera/camera_info", "--board"])
        .arg(board)
        .arg("-o")
        .arg(out);
    c
}

fn main() {
    // `BAG_SECONDS=600` writes a 10-minute bag (16.6 GB: needs the disk) and measures it once.
    let seconds: f64 = std::env::var("BAG_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(60.0);
    // `BAG_STOPS=200`: that many stops, each at its own view (default: 20 views, 3.05 s a stop).
    let stops: usize = std::env::var("BAG_STOPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let dir = tempfile::tempdir().unwrap();
    // `HANDEYE_BENCH_BAG_DIR`: write the bag there and keep it (to profile the import by hand);
    // with `HANDEYE_BENCH_WRITE_ONLY=1` nothing else is done (the bags of the docs' table).
    let bag = match std::env::var_os("HANDEYE_BENCH_BAG_DIR") {
        Some(keep) => write_bag(Path::new(&keep), seconds, stops),
        None => write_bag(dir.path(), seconds, stops),
    };
    if std::env::var_os("HANDEYE_BENCH_WRITE_ONLY").is_some() {
        println!("bag written: {}", bag.display());
        return;
    }
    let size: u64 = std::fs::read_dir(&bag)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.metadata().map(|m| m.len()).unwrap_or(0))
        .sum();
    println!("bag: {} ({:.2} GB)", bag.display(), size as f64 / 1e9);
    let board = util::repo().join("configs/targets/aprilgrid-6x6.yaml");
    // The split, once: the library's part (read, TF, selection, decoding) and the whole command.
    let options = handeye_ros2_bag::BagOptions {
        base_frame: "base".into(),
        flange_frame: "tool0".into(),
        image_topic: "/camera/image_raw".into(),
        camera_info_topic: Some("/camera/camera_info".into()),
        tf_topics: vec!["/tf".into(), "/tf_static".into()],
        tf_static_topics: vec!["/tf_static".into()],
        select: Default::default(),
        setup: handeye_core::setup::Setup::EyeInHand,
        board: Target::load(&board).unwrap(),
        detector: Default::default(),
    };
    let started = std::time::Instant::now();
    let imported = handeye_ros2_bag::import_bag(&bag, &options).unwrap();
    println!(
        "library import_bag: {:.2} s ({} samples of {} images)",
        started.elapsed().as_secs_f64(),
        imported.samples.len(),
        imported.images
    );
    drop(imported);
    // The whole command on both cores, then pinned to one (`taskset`): the detection of the
    // chosen frames runs on every core.
    timed(
        import_command(&bag, &board, &dir.path().join("session-once")),
        "whole command, all cores",
    );
    if Path::new("/usr/bin/taskset").exists() {
        let mut one = Command::new("/usr/bin/taskset");
        let inner = import_command(&bag, &board, &dir.path().join("session-one-core"));
        one.args(["-c", "0"])
            .arg(inner.get_program())
            .args(inner.get_args());
        timed(one, "whole command, one core (taskset -c 0)");
    }
    // The same bag read by the pure-Python `rosbags` (every message deserialised), in the venv
    // tests/it/bag_import.rs uses (or `HANDEYE_BAG_PYTHON`): what a ROS user's own script costs.
    let python = std::env::var_os("HANDEYE_BAG_PYTHON")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(&std::env::var("CARGO_TARGET_DIR").unwrap_or_else(|_| "target".into()))
                .join("tmp/bag-venv/bin/python")
        });
    if python.is_file() {
        let mut c = Command::new(&python);
        c.arg(util::repo().join("benches/read_bag_rosbags.py"))
            .arg(&bag);
        timed(c, "rosbags (Python) reading every message");
    } else {
        println!(
            "rosbags comparison skipped: no {} (scripts/test.sh makes it)",
            python.display()
        );
    }
    if seconds > 60.0 || stops != 0 {
        return;
    }
    let mut run = 0;
    let mut criterion = Criterion::default().configure_from_args().sample_size(10);
    criterion.bench_function(
        "import bag: 60 s, 30 fps 1280x720 mono8, to a solved session",
        |b| {
            b.iter(|| {
                run += 1;
                let out = dir.path().join(format!("session-{run}"));
                let o = import_command(&bag, &board, &out).output().unwrap();
                assert!(
                    o.status.success(),
                    "{}{}",
                    String::from_utf8_lossy(&o.stdout),
                    String::from_utf8_lossy(&o.stderr)
                );
                std::fs::remove_dir_all(&out).unwrap();
            })
        },
    );
    criterion.final_summary();
}
