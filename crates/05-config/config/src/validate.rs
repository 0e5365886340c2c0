//! Validation of a cell config's values: the accepted range of every numeric key (the constants
//! below, documented in the README) and the cross-field rules (the setup's transform names, one
//! plan source, ground truth for the sim backends, joint ranges inside the arm's and a sim arm's
//! start inside them). Runs at load, before any folder is created or
//! anything moves; every error names the file, the YAML key path, the value and what is
//! accepted. Works on the shapes of `config::schema`; depends on `plan` and `vision` for the
//! bounds they own (plan size, detector options).
//!
//! Why one file of ~620 lines: every accepted range sits next to the check that applies it, in
//! the order of the schema, so the README's range table and this file can be read side by side.

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;
use std::time::Duration;

use nalgebra::Vector3;

use super::schema::{
    ArmErrorsFile, CameraConfig, ConfigFile, KinematicsChoice, RobotConfig, ARM_JOINT_RANGES_DEG,
    JOINT_NAMES,
};
use super::ConfigError;
use handeye_core::geometry::{readable, PoseYaml};
use handeye_core::setup::{CellTransforms, Setup};
use handeye_robot::arm_errors::{ArmErrorSigmas, ArmErrors};
use handeye_robot::{MotionLimits, WorkspaceBox};
use handeye_vision::DetectorOptions;

/// The accepted values of one numeric key: an interval with its unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    /// Lower end.
    pub min: f64,
    /// Upper end.
    pub max: f64,
    /// Whether `min` itself is refused (`(min, …`).
    pub min_open: bool,
    /// Whether `max` itself is refused (`…, max)`).
    pub max_open: bool,
    /// Unit as a person reads it (`s`, `mm`, `°/s`), empty for a plain count or ratio.
    pub unit: &'static str,
}

impl Range {
    /// `[min, max]`.
    pub const fn closed(min: f64, max: f64, unit: &'static str) -> Range {
        Range {
            min,
            max,
            min_open: false,
            max_open: false,
            unit,
        }
    }

    /// `(min, max]`: for values that must be positive.
    pub const fn above(min: f64, max: f64, unit: &'static str) -> Range {
        Range {
            min,
            max,
            min_open: true,
            max_open: false,
            unit,
        }
    }

    /// Whether `v` is a finite number inside the range.
    pub fn contains(&self, v: f64) -> bool {
        v.is_finite()
            && (if self.min_open {
                v > self.min
            } else {
                v >= self.min
            })
            && (if self.max_open {
                v < self.max
            } else {
                v <= self.max
            })
    }
}

impl fmt::Display for Range {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}{}, {}{}",
            if self.min_open { "(" } else { "[" },
            readable(self.min),
            readable(self.max),
            if self.max_open { ")" } else { "]" },
        )?;
        if !self.unit.is_empty() {
            write!(f, " {}", self.unit)?;
        }
        Ok(())
    }
}

// The bounds. Generous: they refuse only what no real cell means (a typo, a unit mix-up, a value
// that would hang or exhaust the machine), never an unusual but real setup.

