//! `robot.backend: ros2`: an arm under a ROS 2 driver (the UR driver, any ros2_control arm).
//! The flange pose is `T_base_flange` from `/tf` + `/tf_static` between the configured frames,
//! the joints come from `/joint_states`, and a move is one `control_msgs/FollowJointTrajectory`
//! goal: the UR `moveJ` trapezoid at the configured joint speed and acceleration, sampled into
//! waypoints with their speeds, so the controller never exceeds the limits. The interrupt flag
//! (STOP, Ctrl-C) cancels the goal; a controller's error code comes back in words.
//!
//! Blocking: every call waits for its messages with the configured timeout; after any error no
//! goal of ours is left running (it was cancelled, or the controller ended it).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

use futures::StreamExt;
use ros2_client::action::{ActionClient, ActionClientQosPolicies};
use ros2_client::action_msgs::GoalStatusEnum;
use ros2_client::{ActionTypeName, ServiceMapping};

use handeye_core::geometry::Pose;
use handeye_robot::kinematics::UrModel;
use handeye_robot::{trapezoid_at, Joints, MotionLimits, Robot, RobotError, RobotStatus};

use crate::freedrive::{Freedrive, FreedriveOptions};
use crate::link::{
    answer_to, poll_for, sensor_data_qos, serves, settle_after_match, static_reader_qos,
    tf_listener_qos, topic_name, Ros2Link, POLL, REQUEST_RESEND,
};
use crate::listen::{joint_sample, JointSample, Shared, AT_REST_JITTER_M, AT_REST_JITTER_RAD};
use crate::msg::{
    follow_joint_trajectory_error, Duration as RosDuration, FollowJointTrajectoryFeedback,
    FollowJointTrajectoryGoal, FollowJointTrajectoryResult, JointState, JointTrajectory,
    JointTrajectoryPoint, TfMessage,
};
use crate::Ros2Error;

impl ros2_client::Message for FollowJointTrajectoryGoal {}
impl ros2_client::Message for FollowJointTrajectoryResult {}
impl ros2_client::Message for FollowJointTrajectoryFeedback {}

type FjtClient = ActionClient<
    FollowJointTrajectoryGoal,
    FollowJointTrajectoryResult,
    FollowJointTrajectoryFeedback,
>;

/// How request/reply (actions) is framed: the middleware of the other nodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Framing {
    /// rmw_fastrtps (RPC over DDS, enhanced mapping).
    FastRtps,
    /// rmw_cyclonedds.
    Cyclone,
}

/// The arm's names and timeouts.
#[derive(Debug, Clone)]
pub struct ArmOptions {
    /// `T_base_flange`'s base frame.
    pub base_frame: String,
    /// Its flange frame.
    pub flange_frame: String,
    /// Joint names, base joint first: one per joint of the arm (six on a UR, seven on a Franka
    /// or a KUKA iiwa; at most [`handeye_robot::MAX_JOINTS`]).
    pub joint_names: Vec<String>,
    /// `/joint_states`.
    pub joint_states_topic: String,
    /// `/tf`.
    pub tf_topic: String,
    /// `/tf_static`.
    pub tf_static_topic: String,
    /// The FollowJointTrajectory action.
    pub action: String,
    /// Wait for a topic's message or the action server this long.
    pub timeout: Duration,
    /// Request/reply framing.
    pub framing: Framing,
    /// The arm's kinematics, when it is a UR model handeye knows: linear moves (IK to joints),
    /// and the check of each flange pose against the forward kinematics of its joints.
    pub kinematics: Option<UrModel>,
    /// The flange pose from the joints (`robot.flange_pose: joints`): the forward kinematics of
    /// the published model of `kinematics` at the joints on /joint_states, /tf not read for it.
    pub flange_from_joints: bool,
    /// Freedrive through the UR driver's controllers; `None`: the person switches it on the arm.
    pub freedrive: Option<FreedriveOptions>,
}

/// How to hand-guide an arm under a ROS 2 driver when handeye does not switch its freedrive.
pub const HAND_GUIDING: &str = "handeye does not switch freedrive on this arm (a UR under ur_robot_driver 2.5 or later: give robot.freedrive in the config): hand-guide the arm with its own means (a UR: hold the freedrive button on the back of the teach pendant, or Freedrive on the pendant's Move tab; another arm: its hand-guiding or teach mode), let go where the board is in view, then capture: the capture waits for /joint_states to show the arm still and takes a frame stamped after that";

