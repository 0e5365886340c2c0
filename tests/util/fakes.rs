//! Strict scripted fakes of the hardware traits, for fast and exact unit tests of the session
//! driver (issue #12, item 6): a [`ScriptedRobot`] and a [`ScriptedCamera`] each take the list of
//! calls they expect, in order, with the canned reply of each. Any other call, an argument that
//! differs, or a call after the script ran out panics with a message naming the call number,
//! what came and what was expected; dropping a fake with expected calls left panics too (unless
//! the test is already panicking). No sleeps, no threads, no clocks: a frame's capture time is
//! the instant of the `grab` call.
//!
//! Include with `#[path = "util/fakes.rs"] mod fakes;` next to `mod util;`.

#![allow(dead_code)]

use std::collections::VecDeque;
use std::fmt;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use handeye_camera::{Camera, CameraError, Frame};
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_robot::{Joints, MotionLimits, Robot, RobotError, RobotStatus};
use image::GrayImage;

/// Joint values and pose coordinates must match to this (radians, metres): the driver passes
/// plan values through unchanged, so only exact copies pass.
const EXACT: f64 = 1e-12;

/// One expected robot call and its reply.
pub enum Expect {
    /// `set_interrupt(flag)`; the fake keeps the flag ([`ScriptedRobot::interrupt_flag`]).
    SetInterrupt,
    /// `base_from_flange()`.
    Pose(Result<Pose, RobotError>),
    /// `joint_positions()`.
    Joints(Result<Joints, RobotError>),
    /// `move_joints(joints, limits)` with exactly these joints.
    MoveJoints(Joints, Result<(), RobotError>),
    /// `move_linear(pose, limits)` with exactly this pose.
    MoveLinear(Pose, Result<(), RobotError>),
    /// `stop()`.
    Stop(Result<(), RobotError>),
    /// `status()`.
    Status(Result<RobotStatus, RobotError>),
}

impl Expect {
    /// A joint move to `joints` that arrives.
    pub fn move_to(joints: Joints) -> Expect {
        Expect::MoveJoints(joints, Ok(()))
    }

    /// A flange pose reading that answers `pose`.
    pub fn pose(pose: Pose) -> Expect {
        Expect::Pose(Ok(pose))
    }

    /// A `stop()` that succeeds.
    pub fn stop() -> Expect {
        Expect::Stop(Ok(()))
    }

    fn name(&self) -> String {
        match self {
            Expect::SetInterrupt => "set_interrupt(..)".into(),
            Expect::Pose(_) => "base_from_flange()".into(),
            Expect::Joints(_) => "joint_positions()".into(),
            Expect::MoveJoints(q, _) => format!("move_joints({q:?}, ..)"),
            Expect::MoveLinear(p, _) => format!("move_linear({p}, ..)"),
            Expect::Stop(_) => "stop()".into(),
            Expect::Status(_) => "status()".into(),
        }
    }
}

impl fmt::Debug for Expect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}

/// A robot that answers exactly the calls of its script, in order.
pub struct ScriptedRobot {
    script: VecDeque<Expect>,
    /// Limits every move must carry, when set.
    limits: Option<MotionLimits>,
    calls: usize,
    interrupt: Option<Arc<AtomicBool>>,
}

impl ScriptedRobot {
    /// A robot expecting `script`, in order.
    pub fn new(script: Vec<Expect>) -> Self {
        ScriptedRobot {
            script: script.into(),
            limits: None,
            calls: 0,
            interrupt: None,
        }
    }

    /// Every move must also carry exactly these limits.
    pub fn with_limits(mut self, limits: MotionLimits) -> Self {
        self.limits = Some(limits);
        self
    }

    /// The flag given to `set_interrupt`, once it was called.
    pub fn interrupt_flag(&self) -> Option<Arc<AtomicBool>> {
        self.interrupt.clone()
    }

    /// Calls still expected.
    pub fn remaining(&self) -> usize {
        self.script.len()
    }

    /// The next expected call, or a panic naming `call` and what was expected instead.
    fn next(&mut self, call: &str) -> Expect {
        self.calls += 1;
        match self.script.pop_front() {
            Some(e) => e,
            None => panic!(
                "ScriptedRobot: unexpected call #{} {call}: the script has no more calls",
                self.calls
            ),
        }
    }

    fn mismatch(&self, call: &str, expected: &Expect) -> ! {
        panic!(
            "ScriptedRobot: call #{} was {call}, expected {expected:?} (then {} more)",
            self.calls,
            self.script.len()
        )
    }

    fn check_limits(&self, call: &str, limits: &MotionLimits) {
        if let Some(want) = &self.limits {
            assert_eq!(
                limits, want,
                "ScriptedRobot: call #{} {call} carries other motion limits",
                self.calls
            );
        }
    }
}

fn same_joints(a: &Joints, b: &Joints) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() <= EXACT)
}

