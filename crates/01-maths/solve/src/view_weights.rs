//! Each sample weighted by how precisely its view fixed its board pose.
//!
//! A board pose estimate is as good as its view: a near board seen whole by 36 tags fixes
//! `T_camera_target` to a fraction of a millimetre, a far one seen at the image's edge by a
//! few tags several times worse. The pose-space noise model has one sigma per group for every
//! sample, so without this the noisy views both pull the answer and stand out as "outliers"
//! (a fixed camera watching a board on the flange sees both kinds in one session). The
//! precision of each view comes from its pose estimate ([`ViewSigma`], its 1-sigma, recorded
//! with the sample); here it becomes a weight relative to the typical view.
//!
//! Depends on the ground floor only.

use std::borrow::Cow;

use handeye_core::setup::{PosePair, ViewSigma};

use crate::diagnostics::median;
use crate::SolveOptions;

impl SolveOptions {
    /// `pairs` as these options weigh them: [`view_weighted`] unless
    /// [`SolveOptions::weigh_views`] is off.
    pub fn weighted<'a>(&self, pairs: &'a [PosePair]) -> Cow<'a, [PosePair]> {
        if self.weigh_views {
            view_weighted(pairs)
        } else {
            Cow::Borrowed(pairs)
        }
    }
}

/// `pairs` with each sample's weight multiplied by its view's precision relative to the
/// typical view's (the median over the samples that record one): with the variance ratio
/// `v = ½ (σ_rot² / median σ_rot² + σ_t² / median σ_t²)` of its [`ViewSigma`], the weight is
/// multiplied by `min(1, 1/v)`. A view noisier than the typical one counts for less in the fit
/// and in every outlier test; a view better than the typical one is not trusted beyond it (the
/// robot's noise, the same at every pose, sets a floor its corners do not show). The weights
/// are folded in and `view_sigma` cleared, so a subset or fold solved again keeps the weights of
/// the whole set. A sample with no valid `view_sigma` (a dataset written by hand, a session
/// recorded before it and resumed since) is taken as a typical view: its weight as given, as
/// every sample's is with `weigh_views` off. `pairs` as given when none records one.
pub fn view_weighted(pairs: &[PosePair]) -> Cow<'_, [PosePair]> {
    let sigmas: Vec<Option<ViewSigma>> = pairs
        .iter()
        .map(|p| p.view_sigma.filter(ViewSigma::is_valid))
        .collect();
    let known: Vec<&ViewSigma> = sigmas.iter().flatten().collect();
    if known.is_empty() {
        return Cow::Borrowed(pairs);
    }
    let typical = |figure: fn(&ViewSigma) -> f64| {
        median(&known.iter().map(|s| figure(s).powi(2)).collect::<Vec<_>>())
    };
    let typical_rotation = typical(|s| s.rotation_deg);
    let typical_translation = typical(|s| s.translation_mm);
    Cow::Owned(
        pairs
            .iter()
            .zip(&sigmas)
            .map(|(pair, sigma)| {
                let factor = sigma.map_or(1.0, |s| {
                    relative_weight(
                        0.5 * (s.rotation_deg.powi(2) / typical_rotation
                            + s.translation_mm.powi(2) / typical_translation),
                    )
                });
                PosePair {
                    weight: pair.weight * factor,
                    view_sigma: None,
                    ..pair.clone()
                }
            })
            .collect(),
    )
}

/// The weight of a measurement whose variance is `ratio` times the typical one's:
/// `min(1, 1/ratio)`, the rule of [`view_weighted`] (a noisier one counts for less, a better one
/// no more than the typical one). 1 for a ratio that is not a positive number.
pub fn relative_weight(ratio: f64) -> f64 {
    if ratio.is_finite() && ratio > 0.0 {
        ratio.recip().min(1.0)
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_core::geometry::Pose;

    fn pair(view_sigma: Option<(f64, f64)>, weight: f64) -> PosePair {
        PosePair {
            weight,
            view_sigma: view_sigma.map(|(r, t)| ViewSigma {
                rotation_deg: r,
                translation_mm: t,
            }),
            ..PosePair::new(Pose::identity(), Pose::identity())
        }
    }

    #[test]
    fn a_noisier_view_weighs_less_and_a_better_one_no_more_than_the_typical() {
        let pairs = vec![
            pair(Some((0.01, 0.2)), 1.0),
            pair(Some((0.01, 0.2)), 2.0),
            // Three times the typical sigma in both groups: a ninth of the weight.
            pair(Some((0.03, 0.6)), 1.0),
            // Half the typical sigma: the typical view's weight, not four times it.
            pair(Some((0.005, 0.1)), 1.0),
            pair(Some((0.01, 0.2)), 1.0),
        ];
        let weighted = view_weighted(&pairs);
        let weights: Vec<f64> = weighted.iter().map(|p| p.weight).collect();
        assert_eq!(weights[0], 1.0);
        assert_eq!(weights[1], 2.0, "a sample's own weight is kept");
        assert!((weights[2] - 1.0 / 9.0).abs() < 1e-12, "{weights:?}");
        assert_eq!(weights[3], 1.0);
        // Folded in once: solving the weighted set again does not weigh it twice.
        assert!(weighted.iter().all(|p| p.view_sigma.is_none()));
        assert!(matches!(view_weighted(&weighted), Cow::Borrowed(_)));
    }

    #[test]
    fn a_sample_of_unknown_precision_is_taken_as_a_typical_view() {
        // A session recorded before `view_sigma` and resumed since: the old samples have none.
        let pairs = vec![
            pair(Some((0.01, 0.2)), 1.0),
            pair(None, 1.0),
            pair(Some((0.01, 0.2)), 1.0),
            pair(Some((f64::NAN, 0.2)), 0.5),
            // Twice the typical sigma: a quarter of the weight, though others record none.
            pair(Some((0.02, 0.4)), 1.0),
        ];
        let weights: Vec<f64> = view_weighted(&pairs).iter().map(|p| p.weight).collect();
        assert_eq!(weights[..4], [1.0, 1.0, 1.0, 0.5]);
        assert!((weights[4] - 0.25).abs() < 1e-12, "{weights:?}");
        // None recorded: the set as given.
        let unknown = vec![pair(None, 1.0), pair(Some((0.0, 0.2)), 1.0)];
        assert!(matches!(view_weighted(&unknown), Cow::Borrowed(_)));
    }
}
