//! The TF tree of a bag: static transforms (`/tf_static`) and time series (`/tf`) per edge
//! `parent → child`, looked up at a stamp by chaining edges through their common root. A dynamic
//! edge is interpolated between the two samples around the stamp (lerp of the translation, slerp
//! of the rotation) and never extrapolated: a stamp outside an edge's samples, or between two
//! samples further apart than the allowed gap, is a TF gap.
//!
//! A bag can lie about its tree, and every lie is found and named ([`TfIssue`]): one child given
//! two different static transforms, a frame with two parents, parents that loop back, one edge
//! with two different transforms at one stamp, stamps that go back in time on an edge, one edge
//! both static and moving (the moving one is used, whichever came first).
//! [`TfBuffer::check`] refuses the ones that make `T_base_flange` ambiguous when they are on the
//! chain it is read from, and returns the others as warnings.
mod issue;
#[cfg(test)]
mod tests;

use std::collections::{BTreeMap, BTreeSet};

use handeye_core::geometry::Pose;

use handeye_ros2::cdr::CdrError;
use handeye_ros2::msg::TfMessage;

use issue::{apart, same};
pub use issue::{stamp_text, TfError, TfIssue, TfSource, TfWarning, AMBIGUOUS_DEG, AMBIGUOUS_MM};

/// One transform of a TF message as the buffer keeps it: `T_parent_child` at `stamp_ns`, the
/// frame ids without a leading `/` (tf2 ignores it, a ROS 1 habit).
#[derive(Debug, Clone, PartialEq)]
pub struct EdgeSample {
    /// Header stamp, ns.
    pub stamp_ns: i64,
    /// `header.frame_id` (the parent).
    pub parent: String,
    /// `child_frame_id`.
    pub child: String,
    /// Maps points in the child frame into the parent frame.
    pub parent_from_child: Pose,
}

/// The transforms of one `tf2_msgs/TFMessage` of a bag, or the first that is not a stamped rigid
/// transform: a `nanosec` of a second or more, a value not finite, a quaternion further than
/// 1e-3 from unit length (a bag's numbers are the publisher's, unrounded). Refused, not skipped:
/// the pose at a frame would silently come from other messages.
pub fn edge_samples(message: &TfMessage) -> Result<Vec<EdgeSample>, CdrError> {
    let strip = |frame: &str| frame.strip_prefix('/').unwrap_or(frame).to_string();
    let mut out = Vec::with_capacity(message.transforms.len());
    for (i, t) in message.transforms.iter().enumerate() {
        let field = |name: &str| format!("transforms[{i}].{name}");
        let stamp_ns = t.header.stamp.checked_ns(&field("header.stamp"))?;
        let (v, r) = (t.transform.translation, t.transform.rotation);
        let norm = (r.x * r.x + r.y * r.y + r.z * r.z + r.w * r.w).sqrt();
        let pose = t
            .transform
            .to_pose()
            .filter(|_| (norm - 1.0).abs() < 1e-3)
            .ok_or_else(|| CdrError::Field {
                field: field("transform"),
                problem: format!(
                    "translation {:?}, rotation (x, y, z, w) {:?}: not finite or not a unit quaternion",
                    [v.x, v.y, v.z],
                    [r.x, r.y, r.z, r.w]
                ),
            })?;
        out.push(EdgeSample {
            stamp_ns,
            parent: strip(&t.header.frame_id),
            child: strip(&t.child_frame_id),
            parent_from_child: pose,
        });
    }
    Ok(out)
}

/// An edge's transforms, with its first message.
#[derive(Debug, Clone)]
enum Edge {
    Static(Pose, TfSource),
    Dynamic(Vec<(i64, Pose)>, TfSource),
}

/// Steps back in time on one edge of one topic.
#[derive(Debug, Clone)]
struct BackSteps {
    last_ns: i64,
    count: usize,
    largest: Option<(i64, TfSource, i64, i64)>,
}

