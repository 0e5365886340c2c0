//! Camera buffer decoding: the raw frame forms USB/UVC cameras deliver (YUYV 4:2:2, MJPEG, 8-bit
//! grey, packed RGB) turned into the grey image the detector reads. Plain functions with no
//! camera library behind them, so they are tested on synthetic buffers in every build; the
//! `uvc` backend feeds them the driver's bytes.
//!
//! Grey is luma: YUYV's Y samples as they are (no colour conversion needed), JPEG decoded to
//! luma by the `image` crate, RGB by Rec. 601 weights. Buffers are tightly packed rows (no
//! padding), as V4L2 delivers them for these formats. Depends on `image` only.

use image::GrayImage;

/// A raw frame layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelFormat {
    /// YUYV 4:2:2: `Y0 U Y1 V` per two pixels, 2 bytes per pixel.
    Yuyv,
    /// Motion JPEG: one JPEG image per frame.
    Mjpeg,
    /// 8-bit grey, 1 byte per pixel.
    Gray,
    /// Packed 8-bit RGB, 3 bytes per pixel.
    Rgb,
}

impl PixelFormat {
    /// The name used in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            PixelFormat::Yuyv => "yuyv",
            PixelFormat::Mjpeg => "mjpeg",
            PixelFormat::Gray => "gray",
            PixelFormat::Rgb => "rgb",
        }
    }
}

