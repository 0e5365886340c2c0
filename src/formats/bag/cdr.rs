//! A small reader of ROS 2's CDR (XCDR1, plain) serialisation for exactly the messages a bag
//! import needs: `tf2_msgs/msg/TFMessage`, `sensor_msgs/msg/Image`,
//! `sensor_msgs/msg/CompressedImage` and `sensor_msgs/msg/CameraInfo`.
//!
//! A CDR message starts with a 4-byte encapsulation header (`00 01` little endian, `00 00` big
//! endian, then two option bytes); every primitive is aligned to its own size counted from the
//! end of that header; a string is a `u32` length (including its NUL) and the bytes; a sequence
//! is a `u32` count and the elements. Every read is bounds-checked: a short or malformed message
//! is an error naming the field, never a panic.

use nalgebra::{Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::geometry::Pose;

/// Why a message could not be decoded: the field being read and what was wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("CDR field `{field}`: {problem}")]
pub struct CdrError {
    /// The field being read (`transforms[2].child_frame_id`).
    pub field: String,
    /// What was wrong.
    pub problem: String,
}

/// A cursor over one CDR message.
pub struct CdrReader<'a> {
    data: &'a [u8],
    /// Offset in `data` (which starts after the encapsulation header).
    at: usize,
    little: bool,
}

impl<'a> CdrReader<'a> {
    /// A reader of `message` (encapsulation header included).
    pub fn new(message: &'a [u8]) -> Result<CdrReader<'a>, CdrError> {
        let bad = |problem: String| CdrError {
            field: "encapsulation header".into(),
            problem,
        };
        if message.len() < 4 {
            return Err(bad(format!(
                "{} bytes, a CDR message has at least 4",
                message.len()
            )));
        }
        let little = match (message[0], message[1]) {
            (0x00, 0x01) => true,
            (0x00, 0x00) => false,
            (a, b) => {
                return Err(bad(format!(
                    "representation {a:#04x} {b:#04x}, expected plain CDR (00 00 or 00 01)"
                )))
            }
        };
        Ok(CdrReader {
            data: &message[4..],
            at: 0,
            little,
        })
    }

    fn take(&mut self, n: usize, align: usize, field: &str) -> Result<&'a [u8], CdrError> {
        let start = self.at.div_ceil(align) * align;
        let end = start.checked_add(n).filter(|&e| e <= self.data.len());
        match end {
            Some(end) => {
                self.at = end;
                Ok(&self.data[start..end])
            }
            None => Err(CdrError {
                field: field.into(),
                problem: format!(
                    "message ends at byte {} but the field needs {n} bytes from byte {start}",
                    self.data.len()
                ),
            }),
        }
    }

    /// A `uint8`/`bool`.
    pub fn u8(&mut self, field: &str) -> Result<u8, CdrError> {
        Ok(self.take(1, 1, field)?[0])
    }

    /// A `uint32`.
    pub fn u32(&mut self, field: &str) -> Result<u32, CdrError> {
        let b: [u8; 4] = self.take(4, 4, field)?.try_into().unwrap_or([0; 4]);
        Ok(if self.little {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        })
    }

    /// An `int32`.
    pub fn i32(&mut self, field: &str) -> Result<i32, CdrError> {
        Ok(self.u32(field)? as i32)
    }

    /// A `float64`.
    pub fn f64(&mut self, field: &str) -> Result<f64, CdrError> {
        let b: [u8; 8] = self.take(8, 8, field)?.try_into().unwrap_or([0; 8]);
        Ok(if self.little {
            f64::from_le_bytes(b)
        } else {
            f64::from_be_bytes(b)
        })
    }

    /// A `string` (UTF-8, NUL-terminated, length including the NUL).
    pub fn string(&mut self, field: &str) -> Result<String, CdrError> {
        let len = self.u32(field)? as usize;
        let bytes = self.take(len, 1, field)?;
        let text = bytes.strip_suffix(&[0]).unwrap_or(bytes);
        String::from_utf8(text.to_vec()).map_err(|e| CdrError {
            field: field.into(),
            problem: format!("not UTF-8: {e}"),
        })
    }

