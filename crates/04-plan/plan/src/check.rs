//! Plan validation before anything moves: every pose reachable inside the joint limits by a joint
//! move whose whole path keeps the flange inside the workspace box, the whole board inside the
//! image with a margin at the expected target position, enough rotation diversity for the solver
//! (the solver's own observability rule), and move times at the configured speed limits.
//! [`check_plan_ordered`] also puts the poses in the order of least total move time
//! ([`super::order`]) when that order passes the same checks.

use std::fmt;

use nalgebra::Point3;

use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::{translation_distance, Pose};
use handeye_robot::kinematics::{outside_ranges, UrModel, JOINT_NAMES};
use handeye_robot::{Joints, MotionLimits, WorkspaceBox};
use handeye_vision::Target;

use super::{Plan, Waypoint};
use handeye_core::setup::CellTransforms;

/// Points checked along each joint move (the path in joint space is a straight line).
const PATH_SAMPLES: usize = 16;

/// What the checker needs to know about the cell.
pub struct CheckContext<'a> {
    /// The arm's kinematics (a UR model); `None` for an arm handeye has no model of, whose plan
    /// is taught: its flange poses are the taught ones and its paths are not checked.
    pub arm: Option<&'a UrModel>,
    /// The cell's joint ranges, `(min, max)` rad (`robot.joint_ranges_deg`).
    pub joint_limits: &'a [(f64, f64)],
    /// Where the arm is before the first move.
    pub start_joints: Joints,
    /// Nominal cell transforms.
    pub cell: &'a CellTransforms,
    /// Flange workspace box.
    pub workspace: &'a WorkspaceBox,
    /// Motion limits.
    pub limits: &'a MotionLimits,
    /// Camera intrinsics.
    pub camera: &'a CameraModel,
    /// The board.
    pub board: &'a Target,
    /// Margin between the board and the image border, px.
    pub margin_px: f64,
}

/// The verdict on one plan pose.
#[derive(Debug, Clone)]
pub struct PoseCheck {
    /// Plan index.
    pub index: usize,
    /// The flange pose.
    pub base_from_flange: Pose,
    /// The joint solution reached by the move, if one exists.
    pub joints: Option<Joints>,
    /// Expected camera-to-board distance, m.
    pub distance_m: f64,
    /// Smallest distance from a board corner to the image border, px (negative = outside).
    pub image_margin_px: f64,
    /// Estimated duration of the joint move from the previous pose, s.
    pub move_time_s: f64,
    /// Problems found; empty when the pose is good.
    pub problems: Vec<String>,
}

/// The verdict on a whole plan.
#[derive(Debug, Clone)]
pub struct PlanReport {
    /// One line per pose.
    pub poses: Vec<PoseCheck>,
    /// Problems of the plan as a whole (rotation diversity).
    pub plan_problems: Vec<String>,
    /// Things to know that do not stop the plan (e.g. whether it could also estimate the
    /// intrinsics: tilt variety and image coverage).
    pub notes: Vec<String>,
    /// How well the views constrain the camera intrinsics (`None` when not measured).
    pub intrinsics: Option<handeye_solve::intrinsics::IntrinsicsCoverage>,
    /// When the poses were put in the order of least move time: the total move time of the
    /// plan in its given order, s (the report's own poses are in the order that runs, each
    /// with its plan index).
    pub given_order_move_time_s: Option<f64>,
}

impl PlanReport {
    /// Total move time of the poses in the report's order at the configured limits, s.
    pub fn total_move_time_s(&self) -> f64 {
        // fold from +0.0: `sum` of no poses is -0.0, printed "-0.0 s".
        self.poses
            .iter()
            .fold(0.0, |total, p| total + p.move_time_s)
    }

    /// Whether the plan may run.
    pub fn ok(&self) -> bool {
        self.plan_problems.is_empty() && self.poses.iter().all(|p| p.problems.is_empty())
    }