/// `robot.start_joints_deg[i]` (sim), degrees: UR joints turn ±360°.
/// `simulation.arm_errors.joint_offset_deg` and `twist_deg` (sigmas), °.
pub const ARM_ERROR_SIGMA_DEG: Range = Range::closed(0.0, 1.0, "°");
/// `simulation.arm_errors.length_mm` (sigma), mm.
pub const ARM_ERROR_SIGMA_MM: Range = Range::closed(0.0, 10.0, "mm");
/// `simulation.arm_errors.joint_offsets_deg[i]` and `alpha_deg[i]`, °.
pub const ARM_ERROR_DEG: Range = Range::closed(-5.0, 5.0, "°");
/// `simulation.arm_errors.d_mm[i]` and `a_mm[i]`, mm.
pub const ARM_ERROR_MM: Range = Range::closed(-50.0, 50.0, "mm");
/// `robot.start_joints_deg[i]`, °.
pub const START_JOINT_DEG: Range = Range::closed(-360.0, 360.0, "°");
/// `robot.move_duration_s` (sim), s.
pub const MOVE_DURATION_S: Range = Range::closed(0.0, 60.0, "s");
/// `robot.repeatability_mm` of the sim (0 = exact poses), mm.
pub const SIM_REPEATABILITY_MM: Range = Range::closed(0.0, 10.0, "mm");
/// `robot.repeatability_deg` of the sim (0 = exact poses), degrees.
pub const SIM_REPEATABILITY_DEG: Range = Range::closed(0.0, 5.0, "°");
/// `robot.repeatability_mm` of a real or recorded arm (it seeds a noise estimate: positive), mm.
pub const REPEATABILITY_MM: Range = Range::above(0.0, 10.0, "mm");
/// `robot.repeatability_deg` of a real or recorded arm, degrees.
pub const REPEATABILITY_DEG: Range = Range::above(0.0, 5.0, "°");
/// `robot.protective_stop_after_moves` (sim fault injection), moves.
pub const PROTECTIVE_STOP_AFTER_MOVES: Range = Range::closed(0.0, 1e6, "moves");
/// `robot.connect_timeout_s`, s.
pub const CONNECT_TIMEOUT_S: Range = Range::above(0.0, 120.0, "s");
/// `camera.noise_sigma` (sim), grey levels.
pub const NOISE_SIGMA: Range = Range::closed(0.0, 64.0, "grey levels");
/// `camera.blur_sigma_px` (sim), px: more is a lens out of focus, and rendering slows with it.
pub const BLUR_SIGMA_PX: Range = Range::closed(0.0, 10.0, "px");
/// `camera.hide_board_in_grabs[i]` (sim fault injection), grab numbers.
pub const HIDDEN_GRAB: Range = Range::closed(0.0, 1e6, "");
/// `camera.width` and `camera.height` (uvc), px.
pub const IMAGE_SIDE_PX: Range = Range::closed(1.0, 16384.0, "px");
/// `camera.fps` (uvc), frames/s.
pub const FPS: Range = Range::closed(1.0, 1000.0, "frames/s");
/// `camera.exposure_us` (uvc), µs.
pub const EXPOSURE_US: Range = Range::closed(1.0, 10e6, "µs");
/// `camera.gain` and `camera.focus` (uvc), camera units.
pub const CAMERA_CONTROL: Range = Range::closed(-1e6, 1e6, "camera units");
/// `camera.stale_frames` (uvc), frames.
pub const STALE_FRAMES: Range = Range::closed(0.0, 100.0, "frames");
/// Ceiling on `limits.linear_speed`, m/s: calibration moves near people never need more.
pub const MAX_LINEAR_SPEED: f64 = 0.5;
/// Ceiling on `limits.linear_acceleration`, m/s².
pub const MAX_LINEAR_ACCELERATION: f64 = 2.0;
/// Ceiling on `limits.joint_speed_deg`, °/s.
pub const MAX_JOINT_SPEED_DEG: f64 = 90.0;
/// Ceiling on `limits.joint_acceleration_deg`, °/s².
pub const MAX_JOINT_ACCELERATION_DEG: f64 = 180.0;
/// `limits.linear_speed`, m/s.
pub const LINEAR_SPEED: Range = Range::above(0.0, MAX_LINEAR_SPEED, "m/s");
/// `limits.linear_acceleration`, m/s².
pub const LINEAR_ACCELERATION: Range = Range::above(0.0, MAX_LINEAR_ACCELERATION, "m/s²");
/// `limits.joint_speed_deg`, °/s.
pub const JOINT_SPEED_DEG: Range = Range::above(0.0, MAX_JOINT_SPEED_DEG, "°/s");
/// `limits.joint_acceleration_deg`, °/s².
pub const JOINT_ACCELERATION_DEG: Range = Range::above(0.0, MAX_JOINT_ACCELERATION_DEG, "°/s²");
/// `workspace.min[i]` and `workspace.max[i]`, m (base frame).
pub const WORKSPACE_M: Range = Range::closed(-10.0, 10.0, "m");
/// Farthest a flange-mounted camera or board sits from the flange, m: farther, its nominal or
/// simulated offset is taken for millimetres written as metres.
pub const MAX_FLANGE_OFFSET_M: f64 = 2.0;
/// Farthest a base-mounted board or camera sits from the robot base, m (the workspace bound).
pub const MAX_BASE_OFFSET_M: f64 = 10.0;

/// A length written in mm, in metres (rounded to the nanometre, so 44.7 reads 0.0447).
fn mm_to_m(mm: f64) -> f64 {
    (mm * 1e6).round() / 1e9
}

/// `[a, b, c]` with readable numbers.
fn triple(v: &[f64]) -> String {
    let parts: Vec<String> = v.iter().map(|x| readable(*x)).collect();
    format!("[{}]", parts.join(", "))
}