/// Why a buffer could not be decoded.
#[derive(Debug, thiserror::Error)]
pub enum DecodeError {
    /// The buffer's length does not match the frame size.
    #[error("{format} frame of {width}x{height} px needs {expected} bytes, got {actual}")]
    Length {
        /// The format name.
        format: &'static str,
        /// Width, px.
        width: u32,
        /// Height, px.
        height: u32,
        /// Bytes the frame needs.
        expected: usize,
        /// Bytes received.
        actual: usize,
    },
    /// YUYV needs an even width.
    #[error("yuyv frame width {0} px is odd; YUYV packs pixel pairs")]
    OddWidth(u32),
    /// The JPEG data is corrupt.
    #[error("mjpeg frame does not decode")]
    Jpeg(#[source] image::ImageError),
    /// The JPEG decoded to another size than the stream's.
    #[error("mjpeg frame is {actual_width}x{actual_height} px, the stream is {width}x{height} px")]
    JpegSize {
        /// Stream width, px.
        width: u32,
        /// Stream height, px.
        height: u32,
        /// Decoded width, px.
        actual_width: u32,
        /// Decoded height, px.
        actual_height: u32,
    },
}

fn check_length(
    format: PixelFormat,
    width: u32,
    height: u32,
    bytes_per_pixel: usize,
    data: &[u8],
) -> Result<(), DecodeError> {
    let expected = width as usize * height as usize * bytes_per_pixel;
    if data.len() != expected {
        return Err(DecodeError::Length {
            format: format.name(),
            width,
            height,
            expected,
            actual: data.len(),
        });
    }
    Ok(())
}

/// Decodes a raw frame of `width` x `height` pixels in `format` to grey.
pub fn to_gray(
    format: PixelFormat,
    width: u32,
    height: u32,
    data: &[u8],
) -> Result<GrayImage, DecodeError> {
    match format {
        PixelFormat::Yuyv => yuyv_to_gray(width, height, data),
        PixelFormat::Mjpeg => mjpeg_to_gray(width, height, data),
        PixelFormat::Gray => {
            check_length(format, width, height, 1, data)?;
            Ok(GrayImage::from_raw(width, height, data.to_vec()).expect("length checked"))
        }
        PixelFormat::Rgb => {
            check_length(format, width, height, 3, data)?;
            let grey = data
                .chunks_exact(3)
                .map(|p| {
                    let y = 0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64;
                    y.round().clamp(0.0, 255.0) as u8
                })
                .collect();
            Ok(GrayImage::from_raw(width, height, grey).expect("length checked"))
        }
    }
}

/// YUYV 4:2:2 to grey: the Y bytes (every other byte) are the luma.
pub fn yuyv_to_gray(width: u32, height: u32, data: &[u8]) -> Result<GrayImage, DecodeError> {
    if !width.is_multiple_of(2) {
        return Err(DecodeError::OddWidth(width));
    }
    check_length(PixelFormat::Yuyv, width, height, 2, data)?;
    let luma = data.iter().step_by(2).copied().collect();
    Ok(GrayImage::from_raw(width, height, luma).expect("length checked"))
}

/// MJPEG (one JPEG) to grey; the decoded size must be the stream's.
pub fn mjpeg_to_gray(width: u32, height: u32, data: &[u8]) -> Result<GrayImage, DecodeError> {
    let image = image::load_from_memory_with_format(data, image::ImageFormat::Jpeg)
        .map_err(DecodeError::Jpeg)?
        .into_luma8();
    if (image.width(), image.height()) != (width, height) {
        return Err(DecodeError::JpegSize {
            width,
            height,
            actual_width: image.width(),
            actual_height: image.height(),
        });
    }
    Ok(image)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 6x4 grey test pattern with distinct values.
    fn pattern() -> GrayImage {
        GrayImage::from_fn(6, 4, |x, y| image::Luma([(x * 40 + y * 7) as u8]))
    }

    #[test]
    fn yuyv_takes_the_luma_samples() {
        let grey = pattern();
        // Chroma bytes set to values that would corrupt the result if read as luma.
        let yuyv: Vec<u8> = grey
            .pixels()
            .enumerate()
            .flat_map(|(i, p)| [p[0], if i % 2 == 0 { 17 } else { 230 }])
            .collect();
        assert_eq!(to_gray(PixelFormat::Yuyv, 6, 4, &yuyv).unwrap(), grey);
        let e = to_gray(PixelFormat::Yuyv, 6, 4, &yuyv[..47])
            .unwrap_err()
            .to_string();
        assert!(e.contains("48 bytes") && e.contains("got 47"), "{e}");
        assert!(matches!(
            yuyv_to_gray(5, 4, &[0; 40]),
            Err(DecodeError::OddWidth(5))
        ));
    }

    #[test]
    fn gray_and_rgb_buffers() {
        let grey = pattern();
        assert_eq!(
            to_gray(PixelFormat::Gray, 6, 4, grey.as_raw()).unwrap(),
            grey
        );
        // Grey RGB pixels stay the same grey level (weights sum to 1).
        let rgb: Vec<u8> = grey.pixels().flat_map(|p| [p[0]; 3]).collect();
        assert_eq!(to_gray(PixelFormat::Rgb, 6, 4, &rgb).unwrap(), grey);
        // Pure red is 0.299 * 255 = 76.2 -> 76.
        let red = to_gray(PixelFormat::Rgb, 1, 1, &[255, 0, 0]).unwrap();
        assert_eq!(red.get_pixel(0, 0)[0], 76);
        assert!(to_gray(PixelFormat::Gray, 6, 4, &[0; 23]).is_err());
    }

    #[test]
    fn mjpeg_decodes_to_the_encoded_image() {
        // A smooth 64x48 gradient: JPEG at quality 100 keeps every pixel within 3 grey levels.
        let grey = GrayImage::from_fn(64, 48, |x, y| image::Luma([(x * 3 + y) as u8]));
        let mut jpeg = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 100)
            .encode_image(&grey)
            .unwrap();
        let decoded = to_gray(PixelFormat::Mjpeg, 64, 48, &jpeg).unwrap();
        let worst = decoded
            .pixels()
            .zip(grey.pixels())
            .map(|(a, b)| (a[0] as i32 - b[0] as i32).abs())
            .max()
            .unwrap();
        assert!(worst <= 3, "largest JPEG error {worst} grey levels");
        assert!(matches!(
            to_gray(PixelFormat::Mjpeg, 32, 48, &jpeg),
            Err(DecodeError::JpegSize {
                actual_width: 64,
                ..
            })
        ));
        assert!(matches!(
            to_gray(PixelFormat::Mjpeg, 64, 48, &jpeg[..jpeg.len() / 3]),
            Err(DecodeError::Jpeg(_))
        ));
    }
}
