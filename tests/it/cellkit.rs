//! A first real cell without guessing (issue #14, item 3): every Universal Robots model the
//! config accepts, from its published kinematics; joint ranges per joint, applied by the planner
//! and the plan check; a board fitted to a sheet of paper and written as a PDF; templates for a
//! real UR with a USB camera in both setups.

use std::f64::consts::PI;

use nalgebra::{Matrix4, Vector3};

use std::path::{Path, PathBuf};

use handeye_config::schema::{ARM_JOINT_RANGES_DEG, FLANGE_CAMERA_JOINT_RANGES_DEG};
use handeye_config::{CellConfig, RobotConfig};
use handeye_core::setup::Setup;
use handeye_plan::{Plan, Waypoint};
use handeye_robot::kinematics::UrModel;
use handeye_robot::Joints;
use handeye_vision::print::{board_pdf, fit_to_paper, resized_board_yaml, Paper};
use handeye_vision::{Board, DetectorOptions, TagDetector, TagFamily};

use crate::util;

/// UR's published `[d1, a2, a3, d4, d5, d6]` per model, typed in again here from Universal
/// Robots' "DH Parameters for calculations of kinematics and dynamics" page (and the CB3
/// manual's appendix, `ur_description` for UR16e/UR30), so a typo in the library's table fails.
const TABLE: [(&str, [f64; 6]); 9] = [
    (
        "ur3",
        [0.1519, -0.24365, -0.21325, 0.11235, 0.08535, 0.0819],
    ),
    (
        "ur5",
        [0.089159, -0.425, -0.39225, 0.10915, 0.09465, 0.0823],
    ),
    ("ur10", [0.1273, -0.612, -0.5723, 0.163941, 0.1157, 0.0922]),
    (
        "ur3e",
        [0.15185, -0.24355, -0.2132, 0.13105, 0.08535, 0.0921],
    ),
    ("ur5e", [0.1625, -0.425, -0.3922, 0.1333, 0.0997, 0.0996]),
    (
        "ur10e",
        [0.1807, -0.6127, -0.57155, 0.17415, 0.11985, 0.11655],
    ),
    ("ur16e", [0.1807, -0.4784, -0.36, 0.17415, 0.11985, 0.11655]),
    ("ur20", [0.2363, -0.862, -0.7287, 0.201, 0.1593, 0.1543]),
    ("ur30", [0.2363, -0.637, -0.5037, 0.201, 0.1593, 0.1543]),
];

/// The standard DH link matrix `Rz(θ)·Tz(d)·Tx(a)·Rx(α)`, written out as the textbook does.
fn dh(theta: f64, d: f64, a: f64, alpha: f64) -> Matrix4<f64> {
    let (st, ct) = theta.sin_cos();
    let (sa, ca) = alpha.sin_cos();
    Matrix4::new(
        ct,
        -st * ca,
        st * sa,
        a * ct, //
        st,
        ct * ca,
        -ct * sa,
        a * st, //
        0.0,
        sa,
        ca,
        d, //
        0.0,
        0.0,
        0.0,
        1.0,
    )
}

/// The flange pose by a direct product of the six DH matrices of the published table.
fn dh_chain(p: &[f64; 6], q: &[f64; 6]) -> Matrix4<f64> {
    let [d1, a2, a3, d4, d5, d6] = *p;
    let d = [d1, 0.0, 0.0, d4, d5, d6];
    let a = [0.0, a2, a3, 0.0, 0.0, 0.0];
    let alpha = [PI / 2.0, 0.0, 0.0, PI / 2.0, -PI / 2.0, 0.0];
    (0..6).fold(Matrix4::identity(), |t, i| {
        t * dh(q[i], d[i], a[i], alpha[i])
    })
}

const JOINT_VECTORS: [[f64; 6]; 4] = [
    [0.0; 6],
    [0.3, -1.2, 1.4, -0.8, 1.1, 0.4],
    [-2.1, -0.4, -1.9, 2.5, -0.7, 3.0],
    [1.0, -2.0, 0.5, -1.5, 2.2, -1.1],
];