/// The TF tree of a bag.
#[derive(Debug, Clone, Default)]
pub struct TfBuffer {
    /// child → (parent, transforms `parent_from_child`, the topic of its first transform).
    edges: BTreeMap<String, (String, Edge, String)>,
    /// The largest allowed spacing of two dynamic samples to interpolate between, ns.
    max_gap_ns: Option<i64>,
    /// child → every distinct parent given, with its first message.
    parents: BTreeMap<String, Vec<(String, TfSource)>>,
    /// child → its [`TfIssue::StaticConflict`].
    static_conflicts: BTreeMap<String, TfIssue>,
    /// child → its [`TfIssue::StaticAndMoving`].
    static_and_moving: BTreeMap<String, TfIssue>,
    /// (topic, parent, child) → stamps going back.
    back: BTreeMap<(String, String, String), BackSteps>,
    /// Conflicting samples found by [`TfBuffer::finish`].
    conflicts: Vec<TfIssue>,
}

impl TfBuffer {
    /// Adds one transform (from `/tf_static` when `is_static`), read from `source`.
    pub fn add(&mut self, t: EdgeSample, is_static: bool, source: TfSource) {
        let parents = self.parents.entry(t.child.clone()).or_default();
        if !parents.iter().any(|(p, _)| *p == t.parent) {
            parents.push((t.parent.clone(), source.clone()));
        }
        if !is_static {
            let key = (source.topic.clone(), t.parent.clone(), t.child.clone());
            match self.back.get_mut(&key) {
                None => {
                    self.back.insert(
                        key,
                        BackSteps {
                            last_ns: t.stamp_ns,
                            count: 0,
                            largest: None,
                        },
                    );
                }
                Some(b) => {
                    if t.stamp_ns < b.last_ns {
                        b.count += 1;
                        let step = b.last_ns - t.stamp_ns;
                        if b.largest.as_ref().is_none_or(|l| step > l.0) {
                            b.largest = Some((step, source.clone(), b.last_ns, t.stamp_ns));
                        }
                    }
                    b.last_ns = t.stamp_ns;
                }
            }
        }
        let sample = (t.stamp_ns, t.parent_from_child);
        match self.edges.get_mut(&t.child) {
            // One more sample of a known dynamic edge.
            Some((parent, Edge::Dynamic(samples, _), _)) if *parent == t.parent && !is_static => {
                samples.push(sample);
            }
            // The same static edge again: a republished value, or a conflicting one (recorded;
            // the latest wins, as in tf2).
            Some((parent, Edge::Static(value, first), _)) if *parent == t.parent && is_static => {
                if !same(value, &t.parent_from_child) {
                    match self.static_conflicts.get_mut(&t.child) {
                        Some(TfIssue::StaticConflict { more, .. }) => *more += 1,
                        _ => {
                            self.static_conflicts.insert(
                                t.child.clone(),
                                TfIssue::StaticConflict {
                                    parent: t.parent.clone(),
                                    child: t.child.clone(),
                                    first: (*value, first.clone()),
                                    second: (t.parent_from_child, source.clone()),
                                    more: 0,
                                },
                            );
                        }
                    }
                    *value = t.parent_from_child;
                    *first = source;
                }
            }
            // A static value of an edge that moves (the same parent): the moving one is kept,
            // the static one named.
            Some((parent, Edge::Dynamic(_, first), _)) if *parent == t.parent && is_static => {
                let moving = first.clone();
                self.note_static_and_moving(&t, source, moving);
            }
            // A moving edge that had a static value: the moving one replaces it, named.
            Some((parent, Edge::Static(_, first), _)) if *parent == t.parent && !is_static => {
                let statics = first.clone();
                self.note_static_and_moving(&t, statics, source.clone());
                let topic = source.topic.clone();
                let edge = Edge::Dynamic(vec![sample], source);
                self.edges.insert(t.child, (t.parent, edge, topic));
            }
            // A new child, or a child re-parented (the latest parent wins, as in tf2; recorded
            // as two parents): the edge starts again.
            _ => {
                let topic = source.topic.clone();
                let edge = if is_static {
                    Edge::Static(t.parent_from_child, source)
                } else {
                    Edge::Dynamic(vec![sample], source)
                };
                self.edges.insert(t.child, (t.parent, edge, topic));
            }
        }
    }

