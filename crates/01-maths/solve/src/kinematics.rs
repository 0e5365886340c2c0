//! The arm's own model estimated with the cell (issue #41): the joint zero offsets of a serial
//! arm — or with [`ArmModel::Dh`] every DH parameter of its links (offset, `d`, `a`, `α`) —
//! fitted jointly with both unknowns of `A = X·B·Y` in pose space, from each sample's recorded
//! joint angles and the arm's nominal DH chain ([`DhChain`]). Below, "offsets" reads "chain
//! parameters" under `Dh`.
//!
//! A controller reports `T_base_flange = FK_nominal(q)`; with joint zero offsets `δ` the flange
//! is at `FK(q + δ)`. Each sample's robot pose is the reported one corrected by the change of
//! model, `T_base_flange(δ) = T_reported · FK(q)⁻¹ · FK(q + δ)` (equal to the reported pose at
//! `δ = 0`, so the fit starts exactly where the pose-space solve ended, and a controller whose
//! reading differs slightly from the published model keeps its own reading). The residual and
//! its weights are those of the pose-space refinement (`refine`: rotation and translation rows
//! whitened by the board-pose noise, whose two sigmas are re-estimated with the fit by the same
//! variance component estimation, `noise`); the parameters are the refinement's local
//! perturbation of `X` and `Y` (analytic Jacobian, `refine::sample_rows`) and the free offsets
//! (central differences through the chain: a handful of columns). Levenberg-Marquardt on the
//! normal equations (`lm::minimize_normal`), the covariance `(JᵀJ)⁻¹` scaled by `χ²/dof` at the
//! optimum, as the refinement's.
//!
//! Identifiability, from the normal equations at the start: an offset whose Jacobian column lies
//! in the span of the transforms' columns (its Schur complement against them vanishes) is
//! absorbed by them — on a UR the base joint's (a turn of the base frame about z: the base-side
//! transform) and the last joint's (a turn of the flange about its axis: the flange-side one) —
//! and is held at zero and named (under `Dh` also the base link's `d` and the last link's `d`,
//! `a`, `α`); of the rest, taken in order, one the transforms and the parameters kept before it
//! explain but for [`UNDETERMINED_RATIO`] of its information is undetermined by the recorded
//! configurations, held at zero and named too (under `Dh` on a UR: the `d` of the second and
//! third of the three parallel joints, which move the flange only by the sum of the three).
//! Every other parameter gets its 1σ.
//!
//! Pure maths: no I/O, no clocks; depends on the ground floor (`geometry::dh_link`, `setup`).

use nalgebra::{DMatrix, DVector, SMatrix};

use super::arrow::NormalMatrix;
use super::lm::{minimize_normal, NormalEquations};
use super::noise::Estimator;
use super::refine::{mount_uncertainty, perturbed, sample_residual, sample_rows, variance_factor};
use super::{Axby, EstimateNoise, NoiseModel, PoseNoise, SolveError, SolveOptions, Uncertainty};
use handeye_core::geometry::{dh_link, translation_distance, Pose};
use handeye_core::setup::{PosePair, Setup};

/// A transform parameter count: φ_X, ρ_X, φ_Y, ρ_Y.
const POSE_PARAMS: usize = 12;
/// Step of the central differences in a chain parameter, rad or m.
const OFFSET_STEP_RAD: f64 = 1e-6;
/// An offset whose Jacobian column keeps less than this fraction of its norm after the
/// transforms' columns are projected out is absorbed by them (exactly absorbed columns keep
/// ~1e-9: the differences' round-off).
pub const ABSORBED_RATIO: f64 = 1e-5;
/// A parameter of which the transforms and the parameters kept before it explain all but this
/// fraction of its information (its Schur complement over its own diagonal) is undetermined.
pub const UNDETERMINED_RATIO: f64 = 1e-8;
/// Most rounds of noise re-estimation, each a refit.
const MAX_ROUNDS: usize = 12;

/// A serial arm's nominal standard DH chain, base first: link `i` is
/// `Rz(θ_i) · Tz(d_i) · Tx(a_i) · Rx(α_i)` (m, rad), the convention of `geometry::dh_link`.
#[derive(Debug, Clone, PartialEq)]
pub struct DhChain {
    /// Link offsets `d_i`, m.
    pub d: Vec<f64>,
    /// Link lengths `a_i`, m.
    pub a: Vec<f64>,
    /// Link twists `α_i`, rad.
    pub alpha: Vec<f64>,
}

impl DhChain {
    /// Number of joints.
    pub fn joints(&self) -> usize {
        self.d.len()
    }

    /// `T_base_flange` at `joints` plus `offsets` (rad, one each).
    pub fn forward(&self, joints: &[f64], offsets: &[f64]) -> Pose {
        (0..self.joints()).fold(Pose::identity(), |acc, i| {
            acc * dh_link(joints[i] + offsets[i], self.d[i], self.a[i], self.alpha[i])
        })
    }

    /// `T_base_flange` at `joints` with `corrections` of the chain, per joint in the order of
    /// [`LinkParameter`]: the zero offset (rad), the changes of `d` and `a` (m) and of `α` (rad).
    pub fn forward_corrected(&self, joints: &[f64], corrections: &[[f64; 4]]) -> Pose {
        (0..self.joints()).fold(Pose::identity(), |acc, i| {
            let [theta, d, a, alpha] = corrections[i];
            acc * dh_link(
                joints[i] + theta,
                self.d[i] + d,
                self.a[i] + a,
                self.alpha[i] + alpha,
            )
        })
    }

    /// A flange pose `reported` at `joints` through this chain moved to where the chain with
    /// `corrections` ([`DhChain::forward_corrected`]) puts it:
    /// `T_reported · FK(q)⁻¹ · FK_corrected(q)` (the controller's repeatability noise in
    /// `reported` kept).
    pub fn corrected_flange(
        &self,
        reported: &Pose,
        joints: &[f64],
        corrections: &[[f64; 4]],
    ) -> Pose {
        let zero = vec![0.0; self.joints()];
        reported
            * self.forward(joints, &zero).inverse()
            * self.forward_corrected(joints, corrections)
    }
}

/// Which of the arm's model a fit estimates (`solver.kinematics`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArmModel {
    /// The joint zero offsets alone.
    JointOffsets,
    /// Every DH parameter of every link (zero offset, `d`, `a`, `α`) the data observe.
    Dh,
}

/// One DH parameter of a link, in the order of [`DhChain::forward_corrected`]'s corrections.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkParameter {
    /// The joint's zero offset `θ`, rad.
    ThetaOffset,
    /// The link offset `d`, m.
    D,
    /// The link length `a`, m.
    A,
    /// The link twist `α`, rad.
    Alpha,
}

impl LinkParameter {
    /// In the order of the corrections.
    pub const ALL: [LinkParameter; 4] = [
        LinkParameter::ThetaOffset,
        LinkParameter::D,
        LinkParameter::A,
        LinkParameter::Alpha,
    ];