    /// A `sequence<uint8>` (or `uint8[]`), borrowed.
    pub fn bytes(&mut self, field: &str) -> Result<&'a [u8], CdrError> {
        let len = self.u32(field)? as usize;
        self.take(len, 1, field)
    }

    /// A `sequence<float64>`.
    pub fn f64_sequence(&mut self, field: &str) -> Result<Vec<f64>, CdrError> {
        let len = self.u32(field)? as usize;
        if len > self.data.len() / 8 + 1 {
            return Err(CdrError {
                field: field.into(),
                problem: format!("{len} elements do not fit in the message"),
            });
        }
        (0..len)
            .map(|i| self.f64(&format!("{field}[{i}]")))
            .collect()
    }

    /// `n` consecutive `float64` (a fixed array).
    pub fn f64_array<const N: usize>(&mut self, field: &str) -> Result<[f64; N], CdrError> {
        let mut out = [0.0; N];
        for (i, v) in out.iter_mut().enumerate() {
            *v = self.f64(&format!("{field}[{i}]"))?;
        }
        Ok(out)
    }

    /// A `std_msgs/Header`: the stamp in nanoseconds and the frame id.
    pub fn header(&mut self, field: &str) -> Result<(i64, String), CdrError> {
        let stamp_ns = self.stamp(field)?;
        let frame = self.string(&format!("{field}.frame_id"))?;
        Ok((stamp_ns, frame))
    }

    /// The stamp of a `std_msgs/Header`, nanoseconds.
    fn stamp(&mut self, field: &str) -> Result<i64, CdrError> {
        let sec = self.i32(&format!("{field}.stamp.sec"))?;
        let nanosec = self.u32(&format!("{field}.stamp.nanosec"))?;
        // A `builtin_interfaces/Time` keeps the fraction of a second in `nanosec`: a value of a
        // second or more is a broken writer, and read as is it would move the stamp by whole
        // seconds (pairing the frame with another pose), so it is refused.
        if nanosec >= 1_000_000_000 {
            return Err(CdrError {
                field: format!("{field}.stamp.nanosec"),
                problem: format!(
                    "{nanosec}, expected below 1000000000 (the nanoseconds within second {sec})"
                ),
            });
        }
        Ok(i64::from(sec) * 1_000_000_000 + i64::from(nanosec))
    }
}

/// One `geometry_msgs/TransformStamped`: `parent_from_child` at `stamp_ns`.
#[derive(Debug, Clone, PartialEq)]
pub struct TransformStamped {
    /// Header stamp, ns.
    pub stamp_ns: i64,
    /// `header.frame_id` (the parent).
    pub parent: String,
    /// `child_frame_id`.
    pub child: String,
    /// Maps points in the child frame into the parent frame.
    pub parent_from_child: Pose,
}

/// Decodes a `tf2_msgs/msg/TFMessage`.
pub fn decode_tf_message(message: &[u8]) -> Result<Vec<TransformStamped>, CdrError> {
    let mut r = CdrReader::new(message)?;
    let count = r.u32("transforms")? as usize;
    let mut out = Vec::with_capacity(count.min(1024));
    for i in 0..count {
        let f = |name: &str| format!("transforms[{i}].{name}");
        let (stamp_ns, parent) = r.header(&f("header"))?;
        let child = r.string(&f("child_frame_id"))?;
        let t = r.f64_array::<3>(&f("transform.translation"))?;
        let q = r.f64_array::<4>(&f("transform.rotation"))?;
        let quaternion = Quaternion::new(q[3], q[0], q[1], q[2]);
        let norm = quaternion.norm();
        if !(t.iter().chain(q.iter()).all(|v| v.is_finite()) && (norm - 1.0).abs() < 1e-3) {
            return Err(CdrError {
                field: f("transform"),
                problem: format!(
                    "translation {t:?}, rotation (x, y, z, w) {q:?}: not finite or not a unit quaternion"
                ),
            });
        }
        out.push(TransformStamped {
            stamp_ns,
            parent: strip_slash(parent),
            child: strip_slash(child),
            parent_from_child: Pose::from_parts(
                Translation3::from(Vector3::new(t[0], t[1], t[2])),
                UnitQuaternion::from_quaternion(quaternion),
            ),
        });
    }
    Ok(out)
}

/// tf2 ignores a leading `/` of a frame id (ROS 1 habit).
fn strip_slash(frame: String) -> String {
    match frame.strip_prefix('/') {
        Some(rest) => rest.to_string(),
        None => frame,
    }
}

/// A `sensor_msgs/msg/Image`, its pixel buffer borrowed from the message.
#[derive(Debug, Clone, PartialEq)]
pub struct RawImage<'a> {
    /// Header stamp, ns.
    pub stamp_ns: i64,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// `mono8`, `rgb8`, ...
    pub encoding: String,
    /// Whether multi-byte pixels are big endian.
    pub is_bigendian: bool,
    /// Bytes per row.
    pub step: u32,
    /// The pixels.
    pub data: &'a [u8],
}