    /// Notes (once per edge: the first static and moving messages) that `t`'s edge is given
    /// both a static value, at `statics`, and moving ones, from `moving`.
    fn note_static_and_moving(&mut self, t: &EdgeSample, statics: TfSource, moving: TfSource) {
        self.static_and_moving
            .entry(t.child.clone())
            .or_insert_with(|| TfIssue::StaticAndMoving {
                parent: t.parent.clone(),
                child: t.child.clone(),
                statics,
                moving,
            });
    }

    /// Sorts the samples and notes the stamps given two different transforms (the first value of
    /// a stamp is kept); call once after the last [`TfBuffer::add`].
    pub fn finish(&mut self) {
        self.conflicts.clear();
        for (child, (parent, edge, topic)) in self.edges.iter_mut() {
            let Edge::Dynamic(samples, _) = edge else {
                continue;
            };
            // Stable: the first value received for a stamp stays first.
            samples.sort_by_key(|s| s.0);
            let mut count = 0;
            let mut worst: Option<(f64, f64, i64, Pose, Pose)> = None;
            for run in samples.chunk_by(|x, y| x.0 == y.0) {
                let first = run[0].1;
                let mut differs = false;
                for (_, other) in &run[1..] {
                    if same(&first, other) {
                        continue;
                    }
                    differs = true;
                    let (mm, deg) = apart(&first, other);
                    let score = mm / AMBIGUOUS_MM + deg / AMBIGUOUS_DEG;
                    if worst
                        .as_ref()
                        .is_none_or(|w| score > w.0 / AMBIGUOUS_MM + w.1 / AMBIGUOUS_DEG)
                    {
                        worst = Some((mm, deg, run[0].0, first, *other));
                    }
                }
                count += usize::from(differs);
            }
            samples.dedup_by_key(|s| s.0);
            if let Some((largest_mm, largest_deg, stamp_ns, a, b)) = worst {
                self.conflicts.push(TfIssue::ConflictingSamples {
                    topic: topic.clone(),
                    parent: parent.clone(),
                    child: child.clone(),
                    count,
                    stamp_ns,
                    values: (a, b),
                    largest_mm,
                    largest_deg,
                });
            }
        }
    }

    /// Refuses to interpolate across samples more than `gap_ns` apart.
    pub fn set_max_gap_ns(&mut self, gap_ns: i64) {
        self.max_gap_ns = Some(gap_ns);
    }

    /// Every frame any transform named (also one whose only edge was re-parented away).
    fn known(&self) -> Vec<String> {
        let mut all = BTreeSet::new();
        for (child, parents) in &self.parents {
            all.insert(child.clone());
            all.extend(parents.iter().map(|(p, _)| p.clone()));
        }
        all.into_iter().collect()
    }

    /// The edges from `frame` up to its root (child names); a loop ends at its first repeat.
    fn path_to_root(&self, frame: &str) -> Result<Vec<String>, TfError> {
        let seen = |f: &str| {
            self.parents
                .iter()
                .any(|(child, parents)| child == f || parents.iter().any(|(p, _)| p == f))
        };
        if !self.edges.contains_key(frame) && !seen(frame) {
            return Err(TfError::UnknownFrame {
                frame: frame.to_string(),
                known: self.known(),
            });
        }
        let mut path = Vec::new();
        let mut at = frame.to_string();
        while let Some((parent, _, _)) = self.edges.get(&at) {
            if path.contains(&at) {
                break;
            }
            path.push(at.clone());
            at = parent.clone();
        }
        Ok(path)
    }

