//! The simulated UR arm: a [`Robot`] backed by [`UrModel`] kinematics, for dry runs, the
//! simulated cell and tests. It moves instantly, in a fixed time, or in the time a UR's `moveJ`
//! takes at the move's limits (trapezoidal profile of the leading joint); after arriving it can
//! ring down (a decaying joint oscillation, so the joint speeds it reports are not zero right
//! after a move); it reports its pose with repeatability noise, and can inject the faults a real
//! cell shows (protective stop, emergency stop, lost connection).
//!
//! Motion is a function of time: every move is kept as a record (start, profile, target,
//! ringing), so the joints and joint speeds at any instant — now, or when a frame was exposed —
//! follow from the records ([`SimRobot::joint_state_at`]).
//!
//! Which pose is "true": a move puts the arm exactly on the commanded target (the joints the
//! inverse kinematics chose); that exact flange pose is [`SimRobot::true_base_from_flange`] and
//! is what a simulated camera must render from. What the arm *reports*
//! ([`Robot::base_from_flange`]) is that true pose perturbed by the repeatability noise, drawn
//! once per move and held while the arm stands still (a real controller's reading of a standing
//! arm does not jitter from read to read). Joint positions are reported exactly.
//!
//! The arm's own errors: by default the true geometry is the model's. With
//! [`SimRobot::with_true_arm`] the arm stands where a true arm (a calibrated [`UrModel`]:
//! `arm_errors`) puts the flange (`FK_true(q)`, what the camera renders from) while it reports
//! the pose its nominal model computes from the same joints (`FK_nominal(q)`, perturbed by the repeatability noise), as a
//! real controller does.
//!
//! Frames: `T_base_flange`; metres, radians, [`Duration`]. Depends on `robot` and `geometry` only.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use super::kinematics::UrModel;
use super::{
    leading_travel, six_joints, trapezoid_at, Joints, MotionLimits, Robot, RobotError, RobotStatus,
};
use handeye_core::geometry::{pose_from_rotvec, Pose};

/// Faults the simulated arm injects, counted in completed moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SimFaults {
    /// After this many completed moves the next move raises a protective stop (the arm stays
    /// where it was) until [`SimRobot::clear_stop`] is called.
    pub protective_stop_after_moves: Option<usize>,
    /// After this many completed moves the next move raises an emergency stop, as above.
    pub emergency_stop_after_moves: Option<usize>,
    /// After this many completed moves every later call fails with a lost connection.
    pub connection_lost_after_moves: Option<usize>,
}

/// The decaying oscillation of a joint after the arm arrives: joint `i` swings by
/// `amplitude_rad · (travel_i / leading travel) · e^(−t/decay_s) · sin(2π·frequency_hz·t)`
/// about its target, `t` seconds after arrival.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ringing {
    /// Amplitude of the leading joint right after arrival, rad.
    pub amplitude_rad: f64,
    /// Oscillation frequency, Hz.
    pub frequency_hz: f64,
    /// Decay time constant, s.
    pub decay_s: f64,
}

/// How the simulated arm behaves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimRobotOptions {
    /// Wall time every move takes; zero makes moves instant (unless `move_at_limits`).
    pub move_duration: Duration,
    /// Moves take the time a UR `moveJ` takes at the move's joint speed and acceleration limits
    /// (trapezoidal profile, [`MotionLimits::joint_move_time`]) instead of `move_duration`.
    pub move_at_limits: bool,
    /// Ringing after arrival (`None`: the arm stops dead).
    pub ringing: Option<Ringing>,
    /// Standard deviation of the reported flange position per axis, m (UR5e: about 1e-5).
    pub repeatability_m: f64,
    /// Standard deviation of the reported flange rotation per rotation-vector axis, rad.
    pub repeatability_rad: f64,
    /// Seed of the noise generator, so runs repeat exactly.
    pub seed: u64,
    /// Injected faults.
    pub faults: SimFaults,
}

