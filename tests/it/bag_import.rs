//! `handeye import bag` on ROS 2 bags written by an independent writer: the pure-Python
//! `rosbags` package (tests/python/make_bag.py) packs frames rendered by our simulated camera and
//! the simulated arm's TF, in both storage formats (MCAP and sqlite3). The ground truth is known,
//! so the calibration is checked against it (0.5 mm / 0.05°, the sim cell's tolerances), and the
//! camera-to-robot clock offset baked into the image stamps is checked against its estimate (2 ms).
//! Bad bags (a missing TF frame, a topic that is not there, truncated files) must fail with a
//! message naming the frame, topic or file, and leave no output behind.
//!
//! Needs python3 (skips with a printed reason without it); `rosbags` and `numpy` are installed
//! into a venv under CARGO_TARGET_TMPDIR on first use (scripts/test.sh does the same for CI).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use nalgebra::{Point3, UnitQuaternion, Vector3};
use rand::SeedableRng;

use handeye_camera::render::{render_with_rays, PixelRays, RenderOptions};
use handeye_core::camera_model::{CameraModel, Distortion};
use handeye_core::geometry::{pose_from_rotvec, Pose};
use handeye_plan::lookat::LookAt;
use handeye_records::result::ResultFile;
use handeye_ros2_bag::tf::interpolate;
use handeye_vision::Board;

use crate::util;
use util::{handeye, pose_error_mm_deg, repo};

/// The venv's python with rosbags, or `None` (printed) without python3.
fn python() -> Option<PathBuf> {
    static PYTHON: OnceLock<Option<PathBuf>> = OnceLock::new();
    PYTHON
        .get_or_init(|| {
            util::venv_python(
                "bag-venv",
                "rosbags, numpy",
                &["rosbags", "numpy"],
                "the bags are written by the `rosbags` package",
            )
        })
        .clone()
}

/// The simulated cell's ground truth (configs/sim-cell.yaml's `simulation:`).
fn truth() -> (Pose, Pose) {
    (
        pose_from_rotvec(
            Vector3::new(0.0312, -0.0694, 0.0447),
            Vector3::new(0.021, -0.016, 1.561),
        ),
        pose_from_rotvec(
            Vector3::new(0.5034, -0.1467, 0.0021),
            Vector3::new(0.012, -0.018, 0.297),
        ),
    )
}

fn board_path() -> PathBuf {
    repo().join("configs/targets/aprilgrid-6x6.yaml")
}

fn camera() -> CameraModel {
    CameraModel {
        width: 640,
        height: 480,
        fx: 520.0,
        fy: 521.0,
        cx: 318.7,
        cy: 241.2,
        distortion: Distortion::RadTan {
            k1: -0.05,
            k2: 0.01,
            p1: 0.0,
            p2: 0.0,
            k3: 0.0,
        },
    }
}

/// Flange poses that look at the board from `n` directions (eye-in-hand under [`truth`]).
fn views(n: usize, board: &Board) -> Vec<Pose> {
    views_seen_at(n, board, |_| [0.0, 0.0])
}

/// [`views`] with the board centre seen at `seen_at(i)` degrees off the optical axis.
fn views_seen_at(n: usize, board: &Board, seen_at: impl Fn(usize) -> [f64; 2]) -> Vec<Pose> {
    let (flange_from_camera, base_from_target) = truth();
    let corners: Vec<Point3<f64>> = board
        .tags()
        .iter()
        .filter_map(|t| board.tag_corners_in_target(t.id))
        .flatten()
        .collect();
    let centre =
        Point3::from(corners.iter().map(|p| p.coords).sum::<Vector3<f64>>() / corners.len() as f64);
    (0..n)
        .map(|i| {
            let look = LookAt {
                distance: 0.55 + 0.1 * ((i % 3) as f64),
                azimuth_deg: 360.0 * i as f64 / n as f64,
                elevation_deg: 62.0 + 8.0 * ((i % 4) as f64),
                roll_deg: -20.0 + 13.0 * ((i % 4) as f64),
                board_in_image_deg: seen_at(i),
            };
            base_from_target * look.target_from_camera(&centre) * flange_from_camera.inverse()
        })
        .collect()
}

/// A trajectory `T_base_flange(t)` (t in seconds of robot time).
trait Trajectory {
    fn at(&self, t: f64) -> Pose;
    fn duration(&self) -> f64;
}

/// Stands `stay` s at each view, moves `travel` s between them (smooth-step).
struct StopAndGo {
    views: Vec<Pose>,
    stay: f64,
    travel: f64,
}

