//! Pixel encodings of `sensor_msgs/Image` and `sensor_msgs/CompressedImage` to the 8-bit grey the
//! detector reads: `mono8`, `mono16` (top 8 bits), `rgb8`/`bgr8`/`rgba8`/`bgra8` (Rec. 601 luma),
//! `bayer_*8` (the symmetric 3x3 kernel `[1 2 1; 2 4 2; 1 2 1]/16`, which gives `(R + 2G + B)/4`
//! at every pixel of every Bayer layout without shifting edges), and JPEG/PNG via `image`.
//! One decoder of the one message model ([`crate::msg`]) for every source of these messages: bags
//! (`handeye-ros2-bag`) and the live `ros2` camera.

use image::GrayImage;

use crate::msg::{CompressedImage, Image};

/// What an image message says about itself that its data contradicts, where the pixels can
/// still be read: tolerated, but named (issue #40), since a lying writer may lie elsewhere too.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ImageLie {
    /// A compressed image whose `format` names one codec and whose bytes are another's; it is
    /// decoded as what its bytes are.
    FormatLabel {
        /// The `format` field (`jpeg`, `bgr8; jpeg compressed bgr8`, `webp`).
        label: String,
        /// What the bytes are (`PNG`).
        holds: &'static str,
    },
    /// Raw data longer than `height × step`: the bytes past the last row are not pixels.
    DataPastLastRow {
        /// The data's length.
        bytes: usize,
        /// `height × step`.
        rows: usize,
    },
    /// `is_bigendian` set on an encoding of one byte a channel, where byte order means nothing.
    BigEndianOnBytes {
        /// The encoding (`mono8`).
        encoding: String,
    },
}

impl ImageLie {
    /// A short name for counting and tests.
    pub fn kind(&self) -> &'static str {
        match self {
            ImageLie::FormatLabel { .. } => "format label of other data",
            ImageLie::DataPastLastRow { .. } => "data past the last row",
            ImageLie::BigEndianOnBytes { .. } => "big-endian flag on bytes",
        }
    }
}

impl std::fmt::Display for ImageLie {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ImageLie::FormatLabel { label, holds } => write!(
                f,
                "format `{label}` but {holds} data (decoded as {holds})"
            ),
            ImageLie::DataPastLastRow { bytes, rows } => write!(
                f,
                "{bytes} bytes of data, longer than height × step = {rows} (the {} bytes past the last row are ignored)",
                bytes - rows
            ),
            ImageLie::BigEndianOnBytes { encoding } => write!(
                f,
                "is_bigendian set on `{encoding}`, whose channels are single bytes (the flag is ignored)"
            ),
        }
    }
}

/// The codecs a `format` field may name, as the `image` crate knows them.
const CODECS: [(&str, image::ImageFormat, &str); 3] = [
    ("jpeg", image::ImageFormat::Jpeg, "JPEG"),
    ("png", image::ImageFormat::Png, "PNG"),
    ("webp", image::ImageFormat::WebP, "WebP"),
];

/// The lie of a compressed image's `format` label, if it names a codec its bytes are not.
pub fn compressed_lie(image: &CompressedImage) -> Option<ImageLie> {
    let label = image.format.to_ascii_lowercase();
    let named = CODECS
        .iter()
        .find(|(word, _, _)| label.contains(word) || (*word == "jpeg" && label.contains("jpg")))?;
    let found = image::guess_format(&image.data).ok()?;
    let (_, _, holds) = CODECS.iter().find(|(_, format, _)| *format == found)?;
    (named.1 != found).then(|| ImageLie::FormatLabel {
        label: image.format.clone(),
        holds,
    })
}

/// The lies of a raw image's header about its data (see [`ImageLie`]).
pub fn raw_lies<Data: AsRef<[u8]>>(raw: &Image<Data>) -> Vec<ImageLie> {
    let data = raw.data.as_ref();
    let mut lies = Vec::new();
    let rows = raw.height as usize * raw.step as usize;
    if data.len() > rows {
        lies.push(ImageLie::DataPastLastRow {
            bytes: data.len(),
            rows,
        });
    }
    let single_bytes = layout(&raw.encoding).is_some_and(|l| l.channel_bytes == 1);
    if raw.is_bigendian != 0 && single_bytes {
        lies.push(ImageLie::BigEndianOnBytes {
            encoding: raw.encoding.clone(),
        });
    }
    lies
}

/// How a raw encoding lays out a pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Layout {
    /// Bytes a pixel.
    pixel_bytes: usize,
    /// Bytes a channel (where byte order matters above 1).
    channel_bytes: usize,
}

