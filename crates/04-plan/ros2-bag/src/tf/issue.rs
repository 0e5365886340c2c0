//! What is wrong with a bag's TF data ([`TfIssue`]), where each transform came from
//! ([`TfSource`]), and why a lookup fails ([`TfError`]).

use handeye_core::geometry::Pose;

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
pub(super) fn apart(a: &Pose, b: &Pose) -> (f64, f64) {
    (
        (a.translation.vector - b.translation.vector).norm() * 1e3,
        a.rotation.angle_to(&b.rotation).to_degrees(),
    )
}

pub(super) fn same(a: &Pose, b: &Pose) -> bool {
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
    /// One edge given both a static value (`/tf_static`) and moving ones (`/tf`): tf2 would use
    /// whichever came last; the moving one is used here, whatever the order.
    StaticAndMoving {
        /// The parent.
        parent: String,
        /// The child.
        child: String,
        /// Its first static message.
        statics: TfSource,
        /// Its first moving message.
        moving: TfSource,
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
            | TfIssue::StaticAndMoving { child, .. }
            | TfIssue::TwoParents { child, .. }
            | TfIssue::ConflictingSamples { child, .. }
            | TfIssue::StampsBack { child, .. } => vec![child.as_str()],
        }
    }

    /// A short name for counting and tests (`static conflict`, `two parents`, ...).
    pub fn kind(&self) -> &'static str {
        match self {
            TfIssue::StaticConflict { .. } => "static conflict",
            TfIssue::StaticAndMoving { .. } => "edge both static and moving",
            TfIssue::TwoParents { .. } => "two parents",
            TfIssue::Loop { .. } => "loop",
            TfIssue::ConflictingSamples { .. } => "conflicting transforms at one stamp",
            TfIssue::StampsBack { .. } => "stamps going back",
        }
    }

    /// Whether, on the chain looked up, it makes the pose ambiguous (`max_back_ns`: the largest
    /// step back in time still taken for delivery jitter).
    pub(super) fn ambiguous(&self, max_back_ns: i64) -> bool {
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
            // The moving transforms are used: the pose is theirs, what the arm reported.
            TfIssue::StaticAndMoving { .. } => false,
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
            TfIssue::StaticAndMoving {
                parent,
                child,
                statics,
                moving,
            } => write!(
                f,
                "`{parent}` → `{child}` is both static ({statics}) and moving ({moving} on); the moving transforms are used, the static value ignored; expected each edge on one of the two"
            ),
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
                TfIssue::StaticAndMoving { .. } => f.write_str(")"),
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