impl StopAndGo {
    /// Stands `stay` s at each of `n` views of the test board ([`views`]), `travel` s between
    /// them.
    fn through_views(n: usize, stay: f64, travel: f64) -> StopAndGo {
        let board = Board::load(&board_path()).unwrap();
        StopAndGo {
            views: views(n, &board),
            stay,
            travel,
        }
    }

    /// Whether the arm stands at `t` (s): the frames worth rendering.
    fn standing(&self, t: f64) -> bool {
        t % (self.stay + self.travel) <= self.stay + 1e-9
    }
}

impl Trajectory for StopAndGo {
    fn at(&self, t: f64) -> Pose {
        let period = self.stay + self.travel;
        let k = ((t / period).floor() as usize).min(self.views.len() - 1);
        let within = t - k as f64 * period;
        if within <= self.stay || k + 1 >= self.views.len() {
            return self.views[k];
        }
        let s = (within - self.stay) / self.travel;
        interpolate(&self.views[k], &self.views[k + 1], s * s * (3.0 - 2.0 * s))
    }
    fn duration(&self) -> f64 {
        self.views.len() as f64 * (self.stay + self.travel) - self.travel
    }
}

/// Moves through the views without stopping, `segment` s from one to the next, with a smooth
/// speed profile that never reaches zero inside a segment.
struct Continuous {
    views: Vec<Pose>,
    segment: f64,
}

impl Trajectory for Continuous {
    fn at(&self, t: f64) -> Pose {
        let k = ((t / self.segment).floor() as usize).min(self.views.len() - 2);
        let s = ((t - k as f64 * self.segment) / self.segment).clamp(0.0, 1.0);
        // Speed varies (0.5..1.5 of the mean) so the timing is observable from the motion.
        let eased = s + 0.5 * (std::f64::consts::TAU * s).sin() / std::f64::consts::TAU;
        interpolate(&self.views[k], &self.views[k + 1], eased)
    }
    fn duration(&self) -> f64 {
        (self.views.len() - 1) as f64 * self.segment
    }
}

/// What a bag holds.
struct BagSpec<'a> {
    storage: &'a str,
    /// `mono8` (sensor_msgs/Image) or `png` (CompressedImage).
    image_kind: &'a str,
    trajectory: &'a dyn Trajectory,
    fps: f64,
    tf_hz: f64,
    /// Camera stamp − robot stamp, s.
    offset_s: f64,
    camera_info: bool,
    /// Render only frames for which this says true (others reuse a blank frame: they must never
    /// become samples).
    render: &'a dyn Fn(f64) -> bool,
}

impl<'a> BagSpec<'a> {
    /// The bag most tests write: MCAP, `mono8` frames at 5 fps, TF at 50 Hz, the clocks in step,
    /// camera_info recorded; the arm's `trajectory` and the frames that show the board (`render`)
    /// are each test's.
    fn of(trajectory: &'a dyn Trajectory, render: &'a dyn Fn(f64) -> bool) -> BagSpec<'a> {
        BagSpec {
            storage: "mcap",
            image_kind: "mono8",
            trajectory,
            fps: 5.0,
            tf_hz: 50.0,
            offset_s: 0.0,
            camera_info: true,
            render,
        }
    }
}

const ROBOT_START_NS: i64 = 1_700_000_000_000_000_000;

/// Renders the frames, writes the spec and runs make_bag.py; returns the bag folder.
fn make_bag(dir: &Path, name: &str, spec: &BagSpec<'_>) -> Option<PathBuf> {
    make_bag_edited(dir, name, spec, |_| {})
}

/// [`make_bag`] with the spec edited before make_bag.py writes it (a bag that lies).
fn make_bag_edited(
    dir: &Path,
    name: &str,
    spec: &BagSpec<'_>,
    edit: impl FnOnce(&mut serde_json::Value),
) -> Option<PathBuf> {
    make_bag_with_camera(dir, name, spec, &camera(), edit)
}