/// Decodes a `sensor_msgs/msg/Image`.
pub fn decode_image(message: &[u8]) -> Result<RawImage<'_>, CdrError> {
    let mut r = CdrReader::new(message)?;
    let (stamp_ns, _) = r.header("header")?;
    let height = r.u32("height")?;
    let width = r.u32("width")?;
    let encoding = r.string("encoding")?;
    let is_bigendian = r.u8("is_bigendian")? != 0;
    let step = r.u32("step")?;
    let data = r.bytes("data")?;
    Ok(RawImage {
        stamp_ns,
        height,
        width,
        encoding,
        is_bigendian,
        step,
        data,
    })
}

/// A `sensor_msgs/msg/CompressedImage`.
#[derive(Debug, Clone, PartialEq)]
pub struct CompressedImage<'a> {
    /// Header stamp, ns.
    pub stamp_ns: i64,
    /// `jpeg`, `png`, or image_transport's `mono8; jpeg compressed mono8`.
    pub format: String,
    /// The encoded file.
    pub data: &'a [u8],
}

/// The header stamp of a message that starts with a `std_msgs/Header` (`Image`,
/// `CompressedImage`, ...), ns: read from its first bytes, so a message's head is enough.
pub fn decode_stamp(message: &[u8]) -> Result<i64, CdrError> {
    CdrReader::new(message)?.stamp("header")
}

/// Decodes a `sensor_msgs/msg/CompressedImage`.
pub fn decode_compressed_image(message: &[u8]) -> Result<CompressedImage<'_>, CdrError> {
    let mut r = CdrReader::new(message)?;
    let (stamp_ns, _) = r.header("header")?;
    let format = r.string("format")?;
    let data = r.bytes("data")?;
    Ok(CompressedImage {
        stamp_ns,
        format,
        data,
    })
}

/// The part of a `sensor_msgs/msg/CameraInfo` a calibration uses.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraInfo {
    /// Header stamp, ns.
    pub stamp_ns: i64,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// `plumb_bob`, `rational_polynomial`, `equidistant`, ...
    pub distortion_model: String,
    /// Distortion coefficients.
    pub d: Vec<f64>,
    /// Row-major intrinsic matrix.
    pub k: [f64; 9],
    /// Binning (0 and 1 both mean none).
    pub binning: (u32, u32),
    /// Region of interest: x, y offset, height, width.
    pub roi: [u32; 4],
}

