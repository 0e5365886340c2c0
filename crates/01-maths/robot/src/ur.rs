//! The Universal Robots backend: [`UrRobot`] drives a real UR controller (or the mock in
//! `mocks/`) through ur_rtde 1.6.5, behind the `ur-rtde` cargo feature.
//!
//! Layers: `ur/shim.cpp` is a C API over ur_rtde whose functions catch every C++ exception and
//! return a status plus message; `ur/ffi.rs` declares it; this file is the only place with
//! `unsafe`. One worker thread owns the ur_rtde handle and runs every call; the caller waits
//! with a deadline, so a controller that stops answering gives an error instead of a hang (ur_rtde
//! itself has no timeout on its first data package and waits up to 300 s for a move).
//!
//! Frames: the controller reports and takes the TCP pose `T_base_tcp` as `[x, y, z, rx, ry, rz]`
//! (m, rotation vector in rad). The active TCP offset `T_flange_tcp` is read once at connect
//! (or given in the config), and every pose crossing this API is the flange pose:
//! `T_base_flange = T_base_tcp * inv(T_flange_tcp)`. Rotation vectors go through
//! [`handeye_core::geometry::rotvec`], which stays exact near 180°.
//!
//! Moves are sent asynchronously and then watched: the move ends when the script's async
//! operation finishes; a protective or emergency stop, a lost connection (closed socket, or no
//! fresh state for `stale_after`), or the move deadline ends it with the matching
//! [`RobotError`] (after a deadline the arm is told to stop first).
//!
//! Why one file of ~700 lines: it is the whole safe layer over the FFI, and keeping every
//! `unsafe` call, the one thread that owns the handle and the deadline logic that guards it in
//! one place is what makes the `// SAFETY:` arguments checkable ("only the worker touches the
//! handle").

mod ffi;

use std::ffi::{c_char, c_int, CString};
use std::ptr::NonNull;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use nalgebra::Vector3;

use super::kinematics::UrModel;
use super::{six_joints, Joints, MotionLimits, Robot, RobotError, RobotStatus, WorkspaceBox};
use handeye_core::geometry::{pose_from_rotvec, rotvec, Pose};

/// `runtime_state` PLAYING: the control script runs.
const RUNTIME_PLAYING: u32 = 2;
/// `safety_status_bits` bit 2: protective stop.
const SAFETY_PROTECTIVE_STOP: u32 = 1 << 2;
/// Bits 5, 6, 7: system, robot, any emergency stop.
const SAFETY_EMERGENCY_STOP: u32 = (1 << 5) | (1 << 6) | (1 << 7);
/// `robot_mode` RUNNING: powered, brakes released.
const ROBOT_MODE_RUNNING: i32 = 7;
/// Async progress register: bit 15 = an async operation runs; bits 24..30 = its id.
const ASYNC_RUNNING: u32 = 0x8000;

/// The id of the latest async operation in the async progress register (bits 24..30); it
/// changes when a new move starts.
fn async_op_id(async_status: u32) -> u32 {
    (async_status >> 24) & 0x7F
}
/// How often a move is polled.
const POLL_PERIOD: Duration = Duration::from_millis(4);
/// Deceleration for stops, m/s² (stopL): firm but within what the controller allows.
const STOP_DECELERATION: f64 = 1.0;
/// Controller time the receive interface must advance past a move's end before the pose is
/// read back, so the reading is from after the move (two 500 Hz cycles plus margin).
const FRESH_AFTER_MOVE_S: f64 = 0.01;
/// Wait before sending a refused first command again after the control script (re)started.
const RESTART_SETTLE: Duration = Duration::from_millis(100);
/// Capacity of the shim's error-message buffer.
const ERR_LEN: usize = 512;

