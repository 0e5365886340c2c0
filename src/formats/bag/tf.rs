//! The TF tree of a bag: static transforms (`/tf_static`) and time series (`/tf`) per edge
//! `parent → child`, looked up at a stamp by chaining edges through their common root. A dynamic
//! edge is interpolated between the two samples around the stamp (lerp of the translation, slerp
//! of the rotation) and never extrapolated: a stamp outside an edge's samples, or between two
//! samples further apart than the allowed gap, is a TF gap.
//!
//! A bag can lie about its tree, and every lie is found and named ([`TfIssue`]): one child given
//! two different static transforms, a frame with two parents, parents that loop back, one edge
//! with two different transforms at one stamp, stamps that go back in time on an edge.
//! [`TfBuffer::check`] refuses the ones that make `T_base_flange` ambiguous when they are on the
//! chain it is read from, and returns the others as warnings.

use std::collections::{BTreeMap, BTreeSet};

use crate::geometry::Pose;

use super::cdr::TransformStamped;

/// Two transforms closer than this (m, rad) are the same value (a republished static, a
/// duplicated message): the float round trips of a writer stay orders of magnitude below.
const SAME_M: f64 = 1e-6;
/// See [`SAME_M`].
const SAME_RAD: f64 = 1e-6;
/// Two transforms of one edge at one stamp further apart than this make the pose ambiguous (two
/// publishers on one edge): 0.1 mm is a UR's repeatability, 0.01° well below what a calibration
/// resolves. Closer values pick the same pose for a calibration's purposes, so they are only a
/// warning.
pub const AMBIGUOUS_MM: f64 = 0.1;
/// See [`AMBIGUOUS_MM`], degrees.
pub const AMBIGUOUS_DEG: f64 = 0.01;

/// Where a transform came from: its topic and the message's 0-based index on that topic.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct TfSource {
    /// `/tf`, `/tf_static`.
    pub topic: String,
    /// 0-based index among the topic's messages, in receive order.
    pub index: usize,
}

impl std::fmt::Display for TfSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "`{}` message {}", self.topic, self.index)
    }
}

/// A stamp as ROS writes it, exactly (`sec.nanosec s`).
pub fn stamp_text(ns: i64) -> String {
    format!(
        "{}.{:09} s",
        ns.div_euclid(1_000_000_000),
        ns.rem_euclid(1_000_000_000)
    )
}

fn pose_text(p: &Pose) -> String {
    let t = p.translation.vector;
    let q = p.rotation.coords;
    format!(
        "translation [{:.6}, {:.6}, {:.6}] m, rotation (x, y, z, w) [{:.6}, {:.6}, {:.6}, {:.6}]",
        t.x, t.y, t.z, q.x, q.y, q.z, q.w
    )
}

/// How far apart two transforms are: mm, degrees.
fn apart(a: &Pose, b: &Pose) -> (f64, f64) {
    (
        (a.translation.vector - b.translation.vector).norm() * 1e3,
        a.rotation.angle_to(&b.rotation).to_degrees(),
    )
}

fn same(a: &Pose, b: &Pose) -> bool {
    (a.translation.vector - b.translation.vector).norm() <= SAME_M
        && a.rotation.angle_to(&b.rotation) <= SAME_RAD
}

/// Something a bag's TF data says that a TF tree cannot mean.
#[derive(Debug, Clone, PartialEq)]
pub enum TfIssue {
    /// One child given two different static transforms (the later one replaced the first, as in
    /// tf2, silently moving every frame below it).
    StaticConflict {
        /// The parent.
        parent: String,
        /// The child.
        child: String,
        /// The first value and where it came from.
        first: (Pose, TfSource),
        /// The first value that differs from it.
        second: (Pose, TfSource),
        /// Further differing values after those two.
        more: usize,
    },
    /// A frame given two parents (tf2 keeps the latest, so the tree changes shape mid-bag).
    TwoParents {
        /// The frame.
        child: String,
        /// The first parent and where it came from.
        first: (String, TfSource),
        /// The second parent and where it came from.
        second: (String, TfSource),
    },
    /// Parents that lead back to a frame: `frames[0]` is the parent of `frames[1]`, ..., the
    /// last one the parent of `frames[0]`.
    Loop {
        /// The frames of the loop.
        frames: Vec<String>,
    },
    /// One dynamic edge with different transforms at one stamp.
    ConflictingSamples {
        /// The topic of the edge's first transform.
        topic: String,
        /// The parent.
        parent: String,
        /// The child.
        child: String,
        /// Stamps with more than one value.
        count: usize,
        /// The stamp of the furthest-apart pair.
        stamp_ns: i64,
        /// Its two values.
        values: (Pose, Pose),
        /// How far apart they are, mm.
        largest_mm: f64,
        /// How far apart they are, degrees.
        largest_deg: f64,
    },
    /// Stamps that go back in time on one edge of one topic (receive order).
    StampsBack {
        /// The topic.
        topic: String,
        /// The parent.
        parent: String,
        /// The child.
        child: String,
        /// How many times a stamp was earlier than the one before it.
        count: usize,
        /// The largest step back, ns.
        largest_ns: i64,
        /// The message of the largest step back.
        at: TfSource,
        /// The stamp before it, ns.
        from_ns: i64,
        /// Its stamp, ns.
        to_ns: i64,
    },
}