impl Default for SimRobotOptions {
    /// Instant, noise-free moves, no faults.
    fn default() -> Self {
        SimRobotOptions {
            move_duration: Duration::ZERO,
            move_at_limits: false,
            ringing: None,
            repeatability_m: 0.0,
            repeatability_rad: 0.0,
            seed: 0,
            faults: SimFaults::default(),
        }
    }
}

/// Why a simulated arm could not be built.
#[derive(Debug, thiserror::Error)]
pub enum SimRobotError {
    /// A noise level is negative or not finite.
    #[error("sim robot option {name} = {value} {unit} must be finite and >= 0")]
    BadNoise {
        /// Option name.
        name: &'static str,
        /// Offending value.
        value: f64,
        /// Its unit.
        unit: &'static str,
    },
    /// The start joints are outside the model's joint limits.
    #[error("sim robot start joint {index} = {value_deg:.3} deg is outside the {model} joint limits [{min_deg:.1}, {max_deg:.1}] deg")]
    StartOutsideLimits {
        /// Model name.
        model: String,
        /// Joint index (0 = base).
        index: usize,
        /// Value, degrees.
        value_deg: f64,
        /// Lower limit, degrees.
        min_deg: f64,
        /// Upper limit, degrees.
        max_deg: f64,
    },
    /// The start names another number of joints than a UR's six.
    #[error("sim robot start has {0} joints; the simulated UR arm has 6")]
    StartJointCount(usize),
}

/// The latched fault state of the simulated controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Latched {
    None,
    ProtectiveStop,
    EmergencyStop,
    Disconnected,
}

/// One move as it happened (or is happening), for the joint state at any instant.
#[derive(Debug, Clone, Copy)]
struct MotionRecord {
    started: Instant,
    from: Joints,
    to: Joints,
    /// Travel time, s.
    duration_s: f64,
    /// `(speed, acceleration)` of a trapezoidal profile; `None`: constant speed.
    profile: Option<(f64, f64)>,
    /// Ringing amplitude per joint after arrival, rad.
    ringing: Joints,
}

/// A simulated UR arm; see the module docs for which pose is true and which is reported.
#[derive(Debug)]
pub struct SimRobot {
    model: UrModel,
    /// The true geometry (`None`: the model's).
    true_arm: Option<UrModel>,
    options: SimRobotOptions,
    /// The commanded joints (where the arm comes to rest).
    joints: Joints,
    /// The latest motions, oldest first (at most [`HISTORY_LEN`]).
    history: VecDeque<MotionRecord>,
    true_pose: Pose,
    reported_pose: Pose,
    rng: StdRng,
    moves_completed: usize,
    latched: Latched,
    position_noise: Normal<f64>,
    rotation_noise: Normal<f64>,
    interrupt: Option<Arc<AtomicBool>>,
}

impl SimRobot {
    /// A simulated arm of `model` standing at `start` (rad). Fails on negative or non-finite
    /// noise levels and on start joints outside the limits.
    pub fn new(
        model: UrModel,
        start: Joints,
        options: SimRobotOptions,
    ) -> Result<Self, SimRobotError> {
        let noise = |name, value: f64, unit| {
            if value.is_finite() && value >= 0.0 {
                Normal::new(0.0, value).map_err(|_| SimRobotError::BadNoise { name, value, unit })
            } else {
                Err(SimRobotError::BadNoise { name, value, unit })
            }
        };
        if start.len() != 6 {
            return Err(SimRobotError::StartJointCount(start.len()));
        }
        let position_noise = noise("repeatability_m", options.repeatability_m, "m")?;
        let rotation_noise = noise("repeatability_rad", options.repeatability_rad, "rad")?;
        if let Some((index, value)) = model.outside_limits(&start) {
            return Err(SimRobotError::StartOutsideLimits {
                model: model.name.clone(),
                index,
                value_deg: value.to_degrees(),
                min_deg: model.joint_limits[index].0.to_degrees(),
                max_deg: model.joint_limits[index].1.to_degrees(),
            });
        }
        let true_pose = model.forward(&start);
        Ok(SimRobot {
            rng: StdRng::seed_from_u64(options.seed),
            model,
            true_arm: None,
            options,
            joints: start,
            history: VecDeque::with_capacity(HISTORY_LEN),
            true_pose,
            // Standing at the start the reading is exact until the first move draws noise.
            reported_pose: true_pose,
            moves_completed: 0,
            latched: Latched::None,
            position_noise,
            rotation_noise,
            interrupt: None,
        })
    }

