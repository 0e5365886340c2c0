//! A ROS 2 message in its serialised form, as rosbag2 stores it and DDS carries it: a 4-byte
//! encapsulation header (`00 01` little endian, `00 00` big endian, then two option bytes) and
//! the fields in plain CDR (XCDR1). Decoded and encoded by `cdr-encoding`, the serde codec RustDDS
//! itself uses, into the structs of [`crate::msg`]: one codec and one message model for bags and
//! the live graph.
//!
//! Hostile input is safe: `cdr-encoding` checks every length prefix against the bytes left before
//! it allocates, and a sequence grows element by element (serde's `Vec` takes no size hint from
//! it), so a message can allocate no more than its own size. A short or malformed message is an
//! error naming the message type, never a panic.

use byteorder::{BigEndian, LittleEndian};
use serde::{Deserialize, Serialize};

use crate::msg::{RosType, Time};

/// Why a message could not be decoded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CdrError {
    /// The encapsulation header is not plain CDR.
    #[error("CDR encapsulation header: {0}")]
    Header(String),
    /// The bytes are not a message of that type (cut short, a bad length or value).
    #[error("not a {type_name} in plain CDR: {problem}")]
    Malformed {
        /// `sensor_msgs/msg/Image`, ...
        type_name: String,
        /// What `cdr-encoding` found (`unexpected end of input`, a bad boolean, ...).
        problem: String,
    },
    /// A field decoded but holds a value the message type does not allow.
    #[error("CDR field `{field}`: {problem}")]
    Field {
        /// The field (`transforms[2].header.stamp.nanosec`).
        field: String,
        /// What was wrong, with the value.
        problem: String,
    },
}

/// The byte order the encapsulation header of `message` names, and the CDR body after it.
fn body(message: &[u8]) -> Result<(bool, &[u8]), CdrError> {
    match message {
        [0x00, 0x01, _, _, rest @ ..] => Ok((true, rest)),
        [0x00, 0x00, _, _, rest @ ..] => Ok((false, rest)),
        [a, b, _, _, ..] => Err(CdrError::Header(format!(
            "representation {a:#04x} {b:#04x}, expected plain CDR (00 00 or 00 01)"
        ))),
        short => Err(CdrError::Header(format!(
            "{} bytes, a CDR message has at least 4",
            short.len()
        ))),
    }
}

fn decode_named<'a, T: Deserialize<'a>>(message: &'a [u8], type_name: &str) -> Result<T, CdrError> {
    let (little, body) = body(message)?;
    let decoded = if little {
        cdr_encoding::from_bytes::<T, LittleEndian>(body)
    } else {
        cdr_encoding::from_bytes::<T, BigEndian>(body)
    };
    decoded
        .map(|(value, _consumed)| value)
        .map_err(|e| CdrError::Malformed {
            type_name: type_name.to_string(),
            problem: e.to_string(),
        })
}

/// Decodes one serialised message (encapsulation header included). Bytes after the message's
/// last field are ignored, as every ROS 2 reader does. A message type that borrows
/// (`Image<&[u8]>`) lends its pixels from `message`.
pub fn decode<'a, T: Deserialize<'a> + RosType>(message: &'a [u8]) -> Result<T, CdrError> {
    decode_named(message, &T::type_name())
}

/// The header stamp of a message that starts with a `std_msgs/Header` (`Image`,
/// `CompressedImage`, `CameraInfo`, ...): read from its first bytes, so a message's head is
/// enough.
pub fn decode_header_stamp(message: &[u8]) -> Result<Time, CdrError> {
    decode_named(message, "std_msgs/msg/Header")
}