impl TfIssue {
    /// The child frames the issue is about (an edge is named by its child).
    pub fn frames(&self) -> Vec<&str> {
        match self {
            TfIssue::Loop { frames } => frames.iter().map(String::as_str).collect(),
            TfIssue::StaticConflict { child, .. }
            | TfIssue::TwoParents { child, .. }
            | TfIssue::ConflictingSamples { child, .. }
            | TfIssue::StampsBack { child, .. } => vec![child.as_str()],
        }
    }

    /// A short name for counting and tests (`static conflict`, `two parents`, ...).
    pub fn kind(&self) -> &'static str {
        match self {
            TfIssue::StaticConflict { .. } => "static conflict",
            TfIssue::TwoParents { .. } => "two parents",
            TfIssue::Loop { .. } => "loop",
            TfIssue::ConflictingSamples { .. } => "conflicting transforms at one stamp",
            TfIssue::StampsBack { .. } => "stamps going back",
        }
    }

    /// Whether, on the chain looked up, it makes the pose ambiguous (`max_back_ns`: the largest
    /// step back in time still taken for delivery jitter).
    fn ambiguous(&self, max_back_ns: i64) -> bool {
        match self {
            TfIssue::StaticConflict { .. } | TfIssue::TwoParents { .. } | TfIssue::Loop { .. } => {
                true
            }
            TfIssue::ConflictingSamples {
                largest_mm,
                largest_deg,
                ..
            } => *largest_mm > AMBIGUOUS_MM || *largest_deg > AMBIGUOUS_DEG,
            // Samples are sorted by stamp, so a small step back (two publishers, delivery
            // jitter) changes nothing. A step back by more than the TF gap allowed is a clock
            // that went back (a restarted simulation, a looped playback): one stamp then names
            // two moments and the interpolation mixes them.
            TfIssue::StampsBack { largest_ns, .. } => *largest_ns > max_back_ns,
        }
    }
}

impl std::fmt::Display for TfIssue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TfIssue::StaticConflict {
                parent,
                child,
                first,
                second,
                more,
            } => {
                let (mm, deg) = apart(&first.0, &second.0);
                write!(
                    f,
                    "static transform `{parent}` → `{child}` given two values: {} has {}, {} has {} ({mm:.3} mm and {deg:.4}° apart{}); expected one value per static transform",
                    first.1,
                    pose_text(&first.0),
                    second.1,
                    pose_text(&second.0),
                    if *more > 0 {
                        format!("; {more} more differing values follow")
                    } else {
                        String::new()
                    }
                )
            }
            TfIssue::TwoParents {
                child,
                first,
                second,
            } => write!(
                f,
                "frame `{child}` has two parents: `{}` ({}) and `{}` ({}); expected one parent per frame (a tree)",
                first.0, first.1, second.0, second.1
            ),
            TfIssue::Loop { frames } => {
                let mut chain: Vec<String> = frames.iter().map(|f| format!("`{f}`")).collect();
                chain.push(format!("`{}`", frames[0]));
                write!(
                    f,
                    "TF loop: {} (each frame the parent of the next); expected a tree without loops",
                    chain.join(" → ")
                )
            }
            TfIssue::ConflictingSamples {
                topic,
                parent,
                child,
                count,
                stamp_ns,
                values,
                largest_mm,
                largest_deg,
            } => write!(
                f,
                "`{topic}`: `{parent}` → `{child}` has {count} stamp(s) with two different transforms (two publishers on one edge?); furthest apart at {}: {} and {} ({largest_mm:.3} mm, {largest_deg:.4}°); expected one transform per stamp",
                stamp_text(*stamp_ns),
                pose_text(&values.0),
                pose_text(&values.1)
            ),
            TfIssue::StampsBack {
                topic,
                parent,
                child,
                count,
                largest_ns,
                at,
                from_ns,
                to_ns,
            } => write!(
                f,
                "`{topic}`: stamps of `{parent}` → `{child}` go back in time {count} time(s), by up to {:.3} ms ({at} is stamped {} after {}); expected stamps that only increase",
                *largest_ns as f64 * 1e-6,
                stamp_text(*to_ns),
                stamp_text(*from_ns)
            ),
        }
    }
}