/// A joint sample older than this is stale: the driver is gone or the graph split.
const STALE: Duration = Duration::from_secs(1);
/// How long a flange pose is watched for standing with the joints, and for how many /tf
/// messages at most (a driver at 50–500 Hz sends several within it).
const STANDING_WINDOW: Duration = Duration::from_millis(150);
const STANDING_MESSAGES: usize = 4;
/// Joints that move less than this (rad, 0.005°) between two samples stand.
const JOINTS_STAND_RAD: f64 = 0.005 * std::f64::consts::PI / 180.0;
/// Farthest a joint may be from a goal's end point once the controller says it succeeded, rad
/// (a trajectory controller's goal tolerance is far tighter; this is about a goal that did
/// not move the arm at all).
const ARRIVED_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;
/// How long `/joint_states` may take to show the arm at a succeeded goal's end point.
const ARRIVAL_WAIT: Duration = Duration::from_secs(2);
/// Farthest the flange pose on /tf may be from the forward kinematics of the arm's model (its
/// published parameters, or as an earlier session estimated them: `solver.arm_model`) at the
/// joints on /joint_states (m, rad): a UR driver publishes its arm's factory
/// calibration, a few millimetres and tenths of a degree from the nominal model; a chain that
/// is not the arm's (another tool0, a wrong base frame, a relay) is centimetres or degrees off.
const MODEL_AGREES_M: f64 = 0.02;
/// See [`MODEL_AGREES_M`]: 2°.
const MODEL_AGREES_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// How long a flange pose that contradicts the joints' kinematics listens for a second publisher
/// of its chain before the model or the frame names are blamed (DDS discovery can match the
/// driver's writer after a second one, and a loaded machine delays a 50 Hz writer beside a
/// 200 Hz one: seen in CI).
const LATE_PUBLISHER_WAIT: Duration = Duration::from_secs(2);

/// The ROS 2 arm.
pub struct Ros2Arm {
    options: ArmOptions,
    shared: Arc<Shared>,
    action: FjtClient,
    interrupt: Option<Arc<AtomicBool>>,
    freedrive: Option<Freedrive>,
    // Dropping it ends the reader task.
    _stop_reader: smol::channel::Sender<()>,
    link: Ros2Link,
}

fn backend(message: String) -> RobotError {
    RobotError::Backend(message.into())
}

fn setup_error(e: Ros2Error) -> RobotError {
    RobotError::Connect {
        address: "the ROS 2 graph".into(),
        timeout: Duration::ZERO,
        reason: e.to_string(),
    }
}

impl Ros2Arm {
    /// Subscribes to the joint states and TF, makes the action client, and waits (up to the
    /// timeout) for the first joint state and the flange pose: a missing topic or frame fails
    /// here, before anything moves.
    pub fn open(link: &Ros2Link, options: ArmOptions) -> Result<Ros2Arm, RobotError> {
        let joints_sub = link
            .subscribe::<JointState>(&options.joint_states_topic, sensor_data_qos())
            .map_err(setup_error)?;
        let tf_sub = link
            .subscribe::<TfMessage>(&options.tf_topic, tf_listener_qos())
            .map_err(setup_error)?;
        let static_sub = link
            .subscribe::<TfMessage>(&options.tf_static_topic, static_reader_qos())
            .map_err(setup_error)?;
        let action_name = topic_name(&options.action).map_err(setup_error)?;
        let qos = crate::link::reliable_qos();
        let action = link
            .with_node(|node| {
                node.create_action_client::<FollowJointTrajectoryGoal, FollowJointTrajectoryResult, FollowJointTrajectoryFeedback>(
                    match options.framing {
                        Framing::FastRtps => ServiceMapping::Enhanced,
                        Framing::Cyclone => ServiceMapping::Cyclone,
                    },
                    &action_name,
                    &ActionTypeName::new("control_msgs", "FollowJointTrajectory"),
                    ActionClientQosPolicies {
                        goal_service: qos.clone(),
                        result_service: qos.clone(),
                        cancel_service: qos.clone(),
                        feedback_subscription: qos.clone(),
                        status_subscription: qos,
                    },
                )
            })
            .map_err(|e| {
                setup_error(Ros2Error::Setup {
                    what: format!("the action client of {}", options.action),
                    reason: e.to_string(),
                })
            })?;
        // The controller's action server must be on the graph before anything moves.
        let found = link.wait_until_matched(options.timeout, |node| {
            serves(action.goal_client(), node)
                && serves(action.result_client(), node)
                && serves(action.cancel_client(), node)
        });
        if !found {
            return Err(RobotError::Connect {
                address: options.action.clone(),
                timeout: options.timeout,
                reason: format!(
                    "no FollowJointTrajectory action server answers there ({})",
                    silent_action(link, &options.action, options.framing)
                ),
            });
        }
        settle_after_match();
        one_action_server(link, &options.action)?;
        let shared = Arc::new(Shared::wanting(&[
            &options.base_frame,
            &options.flange_frame,
        ]));
        let (stop_tx, stop_rx) = smol::channel::bounded::<()>(1);
        let names = options.joint_names.clone();
        let task_shared = shared.clone();
        thread::Builder::new()
            .name("ros2-arm".into())
            .spawn(move || {
                smol::block_on(async move {
                    let joints = joints_sub.async_stream().map(Event::Joints);
                    let tf = tf_sub.async_stream().map(|m| Event::Tf(m, false));
                    let statics = static_sub.async_stream().map(|m| Event::Tf(m, true));
                    let events =
                        futures::stream::select(joints, futures::stream::select(tf, statics));
                    let apply = events.for_each(|event| {
                        apply(&task_shared, &names, event);
                        futures::future::ready(())
                    });
                    futures::future::select(Box::pin(apply), Box::pin(stop_rx.recv())).await;
                })
            })
            .map_err(|e| backend(format!("cannot start the ROS 2 arm reader: {e}")))?;
        let freedrive = match &options.freedrive {
            Some(f) => Some(Freedrive::open(link, f.clone(), options.framing)?),
            None => None,
        };
        let mut arm = Ros2Arm {
            options,
            shared,
            action,
            interrupt: None,
            freedrive,
            _stop_reader: stop_tx,
            link: link.clone(),
        };
        arm.fresh_joints(Instant::now() - STALE)?;
        arm.base_from_flange()?;
        Ok(arm)
    }

