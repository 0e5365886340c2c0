//! handeye's ground floor: the vocabulary every other crate shares and nothing below it.
//!
//! - [`geometry`]: poses (`Pose` = `T_a_b`, `a_from_b` in code), rotation helpers and the pose
//!   YAML forms of DESIGN.md;
//! - [`camera_model`]: the pinhole camera with its distortion models and the intrinsics files
//!   (ROS camera_info, Kalibr camchain), validated on load;
//! - [`setup`]: eye-in-hand / eye-to-hand, the two unknowns of a cell, a pose pair, a corner
//!   observation;
//! - [`notice`]: typed messages with a severity;
//! - [`memory`]: the memory limits the process runs under (`ulimit -v`, the cgroup's), and the
//!   check that a step fits them;
//! - [`atomic_file`], [`yaml_file`]: files written whole or not at all, YAML read with errors that
//!   name the file, the key and the line.

pub mod atomic_file;
pub mod camera_model;
pub mod error_text;
pub mod geometry;
pub mod memory;
pub mod notice;
pub mod setup;
pub mod yaml_file;

/// `most` indices evenly spaced through `0..count` (`⌊k·count / most⌋` for k = 0, 1, …), or every
/// index when `count ≤ most`; increasing. The one way the tree thins a long list: the held-out
/// check's folds, the pairs and corners a report draws.
pub fn evenly_spaced(count: usize, most: usize) -> impl Iterator<Item = usize> + Clone {
    let taken = count.min(most);
    (0..taken).map(move |k| k * count / taken)
}

#[cfg(test)]
mod tests {
    use super::evenly_spaced;

    #[test]
    fn a_short_list_is_kept_whole_and_a_long_one_thinned_from_end_to_end() {
        assert_eq!(evenly_spaced(5, 8).collect::<Vec<_>>(), [0, 1, 2, 3, 4]);
        assert_eq!(evenly_spaced(10, 4).collect::<Vec<_>>(), [0, 2, 5, 7]);
        let thinned: Vec<usize> = evenly_spaced(499_500, 2016).collect();
        assert_eq!(thinned.len(), 2016);
        assert!(thinned.windows(2).all(|w| w[0] < w[1]));
        // The last within one stride of the end.
        assert!(*thinned.last().unwrap() >= 499_500 - 499_500_usize.div_ceil(2016));
        assert_eq!(evenly_spaced(0, 3).count(), 0);
    }
}