/// How to reach and drive a UR controller.
#[derive(Debug, Clone, PartialEq)]
pub struct UrRobotConfig {
    /// Controller host name or IP address.
    pub host: String,
    /// How long connecting may take (ur_rtde's own connect has no timeout on its first data).
    pub connect_timeout: Duration,
    /// How long one non-move call (state, pose, TCP offset, stop) may take.
    pub call_timeout: Duration,
    /// How long one move may take from command to arrival.
    pub move_timeout: Duration,
    /// No new state from the controller for this long counts as a lost connection.
    pub stale_after: Duration,
    /// RTDE frequency, Hz; `None` lets ur_rtde choose (500 Hz on e-Series).
    pub frequency_hz: Option<f64>,
    /// The active TCP offset `T_flange_tcp`; `None` reads it from the controller at connect.
    pub flange_from_tcp: Option<Pose>,
    /// Every target's flange origin must lie inside this box; nothing is sent otherwise.
    pub workspace: Option<WorkspaceBox>,
    /// Kinematics used to check joint-move targets against `workspace`.
    pub model: Option<UrModel>,
}

impl UrRobotConfig {
    /// Defaults for `host`: 10 s to connect, 5 s per call, 120 s per move, 1 s staleness,
    /// TCP offset read from the controller, no workspace box.
    pub fn new(host: impl Into<String>) -> Self {
        UrRobotConfig {
            host: host.into(),
            connect_timeout: Duration::from_secs(10),
            call_timeout: Duration::from_secs(5),
            move_timeout: Duration::from_secs(120),
            stale_after: Duration::from_secs(1),
            frequency_hz: None,
            flange_from_tcp: None,
            workspace: None,
            model: None,
        }
    }
}

/// Failures specific to this backend, carried inside [`RobotError::Backend`].
#[derive(Debug, thiserror::Error)]
pub enum UrError {
    /// A ur_rtde call threw or failed.
    #[error("ur_rtde {call} failed: {message}")]
    Call {
        /// The call (moveL, getTCPOffset, ...).
        call: &'static str,
        /// ur_rtde's message.
        message: String,
    },
    /// The controller did not run a command (ur_rtde returned false) with no stop active.
    #[error("the controller did not run {call} (is the arm in remote control and the program able to run?)")]
    Refused {
        /// The call.
        call: &'static str,
    },
    /// The control program stopped while a move ran, without a safety stop.
    #[error("the control program on the robot stopped during {call}")]
    ProgramStopped {
        /// The call.
        call: &'static str,
    },
    /// A target holds NaN or infinity.
    #[error("{what} target is not finite")]
    NonFinite {
        /// Which target.
        what: &'static str,
    },
    /// The host name cannot be passed to C (it holds a NUL byte).
    #[error("robot host {0:?} contains a NUL byte")]
    BadHost(String),
}

fn backend(e: UrError) -> RobotError {
    RobotError::Backend(Box::new(e))
}

/// Status and message of one shim call.
struct RawError {
    code: c_int,
    message: String,
}

/// Calls a shim function with an error buffer; `Err` carries its status and message.
fn raw_call(f: impl FnOnce(*mut c_char, usize) -> c_int) -> Result<(), RawError> {
    let mut err = [0 as c_char; ERR_LEN];
    let code = f(err.as_mut_ptr(), ERR_LEN);
    if code == ffi::URRTDE_OK {
        return Ok(());
    }
    // SAFETY: the shim always NUL-terminates within ERR_LEN (or leaves the zeroed buffer), and
    // the buffer lives until after this read.
    let message = unsafe { std::ffi::CStr::from_ptr(err.as_ptr()) }
        .to_string_lossy()
        .into_owned();
    Err(RawError { code, message })
}

/// A shim getter that writes six doubles (a pose vector or joint values).
type SixGetter =
    unsafe extern "C" fn(*mut ffi::UrrtdeHandle, *mut f64, *mut c_char, usize) -> c_int;

/// The ur_rtde handle, owned by the worker thread.
struct Handle(NonNull<ffi::UrrtdeHandle>);

// SAFETY: the handle is only ever used by one thread at a time: it is created on the worker
// thread and moved nowhere else; `Send` is needed only to move the struct into that thread's
// closure environment. ur_rtde's interfaces are not thread-safe, and this serialisation is
// exactly what they require.
unsafe impl Send for Handle {}