    /// The newest joint sample received after `after`, waiting up to the timeout.
    fn fresh_joints(&self, after: Instant) -> Result<JointSample, RobotError> {
        let deadline = Instant::now() + self.options.timeout;
        let (state, ok) = self
            .shared
            .wait_until(deadline, |s| s.joints.is_some_and(|j| j.received >= after));
        match state.joints {
            Some(j) if ok => Ok(j),
            _ => {
                let why = match (&state.joints_problem, state.joints) {
                    (Some(p), _) => format!(": its messages do not fit the configured joints: {p}"),
                    (None, Some(j)) => format!(
                        ": the last one came {:.1} s ago (is the driver still running?)",
                        j.received.elapsed().as_secs_f64()
                    ),
                    (None, None) => ": none heard at all (is the driver running, on this domain id, with this topic name?)".into(),
                };
                Err(RobotError::ConnectionLost(format!(
                    "no fresh message on {} within {:.1} s{why}",
                    self.options.joint_states_topic,
                    self.options.timeout.as_secs_f64()
                )))
            }
        }
    }

    /// The flange pose of the first /tf message heard after `asked`, waiting until `deadline`;
    /// a chain that no wait mends ([`TfTree::broken_chain`](crate::listen::TfTree::broken_chain):
    /// an edge whose publishers contradict each other, a loop) ends the wait at once (waiting
    /// on leaves a loaded machine time to miss one publisher for a moment and take the other's
    /// pose as the arm's).
    fn flange_after(&self, asked: Instant, deadline: Instant) -> Result<Pose, RobotError> {
        let (base, flange) = (&self.options.base_frame, &self.options.flange_frame);
        let (state, _) = self.shared.wait_until(deadline, |s| {
            s.tf_received.is_some_and(|t| t >= asked)
                && (s.tf.lookup(base, flange).is_ok()
                    || s.tf.broken_chain(base).is_some()
                    || s.tf.broken_chain(flange).is_some())
        });
        match state.tf.lookup(base, flange) {
            Ok(pose) if state.tf_received.is_some_and(|t| t >= asked) => Ok(pose),
            Ok(_) => Err(RobotError::ConnectionLost(format!(
                "no fresh message on {} within {:.1} s (is the driver still running?)",
                self.options.tf_topic,
                self.options.timeout.as_secs_f64()
            ))),
            Err(why) => Err(backend(format!(
                "T_{base}_{flange} from {} + {}: {why}",
                self.options.tf_topic, self.options.tf_static_topic
            ))),
        }
    }