#[test]
fn every_model_matches_its_published_dh_chain() {
    assert_eq!(
        UrModel::NAMES.to_vec(),
        TABLE.iter().map(|(n, _)| *n).collect::<Vec<_>>()
    );
    for (name, params) in TABLE {
        let model = UrModel::by_name(name).unwrap();
        for q in JOINT_VECTORS {
            let expected = dh_chain(&params, &q);
            let got = model.forward(&Joints::from(q)).to_homogeneous();
            assert!(
                (got - expected).abs().max() < 1e-12,
                "{name} at {q:?}: {got} vs {expected}"
            );
        }
        // Stretched out at zero joints the flange is a2 + a3 along x: the arm's published reach
        // figures are that plus the wrist (so a swapped a2/d4 would show here too).
        let home = model.forward(&Joints::zeros(6)).translation.vector;
        let expected = Vector3::new(
            params[1] + params[2],
            -(params[3] + params[5]),
            params[0] - params[4],
        );
        assert!((home - expected).norm() < 1e-12, "{name}: {home:?}");
    }
}

#[test]
fn every_model_inverts_its_own_forward_kinematics() {
    for name in UrModel::NAMES {
        let model = UrModel::by_name(name).unwrap();
        for q in &JOINT_VECTORS[1..] {
            let q = &Joints::from(*q);
            let pose = model.forward(q);
            let all = model.inverse(&pose);
            assert!(
                !all.is_empty() && all.len() <= 8,
                "{name}: {} solutions",
                all.len()
            );
            for s in &all {
                let fk = model.forward(s);
                assert!(
                    (fk.translation.vector - pose.translation.vector).norm() < 1e-9,
                    "{name}"
                );
                assert!(fk.rotation.angle_to(&pose.rotation) < 1e-9, "{name}");
            }
            let near = model.inverse_nearest(&pose, q).unwrap();
            let err = near
                .iter()
                .zip(q)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-9, "{name}: {near:?} vs {q:?}");
        }
    }
}

fn sim_with_model(dir: &Path, model: &str) -> PathBuf {
    util::config_variant(
        dir,
        "sim-cell.yaml",
        "cell.yaml",
        &[("model: ur10e", &format!("model: {model}"))],
    )
}

#[test]
fn every_model_name_is_accepted_in_the_config() {
    let dir = tempfile::tempdir().unwrap();
    for name in UrModel::NAMES {
        let config = CellConfig::load(&sim_with_model(dir.path(), name)).unwrap();
        assert!(matches!(config.robot, RobotConfig::Sim(_)));
        assert_eq!(config.robot.model(), Some(name));
        assert_eq!(
            UrModel::by_name(config.robot.model().unwrap())
                .unwrap()
                .name,
            name
        );
    }
}

#[test]
fn an_unknown_model_is_refused_listing_the_accepted_ones() {
    let dir = tempfile::tempdir().unwrap();
    let path = sim_with_model(dir.path(), "ur7e");
    let message = match CellConfig::load(&path) {
        Ok(_) => panic!("ur7e loaded"),
        Err(e) => format!("{:#}", anyhow::Error::new(e)),
    };
    assert!(message.contains(&path.display().to_string()), "{message}");
    assert!(
        message.contains("robot.model") && message.contains("ur7e"),
        "{message}"
    );
    for name in UrModel::NAMES {
        assert!(
            message.contains(&format!("`{name}`")),
            "{name} not listed: {message}"
        );
    }
}

/// The demo sim cell with `robot.joint_ranges_deg: ranges` (YAML flow text).
fn sim_with_ranges(dir: &Path, ranges: &str) -> PathBuf {
    let start = "start_joints_deg: [0, -90, 90, -90, -90, 0]";
    util::config_variant(
        dir,
        "sim-cell.yaml",
        "cell.yaml",
        &[(start, &format!("{start}\n  joint_ranges_deg: {ranges}"))],
    )
}

fn inside(q: &Joints, ranges: &[[f64; 2]]) -> bool {
    q.iter()
        .zip(ranges)
        .all(|(v, [lo, hi])| (lo..=hi).contains(&&v.to_degrees()))
}

