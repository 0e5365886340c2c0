//! What the arm says on the graph, kept current by a reader task: the newest `/joint_states`
//! (and the one before, for speeds when the driver sends none) and the TF tree from `/tf` and
//! `/tf_static`. Readers wait on it with a deadline; nothing here blocks a DDS thread.
//!
//! Frames: each TF edge is `T_parent_child`; [`TfTree::lookup`] chains them to `T_a_b` for any
//! two frames of one tree.

use std::collections::BTreeMap;
use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime};

use handeye_core::geometry::Pose;

use handeye_robot::{JointCountError, Joints, MAX_JOINTS};

use crate::msg::{JointState, TfMessage};

/// One `/joint_states` message in the configured joint order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointSample {
    /// Positions, rad, one per configured joint name.
    pub positions: Joints,
    /// Speeds the driver reported, rad/s (`None` when it sends none).
    pub velocities: Option<Joints>,
    /// The message's stamp.
    pub stamp: SystemTime,
    /// When it arrived here.
    pub received: Instant,
}

/// One TF edge: `T_parent_child`, with what each publisher of it said last.
#[derive(Debug, Clone, PartialEq)]
struct Edge {
    parent: String,
    parent_from_child: Pose,
    /// Per publisher heard within [`RECENT_SOURCES`]: its id, its last pose, when (those
    /// within [`SOURCES_WINDOW`] of the newest are the current ones).
    sources: Vec<(u64, Pose, Instant)>,
    /// Two publishers that disagree: the message a lookup through this edge fails with.
    conflict: Option<String>,
}

/// How long a publisher of an edge counts as current: two publishers of one edge heard within
/// this of each other, saying different transforms, contradict each other (a handover to a
/// restarted publisher does not).
const SOURCES_WINDOW: Duration = Duration::from_secs(1);
/// How long a publisher of an edge is remembered for [`TfTree::recent_disagreement`]: on a
/// loaded machine the driver's publisher can go unheard for more than [`SOURCES_WINDOW`] beside
/// a faster second one, and a pose that contradicts the joints is then better explained by the
/// second publisher than by a wrong model.
const RECENT_SOURCES: Duration = Duration::from_secs(10);
/// How far one edge's transform may jitter at rest, m and rad (far above a driver's own
/// jitter): two publishers of one edge farther apart contradict each other, and so does a
/// flange pose that moves this much while its joints stand (`arm`).
pub(crate) const AT_REST_JITTER_M: f64 = 1e-3;
pub(crate) const AT_REST_JITTER_RAD: f64 = 0.1 * std::f64::consts::PI / 180.0;
/// Publishers of one edge remembered at once: two are enough to see a contradiction, and a
/// domain where anyone can make writers must not grow an edge's list with each of them.
const MAX_SOURCES: usize = 8;

/// The most frames the tree keeps: a robot cell's tree has tens to a few hundred. Anyone on the
/// DDS domain can publish `/tf` (plain DDS has no authentication), and each new child name would
/// otherwise be kept for the life of the run; edges of frames already known still update. The
/// frames the run needs ([`TfTree::wanting`]) and their chains are never crowded out: a full
/// tree drops another frame to take them.
pub const MAX_TF_FRAMES: usize = 4096;

/// The TF tree as last heard.
#[derive(Debug, Clone, Default)]
pub struct TfTree {
    edges: BTreeMap<String, Edge>,
    /// The frames looked up (the configured base and flange): they and every frame above them
    /// stay when the tree is full.
    wanted: Vec<String>,
    /// Whether a new frame was dropped at [`MAX_TF_FRAMES`] (said once).
    full: bool,
}

impl TfTree {
    /// An empty tree that keeps `frames` and their chains even when a flood of other frame names
    /// fills it.
    pub fn wanting(frames: &[&str]) -> TfTree {
        TfTree {
            wanted: frames
                .iter()
                .map(|f| f.trim_start_matches('/').to_string())
                .collect(),
            ..TfTree::default()
        }
    }

    /// Adds or replaces the edges of one message (a bad quaternion is skipped and logged), as
    /// from one publisher heard now.
    pub fn update(&mut self, msg: &TfMessage) {
        self.update_from(msg, 0, Instant::now());
    }