/// [`make_bag_edited`] with frames rendered by `camera` (its size is the images').
fn make_bag_with_camera(
    dir: &Path,
    name: &str,
    spec: &BagSpec<'_>,
    camera: &CameraModel,
    edit: impl FnOnce(&mut serde_json::Value),
) -> Option<PathBuf> {
    let python = python()?;
    let board = Board::load(&board_path()).unwrap();
    let camera = *camera;
    let (flange_from_camera, base_from_target) = truth();
    let frames = dir.join(format!("{name}-frames"));
    std::fs::create_dir_all(&frames).unwrap();
    let rays = PixelRays::new(&camera).expect("memory for the lens's rays");
    let options = RenderOptions {
        supersample: 2,
        ..RenderOptions::default()
    };
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let write_frame = |image: &image::GrayImage, file: &Path| {
        if spec.image_kind == "mono8" {
            std::fs::write(file, image.as_raw()).unwrap();
        } else {
            image
                .save_with_format(file, image::ImageFormat::Png)
                .unwrap();
        }
    };
    let ext = if spec.image_kind == "mono8" {
        "gray"
    } else {
        "png"
    };
    let blank = image::GrayImage::from_pixel(camera.width, camera.height, image::Luma([110]));
    write_frame(&blank, &frames.join(format!("blank.{ext}")));
    let mut images = Vec::new();
    let mut rendered: Vec<(Pose, String)> = Vec::new();
    let count = (spec.trajectory.duration() * spec.fps).floor() as usize;
    for i in 0..=count {
        let t = i as f64 / spec.fps;
        let stamp = ROBOT_START_NS + ((t + spec.offset_s) * 1e9).round() as i64;
        let file = if (spec.render)(t) {
            let flange = spec.trajectory.at(t);
            // A standing arm gives the same view: render it once.
            match rendered
                .iter()
                .find(|(p, _)| pose_error_mm_deg(p, &flange).0 < 1e-9)
            {
                Some((_, f)) => f.clone(),
                None => {
                    let camera_from_target =
                        (flange * flange_from_camera).inverse() * base_from_target;
                    let image = render_with_rays(
                        &board,
                        &camera,
                        &rays,
                        &camera_from_target,
                        &options,
                        &mut rng,
                    )
                    .expect("memory for a frame");
                    let f = format!("{i:05}.{ext}");
                    write_frame(&image, &frames.join(&f));
                    rendered.push((flange, f.clone()));
                    f
                }
            }
        } else {
            format!("blank.{ext}")
        };
        images.push(serde_json::json!([stamp, format!("{name}-frames/{file}")]));
    }
    let mut tf = Vec::new();
    // TF covers the images with a margin (the robot driver publishes all along).
    let tf_count = ((spec.trajectory.duration() + 1.0) * spec.tf_hz) as i64;
    for k in -(spec.tf_hz as i64)..=tf_count {
        let t = k as f64 / spec.tf_hz;
        let p = spec.trajectory.at(t.max(0.0));
        let stamp = ROBOT_START_NS + (t * 1e9).round() as i64;
        // base_link -> base -> shoulder_link (static) -> wrist_3_link (moving) -> tool0 (static).
        let rest = shoulder_static().inverse() * p;
        let (rt, rq) = (rest.translation.vector, rest.rotation.coords);
        tf.push(serde_json::json!([
            stamp,
            "shoulder_link",
            "wrist_3_link",
            rt.x,
            rt.y,
            rt.z,
            rq.x,
            rq.y,
            rq.z,
            rq.w
        ]));
    }
    let s = shoulder_static();
    let (st, sq) = (s.translation.vector, s.rotation.coords);
    let tf_static = vec![
        serde_json::json!([
            ROBOT_START_NS,
            "base_link",
            "base",
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            1.0
        ]),
        serde_json::json!([
            ROBOT_START_NS,
            "base",
            "shoulder_link",
            st.x,
            st.y,
            st.z,
            sq.x,
            sq.y,
            sq.z,
            sq.w
        ]),
        serde_json::json!([
            ROBOT_START_NS,
            "wrist_3_link",
            "tool0",
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            1.0
        ]),
    ];
    let k = [
        camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0,
    ];
    let spec_json = serde_json::json!({
        "storage": spec.storage,
        "image_topic": "/camera/image_raw",
        "camera_info_topic": "/camera/camera_info",
        "frame_id": "camera_optical_frame",
        "image_kind": spec.image_kind,
        "width": camera.width,
        "height": camera.height,
        "camera_info": if spec.camera_info {
            serde_json::json!({"k": k, "d": camera.distortion_coefficients(), "distortion_model": "plumb_bob"})
        } else {
            serde_json::Value::Null
        },
        "tf": tf,
        "tf_static": tf_static,
        "images": images,
    });
    let mut spec_json = spec_json;
    edit(&mut spec_json);
    let spec_file = dir.join(format!("{name}.json"));
    std::fs::write(&spec_file, serde_json::to_string(&spec_json).unwrap()).unwrap();
    let bag = dir.join(name);
    let out = Command::new(python)
        .arg(repo().join("tests/python/make_bag.py"))
        .arg(&spec_file)
        .arg(&bag)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "make_bag.py: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    Some(bag)
}