/// The layout of the raw encodings handeye reads; `None` for another.
fn layout(encoding: &str) -> Option<Layout> {
    let (pixel_bytes, channel_bytes) = match encoding {
        "mono8" | "8UC1" => (1, 1),
        "mono16" | "16UC1" => (2, 2),
        "rgb8" | "bgr8" => (3, 1),
        "rgba8" | "bgra8" => (4, 1),
        e if e.starts_with("bayer_") && e.ends_with('8') => (1, 1),
        _ => return None,
    };
    Some(Layout {
        pixel_bytes,
        channel_bytes,
    })
}

/// A raw image as 8-bit grey.
pub fn raw_to_gray<Data: AsRef<[u8]>>(raw: &Image<Data>) -> Result<GrayImage, String> {
    let data = raw.data.as_ref();
    let (w, h) = (raw.width as usize, raw.height as usize);
    let Some(Layout {
        pixel_bytes: bytes_per_pixel,
        ..
    }) = layout(&raw.encoding)
    else {
        return Err(format!(
            "image encoding `{}` is not supported (mono8, mono16, rgb8, bgr8, rgba8, bgra8, bayer_*8)",
            raw.encoding
        ));
    };
    let step = raw.step as usize;
    if w == 0
        || h == 0
        || step < w * bytes_per_pixel
        || data.len() < step * (h - 1) + w * bytes_per_pixel
    {
        return Err(format!(
            "{}x{} {} with step {} needs {} bytes, the message has {}",
            w,
            h,
            raw.encoding,
            step,
            step * h,
            data.len()
        ));
    }
    let row = |y: usize| &data[y * step..y * step + w * bytes_per_pixel];
    let mut out = vec![0u8; w * h];
    match raw.encoding.as_str() {
        "mono8" | "8UC1" => {
            for y in 0..h {
                out[y * w..(y + 1) * w].copy_from_slice(row(y));
            }
        }
        "mono16" | "16UC1" => {
            let high = usize::from(raw.is_bigendian == 0);
            for y in 0..h {
                for (o, px) in out[y * w..(y + 1) * w]
                    .iter_mut()
                    .zip(row(y).chunks_exact(2))
                {
                    *o = px[high];
                }
            }
        }
        e @ ("rgb8" | "bgr8" | "rgba8" | "bgra8") => {
            let (r, b) = if e.starts_with("rgb") { (0, 2) } else { (2, 0) };
            for y in 0..h {
                for (o, px) in out[y * w..(y + 1) * w]
                    .iter_mut()
                    .zip(row(y).chunks_exact(bytes_per_pixel))
                {
                    let luma =
                        299 * u32::from(px[r]) + 587 * u32::from(px[1]) + 114 * u32::from(px[b]);
                    *o = ((luma + 500) / 1000) as u8;
                }
            }
        }
        _ => bayer_luma(&mut out, w, h, |x, y| row(y)[x]),
    }
    GrayImage::from_raw(w as u32, h as u32, out).ok_or_else(|| "image buffer size".to_string())
}

/// `[1 2 1; 2 4 2; 1 2 1]/16` over a Bayer mosaic (edges mirrored).
fn bayer_luma(out: &mut [u8], w: usize, h: usize, at: impl Fn(usize, usize) -> u8) {
    let mirror = |i: isize, n: usize| -> usize {
        if i < 0 {
            (-i) as usize
        } else if i as usize >= n {
            (2 * n as isize - 2 - i).max(0) as usize
        } else {
            i as usize
        }
    };
    const K: [[u32; 3]; 3] = [[1, 2, 1], [2, 4, 2], [1, 2, 1]];
    for y in 0..h {
        for x in 0..w {
            let mut sum = 0u32;
            for (dy, krow) in K.iter().enumerate() {
                for (dx, k) in krow.iter().enumerate() {
                    let xx = mirror(x as isize + dx as isize - 1, w);
                    let yy = mirror(y as isize + dy as isize - 1, h);
                    sum += k * u32::from(at(xx, yy));
                }
            }
            out[y * w + x] = ((sum + 8) / 16) as u8;
        }
    }
}

/// The largest compressed image decoded, px a side: a camera frame is far below; a header that
/// claims more is damage (or an attack) and would ask for gigabytes.
pub const MAX_DECODED_SIDE_PX: u32 = 16384;
/// The most memory one decode may allocate, bytes (a 16384x16384 RGBA frame would need 1 GB).
pub const MAX_DECODE_BYTES: u64 = 512 << 20;

