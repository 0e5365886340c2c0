//! Freedrive on a UR arm under the UR ROS 2 driver (`ur_robot_driver` 2.5 or later): its
//! `freedrive_mode_controller` takes the arm while a person guides it. On: the controller manager
//! switches from the motion controller (`scaled_joint_trajectory_controller`, whose goals then stop
//! being taken) to the freedrive controller, and `true` goes to the controller's
//! `~/enable_freedrive_mode` every 100 ms — a keep-alive: the controller ends freedrive by itself
//! when it stops hearing it (its `inactive_timeout`). Off: `false`, then the switch back. Dropping
//! the handle while on switches back too, so a session that ends in any way leaves the arm under
//! the motion controller.
//!
//! `controller_manager_msgs/SwitchController` is laid out differently on the wire by Humble's
//! ros2_control and Jazzy's ([`Distro`]); the config names the distribution.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::{self, JoinHandle};
use std::time::Duration;

use ros2_client::service::Client;
use ros2_client::{Publisher, ServiceMapping, ServiceTypeName};

use handeye_robot::RobotError;

use crate::arm::Framing;
use crate::link::{
    call, reliable_qos, serves, settle_after_match, topic_name, Ros2Link, REQUEST_RESEND,
};
use crate::msg::{
    Bool, SwitchControllerHumble, SwitchControllerJazzy, SwitchControllerResponse, SWITCH_STRICT,
};

impl ros2_client::Message for Bool {}
impl ros2_client::Message for SwitchControllerHumble {}
impl ros2_client::Message for SwitchControllerJazzy {}
impl ros2_client::Message for SwitchControllerResponse {}

/// How often the keep-alive `true` is sent (the UR controller's default timeout is 10 s).
const KEEP_ALIVE: Duration = Duration::from_millis(100);

/// The ROS 2 distribution of the controller manager: its `SwitchController` layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Distro {
    /// ros2_control 2.x.
    Humble,
    /// ros2_control 4.x.
    Jazzy,
}

/// Where the controllers are and what they are called.
#[derive(Debug, Clone)]
pub struct FreedriveOptions {
    /// The controller manager's node (`/controller_manager`).
    pub controller_manager: String,
    /// The freedrive controller (`freedrive_mode_controller`).
    pub freedrive_controller: String,
    /// The controller that takes trajectory goals (`scaled_joint_trajectory_controller`),
    /// inactive while freedrive is on.
    pub motion_controller: String,
    /// The controller manager's ROS 2 distribution.
    pub distro: Distro,
    /// How long to wait for the controller manager's answer.
    pub timeout: Duration,
}

enum SwitchClient {
    Humble(Client<SwitchControllerHumble, SwitchControllerResponse>),
    Jazzy(Client<SwitchControllerJazzy, SwitchControllerResponse>),
}

/// Freedrive through the UR driver's controllers; see the module docs.
pub struct Freedrive {
    link: Ros2Link,
    options: FreedriveOptions,
    switch: SwitchClient,
    /// Whether a switch was asked for already (its client's first request settled).
    switched: AtomicBool,
    enable: Arc<Publisher<Bool>>,
    enable_topic: String,
    /// The keep-alive while freedrive is on: its stop flag and thread.
    keep_alive: Option<(Arc<AtomicBool>, JoinHandle<()>)>,
}

fn backend(message: String) -> RobotError {
    RobotError::Backend(message.into())
}

impl Freedrive {
    /// Makes the service client and the keep-alive writer (nothing is asked of the arm yet).
    pub fn open(
        link: &Ros2Link,
        options: FreedriveOptions,
        framing: Framing,
    ) -> Result<Freedrive, RobotError> {
        let service = format!(
            "{}/switch_controller",
            options.controller_manager.trim_end_matches('/')
        );
        let name = topic_name(&service).map_err(|e| backend(e.to_string()))?;
        let mapping = match framing {
            Framing::FastRtps => ServiceMapping::Enhanced,
            Framing::Cyclone => ServiceMapping::Cyclone,
        };
        let type_name = ServiceTypeName::new("controller_manager_msgs", "SwitchController");
        let setup = |e: ros2_client::CreateError| {
            backend(format!("cannot set up the client of {service}: {e}"))
        };
        let switch = link.with_node(|node| -> Result<SwitchClient, RobotError> {
            Ok(match options.distro {
                Distro::Humble => SwitchClient::Humble(
                    node.create_client(mapping, &name, &type_name, reliable_qos(), reliable_qos())
                        .map_err(setup)?,
                ),
                Distro::Jazzy => SwitchClient::Jazzy(
                    node.create_client(mapping, &name, &type_name, reliable_qos(), reliable_qos())
                        .map_err(setup)?,
                ),
            })
        })?;
        let enable_topic = format!("/{}/enable_freedrive_mode", options.freedrive_controller);
        let enable = link
            .publisher::<Bool>(&enable_topic, reliable_qos())
            .map_err(|e| backend(e.to_string()))?;
        Ok(Freedrive {
            link: link.clone(),
            options,
            switch,
            switched: AtomicBool::new(false),
            enable: Arc::new(enable),
            enable_topic,
            keep_alive: None,
        })
    }