/// Decodes a `sensor_msgs/msg/CameraInfo`.
pub fn decode_camera_info(message: &[u8]) -> Result<CameraInfo, CdrError> {
    let mut r = CdrReader::new(message)?;
    let (stamp_ns, _) = r.header("header")?;
    let height = r.u32("height")?;
    let width = r.u32("width")?;
    let distortion_model = r.string("distortion_model")?;
    let d = r.f64_sequence("d")?;
    let k = r.f64_array::<9>("k")?;
    let _r = r.f64_array::<9>("r")?;
    let _p = r.f64_array::<12>("p")?;
    let binning = (r.u32("binning_x")?, r.u32("binning_y")?);
    let roi = [
        r.u32("roi.x_offset")?,
        r.u32("roi.y_offset")?,
        r.u32("roi.height")?,
        r.u32("roi.width")?,
    ];
    Ok(CameraInfo {
        stamp_ns,
        height,
        width,
        distortion_model,
        d,
        k,
        binning,
        roi,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A little-endian CDR writer for the tests (the real bags in tests/it/bag_import.rs come from
    /// the `rosbags` Python package).
    pub(crate) struct Writer(pub Vec<u8>);

    impl Writer {
        pub(crate) fn new() -> Self {
            Writer(vec![0, 1, 0, 0])
        }
        fn align(&mut self, n: usize) {
            while !(self.0.len() - 4).is_multiple_of(n) {
                self.0.push(0);
            }
        }
        pub(crate) fn u32(&mut self, v: u32) {
            self.align(4);
            self.0.extend_from_slice(&v.to_le_bytes());
        }
        pub(crate) fn f64(&mut self, v: f64) {
            self.align(8);
            self.0.extend_from_slice(&v.to_le_bytes());
        }
        pub(crate) fn string(&mut self, s: &str) {
            self.u32(s.len() as u32 + 1);
            self.0.extend_from_slice(s.as_bytes());
            self.0.push(0);
        }
        pub(crate) fn header(&mut self, stamp_ns: i64, frame: &str) {
            self.u32((stamp_ns / 1_000_000_000) as u32);
            self.u32((stamp_ns % 1_000_000_000) as u32);
            self.string(frame);
        }
    }

    /// One transform of a test TFMessage: stamp, parent, child, translation, quaternion xyzw.
    pub(crate) type TestTransform<'a> = (i64, &'a str, &'a str, [f64; 3], [f64; 4]);

    pub(crate) fn tf_message(items: &[TestTransform<'_>]) -> Vec<u8> {
        let mut w = Writer::new();
        w.u32(items.len() as u32);
        for (stamp, parent, child, t, q) in items {
            w.header(*stamp, parent);
            w.string(child);
            for v in t.iter().chain(q.iter()) {
                w.f64(*v);
            }
        }
        w.0
    }

    #[test]
    fn tf_message_round_trip_and_slashes() {
        let bytes = tf_message(&[
            (
                1_500_000_000,
                "/base",
                "tool0",
                [0.1, 0.2, 0.3],
                [0.0, 0.0, 0.0, 1.0],
            ),
            (
                2_000_000_001,
                "a",
                "b",
                [1.0, -2.0, 3.0],
                [
                    0.0,
                    0.0,
                    std::f64::consts::FRAC_1_SQRT_2,
                    std::f64::consts::FRAC_1_SQRT_2,
                ],
            ),
        ]);
        let tf = decode_tf_message(&bytes).unwrap();
        assert_eq!(tf.len(), 2);
        assert_eq!(
            (tf[0].stamp_ns, tf[0].parent.as_str()),
            (1_500_000_000, "base")
        );
        assert_eq!(tf[1].stamp_ns, 2_000_000_001);
        assert!(
            (tf[1].parent_from_child.rotation.angle() - std::f64::consts::FRAC_PI_2).abs() < 1e-12
        );
        assert_eq!(
            tf[0].parent_from_child.translation.vector,
            Vector3::new(0.1, 0.2, 0.3)
        );
    }

    #[test]
    fn short_messages_name_the_field() {
        let bytes = tf_message(&[(0, "base", "tool0", [0.0; 3], [0.0, 0.0, 0.0, 1.0])]);
        for cut in [2, 8, 30, bytes.len() - 1] {
            let e = decode_tf_message(&bytes[..cut]).unwrap_err();
            assert!(!e.field.is_empty(), "{e}");
        }
        let e = decode_tf_message(&bytes[..bytes.len() - 1]).unwrap_err();
        assert_eq!(e.field, "transforms[0].transform.rotation[3]");
        let mut bad = bytes.clone();
        bad[1] = 7;
        assert!(decode_tf_message(&bad)
            .unwrap_err()
            .to_string()
            .contains("encapsulation"));
    }

    #[test]
    fn nanoseconds_of_a_second_or_more_are_refused() {
        let mut w = Writer::new();
        w.u32(1);
        w.u32(12); // sec
        w.u32(1_500_000_000); // nanosec
        w.string("base");
        let e = decode_tf_message(&w.0).unwrap_err();
        assert_eq!(e.field, "transforms[0].header.stamp.nanosec");
        assert!(
            e.problem.contains("1500000000, expected below 1000000000"),
            "{e}"
        );
    }

    #[test]
    fn image_and_camera_info() {
        let mut w = Writer::new();
        w.header(5, "cam");
        w.u32(2);
        w.u32(3);
        w.string("mono8");
        w.0.push(0);
        w.u32(3);
        w.u32(6);
        w.0.extend_from_slice(&[1, 2, 3, 4, 5, 6]);
        let image = decode_image(&w.0).unwrap();
        assert_eq!((image.height, image.width, image.step), (2, 3, 3));
        assert_eq!(image.encoding, "mono8");
        assert_eq!(image.data, &[1, 2, 3, 4, 5, 6]);

        let mut w = Writer::new();
        w.header(7, "cam");
        w.u32(480);
        w.u32(640);
        w.string("plumb_bob");
        w.u32(5);
        for v in [-0.1, 0.01, 0.001, 0.002, 0.0] {
            w.f64(v);
        }
        for v in [600.0, 0.0, 320.0, 0.0, 601.0, 240.0, 0.0, 0.0, 1.0] {
            w.f64(v);
        }
        for _ in 0..21 {
            w.f64(0.0);
        }
        for _ in 0..6 {
            w.u32(0);
        }
        w.0.push(0);
        let info = decode_camera_info(&w.0).unwrap();
        assert_eq!(info.distortion_model, "plumb_bob");
        assert_eq!(info.d, vec![-0.1, 0.01, 0.001, 0.002, 0.0]);
        assert_eq!(
            (info.k[0], info.k[2], info.k[4], info.k[5]),
            (600.0, 320.0, 601.0, 240.0)
        );
        assert_eq!((info.width, info.height), (640, 480));
    }
}