/// `plan.target_uncertainty_mm`, mm.
pub const TARGET_UNCERTAINTY_MM: Range = Range::above(0.0, 100.0, "mm");
/// `solver.rotation_sigma_deg`, degrees.
pub const ROTATION_SIGMA_DEG: Range = Range::above(0.0, 10.0, "°");
/// `solver.translation_sigma_mm`, mm.
pub const TRANSLATION_SIGMA_MM: Range = Range::above(0.0, 100.0, "mm");
/// `solver.pixel_sigma_px`, px.
pub const PIXEL_SIGMA_PX: Range = Range::above(0.0, 10.0, "px");
/// `verdict.accuracy_mm`, mm.
pub const ACCURACY_MM: Range = Range::above(0.0, 1000.0, "mm");
/// `verdict.accuracy_deg`, degrees.
pub const ACCURACY_DEG: Range = Range::above(0.0, 45.0, "°");
/// `session.settle_s`, s.
pub const SETTLE_S: Range = Range::closed(0.0, 60.0, "s");
/// `session.settle_speed_deg_s`, °/s (0 = off).
pub const SETTLE_SPEED_DEG_S: Range = Range::closed(0.0, 30.0, "°/s");
/// `session.settle_window_s`, s.
pub const SETTLE_WINDOW_S: Range = Range::closed(0.0, 5.0, "s");
/// `session.settle_timeout_s`, s.
pub const SETTLE_TIMEOUT_S: Range = Range::above(0.0, 600.0, "s");
/// `plan.min_poses` and `plan.max_poses`.
pub const PLAN_POSES: Range = Range::closed(3.0, 1000.0, "poses");
/// `robot.ringing_deg` (sim), degrees.
pub const RINGING_DEG: Range = Range::closed(0.0, 5.0, "°");
/// `robot.ringing_hz` (sim), Hz.
pub const RINGING_HZ: Range = Range::above(0.0, 200.0, "Hz");
/// `robot.ringing_decay_s` (sim), s.
pub const RINGING_DECAY_S: Range = Range::above(0.0, 10.0, "s");
/// `session.max_reprojection_rms_px`, px.
pub const MAX_REPROJECTION_RMS_PX: Range = Range::above(0.0, 100.0, "px");
/// `session.image_margin_px`, px.
pub const IMAGE_MARGIN_PX: Range = Range::closed(0.0, 1000.0, "px");

/// What validation produces besides the checked shape: the values converted to the units and
/// types the rest of the tool uses.
pub(super) struct Checked {
    pub setup: Setup,
    pub camera: CameraConfig,
    pub nominal: CellTransforms,
    pub simulation: Option<CellTransforms>,
    pub arm_errors: Option<ArmErrors>,
    pub limits: MotionLimits,
    pub workspace: WorkspaceBox,
    pub settle: Duration,
}

/// Checks every value of `raw` (read from `file`).
pub(super) fn check(raw: &ConfigFile, file: &Path) -> Result<Checked, ConfigError> {
    let v = Validator { file };
    // `config::cameras` hands each camera over in the one-camera form, its setup and backend given.
    let (Some(setup), Some(camera)) = (raw.setup, raw.camera.clone()) else {
        return Err(v.inconsistent(
            "setup",
            "missing: a camera needs its `setup` and `camera`".into(),
        ));
    };
    v.robot(&raw.robot)?;
    v.joint_ranges(&raw.robot, setup)?;
    v.camera(&camera, raw.intrinsics.is_some())?;
    let limits = v.limits(raw)?;
    let workspace = v.workspace(raw)?;
    v.plan(raw)?;
    v.detector(raw)?;
    v.solver(raw)?;
    v.number("verdict.accuracy_mm", raw.verdict.accuracy_mm, ACCURACY_MM)?;
    v.number(
        "verdict.accuracy_deg",
        raw.verdict.accuracy_deg,
        ACCURACY_DEG,
    )?;
    let settle = v.session(raw)?;
    let nominal = v.transforms(setup, "nominal", &raw.nominal)?;
    let simulation = raw
        .simulation
        .as_ref()
        .map(|m| v.transforms(setup, "simulation", &m.transforms))
        .transpose()?;
    let arm_errors = match raw.simulation.as_ref().and_then(|m| m.arm_errors.as_ref()) {
        Some(errors) => Some(v.arm_errors(&raw.robot, errors)?),
        None => None,
    };
    let uses_sim = raw.robot.backend().simulated() || camera.backend().simulated();
    if uses_sim && simulation.is_none() {
        let (camera_key, target_key) = setup.unknown_names();
        return Err(v.inconsistent(
            "simulation",
            format!("the sim backends need the ground truth: `simulation: {{{camera_key}: ..., {target_key}: ...}}`"),
        ));
    }
    Ok(Checked {
        setup,
        camera,
        nominal,
        simulation,
        arm_errors,
        limits,
        workspace,
        settle,
    })
}