/// The generated plan of the demo cell puts wrist 3 on both sides of zero; with wrist 3 held to
/// [0, 360]° the IK picks another solution for those: the same views, all inside.
#[test]
fn a_generated_plan_stays_inside_a_restricted_range() {
    let dir = tempfile::tempdir().unwrap();
    let free = handeye_session::cell::prepare(&util::config_variant(
        dir.path(),
        "sim-cell.yaml",
        "free.yaml",
        &[],
    ))
    .unwrap();
    let ranges = [
        [-360.0, 360.0],
        [-360.0, 360.0],
        [-180.0, 180.0],
        [-360.0, 360.0],
        [-360.0, 360.0],
        [0.0, 360.0],
    ];
    let free_joints: Vec<_> = free
        .report
        .validated()
        .expect("the demo plan passes")
        .into_iter()
        .map(|(_, q)| q)
        .collect();
    assert!(
        free_joints.iter().any(|q| !inside(q, &ranges)),
        "the unrestricted plan already keeps wrist 3 >= 0: this test would prove nothing"
    );

    let path = sim_with_ranges(
        dir.path(),
        "[[-360, 360], [-360, 360], [-180, 180], [-360, 360], [-360, 360], [0, 360]]",
    );
    let cell = handeye_session::cell::prepare(&path).unwrap();
    let validated = cell.report.validated().unwrap_or_else(|| {
        panic!(
            "{:#?}",
            cell.report
                .poses
                .iter()
                .map(|p| &p.problems)
                .collect::<Vec<_>>()
        )
    });
    assert_eq!(validated.len(), free_joints.len());
    for (pose, q) in &validated {
        assert!(inside(q, &ranges), "{q:?} leaves the ranges");
        // The same flange pose (so the same view), reached by another joint solution where the
        // free one turned wrist 3 below zero.
        assert!(
            (cell.arm.as_ref().unwrap().forward(q).to_homogeneous() - pose.to_homogeneous())
                .abs()
                .max()
                < 1e-9
        );
    }
}

/// A range so tight that some generated views cannot be reached: those are refused naming the
/// joint, its value and the key; the rest stay inside.
#[test]
fn views_outside_a_tight_range_are_refused_naming_the_joint() {
    let dir = tempfile::tempdir().unwrap();
    let path = sim_with_ranges(
        dir.path(),
        "[[-360, 360], [-360, 360], [-180, 180], [-360, 360], [-360, 360], [-20, 20]]",
    );
    let cell = handeye_session::cell::prepare(&path).unwrap();
    let ranges = cell
        .config
        .robot
        .joint_ranges_deg(cell.config.camera().setup);
    let mut refused = 0;
    for p in &cell.report.poses {
        match p.joints {
            Some(q) => assert!(inside(&q, &ranges), "{q:?}"),
            None => {
                refused += 1;
                let message = p.problems.join("; ");
                assert!(
                    message.contains("reachable only with joint 6 (wrist 3) at ")
                        && message
                            .contains("outside its range [-20, 20]° (robot.joint_ranges_deg[5])"),
                    "{message}"
                );
            }
        }
    }
    assert!(refused > 0, "no generated view needed wrist 3 beyond ±20°");
    assert!(!cell.report.ok());
}

/// The issue's template plan swung wrist 3 to 280°: a scripted joint waypoint like that is
/// refused under the flange-camera defaults, naming the joint and its value.
#[test]
fn a_scripted_pose_outside_the_range_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let flange = FLANGE_CAMERA_JOINT_RANGES_DEG
        .map(|[lo, hi]| format!("[{lo}, {hi}]"))
        .join(", ");
    let path = sim_with_ranges(dir.path(), &format!("[{flange}]"));
    let cell = handeye_session::cell::prepare(&path).unwrap();
    let plan = Plan {
        waypoints: vec![
            Waypoint::Joints(Joints::from(
                [0.0, -90.0, 90.0, -90.0, -90.0, 170.0].map(f64::to_radians),
            )),
            Waypoint::Joints(Joints::from(
                [0.0, -90.0, 90.0, -90.0, -90.0, 280.0].map(f64::to_radians),
            )),
        ],
    };
    let report = cell.check_plan(&plan);
    assert!(report.poses[0].joints.is_some());
    assert!(!report.poses[0]
        .problems
        .iter()
        .any(|p| p.contains("joint range")));
    assert_eq!(report.poses[1].joints, None);
    assert_eq!(
        report.poses[1].problems[0],
        "outside the joint ranges: its joints put joint 6 (wrist 3) at 280.0°, outside its range [-180, 180]° (robot.joint_ranges_deg[5])"
    );
    assert!(report.validated().is_none());
}

