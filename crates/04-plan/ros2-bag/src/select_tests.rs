//! Pass 2 hands each chosen frame on as it is chosen and keeps none: a bag of many stops is
//! imported with a bounded number of decoded frames alive at once (counted where frames are
//! decoded and dropped, [`super::BagImport::frames_held_at_once`]), and each stop's sharp frame is
//! the one handed on.

use std::collections::BTreeMap;
use std::path::Path;

use image::GrayImage;
use nalgebra::{UnitQuaternion, Vector3};

use handeye_core::geometry::Pose;
use handeye_ros2::msg::{Header, Image, TfMessage, Time, Transform, TransformStamped};

use super::{import_bag_to, BagOptions};

const START_NS: i64 = 1_700_000_000_000_000_000;
const WIDTH: u32 = 128;
const HEIGHT: u32 = 96;
/// A stop: the arm stands for 0.6 s, then travels 0.4 s to the next one.
const STAY_S: f64 = 0.6;
const PERIOD_S: f64 = 1.0;
/// The frame of each stop that is sharp (the others are blurred): 0.3 s into the stop.
const SHARP_AT_S: f64 = 0.3;

fn header(ns: i64, frame: &str) -> Header {
    Header {
        stamp: Time {
            sec: (ns / 1_000_000_000) as i32,
            nanosec: (ns % 1_000_000_000) as u32,
        },
        frame_id: frame.into(),
    }
}

/// `T_base_flange` at `t` s: standing at x = 0.1 m · stop, then moving to the next.
fn flange_at(t: f64) -> Pose {
    let k = (t / PERIOD_S).floor();
    let within = t - k * PERIOD_S;
    let x = if within <= STAY_S {
        0.1 * k
    } else {
        0.1 * (k + (within - STAY_S) / (PERIOD_S - STAY_S))
    };
    Pose::from_parts(
        Vector3::new(x, 0.2, 0.5).into(),
        UnitQuaternion::from_euler_angles(0.1, 0.0, 0.0),
    )
}

/// A checkerboard of 16 px squares; blurred by 3 px when `sharp` is false.
fn frame(sharp: bool) -> GrayImage {
    let crisp = GrayImage::from_fn(WIDTH, HEIGHT, |x, y| {
        image::Luma([if (x / 16 + y / 16) % 2 == 0 { 40 } else { 210 }])
    });
    if sharp {
        crisp
    } else {
        image::imageops::blur(&crisp, 3.0)
    }
}

/// An MCAP bag (uncompressed chunks, read through its index) of `stops` stops: TF at 100 Hz and
/// 20 fps `mono8` frames, each stop's frame at [`SHARP_AT_S`] sharp and the others blurred.
fn write_stops_bag(file: &Path, stops: usize) {
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .compression(None)
        .create(std::io::BufWriter::new(
            std::fs::File::create(file).unwrap(),
        ))
        .unwrap();
    let tf_schema = w
        .add_schema("tf2_msgs/msg/TFMessage", "ros2msg", b"")
        .unwrap();
    let image_schema = w
        .add_schema("sensor_msgs/msg/Image", "ros2msg", b"")
        .unwrap();
    let tf = w
        .add_channel(tf_schema, "/tf", "cdr", &BTreeMap::new())
        .unwrap();
    let image = w
        .add_channel(image_schema, "/camera/image_raw", "cdr", &BTreeMap::new())
        .unwrap();
    let (sharp, blurred) = (frame(true).into_raw(), frame(false).into_raw());
    let seconds = stops as f64 * PERIOD_S;
    let mut messages: Vec<(i64, u16, Vec<u8>)> = Vec::new();
    for k in 0..=(seconds * 100.0) as i64 {
        let t = k as f64 / 100.0;
        let stamp = START_NS + k * 10_000_000;
        let message = TfMessage {
            transforms: vec![TransformStamped {
                header: header(stamp, "base"),
                child_frame_id: "tool0".into(),
                transform: Transform::from_pose(&flange_at(t)),
            }],
        };
        messages.push((stamp, tf, handeye_ros2::cdr::encode(&message).unwrap()));
    }
    for k in 0..(seconds * 20.0) as i64 {
        let stamp = START_NS + k * 50_000_000;
        let within = (k % 20) as f64 * 0.05;
        let pixels = if (within - SHARP_AT_S).abs() < 1e-9 {
            &sharp
        } else {
            &blurred
        };
        let message = Image {
            header: header(stamp, "camera"),
            height: HEIGHT,
            width: WIDTH,
            encoding: "mono8".into(),
            is_bigendian: 0,
            step: WIDTH,
            data: pixels.clone(),
        };
        // Received 1 ms after its stamp.
        messages.push((
            stamp + 1_000_000,
            image,
            handeye_ros2::cdr::encode(&message).unwrap(),
        ));
    }
    messages.sort_by_key(|m| m.0);
    for (sequence, (time, channel_id, data)) in messages.into_iter().enumerate() {
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id,
                sequence: sequence as u32,
                log_time: time as u64,
                publish_time: time as u64,
            },
            &data,
        )
        .unwrap();
    }
    w.finish().unwrap();
}

