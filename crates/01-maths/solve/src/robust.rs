//! Robust by default: the answer is not pulled by gross outliers.
//!
//! 1. Consensus start (least median of squares): the closed form on many random 4-sample
//!    subsets (seeded, so the answer is reproducible); the subset answer with the smallest
//!    median whitened residual over all samples wins. Up to half the samples may be wrong.
//! 2. The samples whose residual against that start is an outlier (robust scale per group,
//!    [`diagnostics::flag_outliers`]) are set aside and the chosen method (with its noise
//!    estimate) fits the rest.
//! 3. Every sample is tested against that fit, whitened by the estimated noise, with the same
//!    rule as the diagnostics' outlier flags (a sample left out whitened by the noise plus the
//!    uncertainty of its prediction); the fit is repeated on the samples that pass until
//!    the set is stable. A sample set aside by the start but consistent with the fit comes back,
//!    so a clean data set ends with every sample and exactly the plain fit.
//!
//! Every sample left out is named in a [`NoticeKind::DroppedOutliers`] warning with its residual.
//! Depends on the pipeline in `solve` (the fit of a subset), the closed form and the diagnostics.

use rand::rngs::StdRng;
use rand::SeedableRng;

use super::diagnostics::{self, check_rotation_diversity, median, MIN_SAMPLES};
use super::refine::test_norms;
use super::{closed_form, solve_subset, Axby, AxbyData, Calibration, SolveError, SolveOptions};
use handeye_core::notice::{Notice, NoticeKind};
use handeye_core::setup::{PosePair, Setup};

/// Samples per consensus subset: the fewest that give both unknowns with a little redundancy.
const SUBSET: usize = 4;
/// Consensus subsets drawn: with 20 % outliers a clean 4-subset comes up with p ≈ 0.4, so 60
/// draws miss one with p < 1e-13.
const DRAWS: usize = 60;
/// Fewest samples for a consensus start: below, one outlier is a quarter of the data and
/// the start is not better than the fit of all.
const MIN_CONSENSUS_SAMPLES: usize = 8;
/// Rounds of fit-and-test.
const MAX_ROUNDS: usize = 6;
/// Median of the chi distribution with 3 degrees of freedom: median residual norm of a group
/// (3 axes) over its per-axis sigma.
const CHI3_MEDIAN: f64 = 1.5382;
/// Whitened residual (sigmas, 6 dof) a sample must exceed to be left out of the final fit
/// (beside the robust `median + k·MAD` rule). Higher than the flagging floor (4.74, the 99.9 %
/// quantile): χ² with 6 dof exceeds 36 with probability 1e-6, so a clean set keeps every sample
/// even when its noise, estimated from the other samples, comes out 25 % low (as it can with
/// 8–10 samples); a sample that can pull the answer is far above it.
const EXCLUDE_FLOOR_SIGMA: f64 = 6.0;
/// Seed of the consensus draws (any fixed value: the answer must not change between runs).
const SEED: u64 = 0x4845_5945; // "HEYE"

/// The samples consistent with a least-median-of-squares consensus start, or `None` when there
/// are too few samples for one or no subset gives an answer.
fn consensus_inliers(
    setup: Setup,
    pairs: &[PosePair],
    options: &SolveOptions,
) -> Option<Vec<usize>> {
    let n = pairs.len();
    if n < MIN_CONSENSUS_SAMPLES {
        return None;
    }
    let data = AxbyData::new(setup, pairs);
    let mut rng = StdRng::seed_from_u64(SEED);
    let mut best: Option<(f64, Axby)> = None;
    for _ in 0..DRAWS {
        let mut subset = rand::seq::index::sample(&mut rng, n, SUBSET).into_vec();
        subset.sort_unstable();
        let robot: Vec<_> = subset.iter().map(|&i| pairs[i].base_from_flange).collect();
        if check_rotation_diversity(&robot).is_err() {
            continue;
        }
        let sub = AxbyData {
            a: subset.iter().map(|&i| data.a[i]).collect(),
            b: subset.iter().map(|&i| data.b[i]).collect(),
            weights: subset.iter().map(|&i| data.weights[i]).collect(),
        };
        let Ok(candidate) = closed_form::solve_axby(&sub) else {
            continue;
        };
        let r = diagnostics::residuals(&data, &candidate, &options.noise);
        let score = median(&r.normalised);
        if score.is_finite() && best.as_ref().is_none_or(|(s, _)| score < *s) {
            best = Some((score, candidate));
        }
    }
    let (_, start) = best?;
    let r = diagnostics::residuals(&data, &start, &options.noise);
    // Robust per-group scales of this start, so the test does not depend on the starting noise.
    // Each residual at its sample's weight (a weight w is the noise model's variance over w).
    let scaled = |values: &[f64]| -> Vec<f64> {
        values
            .iter()
            .zip(&data.weights)
            .map(|(v, w)| v * w.sqrt())
            .collect()
    };
    let (rotation, translation) = (scaled(&r.rotation_deg), scaled(&r.translation_mm));
    let scale_r = (median(&rotation) / CHI3_MEDIAN).max(1e-9);
    let scale_t = (median(&translation) / CHI3_MEDIAN).max(1e-9);
    let normalised: Vec<f64> = rotation
        .iter()
        .zip(&translation)
        .map(|(a, t)| ((a / scale_r).powi(2) + (t / scale_t).powi(2)).sqrt())
        .collect();
    let flagged = diagnostics::flag_outliers(
        &normalised,
        options.outlier_mad_factor,
        options.outlier_floor_sigma,
    );
    Some((0..n).filter(|i| !flagged.contains(i)).collect())
}