#[test]
fn a_real_flange_camera_gets_cable_friendly_ranges_by_default() {
    let ur = |setup| {
        let robot: RobotConfig =
            serde_yaml_ng::from_str("{backend: ur, host: 192.168.1.10, model: ur5e}").unwrap();
        robot.joint_ranges_deg(setup)
    };
    assert_eq!(ur(Setup::EyeInHand), FLANGE_CAMERA_JOINT_RANGES_DEG);
    assert_eq!(ur(Setup::EyeToHand), ARM_JOINT_RANGES_DEG);
    assert_eq!(FLANGE_CAMERA_JOINT_RANGES_DEG[5], [-180.0, 180.0]);
    // The arm's own ranges are the kinematics' limits.
    let arm = UrModel::ur5e();
    for (deg, rad) in ARM_JOINT_RANGES_DEG.iter().zip(arm.joint_limits) {
        assert_eq!((deg[0].to_radians(), deg[1].to_radians()), rad);
    }
}

fn load_error(path: &Path) -> String {
    match CellConfig::load(path) {
        Ok(_) => panic!("{} loaded", path.display()),
        Err(e) => format!("{:#}", anyhow::Error::new(e)),
    }
}

#[test]
fn bad_joint_ranges_are_refused_at_load() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            "[[-360, 360], [-360, 360], [-180, 180], [-360, 360], [-360, 360], [90, -90]]",
            "robot.joint_ranges_deg[5]: wrist 3 range [90, -90] °: expected min < max",
        ),
        (
            "[[-360, 360], [-360, 360], [-200, 180], [-360, 360], [-360, 360], [-180, 180]]",
            "robot.joint_ranges_deg[2][0]: expected a value in [-180, 180] °, found -200",
        ),
        (
            "[[-360, 360], [-360, 360], [-180, 180], [-360, 360], [-360, 360], [10, 180]]",
            "robot.start_joints_deg[5]: expected a value inside the wrist 3 joint range [10, 180] ° (robot.joint_ranges_deg[5]), found 0",
        ),
    ];
    for (ranges, expected) in cases {
        let path = sim_with_ranges(dir.path(), ranges);
        let message = load_error(&path);
        assert!(message.contains(expected), "{message}");
        assert!(message.contains(&path.display().to_string()), "{message}");
    }
    // Five pairs instead of six is a shape error at the key.
    let path = sim_with_ranges(dir.path(), "[[-1, 1], [-1, 1], [-1, 1], [-1, 1], [-1, 1]]");
    assert!(load_error(&path).contains("robot"), "{}", load_error(&path));
}

/// A resumed or adaptive run moves in another order than the check saw: every move is held to
/// the ranges right before it is sent, and moving back in from outside is allowed.
#[test]
fn every_move_is_held_to_the_ranges() {
    let mut arm = UrModel::ur5e();
    arm.joint_limits =
        FLANGE_CAMERA_JOINT_RANGES_DEG.map(|[lo, hi]| (lo.to_radians(), hi.to_radians()));
    let check = handeye_plan::check::MoveCheck::with_model(
        arm,
        handeye_robot::WorkspaceBox {
            min: Vector3::new(-2.0, -2.0, -2.0),
            max: Vector3::new(2.0, 2.0, 2.0),
        },
    );
    let home = Joints::from([0.0, -90.0, 90.0, -90.0, -90.0, 0.0].map(f64::to_radians));
    let wound = Joints::from([0.0, -90.0, 90.0, -90.0, -90.0, 280.0].map(f64::to_radians));
    assert_eq!(check.problem(&home, &home), None);
    assert_eq!(
        check.problem(&home, &wound).as_deref(),
        Some("the move puts joint 6 (wrist 3) at 280.0°, outside its range [-180, 180]° (robot.joint_ranges_deg[5])")
    );
    assert_eq!(check.problem(&wound, &home), None);
}