impl Handle {
    fn ptr(&mut self) -> *mut ffi::UrrtdeHandle {
        self.0.as_ptr()
    }
}

impl Drop for Handle {
    fn drop(&mut self) {
        let ptr = self.ptr();
        // SAFETY: `ptr` came from a successful urrtde_connect and is freed exactly once, here;
        // the shim catches every exception from ur_rtde's disconnect.
        let _ = raw_call(|err, len| unsafe { ffi::urrtde_disconnect(ptr, err, len) });
    }
}

type Job = Box<dyn FnOnce(&mut Handle) + Send>;

fn call_error(call: &'static str, e: RawError) -> RobotError {
    if e.code == ffi::URRTDE_REFUSED {
        backend(UrError::Refused { call })
    } else {
        backend(UrError::Call {
            call,
            message: e.message,
        })
    }
}

fn to_ur_vector(pose: &Pose) -> [f64; 6] {
    let t = pose.translation.vector;
    let r = rotvec(&pose.rotation);
    [t.x, t.y, t.z, r.x, r.y, r.z]
}

fn from_ur_vector(v: &[f64; 6]) -> Pose {
    pose_from_rotvec(
        Vector3::new(v[0], v[1], v[2]),
        Vector3::new(v[3], v[4], v[5]),
    )
}

/// A connected Universal Robots arm. Dropping it disconnects (on the worker thread, without
/// blocking the caller).
pub struct UrRobot {
    config: UrRobotConfig,
    jobs: mpsc::Sender<Job>,
    flange_from_tcp: Pose,
    /// Set once a call timed out or the connection was lost: the handle is not used again.
    broken: Option<String>,
    last_timestamp: f64,
    last_timestamp_change: Instant,
    /// Set by someone else (Ctrl-C) to stop a move in progress.
    interrupt: Option<Arc<AtomicBool>>,
}

impl std::fmt::Debug for UrRobot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UrRobot")
            .field("host", &self.config.host)
            .field("flange_from_tcp", &self.flange_from_tcp)
            .field("broken", &self.broken)
            .finish()
    }
}

#[derive(Debug, Clone, Copy)]
enum MoveKind {
    Linear,
    Joint,
}

impl MoveKind {
    /// The ur_rtde call that runs this move, for errors.
    fn call(self) -> &'static str {
        match self {
            MoveKind::Linear => "moveL",
            MoveKind::Joint => "moveJ",
        }
    }
}

impl UrRobot {
    /// Calls `get`, the shim's getter for ur_rtde's `name`, which writes six doubles.
    fn read_six(&mut self, name: &'static str, get: SixGetter) -> Result<[f64; 6], RobotError> {
        self.call(name, move |h| {
            let mut out = [0.0; 6];
            let ptr = h.ptr();
            // SAFETY: `ptr` is the live handle owned by this worker; `out` has room for the six
            // doubles every getter of this type writes.
            raw_call(|err, len| unsafe { get(ptr, out.as_mut_ptr(), err, len) })
                .map(|()| out)
                .map_err(|e| call_error(name, e))
        })
    }