/// `base → shoulder_link`, the static part of the test's TF chain.
fn shoulder_static() -> Pose {
    Pose::from_parts(
        Vector3::new(0.0, 0.0, 0.18).into(),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 0.4),
    )
}

fn import(bag: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    import_command(bag, out, extra).output().unwrap()
}

/// The `import bag` command of [`import`], to run with more set (the environment).
fn import_command(bag: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut command = handeye();
    command
        .args(["import", "bag"])
        .arg(bag)
        .args(["--base", "base_link", "--flange", "tool0"])
        .args(["--image", "/camera/image_raw"])
        .arg("--board")
        .arg(board_path())
        .arg("-o")
        .arg(out)
        .args(extra);
    command
}

/// A stop-and-go bag of 6 views with the board rendered while standing (so an import that
/// finishes calibrates), 5 fps, in `storage`.
fn six_view_bag(dir: &Path, storage: &str) -> Option<PathBuf> {
    let trajectory = StopAndGo::through_views(6, 0.6, 0.4);
    let standing = |t: f64| trajectory.standing(t);
    make_bag(
        dir,
        &format!("six-views-{storage}"),
        &BagSpec {
            storage,
            ..BagSpec::of(&trajectory, &standing)
        },
    )
}

/// The import options of the bags these tests write (the sim arm's frames and topics).
fn sim_bag_options() -> handeye_ros2_bag::BagOptions {
    handeye_ros2_bag::BagOptions {
        base_frame: "base_link".into(),
        flange_frame: "tool0".into(),
        image_topic: "/camera/image_raw".into(),
        camera_info_topic: Some("/camera/camera_info".into()),
        tf_topics: vec!["/tf".into(), "/tf_static".into()],
        tf_static_topics: vec!["/tf_static".into()],
        select: Default::default(),
        setup: handeye_core::setup::Setup::EyeInHand,
        board: handeye_vision::Target::load(&board_path()).unwrap(),
        detector: Default::default(),
    }
}

fn text(out: &std::process::Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Both transforms within the sim cell's tolerances (0.5 mm, 0.05°) of the ground truth.
fn assert_calibrated(session: &Path) {
    let (flange_from_camera, base_from_target) = truth();
    let result = ResultFile::load_mounts(&session.join("result.yaml")).unwrap();
    let (mm, deg) = pose_error_mm_deg(&result.camera_mount, &flange_from_camera);
    let (mm2, deg2) = pose_error_mm_deg(&result.target_mount, &base_from_target);
    println!("T_flange_camera off by {mm:.3} mm, {deg:.4} deg; T_base_target off by {mm2:.3} mm, {deg2:.4} deg");
    assert!(
        mm < 0.5 && deg < 0.05,
        "T_flange_camera {mm:.3} mm {deg:.4} deg"
    );
    assert!(
        mm2 < 0.5 && deg2 < 0.05,
        "T_base_target {mm2:.3} mm {deg2:.4} deg"
    );
}

fn no_leftovers(dir: &Path, out: &Path) {
    assert!(!out.exists(), "{} was written", out.display());
    no_staging_left(dir);
}

fn no_staging_left(dir: &Path) {
    let stray: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().contains(".importing-"))
        .collect();
    assert!(stray.is_empty(), "staging left behind: {stray:?}");
}

