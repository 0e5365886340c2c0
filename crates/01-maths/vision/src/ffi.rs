//! The raw AprilTag layer: every call into the C library (`apriltag-sys`, and the `apriltag`
//! crate's detector handle built from a raw pointer) lives here, and nowhere else in `vision`.
//! Each `unsafe` block states why it is sound in a `// SAFETY:` line. Handles are owned by Rust
//! types that free them in `Drop`, in the order the C library needs (detector before family).
//!
//! The C detector does not check its input: an image whose quad-search copy (after decimation)
//! is smaller than one 4x4 threshold tile indexes memory before its buffers and crashes the
//! process. [`DetectorHandle::detect`] therefore checks every image's size first
//! ([`check_image_size`]); the decimation itself is bounded by `vision::detect` before a
//! detector is built. Nor does it check what its `malloc`s return: [`detector_bytes`] bounds what
//! it allocates for an image, and `vision::detect` makes sure that much is there before each call
//! (issue #44), so a memory limit is an error, not a crash in C. Depends on `vision::family` (the layout type) and `vision::TargetError`.

use apriltag::{Detector, Image};
use apriltag_sys as sys;
use image::GrayImage;

use super::family::{FamilyLayout, TagFamily};
use super::TargetError;

/// The library's tag-family table, copied into Rust data (create → read → destroy).
pub(super) fn standard_layout(family: TagFamily) -> FamilyLayout {
    // SAFETY: the create functions return a fresh heap family or NULL (read_family checks);
    // the family is read while alive and freed with the matching destroy exactly once.
    unsafe {
        match family {
            TagFamily::Tag36h11 => {
                let ptr = sys::tag36h11_create();
                let layout = read_family(ptr);
                sys::tag36h11_destroy(ptr);
                layout
            }
            TagFamily::TagStandard41h12 => {
                let ptr = sys::tagStandard41h12_create();
                let layout = read_family(ptr);
                sys::tagStandard41h12_destroy(ptr);
                layout
            }
        }
    }
}

/// Copies a C family table into Rust data.
///
/// # Safety
/// `family` must be NULL or point to a valid, initialised `apriltag_family_t`.
unsafe fn read_family(family: *const sys::apriltag_family_t) -> FamilyLayout {
    // The bundled C tables are a few kB; NULL means the process is out of memory at start-up,
    // which no caller can cause or handle.
    assert!(!family.is_null(), "AprilTag family allocation failed");
    // SAFETY: non-null and valid per the contract.
    let f = unsafe { &*family };
    // SAFETY: `codes` holds `ncodes` entries (the family table's invariant).
    let codes = unsafe { std::slice::from_raw_parts(f.codes, f.ncodes as usize) }.to_vec();
    // bit_x / bit_y are declared unsigned but hold small negative numbers (-2) for families
    // with data outside the border: reinterpret as i32.
    // SAFETY: `bit_x` and `bit_y` hold `nbits` entries each (the family table's invariant).
    let (bit_x, bit_y) = unsafe {
        (
            std::slice::from_raw_parts(f.bit_x, f.nbits as usize),
            std::slice::from_raw_parts(f.bit_y, f.nbits as usize),
        )
    };
    FamilyLayout {
        codes,
        nbits: f.nbits,
        bit_x: bit_x.iter().map(|&v| v as i32).collect(),
        bit_y: bit_y.iter().map(|&v| v as i32).collect(),
        width_at_border: f.width_at_border,
        total_width: f.total_width,
        reversed_border: f.reversed_border,
    }
}

/// Owns the C family struct a detector points at; frees it on drop (after the detector).
pub(super) struct OwnedFamily {
    family: TagFamily,
    ptr: *mut sys::apriltag_family_t,
}

impl OwnedFamily {
    /// Allocates `family` with a black border `border_bits` cells wide (1, or 2 for Kalibr's
    /// aprilgrid: the same codes with the border one cell wider on each side).
    pub(super) fn create(family: TagFamily, border_bits: u32) -> Result<Self, String> {
        if !(1..=2).contains(&border_bits) {
            return Err(format!("border_bits must be 1 or 2, found {border_bits}"));
        }
        // SAFETY: the create functions take no input and return a fresh heap family or NULL
        // (checked below).
        let ptr = unsafe {
            match family {
                TagFamily::Tag36h11 => sys::tag36h11_create(),
                TagFamily::TagStandard41h12 => sys::tagStandard41h12_create(),
            }
        };
        if ptr.is_null() {
            return Err(format!("cannot allocate the {} family", family.name()));
        }
        // From here on Drop frees ptr, on the error paths too.
        let owned = OwnedFamily { family, ptr };
        if border_bits == 2 {
            // SAFETY: ptr is a valid family we own exclusively (no detector references it yet);
            // bit_x / bit_y hold nbits entries. The border square grows by 2 cells and the
            // data moves in by 1.
            unsafe {
                let f = &mut *owned.ptr;
                if f.reversed_border {
                    return Err(format!("{} has no 2-cell-border layout", family.name()));
                }
                f.width_at_border += 2;
                f.total_width += 2;
                for i in 0..f.nbits as usize {
                    *f.bit_x.add(i) = (*f.bit_x.add(i)).wrapping_add(1);
                    *f.bit_y.add(i) = (*f.bit_y.add(i)).wrapping_add(1);
                }
            }
        }
        Ok(owned)
    }
}