    /// [`TfTree::update`] of a message from the publisher `source` (its DDS writer, hashed)
    /// heard at `now`: an edge that two publishers send with different transforms is marked,
    /// and a lookup through it fails naming both (issue #40: a second publisher of
    /// base → tool0 made a run "measure the board at 0.119×").
    pub fn update_from(&mut self, msg: &TfMessage, source: u64, now: Instant) {
        for t in &msg.transforms {
            let child = t.child_frame_id.trim_start_matches('/').to_string();
            let parent = t.header.frame_id.trim_start_matches('/').to_string();
            if self.edges.len() >= MAX_TF_FRAMES
                && !self.edges.contains_key(&child)
                && !(self.needs(&child) && self.drop_one_unneeded())
            {
                if !self.full {
                    tracing::warn!(
                        "TF: more than {MAX_TF_FRAMES} frames heard; new frames ({child}, ...) are ignored"
                    );
                    self.full = true;
                }
                continue;
            }
            match t.transform.to_pose() {
                Some(pose) => {
                    let mut sources = self
                        .edges
                        .remove(&child)
                        .map(|e| e.sources)
                        .unwrap_or_default();
                    sources.retain(|(id, _, heard)| {
                        *id != source && now.saturating_duration_since(*heard) <= RECENT_SOURCES
                    });
                    if sources.len() >= MAX_SOURCES {
                        sources.remove(0);
                    }
                    sources.push((source, pose, now));
                    let current: Vec<_> = sources
                        .iter()
                        .filter(|(_, _, heard)| {
                            now.saturating_duration_since(*heard) <= SOURCES_WINDOW
                        })
                        .copied()
                        .collect();
                    let conflict = contradiction(&parent, &child, &current);
                    self.edges.insert(
                        child,
                        Edge {
                            parent,
                            parent_from_child: pose,
                            sources,
                            conflict,
                        },
                    );
                }
                None => tracing::warn!("TF {parent} → {child}: not a rigid transform, skipped"),
            }
        }
    }

    /// The frames on the chains of the wanted frames, each up to the highest one heard.
    fn pinned(&self) -> std::collections::BTreeSet<String> {
        let mut pinned = std::collections::BTreeSet::new();
        for frame in &self.wanted {
            let mut at = frame.clone();
            // A loop ends the walk (at most one pass over the tree).
            while pinned.insert(at.clone()) {
                match self.edges.get(&at) {
                    Some(edge) => at.clone_from(&edge.parent),
                    None => break,
                }
            }
        }
        pinned
    }

    /// Whether `child`'s edge belongs to a wanted frame's chain: the frame itself, or the top
    /// of its chain so far (the next edge up).
    fn needs(&self, child: &str) -> bool {
        self.pinned().contains(child)
    }

    /// Makes room by dropping one frame no wanted chain goes through; false when there is none.
    fn drop_one_unneeded(&mut self) -> bool {
        let pinned = self.pinned();
        let Some(victim) = self.edges.keys().find(|k| !pinned.contains(*k)).cloned() else {
            return false;
        };
        self.edges.remove(&victim);
        true
    }

    fn known(&self, frame: &str) -> bool {
        self.edges.contains_key(frame) || self.edges.values().any(|e| e.parent == frame)
    }

    /// `(root, T_root_frame)`.
    fn root_and_pose(&self, frame: &str) -> Result<(String, Pose), String> {
        let mut pose = Pose::identity();
        let mut at = frame.to_string();
        for _ in 0..256 {
            match self.edges.get(&at) {
                Some(Edge {
                    conflict: Some(conflict),
                    ..
                }) => return Err(conflict.clone()),
                Some(edge) => {
                    pose = edge.parent_from_child * pose;
                    at = edge.parent.clone();
                }
                None => return Ok((at, pose)),
            }
        }
        Err(format!("the TF tree has a loop through {frame:?}"))
    }

