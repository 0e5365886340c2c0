//! The mock controller's arm and program state, shared by every connection: joint positions,
//! motion interpolation, the RTDE registers, and an emulation of the command loop of ur_rtde's
//! control script (`rtde_control.script`). State advances lazily: every reader or writer calls
//! [`Arm::advance`] with the current time first, so no thread ticks while nobody is connected.
//!
//! Motion: a joint move runs at constant speed, or — with `trapezoidal_moves` — on the
//! trapezoidal profile a UR's `moveJ` follows at the commanded speed and acceleration. With
//! `ringing` the arm rings down after a joint move (a decaying joint oscillation): the move is
//! reported done on arrival while `actual_q` / `actual_qd` still show the arm swinging, as a real
//! arm's do for a moment.
//!
//! Frames: `T_base_flange` from the kinematics; the TCP pose the controller reports is
//! `T_base_tcp = T_base_flange * T_flange_tcp`. Metres, radians, rotation vectors on the wire.

use std::time::{Duration, Instant};

use handeye_core::geometry::{pose_from_rotvec, rotvec, Pose};
use handeye_robot::kinematics::UrModel;
use handeye_robot::sim::Ringing;
use handeye_robot::{trapezoid_at, trapezoid_time, Joints};
use nalgebra::{Isometry3, Translation3, Vector3};

use super::MockFaults;

/// Number of general-purpose RTDE registers of each kind (0..47, upper range included).
pub(crate) const REGISTERS: usize = 48;

/// `runtime_state` values (ur_rtde's RuntimeState).
pub(crate) const RUNTIME_STOPPED: u32 = 1;
/// The control program is running.
pub(crate) const RUNTIME_PLAYING: u32 = 2;

/// `safety_status_bits`: normal mode.
const SAFETY_NORMAL: u32 = 1 << 0;
/// `safety_status_bits`: protective stop.
pub(crate) const SAFETY_PROTECTIVE_STOP: u32 = 1 << 2;
/// `safety_status_bits`: emergency stop (any source).
pub(crate) const SAFETY_EMERGENCY_STOP: u32 = 1 << 7;
/// `safety_status_bits`: stopped due to safety.
const SAFETY_STOPPED_DUE_TO_SAFETY: u32 = 1 << 10;

/// Control-script handshake values in `output_int_register_0`.
const SCRIPT_READY: i32 = 1;
const SCRIPT_DONE: i32 = 2;

/// Rotation rate (rad/s) of a linear move that only turns the tool: UR's movel speed is a
/// translation speed, so the mock needs some rate for pure rotations.
const LINEAR_MOVE_ROTATION_SPEED: f64 = std::f64::consts::FRAC_PI_2;

/// Fastest speed a move may ask for (rad/s for moveJ, m/s for moveL): well above a UR's
/// 3.14 rad/s and 3 m/s, so only nonsense is refused.
const MAX_MOVE_SPEED: f64 = 10.0;
/// Longest move the mock accepts, s: a slower one (speed 1e-300) is a client bug, refused with a
/// script error rather than interpolated for centuries (or overflowing `Duration`).
const MAX_MOVE_DURATION_S: f64 = 3600.0;

/// Command ids of ur_rtde 1.6.5 (`RTDE::RobotCommand::Type`) that the mock understands.
mod cmd {
    pub(super) const MOVEJ: i32 = 1;
    pub(super) const MOVEJ_IK: i32 = 2;
    pub(super) const MOVEL: i32 = 3;
    pub(super) const MOVEL_FK: i32 = 4;
    pub(super) const TEACH_MODE: i32 = 18;
    pub(super) const END_TEACH_MODE: i32 = 19;
    pub(super) const SET_TCP: i32 = 29;
    pub(super) const STOPL: i32 = 33;
    pub(super) const STOPJ: i32 = 34;
    pub(super) const GET_TCP_OFFSET: i32 = 40;
    pub(super) const GET_FORWARD_KINEMATICS_DEFAULT: i32 = 43;
    pub(super) const GET_ACTUAL_TOOL_FLANGE_POSE: i32 = 58;
    pub(super) const STOP_SCRIPT: i32 = 255;
    /// Commands the script runs and then signals "ready" instead of "done".
    pub(super) const REALTIME: [i32; 16] =
        [24, 11, 9, 10, 6, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71];
}