    /// The same arm whose true geometry is `arm` (see the module docs): it stands at
    /// `arm.forward(q)` and reports its model's `forward(q)`.
    pub fn with_true_arm(mut self, arm: UrModel) -> Self {
        self.true_arm = Some(arm);
        self.true_pose = self.true_forward(&self.joints);
        self
    }

    /// The flange pose the true geometry puts the flange at for `joints`.
    fn true_forward(&self, joints: &Joints) -> Pose {
        match &self.true_arm {
            Some(arm) => arm.forward(joints),
            None => self.model.forward(joints),
        }
    }

    /// The arm's exact flange pose `T_base_flange` now (what a simulated camera renders from):
    /// the pose at rest, or where the arm is on its way or while it rings down.
    pub fn true_base_from_flange(&self) -> Pose {
        match self.options.ringing {
            None => self.true_pose,
            Some(_) => self.true_forward(&self.joint_state_at(Instant::now()).0),
        }
    }

    /// The true joint positions (rad) and speeds (rad/s) at instant `t`: standing, moving, or
    /// ringing down after a move.
    pub fn joint_state_at(&self, t: Instant) -> (Joints, Joints) {
        let Some(record) = self.history.iter().rev().find(|r| r.started <= t) else {
            // Before the first move (or a moment before it started): standing at the start.
            let q = self.history.front().map_or(self.joints, |r| r.from);
            return (q, Joints::zeros(6));
        };
        let dt = t.duration_since(record.started).as_secs_f64();
        let delta: Joints = Joints::from_fn(6, |i| record.to[i] - record.from[i]);
        let lead = leading_travel(&record.from, &record.to);
        if dt < record.duration_s && lead > 0.0 {
            let (fraction, lead_speed) = match record.profile {
                Some((v, a)) => trapezoid_at(lead, v, a, dt),
                None => (dt / record.duration_s, lead / record.duration_s),
            };
            return (
                Joints::from_fn(6, |i| record.from[i] + delta[i] * fraction),
                Joints::from_fn(6, |i| delta[i] / lead * lead_speed),
            );
        }
        let Some(ringing) = self.options.ringing else {
            return (record.to, Joints::zeros(6));
        };
        let t = dt - record.duration_s;
        let w = 2.0 * std::f64::consts::PI * ringing.frequency_hz;
        let envelope = (-t / ringing.decay_s).exp();
        let (sin, cos) = (w * t).sin_cos();
        (
            Joints::from_fn(6, |i| record.to[i] + record.ringing[i] * envelope * sin),
            Joints::from_fn(6, |i| {
                record.ringing[i] * envelope * (w * cos - sin / ringing.decay_s)
            }),
        )
    }

    /// Keeps `record` as the latest motion. Only the last [`HISTORY_LEN`] are kept: the state
    /// is asked for now or a moment ago, so a long run's memory stays flat.
    fn record(&mut self, record: MotionRecord) {
        if self.history.len() == HISTORY_LEN {
            self.history.pop_front();
        }
        self.history.push_back(record);
    }

    /// How many moves have completed.
    pub fn moves_completed(&self) -> usize {
        self.moves_completed
    }

    /// Clears a protective or emergency stop (what a person does on the teach pendant), and
    /// disarms the fault that raised it so the run can resume. A lost connection stays lost.
    pub fn clear_stop(&mut self) {
        match self.latched {
            Latched::ProtectiveStop => {
                self.latched = Latched::None;
                self.options.faults.protective_stop_after_moves = None;
            }
            Latched::EmergencyStop => {
                self.latched = Latched::None;
                self.options.faults.emergency_stop_after_moves = None;
            }
            Latched::None | Latched::Disconnected => {}
        }
    }