    /// The validated plan as (flange pose, joints) pairs; `None` if any check failed.
    pub fn validated(&self) -> Option<Vec<(Pose, Joints)>> {
        if !self.ok() {
            return None;
        }
        self.poses
            .iter()
            .map(|p| p.joints.map(|q| (p.base_from_flange, q)))
            .collect()
    }

    /// The poses that pass every check, as (flange pose, joints) pairs, in plan order: for
    /// uses that skip a failing pose instead of refusing the plan (adaptive candidates,
    /// verification views).
    pub fn passing(&self) -> Vec<(Pose, Joints)> {
        self.poses
            .iter()
            .filter(|p| p.problems.is_empty())
            .filter_map(|p| p.joints.map(|q| (p.base_from_flange, q)))
            .collect()
    }
}

/// Checks every pose of `plan` and the plan as a whole.
pub fn check_plan(plan: &Plan, ctx: &CheckContext) -> PlanReport {
    // Units first: look-at distances in mm put every view hundreds of metres out, and each pose
    // would fail on its own ("unreachable", "outside the workspace box"): one message instead.
    if let Some(problem) = distances_in_millimetres(plan) {
        return PlanReport {
            poses: Vec::new(),
            plan_problems: vec![problem],
            notes: Vec::new(),
            intrinsics: None,
            given_order_move_time_s: None,
        };
    }
    let board_points = board_points(ctx.board);
    let centre = board_centre(ctx.board);
    let mut previous = ctx.start_joints;
    let mut poses = Vec::with_capacity(plan.waypoints.len());
    let mut views = Vec::with_capacity(plan.waypoints.len());
    let mut view_pixels = Vec::with_capacity(plan.waypoints.len());
    for (index, waypoint) in plan.waypoints.iter().enumerate() {
        let forward = |q: &Joints| ctx.arm.map(|arm| arm.forward(q));
        // Joints of another arm (a count other than this arm's) have no pose here; joints without
        // a taught pose on an arm without kinematics: nowhere to check.
        let count = waypoint
            .joints()
            .and_then(|q| joint_count_problem(ctx.joint_limits, &q));
        let base_from_flange = match count {
            None => waypoint.flange_pose(ctx.cell, &centre, forward),
            Some(_) => None,
        };
        let Some(base_from_flange) = base_from_flange else {
            let why = count.unwrap_or_else(|| {
                let why = waypoint.needs_kinematics().map_or("", |(_, why)| why);
                why.to_string()
            });
            poses.push(PoseCheck {
                index,
                base_from_flange: Pose::identity(),
                joints: None,
                distance_m: f64::NAN,
                image_margin_px: f64::NEG_INFINITY,
                move_time_s: 0.0,
                problems: vec![why],
            });
            continue;
        };
        let mut problems = Vec::new();
        let joints = match (waypoint.joints(), ctx.arm) {
            (Some(q), _) => joints_fit(ctx.joint_limits, &q).then_some(q),
            (None, Some(arm)) => arm.inverse_nearest(&base_from_flange, &previous),
            (None, None) => None,
        };
        let mut move_time_s = 0.0;
        match joints {
            None => problems.push(unreachable(ctx, waypoint, &base_from_flange, &previous)),
            Some(q) => {
                // Without kinematics the path between taught poses is unknown (a note says so).
                let outside = ctx
                    .arm
                    .and_then(|arm| path_leaves_box(arm, &previous, &q, ctx.workspace));
                if let Some(outside) = outside {
                    problems.push(outside);
                }
                move_time_s = ctx.limits.joint_move_time(&previous, &q);
                previous = q;
            }
        }
        if !ctx.workspace.contains(&base_from_flange) {
            let p = base_from_flange.translation.vector;
            problems.push(format!(
                "flange at [{:.3}, {:.3}, {:.3}] m is outside the workspace box",
                p.x, p.y, p.z
            ));
        }
        let camera_from_target = ctx.cell.camera_from_target(&base_from_flange);
        let distance_m = (camera_from_target * centre).coords.norm();
        let image_margin_px = board_margin(ctx.camera, &camera_from_target, &board_points);
        views.push(camera_from_target);
        view_pixels.push(
            board_points
                .iter()
                .filter_map(|p| ctx.camera.project(&(camera_from_target * p)))
                .collect::<Vec<_>>(),
        );
        if image_margin_px < ctx.margin_px {
            problems.push(if image_margin_px == f64::NEG_INFINITY {
                "board is behind the camera".to_string()
            } else {
                let fits = match fitting_distance(ctx, &camera_from_target, &board_points, &centre) {
                    Some(d) => format!("; this view fits from {d:.2} m (now {distance_m:.2} m)"),
                    None => "; no distance fits: the view aims the board's centre too near the image border".into(),
                };
                format!(
                    "{NOT_INSIDE} with {:.0} px margin (closest corner {:.0} px from the border){fits}",
                    ctx.margin_px, image_margin_px
                )
            });
        }
        poses.push(PoseCheck {
            index,
            base_from_flange,
            joints,
            distance_m,
            image_margin_px,
            move_time_s,
            problems,
        });
    }
    let flange_poses: Vec<Pose> = poses.iter().map(|p| p.base_from_flange).collect();
    let mut plan_problems = Vec::new();
    if let Err(e) = handeye_solve::check_rotation_diversity(&flange_poses) {
        plan_problems.push(e.to_string());
    }
    let coverage = handeye_solve::intrinsics::IntrinsicsCoverage::measure(
        &views,
        &view_pixels,
        ctx.camera.width,
        ctx.camera.height,
    );
    let mut notes = match coverage.problem() {
        Some(problem) => vec![format!(
            "{problem} (fine when the intrinsics are known; needed when the config has none)"
        )],
        None => vec![format!(
            "the views also constrain the camera intrinsics ({} tilted views, tilt axes {:.0}° apart, {:.0} % image coverage)",
            coverage.tilted_views, coverage.tilt_direction_spread_deg, coverage.coverage_percent
        )],
    };
    match ctx.arm {
        None => notes.push(NO_KINEMATICS_NOTE.into()),
        Some(arm) => notes.extend(calibrated_model_note(arm, &poses)),
    }
    if poses
        .iter()
        .any(|p| p.problems.iter().any(|m| m.starts_with(NOT_INSIDE)))
    {
        let head_on = Pose::from_parts(
            // The board's centre 5 cm in front of the camera, facing it: the search goes out
            // from there.
            nalgebra::Translation3::new(-centre.x, -centre.y, 0.05 - centre.z),
            nalgebra::UnitQuaternion::identity(),
        );
        if let Some(d) = fitting_distance(ctx, &head_on, &board_points, &centre) {
            notes.push(format!(
                "this lens sees the whole board, head-on and centred, from {d:.2} m with a {:.0} px margin: views nearer than that cannot hold it",
                ctx.margin_px
            ));
        }
    }
    PlanReport {
        poses,
        plan_problems,
        notes,
        intrinsics: Some(coverage),
        given_order_move_time_s: None,
    }
}

