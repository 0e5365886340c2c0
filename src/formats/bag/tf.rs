//! The TF tree of a bag: static transforms (`/tf_static`) and time series (`/tf`) per edge
//! `parent → child`, looked up at a stamp by chaining edges through their common root. A dynamic
//! edge is interpolated between the two samples around the stamp (lerp of the translation, slerp
//! of the rotation) and never extrapolated: a stamp outside an edge's samples, or between two
//! samples further apart than the allowed gap, is a TF gap.

use std::collections::{BTreeMap, BTreeSet};

use crate::geometry::Pose;

use super::cdr::TransformStamped;

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
    Static(Pose),
    Dynamic(Vec<(i64, Pose)>),
}

/// The TF tree of a bag.
#[derive(Debug, Clone, Default)]
pub struct TfBuffer {
    /// child → (parent, transforms `parent_from_child`).
    edges: BTreeMap<String, (String, Edge)>,
    /// The largest allowed spacing of two dynamic samples to interpolate between, ns.
    max_gap_ns: Option<i64>,
}

impl TfBuffer {
    /// Adds one transform (from `/tf_static` when `is_static`).
    pub fn add(&mut self, t: TransformStamped, is_static: bool) {
        let sample = (t.stamp_ns, t.parent_from_child);
        match self.edges.get_mut(&t.child) {
            // One more sample of a known dynamic edge.
            Some((parent, Edge::Dynamic(samples))) if *parent == t.parent && !is_static => {
                samples.push(sample);
            }
            // A new child, a static value (the latest wins), a child re-parented (the latest
            // parent wins, as in tf2) or turned static or dynamic: the edge starts again.
            _ => {
                let edge = if is_static {
                    Edge::Static(t.parent_from_child)
                } else {
                    Edge::Dynamic(vec![sample])
                };
                self.edges.insert(t.child, (t.parent, edge));
            }
        }
    }

    /// Sorts the samples; call once after the last [`TfBuffer::add`].
    pub fn finish(&mut self) {
        for (_, edge) in self.edges.values_mut() {
            if let Edge::Dynamic(samples) = edge {
                samples.sort_by_key(|s| s.0);
                samples.dedup_by_key(|s| s.0);
            }
        }
    }

    /// Refuses to interpolate across samples more than `gap_ns` apart.
    pub fn set_max_gap_ns(&mut self, gap_ns: i64) {
        self.max_gap_ns = Some(gap_ns);
    }

    fn known(&self) -> Vec<String> {
        let mut all = BTreeSet::new();
        for (child, (parent, _)) in &self.edges {
            all.insert(child.clone());
            all.insert(parent.clone());
        }
        all.into_iter().collect()
    }

    /// The edges from `frame` up to its root (child names).
    fn path_to_root(&self, frame: &str) -> Result<Vec<String>, TfError> {
        if !self.edges.contains_key(frame) && !self.edges.values().any(|(p, _)| p == frame) {
            return Err(TfError::UnknownFrame {
                frame: frame.to_string(),
                known: self.known(),
            });
        }
        let mut path = Vec::new();
        let mut at = frame.to_string();
        while let Some((parent, _)) = self.edges.get(&at) {
            if path.contains(&at) || path.len() > self.edges.len() {
                break; // a cycle: stop at the repeat
            }
            path.push(at.clone());
            at = parent.clone();
        }
        Ok(path)
    }

    fn root_of(&self, path: &[String], frame: &str) -> String {
        path.last()
            .and_then(|c| self.edges.get(c))
            .map(|(p, _)| p.clone())
            .unwrap_or_else(|| frame.to_string())
    }

    /// Checks that both frames exist and are connected (at no particular time).
    pub fn check_chain(&self, target: &str, source: &str) -> Result<(), TfError> {
        self.connected_paths(target, source).map(|_| ())
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
        let Some((parent, edge)) = self.edges.get(child) else {
            return Ok(Pose::identity());
        };
        let samples = match edge {
            Edge::Static(p) => return Ok(*p),
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
        );
        tf.add(
            stamped(0, "world", "camera", pose([0.0, 2.0, 0.0], 0.5)),
            true,
        );
        tf.add(
            stamped(1_000_000_000, "base", "tool0", pose([0.0, 0.0, 0.0], 0.0)),
            false,
        );
        tf.add(
            stamped(3_000_000_000, "base", "tool0", pose([0.2, 0.0, 0.0], 0.4)),
            false,
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
        tf.add(stamped(0, "base", "shoulder", pose([0.0; 3], 0.0)), false);
        tf.add(stamped(0, "flange", "tool0", pose([0.0; 3], 0.0)), true);
        tf.finish();
        let e = tf.check_chain("base", "wrist_3").unwrap_err().to_string();
        assert!(e.contains("`wrist_3`") && e.contains("shoulder"), "{e}");
        let e = tf.check_chain("base", "tool0").unwrap_err().to_string();
        assert!(e.contains("not connected") && e.contains("flange"), "{e}");
    }
}