    /// The DH table's name (`theta_offset`, `d`, `a`, `alpha`).
    pub fn name(self) -> &'static str {
        match self {
            LinkParameter::ThetaOffset => "theta_offset",
            LinkParameter::D => "d",
            LinkParameter::A => "a",
            LinkParameter::Alpha => "alpha",
        }
    }

    /// Its place in a link's corrections `[θ, d, a, α]` ([`ArmFit::corrections`]).
    pub fn index(self) -> usize {
        self as usize
    }
}

/// One link length or twist correction as fitted (`ArmModel::Dh`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkCorrection {
    /// The joint whose link it is, 0-based from the base.
    pub joint: usize,
    /// `d`, `a` or `α`.
    pub parameter: LinkParameter,
    /// The correction (true minus published), m or rad; zero unless estimated.
    pub value: f64,
    /// Estimated (its 1σ in `value`'s unit), absorbed or undetermined.
    pub status: OffsetStatus,
}

/// One sample for the arm's model: the pose pair (its reported `T_base_flange`) and the joint
/// angles the arm stood at (rad, base first).
#[derive(Debug, Clone, PartialEq)]
pub struct ArmSample {
    /// The pose pair as recorded.
    pub pair: PosePair,
    /// The joints, rad.
    pub joints: Vec<f64>,
}

/// What became of one joint's zero offset (or of a link correction, [`LinkCorrection`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OffsetStatus {
    /// Estimated, with its 1σ (rad; a link length's in m).
    Estimated {
        /// 1σ, rad (a link length's: m).
        sigma_rad: f64,
    },
    /// No data can tell it from a transform: held at zero, absorbed by the transform of this
    /// YAML key (`T_base_target`, `T_flange_camera`, ...), or by both together.
    Absorbed {
        /// The key of the transform that absorbs it; `None`: the two together.
        by: Option<&'static str>,
    },
    /// The recorded configurations do not determine it (with the others): held at zero.
    Undetermined,
}

/// One joint's zero offset as fitted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointOffset {
    /// The joint, 0-based from the base.
    pub joint: usize,
    /// The offset, rad (the true joint angle is the reported one plus this); zero unless
    /// estimated.
    pub offset_rad: f64,
    /// Estimated, absorbed or undetermined.
    pub status: OffsetStatus,
}

/// The joint fit of the two transforms and the arm's joint offsets.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmFit {
    /// Which setup.
    pub setup: Setup,
    /// The camera mount (`T_flange_camera` or `T_base_camera`) with the offsets estimated.
    pub camera_mount: Pose,
    /// The target mount (`T_base_target` or `T_flange_target`).
    pub target_mount: Pose,
    /// The transforms' 1σ, the offsets' uncertainty included (marginal); `None` if singular.
    pub uncertainty: Option<Uncertainty>,
    /// Every joint's offset, base first.
    pub offsets: Vec<JointOffset>,
    /// What was estimated.
    pub model: ArmModel,
    /// With [`ArmModel::Dh`]: every link's `d`, `a` and `α` corrections, base first; empty with
    /// the offsets alone.
    pub links: Vec<LinkCorrection>,
    /// The board-pose noise the fit ended with.
    pub noise: PoseNoise,
    /// Translation residual RMS of the fit, mm, with the offsets and without them (the
    /// pose-space fit of the same samples, the start).
    pub translation_rms_mm: [f64; 2],
    /// Rotation residual RMS, degrees, with and without the offsets.
    pub rotation_rms_deg: [f64; 2],
    /// Levenberg-Marquardt met its tolerance in the last round.
    pub converged: bool,
    /// Σ of the whitened squared residuals under the board-pose noise the fit ended with: with
    /// the estimated offsets, and of the best fit of the two transforms alone (offsets zero).
    pub chi2: [f64; 2],
    /// Samples fitted.
    pub samples: usize,
}

/// The 99 % quantile of χ² with 1, 2, … 30 degrees of freedom (an arm's joint offsets, or its
/// DH link corrections beside them; scipy's `chi2.ppf(0.99, k)`).
const CHI2_99: [f64; 30] = [
    6.635, 9.210, 11.345, 13.277, 15.086, 16.812, 18.475, 20.090, 21.666, 23.209, 24.725, 26.217,
    27.688, 29.141, 30.578, 32.000, 33.409, 34.805, 36.191, 37.566, 38.932, 40.289, 41.638, 42.980,
    44.314, 45.642, 46.963, 48.278, 49.588, 50.892,
];

/// How much `k` free numbers lower χ² by noise alone in 99 % of cells, `χ²(k; 0.99)`;
/// infinite (the data never choose them) for none or more than the table holds.
fn chi2_99(k: usize) -> f64 {
    k.checked_sub(1)
        .and_then(|k| CHI2_99.get(k))
        .copied()
        .unwrap_or(f64::INFINITY)
}

impl ArmFit {
    /// Parameters estimated (neither absorbed nor undetermined): offsets and link corrections.
    pub fn estimated(&self) -> usize {
        self.offsets
            .iter()
            .map(|o| o.status)
            .chain(self.links.iter().map(|l| l.status))
            .filter(|s| matches!(s, OffsetStatus::Estimated { .. }))
            .count()
    }

    /// By how much the estimated offsets lower χ² beyond what `k` free numbers would lower it
    /// by noise alone in 99 % of cells: `χ²_without − χ²_with − χ²(k; 0.99)`, the likelihood-ratio
    /// test of the nested models at 1 % (the χ² under the board-pose noise the fit ended with).
    /// Positive: the data choose the arm's model. (The information criterion `k·ln N` asks
    /// ~21 of four offsets at 30 poses and let eye-to-hand cells whose offsets cost 0.4–0.9 mm
    /// go without; noise alone passes this test once in a hundred cells.)
    pub fn model_choice_margin(&self) -> f64 {
        self.chi2[1] - self.chi2[0] - self.model_choice_threshold()
    }

    /// How much `k` free numbers lower χ² by noise alone in 99 % of cells, `χ²(k; 0.99)`;
    /// infinite (the data never choose) with no offset estimated or more than the table holds.
    pub fn model_choice_threshold(&self) -> f64 {
        chi2_99(self.estimated())
    }

    /// Every joint's corrections in the order of [`LinkParameter`] (zero where not estimated),
    /// for [`DhChain::forward_corrected`].
    pub fn corrections(&self) -> Vec<[f64; 4]> {
        let mut out: Vec<[f64; 4]> = self
            .offsets
            .iter()
            .map(|o| [o.offset_rad, 0.0, 0.0, 0.0])
            .collect();
        for l in &self.links {
            out[l.joint][l.parameter.index()] = l.value;
        }
        out
    }

    /// A sample's robot pose corrected by the fitted model ([`DhChain::corrected_flange`]).
    pub fn corrected_flange(&self, chain: &DhChain, sample: &ArmSample) -> Pose {
        chain.corrected_flange(
            &sample.pair.base_from_flange,
            &sample.joints,
            &self.corrections(),
        )
    }
}