/// With a calibrated model of the arm (`solver.arm_model`): the plan is checked and its moves
/// solved through it, so the flange goes to the planned poses, and the controller, computing
/// through its published model, reports them somewhat off (the solve corrects them back): how
/// far, over the poses that reach.
fn calibrated_model_note(arm: &UrModel, poses: &[PoseCheck]) -> Option<String> {
    let published = arm.published();
    if *arm == published {
        return None;
    }
    let apart_mm: Vec<f64> = poses
        .iter()
        .filter_map(|p| {
            let q = p.joints.as_ref()?;
            Some(translation_distance(&published.forward(q), &p.base_from_flange) * 1e3)
        })
        .collect();
    if apart_mm.is_empty() {
        return None;
    }
    let mean = apart_mm.iter().sum::<f64>() / apart_mm.len() as f64;
    let max = apart_mm.iter().copied().fold(0.0, f64::max);
    Some(format!(
        "the moves are solved through the {} model as an earlier session estimated it (solver.arm_model), so the flange goes to the planned poses; the controller, computing through the published model, will report them {mean:.2} mm mean ({max:.2} max) from there, which the solve corrects",
        arm.name
    ))
}

/// Checks `plan` as [`check_plan`] does and, when `reorder`, also in the order of least total
/// move time from the start joints (every move of that order checked against the joint ranges
/// and the workspace box); returns the report of the order that will run: the reordered one
/// when it passes every check the given order passes and saves time, else the given order.
/// Either way `given_order_move_time_s` holds the given order's move time when `reorder`.
pub fn check_plan_ordered(plan: &Plan, ctx: &CheckContext, reorder: bool) -> PlanReport {
    let mut given = check_plan(plan, ctx);
    if !reorder {
        return given;
    }
    let given_time = given.total_move_time_s();
    given.given_order_move_time_s = Some(given_time);
    let Some(joints) = given
        .poses
        .iter()
        .map(|p| p.joints)
        .collect::<Option<Vec<Joints>>>()
    else {
        // An unreachable pose: the plan fails anyway (or, adaptive, is chosen from freely).
        return given;
    };
    let mover = MoveCheck {
        arm: ctx.arm.cloned(),
        joint_limits: ctx.joint_limits.to_vec(),
        workspace: *ctx.workspace,
    };
    let order = super::order::order_for_travel(&ctx.start_joints, &joints, |a, b| {
        mover.safe_move_time(a, b, ctx.limits)
    });
    if order.iter().enumerate().all(|(k, &i)| k == i) {
        return given;
    }
    let reordered_plan = Plan {
        waypoints: order.iter().map(|&i| plan.waypoints[i].clone()).collect(),
    };
    let mut reordered = check_plan(&reordered_plan, ctx);
    for (check, &i) in reordered.poses.iter_mut().zip(&order) {
        check.index = i;
    }
    let failing = |r: &PlanReport| r.poses.iter().filter(|p| !p.problems.is_empty()).count();
    let no_worse = failing(&reordered) <= failing(&given)
        && reordered.plan_problems.len() <= given.plan_problems.len();
    if no_worse && reordered.total_move_time_s() < given_time {
        reordered.given_order_move_time_s = Some(given_time);
        reordered
    } else {
        given
    }
}