    /// Checks that the flange pose /tf gives stands while /joint_states stand (issue #38: a
    /// robot pose stream that contradicts itself is named as such, not as a board scale): over
    /// the next few /tf messages (at most [`STANDING_WINDOW`]) it may not move by more than a
    /// driver's jitter while the joints move by less than [`JOINTS_STAND_RAD`]. A jumping flange
    /// (a relay replaying old transforms, a second chain published under the driver's frame
    /// names from one writer, a driver publishing a wrong chain) is refused with what moved.
    /// Whether the joints stood (the flange pose and the joints then describe one instant).
    fn check_standing_flange(&self, first: &Pose) -> Result<bool, RobotError> {
        let joints_first = self.shared.lock().joints;
        let window_end = Instant::now() + STANDING_WINDOW;
        let (mut moved_m, mut moved_rad, mut heard) = (0.0f64, 0.0f64, 0);
        let mut after = Instant::now();
        while heard < STANDING_MESSAGES && Instant::now() < window_end {
            let pose = match self.flange_after(after, window_end) {
                Ok(pose) => pose,
                // Nothing more within the window: what was heard is the check.
                Err(RobotError::ConnectionLost(_)) => break,
                Err(e) => return Err(e),
            };
            after = Instant::now();
            heard += 1;
            let step = first.inverse() * pose;
            moved_m = moved_m.max(step.translation.vector.norm());
            moved_rad = moved_rad.max(step.rotation.angle());
        }
        let joints_last = self.shared.lock().joints;
        let (Some(before), Some(now)) = (joints_first, joints_last) else {
            return Ok(false);
        };
        let joints_moved =
            farthest_joint(&before.positions, &now.positions).map_or(0.0, |(_, rad)| rad);
        let stood = now.received > before.received && joints_moved < JOINTS_STAND_RAD;
        if stood && (moved_m > AT_REST_JITTER_M || moved_rad > AT_REST_JITTER_RAD) {
            let (base, flange) = (&self.options.base_frame, &self.options.flange_frame);
            return Err(backend(format!(
                "the flange pose {base} → {flange} on {} moved {:.1} mm / {:.2}° over {} messages while {} stood still (the joints moved {:.4}°): the flange pose contradicts the joints — is a relay replaying old transforms, or another chain published under these frame names? Stop it; nothing was recorded at this pose",
                self.options.tf_topic,
                moved_m * 1e3,
                moved_rad.to_degrees(),
                heard + 1,
                self.options.joint_states_topic,
                joints_moved.to_degrees()
            )));
        }
        Ok(stood)
    }

    /// Checks the flange pose /tf gives against the forward kinematics of the arm's model at
    /// the joints /joint_states gives (issue #40; with a known model only): beyond
    /// [`MODEL_AGREES_M`] / [`MODEL_AGREES_RAD`] the two sources contradict each other and the
    /// pose is refused naming both, as [`Ros2Arm::check_standing_flange`] refuses a flange that
    /// moves while the joints stand. Called only when the joints stood (a hand-guided arm in
    /// motion would be compared across the few milliseconds between the two topics).
    fn check_flange_against_model(&self, flange: &Pose) -> Result<(), RobotError> {
        let Some(model) = &self.options.kinematics else {
            return Ok(());
        };
        let joints = self.fresh_joints(Instant::now() - STALE)?.positions;
        if joints.len() != 6 {
            return Ok(());
        }
        let from_joints = model.forward(&joints);
        let off = from_joints.inverse() * flange;
        let (off_m, off_rad) = (off.translation.vector.norm(), off.rotation.angle());
        if off_m <= MODEL_AGREES_M && off_rad <= MODEL_AGREES_RAD {
            return Ok(());
        }
        let (base, flange_frame) = (&self.options.base_frame, &self.options.flange_frame);
        let degrees: Vec<String> = joints
            .iter()
            .map(|q| format!("{:.2}", q.to_degrees()))
            .collect();
        let at = |p: &Pose| {
            let t = p.translation.vector * 1e3;
            format!("[{:.1}, {:.1}, {:.1}] mm", t.x, t.y, t.z)
        };
        Err(backend(format!(
            "the flange pose {base} → {flange_frame} on {} (at {}) is {:.1} mm / {:.2}° from the forward kinematics of the {} model at the joints on {} ([{}]°, at {}), beyond the {:.0} mm / {:.0}° an arm's calibration explains: the flange pose contradicts the joints' kinematics — are robot.base_frame and robot.flange_frame the model's base and flange (a UR driver's `base` and `tool0`, not `base_link`), robot.model this arm's, and no other chain published under these frame names? Nothing was recorded at this pose",
            self.options.tf_topic,
            at(flange),
            off_m * 1e3,
            off_rad.to_degrees(),
            model.name,
            self.options.joint_states_topic,
            degrees.join(", "),
            at(&from_joints),
            MODEL_AGREES_M * 1e3,
            MODEL_AGREES_RAD.to_degrees(),
        )))
    }

    /// Why a flange pose contradicts the joints' kinematics twice: a second publisher of an edge
    /// on its chain, when one was heard in the last seconds or is heard within
    /// [`LATE_PUBLISHER_WAIT`], explains it better than a wrong model or wrong frame names (the
    /// driver's publisher unheard a moment beside a faster one, or matched by DDS discovery
    /// after it, on a loaded machine: CI runs); else `contradiction`.
    fn second_publisher_or(&self, contradiction: RobotError) -> RobotError {
        let flange_frame = &self.options.flange_frame;
        let named = || {
            let second = self.shared.lock().tf.recent_disagreement(flange_frame)?;
            Some(backend(format!(
                "{second}; nothing was recorded at this pose"
            )))
        };
        let deadline = Instant::now() + LATE_PUBLISHER_WAIT;
        // Every /tf message (of either publisher) is a new look, until the deadline; a lookup
        // that fails outright is a last look.
        while Instant::now() < deadline && self.flange_after(Instant::now(), deadline).is_ok() {
            if let Some(error) = named() {
                return error;
            }
        }
        named().unwrap_or(contradiction)
    }