/// A compressed image (JPEG or PNG) as 8-bit grey, within [`MAX_DECODED_SIDE_PX`] and
/// [`MAX_DECODE_BYTES`].
pub fn compressed_to_gray(image: &CompressedImage) -> Result<GrayImage, String> {
    let fail = |e: image::ImageError| format!("format `{}`: cannot decode: {e}", image.format);
    let mut reader = image::ImageReader::new(std::io::Cursor::new(&image.data))
        .with_guessed_format()
        .map_err(|e| fail(e.into()))?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_DECODED_SIDE_PX);
    limits.max_image_height = Some(MAX_DECODED_SIDE_PX);
    limits.max_alloc = Some(MAX_DECODE_BYTES);
    reader.limits(limits);
    let decoded = reader.decode().map_err(|e| match e {
        image::ImageError::Limits(_) => format!(
            "format `{}`: {e} (at most {MAX_DECODED_SIDE_PX} px a side and {} MB are decoded)",
            image.format,
            MAX_DECODE_BYTES >> 20
        ),
        e => fail(e),
    })?;
    Ok(decoded.into_luma8())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raw(encoding: &str, w: u32, h: u32, step: u32, data: &[u8]) -> Image {
        Image {
            height: h,
            width: w,
            encoding: encoding.into(),
            step,
            data: data.to_vec(),
            ..Image::default()
        }
    }

    /// Each lie is found on the encodings it applies to and only there: an honest message of
    /// each kind says nothing.
    #[test]
    fn lies_of_a_header_about_its_data_are_found() {
        assert!(raw_lies(&raw("mono8", 2, 2, 2, &[0; 4])).is_empty());
        assert!(raw_lies(&raw("mono8", 2, 2, 3, &[0; 5])).is_empty());
        let long = raw_lies(&raw("mono8", 2, 2, 2, &[0; 7]));
        assert_eq!(long, [ImageLie::DataPastLastRow { bytes: 7, rows: 4 }]);
        assert!(long[0]
            .to_string()
            .contains("height × step = 4 (the 3 bytes"));
        for encoding in ["mono8", "rgb8", "bgra8", "bayer_grbg8"] {
            let mut image = raw(encoding, 1, 1, 4, &[0; 4]);
            image.is_bigendian = 1;
            assert_eq!(
                raw_lies(&image)[0].kind(),
                "big-endian flag on bytes",
                "{encoding}"
            );
        }
        let mut wide = raw("mono16", 1, 1, 2, &[0; 2]);
        wide.is_bigendian = 1;
        assert!(
            raw_lies(&wide).is_empty(),
            "byte order means something on mono16"
        );

        let mut png = Vec::new();
        GrayImage::new(2, 2)
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let compressed = |format: &str, data: &[u8]| CompressedImage {
            format: format.into(),
            data: data.to_vec(),
            ..CompressedImage::default()
        };
        for label in ["jpeg", "bgr8; jpeg compressed bgr8", "jpg", "webp"] {
            let lie = compressed_lie(&compressed(label, &png)).expect(label);
            assert_eq!(
                lie,
                ImageLie::FormatLabel {
                    label: label.into(),
                    holds: "PNG"
                }
            );
        }
        assert_eq!(compressed_lie(&compressed("png", &png)), None);
        assert_eq!(
            compressed_lie(&compressed("", &png)),
            None,
            "no codec named"
        );
    }

    #[test]
    fn encodings_to_grey() {
        let g = raw_to_gray(&raw("mono8", 2, 2, 3, &[1, 2, 99, 3, 4])).unwrap();
        assert_eq!(g.as_raw(), &[1, 2, 3, 4]);
        let g = raw_to_gray(&raw("mono16", 2, 1, 4, &[0x00, 0x12, 0xff, 0x34])).unwrap();
        assert_eq!(g.as_raw(), &[0x12, 0x34]);
        let g = raw_to_gray(&raw("rgb8", 2, 1, 6, &[255, 0, 0, 0, 0, 255])).unwrap();
        assert_eq!(g.as_raw(), &[76, 29]);
        let g = raw_to_gray(&raw("bgr8", 1, 1, 3, &[0, 0, 255])).unwrap();
        assert_eq!(g.as_raw(), &[76]);
        // A uniform grey scene through any Bayer mosaic of equal R, G, B stays uniform.
        let mosaic = vec![100u8; 16];
        let g = raw_to_gray(&raw("bayer_rggb8", 4, 4, 4, &mosaic)).unwrap();
        assert!(g.as_raw().iter().all(|&v| v == 100));
        let e = raw_to_gray(&raw("yuv422", 2, 2, 4, &[0; 8])).unwrap_err();
        assert!(e.contains("yuv422"), "{e}");
        let e = raw_to_gray(&raw("mono8", 4, 4, 4, &[0; 10])).unwrap_err();
        assert!(e.contains("needs 16 bytes"), "{e}");
    }
}