/// Checks the values of one config file, naming it and the key in every error.
pub struct Validator<'a> {
    file: &'a Path,
}

impl Validator<'_> {
    /// `value` at `key` must lie in `range`.
    pub(crate) fn number(&self, key: &str, value: f64, range: Range) -> Result<f64, ConfigError> {
        if range.contains(value) {
            Ok(value)
        } else {
            Err(self.out_of_range(key, readable(value), range))
        }
    }

    /// An integer at `key` must lie in `range` (shown as an integer).
    pub(crate) fn integer(&self, key: &str, value: i128, range: Range) -> Result<(), ConfigError> {
        // Every bound is far below 2^53, so the comparison in f64 is exact where it matters.
        if range.contains(value as f64) {
            Ok(())
        } else {
            Err(self.out_of_range(key, value.to_string(), range))
        }
    }

    fn out_of_range(&self, key: &str, found: String, range: Range) -> ConfigError {
        ConfigError::OutOfRange {
            file: self.file.to_path_buf(),
            key: key.to_string(),
            found,
            expected: format!("a value in {range}"),
        }
    }

    pub(crate) fn inconsistent(&self, key: &str, problem: String) -> ConfigError {
        ConfigError::Inconsistent {
            file: self.file.to_path_buf(),
            key: key.to_string(),
            problem,
        }
    }

    fn robot(&self, robot: &RobotConfig) -> Result<(), ConfigError> {
        robot.backend().check(self)
    }

    /// `robot.joint_ranges_deg`: per joint `[min, max]` inside the arm's own range with
    /// `min < max`; a sim arm's `start_joints_deg` inside the ranges in force.
    fn joint_ranges(&self, robot: &RobotConfig, setup: Setup) -> Result<(), ConfigError> {
        let given = robot.backend().given_joint_ranges_deg();
        // An arm of no known model (a ROS 2 arm with `model: none`) has its own limits: any
        // range within a full turn each way is taken as the datasheet's.
        let no_model = robot.model().is_none();
        if let Some(ranges) = given {
            for (i, [lo, hi]) in ranges.iter().enumerate() {
                let arm = match ARM_JOINT_RANGES_DEG.get(i) {
                    Some([arm_lo, arm_hi]) if !no_model => Range::closed(*arm_lo, *arm_hi, "°"),
                    _ => Range::closed(-360.0, 360.0, "°"),
                };
                self.number(&format!("robot.joint_ranges_deg[{i}][0]"), *lo, arm)?;
                self.number(&format!("robot.joint_ranges_deg[{i}][1]"), *hi, arm)?;
                if lo >= hi {
                    return Err(self.inconsistent(
                        &format!("robot.joint_ranges_deg[{i}]"),
                        format!(
                            "{} range [{}, {}] °: expected min < max",
                            match JOINT_NAMES.get(i) {
                                Some(name) if !no_model => name,
                                _ => "the joint's",
                            },
                            readable(*lo),
                            readable(*hi)
                        ),
                    ));
                }
            }
        }
        if let Some(start_joints_deg) = robot.backend().start_joints_deg() {
            let ranges = robot.joint_ranges_deg(setup);
            for (i, (q, [lo, hi])) in start_joints_deg.iter().zip(ranges).enumerate() {
                if *q < lo || *q > hi {
                    return Err(ConfigError::OutOfRange {
                        file: self.file.to_path_buf(),
                        key: format!("robot.start_joints_deg[{i}]"),
                        found: readable(*q),
                        expected: format!(
                            "a value inside the {} joint range [{}, {}] ° (robot.joint_ranges_deg[{i}])",
                            JOINT_NAMES[i],
                            readable(lo),
                            readable(hi)
                        ),
                    });
                }
            }
        }
        Ok(())
    }

    pub(crate) fn repeatability(
        &self,
        mm: Option<f64>,
        deg: Option<f64>,
    ) -> Result<(), ConfigError> {
        if let Some(mm) = mm {
            self.number("robot.repeatability_mm", mm, REPEATABILITY_MM)?;
        }
        if let Some(deg) = deg {
            self.number("robot.repeatability_deg", deg, REPEATABILITY_DEG)?;
        }
        Ok(())
    }

    fn camera(&self, camera: &CameraConfig, cell_intrinsics: bool) -> Result<(), ConfigError> {
        camera.backend().check(self, cell_intrinsics)
    }

    fn limits(&self, raw: &ConfigFile) -> Result<MotionLimits, ConfigError> {
        let l = raw.limits;
        Ok(MotionLimits {
            linear_speed: self.number("limits.linear_speed", l.linear_speed, LINEAR_SPEED)?,
            linear_acceleration: self.number(
                "limits.linear_acceleration",
                l.linear_acceleration,
                LINEAR_ACCELERATION,
            )?,
            joint_speed: self
                .number("limits.joint_speed_deg", l.joint_speed_deg, JOINT_SPEED_DEG)?
                .to_radians(),
            joint_acceleration: self
                .number(
                    "limits.joint_acceleration_deg",
                    l.joint_acceleration_deg,
                    JOINT_ACCELERATION_DEG,
                )?
                .to_radians(),
        })
    }

    fn workspace(&self, raw: &ConfigFile) -> Result<WorkspaceBox, ConfigError> {
        let w = raw.workspace;
        // A box in mm: some value out of range as written, all in range divided by 1000, and
        // every side longer than 20 (m as written: no cell spans that; 20 mm in mm). One wild
        // value in a box of metres is a typo, named by the range check below.
        let values = w.min.iter().chain(&w.max);
        let outside = values.clone().any(|v| !WORKSPACE_M.contains(*v));
        let long_sides = (0..3).all(|i| w.max[i] - w.min[i] > 20.0);
        if outside && long_sides && values.clone().all(|v| WORKSPACE_M.contains(v / 1000.0)) {
            let metres = |v: [f64; 3]| triple(&v.map(mm_to_m));
            return Err(ConfigError::Millimetres {
                file: self.file.to_path_buf(),
                key: "workspace".into(),
                found: format!("the box min {}, max {}", triple(&w.min), triple(&w.max)),
                why: format!(
                    "as metres the box would reach beyond the {WORKSPACE_M} the workspace keys accept (base frame)"
                ),
                metres: format!("min: {}, max: {}", metres(w.min), metres(w.max)),
            });
        }
        for i in 0..3 {
            self.number(&format!("workspace.min[{i}]"), w.min[i], WORKSPACE_M)?;
            self.number(&format!("workspace.max[{i}]"), w.max[i], WORKSPACE_M)?;
        }
        if let Some(axis) = (0..3).find(|&i| w.min[i] >= w.max[i]) {
            return Err(self.inconsistent(
                "workspace",
                format!(
                    "expected min < max on every axis, found min[{axis}] = {} >= max[{axis}] = {}",
                    readable(w.min[axis]),
                    readable(w.max[axis])
                ),
            ));
        }
        Ok(WorkspaceBox {
            min: Vector3::from(w.min),
            max: Vector3::from(w.max),
        })
    }

    fn plan(&self, raw: &ConfigFile) -> Result<(), ConfigError> {
        let plan = &raw.plan;
        let recorded = !raw.robot.backend().moves();
        if plan.manual && (recorded || plan.adaptive == Some(true)) {
            return Err(self.inconsistent(
                "plan.manual",
                if recorded {
                    "a recorded robot cannot be hand-guided: leave out `plan`".into()
                } else {
                    "expected one of `manual` (a person chooses the views) and `adaptive` (the planner does)".into()
                },
            ));
        }
        match (&plan.file, &plan.generate) {
            (None, None) if recorded => {}
            _ if recorded => {
                return Err(self.inconsistent(
                    "plan",
                    "a recorded robot's plan is its recorded poses: leave out `plan`".into(),
                ))
            }
            (Some(_), None) => {}
            // Hand-guided with no views to suggest (an arm of no known model, say).
            (None, None) if plan.manual => {}
            (None, Some(spec)) => {
                // Views at hundreds of metres: the distances were written in mm.
                let [near, far] = spec.distance;
                let limit = handeye_plan::generate::MAX_DISTANCE_M;
                if near > 0.0 && far > limit && far / 1000.0 <= limit {
                    return Err(ConfigError::Millimetres {
                        file: self.file.to_path_buf(),
                        key: "plan.generate.distance".into(),
                        found: format!("[{}, {}]", readable(near), readable(far)),
                        why: format!(
                            "as metres the camera would view the board from up to {} m, where a generated plan's views lie within {} m",
                            readable(far),
                            readable(limit)
                        ),
                        metres: format!("[{}, {}]", readable(mm_to_m(near)), readable(mm_to_m(far))),
                    });
                }
                spec.validate().map_err(|e| ConfigError::OutOfRange {
                    file: self.file.to_path_buf(),
                    key: format!("plan.generate.{}", e.field),
                    found: e.found,
                    expected: e.expected,
                })?
            }
            _ => {
                return Err(self.inconsistent(
                    "plan",
                    "expected exactly one of `file` (a scripted plan) and `generate` (or neither with `manual: true`: hand-guided, no suggested views)".into(),
                ))
            }
        }
        if let Some(target) = plan.target_uncertainty_mm {
            self.number("plan.target_uncertainty_mm", target, TARGET_UNCERTAINTY_MM)?;
        }
        self.integer("plan.min_poses", plan.min_poses as i128, PLAN_POSES)?;
        if let Some(max) = plan.max_poses {
            self.integer("plan.max_poses", max as i128, PLAN_POSES)?;
            if max < plan.min_poses {
                return Err(self.inconsistent(
                    "plan.max_poses",
                    format!(
                        "expected at least plan.min_poses ({}), found {max}",
                        plan.min_poses
                    ),
                ));
            }
        }
        if plan.adaptive == Some(true) && plan.file.is_none() && plan.generate.is_none() {
            return Err(self.inconsistent(
                "plan.adaptive",
                "an adaptive plan chooses from the plan's poses: give `file` or `generate`".into(),
            ));
        }
        Ok(())
    }

    fn detector(&self, raw: &ConfigFile) -> Result<(), ConfigError> {
        let d = raw.detector;
        let options = DetectorOptions {
            decimation: d.decimate,
            threads: d.threads,
            max_hamming: d.max_hamming,
            ..DetectorOptions::default()
        };
        options.validate().map_err(|e| ConfigError::OutOfRange {
            file: self.file.to_path_buf(),
            // The config's key for the detector's `decimation`.
            key: match e.field {
                "decimation" => "detector.decimate".to_string(),
                field => format!("detector.{field}"),
            },
            found: e.found,
            expected: e.expected,
        })
    }

    fn solver(&self, raw: &ConfigFile) -> Result<(), ConfigError> {
        let s = &raw.solver;
        if let Some(sigma) = s.rotation_sigma_deg {
            self.number("solver.rotation_sigma_deg", sigma, ROTATION_SIGMA_DEG)?;
        }
        if let Some(sigma) = s.translation_sigma_mm {
            self.number("solver.translation_sigma_mm", sigma, TRANSLATION_SIGMA_MM)?;
        }
        self.number("solver.pixel_sigma_px", s.pixel_sigma_px, PIXEL_SIGMA_PX)?;
        if let Some(choice @ (KinematicsChoice::JointOffsets | KinematicsChoice::Dh)) = s.kinematics
        {
            if let Some(needs) =
                super::schema::arm_model_unavailable(&raw.robot, raw.intrinsics.as_deref())
            {
                return Err(self.inconsistent(
                    "solver.kinematics",
                    format!("`{}` needs {needs}", choice.name()),
                ));
            }
        }
        if s.arm_model.is_some() {
            if let Some(choice) = s.kinematics {
                return Err(self.inconsistent(
                    "solver.arm_model",
                    format!("the arm model given is applied as it is, and `kinematics: {}` says what to estimate: leave out `kinematics`", choice.name()),
                ));
            }
            if raw.robot.model().is_none() || !raw.robot.backend().reports_joints() {
                return Err(self.inconsistent(
                    "solver.arm_model",
                    "an arm model corrects each pose through its joints and the arm's published model: a sim, ur or ros2 arm with `robot.model`".into(),
                ));
            }
        }
        Ok(())
    }

    /// `simulation.arm_errors`: a seeded draw or the per-joint lists (not both), for the sim arm.
    fn arm_errors(&self, robot: &RobotConfig, e: &ArmErrorsFile) -> Result<ArmErrors, ConfigError> {
        const KEY: &str = "simulation.arm_errors";
        if !robot.backend().simulated() {
            return Err(self.inconsistent(
                KEY,
                "the arm's own errors are simulated by the sim arm only (`robot: {backend: sim}`)"
                    .into(),
            ));
        }
        let lists = [
            ("joint_offsets_deg", &e.joint_offsets_deg, ARM_ERROR_DEG),
            ("d_mm", &e.d_mm, ARM_ERROR_MM),
            ("a_mm", &e.a_mm, ARM_ERROR_MM),
            ("alpha_deg", &e.alpha_deg, ARM_ERROR_DEG),
        ];
        let sigmas = [
            ("joint_offset_deg", e.joint_offset_deg, ARM_ERROR_SIGMA_DEG),
            ("length_mm", e.length_mm, ARM_ERROR_SIGMA_MM),
            ("twist_deg", e.twist_deg, ARM_ERROR_SIGMA_DEG),
        ];
        let listed = lists.iter().any(|(_, l, _)| l.is_some());
        if let Some(seed) = e.seed {
            if listed {
                return Err(self.inconsistent(
                    KEY,
                    "give a seeded draw (`seed` with `joint_offset_deg`, `length_mm`, `twist_deg`) or the per-joint lists (`joint_offsets_deg`, `d_mm`, `a_mm`, `alpha_deg`), not both".into(),
                ));
            }
            let mut values = [0.0; 3];
            for (value, (name, sigma, range)) in values.iter_mut().zip(sigmas) {
                *value = self.number(&format!("{KEY}.{name}"), sigma.unwrap_or(0.0), range)?;
            }
            return Ok(ArmErrors::draw(
                seed,
                &ArmErrorSigmas {
                    joint_offset_rad: values[0].to_radians(),
                    length_m: values[1] * 1e-3,
                    twist_rad: values[2].to_radians(),
                },
            ));
        }
        if let Some((name, _, _)) = sigmas.iter().find(|(_, s, _)| s.is_some()) {
            return Err(self.inconsistent(
                &format!("{KEY}.seed"),
                format!("missing: `{name}` is the sigma of a random draw, which needs a `seed`"),
            ));
        }
        let mut six = [[0.0; 6]; 4];
        for (out, (name, list, range)) in six.iter_mut().zip(lists) {
            let Some(list) = list else { continue };
            if list.len() != 6 {
                return Err(self.inconsistent(
                    &format!("{KEY}.{name}"),
                    format!("{} values: one per joint, base first (six)", list.len()),
                ));
            }
            for (i, value) in list.iter().enumerate() {
                out[i] = self.number(&format!("{KEY}.{name}[{i}]"), *value, range)?;
            }
        }
        Ok(ArmErrors {
            joint_offsets_rad: six[0].map(f64::to_radians),
            d_m: six[1].map(|v| v * 1e-3),
            a_m: six[2].map(|v| v * 1e-3),
            alpha_rad: six[3].map(f64::to_radians),
        })
    }

    fn session(&self, raw: &ConfigFile) -> Result<Duration, ConfigError> {
        let s = raw.session;
        let settle_s = self.number("session.settle_s", s.settle_s, SETTLE_S)?;
        self.number(
            "session.settle_speed_deg_s",
            s.settle_speed_deg_s,
            SETTLE_SPEED_DEG_S,
        )?;
        self.number(
            "session.settle_window_s",
            s.settle_window_s,
            SETTLE_WINDOW_S,
        )?;
        self.number(
            "session.settle_timeout_s",
            s.settle_timeout_s,
            SETTLE_TIMEOUT_S,
        )?;
        self.number(
            "session.max_reprojection_rms_px",
            s.max_reprojection_rms_px,
            MAX_REPROJECTION_RMS_PX,
        )?;
        self.number(
            "session.image_margin_px",
            s.image_margin_px,
            IMAGE_MARGIN_PX,
        )?;
        // In range, so the conversion cannot fail; checked all the same.
        Duration::try_from_secs_f64(settle_s)
            .map_err(|_| self.out_of_range("session.settle_s", readable(settle_s), SETTLE_S))
    }

    /// A mount's translation farther than any real mount sits ([`MAX_FLANGE_OFFSET_M`] from the
    /// flange, [`MAX_BASE_OFFSET_M`] from the base) but plausible once divided by 1000 is
    /// millimetres written as metres: one message naming the key.
    fn offset_in_metres(
        &self,
        setup: Setup,
        section: &str,
        key: &str,
        pose: &PoseYaml,
    ) -> Result<(), ConfigError> {
        let Some(t) = pose.translation.as_deref().filter(|t| t.len() == 3) else {
            return Ok(());
        };
        let norm = t.iter().map(|v| v * v).sum::<f64>().sqrt();
        let (camera_key, _) = setup.unknown_names();
        let on_flange = (key == camera_key) == (setup == Setup::EyeInHand);
        let what = if key == camera_key { "camera" } else { "board" };
        let (limit, why) = if on_flange {
            (
                MAX_FLANGE_OFFSET_M,
                format!(
                    "as metres it puts the {what} {norm:.1} m from the flange, where a flange-mounted {what} sits within {} m",
                    readable(MAX_FLANGE_OFFSET_M)
                ),
            )
        } else {
            (
                MAX_BASE_OFFSET_M,
                format!(
                    "as metres it puts the {what} {norm:.1} m from the robot base, where a {what} in the cell sits within {} m",
                    readable(MAX_BASE_OFFSET_M)
                ),
            )
        };
        if norm.is_finite() && norm > limit && norm / 1000.0 <= limit {
            return Err(ConfigError::Millimetres {
                file: self.file.to_path_buf(),
                key: format!("{section}.{key}.translation"),
                found: triple(t),
                why,
                metres: triple(&t.iter().map(|v| mm_to_m(*v)).collect::<Vec<_>>()),
            });
        }
        Ok(())
    }

    /// The setup's two transforms from `section` (`nominal` or `simulation`).
    fn transforms(
        &self,
        setup: Setup,
        section: &str,
        map: &BTreeMap<String, PoseYaml>,
    ) -> Result<CellTransforms, ConfigError> {
        let (camera_key, target_key) = setup.unknown_names();
        let setup_name = setup.name();
        if let Some(key) = map.keys().find(|k| *k != camera_key && *k != target_key) {
            return Err(self.inconsistent(
                &format!("{section}.{key}"),
                format!("unknown transform for setup {setup_name}: expected `{camera_key}` and `{target_key}`"),
            ));
        }
        let get = |key: &str| {
            let pose = map.get(key).ok_or_else(|| {
                self.inconsistent(
                    section,
                    format!("missing `{key}` (setup {setup_name} expects `{camera_key}` and `{target_key}`)"),
                )
            })?;
            self.offset_in_metres(setup, section, key, pose)?;
            pose.to_pose(&format!("{section}.{key}"))
                .map_err(|problem| ConfigError::Pose {
                    file: self.file.to_path_buf(),
                    problem,
                })
        };
        Ok(CellTransforms {
            setup,
            camera_mount: get(camera_key)?,
            target_mount: get(target_key)?,
        })
    }
}