// ---- printing the board ----------------------------------------------------------------

const PT_PER_MM: f64 = 72.0 / 25.4;

fn six_by_six() -> Board {
    Board::load(&util::repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap()
}

/// The numbers of the PDF's `/MediaBox [x0 y0 x1 y1]`, pt.
fn media_box(pdf: &str) -> [f64; 4] {
    let at = pdf.find("/MediaBox [").expect("no MediaBox") + "/MediaBox [".len();
    let end = at + pdf[at..].find(']').unwrap();
    let v: Vec<f64> = pdf[at..end]
        .split_whitespace()
        .map(|t| t.parse().unwrap())
        .collect();
    v.try_into().unwrap()
}

/// Every `x y w h re` rectangle of the (uncompressed) content stream, pt.
fn rectangles(pdf: &str) -> Vec<[f64; 4]> {
    let tokens: Vec<&str> = pdf.split_whitespace().collect();
    tokens
        .windows(5)
        .filter(|w| w[4] == "re")
        .map(|w| std::array::from_fn(|i| w[i].parse().unwrap()))
        .collect()
}

/// #14: the 6x6 board (310 x 335 mm with its caption strip) fits no A4 sheet at its size; fitted,
/// its tags shrink to fill the printable area, the PDF page is the sheet, every black cell lies
/// inside the margins, and the widest black run (a tag's top border row) is the reported tag size.
#[test]
fn a_board_fitted_to_a4_fills_the_sheet_inside_the_margin() {
    let board = six_by_six();
    let extent = board.extent();
    let (w, h) = (extent.max.x - extent.min.x, extent.max.y - extent.min.y);
    assert!(
        w > 0.19 && h > 0.19,
        "the issue's board fits A4 as it is: {w} x {h} m"
    );

    let fitted = fit_to_paper(&board, Paper::A4, 0.010).unwrap();
    assert!(!fitted.sheet.landscape);
    let tag = fitted.board.aprilgrid().unwrap().tag_size();
    assert!(tag < board.tag_size() && tag > 0.02, "{tag}");
    // Whole tenths of a millimetre, and the largest such size: 0.1 mm more no longer fits.
    assert_eq!((tag * 1e4).round() / 1e4, tag);
    let fe = fitted.board.extent();
    let fw = fe.max.x - fe.min.x;
    assert!(
        fw <= 0.190 + 1e-12 && fw * (tag + 1e-4) / tag > 0.190,
        "{fw}"
    );
    assert_eq!(
        (
            fitted.board.aprilgrid().unwrap().cols(),
            fitted.board.aprilgrid().unwrap().rows(),
            fitted.board.aprilgrid().unwrap().tag_spacing()
        ),
        (board.cols(), board.rows(), board.tag_spacing())
    );

    let pdf = board_pdf(&fitted.board, Some(&fitted.sheet)).unwrap();
    assert!(pdf.starts_with(b"%PDF-"));
    let text = String::from_utf8_lossy(&pdf);
    let [x0, y0, x1, y1] = media_box(&text);
    assert_eq!((x0, y0), (0.0, 0.0));
    assert!((x1 - 210.0 * PT_PER_MM).abs() < 0.01 && (y1 - 297.0 * PT_PER_MM).abs() < 0.01);
    let margin = 10.0 * PT_PER_MM;
    let rects = rectangles(&text);
    assert!(rects.len() > 36 * 10, "{} rectangles", rects.len());
    for [x, y, w, h] in &rects {
        assert!(
            *x >= margin - 1e-3
                && *y >= margin - 1e-3
                && x + w <= x1 - margin + 1e-3
                && y + h <= y1 - margin + 1e-3,
            "rectangle {x} {y} {w} {h} leaves the printable area"
        );
    }
    // The scale bar's blocks and outline are 2 mm tall; every other rectangle is a run of cells.
    let bar = 2.0 * PT_PER_MM;
    let widest = rects
        .iter()
        .filter(|r| (r[3] - bar).abs() > 1e-3)
        .map(|r| r[2])
        .fold(0.0, f64::max);
    assert!(
        (widest - tag * 1000.0 * PT_PER_MM).abs() < 1e-3,
        "{widest} pt vs tag {tag} m"
    );
    assert!(
        text.contains(&format!("tagSize {tag} m")),
        "the caption names the tag size"
    );
    assert!(text.contains("print at actual size"));
}

#[test]
fn larger_paper_gives_larger_tags_and_a_small_board_is_scaled_up() {
    let board = six_by_six();
    let a4 = fit_to_paper(&board, Paper::A4, 0.01)
        .unwrap()
        .board
        .aprilgrid()
        .unwrap()
        .tag_size();
    let letter = fit_to_paper(&board, Paper::Letter, 0.01)
        .unwrap()
        .board
        .aprilgrid()
        .unwrap()
        .tag_size();
    let a3 = fit_to_paper(&board, Paper::A3, 0.01)
        .unwrap()
        .board
        .aprilgrid()
        .unwrap()
        .tag_size();
    assert!(a4 < letter && letter < a3, "{a4} {letter} {a3}");
    // A wide 6x2 board goes landscape.
    let wide = Board::aprilgrid(6, 2, 0.01, 0.25, TagFamily::Tag36h11, 0, 2).unwrap();
    let fitted = fit_to_paper(&wide, Paper::A4, 0.01).unwrap();
    assert!(fitted.sheet.landscape && fitted.board.aprilgrid().unwrap().tag_size() > 0.03);
    // Margins out of range and boards that would need tiny tags are refused.
    let e = fit_to_paper(&board, Paper::A4, 0.2)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("margin-mm") && e.contains("[0, 50] mm") && e.contains("200 mm"),
        "{e}"
    );
    let many = Board::aprilgrid(24, 24, 0.02, 0.25, TagFamily::Tag36h11, 0, 2).unwrap();
    let e = fit_to_paper(&many, Paper::A4, 0.05)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("24x24") && e.contains("on A4") && e.contains("at least 5 mm"),
        "{e}"
    );
    // A board that does not fit the sheet is refused by the PDF writer, not clipped.
    let sheet = fit_to_paper(&board, Paper::A4, 0.01).unwrap().sheet;
    assert!(board_pdf(&board, Some(&sheet)).is_err());
}