/// A message serialised little endian, as rosbag2 and ROS 2 nodes on x86 and ARM write it
/// (encapsulation header `00 01 00 00` included).
pub fn encode<T: Serialize>(message: &T) -> Result<Vec<u8>, CdrError> {
    let body =
        cdr_encoding::to_vec::<T, LittleEndian>(message).map_err(|e| CdrError::Malformed {
            type_name: std::any::type_name::<T>().to_string(),
            problem: e.to_string(),
        })?;
    let mut out = Vec::with_capacity(body.len() + 4);
    out.extend_from_slice(&[0x00, 0x01, 0x00, 0x00]);
    out.extend_from_slice(&body);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{
        CameraInfo, Header, Image, Quaternion, TfMessage, Transform, TransformStamped, Vector3,
    };

    fn tf_message() -> TfMessage {
        TfMessage {
            transforms: vec![TransformStamped {
                header: Header {
                    stamp: Time {
                        sec: 1,
                        nanosec: 500_000_000,
                    },
                    frame_id: "/base".into(),
                },
                child_frame_id: "tool0".into(),
                transform: Transform {
                    translation: Vector3 {
                        x: 0.1,
                        y: 0.2,
                        z: 0.3,
                    },
                    rotation: Quaternion {
                        x: 0.0,
                        y: 0.0,
                        z: 0.0,
                        w: 1.0,
                    },
                },
            }],
        }
    }

    /// The bytes of the ROS 2 wire form, written out by hand: a count, the header (sec,
    /// nanosec, a string with its NUL), the child frame, padding to 8, seven doubles.
    #[test]
    fn a_tf_message_has_the_wire_layout_and_round_trips() {
        let bytes = encode(&tf_message()).unwrap();
        let mut want = vec![0, 1, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0, 0x65, 0xcd, 0x1d];
        want.extend_from_slice(&[6, 0, 0, 0]);
        want.extend_from_slice(b"/base\0");
        want.extend_from_slice(&[0, 0]);
        want.extend_from_slice(&[6, 0, 0, 0]);
        want.extend_from_slice(b"tool0\0");
        want.extend_from_slice(&[0, 0, 0, 0, 0, 0]);
        for v in [0.1f64, 0.2, 0.3, 0.0, 0.0, 0.0, 1.0] {
            want.extend_from_slice(&v.to_le_bytes());
        }
        assert_eq!(bytes, want);
        assert_eq!(decode::<TfMessage>(&bytes).unwrap(), tf_message());
        // The body alone (it starts `01 00`) is no encapsulation header.
        assert_eq!(
            decode_header_stamp(&bytes[4..]).unwrap_err().to_string(),
            "CDR encapsulation header: representation 0x01 0x00, expected plain CDR (00 00 or 00 01)"
        );
        assert!(decode::<TfMessage>(&bytes[..3])
            .unwrap_err()
            .to_string()
            .contains("3 bytes, a CDR message has at least 4"));
    }

    #[test]
    fn big_endian_messages_decode() {
        let body = cdr_encoding::to_vec::<TfMessage, BigEndian>(&tf_message()).unwrap();
        let mut bytes = vec![0, 0, 0, 0];
        bytes.extend_from_slice(&body);
        assert_eq!(decode::<TfMessage>(&bytes).unwrap(), tf_message());
    }

    /// Every cut of a message, and every length prefix set to the largest count, is an error
    /// naming the type: never a panic, never an allocation of what the prefix claims.
    #[test]
    fn cut_and_lying_messages_are_errors() {
        let info = CameraInfo {
            distortion_model: "plumb_bob".into(),
            d: vec![0.1; 5],
            ..CameraInfo::default()
        };
        let image = Image {
            encoding: "mono8".into(),
            width: 4,
            height: 2,
            step: 4,
            data: vec![7; 8],
            ..Image::default()
        };
        for (bytes, name) in [
            (encode(&tf_message()).unwrap(), "tf2_msgs/msg/TFMessage"),
            (encode(&info).unwrap(), "sensor_msgs/msg/CameraInfo"),
            (encode(&image).unwrap(), "sensor_msgs/msg/Image"),
        ] {
            for cut in 0..bytes.len() {
                let e = match name {
                    "tf2_msgs/msg/TFMessage" => decode::<TfMessage>(&bytes[..cut]).err(),
                    "sensor_msgs/msg/CameraInfo" => decode::<CameraInfo>(&bytes[..cut]).err(),
                    _ => decode::<Image>(&bytes[..cut]).err(),
                };
                let e = e.unwrap_or_else(|| panic!("{name} cut at {cut} decoded"));
                if cut >= 4 {
                    assert!(e.to_string().contains(name), "{e}");
                }
            }
            // Each 4-aligned word set to u32::MAX: a count or length that lies.
            for at in (4..bytes.len() - 3).step_by(4) {
                let mut lying = bytes.clone();
                lying[at..at + 4].copy_from_slice(&[0xff; 4]);
                let _ = decode::<TfMessage>(&lying);
                let _ = decode::<CameraInfo>(&lying);
                let _ = decode::<Image>(&lying);
            }
        }
        let e = decode::<TfMessage>(&[0, 1, 0, 0, 0xff, 0xff, 0xff, 0xff]).unwrap_err();
        assert!(e.to_string().contains("unexpected end of input"), "{e}");
    }

    #[test]
    fn pixels_are_one_block_on_the_wire() {
        let image = Image {
            header: Header {
                stamp: Time { sec: 0, nanosec: 5 },
                frame_id: "cam".into(),
            },
            height: 2,
            width: 3,
            encoding: "mono8".into(),
            is_bigendian: 0,
            step: 3,
            data: vec![1, 2, 3, 4, 5, 6],
        };
        let bytes = encode(&image).unwrap();
        assert!(
            bytes.ends_with(&[6, 0, 0, 0, 1, 2, 3, 4, 5, 6]),
            "{bytes:?}"
        );
        assert_eq!(decode::<Image>(&bytes).unwrap(), image);
        // Lent: the same fields, the pixels where they lie in the message (no copy).
        let lent = decode::<Image<&[u8]>>(&bytes).unwrap();
        assert_eq!(
            (lent.width, lent.height, &lent.encoding),
            (3, 2, &image.encoding)
        );
        assert_eq!(lent.data, &image.data[..]);
        assert!(std::ptr::eq(lent.data, &bytes[bytes.len() - 6..]));
        // A length prefix past the message is the same clear error either way.
        let cut = &bytes[..bytes.len() - 1];
        assert!(decode::<Image<&[u8]>>(cut).is_err() && decode::<Image>(cut).is_err());
        assert_eq!(
            decode_header_stamp(&bytes[..12]).unwrap(),
            Time { sec: 0, nanosec: 5 }
        );
    }
}