/// The pose-space solver's settings given on a command line or to the Python package, checked
/// as the config's `solver:` section is: a noise sigma given lies in its range
/// ([`ROTATION_SIGMA_DEG`], [`TRANSLATION_SIGMA_MM`]; an absent one is estimated), and the
/// robust loss's scale is a positive number. `name` spells a setting as its caller's user types
/// it (`--rotation-sigma-deg`, `rotation_sigma_deg`).
pub fn check_solver_choice(
    rotation_sigma_deg: Option<f64>,
    translation_sigma_mm: Option<f64>,
    robust_scale: f64,
    name: &dyn Fn(&str) -> String,
) -> Result<(), String> {
    for (setting, value, range) in [
        ("rotation_sigma_deg", rotation_sigma_deg, ROTATION_SIGMA_DEG),
        (
            "translation_sigma_mm",
            translation_sigma_mm,
            TRANSLATION_SIGMA_MM,
        ),
    ] {
        if let Some(value) = value.filter(|v| !range.contains(*v)) {
            return Err(format!(
                "{} = {}: must be a value in {range}",
                name(setting),
                readable(value)
            ));
        }
    }
    if !(robust_scale.is_finite() && robust_scale > 0.0) {
        return Err(format!(
            "{} = {robust_scale}: must be a positive number",
            name("robust_scale")
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The CLI's and the Python package's solver settings are checked by one rule, each naming
    /// the setting as its user types it; a sigma left out is estimated, so not checked.
    #[test]
    fn a_solver_choice_is_checked_as_the_config_is_and_named_as_its_caller_spells_it() {
        let cli = |setting: &str| format!("--{}", setting.replace('_', "-"));
        assert_eq!(check_solver_choice(None, None, 3.0, &cli), Ok(()));
        assert_eq!(
            check_solver_choice(Some(10.0), Some(100.0), 0.5, &cli),
            Ok(())
        );
        assert_eq!(
            check_solver_choice(Some(20.0), None, 3.0, &cli),
            Err(format!(
                "--rotation-sigma-deg = 20: must be a value in {ROTATION_SIGMA_DEG}"
            ))
        );
        assert_eq!(
            check_solver_choice(None, Some(0.0), 3.0, &str::to_string),
            Err(format!(
                "translation_sigma_mm = 0: must be a value in {TRANSLATION_SIGMA_MM}"
            ))
        );
        for scale in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let error = check_solver_choice(None, None, scale, &str::to_string).unwrap_err();
            assert_eq!(
                error,
                format!("robust_scale = {scale}: must be a positive number")
            );
        }
    }
}