    /// Fails if a fault is latched.
    fn check_latched(&self) -> Result<(), RobotError> {
        match self.latched {
            Latched::None => Ok(()),
            Latched::ProtectiveStop => Err(RobotError::ProtectiveStop),
            Latched::EmergencyStop => Err(RobotError::EmergencyStop),
            Latched::Disconnected => Err(RobotError::ConnectionLost(
                "simulated connection drop (fault injection)".to_string(),
            )),
        }
    }

    /// Latches a fault whose move count has been reached, before a move starts.
    fn arm_faults(&mut self) -> Result<(), RobotError> {
        let due = |k: Option<usize>| k.is_some_and(|k| self.moves_completed >= k);
        if due(self.options.faults.connection_lost_after_moves) {
            self.latched = Latched::Disconnected;
        } else if due(self.options.faults.emergency_stop_after_moves) {
            self.latched = Latched::EmergencyStop;
        } else if due(self.options.faults.protective_stop_after_moves) {
            self.latched = Latched::ProtectiveStop;
        }
        self.check_latched()
    }

    /// Completes a move to `joints`: waits the move time, then updates the true and reported
    /// poses. When the interrupt flag is set part-way the arm stops where it is by then (on the
    /// joint-space line between start and target) and the move returns
    /// [`RobotError::Interrupted`].
    fn finish_move(&mut self, joints: Joints, limits: &MotionLimits) -> Result<(), RobotError> {
        let from = self.joint_state_at(Instant::now()).0;
        let (duration_s, profile) = if self.options.move_at_limits {
            (
                limits.joint_move_time(&from, &joints),
                Some((limits.joint_speed, limits.joint_acceleration)),
            )
        } else {
            (self.options.move_duration.as_secs_f64(), None)
        };
        let lead = leading_travel(&from, &joints);
        let amplitude = self.options.ringing.map_or(0.0, |r| r.amplitude_rad);
        let started = Instant::now();
        self.record(MotionRecord {
            started,
            from,
            to: joints,
            duration_s,
            profile,
            ringing: Joints::from_fn(6, |i| {
                if lead > 0.0 {
                    amplitude * (joints[i] - from[i]) / lead
                } else {
                    0.0
                }
            }),
        });
        let duration = Duration::from_secs_f64(duration_s);
        while !duration.is_zero() {
            let elapsed = started.elapsed();
            if elapsed >= duration {
                break;
            }
            if self.interrupted() {
                let now = Instant::now();
                let stopped = self.joint_state_at(now).0;
                // The arm stops where it is (the sim decelerates at once) and stands there.
                self.record(MotionRecord {
                    started: now,
                    from: stopped,
                    to: stopped,
                    duration_s: 0.0,
                    profile: None,
                    ringing: Joints::zeros(6),
                });
                self.arrive(stopped);
                return Err(RobotError::Interrupted);
            }
            std::thread::sleep((duration - elapsed).min(INTERRUPT_POLL));
        }
        self.arrive(joints);
        self.moves_completed += 1;
        Ok(())
    }

    /// The arm stands at `joints`: the true pose follows, the reading draws new noise.
    fn arrive(&mut self, joints: Joints) {
        self.joints = joints;
        self.true_pose = self.true_forward(&joints);
        let dp = Vector3::from_fn(|_, _| self.position_noise.sample(&mut self.rng));
        let dr = Vector3::from_fn(|_, _| self.rotation_noise.sample(&mut self.rng));
        // Noise in the flange frame: the reading is off by a small rigid motion at the flange.
        // The controller computes the reading through its nominal model.
        let computed = match self.true_arm {
            Some(_) => self.model.forward(&joints),
            None => self.true_pose,
        };
        self.reported_pose = computed * pose_from_rotvec(dp, dr);
    }

    fn interrupted(&self) -> bool {
        self.interrupt
            .as_ref()
            .is_some_and(|flag| flag.load(Ordering::SeqCst))
    }
}

