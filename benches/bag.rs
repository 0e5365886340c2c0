//! Importing a ROS 2 bag with 30 fps 1280x720 `mono8` images (a 60 s bag is 1.7 GB of pixels,
//! MCAP without chunk compression, as rosbag2 writes by default) and 125 Hz TF: the whole
//! `handeye import bag` command — reading, TF chaining, stationary detection and sharpness over
//! every standing frame, the chosen frames written, then the recorded-cell session (detection of
//! the chosen frames), the solve and the report. Target: ≤ 10 s for 60 s.
//!
//! The bag is written here with the `mcap` crate and the tree's one CDR codec
//! (`handeye_ros2::cdr`) into a temporary folder (the integration tests
//! use bags from the independent `rosbags` writer; this only needs the size). Frames while the arm
//! moves are a blank image: they are rejected as moving before being decoded, as real ones would
//! be.
//!
//! Printed once before criterion's rounds: the whole command under GNU time (`-v`: CPU user +
//! system, peak RSS) beside the same bag read by the pure-Python `rosbags` (every message
//! deserialised; `benches/read_bag_rosbags.py`) in the same round, with the ratio of their CPU
//! and the load average, then the command pinned to one core (`taskset -c 0`). Issue #43's
//! goals: peak RSS ≤ 150 MB, CPU ≤ 1.5× the Python reader's.
//!
//! * `BAG_SECONDS=15` (default 60) and `BAG_STOPS=200` (default: 20 views of 1.55 s with 1.5 s
//!   of travel, looped; with `BAG_STOPS` each stop its own view, 60 % of a stop standing): other
//!   bags, measured once without criterion's rounds. 200 stops need 120 s or more (a stop must
//!   outlast the 0.2 s still window).
//! * `HANDEYE_BENCH_BAG_DIR=DIR HANDEYE_BENCH_WRITE_ONLY=1`: write the bag into DIR and stop;
//!   `HANDEYE_BENCH_BAG=DIR/bag`: measure that bag instead of writing one.
//! * `HANDEYE_BENCH_BEFORE=PATH`: also measure another `handeye` build (before a change), in the
//!   same rounds; `HANDEYE_BENCH_ROUNDS=N` rounds (default 1), interleaved.
//! * `HANDEYE_BENCH_LOAD=N`: the comparison under a fixed load, N threads of this process
//!   spinning on the CPU while each command runs (the load is the same for the reader and the
//!   import, and is not counted in their CPU): how the ratio holds on a machine shared with
//!   other work, where a quiet machine's figures say little.
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
use handeye_plan::lookat::LookAt;
use handeye_ros2::msg::{CameraInfo, Header, Image, TfMessage, Time, Transform, TransformStamped};
use handeye_ros2_bag::tf::interpolate;
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
    let rays = PixelRays::new(&camera).expect("memory for the lens's rays");
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
            .expect("memory for a frame")
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

/// What GNU time (`/usr/bin/time -v`) measured of one command, and the load average (1 min)
/// just before it started.
struct Measured {
    wall_s: f64,
    user_s: f64,
    system_s: f64,
    peak_rss_kb: u64,
    load: f64,
}

impl Measured {
    fn cpu_s(&self) -> f64 {
        self.user_s + self.system_s
    }
}

/// The 1-minute load average (`/proc/loadavg`), or NaN.
fn load_average() -> f64 {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or(f64::NAN)
}

/// The value of GNU time's `-v` line `name: value`.
fn time_field(report: &str, name: &str) -> Option<String> {
    report.lines().find_map(|line| {
        let (key, value) = line.trim().rsplit_once(": ")?;
        (key == name).then(|| value.trim().to_string())
    })
}

/// `h:mm:ss` or `m:ss.ss` as seconds.
fn clock_seconds(text: &str) -> f64 {
    text.split(':').fold(0.0, |total, part| {
        total * 60.0 + part.parse::<f64>().unwrap_or(f64::NAN)
    })
}

/// `cmd` under GNU time `-v` (when it is there): prints its output and one line of figures;
/// `None` without GNU time or when it failed.
fn timed(cmd: Command, label: &str) -> Option<Measured> {
    let load = load_average();
    if !Path::new("/usr/bin/time").exists() {
        let mut cmd = cmd;
        let o = cmd.output().unwrap();
        println!(
            "{label}: (no /usr/bin/time)\n{}",
            String::from_utf8_lossy(&o.stdout)
        );
        return None;
    }
    let mut c = Command::new("/usr/bin/time");
    c.arg("-v").arg(cmd.get_program()).args(cmd.get_args());
    let o = c.output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    let field = |name: &str| time_field(&stderr, name);
    let measured = Measured {
        wall_s: clock_seconds(&field("Elapsed (wall clock) time (h:mm:ss or m:ss)")?),
        user_s: field("User time (seconds)")?.parse().ok()?,
        system_s: field("System time (seconds)")?.parse().ok()?,
        peak_rss_kb: field("Maximum resident set size (kbytes)")?.parse().ok()?,
        load,
    };
    let last = |text: &str, n: usize| -> String {
        let lines: Vec<&str> = text.lines().collect();
        lines[lines.len().saturating_sub(n)..].join("\n")
    };
    println!(
        "{label}: {:.2} s wall, {:.2} s user + {:.2} s system = {:.2} s CPU, {:.0} MB peak RSS (load average {:.2}){}\n{}",
        measured.wall_s,
        measured.user_s,
        measured.system_s,
        measured.cpu_s(),
        measured.peak_rss_kb as f64 / 1024.0,
        load,
        if o.status.success() { "" } else { " FAILED" },
        last(&String::from_utf8_lossy(&o.stdout), 3)
    );
    o.status.success().then_some(measured)
}