/// A [`TfIssue`] that does not make the pose ambiguous, reported as a warning.
#[derive(Debug, Clone, PartialEq)]
pub struct TfWarning {
    /// What is wrong.
    pub issue: TfIssue,
    /// Whether it is on the chain looked up (else the poses do not use it).
    pub on_chain: bool,
    /// The chain's frames (`base` → `tool0`).
    pub chain: (String, String),
}

impl std::fmt::Display for TfWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (from, to) = &self.chain;
        if self.on_chain {
            write!(f, "{} (on the chain `{from}` → `{to}`", self.issue)?;
            match &self.issue {
                TfIssue::ConflictingSamples { .. } => write!(
                    f,
                    ", but at most {AMBIGUOUS_MM} mm and {AMBIGUOUS_DEG}° apart; the first value of each stamp is used)"
                ),
                _ => f.write_str(", but within the allowed TF gap: the samples are used in stamp order)"),
            }
        } else {
            write!(
                f,
                "{} (not on the chain `{from}` → `{to}`, so the poses do not use it)",
                self.issue
            )
        }
    }
}

/// Why a transform cannot be looked up.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TfError {
    /// A frame appears nowhere in the TF messages.
    #[error("frame `{frame}` is not in the TF tree (frames present: {})", known.join(", "))]
    UnknownFrame {
        /// The missing frame.
        frame: String,
        /// The frames that are there.
        known: Vec<String>,
    },
    /// The two frames are in separate trees.
    #[error("frames `{from}` (tree root `{from_root}`) and `{to}` (tree root `{to_root}`) are not connected: a transform between the two trees is missing")]
    NotConnected {
        /// The first frame.
        from: String,
        /// Its root.
        from_root: String,
        /// The second frame.
        to: String,
        /// Its root.
        to_root: String,
    },
    /// The TF data on the chain contradicts itself, so the pose would be ambiguous.
    #[error("{issue}; it is on the chain `{from}` → `{to}`, so T_{from}_{to} would be ambiguous")]
    Inconsistent {
        /// The chain's first frame.
        from: String,
        /// The chain's last frame.
        to: String,
        /// What is wrong.
        issue: Box<TfIssue>,
    },
    /// An edge has no sample close enough to the stamp on one side.
    #[error(
        "TF gap: `{parent}` → `{child}` has no transform {side} {stamp_s:.6} s (nearest {nearest})"
    )]
    Gap {
        /// The edge's parent.
        parent: String,
        /// The edge's child.
        child: String,
        /// The stamp looked up, s.
        stamp_s: f64,
        /// `before`/`after`/`within the allowed gap of`.
        side: &'static str,
        /// The nearest sample, described.
        nearest: String,
    },
}

#[derive(Debug, Clone)]
enum Edge {
    Static(Pose, TfSource),
    Dynamic(Vec<(i64, Pose)>),
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
    /// (topic, parent, child) → stamps going back.
    back: BTreeMap<(String, String, String), BackSteps>,
    /// Conflicting samples found by [`TfBuffer::finish`].
    conflicts: Vec<TfIssue>,
}

impl TfBuffer {
    /// Adds one transform (from `/tf_static` when `is_static`), read from `source`.
    pub fn add(&mut self, t: TransformStamped, is_static: bool, source: TfSource) {
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
            Some((parent, Edge::Dynamic(samples), _)) if *parent == t.parent && !is_static => {
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
            // A new child, a child re-parented (the latest parent wins, as in tf2; recorded as
            // two parents) or turned static or dynamic: the edge starts again.
            _ => {
                let topic = source.topic.clone();
                let edge = if is_static {
                    Edge::Static(t.parent_from_child, source)
                } else {
                    Edge::Dynamic(vec![sample])
                };
                self.edges.insert(t.child, (t.parent, edge, topic));
            }
        }
    }