impl Drop for OwnedFamily {
    fn drop(&mut self) {
        // SAFETY: ptr came from the matching create function and is freed exactly once; the
        // detector that referenced it is dropped first (see `DetectorHandle`'s field order).
        unsafe {
            match self.family {
                TagFamily::Tag36h11 => sys::tag36h11_destroy(self.ptr),
                TagFamily::TagStandard41h12 => sys::tagStandard41h12_destroy(self.ptr),
            }
        }
    }
}

/// A configured C detector and the family it searches for. Not `Send` (raw pointers): it lives
/// on `vision::detect`'s detector thread.
pub(super) struct DetectorHandle {
    // Field order is drop order: the detector (which points at the family) goes first.
    detector: Detector,
    _family: OwnedFamily,
    decimation: f32,
    quad_sigma: f32,
}

/// Settings the C detector takes, already validated by `vision::detect`.
pub(super) struct RawOptions {
    pub(super) decimation: f32,
    pub(super) threads: u8,
    pub(super) quad_sigma: f32,
    pub(super) max_hamming: u32,
}

impl DetectorHandle {
    /// Creates a detector for `family`.
    pub(super) fn new(family: OwnedFamily, options: &RawOptions) -> Result<Self, String> {
        // SAFETY: apriltag_detector_create returns a fresh detector or NULL (checked); adding
        // the family stores its pointer, which outlives the detector (field order above).
        // Detector::from_raw takes ownership of the detector pointer and destroys it on drop.
        let mut detector = unsafe {
            let raw = sys::apriltag_detector_create();
            if raw.is_null() {
                return Err("apriltag_detector_create failed".to_string());
            }
            // The quick-decode table grows steeply with corrected bits; 2 covers
            // max_hamming ≤ 2.
            sys::apriltag_detector_add_family_bits(
                raw,
                family.ptr,
                options.max_hamming.clamp(1, 2) as i32,
            );
            Detector::from_raw(raw)
        };
        detector.set_decimation(options.decimation);
        detector.set_thread_number(options.threads.max(1));
        detector.set_sigma(options.quad_sigma);
        detector.set_refine_edges(true);
        Ok(DetectorHandle {
            detector,
            _family: family,
            decimation: options.decimation,
            quad_sigma: options.quad_sigma,
        })
    }

    /// Runs the detector on `image`, after checking that its size is safe for the C code at
    /// this detector's decimation (see the module docs).
    pub(super) fn detect(&mut self, image: &GrayImage) -> Result<Vec<RawTag>, TargetError> {
        self.detect_at(image, self.decimation)
    }

    /// [`Self::detect`] with the quad search at `decimation` for this image only (the second
    /// pass searches small crops at full resolution).
    pub(super) fn detect_at(
        &mut self,
        image: &GrayImage,
        decimation: f32,
    ) -> Result<Vec<RawTag>, TargetError> {
        check_image_size(image.width(), image.height(), decimation, self.quad_sigma)?;
        if decimation != self.decimation {
            self.detector.set_decimation(decimation);
            let tags = self.detect_checked(image);
            self.detector.set_decimation(self.decimation);
            return tags;
        }
        self.detect_checked(image)
    }

    /// The C detector on an image whose size was checked for the current decimation.
    fn detect_checked(&mut self, image: &GrayImage) -> Result<Vec<RawTag>, TargetError> {
        let (width, height) = (image.width() as usize, image.height() as usize);
        let mut buffer = Image::zeros_with_alignment(width, height, 96).map_err(|error| {
            TargetError::Detector {
                reason: format!("cannot allocate a {width}x{height} detector image: {error}"),
            }
        })?;
        let stride = buffer.stride();
        let data = buffer.as_slice_mut();
        for (y, row) in image.as_raw().chunks_exact(width).enumerate() {
            data[y * stride..y * stride + width].copy_from_slice(row);
        }
        Ok(self
            .detector
            .detect(&buffer)
            .into_iter()
            .map(|d| RawTag {
                id: d.id() as u32,
                hamming: d.hamming() as u32,
                decision_margin: d.decision_margin(),
                corners: d.corners(),
            })
            .collect())
    }
}

/// The size of the image the C detector searches for quads: `apriltag_detector_detect`
/// decimates with `image_u8_decimate`, whose arithmetic this repeats (1.5 is a special case;
/// any other factor is truncated to an integer).
pub(super) fn quad_image_size(width: u32, height: u32, decimation: f32) -> (u32, u32) {
    if decimation <= 1.0 {
        (width, height)
    } else if decimation == 1.5 {
        (width / 3 * 2, height / 3 * 2)
    } else {
        // The caller bounds decimation (≤ MAX_DECIMATION), so the cast is exact.
        let factor = decimation as u32;
        let side = |n: u32| if n == 0 { 0 } else { 1 + (n - 1) / factor };
        (side(width), side(height))
    }
}