#[test]
fn stop_and_go_mcap_raw_images_calibrate_within_tolerance() {
    let dir = tempfile::tempdir().unwrap();
    let board = Board::load(&board_path()).unwrap();
    let trajectory = StopAndGo {
        views: views(16, &board),
        stay: 0.8,
        travel: 0.7,
    };
    // Frames while moving are blank: taking one would lose a view (checked below).
    let standing = |t: f64| trajectory.standing(t);
    let Some(bag) = make_bag(
        dir.path(),
        "stop-and-go",
        &BagSpec {
            fps: 15.0,
            tf_hz: 125.0,
            offset_s: 0.030,
            ..BagSpec::of(&trajectory, &standing)
        },
    ) else {
        return;
    };
    let out = dir.path().join("session");
    let run = import(
        &bag,
        &out,
        &[
            "--time-offset",
            "0.030",
            "--camera-info",
            "/camera/camera_info",
        ],
    );
    let log = text(&run);
    println!("{log}");
    assert!(run.status.success(), "{log}");
    assert!(
        log.contains("(mcap)") && log.contains("16 frames taken"),
        "{log}"
    );
    assert!(
        log.contains("moving") && log.contains("not sharpest"),
        "{log}"
    );
    assert!(log.contains("16 samples accepted, 0 skipped"), "{log}");
    assert_calibrated(&out);
    assert_recorded_as_the_run_records(&out, &dir.path().join("rerun"));
    // The result says which frames its robot poses were read in, and the exports name them and
    // leave the transforms as they are: by default and with `--base-frame base_link` alike (it
    // used to be turned 180° a second time as if it were the controller's `base`).
    let result = ResultFile::load(&out.join("result.yaml")).unwrap();
    let frames = result.robot_frames.clone().expect("robot_frames recorded");
    assert_eq!(
        (frames.base.as_str(), frames.flange.as_str()),
        ("base_link", "tool0")
    );
    let (_, base_link_from_target) = truth();
    for extra in [&[][..], &["--base-frame", "base_link"][..]] {
        let export = handeye()
            .arg("export")
            .arg(out.join("result.yaml"))
            .args(["--format", "json"])
            .args(extra)
            .output()
            .unwrap();
        assert!(export.status.success(), "{}", text(&export));
        let json: serde_json::Value = serde_json::from_slice(&export.stdout).unwrap();
        let board = &json["T_base_target"];
        assert_eq!(board["parent"], "base_link", "{extra:?}: {json}");
        let t = &board["translation"];
        let exported = Vector3::new(
            t[0].as_f64().unwrap(),
            t[1].as_f64().unwrap(),
            t[2].as_f64().unwrap(),
        );
        let off_mm = (exported - base_link_from_target.translation.vector).norm() * 1e3;
        assert!(
            off_mm < 0.5,
            "{extra:?}: {off_mm} mm from the truth in base_link"
        );
    }
    // The report's "use it" names the frames as the export does.
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(
        page.contains("--frame-id base_link") && !page.contains("--frame-id base "),
        "the report's ROS 2 snippet does not name base_link"
    );
    // Like a run's, the import ends with its report and the next step; the importer's
    // placeholder nominal is not judged (it used to make every import CHECK "far from nominal").
    assert!(out.join("report.html").is_file(), "{log}");
    assert!(log.contains("verdict: GOOD"), "{log}");
    assert!(
        log.contains("report:") && log.lines().last().unwrap().starts_with("next: "),
        "{log}"
    );
    // A bag is a ROS 2 recording: the next step puts the answer on its graph.
    assert!(
        log.lines()
            .last()
            .unwrap()
            .starts_with("next: handeye publish "),
        "{log}"
    );
    // It is an ordinary session: the reprojection-space solve and the report work on it.
    let solve = handeye()
        .arg("solve")
        .arg(&out)
        .args(["--space", "reprojection"])
        .output()
        .unwrap();
    assert!(solve.status.success(), "{}", text(&solve));
    assert_calibrated(&out);
    let report = handeye().arg("report").arg(&out).output().unwrap();
    assert!(report.status.success(), "{}", text(&report));
    let replay = handeye().arg("replay").arg(&out).output().unwrap();
    let log = text(&replay);
    assert!(replay.status.success(), "{log}");
    // A replay writes its own report beside the run's and says what to do next.
    assert!(out.join("replay-report.html").is_file(), "{log}");
    let next = String::from_utf8_lossy(&replay.stdout);
    assert!(
        next.lines().last().unwrap().starts_with("next: ") && next.contains("verdict: "),
        "{log}"
    );
    // The detector searched the quads at half resolution, as a cell's default; the old default
    // (full resolution) is one flag away and gives the same answer.
    assert_eq!(recorded_decimation(&out), 2.0);
    let full = dir.path().join("full-resolution");
    let run = import(
        &bag,
        &full,
        &[
            "--time-offset",
            "0.030",
            "--camera-info",
            "/camera/camera_info",
            "--decimation",
            "1",
        ],
    );
    assert!(run.status.success(), "{}", text(&run));
    assert_eq!(recorded_decimation(&full), 1.0);
    assert_calibrated(&full);
}

