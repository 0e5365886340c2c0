//! AprilTag families as plain Rust data: codes and bit layout read once from the C library's
//! tables, and the wider-border variant Kalibr prints (black border two cells wide).
//!
//! The layout is in tag cells, rows from the top of the printed tag (image order). The
//! `width_at_border` square is the one the detector's corners outline and whose edge is the
//! board's `tagSize`. The tables are read through `vision::ffi` (the one module with `unsafe`
//! code). Depends on nothing else of ours.

use std::sync::OnceLock;

use serde::Deserialize;

/// The tag families a board may use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Default)]
pub enum TagFamily {
    /// `tag36h11` (587 codes): the default and Kalibr's family.
    #[default]
    #[serde(rename = "tag36h11")]
    Tag36h11,
    /// `tagStandard41h12` (2115 codes, reversed border, data outside the border).
    #[serde(rename = "tagStandard41h12")]
    TagStandard41h12,
}

impl TagFamily {
    /// The family's name as the AprilTag library spells it.
    pub fn name(self) -> &'static str {
        match self {
            TagFamily::Tag36h11 => "tag36h11",
            TagFamily::TagStandard41h12 => "tagStandard41h12",
        }
    }

    /// The family's layout with a black border `border_bits` cells wide (1: the library's
    /// standard, 2: Kalibr's printed aprilgrid). Only non-reversed families take 2.
    pub fn layout(self, border_bits: u32) -> Option<FamilyLayout> {
        let base = self.standard_layout();
        match border_bits {
            1 => Some(base.clone()),
            2 if !base.reversed_border => Some(FamilyLayout {
                width_at_border: base.width_at_border + 2,
                total_width: base.total_width + 2,
                bit_x: base.bit_x.iter().map(|x| x + 1).collect(),
                bit_y: base.bit_y.iter().map(|y| y + 1).collect(),
                ..base.clone()
            }),
            _ => None,
        }
    }

    fn standard_layout(self) -> &'static FamilyLayout {
        static TAG36H11: OnceLock<FamilyLayout> = OnceLock::new();
        static TAG41H12: OnceLock<FamilyLayout> = OnceLock::new();
        let cell = match self {
            TagFamily::Tag36h11 => &TAG36H11,
            TagFamily::TagStandard41h12 => &TAG41H12,
        };
        cell.get_or_init(|| super::ffi::standard_layout(self))
    }
}

/// A family's codes and bit positions, in cells.
#[derive(Debug, Clone, PartialEq)]
pub struct FamilyLayout {
    /// The codes; index = tag id.
    pub codes: Vec<u64>,
    /// Bits per code.
    pub nbits: u32,
    /// Column of bit i (most significant first), in cells from the border square's left edge;
    /// may be negative (data outside the border).
    pub bit_x: Vec<i32>,
    /// Row of bit i, in cells from the border square's top edge.
    pub bit_y: Vec<i32>,
    /// Edge of the border square, cells (the detector's corners and `tagSize`).
    pub width_at_border: i32,
    /// Edge of the whole printed tag including its outer ring, cells.
    pub total_width: i32,
    /// True when the border is white on black (tagStandard41h12).
    pub reversed_border: bool,
}

impl FamilyLayout {
    /// Cells between the border square and the tag's outer edge, on each side.
    pub fn margin_cells(&self) -> i32 {
        (self.total_width - self.width_at_border) / 2
    }

    /// The printed tag as `total_width²` cells, row-major from the top-left; `true` is white.
    /// Same construction as the C library's `apriltag_to_image`: black everywhere, a one-cell
    /// white ring, then the white data bits. `None` for an id outside the family.
    pub fn bitmap(&self, index: usize) -> Option<Vec<bool>> {
        let code = *self.codes.get(index)?;
        let n = self.total_width as usize;
        let mut cells = vec![false; n * n];
        let white_ring = self.width_at_border + if self.reversed_border { 0 } else { 2 };
        let start = ((self.total_width - white_ring) / 2) as usize;
        let end = start + white_ring as usize - 1;
        for i in start..=end {
            for (r, c) in [(start, i), (end, i), (i, start), (i, end)] {
                cells[r * n + c] = true;
            }
        }
        let offset = self.margin_cells();
        for bit in 0..self.nbits as usize {
            if code & (1u64 << (self.nbits as usize - 1 - bit)) != 0 {
                let x = (self.bit_x[bit] + offset) as usize;
                let y = (self.bit_y[bit] + offset) as usize;
                cells[y * n + x] = true;
            }
        }
        Some(cells)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tag36h11_layout_matches_the_published_family() {
        let layout = TagFamily::Tag36h11.layout(1).unwrap();
        assert_eq!(layout.codes.len(), 587);
        assert_eq!(
            (layout.nbits, layout.width_at_border, layout.total_width),
            (36, 8, 10)
        );
        let kalibr = TagFamily::Tag36h11.layout(2).unwrap();
        assert_eq!((kalibr.width_at_border, kalibr.total_width), (10, 12));
        assert!(TagFamily::TagStandard41h12.layout(2).is_none());
    }

    #[test]
    fn bitmap_has_black_border_inside_white_ring() {
        for border in [1, 2] {
            let layout = TagFamily::Tag36h11.layout(border).unwrap();
            let n = layout.total_width as usize;
            let cells = layout.bitmap(0).unwrap();
            for i in 0..n {
                assert!(cells[i] && cells[(n - 1) * n + i], "outer ring white");
            }
            for b in 1..=border as usize {
                for i in b..n - b {
                    assert!(
                        !cells[b * n + i] && !cells[i * n + b],
                        "border {border} black"
                    );
                }
            }
        }
    }
}
