//! What the ros2 arm and camera cost while idle: both open against the peer's streams (joint
//! states at 100 Hz, TF at 50 Hz, 1280x720 mono8 images at 15 Hz), nothing moving, for 10 s;
//! the process's CPU time over that. A measurement, not a check of this machine's speed: run it
//! alone (`cargo test --features ros2 --test it -- --ignored ros2_live::idle --nocapture`), since
//! the other tests' threads would count too.

use std::time::{Duration, Instant};

use handeye_camera::Camera;
use handeye_robot::Robot;

use super::cell::Peer;
use super::{loopback_link, open_sim_camera, open_ur_arm, python};
use crate::util::ros_domain;

/// CPU time (user + system) of this process, s.
fn cpu_seconds() -> f64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::ProcessCPUTime);
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

#[test]
#[ignore = "a measurement: run alone"]
fn idle_cpu_of_the_ros2_backends() {
    let Some(python) = python() else { return };
    let domain = ros_domain();
    let _peer = Peer::start(&python, domain, &[]);
    let link = loopback_link(domain, "handeye_idle");
    let mut arm = open_ur_arm(&link, None);
    let mut camera = open_sim_camera(&link);
    camera.grab(Instant::now()).unwrap();
    arm.joint_positions().unwrap();
    let (cpu0, wall0) = (cpu_seconds(), Instant::now());
    std::thread::sleep(Duration::from_secs(10));
    let share = (cpu_seconds() - cpu0) / wall0.elapsed().as_secs_f64();
    eprintln!("idle ros2 arm + camera: {:.1} % of one core", share * 100.0);
    assert!(share < 1.0, "{share}");
}