/// The import measures each frame while it is in memory, as it is chosen; a run of its recorded
/// cell (`import/cell.yaml`, reading the frames from the session) into `rerun` records the same:
/// every pose record, preview and `samples.yaml`, byte for byte.
fn assert_recorded_as_the_run_records(session: &Path, rerun: &Path) {
    let run = handeye()
        .arg("run")
        .arg("--config")
        .arg(session.join("import/cell.yaml"))
        .arg("-o")
        .arg(rerun)
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", text(&run));
    for folder in ["poses", "previews"] {
        let names = |root: &Path| -> Vec<_> {
            let mut names: Vec<_> = std::fs::read_dir(root.join(folder))
                .unwrap()
                .map(|e| e.unwrap().file_name())
                .collect();
            names.sort();
            names
        };
        let imported = names(session);
        assert!(!imported.is_empty(), "no {folder} in {}", session.display());
        assert_eq!(imported, names(rerun), "{folder}");
        for name in imported {
            let read = |root: &Path| std::fs::read(root.join(folder).join(&name)).unwrap();
            assert!(
                read(session) == read(rerun),
                "{folder}/{}: the import's differs from the run's",
                name.to_string_lossy()
            );
        }
    }
    assert_eq!(
        std::fs::read_to_string(session.join("samples.yaml")).unwrap(),
        std::fs::read_to_string(rerun.join("samples.yaml")).unwrap()
    );
}

/// The import measures and records each frame as it is chosen: a record that cannot be written
/// (a full disk) stops it there with the error, naming the file, and leaves nothing behind.
#[test]
fn a_record_that_cannot_be_written_stops_the_import_and_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let Some(bag) = six_view_bag(dir.path(), "mcap") else {
        return;
    };
    let out = dir.path().join("session");
    let run = import_command(&bag, &out, &["--camera-info", "/camera/camera_info"])
        .env("HANDEYE_FAULT", "full-disk-at-record:2")
        .output()
        .unwrap();
    let log = text(&run);
    assert_eq!(run.status.code(), Some(1), "{log}");
    assert!(
        log.contains("recording the bag's chosen frames")
            && log.contains("poses/002.yaml")
            && log.contains("no space left on device"),
        "{log}"
    );
    no_leftovers(dir.path(), &out);
}

/// The quad decimation the import's recorded cell (`import/cell.yaml`) detects with.
fn recorded_decimation(session: &Path) -> f64 {
    let cell: serde_yaml_ng::Value = serde_yaml_ng::from_str(
        &std::fs::read_to_string(session.join("import/cell.yaml")).unwrap(),
    )
    .unwrap();
    cell["detector"]["decimate"].as_f64().unwrap()
}

/// The import as a library call (what `handeye import bag` is a thin caller of): the notes
/// arrive as it goes, the session is where it was asked for, the answer is the truth, and the
/// report is the run's tail (`write_run_report`, as after `handeye run`), where the session is.
#[test]
fn the_library_imports_a_bag_into_a_solved_session() {
    use handeye_session::cell::bag::{import_bag_session, BagNote, BagSessionRequest};
    let dir = tempfile::tempdir().unwrap();
    let trajectory = StopAndGo::through_views(12, 0.8, 0.7);
    let standing = |t: f64| trajectory.standing(t);
    let Some(bag) = make_bag(
        dir.path(),
        "library",
        &BagSpec {
            fps: 15.0,
            tf_hz: 125.0,
            ..BagSpec::of(&trajectory, &standing)
        },
    ) else {
        return;
    };
    let out = dir.path().join("session");
    let request = BagSessionRequest {
        bag: bag.clone(),
        options: sim_bag_options(),
        board_file: board_path(),
        decimation: 1.0,
        continuous: false,
        output: out.clone(),
    };
    let mut notes = Vec::new();
    let report = |done: &handeye_session::cell::run::CellRun| {
        handeye_report::session::write_run_report(done).map_err(|e| e.to_string())
    };
    let imported = import_bag_session(&request, &mut |note| notes.push(note), &report).unwrap();
    assert_eq!(imported.report, Ok(out.join("report.html")));
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    let staging = page.find(".importing-").map(|i| {
        page.get(i.saturating_sub(300)..i + 100)
            .unwrap_or(".importing-")
    });
    assert!(
        page.contains("T_flange_camera") && staging.is_none(),
        "the page of the session, never naming the staging folder: {staging:?}"
    );
    assert!(
        notes
            .iter()
            .any(|n| matches!(n, BagNote::Line(l) if l.contains("12 frames taken"))),
        "{notes:#?}"
    );
    assert!(
        !notes.iter().any(|n| matches!(n, BagNote::Warning(_))),
        "{notes:#?}"
    );
    assert_eq!(imported.folder, out);
    assert_eq!(
        (imported.accepted, imported.skipped, imported.warnings),
        (12, 0, 0)
    );
    assert!(
        imported.summary.contains("T_flange_camera") && !imported.summary.contains(".importing-"),
        "the summary never names the staging folder:\n{}",
        imported.summary
    );
    assert!(out.join("import/bag-import.yaml").is_file());
    assert_frames_stored_once(&out, 12);
    assert_calibrated(&out);
    no_staging_left(dir.path());
}