/// Whether an arm's DH link corrections are worth estimating beside its joint offsets: what
/// `solver.kinematics: auto` asks before it keeps them ([`ArmRefit::links_choice`]). Both of:
///
/// * **The data need them**: the test of the nested models at 1 %, both χ² under the DH fit's
///   board-pose noise and divided by the DH fit's χ²/dof, `(χ²_offsets − χ²_dh) / (χ²_dh/dof) >
///   χ²(k; 0.99)` with `k` the link corrections estimated ([`LinksChoice::fit_margin`]; the
///   F test, with the χ² quantile for F's at the ~150 degrees of freedom of a session). The
///   division makes it a test of the residuals, not of the noise given: a cell whose board-pose
///   noise is given ten times too large (a rendered sim cell's 0.2 mm) would otherwise never
///   need the links, and one given too small would always.
/// * **The answer is better with them, not only the fit**: the offsets' answer's expected squared
///   error (its variance plus its squared bias, the bias read from how far it lies from the DH
///   answer: `E|Δ|² = b² + σ²_dh − σ²_offsets` when the DH model holds) exceeds the DH answer's
///   variance, `|Δ|² > 2·(σ²_dh − σ²_offsets)`, over both transforms' translations
///   ([`LinksChoice::answer_margin_mm2`]). Without it a plan that determines the links poorly
///   (the shipped eye-to-hand cell at five times its board noise: transforms' 1σ 3.1 mm with the
///   links free) would trade a bias of about a millimetre for three of scatter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinksChoice {
    /// χ² under the DH fit's noise: with the link corrections, with the offsets alone.
    pub chi2: [f64; 2],
    /// Parameters the link corrections add (the test's degrees of freedom).
    pub added: usize,
    /// `|Δ|²`: the squared translation difference of the two answers, summed over both
    /// transforms, mm².
    pub difference_mm2: f64,
    /// `σ²_dh − σ²_offsets` of the translations, summed over both transforms, mm² (infinite when
    /// either fit has no covariance).
    pub added_variance_mm2: f64,
    /// The DH fit's χ²/dof: the residuals' variance against the noise they were weighed with.
    pub variance_factor: f64,
}

impl LinksChoice {
    /// The choice between `offsets` (the offsets' fit under its own noise: the answer kept
    /// without the links), `offsets_at_dh_noise` (the same under `links`' noise) and `links`.
    fn of(offsets: &ArmFit, offsets_at_dh_noise: &ArmFit, links: &ArmFit) -> LinksChoice {
        let squared_mm = |a: &Pose, b: &Pose| (translation_distance(a, b) * 1e3).powi(2);
        let added_variance_mm2 = match (&offsets.uncertainty, &links.uncertainty) {
            (Some(o), Some(l)) => {
                l.camera_mount.translation_mm.powi(2) - o.camera_mount.translation_mm.powi(2)
                    + l.target_mount.translation_mm.powi(2)
                    - o.target_mount.translation_mm.powi(2)
            }
            _ => f64::INFINITY,
        };
        let dof = (6 * links.samples).saturating_sub(POSE_PARAMS + links.estimated());
        let variance_factor = links.chi2[0] / dof as f64;
        LinksChoice {
            variance_factor: if variance_factor.is_finite() && variance_factor > 0.0 {
                variance_factor
            } else {
                1.0
            },
            chi2: [links.chi2[0], offsets_at_dh_noise.chi2[0]],
            added: links
                .estimated()
                .saturating_sub(offsets_at_dh_noise.estimated()),
            difference_mm2: squared_mm(&offsets.camera_mount, &links.camera_mount)
                + squared_mm(&offsets.target_mount, &links.target_mount),
            added_variance_mm2,
        }
    }

    /// `(χ²_offsets − χ²_dh) / (χ²_dh/dof)`: how much the links lower the residuals, in units of
    /// what one free number lowers them by noise alone.
    pub fn statistic(&self) -> f64 {
        (self.chi2[1] - self.chi2[0]) / self.variance_factor
    }

    /// [`LinksChoice::statistic`] `− χ²(k; 0.99)`: positive when the data need the link
    /// corrections.
    pub fn fit_margin(&self) -> f64 {
        self.statistic() - self.threshold()
    }

    /// `χ²(k; 0.99)` for the `k` parameters the links add.
    pub fn threshold(&self) -> f64 {
        chi2_99(self.added)
    }

    /// `|Δ|² − 2·(σ²_dh − σ²_offsets)`, mm²: positive when the offsets' answer is expected to
    /// be further from the truth than the DH answer.
    pub fn answer_margin_mm2(&self) -> f64 {
        self.difference_mm2 - 2.0 * self.added_variance_mm2
    }

    /// Both tests pass: `auto` keeps the DH link corrections.
    pub fn chosen(&self) -> bool {
        self.fit_margin() > 0.0 && self.answer_margin_mm2() > 0.0
    }
}

/// An arm fit as made, to be made again without one sample: a held-out sample predicted
/// through an arm model fitted to it too would owe its small error partly to itself (the
/// verdict's held-out folds refit it: `verdict::held_out_refitting`).
#[derive(Debug, Clone)]
pub struct ArmRefit {
    /// The layout.
    pub setup: Setup,
    /// What is estimated.
    pub model: ArmModel,
    /// The published chain.
    pub chain: DhChain,
    /// Every sample, in the order of the session's pairs.
    pub samples: Vec<ArmSample>,
    /// Samples the start left out of the fit (its outliers).
    pub dropped: Vec<usize>,
    /// The start: `(camera mount, target mount)`.
    pub start: (Pose, Pose),
    /// The board-pose noise the fit weighs with.
    pub noise: NoiseModel,
    /// The solve's options.
    pub options: SolveOptions,
}

impl ArmRefit {
    /// The fit of every sample but the start's outliers and `left_out` (none: the fit of all),
    /// from the start.
    pub fn fit_without(&self, left_out: Option<usize>) -> Result<ArmFit, SolveError> {
        let kept: Vec<ArmSample> = self
            .samples
            .iter()
            .enumerate()
            .filter(|(i, _)| Some(*i) != left_out && !self.dropped.contains(i))
            .map(|(_, s)| s.clone())
            .collect();
        fit_arm(
            self.model,
            self.setup,
            &self.chain,
            &kept,
            (&self.start.0, &self.start.1),
            self.noise,
            &self.options,
        )
    }

    /// Every sample's flange pose corrected by `fit`.
    pub fn corrected_flanges(&self, fit: &ArmFit) -> Vec<Pose> {
        self.samples
            .iter()
            .map(|s| fit.corrected_flange(&self.chain, s))
            .collect()
    }

    /// Whether the DH link corrections earn their place beside the joint offsets `offsets` (this
    /// refit's fit, with [`ArmModel::JointOffsets`]): the DH fit of the same samples and the
    /// [`LinksChoice`] between the two. Returns the DH refit (for the held-out folds), its fit
    /// and the choice.
    pub fn links_choice(
        &self,
        offsets: &ArmFit,
    ) -> Result<(ArmRefit, ArmFit, LinksChoice), SolveError> {
        let dh = ArmRefit {
            model: ArmModel::Dh,
            ..self.clone()
        };
        let links = dh.fit_without(None)?;
        // The nested test compares χ² under one noise, the larger model's estimate: the offsets'
        // own estimate swells with the residuals the links would explain.
        let noise = links.noise.model();
        let offsets_at_that_noise = ArmRefit {
            model: ArmModel::JointOffsets,
            noise,
            options: SolveOptions {
                noise,
                estimate_noise: EstimateNoise::NONE,
                ..self.options.clone()
            },
            ..self.clone()
        }
        .fit_without(None)?;
        let choice = LinksChoice::of(offsets, &offsets_at_that_noise, &links);
        Ok((dh, links, choice))
    }