#[test]
fn the_fitted_board_file_keeps_everything_but_the_tag_size() {
    let path = util::repo().join("configs/targets/aprilgrid-6x6.yaml");
    let original = std::fs::read_to_string(&path).unwrap();
    let fitted = fit_to_paper(&six_by_six(), Paper::Letter, 0.008).unwrap();
    let yaml = resized_board_yaml(&original, &path, &fitted.board, "Fitted to the paper").unwrap();
    // The first line says the file's size is the fitted one (the original's comments may give
    // another); then the original, its tag size rewritten.
    let (header, rest) = yaml.split_once('\n').unwrap();
    let tag_size = fitted.board.aprilgrid().unwrap().tag_size();
    assert!(
        header.starts_with("# Fitted to the paper")
            && header.contains(&format!("tagSize: {tag_size}"))
            && header.contains("aprilgrid-6x6.yaml"),
        "{header}"
    );
    let changed: Vec<(&str, &str)> = original
        .lines()
        .zip(rest.lines())
        .filter(|(a, b)| a != b)
        .collect();
    assert_eq!(
        changed,
        vec![(
            "tagSize: 0.04",
            &*format!("tagSize: {}", fitted.board.aprilgrid().unwrap().tag_size())
        )]
    );
    let back = Board::from_yaml_str(&yaml, &path).unwrap();
    assert_eq!(
        back.tag_size(),
        fitted.board.aprilgrid().unwrap().tag_size()
    );
}