#[derive(Debug, Clone, Copy)]
enum MotionPath {
    Joint { from: Joints, to: Joints },
    Linear { from: Pose, to: Pose },
}

#[derive(Debug, Clone, Copy)]
struct Motion {
    path: MotionPath,
    started: Instant,
    duration: Duration,
    /// The stall fault: the arm never leaves the start.
    stalled: bool,
    /// Fraction of the path at which an injected protective stop halts the arm.
    protective_stop_at: Option<f64>,
    asynchronous: bool,
    /// `(speed, acceleration)` of a trapezoidal joint move; `None`: constant speed.
    profile: Option<(f64, f64)>,
}

/// The arm ringing down after a joint move.
#[derive(Debug, Clone, Copy)]
struct RingDown {
    arrived: Instant,
    to: Joints,
    /// Amplitude per joint, rad.
    amplitude: Joints,
}

/// The arm and controller state of one mock.
#[derive(Debug)]
pub(crate) struct Arm {
    model: UrModel,
    flange_from_tcp: Pose,
    instant_moves: bool,
    trapezoidal_moves: bool,
    ringing: Option<Ringing>,
    ring: Option<RingDown>,
    faults: MockFaults,
    epoch: Instant,
    joints: Joints,
    motion: Option<Motion>,
    moves_started: usize,
    moves_completed: usize,
    /// Freedrive (teach mode) is on: the arm follows a hand ([`Arm::hand_guide`]).
    teach_mode: bool,
    program_running: bool,
    executing_cmd: bool,
    /// A synchronous command (a move) whose "done" the script has not signalled yet.
    pending_done: bool,
    pub(crate) in_int: [i32; REGISTERS],
    pub(crate) in_double: [f64; REGISTERS],
    out_int: [i32; REGISTERS],
    out_double: [f64; REGISTERS],
    /// 0, or 24 when the client uses the upper register range.
    reg_offset: usize,
    safety_bits: u32,
    async_op_id: i32,
    async_wr_count: i32,
    protective_stop_fired: bool,
    scripts_received: usize,
}

/// A consistent snapshot for one outgoing data package.
#[derive(Debug, Clone)]
pub(crate) struct Snapshot {
    pub timestamp: f64,
    pub joints: Joints,
    pub target_joints: Joints,
    pub tcp_pose: [f64; 6],
    pub target_tcp_pose: [f64; 6],
    pub joint_speeds: Joints,
    pub runtime_state: u32,
    pub robot_status_bits: u32,
    pub safety_status_bits: u32,
    pub safety_mode: i32,
    pub out_int: [i32; REGISTERS],
    pub out_double: [f64; REGISTERS],
}

/// The largest joint travel of a joint move, rad.
fn lead_travel(from: &Joints, to: &Joints) -> f64 {
    from.iter()
        .zip(to)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
}

/// `[x, y, z, rx, ry, rz]` of a pose, the UR wire form.
pub(crate) fn to_ur_vector(pose: &Pose) -> [f64; 6] {
    let t = pose.translation.vector;
    let r = rotvec(&pose.rotation);
    [t.x, t.y, t.z, r.x, r.y, r.z]
}

/// The pose of a UR `[x, y, z, rx, ry, rz]` vector.
pub(crate) fn from_ur_vector(v: &[f64]) -> Pose {
    pose_from_rotvec(
        Vector3::new(v[0], v[1], v[2]),
        Vector3::new(v[3], v[4], v[5]),
    )
}

impl Arm {
    pub(crate) fn new(
        model: UrModel,
        start: Joints,
        flange_from_tcp: Pose,
        instant_moves: bool,
        faults: MockFaults,
    ) -> Self {
        Arm {
            model,
            flange_from_tcp,
            instant_moves,
            trapezoidal_moves: false,
            ringing: None,
            ring: None,
            faults,
            epoch: Instant::now(),
            joints: start,
            motion: None,
            moves_started: 0,
            moves_completed: 0,
            teach_mode: false,
            program_running: false,
            executing_cmd: false,
            pending_done: false,
            in_int: [0; REGISTERS],
            in_double: [0.0; REGISTERS],
            out_int: [0; REGISTERS],
            out_double: [0.0; REGISTERS],
            reg_offset: 0,
            safety_bits: SAFETY_NORMAL,
            async_op_id: 0,
            async_wr_count: 0,
            protective_stop_fired: false,
            scripts_received: 0,
        }
    }