    /// Every sample's flange pose corrected by the model fitted without sample `left_out`.
    pub fn flanges_without(&self, left_out: usize) -> Result<Vec<Pose>, String> {
        let fit = self
            .fit_without(Some(left_out))
            .map_err(|e| e.to_string())?;
        Ok(self.corrected_flanges(&fit))
    }
}

/// A sample prepared for the fit: its measured `A`, its correction `T_reported · FK(q)⁻¹`, its
/// joints, and its scale `sqrt(weight)`.
struct Prepared {
    a: Pose,
    correction: Pose,
    joints: Vec<f64>,
    scale: f64,
}

/// A parameter of the chain: the joint and the [`LinkParameter`] index.
type Param = (usize, usize);

/// The fit's problem for [`minimize_normal`]: parameters `[δX/δY perturbation, free chain
/// parameters]` around an anchor that moves to every accepted point.
struct Problem<'a> {
    setup: Setup,
    chain: &'a DhChain,
    samples: &'a [Prepared],
    /// The chain's free parameters, in parameter order.
    free: &'a [Param],
    noise: NoiseModel,
    anchor: Axby,
    anchor_corrections: Vec<[f64; 4]>,
    delta: DVector<f64>,
}

/// The normal equations at one point, split by group of rows (for the noise estimate).
struct Linearised {
    rotation: DMatrix<f64>,
    translation: DMatrix<f64>,
    gradient: DVector<f64>,
    squares: [f64; 2],
}

impl Problem<'_> {
    fn params(&self) -> usize {
        POSE_PARAMS + self.free.len()
    }

    fn current(&self) -> (Axby, Vec<[f64; 4]>) {
        let pose = perturbed(
            &self.anchor,
            &self.delta.fixed_rows::<POSE_PARAMS>(0).into_owned(),
        );
        let mut corrections = self.anchor_corrections.clone();
        for (k, &(j, p)) in self.free.iter().enumerate() {
            corrections[j][p] += self.delta[POSE_PARAMS + k];
        }
        (pose, corrections)
    }

    fn b(&self, sample: &Prepared, corrections: &[[f64; 4]]) -> Pose {
        self.setup.chain_b(
            &(sample.correction * self.chain.forward_corrected(&sample.joints, corrections)),
        )
    }

    fn weights(&self, sample: &Prepared) -> (f64, f64) {
        (
            sample.scale / self.noise.rotation_sigma_rad,
            sample.scale / self.noise.translation_sigma_m,
        )
    }

    /// Residual and Jacobian (6 × params) of every sample at the current point, with the
    /// chain parameters of `columns` as the last columns.
    fn linearise(&self, columns: &[Param]) -> Linearised {
        let (s, offsets) = self.current();
        let p = POSE_PARAMS + columns.len();
        let mut lin = Linearised {
            rotation: DMatrix::zeros(p, p),
            translation: DMatrix::zeros(p, p),
            gradient: DVector::zeros(p),
            squares: [0.0; 2],
        };
        for sample in self.samples {
            let (kr, kt) = self.weights(sample);
            let b = self.b(sample, &offsets);
            let (e, pose_rows) = sample_rows(&s, &sample.a, &b, kr, kt);
            let mut j = DMatrix::<f64>::zeros(6, p);
            j.view_mut((0, 0), (6, POSE_PARAMS)).copy_from(&pose_rows);
            for (k, &(joint, p)) in columns.iter().enumerate() {
                let mut shifted = offsets.clone();
                shifted[joint][p] += OFFSET_STEP_RAD;
                let plus = sample_residual(&s, &sample.a, &self.b(sample, &shifted), kr, kt);
                shifted[joint][p] -= 2.0 * OFFSET_STEP_RAD;
                let minus = sample_residual(&s, &sample.a, &self.b(sample, &shifted), kr, kt);
                j.set_column(POSE_PARAMS + k, &((plus - minus) / (2.0 * OFFSET_STEP_RAD)));
            }
            let (jr, jt) = (j.rows(0, 3), j.rows(3, 3));
            lin.rotation += jr.tr_mul(&jr);
            lin.translation += jt.tr_mul(&jt);
            lin.gradient += j.tr_mul(&DVector::from_column_slice(e.as_slice()));
            lin.squares[0] += e.fixed_rows::<3>(0).norm_squared();
            lin.squares[1] += e.fixed_rows::<3>(3).norm_squared();
        }
        lin
    }

    /// Σ r² at the current point.
    fn total_cost(&self) -> f64 {
        let (s, offsets) = self.current();
        self.samples
            .iter()
            .map(|sample| {
                let (kr, kt) = self.weights(sample);
                sample_residual(&s, &sample.a, &self.b(sample, &offsets), kr, kt).norm_squared()
            })
            .sum()
    }

    /// Unweighted residual RMS (rad, m) at the current point.
    fn rms(&self) -> (f64, f64) {
        let (s, offsets) = self.current();
        let n = self.samples.len().max(1) as f64;
        let (mut r2, mut t2) = (0.0, 0.0);
        for sample in self.samples {
            let e = sample_residual(&s, &sample.a, &self.b(sample, &offsets), 1.0, 1.0);
            r2 += e.fixed_rows::<3>(0).norm_squared();
            t2 += e.fixed_rows::<3>(3).norm_squared();
        }
        ((r2 / n).sqrt(), (t2 / n).sqrt())
    }
}

impl NormalEquations for Problem<'_> {
    fn normal_equations(&mut self) -> Option<(NormalMatrix, DVector<f64>, f64)> {
        let lin = self.linearise(self.free);
        let cost = lin.squares[0] + lin.squares[1];
        if !cost.is_finite() {
            return None;
        }
        Some((
            NormalMatrix::Dense(&lin.rotation + &lin.translation),
            lin.gradient,
            cost,
        ))
    }

    fn cost(&mut self) -> Option<f64> {
        let cost = self.total_cost();
        cost.is_finite().then_some(cost)
    }

    fn params_mut(&mut self) -> &mut DVector<f64> {
        &mut self.delta
    }

    fn accepted(&mut self) {
        let (pose, corrections) = self.current();
        self.anchor = pose;
        self.anchor_corrections = corrections;
        self.delta.fill(0.0);
    }
}