/// With poppler's `pdftoppm` on the machine, the fitted PDF is rasterised at 150 dpi and the
/// detector finds all 36 tags on it (skipped, saying so, without it).
#[test]
fn the_pdf_renders_and_its_tags_are_detected() {
    let dir = tempfile::tempdir().unwrap();
    let fitted = fit_to_paper(&six_by_six(), Paper::A4, 0.01).unwrap();
    let file = dir.path().join("board.pdf");
    std::fs::write(
        &file,
        board_pdf(&fitted.board, Some(&fitted.sheet)).unwrap(),
    )
    .unwrap();
    let rendered = std::process::Command::new("pdftoppm")
        .args(["-r", "150", "-gray", "-png", "-singlefile"])
        .arg(&file)
        .arg(dir.path().join("page"))
        .output();
    match rendered {
        Ok(out) if out.status.success() => {}
        Ok(out) => panic!(
            "pdftoppm refused the PDF: {}",
            String::from_utf8_lossy(&out.stderr)
        ),
        Err(e) => {
            eprintln!("pdftoppm not available ({e}): rendering check skipped");
            return;
        }
    }
    let image = image::open(dir.path().join("page.png"))
        .unwrap()
        .into_luma8();
    // A4 at 150 dpi: 1240.2 x 1753.9 px, rounded either way.
    assert!(image.width().abs_diff(1240) <= 1 && image.height().abs_diff(1754) <= 1);
    let detector = TagDetector::spawn(
        fitted.board.aprilgrid().unwrap(),
        DetectorOptions::default(),
    )
    .unwrap();
    let detection = detector.detect(&image).unwrap();
    assert_eq!(detection.tags.len(), 36);
}

// ---- templates for a real cell ---------------------------------------------------------------

const TEMPLATES: [&str; 2] = [
    "ur-usb-camera-eye-in-hand.yaml",
    "ur-usb-camera-eye-to-hand.yaml",
];

/// Both templates load, name a real arm and a USB camera, and no longer point at the simulated
/// camera's intrinsics (#14): their lens file is a placeholder that says so.
#[test]
fn the_templates_load_without_the_simulated_lens() {
    for (name, setup) in TEMPLATES.iter().zip([Setup::EyeInHand, Setup::EyeToHand]) {
        let path = util::repo().join("configs").join(name);
        let config = CellConfig::load(&path).unwrap_or_else(|e| panic!("{name}: {e:#}"));
        assert_eq!(config.camera().setup, setup, "{name}");
        assert!(matches!(config.robot, RobotConfig::Ur(_)), "{name}");
        assert!(
            matches!(
                config.camera().backend,
                handeye_config::CameraConfig::Uvc(_)
            ),
            "{name}"
        );
        let lens = config.camera().intrinsics.as_ref().expect("a lens file");
        assert!(
            !lens.ends_with("sim-1280x720.yaml"),
            "{name} uses the sim camera's lens"
        );
        let text = std::fs::read_to_string(lens).unwrap();
        assert!(
            text.starts_with("# CHANGE: PLACEHOLDER, NOT YOUR CAMERA."),
            "{}",
            lens.display()
        );
        handeye_core::camera_model::CameraModel::load(lens).unwrap();
    }
}

/// Every value a user must change is marked `# CHANGE:`, on its line or in the comment block
/// right above it.
#[test]
fn every_value_to_change_is_marked() {
    let must_change = [
        "target:",
        "intrinsics:",
        "host:",
        "model:",
        "device:",
        "width:",
        "exposure_us:",
        "focus:",
        "workspace:",
    ];
    let per_setup: [&[&str]; 2] = [
        &["T_flange_camera:", "T_base_target:", "joint_ranges_deg:"],
        &["T_base_camera:", "T_flange_target:"],
    ];
    for (name, extra) in TEMPLATES.iter().zip(per_setup) {
        let text = std::fs::read_to_string(util::repo().join("configs").join(name)).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        for key in must_change.iter().chain(extra) {
            let at = lines
                .iter()
                .position(|l| l.trim_start().starts_with(key))
                .unwrap_or_else(|| panic!("{name}: no `{key}`"));
            let marked = lines[at].contains("# CHANGE:")
                || lines[..at]
                    .iter()
                    .rev()
                    .take_while(|l| l.trim_start().starts_with('#'))
                    .any(|l| l.contains("CHANGE:"));
            assert!(marked, "{name}: `{key}` is not marked `# CHANGE:`");
        }
    }
}