    /// `robot.flange_pose: joints`: the flange pose the arm's published model computes at the
    /// first joint state heard after this call (what its controller would report; the solve
    /// corrects it by the arm's model as it does any reported pose).
    fn flange_from_joints(&self) -> Result<Pose, RobotError> {
        let model = self.options.kinematics.as_ref().ok_or_else(|| {
            backend(
                "the flange pose from the joints needs the arm's kinematics (robot.model)".into(),
            )
        })?;
        // Six joints: the config holds a UR model's joint names to six.
        let joints = self.fresh_joints(Instant::now())?.positions;
        handeye_robot::six_joints(&joints)?;
        Ok(model.published().forward(&joints))
    }

    fn interrupted(&self) -> bool {
        self.interrupt
            .as_ref()
            .is_some_and(|f| f.load(Ordering::SeqCst))
    }

    /// The goal for a synchronised joint move `from` → `to` at `limits`: the trapezoid of the
    /// leading joint sampled every 50 ms (at least 4 points), positions and speeds.
    pub fn trajectory(
        names: &[String],
        from: &Joints,
        to: &Joints,
        limits: &MotionLimits,
    ) -> FollowJointTrajectoryGoal {
        let travel = handeye_robot::leading_travel(from, to);
        let total = limits.joint_move_time(from, to);
        let steps = ((total / 0.05).ceil() as usize).clamp(4, 400);
        let points = (1..=steps)
            .map(|k| {
                let t = total * k as f64 / steps as f64;
                let (fraction, speed) =
                    trapezoid_at(travel, limits.joint_speed, limits.joint_acceleration, t);
                let last = k == steps;
                JointTrajectoryPoint {
                    positions: (0..to.len())
                        .map(|i| from[i] + fraction * (to[i] - from[i]))
                        .collect(),
                    velocities: (0..to.len())
                        .map(|i| {
                            if last || travel == 0.0 {
                                0.0
                            } else {
                                (to[i] - from[i]) / travel * speed
                            }
                        })
                        .collect(),
                    time_from_start: RosDuration::from_secs_f64(t),
                    ..JointTrajectoryPoint::default()
                }
            })
            .collect();
        FollowJointTrajectoryGoal {
            trajectory: JointTrajectory {
                joint_names: names.to_vec(),
                points,
                ..JointTrajectory::default()
            },
            ..FollowJointTrajectoryGoal::default()
        }
    }

    /// A goal the controller reported SUCCEEDED is only done when `/joint_states` shows the arm
    /// at its end point: a second action server of the same name, or a controller that answers
    /// without moving, would otherwise pass for a move (and every pose would "see no board").
    fn check_arrival(&self, goal: &Joints) -> Result<(), RobotError> {
        let off =
            |s: &crate::listen::ArmState| s.joints.and_then(|j| farthest_joint(&j.positions, goal));
        let (state, arrived) = self.shared.wait_until(Instant::now() + ARRIVAL_WAIT, |s| {
            off(s).is_some_and(|(_, rad)| rad <= ARRIVED_RAD)
        });
        if arrived {
            return Ok(());
        }
        let worst = match off(&state) {
            Some((joint, rad)) => format!(
                "{} is {:.1}° from it",
                self.options.joint_names[joint],
                rad.to_degrees()
            ),
            None => format!("no {} message was heard", self.options.joint_states_topic),
        };
        Err(backend(format!(
            "the controller behind {} answered SUCCEEDED but {} did not reach the goal's end point within {:.0} s: {worst} (a second action server of that name on the domain, or a controller that does not drive this arm?)",
            self.options.action,
            self.options.joint_states_topic,
            ARRIVAL_WAIT.as_secs_f64()
        )))
    }