/// Each chosen frame is on disk once, as the session's frame file of its pose: the import wrote
/// `frames/NNN.png`, its record names it, and the run kept it (no second copy under `import/`).
fn assert_frames_stored_once(session: &Path, samples: usize) {
    let expected: Vec<String> = (0..samples).map(|i| format!("frames/{i:03}.png")).collect();
    assert_eq!(import_record_field(session, "samples", "frame"), expected);
    let mut stored: Vec<String> = std::fs::read_dir(session.join("frames"))
        .unwrap()
        .map(|e| format!("frames/{}", e.unwrap().file_name().to_string_lossy()))
        .collect();
    stored.sort();
    assert_eq!(
        stored, expected,
        "one file per sample in frames/, nothing else"
    );
    let copies: Vec<PathBuf> = walk_files(&session.join("import"))
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    assert!(copies.is_empty(), "a second copy of the frames: {copies:?}");
    // The frames the run detected the board in are these files.
    for file in &expected {
        let frame = image::open(session.join(file)).unwrap();
        assert_eq!(
            (frame.width(), frame.height()),
            (camera().width, camera().height),
            "{file}"
        );
    }
}

/// `field` of each entry of `list` in the session's `import/bag-import.yaml`, as text.
fn import_record_field(session: &Path, list: &str, field: &str) -> Vec<String> {
    let text = std::fs::read_to_string(session.join("import/bag-import.yaml")).unwrap();
    let record: serde_yaml_ng::Value = serde_yaml_ng::from_str(&text).unwrap();
    record[list]
        .as_sequence()
        .unwrap_or_else(|| panic!("no list `{list}` in the import record:\n{text}"))
        .iter()
        .map(|entry| entry[field].as_str().unwrap().to_string())
        .collect()
}

fn walk_files(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .unwrap()
        .flat_map(|e| {
            let path = e.unwrap().path();
            if path.is_dir() {
                walk_files(&path)
            } else {
                vec![path]
            }
        })
        .collect()
}

#[test]
fn continuous_sqlite_compressed_images_recover_the_clock_offset() {
    let dir = tempfile::tempdir().unwrap();
    let board = Board::load(&board_path()).unwrap();
    let trajectory = Continuous {
        views: views(12, &board),
        segment: 1.6,
    };
    let offset = 0.0417;
    let Some(bag) = make_bag(
        dir.path(),
        "continuous",
        &BagSpec {
            storage: "sqlite3",
            image_kind: "png",
            tf_hz: 200.0,
            offset_s: offset,
            ..BagSpec::of(&trajectory, &|_| true)
        },
    ) else {
        return;
    };
    let out = dir.path().join("session");
    let run = import(
        &bag,
        &out,
        &[
            "--continuous",
            "--spacing",
            "0.19",
            "--time-offset",
            "auto",
            "--camera-info",
            "/camera/camera_info",
        ],
    );
    let log = text(&run);
    println!("{log}");
    assert!(run.status.success(), "{log}");
    assert!(log.contains("(sqlite3)"), "{log}");
    let record = std::fs::read_to_string(out.join("import/bag-import.yaml")).unwrap();
    let value: serde_yaml_ng::Value = serde_yaml_ng::from_str(&record).unwrap();
    let estimated = value["time_offset_s"].as_f64().unwrap();
    println!(
        "offset {:.3} ms, true {:.3} ms",
        estimated * 1e3,
        offset * 1e3
    );
    assert!(
        (estimated - offset).abs() < 0.002,
        "offset {estimated} s, true {offset} s"
    );
    assert!(value["time_offset_estimated"].as_bool().unwrap());
    assert_calibrated(&out);
}