    /// Joint moves on the trapezoidal profile of the commanded speed and acceleration, and the
    /// ring-down after a joint move (see the module docs).
    pub(crate) fn with_motion_model(mut self, trapezoidal: bool, ringing: Option<Ringing>) -> Self {
        self.trapezoidal_moves = trapezoidal;
        self.ringing = ringing;
        self
    }

    pub(crate) fn joints(&self) -> Joints {
        self.joints
    }

    pub(crate) fn base_from_flange(&self) -> Pose {
        self.model.forward(&self.joints)
    }

    pub(crate) fn base_from_tcp(&self) -> Pose {
        self.base_from_flange() * self.flange_from_tcp
    }

    /// Whether freedrive (teach mode) is on.
    pub(crate) fn teach_mode(&self) -> bool {
        self.teach_mode
    }

    /// A person pushes the arm to `joints`: it follows only in freedrive, and only when no move
    /// runs. Returns whether it moved.
    pub(crate) fn hand_guide(&mut self, joints: Joints) -> bool {
        if !self.teach_mode || self.motion.is_some() {
            return false;
        }
        self.joints = joints;
        true
    }

    pub(crate) fn moves_completed(&self) -> usize {
        self.moves_completed
    }

    pub(crate) fn moves_started(&self) -> usize {
        self.moves_started
    }

    pub(crate) fn program_running(&self) -> bool {
        self.program_running
    }

    pub(crate) fn scripts_received(&self) -> usize {
        self.scripts_received
    }

    pub(crate) fn is_moving(&self) -> bool {
        self.motion.is_some()
    }

    pub(crate) fn set_register_offset(&mut self, offset: usize) {
        self.reg_offset = offset;
    }

    /// Whether the "drop the connection" fault has fired.
    pub(crate) fn connection_dropped(&self) -> bool {
        self.faults
            .drop_connection_after_moves
            .is_some_and(|k| self.moves_completed >= k)
    }

    /// Whether the "stop streaming" fault has fired.
    pub(crate) fn streaming_stopped(&self) -> bool {
        self.faults
            .stop_streaming_after_moves
            .is_some_and(|k| self.moves_completed >= k)
    }

    /// Whether a protective or emergency stop is active.
    pub(crate) fn safety_stopped(&self) -> bool {
        self.safety_bits & (SAFETY_PROTECTIVE_STOP | SAFETY_EMERGENCY_STOP) != 0
    }

    pub(crate) fn safety_bits(&self) -> u32 {
        self.safety_bits
    }

    /// Raises a protective stop (or, with `emergency`, an emergency stop): the arm halts where it
    /// is and the control program stops, as on a real controller.
    pub(crate) fn raise_stop(&mut self, now: Instant, emergency: bool) {
        self.advance(now);
        self.halt(emergency);
    }

    /// Halts the arm where it is and stops the program with a safety stop.
    fn halt(&mut self, emergency: bool) {
        self.motion = None;
        self.ring = None;
        self.pending_done = false;
        self.program_running = false;
        self.executing_cmd = false;
        self.safety_bits = SAFETY_STOPPED_DUE_TO_SAFETY
            | if emergency {
                SAFETY_EMERGENCY_STOP
            } else {
                SAFETY_PROTECTIVE_STOP
            };
    }

    /// Clears protective and emergency stops (the dashboard's "unlock protective stop", or a
    /// person at the pendant). The program stays stopped until a script is uploaded again.
    pub(crate) fn clear_stops(&mut self) {
        self.safety_bits = SAFETY_NORMAL;
    }