/// When every look-at distance of the plan lies beyond the generator's limit
/// (`plan::generate::MAX_DISTANCE_M`) but within it divided by 1000, the plan was written in
/// millimetres: the message names the first such waypoint's key and the value in metres.
fn distances_in_millimetres(plan: &Plan) -> Option<String> {
    let limit = super::generate::MAX_DISTANCE_M;
    let distances: Vec<(usize, f64)> = plan
        .waypoints
        .iter()
        .enumerate()
        .filter_map(|(i, w)| match w {
            Waypoint::LookAt(view) => Some((i, view.distance)),
            _ => None,
        })
        .collect();
    let &(first, distance) = distances.first()?;
    distances
        .iter()
        .all(|(_, d)| *d > limit && *d / 1000.0 <= limit)
        .then(|| {
            format!(
                "waypoints[{first}].look_at.distance: {distance} looks like millimetres (as do all {} look-at distances): as metres the camera would view the board from {distance} m, where views lie within {limit} m; plan files take metres: write {}",
                distances.len(),
                (distance * 1e6).round() / 1e9
            )
        })
}

/// What the plan check of an arm without kinematics (`robot.model: none`) cannot check.
pub const NO_KINEMATICS_NOTE: &str = "robot.model: none: the taught flange poses are checked (workspace box, board in view, rotation spread), the joint paths between them are not (no kinematics): each move is a straight line in joint space between taught joints at the configured limits, so teach the poses in an order whose paths are clear";