    fn run_goal(&mut self, goal: FollowJointTrajectoryGoal, total: f64) -> Result<(), RobotError> {
        let action = self.options.action.clone();
        // A second server may have joined since the arm was opened.
        one_action_server(&self.link, &action)?;
        let timeout = self.options.timeout;
        // A goal unanswered for REQUEST_RESEND is sent again, as a new goal of the same
        // trajectory: Cyclone DDS drops for good a request written before the server's reader
        // took in our writer (a CI run: the first goal of a run unheard for 30 s). A new goal
        // id, not the same one again: a server that took the first and lost only its answer
        // would refuse (rclcpp: fail on) a repeated id, while a new goal of the same trajectory
        // replaces the first (a trajectory controller preempts it) and ends where it would have.
        // The newest goal is the one followed.
        let deadline = Instant::now() + timeout;
        let mut sendings = 0;
        let (response, goal_id) = loop {
            let (request, goal_id) = self.action.send_goal(goal.clone()).map_err(|e| {
                backend(format!(
                    "sending the trajectory goal to {action} failed: {e:?}"
                ))
            })?;
            sendings += 1;
            let resend_at = (Instant::now() + REQUEST_RESEND).min(deadline);
            match poll_for(resend_at, || self.action.receive_goal_response(request)) {
                Some(Ok(r)) => break (r, goal_id),
                Some(Err(e)) => {
                    return Err(backend(format!(
                        "reading the answer to the trajectory goal from {action} failed: {e:?}"
                    )))
                }
                None if Instant::now() >= deadline => {
                    return Err(RobotError::ConnectionLost(format!(
                        "the action server {action} did not answer the goal within {:.1} s (sent {sendings} times; {})",
                        timeout.as_secs_f64(),
                        silent_action(&self.link, &action, self.options.framing)
                    )))
                }
                None => tracing::warn!(
                    "{action}: no answer to the trajectory goal within {} s: sending it again",
                    REQUEST_RESEND.as_secs()
                ),
            }
        };
        if !response.accepted {
            return Err(backend(format!(
                "the controller behind {action} rejected the trajectory goal (is it active, and are the joint names {} its joints?)",
                self.options.joint_names.join(", ")
            )));
        }
        // The result arrives when the controller ends the goal; meanwhile watch the interrupt
        // flag, the deadline and the driver's heartbeat. A result request or its answer lost on
        // the way must not end the run (a CI run against Cyclone DDS ended "move did not
        // finish" with the arm arrived and the result never heard): from the move's planned
        // end on, the result is asked for again every RESULT_REASK; an action server answers
        // each request, and the first answer to any of them ends the wait.
        let started = Instant::now();
        let deadline = started + Duration::from_secs_f64(total) + timeout;
        let ask = |this: &Self| {
            this.action.request_result(goal_id).map_err(|e| {
                backend(format!(
                    "asking {action} for the move's result failed: {e:?}"
                ))
            })
        };
        let mut asked = vec![ask(self)?];
        let mut next_ask = started + Duration::from_secs_f64(total) + RESULT_REASK;
        let outcome = loop {
            match answer_to(self.action.result_client(), &asked) {
                Ok(Some((_, r))) => break Outcome::Done(Ok((r.status, r.result))),
                Ok(None) => {}
                Err(e) => break Outcome::Done(Err(e)),
            }
            if self.interrupted() {
                break Outcome::Interrupted;
            }
            let now = Instant::now();
            if now > deadline {
                break Outcome::Late;
            }
            let silent = self
                .shared
                .lock()
                .joints
                .is_none_or(|j| j.received.elapsed() > timeout);
            if silent {
                break Outcome::Silent;
            }
            if now >= next_ask {
                // A request that cannot be written is no reason to leave the move unwatched:
                // the earlier ones stand.
                match ask(self) {
                    Ok(id) => asked.push(id),
                    Err(e) => tracing::warn!("{e}"),
                }
                next_ask = now + RESULT_REASK;
            }
            thread::sleep(POLL);
        };
        let cancel = |this: &Self| {
            let request = this.action.cancel_goal(goal_id).ok()?;
            poll_for(Instant::now() + Duration::from_secs(2), || {
                this.action.receive_cancel_response(request)
            })
        };
        match outcome {
            Outcome::Done(Ok((GoalStatusEnum::Succeeded, r))) if r.error_code == 0 => Ok(()),
            Outcome::Done(Ok((status, r))) => Err(backend(format!(
                "the controller behind {action} ended the move {status:?}: error_code {} ({}){}",
                r.error_code,
                follow_joint_trajectory_error(r.error_code),
                if r.error_string.is_empty() { String::new() } else { format!(": {}", r.error_string) }
            ))),
            Outcome::Done(Err(e)) => Err(backend(format!("asking {action} for the move's result failed: {e}"))),
            Outcome::Interrupted => match cancel(self) {
                Some(Ok(_)) => Err(RobotError::Interrupted),
                other => Err(backend(format!(
                    "the move was stopped on request but {action} did not confirm the cancel ({}): stop the arm on the teach pendant",
                    match other { Some(Err(e)) => format!("{e:?}"), _ => "no answer within 2 s".into() }
                ))),
            },
            Outcome::Late => {
                let _ = cancel(self);
                Err(RobotError::MoveTimeout(Duration::from_secs_f64(total) + timeout))
            }
            Outcome::Silent => {
                let _ = cancel(self);
                Err(RobotError::ConnectionLost(format!(
                    "{} went silent for {:.1} s during the move (driver or network gone); the goal was cancelled if the controller could still hear it",
                    self.options.joint_states_topic,
                    timeout.as_secs_f64()
                )))
            }
        }
    }
}