    /// Freedrive on or off; see the module docs. Switching to the state it is in does nothing.
    pub fn set(&mut self, on: bool) -> Result<(), RobotError> {
        if on == self.keep_alive.is_some() {
            return Ok(());
        }
        let (freedrive, motion) = (
            self.options.freedrive_controller.clone(),
            self.options.motion_controller.clone(),
        );
        if on {
            self.switch(vec![freedrive.clone()], vec![motion.clone()])?;
            if let Err(e) = self.publish(true) {
                // Not free after all: give the arm back to the motion controller.
                let _ = self.switch(vec![motion], vec![freedrive]);
                return Err(e);
            }
            let stop = Arc::new(AtomicBool::new(false));
            let (flag, enable) = (stop.clone(), self.enable.clone());
            let thread = thread::Builder::new()
                .name("ros2-freedrive".into())
                .spawn(move || {
                    while !flag.load(Ordering::SeqCst) {
                        let _ = enable.publish(Bool { data: true });
                        thread::sleep(KEEP_ALIVE);
                    }
                })
                .map_err(|e| backend(format!("cannot start the freedrive keep-alive: {e}")))?;
            self.keep_alive = Some((stop, thread));
            Ok(())
        } else {
            self.stop_keep_alive();
            self.publish(false)?;
            self.switch(vec![motion], vec![freedrive])
        }
    }

    fn stop_keep_alive(&mut self) {
        if let Some((stop, thread)) = self.keep_alive.take() {
            stop.store(true, Ordering::SeqCst);
            let _ = thread.join();
        }
    }

    fn publish(&self, on: bool) -> Result<(), RobotError> {
        self.enable
            .publish(Bool { data: on })
            .map_err(|e| backend(format!("cannot publish on {}: {e:?}", self.enable_topic)))
    }

    /// Asks the controller manager to activate `activate` and deactivate `deactivate`, strictly.
    fn switch(&self, activate: Vec<String>, deactivate: Vec<String>) -> Result<(), RobotError> {
        let what = format!(
            "switching the controllers (activate {}, deactivate {}) through {}/switch_controller",
            activate.join(", "),
            deactivate.join(", "),
            self.options.controller_manager
        );
        let timeout = self.options.timeout;
        // The service on the graph first, then the call.
        let served = self
            .link
            .wait_until_matched(timeout, |node| match &self.switch {
                SwitchClient::Humble(client) => serves(client, node),
                SwitchClient::Jazzy(client) => serves(client, node),
            });
        // The first switch of this client only (a settle on every press would slow each).
        if served && !self.switched.swap(true, Ordering::SeqCst) {
            settle_after_match();
        }
        let answer = if served {
            match &self.switch {
                SwitchClient::Humble(client) => call(
                    client,
                    SwitchControllerHumble {
                        activate_controllers: activate.clone(),
                        deactivate_controllers: deactivate.clone(),
                        strictness: SWITCH_STRICT,
                        ..SwitchControllerHumble::default()
                    },
                    timeout,
                ),
                SwitchClient::Jazzy(client) => call(
                    client,
                    SwitchControllerJazzy {
                        activate_controllers: activate.clone(),
                        deactivate_controllers: deactivate.clone(),
                        strictness: SWITCH_STRICT,
                        ..SwitchControllerJazzy::default()
                    },
                    timeout,
                ),
            }
        } else {
            None
        };
        let distro = match self.options.distro {
            Distro::Humble => "humble",
            Distro::Jazzy => "jazzy",
        };
        match answer.map(|a| (a.response, a.to_a_repeat)) {
            Some((Ok(SwitchControllerResponse { ok: true }), _)) => Ok(()),
            Some((Ok(SwitchControllerResponse { ok: false }), false)) => Err(backend(format!(
                "{what}: the controller manager refused (are both controllers loaded? the UR driver 2.5 or later loads {} inactive)",
                self.options.freedrive_controller
            ))),
            // The first request went unanswered and its repeat was refused: the first may have
            // switched them (only its answer lost), and a strict switch refuses to do it twice.
            Some((Ok(SwitchControllerResponse { ok: false }), true)) => Err(backend(format!(
                "{what}: the first request went unanswered for {}s and the controller manager refused its repeat; the first may have switched them — check which controller is active (`ros2 control list_controllers`) before you go on",
                REQUEST_RESEND.as_secs()
            ))),
            Some((Err(e), _)) => Err(backend(format!("{what}: {e}"))),
            None => Err(RobotError::ConnectionLost(format!(
                "{what}: {} within {timeout:?} (is the controller manager on this domain, and is robot.freedrive.distro ({distro}) its ROS 2 distribution? Humble and Jazzy lay this request out differently)",
                if served { "no answer" } else { "no server of it found" }
            ))),
        }
    }
}

impl Drop for Freedrive {
    /// Leaves the arm under the motion controller, whatever ended the session.
    fn drop(&mut self) {
        if self.keep_alive.is_some() {
            if let Err(e) = self.set(false) {
                tracing::warn!("freedrive was left on: {e}; switch it off on the teach pendant");
            }
        }
    }
}