/// Why a waypoint has no joint solution: the joint that leaves its range and its value when the
/// arm could reach the pose with its own limits (or the scripted joints break a range), else
/// plain unreachability (or, without kinematics, why the waypoint needs them).
fn unreachable(ctx: &CheckContext, waypoint: &Waypoint, pose: &Pose, previous: &Joints) -> String {
    let nearest = match (waypoint.joints(), ctx.arm) {
        (Some(q), _) => Some(q),
        (None, Some(arm)) => arm.with_arm_limits().inverse_nearest(pose, previous),
        (None, None) => {
            let why = waypoint.needs_kinematics().map_or("", |(_, why)| why);
            return why.to_string();
        }
    };
    if let Some(count) = nearest.and_then(|q| joint_count_problem(ctx.joint_limits, &q)) {
        return count;
    }
    let Some((i, value)) = nearest.and_then(|q| outside_ranges(ctx.joint_limits, &q)) else {
        return match ctx.arm {
            Some(arm) => beyond_reach(arm, pose),
            None => "unreachable: no inverse-kinematics solution inside the joint limits".into(),
        };
    };
    let how = match waypoint.joints() {
        Some(_) => "its joints put",
        None => "reachable only with",
    };
    format!(
        "outside the joint ranges: {how} {}",
        joint_outside(ctx.joint_limits, ctx.arm.is_some(), i, value)
    )
}

/// How a view's board-outside-the-image problem starts.
const NOT_INSIDE: &str = "board not fully inside the image";

/// The nearest distance (camera to board centre, m) at which the view `camera_from_target`
/// holds the whole board with the margin `ctx` asks, moving the board along the line of sight
/// through its centre (the view's direction and tilt kept), up to 10 m; `None` when no distance
/// does (the centre itself too near the border).
fn fitting_distance(
    ctx: &CheckContext,
    camera_from_target: &Pose,
    points: &[Point3<f64>],
    centre: &Point3<f64>,
) -> Option<f64> {
    let ray = (camera_from_target * centre).coords;
    let distance = ray.norm();
    if distance.is_nan() || distance <= 0.0 {
        return None;
    }
    let at = |d: f64| {
        let shift = ray * (d / distance - 1.0);
        let moved = Pose::from_parts(
            (camera_from_target.translation.vector + shift).into(),
            camera_from_target.rotation,
        );
        board_margin(ctx.camera, &moved, points) >= ctx.margin_px
    };
    // The margin grows with distance once the board is in front: the first 1 cm step that fits,
    // from where the view stands (a view that does not fit now fits only farther out).
    let far = 10.0;
    let mut d = distance.min(far);
    while d <= far {
        if at(d) {
            return Some(d);
        }
        d += 0.01;
    }
    None
}

/// Why a flange pose has no inverse-kinematics solution at all (with the arm's own joint
/// limits): its wrist centre (the flange origin `d6` back along the tool axis) beyond what the
/// upper arm and forearm span from the shoulder — out of reach, with the figures — or within
/// that span (too near the arm's own base axis, or a singular wrist).
fn beyond_reach(arm: &UrModel, pose: &Pose) -> String {
    let wrist = pose * Point3::new(0.0, 0.0, -arm.d[5]);
    let shoulder = Point3::new(0.0, 0.0, arm.d[0]);
    let distance = (wrist - shoulder).norm();
    // The wrist centre moves on a sphere of up to |a2| + |a3| about the shoulder, offset
    // sideways by the wrist's own link d4.
    let span = (arm.a[1].abs() + arm.a[2].abs()).hypot(arm.d[3]);
    if distance > span {
        format!(
            "out of the {}'s reach: its wrist centre would be {distance:.2} m from the shoulder, the arm spans {span:.2} m (bring the view nearer the base)",
            arm.name
        )
    } else {
        format!(
            "no inverse-kinematics solution although within the {}'s reach ({distance:.2} m of {span:.2} m from the shoulder): too near the base axis or at a wrist singularity",
            arm.name
        )
    }
}

