//! What `publish` and `export --format ros2-launch` read from a ROS 2 graph before they give a
//! frame a parent: a camera driver publishes its own chain from the link the camera is mounted
//! by to its optical frame (a RealSense: `camera_link → camera_color_frame →
//! camera_color_optical_frame`, the colour imager's offset included), and a frame has one parent
//! in TF. `--camera-link LINK` hangs the calibrated camera from `LINK` with the chain read from
//! `/tf_static`, so `flange → LINK → … → optical` composes to the calibrated pose exactly; a frame
//! that already hangs from another parent is refused, naming the link to pass. Nothing about the
//! chain is assumed unless asked (`--optical-rotation-only`, the form of earlier versions: the
//! link's REP 103 axes turned to the optical frame, no offset).

use std::net::IpAddr;

use clap::Args;

use handeye_core::geometry::Pose;
use handeye_formats::export::{Exported, ExportedCell, FramedTransform};
use handeye_formats::ros2_launch::{link_from_optical, through_camera_link};
use handeye_ros2::listen::TfTree;

/// The ROS 2 domain to read or publish on.
#[derive(Debug, Args)]
pub(super) struct DomainArgs {
    /// The ROS 2 domain id (default: $ROS_DOMAIN_ID, else 0).
    #[arg(long)]
    domain_id: Option<u16>,
    /// A local address DDS may use (repeat for several; default: every interface).
    #[arg(long = "interface", value_name = "ADDRESS")]
    pub(super) interfaces: Vec<IpAddr>,
}

impl DomainArgs {
    /// `--domain-id`, else `$ROS_DOMAIN_ID`, else 0.
    pub(super) fn domain_id(&self) -> anyhow::Result<u16> {
        Ok(match self.domain_id {
            Some(id) => id,
            None => match std::env::var("ROS_DOMAIN_ID") {
                Ok(v) if !v.trim().is_empty() => v.trim().parse().map_err(|_| {
                    anyhow::anyhow!("ROS_DOMAIN_ID={v:?} is not a domain id (0..=232)")
                })?,
                _ => 0,
            },
        })
    }
}

/// The camera's mounting link and how its chain is found.
#[derive(Debug, Args)]
pub(super) struct CameraLinkArgs {
    /// The camera's mounting link (a RealSense's `camera_link`): the camera driver publishes the
    /// chain from it to --camera-frame on /tf_static; the calibrated camera is then written as a
    /// transform to this link, with that chain read from the graph (--domain-id), so the whole
    /// chain ends at the calibrated optical pose.
    #[arg(long, value_name = "FRAME")]
    pub(super) camera_link: Option<String>,
    /// How long to listen to /tf_static for the driver's chain and for frames that already have
    /// a parent, seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 3.0)]
    tf_wait: f64,
    /// With --camera-link (export): where the driver's chain was recorded — a session folder
    /// (its tf_static.yaml, which a ROS 2 run records) or such a file. Default: the result's own
    /// session when it holds one, else the graph (--domain-id).
    #[arg(long, value_name = "PATH")]
    tf_from: Option<std::path::PathBuf>,
    /// With --camera-link: do not read the chain, assume it is the link's REP 103 axes (x forward,
    /// y left, z up) turned to the optical frame with no offset (what earlier versions wrote; a
    /// RealSense's colour imager sits centimetres from its link, so check before using it).
    #[arg(long, requires = "camera_link")]
    optical_rotation_only: bool,
}

impl CameraLinkArgs {
    /// The listening time, checked.
    pub(super) fn tf_wait(&self) -> anyhow::Result<std::time::Duration> {
        anyhow::ensure!(
            self.tf_wait.is_finite() && (0.0..=600.0).contains(&self.tf_wait),
            "--tf-wait {} s must be between 0 and 600 seconds",
            self.tf_wait
        );
        Ok(std::time::Duration::from_secs_f64(self.tf_wait))
    }

    /// Whether the chain is assumed (`--optical-rotation-only`), not read.
    pub(super) fn assumes_chain(&self) -> bool {
        self.optical_rotation_only
    }

    /// The driver's chain as recorded for a result in `result_folder`: `--tf-from` (a session
    /// folder or its `tf_static.yaml`), else the result's own session's record; with where it
    /// came from. `None`: no record (the graph is read instead).
    pub(super) fn recorded_chain(
        &self,
        result_folder: &std::path::Path,
    ) -> anyhow::Result<Option<(TfTree, String)>> {
        use handeye_records::tf_static::{StaticTransformsFile, TF_STATIC_FILE};
        let file = match &self.tf_from {
            Some(path) if path.is_dir() => path.join(TF_STATIC_FILE),
            Some(path) => path.clone(),
            None => match result_folder.join(TF_STATIC_FILE) {
                recorded if recorded.is_file() => recorded,
                _ => return Ok(None),
            },
        };
        let recorded =
            StaticTransformsFile::load(&file).map_err(|e| anyhow::anyhow!("--tf-from: {e}"))?;
        let from = format!("{} (recorded from {})", file.display(), recorded.topic);
        Ok(Some((recorded.tree(), from)))
    }
}