    /// A complete control program arrived on the script port: start it, as the controller runs a
    /// program sent to the secondary/real-time interface.
    pub(crate) fn start_program(&mut self, now: Instant) {
        self.advance(now);
        self.scripts_received += 1;
        if self.safety_stopped() {
            return; // a stopped controller refuses to run programs
        }
        self.program_running = true;
        self.executing_cmd = false;
        self.pending_done = false;
        self.motion = None;
        self.write_async_progress(-1);
        self.out_int[self.reg_offset] = SCRIPT_READY;
    }

    /// The dashboard's "stop": stops the program and any motion.
    pub(crate) fn stop_program(&mut self, now: Instant) {
        self.advance(now);
        self.motion = None;
        self.pending_done = false;
        self.program_running = false;
        self.executing_cmd = false;
        // Freedrive is a command of the program: it ends with it.
        self.teach_mode = false;
    }

    /// Brings the state up to `now`: moves the arm along its path, finishes moves, then runs one
    /// iteration of the control script's command loop.
    pub(crate) fn advance(&mut self, now: Instant) {
        self.step_motion(now);
        self.step_script(now);
    }

    fn step_motion(&mut self, now: Instant) {
        let Some(motion) = self.motion else {
            self.step_ringing(now);
            return;
        };
        if motion.stalled {
            return;
        }
        let elapsed = now.saturating_duration_since(motion.started).as_secs_f64();
        let fraction = if motion.duration.is_zero() || elapsed >= motion.duration.as_secs_f64() {
            1.0
        } else {
            match (motion.profile, motion.path) {
                (Some((v, a)), MotionPath::Joint { from, to }) => {
                    trapezoid_at(lead_travel(&from, &to), v, a, elapsed).0
                }
                _ => (elapsed / motion.duration.as_secs_f64()).min(1.0),
            }
        };
        if let Some(stop_at) = motion.protective_stop_at {
            if fraction >= stop_at {
                self.set_path_position(&motion.path, stop_at);
                self.protective_stop_fired = true;
                self.halt(false);
                return;
            }
        }
        self.set_path_position(&motion.path, fraction);
        if fraction >= 1.0 {
            self.motion = None;
            self.moves_completed += 1;
            if let (Some(ringing), MotionPath::Joint { from, to }) = (self.ringing, motion.path) {
                let lead = lead_travel(&from, &to);
                if lead > 0.0 {
                    self.ring = Some(RingDown {
                        arrived: motion.started + motion.duration,
                        to,
                        amplitude: Joints::from_fn(6, |i| {
                            ringing.amplitude_rad * (to[i] - from[i]) / lead
                        }),
                    });
                    self.step_ringing(now);
                }
            }
            if motion.asynchronous {
                self.write_async_progress(-1);
            } else if self.pending_done {
                self.pending_done = false;
                self.out_int[self.reg_offset] = SCRIPT_DONE;
            }
        } else if motion.asynchronous {
            self.write_async_progress((fraction * 1000.0) as i32);
        }
    }

    /// The ring-down offset (rad) and speed (rad/s) of every joint at `now`, or `None` when
    /// the arm does not ring (any more).
    fn ringing_at(&self, now: Instant) -> Option<(Joints, Joints)> {
        let (ring, ringing) = (self.ring?, self.ringing?);
        let t = now.saturating_duration_since(ring.arrived).as_secs_f64();
        let w = 2.0 * std::f64::consts::PI * ringing.frequency_hz;
        let envelope = (-t / ringing.decay_s).exp();
        let (sin, cos) = (w * t).sin_cos();
        Some((
            Joints::from_fn(6, |i| ring.amplitude[i] * envelope * sin),
            Joints::from_fn(6, |i| {
                ring.amplitude[i] * envelope * (w * cos - sin / ringing.decay_s)
            }),
        ))
    }

    /// Puts a ringing arm where the oscillation has it now; ends the ringing once it is below
    /// a micro-radian.
    fn step_ringing(&mut self, now: Instant) {
        let Some(ring) = self.ring else { return };
        let Some((offset, _)) = self.ringing_at(now) else {
            return;
        };
        self.joints = Joints::from_fn(6, |i| ring.to[i] + offset[i]);
        let t = now.saturating_duration_since(ring.arrived).as_secs_f64();
        if self
            .ringing
            .is_some_and(|r| (-t / r.decay_s).exp() * r.amplitude_rad < 1e-6)
        {
            self.joints = ring.to;
            self.ring = None;
        }
    }