    /// Sorts the samples and notes the stamps given two different transforms (the first value of
    /// a stamp is kept); call once after the last [`TfBuffer::add`].
    pub fn finish(&mut self) {
        self.conflicts.clear();
        for (child, (parent, edge, topic)) in self.edges.iter_mut() {
            let Edge::Dynamic(samples) = edge else {
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
            Edge::Dynamic(samples) => samples,
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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{UnitQuaternion, Vector3};

    fn pose(t: [f64; 3], angle_z: f64) -> Pose {
        Pose::from_parts(
            Vector3::from(t).into(),
            UnitQuaternion::from_euler_angles(0.0, 0.0, angle_z),
        )
    }

    fn stamped(stamp_ns: i64, parent: &str, child: &str, p: Pose) -> TransformStamped {
        TransformStamped {
            stamp_ns,
            parent: parent.into(),
            child: child.into(),
            parent_from_child: p,
        }
    }

    #[test]
    fn chains_interpolates_and_refuses_to_extrapolate() {
        let mut tf = TfBuffer::default();
        // world -> base static; base -> tool0 moving; world -> camera static.
        tf.add(
            stamped(0, "world", "base", pose([1.0, 0.0, 0.0], 0.0)),
            true,
            TfSource::default(),
        );
        tf.add(
            stamped(0, "world", "camera", pose([0.0, 2.0, 0.0], 0.5)),
            true,
            TfSource::default(),
        );
        tf.add(
            stamped(1_000_000_000, "base", "tool0", pose([0.0, 0.0, 0.0], 0.0)),
            false,
            TfSource::default(),
        );
        tf.add(
            stamped(3_000_000_000, "base", "tool0", pose([0.2, 0.0, 0.0], 0.4)),
            false,
            TfSource::default(),
        );
        tf.finish();
        let mid = tf.lookup("base", "tool0", 2_000_000_000).unwrap();
        assert!((mid.translation.vector - Vector3::new(0.1, 0.0, 0.0)).norm() < 1e-12);
        assert!((mid.rotation.angle() - 0.2).abs() < 1e-12);
        // Across the tree: camera_from_tool0 = (world_from_camera)^-1 world_from_base base_from_tool0.
        let expected = pose([0.0, 2.0, 0.0], 0.5).inverse() * pose([1.0, 0.0, 0.0], 0.0) * mid;
        let got = tf.lookup("camera", "tool0", 2_000_000_000).unwrap();
        assert!((got.to_homogeneous() - expected.to_homogeneous()).norm() < 1e-12);
        assert!(matches!(
            tf.lookup("base", "tool0", 3_000_000_001),
            Err(TfError::Gap { side: "after", .. })
        ));
        assert!(matches!(
            tf.lookup("base", "tool0", 999_999_999),
            Err(TfError::Gap { side: "before", .. })
        ));
        tf.set_max_gap_ns(1_000_000_000);
        let e = tf
            .lookup("base", "tool0", 2_000_000_000)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("base") && e.contains("tool0") && e.contains("2000.0 ms"),
            "{e}"
        );
    }

    #[test]
    fn missing_and_unconnected_frames_are_named() {
        let mut tf = TfBuffer::default();
        tf.add(
            stamped(0, "base", "shoulder", pose([0.0; 3], 0.0)),
            false,
            TfSource::default(),
        );
        tf.add(
            stamped(0, "flange", "tool0", pose([0.0; 3], 0.0)),
            true,
            TfSource::default(),
        );
        tf.finish();
        let e = tf.check_chain("base", "wrist_3").unwrap_err().to_string();
        assert!(e.contains("`wrist_3`") && e.contains("shoulder"), "{e}");
        let e = tf.check_chain("base", "tool0").unwrap_err().to_string();
        assert!(e.contains("not connected") && e.contains("flange"), "{e}");
    }

    fn from(topic: &str, index: usize) -> TfSource {
        TfSource {
            topic: topic.into(),
            index,
        }
    }

    /// base → wrist (moving, 0..=10 s at 1 Hz) → tool0 (static).
    fn arm() -> TfBuffer {
        let mut tf = TfBuffer::default();
        tf.add(
            stamped(0, "wrist", "tool0", pose([0.0, 0.0, 0.1], 0.0)),
            true,
            from("/tf_static", 0),
        );
        for k in 0..=10 {
            tf.add(
                stamped(
                    k * 1_000_000_000,
                    "base",
                    "wrist",
                    pose([0.5, 0.0, 0.0], 0.0),
                ),
                false,
                from("/tf", k as usize),
            );
        }
        tf
    }

    #[test]
    fn a_second_static_value_on_the_chain_is_refused_with_both_values() {
        let mut tf = arm();
        // Republishing the same value is normal.
        tf.add(
            stamped(5, "wrist", "tool0", pose([0.0, 0.0, 0.1], 0.0)),
            true,
            from("/tf_static", 1),
        );
        tf.finish();
        assert_eq!(tf.check("base", "tool0", 100_000_000).unwrap(), vec![]);
        tf.add(
            stamped(5, "wrist", "tool0", pose([0.0, 0.0, 0.2], 0.0)),
            true,
            from("/tf_static", 2),
        );
        tf.finish();
        let e = tf
            .check("base", "tool0", 100_000_000)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`wrist` → `tool0`")
                && e.contains("`/tf_static` message 0")
                && e.contains("`/tf_static` message 2")
                && e.contains("0.100000")
                && e.contains("0.200000")
                && e.contains("100.000 mm"),
            "{e}"
        );
        // Off the chain it is a warning.
        let mut tf = arm();
        for (i, z) in [0.1, 0.3].into_iter().enumerate() {
            tf.add(
                stamped(0, "base", "camera", pose([0.0, 0.0, z], 0.0)),
                true,
                from("/tf_static", i + 1),
            );
        }
        tf.finish();
        let w = tf.check("base", "tool0", 100_000_000).unwrap();
        assert_eq!(w.len(), 1);
        assert!(
            !w[0].on_chain && w[0].to_string().contains("not on the chain"),
            "{}",
            w[0]
        );
    }

    #[test]
    fn two_parents_and_loops_are_named_not_called_unconnected() {
        let mut tf = arm();
        tf.add(
            stamped(0, "world", "wrist", pose([0.0; 3], 0.0)),
            false,
            from("/tf", 11),
        );
        tf.finish();
        let e = tf
            .check("base", "tool0", 100_000_000)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("frame `wrist` has two parents: `base` (`/tf` message 0) and `world` (`/tf` message 11)"),
            "{e}"
        );
        let mut tf = arm();
        tf.add(
            stamped(0, "tool0", "base", pose([0.0; 3], 0.0)),
            true,
            from("/tf_static", 1),
        );
        tf.finish();
        let e = tf
            .check("base", "tool0", 100_000_000)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("TF loop: `base` → `wrist` → `tool0` → `base`")
                && !e.contains("not connected"),
            "{e}"
        );
    }

    #[test]
    fn conflicting_samples_and_stamps_going_back() {
        // A second value at one stamp, 0.05 mm off: a warning; 5 mm off: refused.
        for (dz, refused) in [(0.000_05, false), (0.005, true)] {
            let mut tf = arm();
            tf.add(
                stamped(3_000_000_000, "base", "wrist", pose([0.5, 0.0, dz], 0.0)),
                false,
                from("/tf", 11),
            );
            tf.finish();
            // (The late message also steps back 7 s; allowed here.)
            match tf.check("base", "tool0", 10_000_000_000) {
                Ok(w) => {
                    assert!(!refused);
                    assert_eq!(w.len(), 2, "{w:?}"); // and the stamp going back to 3 s
                    let text = w[0].to_string();
                    assert!(
                        text.contains("1 stamp(s) with two different transforms"),
                        "{text}"
                    );
                }
                Err(e) => {
                    assert!(refused, "{e}");
                    let e = e.to_string();
                    assert!(e.contains("3.000000000 s") && e.contains("5.000 mm"), "{e}");
                }
            }
        }
        // A step back of 50 ms is jitter (warning); of 2 s, a clock that went back (refused).
        let mut tf = arm();
        tf.add(
            stamped(9_950_000_000, "base", "wrist", pose([0.5, 0.0, 0.0], 0.0)),
            false,
            from("/tf", 11),
        );
        tf.finish();
        let w = tf.check("base", "tool0", 100_000_000).unwrap();
        assert!(
            w.len() == 1
                && w[0]
                    .to_string()
                    .contains("go back in time 1 time(s), by up to 50.000 ms"),
            "{w:?}"
        );
        let mut tf = arm();
        tf.add(
            stamped(8_000_000_000, "base", "wrist", pose([0.5, 0.0, 0.0], 0.0)),
            false,
            from("/tf", 11),
        );
        tf.finish();
        let e = tf
            .check("base", "tool0", 100_000_000)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`/tf` message 11 is stamped 8.000000000 s after 10.000000000 s"),
            "{e}"
        );
    }
}