    /// `T_a_b`, or why not (a frame unknown, the two in different trees), naming the frames
    /// the tree holds.
    pub fn lookup(&self, a: &str, b: &str) -> Result<Pose, String> {
        for frame in [a, b] {
            if !self.known(frame) {
                return Err(format!(
                    "frame {frame:?} is not in the TF tree; frames heard: {}",
                    self.frames().join(", ")
                ));
            }
        }
        let (root_a, root_from_a) = self.root_and_pose(a)?;
        let (root_b, root_from_b) = self.root_and_pose(b)?;
        if root_a != root_b {
            return Err(format!(
                "frames {a:?} and {b:?} are not connected in the TF tree ({a:?} hangs from {root_a:?}, {b:?} from {root_b:?})"
            ));
        }
        Ok(root_from_a.inverse() * root_from_b)
    }

    /// Why `frame`'s chain cannot be walked however long one waits (an edge on it whose
    /// publishers contradict each other, a loop), if it cannot: a missing frame may still come,
    /// these will not.
    pub fn broken_chain(&self, frame: &str) -> Option<String> {
        self.root_and_pose(frame).err()
    }

    /// Every edge heard: `(parent, child, T_parent_child)`, by child.
    pub fn edges(&self) -> Vec<(String, String, Pose)> {
        self.edges
            .iter()
            .map(|(child, e)| (e.parent.clone(), child.clone(), e.parent_from_child))
            .collect()
    }

    /// The parent `frame` hangs from, if any was heard.
    pub fn parent_of(&self, frame: &str) -> Option<&str> {
        self.edges.get(frame).map(|e| e.parent.as_str())
    }

    /// An edge on `frame`'s chain that two publishers gave different transforms within the
    /// last [`RECENT_SOURCES`], worded as a lookup through a contradicted edge fails: for a pose
    /// the lookup gave that something else contradicts (the joints' kinematics), when the
    /// driver's publisher went unheard a moment beside a faster second one.
    pub fn recent_disagreement(&self, frame: &str) -> Option<String> {
        let mut at = frame;
        for _ in 0..256 {
            let edge = self.edges.get(at)?;
            if let Some(found) = contradiction(&edge.parent, at, &edge.sources) {
                return Some(found);
            }
            at = &edge.parent;
        }
        None
    }

    /// Every frame heard, sorted.
    pub fn frames(&self) -> Vec<String> {
        let mut all: Vec<String> = self
            .edges
            .iter()
            .flat_map(|(child, e)| [child.clone(), e.parent.clone()])
            .collect();
        all.sort();
        all.dedup();
        all
    }
}

/// The message of an edge whose current publishers disagree, or `None`.
fn contradiction(parent: &str, child: &str, sources: &[(u64, Pose, Instant)]) -> Option<String> {
    let newest = sources.last()?;
    sources[..sources.len() - 1].iter().find_map(|other| {
        let mm = (other.1.translation.vector - newest.1.translation.vector).norm();
        let rad = other.1.rotation.angle_to(&newest.1.rotation);
        (mm > AT_REST_JITTER_M || rad > AT_REST_JITTER_RAD).then(|| {
            format!(
                "the TF edge {parent} → {child} has {} publishers that disagree by {:.1} mm and {:.1}° (another node publishes it too: a second robot_state_publisher, a static publisher left running?); stop all but the driver's",
                sources.len(),
                mm * 1e3,
                rad.to_degrees()
            )
        })
    })
}

/// The state the reader task keeps.
#[derive(Debug, Default)]
pub struct ArmState {
    /// The newest joint sample.
    pub joints: Option<JointSample>,
    /// The one before it.
    pub previous: Option<JointSample>,
    /// A `/joint_states` message that lacked a configured joint (the newest such problem).
    pub joints_problem: Option<String>,
    /// The TF tree.
    pub tf: TfTree,
    /// When the last `/tf` message arrived.
    pub tf_received: Option<Instant>,
}

/// [`ArmState`] behind a lock, with a condition variable readers wait on.
#[derive(Debug, Default)]
pub struct Shared {
    state: Mutex<ArmState>,
    changed: Condvar,
}