    /// Puts the arm at `fraction` of `path`.
    fn set_path_position(&mut self, path: &MotionPath, fraction: f64) {
        match *path {
            MotionPath::Joint { from, to } => {
                self.joints = Joints::from_fn(6, |i| from[i] + (to[i] - from[i]) * fraction);
            }
            MotionPath::Linear { from, to } => {
                let pose = Isometry3::from_parts(
                    Translation3::from(
                        from.translation
                            .vector
                            .lerp(&to.translation.vector, fraction),
                    ),
                    from.rotation.slerp(&to.rotation, fraction),
                );
                // Stay on the branch the arm is on: nearest solution to the current joints.
                if let Some(q) = self.model.inverse_nearest(&pose, &self.joints) {
                    self.joints = q;
                }
            }
        }
    }

    fn step_script(&mut self, now: Instant) {
        if !self.program_running || self.pending_done {
            return;
        }
        let off = self.reg_offset;
        let command = self.in_int[off];
        if cmd::REALTIME.contains(&command) {
            self.process(command, now);
            self.out_int[off] = SCRIPT_READY;
        } else if command == 0 {
            self.executing_cmd = false;
            self.out_int[off] = SCRIPT_READY;
        } else if !self.executing_cmd {
            self.executing_cmd = true;
            match self.process(command, now) {
                Outcome::Done => self.out_int[off] = SCRIPT_DONE,
                Outcome::Pending => self.pending_done = true,
                Outcome::Exit => {
                    self.program_running = false;
                    self.teach_mode = false;
                    self.executing_cmd = false;
                    self.motion = None;
                }
            }
        }
    }

    fn input_vector6(&self, first: usize) -> [f64; 6] {
        std::array::from_fn(|i| self.in_double[self.reg_offset + first + i])
    }

    fn write_output_vector6(&mut self, first: usize, v: &[f64; 6]) {
        for (i, x) in v.iter().enumerate() {
            self.out_double[self.reg_offset + first + i] = *x;
        }
    }

    /// The async progress register, in the control script's bit layout.
    fn write_async_progress(&mut self, value: i32) {
        self.async_wr_count = (self.async_wr_count + 1) % 128;
        if value == 0 {
            self.async_op_id = (self.async_op_id + 1) % 128;
        }
        let mut reg = self.async_wr_count * 65536 + self.async_op_id * 16_777_216;
        if value >= 0 {
            reg += value.min(32767) + 32768;
        }
        self.out_int[self.reg_offset + 2] = reg;
    }

    fn process(&mut self, command: i32, now: Instant) -> Outcome {
        let asynchronous = self.in_int[self.reg_offset + 1] == 1;
        match command {
            cmd::MOVEJ | cmd::MOVEJ_IK | cmd::MOVEL | cmd::MOVEL_FK => {
                let speed = self.in_double[self.reg_offset + 6];
                let target = self.input_vector6(0);
                let path = match command {
                    cmd::MOVEJ => MotionPath::Joint {
                        from: self.joints,
                        to: target.into(),
                    },
                    cmd::MOVEJ_IK => {
                        let flange = from_ur_vector(&target) * self.flange_from_tcp.inverse();
                        match self.model.inverse_nearest(&flange, &self.joints) {
                            Some(to) => MotionPath::Joint {
                                from: self.joints,
                                to,
                            },
                            None => return self.script_error("movej_ik: no IK solution"),
                        }
                    }
                    cmd::MOVEL => MotionPath::Linear {
                        from: self.base_from_flange(),
                        to: from_ur_vector(&target) * self.flange_from_tcp.inverse(),
                    },
                    _ => MotionPath::Linear {
                        from: self.base_from_flange(),
                        to: self.model.forward(&target.into()),
                    },
                };
                if let MotionPath::Linear { to, .. } = path {
                    if self.model.inverse_nearest(&to, &self.joints).is_none() {
                        return self.script_error("movel: target not reachable");
                    }
                }
                self.start_motion(path, speed, now, asynchronous)
            }
            cmd::STOPL | cmd::STOPJ => {
                // Deceleration is not modelled: the arm halts where it is.
                self.step_motion(now);
                if self.motion.take().is_some_and(|m| m.asynchronous) {
                    self.write_async_progress(-1);
                }
                Outcome::Done
            }
            cmd::SET_TCP => {
                self.flange_from_tcp = from_ur_vector(&self.input_vector6(0));
                Outcome::Done
            }
            cmd::GET_TCP_OFFSET => {
                let v = to_ur_vector(&self.flange_from_tcp);
                self.write_output_vector6(0, &v);
                Outcome::Done
            }
            cmd::GET_FORWARD_KINEMATICS_DEFAULT => {
                let v = to_ur_vector(&self.base_from_tcp());
                self.write_output_vector6(0, &v);
                Outcome::Done
            }
            cmd::GET_ACTUAL_TOOL_FLANGE_POSE => {
                let v = to_ur_vector(&self.base_from_flange());
                self.write_output_vector6(0, &v);
                Outcome::Done
            }
            cmd::TEACH_MODE => {
                self.teach_mode = true;
                Outcome::Done
            }
            cmd::END_TEACH_MODE => {
                self.teach_mode = false;
                Outcome::Done
            }
            cmd::STOP_SCRIPT => Outcome::Exit,
            // Anything else (I/O, payload, watchdog, ...) has no effect on the mock arm.
            _ => Outcome::Done,
        }
    }