/// How a goal ended, as [`Ros2Arm::run_goal`] saw it.
enum Outcome {
    Done(Result<(GoalStatusEnum, FollowJointTrajectoryResult), String>),
    Interrupted,
    Late,
    Silent,
}

/// How often the result of a move past its planned end is asked for again.
const RESULT_REASK: Duration = Duration::from_secs(2);

/// Refuses an action whose goals more than one DDS participant takes: both servers answer every
/// goal and the first answer wins, so a simulated controller left running beside the driver
/// answers SUCCEEDED for moves that never happen (issue #40: "no tag of the board found" at
/// every pose, or a workspace-box stop after a few). Said before anything moves, or before the
/// goal a newly joined server would have taken.
fn one_action_server(link: &Ros2Link, action: &str) -> Result<(), RobotError> {
    let servers = link.participants_reading(&format!("rq{action}/_action/send_goalRequest"));
    if servers.len() <= 1 {
        return Ok(());
    }
    Err(backend(format!(
        "{} action servers take the goals of {action} on domain {} (DDS participants {}): each answers every goal and handeye cannot tell which one drives the arm — stop the one that does not (a second driver, or a simulated controller left running); nothing was sent",
        servers.len(),
        link.options().domain_id,
        servers.join(", ")
    )))
}

enum Event {
    Joints(ros2_client::ReadResult<(JointState, ros2_client::MessageInfo)>),
    Tf(
        ros2_client::ReadResult<(TfMessage, ros2_client::MessageInfo)>,
        bool,
    ),
}

/// The joint farthest apart in `a` and `b` and by how much (rad); `None` when their counts
/// differ.
fn farthest_joint(a: &Joints, b: &Joints) -> Option<(usize, f64)> {
    (a.len() == b.len()).then(|| {
        a.iter()
            .zip(b.iter())
            .map(|(x, y)| (x - y).abs())
            .enumerate()
            .fold(
                (0, 0.0),
                |worst, this| if this.1 > worst.1 { this } else { worst },
            )
    })
}

/// Why an action server may not answer, from what discovery heard on the domain (issue #39: a
/// middleware mismatch and an empty domain were both "is the controller running?"): nothing at
/// all heard (the domain id or the network interfaces), the action's own topics heard (the server
/// is there, so it does not read our requests: the other middleware's request framing,
/// `robot.graph.rmw`), or other action servers heard (another name).
fn silent_action(link: &Ros2Link, action: &str, framing: Framing) -> String {
    let heard = link.heard_topics();
    let domain = link.options().domain_id;
    if heard.is_empty() {
        return format!(
            "nothing at all is heard on domain {domain}: no ROS 2 node runs there — check robot.graph.domain_id against the driver's ROS_DOMAIN_ID, and robot.graph.interfaces"
        );
    }
    let own = format!("{action}/_action/");
    if heard.iter().any(|(name, _)| name.starts_with(&own)) {
        let (ours, other) = match framing {
            Framing::FastRtps => ("fastrtps", "cyclonedds"),
            Framing::Cyclone => ("cyclonedds", "fastrtps"),
        };
        return format!(
            "its topics are on the domain, so it is there but does not take our requests: robot.graph.rmw is `{ours}`; if the driver runs the other middleware (its RMW_IMPLEMENTATION), set `rmw: {other}`"
        );
    }
    let servers: Vec<&str> = heard
        .iter()
        .filter_map(|(name, _)| name.strip_suffix("/_action/status"))
        .collect();
    if servers.is_empty() {
        "is the controller running and active? No action server is heard on this domain".into()
    } else {
        format!(
            "is the controller running and active? Action servers heard on this domain: {}",
            servers.join(", ")
        )
    }
}

/// The publisher of a message as a number (its DDS writer's GID, hashed): two publishers of
/// one TF edge are told apart by it.
pub(crate) fn publisher_id(info: &ros2_client::MessageInfo) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    info.publisher_gid().as_bytes().hash(&mut hasher);
    hasher.finish()
}

