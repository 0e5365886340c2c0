//! Tests of the TF tree: lookups, interpolation, gaps, and every lie a bag can tell about it.

use super::*;
use nalgebra::{UnitQuaternion, Vector3};

fn pose(t: [f64; 3], angle_z: f64) -> Pose {
    Pose::from_parts(
        Vector3::from(t).into(),
        UnitQuaternion::from_euler_angles(0.0, 0.0, angle_z),
    )
}

fn stamped(stamp_ns: i64, parent: &str, child: &str, p: Pose) -> EdgeSample {
    EdgeSample {
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

/// One edge both static and moving, in either order of arrival: named with its first static
/// and first moving message, a warning on the chain, and the pose is the moving one's.
#[test]
fn an_edge_both_static_and_moving_is_named_and_the_moving_one_used() {
    let static_value = stamped(0, "base", "wrist", pose([0.8, 0.0, 0.0], 0.0));
    let before = {
        let mut tf = TfBuffer::default();
        tf.add(static_value.clone(), true, from("/tf_static", 3));
        let moving = arm();
        for (child, (parent, edge, _)) in &moving.edges {
            if let Edge::Dynamic(samples, _) = edge {
                for (k, (stamp, p)) in samples.iter().enumerate() {
                    let sample = stamped(*stamp, parent, child, *p);
                    tf.add(sample, false, from("/tf", k));
                }
            } else if let Edge::Static(p, source) = edge {
                tf.add(stamped(0, parent, child, *p), true, source.clone());
            }
        }
        tf
    };
    let after = {
        let mut tf = arm();
        tf.add(static_value, true, from("/tf_static", 3));
        tf
    };
    for mut tf in [before, after] {
        tf.finish();
        let w = tf.check("base", "tool0", 100_000_000).unwrap();
        assert_eq!(w.len(), 1, "{w:?}");
        assert_eq!(w[0].issue.kind(), "edge both static and moving");
        let said = w[0].to_string();
        assert!(
            w[0].on_chain
                && said.contains("`base` → `wrist` is both static (`/tf_static` message 3)")
                && said.contains("moving (`/tf` message 0 on)")
                && said.contains("the moving transforms are used"),
            "{said}"
        );
        let at = tf.lookup("base", "tool0", 5_000_000_000).unwrap();
        assert!((at.translation.vector.x - 0.5).abs() < 1e-12, "{at:?}");
    }
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
        e.contains("TF loop: `base` → `wrist` → `tool0` → `base`") && !e.contains("not connected"),
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

/// A TF message of a bag, through the one codec: slashes dropped, stamps in ns, and a `nanosec`
/// of a second or more or a quaternion off unit length refused with the field and the value.
#[test]
fn tf_messages_become_edge_samples_or_name_the_bad_field() {
    use handeye_ros2::cdr;
    use handeye_ros2::msg::{Header, TfMessage, Time, Transform, TransformStamped};
    let turn = pose([1.0, -2.0, 3.0], std::f64::consts::FRAC_PI_2);
    let message = |nanosec: u32, w_scale: f64| {
        let mut transform = Transform::from_pose(&turn);
        transform.rotation.w *= w_scale;
        let bytes = cdr::encode(&TfMessage {
            transforms: vec![TransformStamped {
                header: Header {
                    stamp: Time { sec: 2, nanosec },
                    frame_id: "/base".into(),
                },
                child_frame_id: "tool0".into(),
                transform,
            }],
        })
        .unwrap();
        edge_samples(&cdr::decode::<TfMessage>(&bytes).unwrap())
    };
    let samples = message(1, 1.0).unwrap();
    assert_eq!(samples.len(), 1);
    assert_eq!(
        (
            samples[0].stamp_ns,
            samples[0].parent.as_str(),
            samples[0].child.as_str()
        ),
        (2_000_000_001, "base", "tool0")
    );
    assert!(
        samples[0]
            .parent_from_child
            .rotation
            .angle_to(&turn.rotation)
            < 1e-12
    );
    let e = message(1_500_000_000, 1.0).unwrap_err().to_string();
    assert!(
        e.contains("`transforms[0].header.stamp.nanosec`: 1500000000, expected below 1000000000"),
        "{e}"
    );
    let e = message(0, 1.5).unwrap_err().to_string();
    assert!(
        e.contains("`transforms[0].transform`") && e.contains("unit quaternion"),
        "{e}"
    );
}