    /// A runtime error in the control script ends the program, as on the controller.
    fn script_error(&mut self, message: &str) -> Outcome {
        eprintln!("mock-ur: control script error: {message}; program stopped");
        Outcome::Exit
    }

    fn start_motion(
        &mut self,
        path: MotionPath,
        speed: f64,
        now: Instant,
        asynchronous: bool,
    ) -> Outcome {
        // As the controller does with a bad argument: a runtime error that ends the program
        // (the client sees the program stop), never a panic in the connection thread.
        if !(speed.is_finite() && speed > 0.0 && speed <= MAX_MOVE_SPEED) {
            return self.script_error(&format!(
                "move speed {speed:e} is outside (0, {MAX_MOVE_SPEED}]"
            ));
        }
        let acceleration = self.in_double[self.reg_offset + 7];
        let profile = (self.trapezoidal_moves
            && matches!(path, MotionPath::Joint { .. })
            && acceleration.is_finite()
            && acceleration > 0.0)
            .then_some((speed, acceleration));
        let seconds = match path {
            MotionPath::Joint { from, to } => match profile {
                Some((v, a)) => trapezoid_time(lead_travel(&from, &to), v, a),
                None => lead_travel(&from, &to) / speed,
            },
            MotionPath::Linear { from, to } => {
                let distance = (to.translation.vector - from.translation.vector).norm();
                let angle = from.rotation.angle_to(&to.rotation);
                (distance / speed).max(angle / LINEAR_MOVE_ROTATION_SPEED)
            }
        };
        let duration = match Duration::try_from_secs_f64(seconds) {
            _ if self.instant_moves => Duration::ZERO,
            Ok(d) if seconds <= MAX_MOVE_DURATION_S => d,
            _ => {
                return self.script_error(&format!(
                    "a move at speed {speed:e} would take {seconds:e} s (more than {MAX_MOVE_DURATION_S} s)"
                ))
            }
        };
        let index = self.moves_started;
        self.moves_started += 1;
        let protective_stop_at = match self.faults.protective_stop_after_moves {
            Some(k) if !self.protective_stop_fired && self.moves_completed >= k => Some(0.5),
            _ => None,
        };
        // A new move starts from where the ringing arm is.
        self.ring = None;
        self.motion = Some(Motion {
            path,
            started: now,
            duration,
            stalled: self.faults.stall_move == Some(index),
            protective_stop_at,
            asynchronous,
            profile: profile.filter(|_| !self.instant_moves),
        });
        if asynchronous {
            self.write_async_progress(0);
            Outcome::Done
        } else {
            Outcome::Pending
        }
    }