/// How often a move in progress looks at the interrupt flag.
const INTERRUPT_POLL: Duration = Duration::from_millis(10);
/// How many motions the sim keeps to answer where the arm was at an instant: the moves whose
/// ringing may still matter, and then some.
const HISTORY_LEN: usize = 8;

impl Robot for SimRobot {
    fn base_from_flange(&mut self) -> Result<Pose, RobotError> {
        self.check_latched_connection()?;
        Ok(self.reported_pose)
    }

    fn joint_positions(&mut self) -> Result<Joints, RobotError> {
        self.check_latched_connection()?;
        Ok(match self.options.ringing {
            None => self.joints,
            Some(_) => self.joint_state_at(Instant::now()).0,
        })
    }

    fn joint_speeds(&mut self) -> Result<Option<Joints>, RobotError> {
        self.check_latched_connection()?;
        // An arm whose moves are instant and that stops dead has no motion to measure: like a
        // backend without speed readings, it leaves settling to the fixed wait.
        let still = self.options.move_duration.is_zero()
            && !self.options.move_at_limits
            && self.options.ringing.is_none();
        Ok((!still).then(|| self.joint_state_at(Instant::now()).1))
    }

    fn move_linear(
        &mut self,
        base_from_flange: &Pose,
        limits: &MotionLimits,
    ) -> Result<(), RobotError> {
        limits.check()?;
        self.arm_faults()?;
        let joints = self
            .model
            .inverse_nearest(base_from_flange, &self.joints)
            .ok_or_else(|| {
                let p = base_from_flange.translation.vector;
                RobotError::Unreachable(format!(
                    "{}: no inverse-kinematics solution within the joint limits for flange position [{:.4}, {:.4}, {:.4}] m",
                    self.model.name, p.x, p.y, p.z
                ))
            })?;
        if self.interrupted() {
            return Err(RobotError::Interrupted);
        }
        self.finish_move(joints, limits)
    }

    fn move_joints(&mut self, joints: &Joints, limits: &MotionLimits) -> Result<(), RobotError> {
        limits.check()?;
        six_joints(joints)?;
        self.arm_faults()?;
        if let Some((i, value)) = self.model.outside_limits(joints) {
            let (lo, hi) = self.model.joint_limits[i];
            return Err(RobotError::Unreachable(format!(
                "{}: joint {i} target {:.3} deg is outside its limits [{:.1}, {:.1}] deg",
                self.model.name,
                value.to_degrees(),
                lo.to_degrees(),
                hi.to_degrees()
            )));
        }
        if self.interrupted() {
            return Err(RobotError::Interrupted);
        }
        self.finish_move(*joints, limits)
    }

    fn stop(&mut self) -> Result<(), RobotError> {
        // A move ends (arrived or interrupted) before the call returns: nothing moves now.
        self.check_latched_connection()
    }

    fn set_interrupt(&mut self, flag: Arc<AtomicBool>) {
        self.interrupt = Some(flag);
    }

    fn status(&mut self) -> Result<RobotStatus, RobotError> {
        self.check_latched_connection()?;
        Ok(match self.latched {
            Latched::ProtectiveStop => RobotStatus::ProtectiveStop,
            Latched::EmergencyStop => RobotStatus::EmergencyStop,
            Latched::None | Latched::Disconnected => RobotStatus::Ready,
        })
    }
}

