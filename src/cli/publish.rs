//! `handeye publish <result.yaml>`: the solved transforms (a one-camera cell's two unknowns, or
//! every camera's mount and the boards of a cell with several) on ROS 2 `/tf_static`, latched
//! (reliable, transient local, depth 1: what `static_transform_publisher` does), until Ctrl-C or
//! `--duration`. The frame ids and the `base_link` turn are `export`'s (`exported_result`); what
//! the graph already publishes is read first (`camera_link`: a frame is never given a second
//! parent, and `--camera-link` hangs the camera from its driver's chain).

use std::path::PathBuf;

use clap::Args;

use super::camera_link::{CameraLinkArgs, DomainArgs};

/// Publish a result's T_parent_child transforms (eye_in_hand T_flange_camera and T_base_target,
/// eye_to_hand T_base_camera and T_flange_target) on /tf_static, with no ROS installation.
/// /tf_static is read first: a frame that already has a parent there is refused, and
/// --camera-link hangs the camera from the link its driver's chain starts at.
#[derive(Debug, Args)]
pub(super) struct PublishArgs {
    /// The result YAML written by `handeye solve` or `handeye run`.
    result: PathBuf,
    #[command(flatten)]
    frames: super::frames::FrameArgs,
    #[command(flatten)]
    domain: DomainArgs,
    #[command(flatten)]
    link: CameraLinkArgs,
    /// The topic.
    #[arg(long, default_value = "/tf_static")]
    topic: String,
    /// Stop after this many seconds (default: keep publishing until Ctrl-C).
    #[arg(long, value_name = "SECONDS")]
    duration: Option<f64>,
}

/// Runs `handeye publish`.
pub(super) fn run(args: PublishArgs) -> anyhow::Result<()> {
    if let Some(d) = args.duration {
        anyhow::ensure!(
            d.is_finite() && d > 0.0,
            "--duration {d} s must be a positive number of seconds"
        );
    }
    let domain_id = args.domain.domain_id()?;
    args.link.tf_wait()?;
    // A tree: every mount and board; camera-to-camera transforms would give a camera a second
    // parent.
    let exported = super::export::exported_result(&args.result, args.frames)?;
    publish(
        exported,
        &args.link,
        domain_id,
        args.domain.interfaces,
        &args.topic,
        args.duration,
    )
}

#[cfg(feature = "ros2")]
fn publish(
    mut exported: handeye_formats::export::Exported,
    camera_link: &CameraLinkArgs,
    domain_id: u16,
    interfaces: Vec<std::net::IpAddr>,
    topic: &str,
    duration: Option<f64>,
) -> anyhow::Result<()> {
    use std::sync::atomic::Ordering;
    use std::time::{Duration, Instant};

    use handeye_ros2::link::{LinkOptions, Ros2Link};
    use handeye_ros2::tf_static::{hear_static, StaticPublisher, StaticTransform};

    let link = Ros2Link::open(LinkOptions {
        domain_id,
        interfaces,
        node_name: "handeye_publish".into(),
    })?;
    // What the graph holds already (a camera driver's chain), before any frame gets a parent.
    let heard = hear_static(&link, topic, camera_link.tf_wait()?)?;
    super::camera_link::hang_camera(&mut exported, camera_link, Some(&heard), topic)?;
    let transforms = exported.tree;
    let statics: Vec<StaticTransform> = transforms
        .iter()
        .map(|t| StaticTransform {
            parent: t.parent.clone(),
            child: t.child.clone(),
            parent_from_child: t.parent_from_child,
        })
        .collect();
    let _publisher = StaticPublisher::publish(&link, topic, &statics)?;
    for t in &transforms {
        outln!(
            "publishing {} ({} → {}) on {topic}, domain {domain_id}",
            t.key,
            t.parent,
            t.child
        );
    }
    match duration {
        Some(s) => outln!("latched for {s} s"),
        None => outln!("latched until Ctrl-C"),
    }
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    super::stop_on_signals(stop.clone());
    let end = duration.map(|s| Instant::now() + Duration::from_secs_f64(s));
    while !stop.load(Ordering::SeqCst) && end.is_none_or(|end| Instant::now() < end) {
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok(())
}

#[cfg(not(feature = "ros2"))]
fn publish(
    _exported: handeye_formats::export::Exported,
    _camera_link: &CameraLinkArgs,
    _domain_id: u16,
    _interfaces: Vec<std::net::IpAddr>,
    _topic: &str,
    _duration: Option<f64>,
) -> anyhow::Result<()> {
    anyhow::bail!(
        "this handeye was built without ROS 2: rebuild with `cargo build --release --features ros2`"
    )
}