/// Samples at `joints` (rad, one list per sample) of an arm reporting its flange through
/// `chain`, each board pose exactly as `solution` predicts it: the point a future solve is
/// linearised at, for planning.
fn predicted_samples(
    setup: Setup,
    chain: &DhChain,
    joints: &[Vec<f64>],
    solution: &Axby,
) -> Vec<Prepared> {
    let zero = vec![0.0; chain.joints()];
    joints
        .iter()
        .map(|q| Prepared {
            a: solution.x * setup.chain_b(&chain.forward(q, &zero)) * solution.y,
            correction: Pose::identity(),
            joints: q.clone(),
            scale: 1.0,
        })
        .collect()
}

/// The whitened information `JᵀJ` that samples at `joints` (rad, one list per sample, each
/// predicted exactly at the mounts `(camera, target)`) give of the two transforms with the
/// joint zero offsets of the joints `free` estimated beside them: `(12 + k)²`, the transforms'
/// 12 parameters first (as [`crate::refine::sample_information`]), then one per joint of
/// `free`. The inverse's 12 × 12 block is the transforms' covariance with those offsets free:
/// what a plan that estimates the arm's offsets is scored by (`plan::nbv`).
pub fn offsets_information(
    setup: Setup,
    chain: &DhChain,
    joints: &[Vec<f64>],
    (camera, target): (&Pose, &Pose),
    noise: NoiseModel,
    free: &[usize],
) -> DMatrix<f64> {
    let columns: Vec<Param> = free.iter().map(|&j| (j, 0)).collect();
    let anchor = Axby::from_mounts(camera, target);
    let samples = predicted_samples(setup, chain, joints, &anchor);
    let problem = Problem {
        setup,
        chain,
        samples: &samples,
        free: &columns,
        noise,
        anchor,
        anchor_corrections: vec![[0.0; 4]; chain.joints()],
        delta: DVector::zeros(POSE_PARAMS + columns.len()),
    };
    let lin = problem.linearise(&columns);
    lin.rotation + lin.translation
}

/// The joints whose zero offsets samples at `joints` determine beside the two transforms (the
/// identifiability analysis of [`fit_arm`]: those the transforms absorb, on a UR the base and
/// last joints, and those the configurations do not move enough are left out), at the mounts
/// `(camera, target)`.
pub fn estimable_offsets(
    setup: Setup,
    chain: &DhChain,
    joints: &[Vec<f64>],
    mounts: (&Pose, &Pose),
    noise: NoiseModel,
) -> Vec<usize> {
    let all: Vec<usize> = (0..chain.joints()).collect();
    let information = offsets_information(setup, chain, joints, mounts, noise, &all);
    identifiability(setup, &information, all.len())
        .into_iter()
        .enumerate()
        .filter(|(_, status)| status.is_none())
        .map(|(j, _)| j)
        .collect()
}

/// Which chain parameters the data can estimate, from the information `n` (whitened `JᵀJ`, the
/// 12 transform parameters then one column per candidate parameter) at the start: each
/// candidate's status, `None` for the free ones.
fn identifiability(setup: Setup, n: &DMatrix<f64>, joints: usize) -> Vec<Option<OffsetStatus>> {
    let (camera_key, target_key) = setup.unknown_names();
    // What of column `c` remains after projecting out the columns `span`, as a fraction.
    let remains = |c: usize, span: &[usize]| -> f64 {
        let own = n[(c, c)];
        if own <= 0.0 {
            return 0.0;
        }
        let k = span.len();
        let nss = DMatrix::from_fn(k, k, |i, j| n[(span[i], span[j])]);
        let nsc = DVector::from_fn(k, |i, _| n[(span[i], c)]);
        let explained = nss.cholesky().map_or(0.0, |ch| nsc.dot(&ch.solve(&nsc)));
        ((own - explained).max(0.0) / own).sqrt()
    };
    let x: Vec<usize> = (0..6).collect();
    let y: Vec<usize> = (6..12).collect();
    let xy: Vec<usize> = (0..12).collect();
    let mut status: Vec<Option<OffsetStatus>> = (0..joints)
        .map(|j| {
            let c = POSE_PARAMS + j;
            if remains(c, &xy) >= ABSORBED_RATIO {
                return None;
            }
            let by = if remains(c, &x) < ABSORBED_RATIO {
                Some(camera_key)
            } else if remains(c, &y) < ABSORBED_RATIO {
                Some(target_key)
            } else {
                None
            };
            Some(OffsetStatus::Absorbed { by })
        })
        .collect();
    // Of the rest, in order, hold each one that the transforms and the parameters kept before
    // it already explain (all but `UNDETERMINED_RATIO` of its information): of a combination the
    // recorded configurations do not determine (the `d` of parallel joints, which only move the
    // flange by their sum) the first member is kept and the later ones held, whatever the noise
    // of the poses this is judged on.
    let mut kept = xy;
    for (c, held) in status.iter_mut().enumerate() {
        if held.is_some() {
            continue;
        }
        let column = POSE_PARAMS + c;
        if remains(column, &kept).powi(2) < UNDETERMINED_RATIO {
            *held = Some(OffsetStatus::Undetermined);
        } else {
            kept.push(column);
        }
    }
    status
}

/// Fits the two transforms and the joint zero offsets the data determine, started from the
/// pose-space answer `start` (camera mount, target mount) and its board-pose noise `noise`, for
/// `samples` of `setup` and the arm's nominal `chain`. `options` says which sigmas are estimated
/// (as the pose-space solve's). Pass the samples the pose-space solve kept (its outliers out).
///
/// Errors: a sample whose joint count is not the chain's, fewer than three samples, or a fit
/// whose residuals break down.
pub fn fit_joint_offsets(
    setup: Setup,
    chain: &DhChain,
    samples: &[ArmSample],
    start: (&Pose, &Pose),
    noise: NoiseModel,
    options: &SolveOptions,
) -> Result<ArmFit, SolveError> {
    fit_arm(
        ArmModel::JointOffsets,
        setup,
        chain,
        samples,
        start,
        noise,
        options,
    )
}

/// Each sample prepared for the fit, checked against the chain's joint count, at its weight as
/// `options` weigh it (each view at its precision, [`SolveOptions::weighted`], as the pose-space
/// solve weighs it: a far view taken as a typical one would read its noise as the arm's error).
fn prepare(
    chain: &DhChain,
    samples: &[ArmSample],
    options: &SolveOptions,
) -> Result<Vec<Prepared>, SolveError> {
    if samples.len() < 3 {
        return Err(SolveError::TooFewSamples {
            found: samples.len(),
            required: 3,
        });
    }
    let joints = chain.joints();
    let zero = vec![0.0; joints];
    let pairs: Vec<PosePair> = samples.iter().map(|s| s.pair.clone()).collect();
    let weighted = options.weighted(&pairs);
    samples
        .iter()
        .zip(weighted.iter())
        .enumerate()
        .map(|(index, (s, weighted))| {
            if s.joints.len() != joints || s.joints.iter().any(|q| !q.is_finite()) {
                return Err(SolveError::ArmJoints {
                    index,
                    id: s.pair.id.clone(),
                    found: s.joints.len(),
                    expected: joints,
                });
            }
            Ok(Prepared {
                a: s.pair.camera_from_target,
                correction: s.pair.base_from_flange * chain.forward(&s.joints, &zero).inverse(),
                joints: s.joints.clone(),
                scale: weighted.weight.sqrt(),
            })
        })
        .collect()
}