/// Joints of another arm: a count other than the arm's (one range per joint in `limits`).
fn joint_count_problem(limits: &[(f64, f64)], joints: &Joints) -> Option<String> {
    (joints.len() != limits.len()).then(|| {
        format!(
            "{} joints named, but the arm has {} (robot.joint_names, robot.joint_ranges_deg): a plan taught on one arm replays only on an arm with the same joints",
            joints.len(),
            limits.len()
        )
    })
}

/// Whether `joints` fit this arm: its joint count, each joint inside its range.
fn joints_fit(limits: &[(f64, f64)], joints: &Joints) -> bool {
    joint_count_problem(limits, joints).is_none() && outside_ranges(limits, joints).is_none()
}

/// `joint 2 (shoulder) at -190.0°, outside its range [-180, 180]° (robot.joint_ranges_deg[1])`
/// (the UR joint's name only for a UR model).
fn joint_outside(limits: &[(f64, f64)], ur: bool, i: usize, value: f64) -> String {
    let (lo, hi) = limits[i];
    let name = match JOINT_NAMES.get(i) {
        Some(name) if ur => format!(" ({name})"),
        _ => String::new(),
    };
    format!(
        "joint {}{name} at {:.1}°, outside its range [{:.0}, {:.0}]° (robot.joint_ranges_deg[{i}])",
        i + 1,
        value.to_degrees(),
        lo.to_degrees(),
        hi.to_degrees()
    )
}

/// The middle of the board's outline, in the target frame (the point look-at views aim at).
pub fn board_centre(board: &Target) -> Point3<f64> {
    let extent = board.extent();
    Point3::new(
        (extent.min.x + extent.max.x) / 2.0,
        (extent.min.y + extent.max.y) / 2.0,
        0.0,
    )
}

/// What every move of a run is checked against right before it is sent: the plan check saw the
/// moves in plan order, but a resumed run, a retry or an adaptive plan moves in another order,
/// and after a stop the arm may stand anywhere.
#[derive(Debug, Clone, PartialEq)]
pub struct MoveCheck {
    /// The arm's kinematics; `None` for an arm handeye has no model of (its path is not known).
    pub arm: Option<UrModel>,
    /// The cell's joint ranges, `(min, max)` rad: one per joint of the arm.
    pub joint_limits: Vec<(f64, f64)>,
    /// The box the flange must stay in along the whole joint move.
    pub workspace: WorkspaceBox,
}

impl MoveCheck {
    /// The check of a UR model's moves: its joint limits, its kinematics, `workspace`.
    pub fn with_model(arm: UrModel, workspace: WorkspaceBox) -> MoveCheck {
        MoveCheck {
            joint_limits: arm.joint_limits.to_vec(),
            arm: Some(arm),
            workspace,
        }
    }

    /// Why the straight joint move `from` → `to` is not safe, if it is not: `to` outside the
    /// arm's joint ranges (the cell's `robot.joint_ranges_deg`), or the path leaving the box.
    /// `from` may lie outside the ranges (the arm stands where it was left): moving back in is
    /// allowed.
    pub fn problem(&self, from: &Joints, to: &Joints) -> Option<String> {
        if let Some(count) = joint_count_problem(&self.joint_limits, to) {
            return Some(count);
        }
        if let Some((i, value)) = outside_ranges(&self.joint_limits, to) {
            return Some(format!(
                "the move puts {}",
                joint_outside(&self.joint_limits, self.arm.is_some(), i, value)
            ));
        }
        let arm = self.arm.as_ref()?;
        path_leaves_box(arm, from, to, &self.workspace)
    }