    /// Connects to the controller at `config.host` within `config.connect_timeout`, uploads
    /// ur_rtde's control script, and reads the TCP offset (unless the config gives it).
    pub fn connect(config: UrRobotConfig) -> Result<UrRobot, RobotError> {
        let started = Instant::now();
        let connect_error = |reason: String| RobotError::Connect {
            address: config.host.clone(),
            timeout: config.connect_timeout,
            reason,
        };
        let host = CString::new(config.host.clone())
            .map_err(|_| backend(UrError::BadHost(config.host.clone())))?;
        let frequency = config.frequency_hz.unwrap_or(-1.0);
        let (ready_tx, ready_rx) = mpsc::sync_channel::<Result<(), String>>(1);
        let (jobs_tx, jobs_rx) = mpsc::channel::<Job>();
        std::thread::Builder::new()
            .name(format!("ur_rtde {}", config.host))
            .spawn(move || {
                let mut raw: *mut ffi::UrrtdeHandle = std::ptr::null_mut();
                let result = raw_call(|err, len| {
                    // SAFETY: `host` is a valid NUL-terminated string alive for the call; `raw`
                    // is a valid out-pointer; the shim catches every C++ exception.
                    unsafe {
                        ffi::urrtde_connect(host.as_ptr(), frequency, 0x01, &mut raw, err, len)
                    }
                });
                let mut handle = match (result, NonNull::new(raw)) {
                    (Ok(()), Some(ptr)) => Handle(ptr),
                    (Err(e), _) => {
                        let _ = ready_tx.send(Err(e.message));
                        return;
                    }
                    (Ok(()), None) => {
                        let _ = ready_tx.send(Err("ur_rtde returned no handle".into()));
                        return;
                    }
                };
                // If the caller gave up waiting, `handle` is dropped here, which disconnects.
                if ready_tx.send(Ok(())).is_err() {
                    return;
                }
                while let Ok(job) = jobs_rx.recv() {
                    job(&mut handle);
                }
            })
            .map_err(|e| connect_error(format!("cannot start the driver thread: {e}")))?;
        match ready_rx.recv_timeout(config.connect_timeout) {
            Ok(Ok(())) => {}
            Ok(Err(reason)) => return Err(connect_error(reason)),
            Err(RecvTimeoutError::Timeout) => {
                return Err(connect_error(format!(
                    "no complete RTDE session after {:.1} s (is a UR controller at this address?)",
                    started.elapsed().as_secs_f64()
                )))
            }
            Err(RecvTimeoutError::Disconnected) => {
                return Err(connect_error("the driver thread ended".into()))
            }
        }
        let mut robot = UrRobot {
            flange_from_tcp: config.flange_from_tcp.unwrap_or_else(Pose::identity),
            config,
            jobs: jobs_tx,
            broken: None,
            last_timestamp: f64::NAN,
            last_timestamp_change: Instant::now(),
            interrupt: None,
        };
        if robot.config.flange_from_tcp.is_none() {
            let v = robot.read_six("getTCPOffset", ffi::urrtde_get_tcp_offset)?;
            if !v.iter().all(|x| x.is_finite()) {
                return Err(backend(UrError::Call {
                    call: "getTCPOffset",
                    message: format!("non-finite TCP offset {v:?}"),
                }));
            }
            robot.flange_from_tcp = from_ur_vector(&v);
        }
        Ok(robot)
    }

    /// The TCP offset `T_flange_tcp` in use.
    pub fn flange_from_tcp(&self) -> Pose {
        self.flange_from_tcp
    }