/// [`fit_joint_offsets`] for the parameters `model` names: with [`ArmModel::Dh`] every link's
/// zero offset, `d`, `a` and `α` are candidates, and the identifiability analysis (module docs)
/// holds those the transforms absorb (on a UR: the base link's `θ` and `d`, the last link's
/// four) and those the recorded configurations do not determine (on a UR: two of the `d` of the
/// three parallel joints, whose sum alone moves the flange).
pub fn fit_arm(
    model: ArmModel,
    setup: Setup,
    chain: &DhChain,
    samples: &[ArmSample],
    start: (&Pose, &Pose),
    noise: NoiseModel,
    options: &SolveOptions,
) -> Result<ArmFit, SolveError> {
    let prepared = prepare(chain, samples, options)?;
    let joints = chain.joints();
    let zero = vec![[0.0; 4]; joints];
    let candidates: Vec<Param> = match model {
        ArmModel::JointOffsets => (0..joints).map(|j| (j, 0)).collect(),
        ArmModel::Dh => (0..joints)
            .flat_map(|j| (0..4).map(move |p| (j, p)))
            .collect(),
    };
    let problem = Problem {
        setup,
        chain,
        samples: &prepared,
        free: &[],
        noise,
        anchor: Axby::from_mounts(start.0, start.1),
        anchor_corrections: zero.clone(),
        delta: DVector::zeros(POSE_PARAMS),
    };
    let before = problem.rms();
    // Which parameters the transforms absorb is a property of the chain and the configurations:
    // judged on the published model's poses (no reading noise, which would blur an exact
    // absorption by its own few 1e-5).
    let structural: Vec<Prepared> = prepared
        .iter()
        .map(|p| Prepared {
            a: p.a,
            correction: Pose::identity(),
            joints: p.joints.clone(),
            scale: p.scale,
        })
        .collect();
    let at_start = Problem {
        samples: &structural,
        anchor: Axby::from_mounts(start.0, start.1),
        delta: DVector::zeros(POSE_PARAMS),
        anchor_corrections: zero.clone(),
        ..problem
    }
    .linearise(&candidates);
    let status = identifiability(
        setup,
        &(&at_start.rotation + &at_start.translation),
        candidates.len(),
    );
    let free: Vec<Param> = candidates
        .iter()
        .zip(&status)
        .filter(|(_, s)| s.is_none())
        .map(|(c, _)| *c)
        .collect();
    let mut problem = Problem {
        free: &free,
        delta: DVector::zeros(POSE_PARAMS + free.len()),
        ..problem
    };
    let mut estimator = Estimator::new(samples.len(), options).starting_at(noise);
    let mut converged = false;
    for _ in 0..MAX_ROUNDS {
        problem.noise = estimator.noise();
        converged = minimize_normal(&mut problem)?.converged;
        let lin = problem.linearise(&free);
        let groups = groups(&lin, 3.0 * samples.len() as f64);
        if estimator.step_with(groups) {
            break;
        }
    }
    let lin = problem.linearise(&free);
    let chi2 = lin.squares[0] + lin.squares[1];
    let factor = variance_factor(chi2, (6 * samples.len()).saturating_sub(problem.params()));
    let covariance = (&lin.rotation + &lin.translation)
        .try_inverse()
        .map(|inverse| inverse * factor);
    let (solution, corrections) = problem.current();
    let uncertainty = covariance.as_ref().map(|c| {
        let block: SMatrix<f64, 12, 12> = c.fixed_view::<12, 12>(0, 0).into_owned();
        mount_uncertainty(&solution, &block, factor)
    });
    let after = problem.rms();
    // The two transforms alone, refitted under the same noise: the model without the arm's,
    // against which the data choose (`ArmFit::model_choice_margin`).
    let chi2_with = problem.total_cost();
    let mut alone = Problem {
        setup,
        chain,
        samples: &prepared,
        free: &[],
        noise: problem.noise,
        anchor: Axby::from_mounts(start.0, start.1),
        anchor_corrections: zero,
        delta: DVector::zeros(POSE_PARAMS),
    };
    minimize_normal(&mut alone)?;
    let chi2_without = alone.total_cost();
    // Each candidate's status: held as the analysis said, or estimated with its 1σ.
    let status_of = |param: Param| -> OffsetStatus {
        let at = candidates.iter().position(|&c| c == param);
        match at.and_then(|i| status[i]) {
            Some(held) => held,
            None => {
                let k = POSE_PARAMS + free.iter().position(|&f| f == param).unwrap_or(0);
                OffsetStatus::Estimated {
                    sigma_rad: covariance
                        .as_ref()
                        .map_or(f64::NAN, |c| c[(k, k)].max(0.0).sqrt()),
                }
            }
        }
    };
    let offsets = (0..joints)
        .map(|j| JointOffset {
            joint: j,
            offset_rad: corrections[j][0],
            status: status_of((j, 0)),
        })
        .collect();
    let links = match model {
        ArmModel::JointOffsets => Vec::new(),
        ArmModel::Dh => (0..joints)
            .flat_map(|j| LinkParameter::ALL[1..].iter().map(move |&p| (j, p)))
            .map(|(j, parameter)| LinkCorrection {
                joint: j,
                parameter,
                value: corrections[j][parameter.index()],
                status: status_of((j, parameter.index())),
            })
            .collect(),
    };
    let (camera_mount, target_mount) = solution.to_mounts();
    Ok(ArmFit {
        setup,
        camera_mount,
        target_mount,
        uncertainty,
        offsets,
        model,
        links,
        noise: estimator.outcome(),
        translation_rms_mm: [after.1 * 1e3, before.1 * 1e3],
        rotation_rms_deg: [after.0.to_degrees(), before.0.to_degrees()],
        converged,
        chi2: [chi2_with, chi2_without],
        samples: samples.len(),
    })
}