/// Fewest samples a fit may keep: more than half of them, and the solver's minimum.
fn min_kept(n: usize) -> usize {
    (n / 2 + 1).max(MIN_SAMPLES)
}

/// The robust pipeline of [`super::solve`] (see the module docs).
pub(super) fn solve_robust(
    setup: Setup,
    pairs: &[PosePair],
    options: &SolveOptions,
) -> Result<Calibration, SolveError> {
    let n = pairs.len();
    let all: Vec<usize> = (0..n).collect();
    // The plain fit first: when it flags nothing, no sample stands out from its own noise
    // estimate and this is the answer (exactly the ML fit of all). Only a flagged set pays for
    // the consensus start below (most of this function's time). A closed form's fit of all is
    // no such test: one gross outlier can pull it so far (Daniilidis with two boards seen
    // turned 180°: 100° and a metre off) that the noise estimated at it hides every outlier,
    // or make it fail; a closed form always takes the consensus start (cheap beside its own
    // fit's cost), which on a clean set ends with every sample and exactly the plain fit.
    let plain = solve_subset(setup, pairs, &all, options);
    match &plain {
        Ok(fit) if fit.outliers.is_empty() && !options.method.is_closed_form() => return plain,
        Err(_) if !options.method.is_closed_form() => return plain,
        _ => {}
    }
    let data = AxbyData::new(setup, pairs);
    let mut keep = consensus_inliers(setup, pairs, options)
        .filter(|k| k.len() >= min_kept(n))
        .unwrap_or_else(|| all.clone());
    let mut tried: Vec<Vec<usize>> = Vec::new();
    let mut last: Option<(Calibration, Vec<usize>, super::Residuals)> = None;
    for _ in 0..MAX_ROUNDS {
        let calibration = match solve_subset(setup, pairs, &keep, options) {
            Ok(c) => c,
            // Leaving samples out cost the rotation diversity: fit them all.
            Err(_) if keep.len() < n => {
                keep = all.clone();
                continue;
            }
            Err(e) => return Err(e),
        };
        let noise = calibration
            .noise
            .map(|p| p.model())
            .unwrap_or(options.noise);
        let solution = Axby::from_mounts(&calibration.camera_mount, &calibration.target_mount);
        let mut residuals = diagnostics::residuals(&data, &solution, &noise);
        // Samples left out are tested against what the fit can predict for them.
        let in_fit: Vec<bool> = all.iter().map(|i| keep.contains(i)).collect();
        if let Some(norms) = test_norms(&data, &solution, &noise, &in_fit) {
            residuals.normalised = norms;
        }
        let flagged = diagnostics::flag_outliers(
            &residuals.normalised,
            options.outlier_mad_factor,
            exclude_floor(options),
        );
        let next: Vec<usize> = all
            .iter()
            .copied()
            .filter(|i| !flagged.contains(i))
            .collect();
        let stable = next == keep;
        let next = if next.len() < min_kept(n) {
            // More than half "outliers" is a model that does not fit, not bad samples: fit all
            // and let the flags and the convention check speak.
            all.clone()
        } else {
            next
        };
        tried.push(keep.clone());
        last = Some((calibration, keep.clone(), residuals));
        if stable || tried.contains(&next) {
            break;
        }
        keep = next;
    }
    let Some((mut calibration, kept, residuals)) = last else {
        // Every round fell back: fit all once more for its error.
        return solve_subset(setup, pairs, &all, options);
    };
    let dropped: Vec<usize> = all.iter().copied().filter(|i| !kept.contains(i)).collect();
    if dropped.is_empty() {
        return Ok(calibration);
    }
    let threshold = diagnostics::outlier_threshold(
        &residuals.normalised,
        options.outlier_mad_factor,
        exclude_floor(options),
    );
    let mut notices: Vec<Notice> = dropped
        .iter()
        .map(|&i| {
            let name = match &pairs[i].id {
                Some(id) => format!("sample {i} ({id})"),
                None => format!("sample {i}"),
            };
            Notice::warning(
                NoticeKind::DroppedOutliers,
                format!(
                    "{name} left out of the final fit: its T_camera_target is {:.3}° and {:.2} mm \
                     from the prediction of the fit of the other {} samples, {:.1} sigmas of the \
                     estimated noise and the prediction's uncertainty (outlier above {:.1}); check its detection and robot pose",
                    residuals.rotation_deg[i],
                    residuals.translation_mm[i],
                    kept.len(),
                    residuals.normalised[i],
                    threshold
                ),
            )
        })
        .collect();
    notices.append(&mut calibration.notices);
    calibration.notices = notices;
    let mut outliers = dropped.clone();
    outliers.extend(calibration.outliers.iter().copied());
    outliers.sort_unstable();
    outliers.dedup();
    calibration.outliers = outliers;
    calibration.dropped = dropped;
    Ok(calibration)
}