    /// Runs `f` on the worker thread and waits up to `call_timeout`.
    fn call<T: Send + 'static>(
        &mut self,
        what: &'static str,
        f: impl FnOnce(&mut Handle) -> Result<T, RobotError> + Send + 'static,
    ) -> Result<T, RobotError> {
        if let Some(reason) = &self.broken {
            return Err(RobotError::ConnectionLost(reason.clone()));
        }
        let (tx, rx) = mpsc::sync_channel(1);
        let job: Job = Box::new(move |h| {
            let _ = tx.send(f(h));
        });
        if self.jobs.send(job).is_err() {
            return Err(self.mark_broken("the ur_rtde driver thread has ended".into()));
        }
        match rx.recv_timeout(self.config.call_timeout) {
            Ok(result) => result,
            Err(RecvTimeoutError::Timeout) => Err(self.mark_broken(format!(
                "ur_rtde {what} did not return within {:?}",
                self.config.call_timeout
            ))),
            Err(RecvTimeoutError::Disconnected) => {
                Err(self.mark_broken(format!("the ur_rtde driver thread died during {what}")))
            }
        }
    }

    fn mark_broken(&mut self, reason: String) -> RobotError {
        self.broken = Some(reason.clone());
        RobotError::ConnectionLost(reason)
    }

    /// One state snapshot; fails on a closed connection or when no new data came for
    /// `stale_after`.
    fn state(&mut self) -> Result<ffi::UrrtdeState, RobotError> {
        let s = self.call("getState", |h| {
            let mut out = ffi::UrrtdeState::default();
            let ptr = h.ptr();
            // SAFETY: `ptr` is the live handle owned by this worker; `out` is a valid
            // `urrtde_state` (same layout, repr(C)).
            raw_call(|err, len| unsafe { ffi::urrtde_get_state(ptr, &mut out, err, len) })
                .map(|()| out)
                .map_err(|e| call_error("getState", e))
        })?;
        if s.control_connected == 0 || s.receive_connected == 0 {
            return Err(self.mark_broken(format!(
                "the controller at {} closed the RTDE connection",
                self.config.host
            )));
        }
        let now = Instant::now();
        if s.receive_timestamp != self.last_timestamp {
            self.last_timestamp = s.receive_timestamp;
            self.last_timestamp_change = now;
        } else if now.duration_since(self.last_timestamp_change) > self.config.stale_after {
            return Err(self.mark_broken(format!(
                "no state from the controller at {} for {:.1} s",
                self.config.host,
                now.duration_since(self.last_timestamp_change).as_secs_f64()
            )));
        }
        Ok(s)
    }

    /// Waits until the controller time in the receive data reaches `after_s` (or any new data
    /// when `None`), so what is read next is current.
    fn wait_fresh(&mut self, after_s: Option<f64>) -> Result<ffi::UrrtdeState, RobotError> {
        let first = self.state()?;
        let target = after_s.unwrap_or(first.receive_timestamp + 1e-9);
        let mut s = first;
        while s.receive_timestamp < target {
            std::thread::sleep(Duration::from_millis(1));
            s = self.state()?;
        }
        Ok(s)
    }

    fn safety_error(bits: u32) -> Option<RobotError> {
        if bits & SAFETY_EMERGENCY_STOP != 0 {
            Some(RobotError::EmergencyStop)
        } else if bits & SAFETY_PROTECTIVE_STOP != 0 {
            Some(RobotError::ProtectiveStop)
        } else {
            None
        }
    }

    /// Makes sure the control script runs (it stops after a protective stop is cleared, or when
    /// someone pressed stop on the pendant), re-uploading it if needed.
    fn ensure_program(&mut self) -> Result<(ffi::UrrtdeState, bool), RobotError> {
        let s = self.state()?;
        if let Some(e) = Self::safety_error(s.safety_status_bits) {
            return Err(e);
        }
        if s.runtime_state != RUNTIME_PLAYING {
            self.call("reuploadScript", |h| {
                let ptr = h.ptr();
                // SAFETY: `ptr` is the live handle owned by this worker.
                raw_call(|err, len| unsafe { ffi::urrtde_reupload_script(ptr, err, len) })
                    .map_err(|e| call_error("reuploadScript", e))
            })?;
            // The upload returns before the program runs; commands sent earlier are refused.
            let deadline = Instant::now() + self.config.call_timeout;
            loop {
                let s = self.state()?;
                if let Some(e) = Self::safety_error(s.safety_status_bits) {
                    return Err(e);
                }
                if s.runtime_state == RUNTIME_PLAYING {
                    return Ok((s, true));
                }
                if Instant::now() > deadline {
                    return Err(backend(UrError::ProgramStopped {
                        call: "reuploadScript",
                    }));
                }
                std::thread::sleep(POLL_PERIOD);
            }
        }
        Ok((s, false))
    }

    fn check_workspace(&self, base_from_flange: &Pose) -> Result<(), RobotError> {
        match &self.config.workspace {
            Some(b) if !b.contains(base_from_flange) => {
                let p = base_from_flange.translation.vector;
                Err(RobotError::OutsideWorkspace {
                    x: p.x,
                    y: p.y,
                    z: p.z,
                })
            }
            _ => Ok(()),
        }
    }

    /// Sends one asynchronous move; the inner error is ur_rtde's refusal.
    fn send_move(
        &mut self,
        kind: MoveKind,
        target: [f64; 6],
        speed: f64,
        acceleration: f64,
    ) -> Result<Result<(), RawError>, RobotError> {
        let call = kind.call();
        self.call(call, move |h| {
            let ptr = h.ptr();
            let result = raw_call(|err, len| match kind {
                // SAFETY: `ptr` is the live handle owned by this worker; `target` holds the 6
                // values the shim reads.
                MoveKind::Linear => unsafe {
                    ffi::urrtde_move_l(ptr, target.as_ptr(), speed, acceleration, 1, err, len)
                },
                // SAFETY: as above.
                MoveKind::Joint => unsafe {
                    ffi::urrtde_move_j(ptr, target.as_ptr(), speed, acceleration, 1, err, len)
                },
            });
            Ok(result)
        })
    }

    fn interrupted(&self) -> bool {
        self.interrupt
            .as_ref()
            .is_some_and(|flag| flag.load(Ordering::SeqCst))
    }

    /// Sends one asynchronous move and watches it to the end (or to the interrupt flag).
    fn run_move(
        &mut self,
        kind: MoveKind,
        target: [f64; 6],
        speed: f64,
        acceleration: f64,
    ) -> Result<(), RobotError> {
        let call = kind.call();
        if self.interrupted() {
            return Err(RobotError::Interrupted);
        }
        let (before, restarted) = self.ensure_program()?;
        let op_before = async_op_id(before.async_status);
        let mut sent = self.send_move(kind, target, speed, acceleration)?;
        if sent.is_err() && restarted {
            // The first command after the control script was (re)started can be refused while
            // the script settles. If the move did not start and no stop is active, send it again
            // once.
            std::thread::sleep(RESTART_SETTLE);
            let after = self.last_timestamp + FRESH_AFTER_MOVE_S;
            let s = self.wait_fresh(Some(after))?;
            let started =
                async_op_id(s.async_status) != op_before || s.async_status & ASYNC_RUNNING != 0;
            if started {
                sent = Ok(());
            } else if Self::safety_error(s.safety_status_bits).is_none() {
                sent = self.send_move(kind, target, speed, acceleration)?;
            }
        }
        if let Err(e) = sent {
            // ur_rtde returns false when a stop is active: report the stop, not "refused". The
            // control connection may have seen it before the receive one: read newer data.
            let after = self.last_timestamp + FRESH_AFTER_MOVE_S;
            let s = self.wait_fresh(Some(after))?;
            return Err(Self::safety_error(s.safety_status_bits).unwrap_or(call_error(call, e)));
        }
        let deadline = Instant::now() + self.config.move_timeout;
        let finished_at = loop {
            let s = self.state()?;
            if let Some(e) = Self::safety_error(s.safety_status_bits) {
                return Err(e);
            }
            if s.runtime_state != RUNTIME_PLAYING {
                return Err(backend(UrError::ProgramStopped { call }));
            }
            let op = async_op_id(s.async_status);
            if op != op_before && s.async_status & ASYNC_RUNNING == 0 {
                break s.receive_timestamp;
            }
            if self.interrupted() {
                self.stop()?;
                return Err(RobotError::Interrupted);
            }
            if Instant::now() > deadline {
                let _ = self.stop();
                return Err(RobotError::MoveTimeout(self.config.move_timeout));
            }
            std::thread::sleep(POLL_PERIOD);
        };
        self.wait_fresh(Some(finished_at + FRESH_AFTER_MOVE_S))?;
        Ok(())
    }
}