    fn root_of(&self, path: &[String], frame: &str) -> String {
        path.last()
            .and_then(|c| self.edges.get(c))
            .map(|(p, _, _)| p.clone())
            .unwrap_or_else(|| frame.to_string())
    }

    /// Every contradiction in the TF data (call after [`TfBuffer::finish`]): loops, frames with
    /// two parents, conflicting static values, conflicting samples at one stamp, stamps going
    /// back; in that order.
    pub fn issues(&self) -> Vec<TfIssue> {
        let mut issues = Vec::new();
        // Loops of the current parent links: follow each frame up until a root or a frame seen.
        let mut done: BTreeSet<&str> = BTreeSet::new();
        for start in self.edges.keys() {
            let mut walk: Vec<&str> = Vec::new();
            let mut at = start.as_str();
            while !done.contains(at) {
                if let Some(i) = walk.iter().position(|f| *f == at) {
                    // Walked child to parent; named parent to child, as every edge is.
                    let mut frames: Vec<String> =
                        walk[i..].iter().rev().map(|f| f.to_string()).collect();
                    // Start the loop at its smallest name, so it reads the same from anywhere.
                    let min = (0..frames.len()).min_by_key(|&k| &frames[k]).unwrap_or(0);
                    frames.rotate_left(min);
                    issues.push(TfIssue::Loop { frames });
                    break;
                }
                walk.push(at);
                match self.edges.get(at) {
                    Some((parent, _, _)) => at = parent.as_str(),
                    None => break,
                }
            }
            done.extend(walk);
        }
        for (child, parents) in &self.parents {
            if let [first, second, ..] = parents.as_slice() {
                issues.push(TfIssue::TwoParents {
                    child: child.clone(),
                    first: first.clone(),
                    second: second.clone(),
                });
            }
        }
        issues.extend(self.static_conflicts.values().cloned());
        issues.extend(self.static_and_moving.values().cloned());
        issues.extend(self.conflicts.iter().cloned());
        for ((topic, parent, child), b) in &self.back {
            if let Some((largest_ns, at, from_ns, to_ns)) = &b.largest {
                issues.push(TfIssue::StampsBack {
                    topic: topic.clone(),
                    parent: parent.clone(),
                    child: child.clone(),
                    count: b.count,
                    largest_ns: *largest_ns,
                    at: at.clone(),
                    from_ns: *from_ns,
                    to_ns: *to_ns,
                });
            }
        }
        issues
    }

    /// Checks that both frames exist and are connected (at no particular time).
    pub fn check_chain(&self, target: &str, source: &str) -> Result<(), TfError> {
        self.connected_paths(target, source).map(|_| ())
    }

    /// Checks the chain `target` → `source` before any lookup: both frames exist, no
    /// [`TfIssue`] on the chain makes the pose ambiguous (a loop, two parents, two static
    /// values, two transforms at one stamp further apart than [`AMBIGUOUS_MM`] /
    /// [`AMBIGUOUS_DEG`], a stamp going back by more than `max_back_ns`), and the frames are
    /// connected. Returns the other issues as warnings. A loop or a second parent is reported
    /// as such, not as frames that are not connected.
    pub fn check(
        &self,
        target: &str,
        source: &str,
        max_back_ns: i64,
    ) -> Result<Vec<TfWarning>, TfError> {
        let a = self.path_to_root(target)?;
        let b = self.path_to_root(source)?;
        let chain: BTreeSet<&str> = a.iter().chain(&b).map(String::as_str).collect();
        let mut warnings = Vec::new();
        for issue in self.issues() {
            let on_chain = issue.frames().iter().any(|f| chain.contains(f));
            if on_chain && issue.ambiguous(max_back_ns) {
                return Err(TfError::Inconsistent {
                    from: target.into(),
                    to: source.into(),
                    issue: Box::new(issue),
                });
            }
            warnings.push(TfWarning {
                issue,
                on_chain,
                chain: (target.into(), source.into()),
            });
        }
        self.connected_paths(target, source)?;
        Ok(warnings)
    }