#[test]
fn without_camera_info_the_intrinsics_are_estimated() {
    let dir = tempfile::tempdir().unwrap();
    let board = Board::load(&board_path()).unwrap();
    // Off-centre views put board corners across the image, which the lens estimate needs.
    let trajectory = StopAndGo {
        views: views_seen_at(20, &board, |i| {
            let a = i as f64 * 2.4;
            [12.0 * a.cos(), 9.0 * a.sin()]
        }),
        stay: 0.6,
        travel: 0.6,
    };
    let standing = |t: f64| trajectory.standing(t);
    let Some(bag) = make_bag(
        dir.path(),
        "no-info",
        &BagSpec {
            image_kind: "png",
            fps: 10.0,
            tf_hz: 100.0,
            camera_info: false,
            ..BagSpec::of(&trajectory, &standing)
        },
    ) else {
        return;
    };
    let out = dir.path().join("session");
    let run = import(&bag, &out, &[]);
    let log = text(&run);
    println!("{log}");
    assert!(run.status.success(), "{log}");
    assert!(log.contains("20 samples accepted"), "{log}");
    let estimated = CameraModel::load(&out.join("camera_info.yaml")).unwrap();
    let truth = camera();
    for (name, got, want) in [
        ("fx", estimated.fx, truth.fx),
        ("fy", estimated.fy, truth.fy),
        ("cx", estimated.cx, truth.cx),
        ("cy", estimated.cy, truth.cy),
    ] {
        assert!(
            (got - want).abs() < 1.0,
            "{name} {got:.2} px, true {want:.2} px"
        );
    }
    assert_calibrated(&out);
}

/// A small stop-and-go bag for the failure tests.
fn small_bag(dir: &Path, storage: &str) -> Option<PathBuf> {
    let trajectory = StopAndGo::through_views(4, 0.5, 0.5);
    make_bag(
        dir,
        &format!("small-{storage}"),
        &BagSpec {
            storage,
            ..BagSpec::of(&trajectory, &|_| false)
        },
    )
}

#[test]
fn bad_bags_fail_clearly_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    for storage in ["mcap", "sqlite3"] {
        let Some(bag) = small_bag(dir.path(), storage) else {
            return;
        };
        let out = dir.path().join(format!("out-{storage}"));

        // A frame that is not in the TF tree: named, with the frames that are there.
        let run = handeye()
            .args(["import", "bag"])
            .arg(&bag)
            .args(["--base", "base_link", "--flange", "tool_flange"])
            .args(["--image", "/camera/image_raw", "--board"])
            .arg(board_path())
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        let log = text(&run);
        println!("{storage}: {log}");
        assert!(!run.status.success());
        assert!(
            log.contains("`tool_flange`") && log.contains("wrist_3_link"),
            "{log}"
        );
        no_leftovers(dir.path(), &out);

        // A topic that does not exist: named, with the topics present.
        let run = handeye()
            .args(["import", "bag"])
            .arg(&bag)
            .args(["--image", "/camera/color/image_raw", "--board"])
            .arg(board_path())
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        let log = text(&run);
        println!("{storage}: {log}");
        assert!(!run.status.success());
        assert!(
            log.contains("/camera/color/image_raw")
                && log.contains("/camera/image_raw (sensor_msgs/msg/Image")
                && log.contains("/tf "),
            "{log}"
        );
        no_leftovers(dir.path(), &out);

        // A truncated storage file: named as truncated or damaged.
        let file = std::fs::read_dir(&bag)
            .unwrap()
            .filter_map(Result::ok)
            .map(|e| e.path())
            .find(|p| p.extension().is_some_and(|e| e == "mcap" || e == "db3"))
            .unwrap();
        let bytes = std::fs::read(&file).unwrap();
        let cut = dir.path().join(format!("cut-{storage}"));
        std::fs::create_dir_all(&cut).unwrap();
        std::fs::copy(bag.join("metadata.yaml"), cut.join("metadata.yaml")).unwrap();
        let cut_file = cut.join(file.file_name().unwrap());
        std::fs::write(&cut_file, &bytes[..bytes.len() * 2 / 3]).unwrap();
        // An existing empty output folder stays as it was.
        std::fs::create_dir_all(&out).unwrap();
        let run = import(&cut, &out, &[]);
        let log = text(&run);
        println!("{storage}: {log}");
        assert!(!run.status.success());
        assert!(
            log.contains(&*cut_file.file_name().unwrap().to_string_lossy())
                && (log.contains("truncated") || log.contains("damaged")),
            "{log}"
        );
        assert!(
            std::fs::read_dir(&out).unwrap().next().is_none(),
            "output touched"
        );
        std::fs::remove_dir(&out).unwrap();
        no_leftovers(dir.path(), &out);
    }
}

mod lies;
mod limits;
mod stops;
mod stream;
mod tolerated;