fn apply(shared: &Shared, names: &[String], event: Event) {
    let received = Instant::now();
    match event {
        Event::Joints(Ok((msg, _))) => {
            shared.update(|s| match joint_sample(&msg, names, received) {
                Ok(sample) => {
                    s.previous = s.joints.replace(sample);
                    s.joints_problem = None;
                }
                Err(problem) => s.joints_problem = Some(problem),
            })
        }
        Event::Tf(Ok((msg, info)), is_static) => shared.update(|s| {
            s.tf.update_from(&msg, publisher_id(&info), received);
            if !is_static {
                s.tf_received = Some(received);
            }
        }),
        Event::Joints(Err(e)) | Event::Tf(Err(e), _) => {
            tracing::warn!("ROS 2 arm: a message could not be read: {e:?}")
        }
    }
}

impl Robot for Ros2Arm {
    fn base_from_flange(&mut self) -> Result<Pose, RobotError> {
        if self.options.flange_from_joints {
            return self.flange_from_joints();
        }
        // A /tf message heard after this call: the pose of the arm as it stands now.
        let asked = Instant::now();
        let flange = self.flange_after(asked, asked + self.options.timeout)?;
        if !self.check_standing_flange(&flange)? {
            return Ok(flange);
        }
        match self.check_flange_against_model(&flange) {
            Ok(()) => Ok(flange),
            // Once more with a flange pose heard after the first look (the joints are read fresh
            // each time): a /tf and a /joint_states message of different instants (one delivered
            // late on a loaded machine) contradict each other for a moment, and the pose that
            // agrees is the one kept; a wrong chain or model contradicts every time.
            Err(contradiction) => {
                let now = Instant::now();
                let again = self.flange_after(now, now + self.options.timeout)?;
                match self.check_flange_against_model(&again) {
                    Ok(()) => Ok(again),
                    Err(_) => Err(self.second_publisher_or(contradiction)),
                }
            }
        }
    }

    fn joint_positions(&mut self) -> Result<Joints, RobotError> {
        Ok(self.fresh_joints(Instant::now() - STALE)?.positions)
    }

    fn move_linear(
        &mut self,
        base_from_flange: &Pose,
        limits: &MotionLimits,
    ) -> Result<(), RobotError> {
        let Some(model) = self.options.kinematics.clone() else {
            return Err(RobotError::Unreachable(
                "linear moves need the arm's kinematics (a UR `robot.model`); give joint waypoints instead".into(),
            ));
        };
        let seed = self.joint_positions()?;
        let joints = model
            .inverse_nearest(base_from_flange, &seed)
            .ok_or_else(|| {
                RobotError::Unreachable("no joint solution within the joint limits".into())
            })?;
        self.move_joints(&joints, limits)
    }

    fn move_joints(&mut self, joints: &Joints, limits: &MotionLimits) -> Result<(), RobotError> {
        limits.check()?;
        if self.interrupted() {
            return Err(RobotError::Interrupted);
        }
        let from = self.joint_positions()?;
        if joints.len() != from.len() {
            return Err(RobotError::JointCount {
                arm: from.len(),
                asked: joints.len(),
            });
        }
        if handeye_robot::leading_travel(&from, joints) < 1e-6 {
            return Ok(());
        }
        let goal = Self::trajectory(&self.options.joint_names, &from, joints, limits);
        let total = limits.joint_move_time(&from, joints);
        self.run_goal(goal, total)?;
        self.check_arrival(joints)
    }

    fn stop(&mut self) -> Result<(), RobotError> {
        // Moves block until they end or are cancelled: no goal of ours is running here.
        Ok(())
    }

    fn set_freedrive(&mut self, on: bool) -> Result<(), RobotError> {
        // ROS 2 has no standard way (the UR driver's is a controller switch plus a keep-alive
        // topic of its own, `freedrive`): without it the person switches freedrive on the arm,
        // and capture reads where the arm stands whatever moved it.
        match &mut self.freedrive {
            Some(freedrive) => freedrive.set(on),
            None => Err(RobotError::NotAvailable(HAND_GUIDING.into())),
        }
    }

    fn set_interrupt(&mut self, flag: Arc<AtomicBool>) {
        self.interrupt = Some(flag);
    }

    fn status(&mut self) -> Result<RobotStatus, RobotError> {
        self.fresh_joints(Instant::now() - STALE)?;
        Ok(RobotStatus::Ready)
    }

    fn joint_speeds(&mut self) -> Result<Option<Joints>, RobotError> {
        let now = self.fresh_joints(Instant::now() - STALE)?;
        if let Some(v) = now.velocities {
            return Ok(Some(v));
        }
        // No speeds from the driver: the difference of the last two samples.
        let previous = self.shared.lock().previous;
        Ok(previous.and_then(|p| {
            let dt = now.stamp.duration_since(p.stamp).ok()?.as_secs_f64();
            (dt > 0.0).then(|| {
                Joints::from_fn(now.positions.len(), |i| {
                    (now.positions[i] - p.positions[i]) / dt
                })
            })
        }))
    }
}