    /// The time of the joint move `from` → `to` at `limits` (s) when it is safe, `None` when
    /// [`Self::problem`] finds it is not: the cost the travel-time order minimises.
    pub fn safe_move_time(&self, from: &Joints, to: &Joints, limits: &MotionLimits) -> Option<f64> {
        self.problem(from, to)
            .is_none()
            .then(|| limits.joint_move_time(from, to))
    }
}

/// The first point of a straight joint-space move that leaves the box, as a message.
fn path_leaves_box(
    arm: &UrModel,
    from: &Joints,
    to: &Joints,
    workspace: &WorkspaceBox,
) -> Option<String> {
    (0..=PATH_SAMPLES).find_map(|k| {
        let s = k as f64 / PATH_SAMPLES as f64;
        let q = Joints::from_fn(to.len(), |j| from[j] + (to[j] - from[j]) * s);
        let pose = arm.forward(&q);
        (!workspace.contains(&pose)).then(|| {
            let p = pose.translation.vector;
            format!(
                "the joint move leaves the workspace box at {:.0} % of the way ([{:.3}, {:.3}, {:.3}] m)",
                s * 100.0,
                p.x,
                p.y,
                p.z
            )
        })
    })
}

/// Every corner of the board (tag corners of an aprilgrid), in the target frame.
pub fn board_points(board: &Target) -> Vec<Point3<f64>> {
    board.points().into_iter().map(|(_, _, p)| p).collect()
}

/// Smallest distance from any board point's projection to the image border (px); −∞ if a point
/// is behind the camera.
pub fn board_margin(
    camera: &CameraModel,
    camera_from_target: &Pose,
    points: &[Point3<f64>],
) -> f64 {
    let (w, h) = (camera.width as f64, camera.height as f64);
    points
        .iter()
        .map(|p| match camera.project(&(camera_from_target * p)) {
            None => f64::NEG_INFINITY,
            // Pixel centres are integers: the image spans [-0.5, w - 0.5].
            Some(px) => (px.x + 0.5)
                .min(w - 0.5 - px.x)
                .min(px.y + 0.5)
                .min(h - 0.5 - px.y),
        })
        .fold(f64::INFINITY, f64::min)
}

impl fmt::Display for PlanReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{:>4}  {:>24}  {:>35}  {:>8}  {:>9}  {:>6}  status",
            "pose", "flange xyz (m)", "joints (deg)", "dist (m)", "margin px", "move s"
        )?;
        for p in &self.poses {
            let t = p.base_from_flange.translation.vector;
            let status = if p.problems.is_empty() {
                "ok".to_string()
            } else {
                p.problems.join("; ")
            };
            let joints = match p.joints {
                Some(q) => q
                    .iter()
                    .map(|v| format!("{:.0}", v.to_degrees()))
                    .collect::<Vec<_>>()
                    .join(", "),
                None => "-".into(),
            };
            writeln!(
                f,
                "{:>4}  [{:>6.3}, {:>6.3}, {:>6.3}]  {:>35}  {:>8.3}  {:>9.0}  {:>6.2}  {}",
                p.index,
                t.x,
                t.y,
                t.z,
                joints,
                p.distance_m,
                p.image_margin_px,
                p.move_time_s,
                status
            )?;
        }
        for problem in &self.plan_problems {
            writeln!(f, "plan: {problem}")?;
        }
        for note in &self.notes {
            writeln!(f, "note: {note}")?;
        }
        let total = self.total_move_time_s();
        let given = match self.given_order_move_time_s {
            Some(given) => format!(" ({given:.1} s in the given order)"),
            None => " at the configured limits".to_string(),
        };
        write!(
            f,
            "{} poses, {} with problems; total move time {:.1} s{} — {}",
            self.poses.len(),
            self.poses.iter().filter(|p| !p.problems.is_empty()).count(),
            total,
            given,
            if self.ok() {
                "plan OK"
            } else {
                "plan REJECTED"
            }
        )
    }
}