impl Robot for UrRobot {
    fn base_from_flange(&mut self) -> Result<Pose, RobotError> {
        self.wait_fresh(None)?;
        let v = self.read_six("getActualTCPPose", ffi::urrtde_get_actual_tcp_pose)?;
        Ok(from_ur_vector(&v) * self.flange_from_tcp.inverse())
    }

    fn joint_positions(&mut self) -> Result<Joints, RobotError> {
        self.wait_fresh(None)?;
        self.read_six("getActualQ", ffi::urrtde_get_actual_q)
            .map(Joints::from)
    }

    fn joint_speeds(&mut self) -> Result<Option<Joints>, RobotError> {
        self.wait_fresh(None)?;
        self.read_six("getActualQd", ffi::urrtde_get_actual_qd)
            .map(|qd| Some(Joints::from(qd)))
    }

    fn move_linear(
        &mut self,
        base_from_flange: &Pose,
        limits: &MotionLimits,
    ) -> Result<(), RobotError> {
        limits.check()?;
        let target = to_ur_vector(&(base_from_flange * self.flange_from_tcp));
        if !target.iter().all(|v| v.is_finite()) {
            return Err(backend(UrError::NonFinite { what: "moveL" }));
        }
        self.check_workspace(base_from_flange)?;
        self.run_move(
            MoveKind::Linear,
            target,
            limits.linear_speed,
            limits.linear_acceleration,
        )
    }

