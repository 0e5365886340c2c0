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

/// The folder `path` is in: its parent, or `.` for a bare file name (whose `parent()` is the
/// empty path, which no file call accepts).
pub fn folder_of(path: &std::path::Path) -> &std::path::Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => std::path::Path::new("."),
    }
}

/// `most` indices evenly spaced through `0..count` (`⌊k·count / most⌋` for k = 0, 1, …), or every
/// index when `count ≤ most`; increasing. The one way the tree thins a long list: the held-out
/// check's folds, the pairs a report draws, and with [`keeping_notable`] and [`keeping_largest`]
/// its corners and frames.
pub fn evenly_spaced(count: usize, most: usize) -> impl Iterator<Item = usize> + Clone {
    let taken = count.min(most);
    (0..taken).map(move |k| k * count / taken)
}

/// The indices of `0..count` to keep when at most `most` may be: every index when they fit;
/// past it, the notable ones (`is_notable`; up to half of `most`, [`evenly_spaced`] among them)
/// and the others evenly spaced to fill `most`; increasing. How a report draws a long list of
/// corners: the notable ones are what a reader looks for.
pub fn keeping_notable(
    count: usize,
    most: usize,
    is_notable: impl Fn(usize) -> bool,
) -> Vec<usize> {
    if count <= most {
        return (0..count).collect();
    }
    let (notable, others): (Vec<usize>, Vec<usize>) = (0..count).partition(|&i| is_notable(i));
    let notable_kept = notable.len().min(most / 2);
    let mut kept: Vec<usize> = evenly_spaced(notable.len(), notable_kept)
        .map(|k| notable[k])
        .chain(evenly_spaced(others.len(), most - notable_kept).map(|k| others[k]))
        .collect();
    kept.sort_unstable();
    kept
}

/// The indices of `0..count` to keep when at most `most` may be: every index when they fit;
/// past it, the `most / 2` with the largest `key` and the others evenly spaced to fill `most`;
/// increasing. How a report draws a long recording's frames: the worst are what a reader opens.
pub fn keeping_largest(count: usize, most: usize, key: impl Fn(usize) -> f64) -> Vec<usize> {
    if count <= most {
        return (0..count).collect();
    }
    let mut by_key: Vec<usize> = (0..count).collect();
    by_key.sort_by(|&a, &b| key(b).total_cmp(&key(a)));
    let mut largest = vec![false; count];
    for &i in &by_key[..most / 2] {
        largest[i] = true;
    }
    keeping_notable(count, most, |i| largest[i])
}

#[cfg(test)]
mod tests {
    use super::{evenly_spaced, keeping_largest, keeping_notable};

    #[test]
    fn a_long_list_keeps_its_largest_half_and_thins_the_rest() {
        assert_eq!(keeping_largest(3, 10, |i| i as f64), [0, 1, 2]);
        // Keys rising with the index: the largest half is the last 50.
        let kept = keeping_largest(1000, 100, |i| i as f64);
        assert_eq!(kept.len(), 100);
        assert!(kept.windows(2).all(|w| w[0] < w[1]));
        assert!((950..1000).all(|i| kept.contains(&i)));
        assert_eq!(kept.iter().filter(|&&i| i < 950).count(), 50);
        assert_eq!(kept[0], 0, "the others start at the start");
    }

    #[test]
    fn a_long_list_keeps_its_notable_items_up_to_half_and_thins_the_rest() {
        // Short: all, notable or not.
        assert_eq!(keeping_notable(4, 10, |i| i == 2), [0, 1, 2, 3]);
        // 1,000 items, every 100th notable: all 10 kept, 90 others evenly spaced.
        let kept = keeping_notable(1000, 100, |i| i % 100 == 7);
        assert_eq!(kept.len(), 100);
        assert!(kept.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(kept.iter().filter(|&&i| i % 100 == 7).count(), 10);
        assert!(
            *kept.last().unwrap() >= 980,
            "the others reach the end: {kept:?}"
        );
        // Mostly notable: they take half, the others the rest.
        let kept = keeping_notable(1000, 100, |i| i < 900);
        assert_eq!(kept.iter().filter(|&&i| i < 900).count(), 50);
        assert_eq!(kept.iter().filter(|&&i| i >= 900).count(), 50);
        // Nothing notable: plain even spacing.
        assert_eq!(
            keeping_notable(1000, 100, |_| false),
            evenly_spaced(1000, 100).collect::<Vec<_>>()
        );
    }

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