    /// The paths from `target` and from `source` up to their root, checked to end at the same
    /// root.
    fn connected_paths(
        &self,
        target: &str,
        source: &str,
    ) -> Result<(Vec<String>, Vec<String>), TfError> {
        let a = self.path_to_root(target)?;
        let b = self.path_to_root(source)?;
        let (ra, rb) = (self.root_of(&a, target), self.root_of(&b, source));
        if ra != rb {
            return Err(TfError::NotConnected {
                from: target.into(),
                from_root: ra,
                to: source.into(),
                to_root: rb,
            });
        }
        Ok((a, b))
    }

    /// `target_from_source` at `stamp_ns` (e.g. `T_base_flange` for `("base", "tool0")`).
    pub fn lookup(&self, target: &str, source: &str, stamp_ns: i64) -> Result<Pose, TfError> {
        let (a, b) = self.connected_paths(target, source)?;
        // Drop the common part above the lowest common ancestor.
        let common = a
            .iter()
            .rev()
            .zip(b.iter().rev())
            .take_while(|(x, y)| x == y)
            .count();
        let root_from = |path: &[String]| -> Result<Pose, TfError> {
            let mut pose = Pose::identity();
            for child in path.iter().rev() {
                pose *= self.edge_at(child, stamp_ns)?;
            }
            Ok(pose)
        };
        let ancestor_from_target = root_from(&a[..a.len() - common])?;
        let ancestor_from_source = root_from(&b[..b.len() - common])?;
        Ok(ancestor_from_target.inverse() * ancestor_from_source)
    }

    fn edge_at(&self, child: &str, stamp_ns: i64) -> Result<Pose, TfError> {
        let Some((parent, edge, _)) = self.edges.get(child) else {
            return Ok(Pose::identity());
        };
        let samples = match edge {
            Edge::Static(p, _) => return Ok(*p),
            Edge::Dynamic(samples, _) => samples,
        };
        let gap = |side, nearest: String| TfError::Gap {
            parent: parent.clone(),
            child: child.to_string(),
            stamp_s: stamp_ns as f64 * 1e-9,
            side,
            nearest,
        };
        let after = samples.partition_point(|s| s.0 < stamp_ns);
        if let Some(s) = samples.get(after).filter(|s| s.0 == stamp_ns) {
            return Ok(s.1);
        }
        if after == 0 {
            return Err(gap(
                "before",
                samples
                    .first()
                    .map_or("none".into(), |s| format!("{:.6} s", s.0 as f64 * 1e-9)),
            ));
        }
        if after == samples.len() {
            return Err(gap(
                "after",
                format!("{:.6} s", samples[after - 1].0 as f64 * 1e-9),
            ));
        }
        let (t0, p0) = samples[after - 1];
        let (t1, p1) = samples[after];
        if self.max_gap_ns.is_some_and(|g| t1 - t0 > g) {
            return Err(gap(
                "within the allowed gap of",
                format!(
                    "{:.6} s and {:.6} s, {:.1} ms apart",
                    t0 as f64 * 1e-9,
                    t1 as f64 * 1e-9,
                    (t1 - t0) as f64 * 1e-6
                ),
            ));
        }
        let s = (stamp_ns - t0) as f64 / (t1 - t0) as f64;
        Ok(interpolate(&p0, &p1, s))
    }
}

/// `a` at `s = 0`, `b` at `s = 1`: translation lerp, rotation slerp.
pub fn interpolate(a: &Pose, b: &Pose, s: f64) -> Pose {
    let translation = a.translation.vector.lerp(&b.translation.vector, s);
    let rotation = a
        .rotation
        .try_slerp(&b.rotation, s, 1e-12)
        .unwrap_or(if s < 0.5 { a.rotation } else { b.rotation });
    Pose::from_parts(translation.into(), rotation)
}