/// Hangs the camera of `exported` from `--camera-link` (the chain read from `heard`, or assumed
/// with `--optical-rotation-only`), then refuses any transform whose child already hangs from
/// another parent in `heard`.
pub(super) fn hang_camera(
    exported: &mut Exported,
    args: &CameraLinkArgs,
    heard: Option<&TfTree>,
    topic: &str,
) -> anyhow::Result<()> {
    if let Some(link) = &args.camera_link {
        handeye_formats::validate_frame_id(link)
            .map_err(|p| anyhow::anyhow!("--camera-link {link:?} is not a ROS frame id: {p}"))?;
        if let ExportedCell::Cameras(n) = exported.cell {
            anyhow::bail!(
                "--camera-link names the link of one camera; this is a result of {n} cameras"
            );
        }
        let camera = &exported.tree[0];
        let chain = match heard {
            Some(tree) => driver_chain(tree, link, &camera.child, topic, args.tf_wait)?,
            None => link_from_optical(),
        };
        exported.tree[0] = through_camera_link(camera, link, &chain);
    }
    if let Some(tree) = heard {
        refuse_second_parents(&exported.tree, tree, topic, args.camera_link.is_some())?;
    }
    Ok(())
}

/// `T_link_optical` as the camera driver publishes it: `link` must be above `optical` in the
/// tree heard.
fn driver_chain(
    tree: &TfTree,
    link: &str,
    optical: &str,
    topic: &str,
    wait_s: f64,
) -> anyhow::Result<Pose> {
    let mut chain = vec![optical.to_string()];
    while let Some(parent) = tree
        .parent_of(chain.last().map_or(optical, String::as_str))
        .map(str::to_string)
    {
        if chain.contains(&parent) || chain.len() > 256 {
            break;
        }
        chain.push(parent.clone());
        if parent == link {
            let pose = tree
                .lookup(link, optical)
                .map_err(|e| anyhow::anyhow!("--camera-link {link}: {e}"))?;
            outln!(
                "the camera's chain as the driver publishes it on {topic}: {} (T_{link}_{optical}: translation [{:.4}, {:.4}, {:.4}] m)",
                chain.iter().rev().cloned().collect::<Vec<_>>().join(" → "),
                pose.translation.vector.x,
                pose.translation.vector.y,
                pose.translation.vector.z
            );
            return Ok(pose);
        }
    }
    let heard_chain = match chain.len() {
        1 => format!("{optical} has no parent on {topic}"),
        _ => format!(
            "{optical}'s chain on {topic} is {}, without {link}",
            chain.iter().rev().cloned().collect::<Vec<_>>().join(" → ")
        ),
    };
    anyhow::bail!(
        "--camera-link {link}: the camera driver's chain {link} → … → {optical} was not heard {within} ({heard_chain}). Start the camera driver first (it publishes the chain), check --domain-id and --camera-frame (the optical frame id of the driver's images), or pass --optical-rotation-only to assume the link's REP 103 axes turned to the optical frame with no offset",
        within = if topic.starts_with('/') {
            format!("within {wait_s} s")
        } else {
            format!("in {topic}")
        }
    )
}

/// Refuses a transform whose child already hangs from another parent on the graph: TF allows
/// one parent per frame, and a second one breaks the tree for every node.
fn refuse_second_parents(
    tree_out: &[FramedTransform],
    heard: &TfTree,
    topic: &str,
    camera_link_given: bool,
) -> anyhow::Result<()> {
    for (i, t) in tree_out.iter().enumerate() {
        let Some(parent) = heard.parent_of(&t.child).map(str::to_string) else {
            continue;
        };
        if parent == t.parent {
            // The same edge from another node (an earlier `handeye publish` still running, say).
            eprintln!(
                "note: {} → {} is already on {topic} from another node; both are latched, and tf2 keeps the newest",
                t.parent, t.child
            );
            continue;
        }
        // The top of the chain it hangs in (bounded: a graph may hold a loop).
        let mut top = parent.clone();
        for _ in 0..256 {
            match heard.parent_of(&top) {
                Some(up) if up != t.child => top = up.to_string(),
                _ => break,
            }
        }
        let advice = if i == 0 && !camera_link_given {
            format!(
                "pass --camera-link {top} (the frame the camera is mounted by): the camera is then published as {} → {top}, with the driver's chain from {top} read from {topic}, so it ends at the calibrated pose",
                t.parent
            )
        } else {
            "choose a frame id of its own for it (--camera-frame, --target-frame) or stop the node that publishes it".to_string()
        };
        anyhow::bail!(
            "{} already hangs from {parent} on {topic} (another node publishes it: a camera driver, a robot_state_publisher?); publishing {} → {} would give it a second parent. Nothing was published: {advice}",
            t.child,
            t.parent,
            t.child
        );
    }
    Ok(())
}