/// The two groups' `(Σ r², redundancy)` of variance component estimation (see
/// `refine::group_redundancy`) from normal equations split by group, `rows` rows in each.
fn groups(lin: &Linearised, rows: f64) -> Option<[(f64, f64); 2]> {
    let inverse = (&lin.rotation + &lin.translation).cholesky()?.inverse();
    let share = |group: &DMatrix<f64>| inverse.component_mul(group).sum();
    Some([
        (lin.squares[0], rows - share(&lin.rotation)),
        (lin.squares[1], rows - share(&lin.translation)),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_core::geometry::{pose_from_rotvec, translation_distance};
    use nalgebra::Vector3;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};
    use rand_distr::{Distribution, Normal};

    /// The UR10e's published DH chain.
    fn ur10e() -> DhChain {
        use std::f64::consts::FRAC_PI_2;
        DhChain {
            d: vec![0.1807, 0.0, 0.0, 0.17415, 0.11985, 0.11655],
            a: vec![0.0, -0.6127, -0.57155, 0.0, 0.0, 0.0],
            alpha: vec![FRAC_PI_2, 0.0, 0.0, FRAC_PI_2, -FRAC_PI_2, 0.0],
        }
    }

    #[test]
    fn chain_forward_shifts_joints_by_offsets() {
        let chain = ur10e();
        let q = [0.3, -1.2, 1.4, -0.8, 1.1, 0.4];
        let d = [0.01, -0.02, 0.0, 0.005, 0.0, 0.03];
        let shifted: Vec<f64> = q.iter().zip(&d).map(|(a, b)| a + b).collect();
        let a = chain.forward(&q, &d);
        let b = chain.forward(&shifted, &[0.0; 6]);
        assert!(translation_distance(&a, &b) < 1e-15);
    }

    /// Samples of an eye-in-hand cell whose arm has `offsets` (rad): reported through the
    /// nominal chain (with reading noise), seen through the true one, board poses with Gaussian
    /// noise.
    fn cell(seed: u64, offsets: [f64; 6], n: usize) -> (Vec<ArmSample>, Pose, Pose) {
        let chain = ur10e();
        let mut rng = StdRng::seed_from_u64(seed);
        let x = pose_from_rotvec(
            Vector3::new(0.03, -0.07, 0.04),
            Vector3::new(0.0, 0.0, 1.57),
        );
        let y = pose_from_rotvec(Vector3::new(0.5, -0.15, 0.0), Vector3::new(0.0, 0.0, 0.3));
        let noise_r = Normal::new(0.0, 0.02f64.to_radians()).unwrap();
        let noise_t = Normal::new(0.0, 0.1e-3).unwrap();
        let samples = (0..n)
            .map(|_| {
                let q: Vec<f64> = (0..6).map(|_| rng.random_range(-1.5..1.5)).collect();
                // The controller's reading, with its repeatability (0.02 mm, 0.002°): the
                // absorbed offsets must be found all the same.
                let reading = pose_from_rotvec(
                    Vector3::from_fn(|_, _| 2e-5 * rng.random_range(-1.0..1.0)),
                    Vector3::from_fn(|_, _| 3.5e-5 * rng.random_range(-1.0..1.0)),
                );
                let reported = chain.forward(&q, &[0.0; 6]) * reading;
                let truth = chain.forward(&q, &offsets);
                let seen = x.inverse() * truth.inverse() * y;
                let dn = pose_from_rotvec(
                    Vector3::from_fn(|_, _| noise_t.sample(&mut rng)),
                    Vector3::from_fn(|_, _| noise_r.sample(&mut rng)),
                );
                ArmSample {
                    pair: PosePair::new(reported, seen * dn),
                    joints: q,
                }
            })
            .collect();
        (samples, x, y)
    }

    #[test]
    fn base_and_last_offsets_are_absorbed_and_the_middle_ones_found() {
        let deg = 1f64.to_radians();
        let offsets = [0.0, 0.03 * deg, -0.04 * deg, 0.05 * deg, -0.02 * deg, 0.0];
        let (samples, x, y) = cell(4, offsets, 40);
        let noise = NoiseModel {
            rotation_sigma_rad: 0.02f64.to_radians(),
            translation_sigma_m: 1e-4,
        };
        let fit = fit_joint_offsets(
            Setup::EyeInHand,
            &ur10e(),
            &samples,
            (&x, &y),
            noise,
            &SolveOptions::default(),
        )
        .unwrap();
        assert_eq!(
            fit.offsets[0].status,
            OffsetStatus::Absorbed {
                by: Some("T_base_target")
            }
        );
        assert_eq!(
            fit.offsets[5].status,
            OffsetStatus::Absorbed {
                by: Some("T_flange_camera")
            }
        );
        for (j, (fitted, truth)) in fit.offsets.iter().zip(offsets).enumerate().take(5).skip(1) {
            let OffsetStatus::Estimated { sigma_rad } = fitted.status else {
                panic!("joint {j}: {fitted:?}");
            };
            let error = fitted.offset_rad - truth;
            assert!(
                error.abs() < 4.0 * sigma_rad,
                "joint {j}: {error} vs {sigma_rad}"
            );
            assert!(sigma_rad < 0.01 * deg, "joint {j}: 1σ {sigma_rad}");
        }
        assert!(translation_distance(&fit.camera_mount, &x) < 0.5e-3);
        assert!(translation_distance(&fit.target_mount, &y) < 0.5e-3);
        assert!(fit.translation_rms_mm[0] < fit.translation_rms_mm[1]);
    }

    #[test]
    fn offsets_of_joints_that_never_move_are_absorbed_by_the_camera_mount() {
        // The three wrist joints held still: everything after the elbow is one constant
        // transform, which the flange-side unknown takes whole, offsets included.
        let chain = ur10e();
        let mut rng = StdRng::seed_from_u64(1);
        let x = pose_from_rotvec(
            Vector3::new(0.03, -0.07, 0.04),
            Vector3::new(0.0, 0.0, 1.57),
        );
        let y = pose_from_rotvec(Vector3::new(0.5, -0.15, 0.0), Vector3::new(0.0, 0.0, 0.3));
        let samples: Vec<ArmSample> = (0..20)
            .map(|_| {
                let q = vec![
                    rng.random_range(-1.5..1.5),
                    rng.random_range(-1.5..1.5),
                    rng.random_range(-1.5..1.5),
                    0.4,
                    1.1,
                    -0.3,
                ];
                let reported = chain.forward(&q, &[0.0; 6]);
                ArmSample {
                    pair: PosePair::new(reported, x.inverse() * reported.inverse() * y),
                    joints: q,
                }
            })
            .collect();
        let fit = fit_joint_offsets(
            Setup::EyeInHand,
            &chain,
            &samples,
            (&x, &y),
            NoiseModel::default(),
            &SolveOptions::default(),
        )
        .unwrap();
        for j in 3..6 {
            assert_eq!(
                fit.offsets[j].status,
                OffsetStatus::Absorbed {
                    by: Some("T_flange_camera")
                },
                "joint {j}"
            );
        }
        assert!(matches!(
            fit.offsets[1].status,
            OffsetStatus::Estimated { .. }
        ));
        assert!(fit.offsets.iter().all(|o| o.offset_rad.abs() < 1e-9));
    }

    /// A UR10e eye-in-hand cell whose true chain differs from the published one by
    /// `corrections` (per joint: θ offset, d, a, α), at `n` joint vectors drawn in ±1.5 rad:
    /// samples with the reading and board noise of [`cell`], and the same without noise.
    fn dh_cell(seed: u64, corrections: &[[f64; 4]], n: usize) -> [Vec<ArmSample>; 2] {
        let chain = ur10e();
        let mut rng = StdRng::seed_from_u64(seed);
        let x = pose_from_rotvec(
            Vector3::new(0.03, -0.07, 0.04),
            Vector3::new(0.0, 0.0, 1.57),
        );
        let y = pose_from_rotvec(Vector3::new(0.5, -0.15, 0.0), Vector3::new(0.0, 0.0, 0.3));
        let noise_r = Normal::new(0.0, 0.005f64.to_radians()).unwrap();
        let noise_t = Normal::new(0.0, 0.02e-3).unwrap();
        let mut noisy = Vec::new();
        let mut exact = Vec::new();
        for _ in 0..n {
            let q: Vec<f64> = (0..6).map(|_| rng.random_range(-1.5..1.5)).collect();
            let reading = pose_from_rotvec(
                Vector3::from_fn(|_, _| 2e-5 * rng.random_range(-1.0..1.0)),
                Vector3::from_fn(|_, _| 3.5e-5 * rng.random_range(-1.0..1.0)),
            );
            let dn = pose_from_rotvec(
                Vector3::from_fn(|_, _| noise_t.sample(&mut rng)),
                Vector3::from_fn(|_, _| noise_r.sample(&mut rng)),
            );
            let nominal = chain.forward(&q, &[0.0; 6]);
            let seen = x.inverse() * chain.forward_corrected(&q, corrections).inverse() * y;
            noisy.push(ArmSample {
                pair: PosePair::new(nominal * reading, seen * dn),
                joints: q.clone(),
            });
            exact.push(ArmSample {
                pair: PosePair::new(nominal, seen),
                joints: q,
            });
        }
        [noisy, exact]
    }

    /// `ArmModel::Dh` over 20 drawn arms (offsets 0.03°, lengths 0.2 mm, twists 0.01°, 1σ; 40
    /// poses): the same parameters held in every draw (base θ and d absorbed by
    /// `T_base_target`, the last link's four by `T_flange_camera`, two `d` of the parallel
    /// joints undetermined); each of the 16 estimated parameters within 3σ of the truth in the
    /// parametrisation the data determine (the fit of the same poses without noise, which
    /// reproduces the true flange poses: the held parameters are absorbed exactly) in ≥ 95 % of
    /// the draws, the errors over 1σ of RMS 0.7–1.3, and both transforms within 0.5 mm / 0.05°
    /// of that truth.
    #[test]
    fn dh_corrections_the_data_observe_are_found_within_their_sigma() {
        let mut within = 0;
        let mut squares = Vec::new();
        let mut outside = std::collections::BTreeMap::new();
        let draws = 20;
        for draw in 0..draws {
            let mut rng = StdRng::seed_from_u64(500 + draw);
            let sigma = [0.03f64.to_radians(), 0.2e-3, 0.2e-3, 0.01f64.to_radians()];
            let corrections: Vec<[f64; 4]> = (0..6)
                .map(|_| {
                    std::array::from_fn(|k| Normal::new(0.0, sigma[k]).unwrap().sample(&mut rng))
                })
                .collect();
            let [noisy, exact] = dh_cell(draw, &corrections, 40);
            let pairs: Vec<PosePair> = noisy.iter().map(|s| s.pair.clone()).collect();
            let options = SolveOptions::default();
            let plain = crate::solve(Setup::EyeInHand, &pairs, &options).unwrap();
            let fit = fit_arm(
                ArmModel::Dh,
                Setup::EyeInHand,
                &ur10e(),
                &noisy,
                (&plain.camera_mount, &plain.target_mount),
                plain.noise.map_or(options.noise, |n| n.model()),
                &options,
            )
            .unwrap();
            // The truth the data can determine: the same fit of the poses without noise, its
            // weights fixed at the noisy fit's.
            let fixed = SolveOptions {
                estimate_noise: EstimateNoise::NONE,
                ..SolveOptions::default()
            };
            let truth = fit_arm(
                ArmModel::Dh,
                Setup::EyeInHand,
                &ur10e(),
                &exact,
                (&fit.camera_mount, &fit.target_mount),
                fit.noise.model(),
                &fixed,
            )
            .unwrap();
            assert!(truth.translation_rms_mm[0] < 1e-6, "draw {draw}: {truth:?}");
            let statuses: Vec<String> = fit
                .offsets
                .iter()
                .map(|o| format!("θ{}: {:?}", o.joint, o.status))
                .chain(
                    fit.links
                        .iter()
                        .map(|l| format!("{}{}: {:?}", l.parameter.name(), l.joint, l.status)),
                )
                .collect();
            if draw == 0 {
                eprintln!("{statuses:#?}");
            }
            // Absorbed: the base link's θ and d by the base-side transform, the last link's
            // four by the flange-side one; undetermined: the d of the second and third of the
            // three parallel joints (only the sum of the three moves the flange).
            let held: Vec<&String> = statuses
                .iter()
                .filter(|s| !s.contains("Estimated"))
                .collect();
            assert_eq!(
                held,
                [
                    "θ0: Absorbed { by: Some(\"T_base_target\") }",
                    "θ5: Absorbed { by: Some(\"T_flange_camera\") }",
                    "d0: Absorbed { by: Some(\"T_base_target\") }",
                    "d2: Undetermined",
                    "d3: Undetermined",
                    "d5: Absorbed { by: Some(\"T_flange_camera\") }",
                    "a5: Absorbed { by: Some(\"T_flange_camera\") }",
                    "alpha5: Absorbed { by: Some(\"T_flange_camera\") }",
                ],
                "draw {draw}"
            );
            let values = |f: &ArmFit| f.corrections();
            let (ours, theirs) = (values(&fit), values(&truth));
            let mut all = true;
            for (j, p, status) in fit.offsets.iter().map(|o| (o.joint, 0, o.status)).chain(
                fit.links
                    .iter()
                    .map(|l| (l.joint, l.parameter.index(), l.status)),
            ) {
                if let OffsetStatus::Estimated { sigma_rad } = status {
                    let e = (ours[j][p] - theirs[j][p]) / sigma_rad;
                    squares.push(e * e);
                    all &= e.abs() <= 3.0;
                    *outside.entry((j, p)).or_insert(0) += usize::from(e.abs() > 3.0);
                }
            }
            within += usize::from(all);
            let mm = translation_distance(&fit.camera_mount, &truth.camera_mount)
                .max(translation_distance(&fit.target_mount, &truth.target_mount))
                * 1e3;
            let deg = fit
                .camera_mount
                .rotation
                .angle_to(&truth.camera_mount.rotation)
                .max(
                    fit.target_mount
                        .rotation
                        .angle_to(&truth.target_mount.rotation),
                )
                .to_degrees();
            eprintln!(
                "draw {draw}: {} estimated, within 3σ: {all}, transforms {mm:.3} mm {deg:.4}°",
                fit.estimated()
            );
            assert!(mm <= 0.5 && deg <= 0.05, "draw {draw}: {mm} mm, {deg}°");
        }
        let rms = (squares.iter().sum::<f64>() / squares.len() as f64).sqrt();
        eprintln!(
            "{within} of {draws} draws with every estimated parameter within 3σ, normalised error RMS {rms:.2}; outside 3σ (joint, parameter): {outside:?}"
        );
        // Each parameter within 3σ in ≥ 95 % of the draws (all 16 at once would be 0.9973^16 ≈
        // 96 % by chance alone), and 1σ that are 1σ.
        for (param, n) in &outside {
            assert!(
                20 * n <= draws as usize,
                "{param:?}: outside 3σ in {n} of {draws}"
            );
        }
        assert!((0.7..1.3).contains(&rms), "normalised error RMS {rms}");
    }
}
