//! Outliers of the reprojection refinement: the robust reweighting of corners (iteratively
//! reweighted least squares) and of robot poses (a frame whose robot correction stands far out
//! from the others' loses its prior, so its correction runs free and it leaves the fit of the two
//! unknowns), and the flags reported at the optimum (frames and corners far above the rest, frames
//! whose correction stands out).
//!
//! The median + MAD rule is [`crate::diagnostics::flag_outliers`], shared with pose space.

use super::problem::{Problem, State};
use super::{ReprojectionErrors, ReprojectionOptions, RobotPrior};
use crate::diagnostics::flag_outliers;

/// Sets every corner's robust weight from its current error, and frees the robot correction of
/// frames whose correction stands far out (see [`robot_outliers`]); returns the largest change.
pub(super) fn reweight(problem: &mut Problem<'_>, options: &ReprojectionOptions) -> f64 {
    let robust = options.robust;
    let s = problem.state();
    let mut change: f64 = 0.0;
    if let Some(prior) = problem.prior {
        let flagged = robot_outliers(&s, &prior, options.outlier_mad_factor);
        for (f, weight) in problem.prior_weights.iter_mut().enumerate() {
            let new = if flagged.contains(&f) { 0.0 } else { 1.0 };
            change = change.max((new - *weight).abs());
            *weight = new;
        }
    }
    let new: Vec<Vec<f64>> = problem
        .pixel_errors(&s)
        .iter()
        .map(|f| {
            f.iter()
                .map(|e| robust.weight(e.norm() * problem.inv_sigma_px))
                .collect()
        })
        .collect();
    let change = new
        .iter()
        .flatten()
        .zip(problem.weights.iter().flatten())
        .map(|(a, b)| (a - b).abs())
        .fold(change, f64::max);
    problem.weights = new;
    change
}

/// Frames whose robot correction, in prior sigmas, stands out from the others' (median + MAD
/// rule) and exceeds [`ROBOT_OUTLIER_SIGMAS`].
fn robot_outliers(s: &State, prior: &RobotPrior, mad_factor: f64) -> Vec<usize> {
    let sizes: Vec<f64> = (0..s.corrections.len())
        .map(|f| correction_sigmas(s, f, prior))
        .collect();
    flag_outliers(&sizes, mad_factor, ROBOT_OUTLIER_SIGMAS)
}

/// Size of frame `f`'s robot correction in prior sigmas (the norm of the whitened 6-vector).
fn correction_sigmas(s: &State, f: usize, prior: &RobotPrior) -> f64 {
    let (phi, rho) = s.corrections[f];
    ((phi / prior.rotation_sigma_rad).norm_squared()
        + (rho / prior.translation_sigma_m).norm_squared())
    .sqrt()
}

/// A frame's robot correction is flagged beyond this many prior sigmas (6-dof norm; the 99.9 %
/// point of a 6-dof Gaussian is 4.7) when it also stands out from the other frames'.
const ROBOT_OUTLIER_SIGMAS: f64 = 5.0;

/// A frame whose robot correction stood out: it was left out of the fit of the two unknowns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct RobotOutlier {
    /// Index of the frame.
    pub frame: usize,
    /// Size of its translation correction, m.
    pub translation_m: f64,
    /// Size of its rotation correction, rad.
    pub rotation_rad: f64,
    /// Its correction in multiples of the repeatability the other frames show (per dof).
    pub repeatabilities: f64,
}

/// The outliers flagged at the optimum.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Flags {
    /// Frames whose reprojection RMS is far above the rest (indices into the input).
    pub pixel_frames: Vec<usize>,
    /// Frames whose robot correction runs free (their recorded pose is far off).
    pub robot_frames: Vec<RobotOutlier>,
    /// Both of the above, sorted, without duplicates.
    pub frames: Vec<usize>,
    /// Corners far above the rest: (frame index, corner index).
    pub corners: Vec<(usize, usize)>,
}

/// Flags frames and corners at the optimum `s` of `problem`, whose errors are `errors`.
pub(super) fn flag(
    problem: &Problem<'_>,
    s: &State,
    errors: &ReprojectionErrors,
    options: &ReprojectionOptions,
) -> Flags {
    let frames = problem.frames;
    let frame_values: Vec<f64> = errors
        .frame_rms_px
        .iter()
        .map(|v| if v.is_finite() { *v } else { 0.0 })
        .collect();
    let pixel_frames = flag_outliers(
        &frame_values,
        options.outlier_mad_factor,
        options.outlier_floor_px,
    );
    let mut outlier_frames = pixel_frames.clone();
    // A frame whose recorded robot pose is far off shows in its correction, not its pixels (the
    // correction absorbs it): flag those too.
    let mut robot_frames = Vec::new();
    if let Some(prior) = problem.prior {
        for f in (0..frames.len()).filter(|&f| problem.prior_weights[f] == 0.0) {
            let (phi, rho) = s.corrections[f];
            robot_frames.push(RobotOutlier {
                frame: f,
                translation_m: rho.norm(),
                rotation_rad: phi.norm(),
                repeatabilities: correction_sigmas(s, f, &prior) / 6f64.sqrt(),
            });
            outlier_frames.push(f);
        }
        outlier_frames.sort_unstable();
        outlier_frames.dedup();
    }
    let all_corners: Vec<f64> = errors.corner_px.iter().flatten().copied().collect();
    let flagged: Vec<usize> = flag_outliers(
        &all_corners,
        options.outlier_mad_factor,
        options.outlier_floor_px,
    );
    let mut corners = Vec::with_capacity(flagged.len());
    let mut starts = Vec::with_capacity(frames.len());
    let mut n = 0;
    for f in frames {
        starts.push(n);
        n += f.corners.len();
    }
    for index in flagged {
        let f = starts.partition_point(|&s| s <= index) - 1;
        corners.push((f, index - starts[f]));
    }
    Flags {
        pixel_frames,
        robot_frames,
        frames: outlier_frames,
        corners,
    }
}