/// The templates' generated plans pass the plan check as shipped (reach, box, board in view),
/// the eye-in-hand one inside the cable-friendly ranges of a flange camera.
#[test]
fn the_template_plans_pass_the_check() {
    for name in TEMPLATES {
        let cell =
            handeye_session::cell::prepare(&util::repo().join("configs").join(name)).unwrap();
        let problems: Vec<_> = cell.report.poses.iter().flat_map(|p| &p.problems).collect();
        assert!(
            cell.report.ok(),
            "{name}: {problems:?} {:?}",
            cell.report.plan_problems
        );
        let ranges = cell
            .config
            .robot
            .joint_ranges_deg(cell.config.camera().setup);
        for (_, q) in cell.report.validated().unwrap() {
            assert!(inside(&q, &ranges), "{name}: {q:?}");
        }
    }
    let in_hand = CellConfig::load(&util::repo().join("configs").join(TEMPLATES[0])).unwrap();
    assert_eq!(
        in_hand.robot.joint_ranges_deg(in_hand.camera().setup),
        FLANGE_CAMERA_JOINT_RANGES_DEG
    );
}

/// The A4 board the templates use is what `--paper a4` makes of the 6x6 grid, and fitting it
/// again changes nothing.
#[test]
fn the_a4_board_is_the_fitted_6x6_grid() {
    let a4 = Board::load(&util::repo().join("configs/targets/aprilgrid-6x6-a4.yaml")).unwrap();
    let fitted = fit_to_paper(&six_by_six(), Paper::A4, 0.01).unwrap();
    assert_eq!(a4.tag_size(), fitted.board.aprilgrid().unwrap().tag_size());
    assert_eq!(
        fit_to_paper(&a4, Paper::A4, 0.01)
            .unwrap()
            .board
            .aprilgrid()
            .unwrap()
            .tag_size(),
        a4.tag_size()
    );
}

/// The command line: `--paper` writes the PDF, says the tag size to enter, and refuses a PNG.
#[test]
fn target_render_with_paper_reports_the_tag_size() {
    let dir = tempfile::tempdir().unwrap();
    let board = util::repo().join("configs/targets/aprilgrid-6x6.yaml");
    let run = |output: &str| {
        std::process::Command::new(env!("CARGO_BIN_EXE_handeye"))
            .args([
                "target",
                "render",
                "--paper",
                "letter",
                "--margin-mm",
                "5",
                "--board",
            ])
            .arg(&board)
            .arg("-o")
            .arg(dir.path().join(output))
            .output()
            .unwrap()
    };
    let ok = run("board.pdf");
    let stdout = String::from_utf8_lossy(&ok.stdout);
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let fitted = fit_to_paper(&six_by_six(), Paper::Letter, 0.005).unwrap();
    let tag = fitted.board.aprilgrid().unwrap().tag_size();
    assert!(
        stdout.contains(&format!(
            "tagSize: {tag} m (the board file says 0.04 m): enter `tagSize: {tag}` in"
        )),
        "{stdout}"
    );
    assert!(
        stdout.contains("fitted to Letter portrait (216 x 279 mm, 5 mm margins)"),
        "{stdout}"
    );
    let pdf = std::fs::read(dir.path().join("board.pdf")).unwrap();
    let [_, _, w, h] = media_box(&String::from_utf8_lossy(&pdf));
    assert!(
        (w - 612.0).abs() < 0.01 && (h - 792.0).abs() < 0.01,
        "{w} x {h} pt"
    );
    let refused = run("board.png");
    assert!(!refused.status.success());
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains("--paper writes the sheet as a PDF page")
    );
    assert!(!dir.path().join("board.png").exists());
}