fn import_command(bag: &Path, board: &Path, out: &Path) -> Command {
    import_command_of(Path::new(env!("CARGO_BIN_EXE_handeye")), bag, board, out)
}

/// `import bag` of `handeye` (this tree's binary, or another build to compare with).
fn import_command_of(handeye: &Path, bag: &Path, board: &Path, out: &Path) -> Command {
    let mut c = Command::new(handeye);
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

/// The Python interpreter of the venv with `rosbags` (`HANDEYE_BAG_PYTHON`, else the one
/// scripts/test.sh makes under the target folder).
fn rosbags_python() -> std::path::PathBuf {
    std::env::var_os("HANDEYE_BAG_PYTHON")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(&std::env::var("CARGO_TARGET_DIR").unwrap_or_else(|_| "target".into()))
                .join("tmp/bag-venv/bin/python")
        })
}

/// The bag to measure: `HANDEYE_BENCH_BAG` (one written before), else one written now into
/// `HANDEYE_BENCH_BAG_DIR` (kept) or `dir`.
fn the_bag(dir: &Path, seconds: f64, stops: usize) -> std::path::PathBuf {
    if let Some(bag) = std::env::var_os("HANDEYE_BENCH_BAG") {
        return bag.into();
    }
    match std::env::var_os("HANDEYE_BENCH_BAG_DIR") {
        Some(keep) => write_bag(Path::new(&keep), seconds, stops),
        None => write_bag(dir, seconds, stops),
    }
}

/// `threads` threads spinning on the CPU until dropped: a fixed load beside the commands
/// measured (`HANDEYE_BENCH_LOAD`).
struct FixedLoad {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    threads: Vec<std::thread::JoinHandle<()>>,
}

impl FixedLoad {
    fn start(threads: usize) -> FixedLoad {
        use std::sync::atomic::{AtomicBool, Ordering};
        let stop = std::sync::Arc::new(AtomicBool::new(false));
        if threads > 0 {
            println!("under a fixed load: {threads} thread(s) spinning beside each command");
        }
        let threads = (0..threads)
            .map(|_| {
                let stop = stop.clone();
                std::thread::spawn(move || {
                    let mut x = 0u64;
                    while !stop.load(Ordering::Relaxed) {
                        x = std::hint::black_box(x.wrapping_mul(6_364_136_223_846_793_005) + 1);
                    }
                })
            })
            .collect();
        FixedLoad { stop, threads }
    }
}

impl Drop for FixedLoad {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

/// The whole command, and `HANDEYE_BENCH_BEFORE`'s (an earlier build) when given, each beside
/// the `rosbags` reader, `HANDEYE_BENCH_ROUNDS` times (default 1) interleaved: peak RSS, CPU
/// (user + system) and the ratio to the reader's CPU in the same round, with the load average.
fn compare(bag: &Path, board: &Path, dir: &Path) {
    let python = rosbags_python();
    let before = std::env::var_os("HANDEYE_BENCH_BEFORE").map(std::path::PathBuf::from);
    let rounds: usize = std::env::var("HANDEYE_BENCH_ROUNDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    // A fixed background load for the whole comparison, when asked for.
    let load_threads: usize = std::env::var("HANDEYE_BENCH_LOAD")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let _load = FixedLoad::start(load_threads);
    let mut binaries = vec![(
        "this build",
        std::path::PathBuf::from(env!("CARGO_BIN_EXE_handeye")),
    )];
    if let Some(before) = before {
        binaries.insert(0, ("before", before));
    }
    for round in 0..rounds {
        let reader = if python.is_file() {
            let mut c = Command::new(&python);
            c.arg(util::repo().join("benches/read_bag_rosbags.py"))
                .arg(bag);
            timed(c, "rosbags (Python) reading every message")
        } else {
            println!(
                "rosbags comparison skipped: no {} (scripts/test.sh makes it)",
                python.display()
            );
            None
        };
        for (name, handeye) in &binaries {
            let out = dir.join(format!("session-{name}-{round}").replace(' ', "-"));
            let label = format!("import bag, {name}, all cores");
            let Some(m) = timed(import_command_of(handeye, bag, board, &out), &label) else {
                continue;
            };
            if let Some(r) = &reader {
                println!(
                    "  {name}: {:.0} MB peak RSS, CPU {:.2} s = {:.2}x the reader's {:.2} s (load average {:.2} / {:.2})",
                    m.peak_rss_kb as f64 / 1024.0,
                    m.cpu_s(),
                    m.cpu_s() / r.cpu_s(),
                    r.cpu_s(),
                    m.load,
                    r.load
                );
            }
            let _ = std::fs::remove_dir_all(&out);
        }
    }
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
    // With `HANDEYE_BENCH_WRITE_ONLY=1` the bag is written (into `HANDEYE_BENCH_BAG_DIR`) and
    // nothing else is done (the bags of the docs' table).
    let bag = the_bag(dir.path(), seconds, stops);
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
        "library import_bag: {:.2} s ({} samples of {} images, {} decoded, at most {} decoded frames alive at once)",
        started.elapsed().as_secs_f64(),
        imported.samples.len(),
        imported.images,
        imported.decoded,
        imported.frames_held_at_once
    );
    drop(imported);
    compare(&bag, &board, dir.path());
    // Pinned to one core (`taskset`): the detection of the chosen frames runs on every core.
    if Path::new("/usr/bin/taskset").exists() {
        let mut one = Command::new("/usr/bin/taskset");
        let inner = import_command(&bag, &board, &dir.path().join("session-one-core"));
        one.args(["-c", "0"])
            .arg(inner.get_program())
            .args(inner.get_args());
        timed(one, "whole command, one core (taskset -c 0)");
    }
    if seconds > 60.0 || stops != 0 || std::env::var_os("HANDEYE_BENCH_BAG").is_some() {
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