    /// The state for one data package.
    pub(crate) fn snapshot(&mut self, now: Instant) -> Snapshot {
        self.advance(now);
        let target_joints = match self.motion {
            Some(Motion {
                path: MotionPath::Joint { to, .. },
                ..
            }) => to,
            _ => self.joints,
        };
        let target_tcp = match self.motion {
            Some(Motion {
                path: MotionPath::Linear { to, .. },
                ..
            }) => to * self.flange_from_tcp,
            _ => self.model.forward(&target_joints) * self.flange_from_tcp,
        };
        let joint_speeds = match self.motion {
            Some(Motion {
                path: MotionPath::Joint { from, to },
                duration,
                stalled: false,
                profile,
                started,
                ..
            }) if !duration.is_zero() => match profile {
                Some((v, a)) => {
                    let lead = lead_travel(&from, &to);
                    let t = now.saturating_duration_since(started).as_secs_f64();
                    let (_, lead_speed) = trapezoid_at(lead, v, a, t);
                    Joints::from_fn(6, |i| (to[i] - from[i]) / lead * lead_speed)
                }
                None => Joints::from_fn(6, |i| (to[i] - from[i]) / duration.as_secs_f64()),
            },
            None => self
                .ringing_at(now)
                .map_or(Joints::zeros(6), |(_, speeds)| speeds),
            _ => Joints::zeros(6),
        };
        let safety_mode = if self.safety_bits & SAFETY_EMERGENCY_STOP != 0 {
            7 // ROBOT_EMERGENCY_STOP
        } else if self.safety_bits & SAFETY_PROTECTIVE_STOP != 0 {
            3 // PROTECTIVE_STOP
        } else {
            1 // NORMAL
        };
        Snapshot {
            timestamp: now.saturating_duration_since(self.epoch).as_secs_f64(),
            joints: self.joints,
            target_joints,
            tcp_pose: to_ur_vector(&self.base_from_tcp()),
            target_tcp_pose: to_ur_vector(&target_tcp),
            joint_speeds,
            runtime_state: if self.program_running {
                RUNTIME_PLAYING
            } else {
                RUNTIME_STOPPED
            },
            // Power on, brakes released; bit 1 = program running.
            robot_status_bits: 1 | if self.program_running { 2 } else { 0 },
            safety_status_bits: self.safety_bits,
            safety_mode,
            out_int: self.out_int,
            out_double: self.out_double,
        }
    }
}

enum Outcome {
    /// The command finished: signal done.
    Done,
    /// A synchronous move started: signal done when it arrives.
    Pending,
    /// Stop the program (stopScript, or a script runtime error).
    Exit,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An arm running the control program with a moveJ to `target` at `speed` in the registers.
    fn arm_with_movej(speed: f64, target: [f64; 6]) -> (Arm, Instant) {
        let model = UrModel::ur5e();
        let start = Joints::from_six([0.0, -1.5, 1.5, -1.5, -1.5, 0.0]);
        let mut arm = Arm::new(model, start, Pose::identity(), false, MockFaults::default());
        let now = Instant::now();
        arm.start_program(now);
        arm.in_int[0] = cmd::MOVEJ;
        arm.in_double[..6].copy_from_slice(&target);
        arm.in_double[6] = speed;
        (arm, now)
    }

    #[test]
    fn issue13_absurd_move_speeds_end_the_program_instead_of_panicking() {
        let target = [0.5, -1.2, 1.4, -1.5, -1.5, 0.3];
        for speed in [1e-300, 0.0, -1.0, f64::NAN, f64::INFINITY, 1e6] {
            let (mut arm, now) = arm_with_movej(speed, target);
            arm.advance(now); // the command is read here; 1e-300 used to panic in Duration
            assert!(
                !arm.program_running(),
                "speed {speed}: program still running"
            );
            assert!(!arm.is_moving(), "speed {speed}: moving");
            assert_eq!(arm.moves_started(), 0, "speed {speed}");
        }
        // A sane speed still moves, and a huge joint target at a sane speed is refused too.
        let (mut arm, now) = arm_with_movej(1.0, target);
        arm.advance(now);
        assert!(arm.program_running() && arm.is_moving());
        let (mut arm, now) = arm_with_movej(1.0, [1e300, 0.0, 0.0, 0.0, 0.0, 0.0]);
        arm.advance(now);
        assert!(!arm.program_running());
    }
}