impl Shared {
    /// Empty, with a TF tree that keeps `frames` (the configured base and flange) and their
    /// chains however many other frames are heard.
    pub fn wanting(frames: &[&str]) -> Shared {
        Shared {
            state: Mutex::new(ArmState {
                tf: TfTree::wanting(frames),
                ..ArmState::default()
            }),
            changed: Condvar::new(),
        }
    }

    /// The state, locked.
    pub fn lock(&self) -> MutexGuard<'_, ArmState> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Applies `f` and wakes the waiters.
    pub fn update(&self, f: impl FnOnce(&mut ArmState)) {
        f(&mut self.lock());
        self.changed.notify_all();
    }

    /// Waits until `ready` holds or `deadline` passes; returns the guard and whether it held.
    pub fn wait_until(
        &self,
        deadline: Instant,
        mut ready: impl FnMut(&ArmState) -> bool,
    ) -> (MutexGuard<'_, ArmState>, bool) {
        let mut guard = self.lock();
        loop {
            if ready(&guard) {
                return (guard, true);
            }
            let now = Instant::now();
            if now >= deadline {
                return (guard, false);
            }
            let wait = (deadline - now).min(Duration::from_millis(100));
            guard = self
                .changed
                .wait_timeout(guard, wait)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }
}

/// The sample of `msg` in the order of `names`, or which name it lacks.
pub fn joint_sample(
    msg: &JointState,
    names: &[String],
    received: Instant,
) -> Result<JointSample, String> {
    if !(1..=MAX_JOINTS).contains(&names.len()) {
        return Err(format!(
            "the configured joint names: {}",
            JointCountError(names.len())
        ));
    }
    let mut positions = Joints::zeros(names.len());
    let mut velocities = positions;
    let mut has_velocity = msg.velocity.len() == msg.name.len();
    for (i, name) in names.iter().enumerate() {
        let Some(k) = msg.name.iter().position(|n| n == name) else {
            return Err(format!(
                "joint {name:?} is not in the message (it names {})",
                msg.name.join(", ")
            ));
        };
        positions[i] = *msg.position.get(k).ok_or_else(|| {
            format!(
                "joint {name:?} has no position ({} positions for {} names)",
                msg.position.len(),
                msg.name.len()
            )
        })?;
        match msg.velocity.get(k) {
            Some(v) if v.is_finite() => velocities[i] = *v,
            _ => has_velocity = false,
        }
    }
    if positions.iter().any(|p| !p.is_finite()) {
        return Err("a joint position is not finite".into());
    }
    Ok(JointSample {
        positions,
        velocities: has_velocity.then_some(velocities),
        stamp: msg.header.stamp.to_system(),
        received,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{Header, Transform, TransformStamped};
    use nalgebra::Vector3;

    fn edge(parent: &str, child: &str, pose: Pose) -> TransformStamped {
        TransformStamped {
            header: Header {
                frame_id: parent.into(),
                ..Header::default()
            },
            child_frame_id: child.into(),
            transform: Transform::from_pose(&pose),
        }
    }

    #[test]
    fn a_flood_of_new_frames_is_bounded_and_known_frames_still_update() {
        let mut tree = TfTree::default();
        tree.update(&TfMessage {
            transforms: vec![edge("base", "tool0", Pose::identity())],
        });
        let flood: Vec<_> = (0..2 * MAX_TF_FRAMES)
            .map(|i| edge("base", &format!("junk_{i}"), Pose::identity()))
            .collect();
        tree.update(&TfMessage { transforms: flood });
        assert_eq!(
            tree.frames().len(),
            MAX_TF_FRAMES + 1,
            "the frames plus `base`"
        );
        let moved = Pose::new(Vector3::new(0.0, 0.0, 0.4), Vector3::zeros());
        tree.update(&TfMessage {
            transforms: vec![edge("base", "tool0", moved)],
        });
        let got = tree.lookup("base", "tool0").unwrap();
        assert!((got.to_homogeneous() - moved.to_homogeneous()).norm() < 1e-12);
    }

    /// #40: a /tf flood of new frame names that fills the tree before the arm's chain is heard
    /// does not crowd the configured frames out: their chain (heard after the flood, child
    /// first as a driver may send it) is kept and composes.
    #[test]
    fn a_flood_before_the_chain_does_not_crowd_out_the_configured_frames() {
        let mut tree = TfTree::wanting(&["base", "/tool0"]);
        let flood: Vec<_> = (0..2 * MAX_TF_FRAMES)
            .map(|i| edge("world", &format!("junk_{i}"), Pose::identity()))
            .collect();
        tree.update(&TfMessage { transforms: flood });
        let shoulder = Pose::new(Vector3::new(0.0, 0.0, 0.18), Vector3::new(0.0, 0.0, 0.3));
        let wrist = Pose::new(Vector3::new(0.4, 0.1, 0.2), Vector3::new(0.2, 0.0, 0.1));
        let tool = Pose::new(Vector3::new(0.0, 0.0, 0.1), Vector3::new(0.0, 0.3, 0.0));
        tree.update(&TfMessage {
            transforms: vec![
                edge("wrist_3_link", "tool0", tool),
                edge("shoulder_link", "wrist_3_link", wrist),
                edge("base", "shoulder_link", shoulder),
                edge("world", "base", Pose::identity()),
            ],
        });
        let got = tree.lookup("base", "tool0").unwrap();
        let want = shoulder * wrist * tool;
        assert!((got.to_homogeneous() - want.to_homogeneous()).norm() < 1e-12);
        assert!(tree.edges.len() <= MAX_TF_FRAMES);
        // Without wanted frames the flood wins, as before (the bound holds).
        let mut plain = TfTree::default();
        plain.update(&TfMessage {
            transforms: (0..MAX_TF_FRAMES + 10)
                .map(|i| edge("world", &format!("junk_{i}"), Pose::identity()))
                .collect(),
        });
        plain.update(&TfMessage {
            transforms: vec![edge("world", "tool0", tool)],
        });
        assert!(plain.lookup("world", "tool0").is_err());
    }

    /// #40: two publishers of base → tool0 10 cm and 180° apart, while the arm stands: the
    /// lookup fails naming the edge and the disagreement; one publisher moving the edge, or a
    /// handover to another after a pause, is no contradiction to a lookup, though the handover
    /// is a recent disagreement for 10 s.
    #[test]
    fn two_publishers_of_one_edge_that_disagree_are_named() {
        let at_rest = Pose::new(Vector3::new(0.4, 0.1, 0.3), Vector3::zeros());
        let other = Pose::new(
            Vector3::new(0.5, 0.1, 0.3),
            Vector3::new(0.0, 0.0, std::f64::consts::PI),
        );
        let start = Instant::now();
        let ms = |t: u64| start + Duration::from_millis(t);
        let msg = |pose| TfMessage {
            transforms: vec![edge("base", "tool0", pose)],
        };
        let mut tree = TfTree::default();
        for k in 0..20 {
            tree.update_from(&msg(at_rest), 1, ms(8 * k));
            tree.update_from(&msg(other), 2, ms(8 * k + 5));
        }
        let e = tree.lookup("base", "tool0").unwrap_err();
        assert!(
            e.contains("base → tool0") && e.contains("2 publishers") && e.contains("100.0 mm"),
            "{e}"
        );
        assert_eq!(tree.broken_chain("tool0"), Some(e.clone()));
        assert_eq!(tree.broken_chain("base"), None);
        // One publisher moving the edge.
        let mut moving = TfTree::default();
        for k in 0..20 {
            let p = Pose::new(
                Vector3::new(0.4 + 0.01 * k as f64, 0.1, 0.3),
                Vector3::zeros(),
            );
            moving.update_from(&msg(p), 1, ms(8 * k));
        }
        assert!(moving.lookup("base", "tool0").is_ok());
        assert_eq!(moving.broken_chain("tool0"), None);
        // A restarted publisher (a new writer) after a pause of more than the window.
        let mut handover = TfTree::default();
        handover.update_from(&msg(at_rest), 1, ms(0));
        handover.update_from(&msg(other), 2, ms(1500));
        let got = handover.lookup("base", "tool0").unwrap();
        assert!((got.to_homogeneous() - other.to_homogeneous()).norm() < 1e-12);
        // ... which a pose the joints contradict may still blame (the driver's publisher unheard
        // for a moment beside a faster second one), within the last 10 s only.
        let recent = handover.recent_disagreement("tool0").unwrap();
        assert!(
            recent.contains("base → tool0 has 2 publishers that disagree by 100.0 mm"),
            "{recent}"
        );
        assert_eq!(moving.recent_disagreement("tool0"), None);
        let mut long_ago = TfTree::default();
        long_ago.update_from(&msg(at_rest), 1, ms(0));
        long_ago.update_from(&msg(other), 2, ms(11_000));
        assert_eq!(long_ago.recent_disagreement("tool0"), None);
    }

    /// Every DDS writer is a source: a thousand writers of one edge within the window keep at
    /// most [`MAX_SOURCES`] of them, and a disagreeing one among the newest is still seen.
    #[test]
    fn an_edge_remembers_a_bounded_number_of_publishers() {
        let at_rest = Pose::new(Vector3::new(0.4, 0.1, 0.3), Vector3::zeros());
        let msg = |pose| TfMessage {
            transforms: vec![edge("base", "tool0", pose)],
        };
        let now = Instant::now();
        let mut tree = TfTree::default();
        for writer in 0..1000 {
            tree.update_from(&msg(at_rest), writer, now);
        }
        assert_eq!(tree.edges["tool0"].sources.len(), MAX_SOURCES);
        assert!(tree.lookup("base", "tool0").is_ok());
        let away = Pose::new(Vector3::new(0.5, 0.1, 0.3), Vector3::zeros());
        tree.update_from(&msg(away), 5000, now);
        assert!(tree.lookup("base", "tool0").is_err());
    }

    #[test]
    fn a_chain_is_composed_and_missing_frames_are_named() {
        let world_base = Pose::new(Vector3::new(1.0, 0.0, 0.0), Vector3::new(0.0, 0.0, 0.5));
        let base_link = Pose::new(Vector3::new(0.0, 0.2, 0.1), Vector3::new(0.1, 0.0, 0.0));
        let link_tool = Pose::new(Vector3::new(0.0, 0.0, 0.3), Vector3::new(0.0, 0.2, 0.0));
        let mut tree = TfTree::default();
        tree.update(&TfMessage {
            transforms: vec![
                edge("world", "base", world_base),
                edge("base", "link", base_link),
                edge("/link", "tool0", link_tool),
            ],
        });
        let got = tree.lookup("base", "tool0").unwrap();
        let want = base_link * link_tool;
        assert!((got.to_homogeneous() - want.to_homogeneous()).norm() < 1e-12);
        let back = tree.lookup("tool0", "world").unwrap();
        let want = (world_base * base_link * link_tool).inverse();
        assert!((back.to_homogeneous() - want.to_homogeneous()).norm() < 1e-12);
        let e = tree.lookup("base", "flange").unwrap_err();
        assert!(
            e.contains("\"flange\" is not in the TF tree") && e.contains("tool0"),
            "{e}"
        );
        tree.update(&TfMessage {
            transforms: vec![edge("map", "camera", Pose::identity())],
        });
        let e = tree.lookup("base", "camera").unwrap_err();
        assert!(e.contains("not connected"), "{e}");
    }

    #[test]
    fn joint_states_are_ordered_by_name() {
        let names = ["a", "b", "c", "d", "e", "f"].map(String::from);
        let msg = JointState {
            name: ["f", "e", "d", "c", "b", "a"].map(String::from).to_vec(),
            position: vec![6.0, 5.0, 4.0, 3.0, 2.0, 1.0],
            ..JointState::default()
        };
        let s = joint_sample(&msg, &names, Instant::now()).unwrap();
        assert_eq!(s.positions, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert!(s.velocities.is_none());
        let short = JointState {
            name: vec!["a".into()],
            position: vec![0.0],
            ..JointState::default()
        };
        let e = joint_sample(&short, &names, Instant::now()).unwrap_err();
        assert!(e.contains("joint \"b\" is not in the message"), "{e}");
    }
}