impl SimRobot {
    /// Fails only if the connection is (simulated as) lost; stops still allow reading state.
    fn check_latched_connection(&self) -> Result<(), RobotError> {
        if self.latched == Latched::Disconnected {
            self.check_latched()
        } else {
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_core::geometry::translation_distance;

    const HOME: Joints = Joints::from_six([0.3, -1.2, 1.4, -0.8, 1.1, 0.4]);

    fn sim(options: SimRobotOptions) -> SimRobot {
        SimRobot::new(UrModel::ur5e(), HOME, options).unwrap()
    }

    #[test]
    fn linear_move_reaches_target_exactly_without_noise() {
        let mut robot = sim(SimRobotOptions::default());
        let target = UrModel::ur5e().forward(&Joints::from([0.5, -1.0, 1.2, -0.9, 1.3, 0.2]));
        robot
            .move_linear(&target, &MotionLimits::default())
            .unwrap();
        let reported = robot.base_from_flange().unwrap();
        assert!(translation_distance(&reported, &target) < 1e-9);
        assert!(reported.rotation.angle_to(&target.rotation) < 1e-9);
        // The chosen branch is the one nearest the start, i.e. the generating configuration.
        let q = robot.joint_positions().unwrap();
        let expected = [0.5, -1.0, 1.2, -0.9, 1.3, 0.2];
        assert!(q.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-9));
        assert_eq!(robot.moves_completed(), 1);
    }

    #[test]
    fn reported_pose_jitters_with_the_configured_spread_and_true_pose_does_not() {
        let options = SimRobotOptions {
            repeatability_m: 1e-4,
            repeatability_rad: 1e-3,
            seed: 42,
            ..Default::default()
        };
        let mut robot = sim(options);
        let target = robot.true_base_from_flange();
        let n = 400;
        let (mut sq_m, mut sq_rad) = (0.0, 0.0);
        for _ in 0..n {
            robot
                .move_linear(&target, &MotionLimits::default())
                .unwrap();
            let truth = robot.true_base_from_flange();
            assert!(translation_distance(&truth, &target) < 1e-9);
            let reported = robot.base_from_flange().unwrap();
            // Held still: a second reading is identical.
            assert_eq!(reported, robot.base_from_flange().unwrap());
            sq_m += translation_distance(&reported, &truth).powi(2);
            sq_rad += reported.rotation.angle_to(&truth.rotation).powi(2);
        }
        // E[|d|²] = 3σ² for three independent axes; 400 draws put the RMS within ~5 %.
        let rms_m = (sq_m / n as f64 / 3.0).sqrt();
        let rms_rad = (sq_rad / n as f64 / 3.0).sqrt();
        assert!((rms_m - 1e-4).abs() < 1e-5, "position rms {rms_m}");
        assert!((rms_rad - 1e-3).abs() < 1e-4, "rotation rms {rms_rad}");
    }

    #[test]
    fn an_arm_with_errors_reports_its_nominal_model_and_stands_at_its_true_one() {
        let errors = crate::arm_errors::ArmErrors::draw(
            3,
            &crate::arm_errors::ArmErrorSigmas {
                joint_offset_rad: 0.03f64.to_radians(),
                length_m: 3e-4,
                twist_rad: 0.02f64.to_radians(),
            },
        );
        let truth = errors.true_arm(&UrModel::ur5e());
        let mut robot = sim(SimRobotOptions::default()).with_true_arm(truth.clone());
        let q = Joints::from([0.5, -1.0, 1.2, -0.9, 1.3, 0.2]);
        robot.move_joints(&q, &MotionLimits::default()).unwrap();
        let reported = robot.base_from_flange().unwrap();
        let nominal = UrModel::ur5e().forward(&q);
        assert!(translation_distance(&reported, &nominal) < 1e-12);
        let seen = robot.true_base_from_flange();
        assert!(translation_distance(&seen, &truth.forward(&q)) < 1e-12);
        // The two differ by what the errors do to the flange (a fraction of a millimetre and up).
        assert!(translation_distance(&seen, &reported) > 1e-4);
    }

    #[test]
    fn same_seed_repeats_exactly() {
        let options = SimRobotOptions {
            repeatability_m: 1e-4,
            repeatability_rad: 1e-3,
            seed: 9,
            ..Default::default()
        };
        let (mut a, mut b) = (sim(options), sim(options));
        let target = a.true_base_from_flange();
        a.move_linear(&target, &MotionLimits::default()).unwrap();
        b.move_linear(&target, &MotionLimits::default()).unwrap();
        assert_eq!(a.base_from_flange().unwrap(), b.base_from_flange().unwrap());
    }

    #[test]
    fn an_interrupt_stops_a_move_part_way() {
        let mut robot = sim(SimRobotOptions {
            move_duration: Duration::from_secs(2),
            ..Default::default()
        });
        let flag = Arc::new(AtomicBool::new(false));
        robot.set_interrupt(flag.clone());
        let start = robot.joint_positions().unwrap();
        let target = Joints::from([0.6, -1.0, 1.2, -0.6, 1.3, 0.2]);
        let setter = {
            let flag = flag.clone();
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(300));
                flag.store(true, Ordering::SeqCst);
            })
        };
        let t0 = Instant::now();
        let err = robot
            .move_joints(&target, &MotionLimits::default())
            .unwrap_err();
        setter.join().unwrap();
        assert!(matches!(err, RobotError::Interrupted), "{err}");
        assert!(t0.elapsed() < Duration::from_secs(1), "{:?}", t0.elapsed());
        // Stopped part-way along, not at either end; the reading follows the arm.
        let stopped = robot.joint_positions().unwrap();
        for i in 0..6 {
            if target[i] != start[i] {
                let done = (stopped[i] - start[i]) / (target[i] - start[i]);
                assert!(done > 0.05 && done < 0.5, "joint {i}: {done:.3} of the way");
            }
        }
        assert_eq!(
            robot.base_from_flange().unwrap(),
            robot.true_base_from_flange()
        );
        // While the flag stays set nothing moves.
        assert!(matches!(
            robot.move_joints(&target, &MotionLimits::default()),
            Err(RobotError::Interrupted)
        ));
        assert_eq!(robot.joint_positions().unwrap(), stopped);
    }

    #[test]
    fn unreachable_target_is_an_error_and_the_arm_stays() {
        let mut robot = sim(SimRobotOptions::default());
        let before = robot.joint_positions().unwrap();
        let far = Pose::translation(3.0, 0.0, 0.5);
        let err = robot
            .move_linear(&far, &MotionLimits::default())
            .unwrap_err();
        assert!(
            matches!(err, RobotError::Unreachable(ref m) if m.contains("3.0000")),
            "{err}"
        );
        assert_eq!(robot.joint_positions().unwrap(), before);
        let err = robot
            .move_joints(
                &Joints::from([0.0, 0.0, 7.0, 0.0, 0.0, 0.0]),
                &MotionLimits::default(),
            )
            .unwrap_err();
        assert!(
            matches!(err, RobotError::Unreachable(ref m) if m.contains("joint 2")),
            "{err}"
        );
        let bad = MotionLimits {
            linear_speed: f64::NAN,
            ..Default::default()
        };
        assert!(matches!(
            robot.move_joints(&HOME, &bad),
            Err(RobotError::Backend(_))
        ));
    }

    #[test]
    fn protective_stop_after_k_moves_then_clear_resumes() {
        let options = SimRobotOptions {
            faults: SimFaults {
                protective_stop_after_moves: Some(2),
                ..Default::default()
            },
            ..Default::default()
        };
        let mut robot = sim(options);
        let limits = MotionLimits::default();
        robot.move_joints(&HOME, &limits).unwrap();
        robot.move_joints(&HOME, &limits).unwrap();
        assert!(matches!(
            robot.move_joints(&HOME, &limits),
            Err(RobotError::ProtectiveStop)
        ));
        assert_eq!(robot.status().unwrap(), RobotStatus::ProtectiveStop);
        // State can still be read while stopped.
        assert!(robot.base_from_flange().is_ok());
        assert!(matches!(
            robot.move_joints(&HOME, &limits),
            Err(RobotError::ProtectiveStop)
        ));
        robot.clear_stop();
        assert_eq!(robot.status().unwrap(), RobotStatus::Ready);
        robot.move_joints(&HOME, &limits).unwrap();
        assert_eq!(robot.moves_completed(), 3);
    }

    #[test]
    fn emergency_stop_and_connection_loss_are_reported() {
        let mut robot = sim(SimRobotOptions {
            faults: SimFaults {
                emergency_stop_after_moves: Some(0),
                ..Default::default()
            },
            ..Default::default()
        });
        let limits = MotionLimits::default();
        assert!(matches!(
            robot.move_joints(&HOME, &limits),
            Err(RobotError::EmergencyStop)
        ));
        assert_eq!(robot.status().unwrap(), RobotStatus::EmergencyStop);

        let mut robot = sim(SimRobotOptions {
            faults: SimFaults {
                connection_lost_after_moves: Some(1),
                ..Default::default()
            },
            ..Default::default()
        });
        robot.move_joints(&HOME, &limits).unwrap();
        assert!(matches!(
            robot.move_joints(&HOME, &limits),
            Err(RobotError::ConnectionLost(_))
        ));
        assert!(matches!(
            robot.base_from_flange(),
            Err(RobotError::ConnectionLost(_))
        ));
        robot.clear_stop();
        assert!(robot.status().is_err());
    }

    #[test]
    fn move_duration_is_waited() {
        let mut robot = sim(SimRobotOptions {
            move_duration: Duration::from_millis(30),
            ..Default::default()
        });
        let t = Instant::now();
        robot.move_joints(&HOME, &MotionLimits::default()).unwrap();
        assert!(t.elapsed() >= Duration::from_millis(30));
    }

    #[test]
    fn moves_at_limits_take_the_trapezoid_time_and_then_ring_down() {
        let limits = MotionLimits {
            joint_speed: 2.0,
            joint_acceleration: 8.0,
            ..MotionLimits::default()
        };
        let ringing = Ringing {
            amplitude_rad: 0.2f64.to_radians(),
            frequency_hz: 8.0,
            decay_s: 0.1,
        };
        let mut robot = sim(SimRobotOptions {
            move_at_limits: true,
            ringing: Some(ringing),
            ..Default::default()
        });
        let mut target = HOME;
        target[0] += 0.8;
        target[2] -= 0.4;
        let expected = limits.joint_move_time(&HOME, &target);
        let t0 = Instant::now();
        robot.move_joints(&target, &limits).unwrap();
        let took = t0.elapsed().as_secs_f64();
        assert!(
            took >= expected && took < expected + 0.05,
            "{took} s vs {expected} s"
        );
        // Right after arrival the joints still move; the lead joint the most, the others in
        // proportion to their travel, the untouched ones not at all.
        let arrived = Instant::now();
        let (_, speeds) = robot.joint_state_at(arrived);
        let omega = 2.0 * std::f64::consts::PI * ringing.frequency_hz;
        assert!(
            speeds[0].abs() > 0.5 * ringing.amplitude_rad * omega,
            "{speeds:?}"
        );
        assert!((speeds[2] + 0.5 * speeds[0]).abs() < 1e-12, "{speeds:?}");
        assert_eq!(speeds[1], 0.0);
        let reported = robot.joint_speeds().unwrap().unwrap();
        assert!(reported[0].abs() > 0.0);
        // A second later the ringing is gone (e^-10) and the arm stands on its target.
        let (q, speeds) = robot.joint_state_at(arrived + Duration::from_secs(1));
        assert!(speeds.iter().all(|v| v.abs() < 1e-5), "{speeds:?}");
        assert!(q.iter().zip(&target).all(|(a, b)| (a - b).abs() < 1e-6));
        // Half-way through the move the lead joint runs at the speed limit.
        let mid = t0 + Duration::from_secs_f64(expected / 2.0);
        let (q, speeds) = robot.joint_state_at(mid);
        assert!((speeds[0] - limits.joint_speed).abs() < 1e-9, "{speeds:?}");
        assert!((q[0] - (HOME[0] + 0.4)).abs() < 1e-3, "{q:?}");
    }

    #[test]
    fn bad_options_are_clear_errors() {
        let err = SimRobot::new(
            UrModel::ur5e(),
            HOME,
            SimRobotOptions {
                repeatability_m: -1.0,
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(err.to_string().contains("repeatability_m = -1 m"), "{err}");
        let err = SimRobot::new(
            UrModel::ur5e(),
            Joints::from([0.0, 0.0, 0.0, 0.0, 0.0, 10.0]),
            SimRobotOptions::default(),
        )
        .unwrap_err();
        assert!(err.to_string().contains("joint 5"), "{err}");
    }
}