    fn move_joints(&mut self, joints: &Joints, limits: &MotionLimits) -> Result<(), RobotError> {
        limits.check()?;
        let target = six_joints(joints)?;
        if !joints.iter().all(|v| v.is_finite()) {
            return Err(backend(UrError::NonFinite { what: "moveJ" }));
        }
        if let Some(model) = &self.config.model {
            let flange = model.forward(joints);
            self.check_workspace(&flange)?;
        }
        self.run_move(
            MoveKind::Joint,
            target,
            limits.joint_speed,
            limits.joint_acceleration,
        )
    }

    fn set_interrupt(&mut self, flag: Arc<AtomicBool>) {
        self.interrupt = Some(flag);
    }

    fn stop(&mut self) -> Result<(), RobotError> {
        let s = self.state()?;
        if s.runtime_state != RUNTIME_PLAYING {
            return Ok(()); // no program, no motion
        }
        self.call("stopL", |h| {
            let ptr = h.ptr();
            // SAFETY: `ptr` is the live handle owned by this worker.
            raw_call(|err, len| unsafe { ffi::urrtde_stop_l(ptr, STOP_DECELERATION, err, len) })
                .map_err(|e| call_error("stopL", e))
        })
    }

    fn set_freedrive(&mut self, on: bool) -> Result<(), RobotError> {
        // Teach mode is a command of the control script: it has to run.
        self.ensure_program()?;
        let call = if on { "teachMode" } else { "endTeachMode" };
        self.call(call, move |h| {
            let ptr = h.ptr();
            // SAFETY: `ptr` is the live handle owned by this worker.
            raw_call(|err, len| unsafe { ffi::urrtde_teach_mode(ptr, i32::from(on), err, len) })
                .map_err(|e| call_error(call, e))
        })
    }

    fn status(&mut self) -> Result<RobotStatus, RobotError> {
        let s = self.wait_fresh(None)?;
        Ok(match Self::safety_error(s.safety_status_bits) {
            Some(RobotError::EmergencyStop) => RobotStatus::EmergencyStop,
            Some(_) => RobotStatus::ProtectiveStop,
            None if s.robot_mode != ROBOT_MODE_RUNNING => RobotStatus::NotReady,
            None => RobotStatus::Ready,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn ur_vector_round_trips_near_180_degrees() {
        for angle in [0.0, 0.5, PI - 1e-7, PI] {
            let axis = Vector3::new(0.2, -0.7, 0.4).normalize();
            let pose = pose_from_rotvec(Vector3::new(0.1, -0.2, 0.3), axis * angle);
            let back = from_ur_vector(&to_ur_vector(&pose));
            assert!(back.rotation.angle_to(&pose.rotation) < 1e-12, "{angle}");
            assert!(rotvec(&back.rotation).norm() <= PI + 1e-12);
        }
    }
}