fn same_pose(a: &Pose, b: &Pose) -> bool {
    (a.translation.vector - b.translation.vector).norm() <= EXACT
        && a.rotation.angle_to(&b.rotation) <= EXACT
}

impl Robot for ScriptedRobot {
    fn base_from_flange(&mut self) -> Result<Pose, RobotError> {
        let call = "base_from_flange()";
        match self.next(call) {
            Expect::Pose(reply) => reply,
            other => self.mismatch(call, &other),
        }
    }

    fn joint_positions(&mut self) -> Result<Joints, RobotError> {
        let call = "joint_positions()";
        match self.next(call) {
            Expect::Joints(reply) => reply,
            other => self.mismatch(call, &other),
        }
    }

    fn move_linear(
        &mut self,
        base_from_flange: &Pose,
        limits: &MotionLimits,
    ) -> Result<(), RobotError> {
        let call = format!("move_linear({base_from_flange}, ..)");
        match self.next(&call) {
            Expect::MoveLinear(want, reply) if same_pose(&want, base_from_flange) => {
                self.check_limits(&call, limits);
                reply
            }
            other => self.mismatch(&call, &other),
        }
    }

    fn move_joints(&mut self, joints: &Joints, limits: &MotionLimits) -> Result<(), RobotError> {
        let call = format!("move_joints({joints:?}, ..)");
        match self.next(&call) {
            Expect::MoveJoints(want, reply) if same_joints(&want, joints) => {
                self.check_limits(&call, limits);
                reply
            }
            other => self.mismatch(&call, &other),
        }
    }

    fn stop(&mut self) -> Result<(), RobotError> {
        let call = "stop()";
        match self.next(call) {
            Expect::Stop(reply) => reply,
            other => self.mismatch(call, &other),
        }
    }

    fn set_interrupt(&mut self, flag: Arc<AtomicBool>) {
        let call = "set_interrupt(..)";
        match self.next(call) {
            Expect::SetInterrupt => self.interrupt = Some(flag),
            other => self.mismatch(call, &other),
        }
    }

    fn status(&mut self) -> Result<RobotStatus, RobotError> {
        let call = "status()";
        match self.next(call) {
            Expect::Status(reply) => reply,
            other => self.mismatch(call, &other),
        }
    }
}

impl Drop for ScriptedRobot {
    fn drop(&mut self) {
        if !std::thread::panicking() && !self.script.is_empty() {
            panic!(
                "ScriptedRobot dropped after {} calls with {} expected calls not made: {:?}",
                self.calls,
                self.script.len(),
                self.script
            );
        }
    }
}

/// One expected `grab` and its reply.
pub enum Grab {
    /// Answer this image (captured at the instant of the call).
    Frame(GrayImage),
    /// Fail with this error.
    Fail(CameraError),
}

impl fmt::Debug for Grab {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Grab::Frame(image) => write!(f, "grab -> {}x{} frame", image.width(), image.height()),
            Grab::Fail(e) => write!(f, "grab -> error {e}"),
        }
    }
}

/// A camera that answers exactly the grabs of its script, in order. `model()` is an accessor
/// without effects and may be called any number of times.
pub struct ScriptedCamera {
    model: CameraModel,
    script: VecDeque<Grab>,
    grabs: usize,
}

impl ScriptedCamera {
    /// A camera with intrinsics `model` expecting the grabs of `script`, in order.
    pub fn new(model: CameraModel, script: Vec<Grab>) -> Self {
        ScriptedCamera {
            model,
            script: script.into(),
            grabs: 0,
        }
    }

    /// Grabs still expected.
    pub fn remaining(&self) -> usize {
        self.script.len()
    }
}

impl Camera for ScriptedCamera {
    fn grab(&mut self, not_before: Instant) -> Result<Frame, CameraError> {
        self.grabs += 1;
        let captured_at = Instant::now();
        assert!(
            not_before <= captured_at,
            "ScriptedCamera: grab #{} asks for a frame from the future",
            self.grabs
        );
        match self.script.pop_front() {
            Some(Grab::Frame(image)) => {
                assert_eq!(
                    image.dimensions(),
                    (self.model.width, self.model.height),
                    "ScriptedCamera: grab #{}: the scripted frame does not have the model's size",
                    self.grabs
                );
                Ok(Frame {
                    image,
                    captured_at,
                    png: None,
                })
            }
            Some(Grab::Fail(e)) => Err(e),
            None => panic!(
                "ScriptedCamera: unexpected grab #{}: the script has no more grabs",
                self.grabs
            ),
        }
    }

    fn model(&self) -> &CameraModel {
        &self.model
    }
}

impl Drop for ScriptedCamera {
    fn drop(&mut self) {
        if !std::thread::panicking() && !self.script.is_empty() {
            panic!(
                "ScriptedCamera dropped after {} grabs with {} expected grabs not made: {:?}",
                self.grabs,
                self.script.len(),
                self.script
            );
        }
    }
}