/// The blur (or sharpening) kernel width the C detector derives from `quad_sigma`, px.
fn kernel_size(quad_sigma: f32) -> u32 {
    // As in apriltag_detector_detect: 2 standard deviations each way, made odd.
    let ksz = (4.0 * quad_sigma.abs()) as u32;
    ksz | 1
}

/// The smallest side of the quad-search image that is safe with `quad_sigma`: one threshold
/// tile margin ([`MIN_QUAD_IMAGE_SIDE_PX`]) and no narrower than the blur kernel, whose
/// convolution writes before its row when the row is shorter than the kernel.
fn min_quad_side(quad_sigma: f32) -> u32 {
    MIN_QUAD_IMAGE_SIDE_PX.max(kernel_size(quad_sigma))
}

/// Refuses an image the C detector cannot search safely: either side of its quad-search copy
/// under [`min_quad_side`].
pub(super) fn check_image_size(
    width: u32,
    height: u32,
    decimation: f32,
    quad_sigma: f32,
) -> Result<(), TargetError> {
    let min_quad = min_quad_side(quad_sigma);
    let (quad_width, quad_height) = quad_image_size(width, height, decimation);
    if quad_width < min_quad || quad_height < min_quad {
        return Err(TargetError::ImageTooSmall {
            width,
            height,
            decimation,
            min_side_px: min_image_side(decimation, min_quad),
        });
    }
    Ok(())
}

/// The smallest image side whose quad-search copy at `decimation` is `min_quad` px, px.
fn min_image_side(decimation: f32, min_quad: u32) -> u32 {
    (min_quad..)
        .find(|&n| quad_image_size(n, n, decimation).0 >= min_quad)
        .unwrap_or(u32::MAX)
}

/// Smallest side of the quad-search image, px. The C thresholding works on 4x4 tiles and
/// indexes out of bounds with fewer than one tile per side; two tiles leave a margin (and no
/// tag fits in less anyway).
pub(super) const MIN_QUAD_IMAGE_SIDE_PX: u32 = 8;

/// Bytes the C detector allocates per pixel of its quad-search image, at most: the decimated
/// copy and the threshold image (1 + 1), the union-find of connected components (8: a 32-bit
/// parent and size per pixel) and the gradient clusters (up to four 12-byte boundary points per
/// pixel, 48). A noisy frame comes near it; a board on a plain background uses a fraction.
const C_BYTES_PER_QUAD_PIXEL: u64 = 58;

/// The C detector's quick-decode table of one family, bytes: three slots of 16 bytes per code
/// and per pattern within `bits` corrected bits (`quick_decode_init`). Built once per detector.
fn quick_decode_bytes(codes: u64, nbits: u64, bits: u32) -> u64 {
    let patterns = match bits {
        0 | 1 => 1 + nbits,
        _ => 1 + nbits + nbits * (nbits - 1) / 2,
    };
    codes * patterns * 3 * 16
}

/// The memory one C detector allocates, at most, to search a `width`x`height` image at
/// `decimation` (the library checks none of its allocations, so this is what must be free):
/// its aligned copy of the image, the quad search's working memory and the decode table of
/// `family` within `max_hamming` bits.
pub(super) fn detector_bytes(
    family: TagFamily,
    width: u32,
    height: u32,
    decimation: f32,
    max_hamming: u32,
) -> u64 {
    let (quad_width, quad_height) = quad_image_size(width, height, decimation);
    let quad = u64::from(quad_width) * u64::from(quad_height);
    // The detector's own copy of the frame, rows padded to 96 bytes.
    let image = u64::from(width.next_multiple_of(96)) * u64::from(height);
    let layout = standard_layout(family);
    let table = quick_decode_bytes(
        layout.codes.len() as u64,
        u64::from(layout.nbits),
        max_hamming.clamp(1, 2),
    );
    image + quad * C_BYTES_PER_QUAD_PIXEL + table
}

/// Under an address-space limit (`ulimit -v`), keeps glibc's allocator to one arena. Each
/// thread that allocates otherwise gets an arena of its own, which reserves 64 MB of address
/// space on a 64-bit system however little it holds: a few detector threads then leave no room
/// for the allocations themselves, and the C detector, which checks none of its `malloc`s,
/// crashes. One arena shares the space (the detectors' large blocks are mapped one by one
/// anyway). Without a limit nothing changes.
pub(super) fn fit_allocator_to_limits() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    if handeye_core::memory::address_space_limited() {
        // SAFETY: mallopt(M_ARENA_MAX) only sets a limit glibc reads when it next creates an
        // arena; it may be called at any time from any thread, and touches no memory of ours.
        unsafe {
            libc::mallopt(libc::M_ARENA_MAX, 1);
        }
    }
}

/// One detection as the C library reports it (pixel centres at `i + 0.5`).
pub(super) struct RawTag {
    pub(super) id: u32,
    pub(super) hamming: u32,
    pub(super) decision_margin: f32,
    pub(super) corners: [[f64; 2]; 4],
}