/// The floor of the exclusion test, sigmas.
fn exclude_floor(options: &SolveOptions) -> f64 {
    options.outlier_floor_sigma.max(EXCLUDE_FLOOR_SIGMA)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Method;
    use handeye_core::geometry::{pose_from_rotvec, Pose};
    use nalgebra::Vector3;

    fn pose(t: [f64; 3], r: [f64; 3]) -> Pose {
        pose_from_rotvec(Vector3::from(t), Vector3::from(r))
    }

    /// 20 eye-in-hand samples with a little deterministic noise (0.05°, 0.3 mm); the board of
    /// samples 3 and 11 seen turned 180° about its normal (a symmetric board's classic
    /// misdetection).
    fn cell_with_flipped_boards() -> (Pose, Vec<PosePair>) {
        let camera_mount = pose([0.03, -0.07, 0.04], [0.02, -0.01, 1.56]);
        let target_mount = pose([0.5, -0.15, 0.0], [0.01, -0.02, 0.3]);
        let flip = pose([0.0; 3], [0.0, 0.0, std::f64::consts::PI]);
        let pairs = (0..20)
            .map(|i| {
                let k = i as f64;
                let view = pose(
                    [
                        0.08 * (k * 0.7).sin(),
                        0.08 * (k * 1.3).cos(),
                        0.6 + 0.01 * k,
                    ],
                    [
                        std::f64::consts::PI + 0.4 * (k * 0.9).sin(),
                        0.4 * (k * 1.7).cos(),
                        0.6 * (k * 0.5).sin(),
                    ],
                );
                let base_from_flange = target_mount * view * camera_mount.inverse();
                let noise = pose(
                    [
                        (k * 2.1).sin() * 3e-4,
                        (k * 3.7).cos() * 3e-4,
                        (k * 5.3).sin() * 3e-4,
                    ],
                    [
                        (k * 1.1).cos() * 1e-3,
                        (k * 2.9).sin() * 1e-3,
                        (k * 4.3).cos() * 1e-3,
                    ],
                );
                let mut measured =
                    noise * camera_mount.inverse() * base_from_flange.inverse() * target_mount;
                if i == 3 || i == 11 {
                    measured *= flip;
                }
                PosePair::new(base_from_flange, measured)
            })
            .collect();
        (camera_mount, pairs)
    }

    #[test]
    fn every_method_drops_and_names_two_boards_seen_turned_180_degrees() {
        let (truth, pairs) = cell_with_flipped_boards();
        for method in [
            Method::Refined,
            Method::Iterative,
            Method::ClosedForm,
            Method::Tsai,
            Method::Park,
            Method::Horaud,
            Method::Andreff,
            Method::Daniilidis,
            Method::Li,
        ] {
            let options = SolveOptions {
                method,
                ..SolveOptions::default()
            };
            let c = crate::solve(Setup::EyeInHand, &pairs, &options).unwrap();
            assert_eq!(c.dropped, vec![3, 11], "{method:?}");
            let named = c
                .notices
                .iter()
                .filter(|n| n.kind == NoticeKind::DroppedOutliers)
                .count();
            assert_eq!(named, 2, "{method:?}");
            let mm = (c.camera_mount.translation.vector - truth.translation.vector).norm() * 1e3;
            let deg = c
                .camera_mount
                .rotation
                .angle_to(&truth.rotation)
                .to_degrees();
            assert!(mm < 2.0 && deg < 0.2, "{method:?}: {mm:.2} mm, {deg:.3}°");
        }
    }
}