fn options(jobs: usize) -> BagOptions {
    let board =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../configs/targets/aprilgrid-6x6.yaml");
    BagOptions {
        base_frame: "base".into(),
        flange_frame: "tool0".into(),
        image_topic: "/camera/image_raw".into(),
        camera_info_topic: None,
        tf_topics: vec!["/tf".into(), "/tf_static".into()],
        tf_static_topics: vec!["/tf_static".into()],
        select: Default::default(),
        setup: handeye_core::setup::Setup::EyeInHand,
        board: handeye_vision::Target::load(&board).unwrap(),
        detector: handeye_vision::DetectorOptions {
            jobs: Some(jobs),
            ..Default::default()
        },
    }
}

#[test]
fn frames_held_at_once_stay_bounded_however_many_stops_and_each_stops_sharp_frame_is_handed_on() {
    let dir = tempfile::tempdir().unwrap();
    let sharp = frame(true);
    for (stops, jobs) in [(4, 1), (40, 1), (40, 2)] {
        let file = dir.path().join(format!("stops-{stops}.mcap"));
        write_stops_bag(&file, stops);
        let mut handed: Vec<(usize, i64)> = Vec::new();
        let imported = import_bag_to(&file, &options(jobs), &mut |chosen| {
            let (i, sample, image) = (chosen.index, chosen.sample, chosen.image);
            assert!(
                image == &sharp,
                "sample {i} at {} ns is not its stop's sharp frame",
                sample.image_stamp_ns - START_NS
            );
            handed.push((i, sample.image_stamp_ns));
            Ok(())
        })
        .unwrap();
        assert_eq!(imported.samples.len(), stops, "one sample per stop");
        // Handed on once each, numbered in stamp order, each at its stop's sharp frame.
        let expected: Vec<(usize, i64)> = (0..stops)
            .map(|k| {
                let t = k as f64 * PERIOD_S + SHARP_AT_S;
                (k, START_NS + (t * 1e9).round() as i64)
            })
            .collect();
        assert_eq!(handed, expected);
        // The standing frames were all decoded (several per stop), yet each worker holds at most
        // its best and the frame it scores, and the interval's best is handed on alone.
        assert!(
            imported.decoded >= 5 * stops,
            "{} decoded",
            imported.decoded
        );
        assert!(
            (1..=2 * jobs + 1).contains(&imported.frames_held_at_once),
            "{stops} stops, {jobs} worker(s): {} frames held at once",
            imported.frames_held_at_once
        );
    }
}

#[test]
fn a_sink_that_fails_stops_the_import_with_its_error() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("stops.mcap");
    write_stops_bag(&file, 3);
    let mut calls = 0;
    let error = import_bag_to(&file, &options(1), &mut |chosen| {
        let i = chosen.index;
        calls += 1;
        if i == 1 {
            return Err(format!("writing /nowhere/{i:03}.png: no space left on device").into());
        }
        Ok(())
    })
    .unwrap_err();
    assert_eq!(calls, 2, "nothing handed on after the failure");
    assert_eq!(
        error.to_string(),
        "writing /nowhere/001.png: no space left on device"
    );
}

#[test]
fn a_packed_mono8_frame_is_taken_as_it_is_and_other_layouts_are_copied() {
    let pixels: Vec<u8> = (0..12u8).collect();
    fn lent(step: u32, data: &[u8]) -> Image<&[u8]> {
        Image {
            header: header(START_NS, "camera"),
            height: 3,
            width: 4,
            encoding: "mono8".into(),
            is_bigendian: 0,
            step,
            data,
        }
    }
    let message = lent(4, &pixels);
    let packed = super::select::packed_mono8(&message).unwrap();
    // The message's own bytes, not a copy.
    assert!(std::ptr::eq(packed, message.data));
    assert_eq!(
        packed,
        handeye_ros2::image::raw_to_gray(&message).unwrap().as_raw()
    );
    // Rows padded to 6 bytes: not packed, left to the copying decoder.
    let padded: Vec<u8> = (0..18u8).collect();
    assert!(super::select::packed_mono8(&lent(6, &padded)).is_none());
    // Too few bytes: left to the decoder, which names the problem.
    assert!(super::select::packed_mono8(&lent(4, &pixels[..11])).is_none());
}
