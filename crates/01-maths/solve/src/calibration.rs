//! What [`solve`](super::solve) returns: the [`Calibration`] (both unknowns, residuals,
//! 1-sigma uncertainty, outliers, the solver's trace and warnings) and its terminal summary.
//! Units: metres and radians in poses; degrees and millimetres in the figures people read.

use nalgebra::SMatrix;
use serde::{Deserialize, Serialize};

use super::{Method, NoiseModel};
use handeye_core::geometry::Pose;
use handeye_core::notice::Notice;
use handeye_core::setup::{CellTransforms, Setup};

/// Residuals of the solution against each sample's measured `T_camera_target`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Residuals {
    /// Per sample: angle between predicted and measured rotation, degrees.
    pub rotation_deg: Vec<f64>,
    /// Per sample: distance between predicted and measured translation, mm.
    pub translation_mm: Vec<f64>,
    /// Per sample: whitened residual norm in sigmas of the noise model (6 dof).
    pub normalised: Vec<f64>,
    /// RMS of `rotation_deg`.
    pub rotation_rms_deg: f64,
    /// Largest of `rotation_deg`.
    pub rotation_max_deg: f64,
    /// RMS of `translation_mm`.
    pub translation_rms_mm: f64,
    /// Largest of `translation_mm`.
    pub translation_max_mm: f64,
}

/// 1-sigma uncertainty of one unknown `T_a_b`: rotation perturbation and translation, both in
/// frame `a`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSigma {
    /// Total 1-sigma rotation (sqrt of the trace of the rotation covariance), degrees.
    pub rotation_deg: f64,
    /// Total 1-sigma translation (sqrt of the trace of the translation covariance), mm.
    pub translation_mm: f64,
    /// Per-axis 1-sigma rotation about x, y, z of frame `a`, degrees.
    pub rotation_axes_deg: [f64; 3],
    /// Per-axis 1-sigma translation along x, y, z of frame `a`, mm.
    pub translation_axes_mm: [f64; 3],
}

/// Where a sigma of [`PoseNoise`] came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseSource {
    /// Estimated from the residuals (variance component estimation).
    Estimated,
    /// Estimated, but the estimate fell outside the allowed range and was clamped to it.
    AtBound,
    /// Given explicitly (command line or config): used as is.
    Given,
    /// Not estimated: too few samples (fewer than 8) to trust an estimate; the starting value
    /// was used.
    TooFewSamples,
}

impl NoiseSource {
    /// The YAML name.
    pub fn name(self) -> &'static str {
        match self {
            NoiseSource::Estimated => "estimated",
            NoiseSource::AtBound => "at_bound",
            NoiseSource::Given => "given",
            NoiseSource::TooFewSamples => "too_few_samples",
        }
    }
}

/// The noise of `T_camera_target` the answer's weights, normalised residuals and covariance
/// used: per-axis 1-sigma, estimated from the residuals or given.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseNoise {
    /// Per-axis rotation sigma, degrees.
    pub rotation_sigma_deg: f64,
    /// Per-axis translation sigma, mm.
    pub translation_sigma_mm: f64,
    /// Where the rotation sigma came from.
    pub rotation: NoiseSource,
    /// Where the translation sigma came from.
    pub translation: NoiseSource,
    /// Rounds of estimation (each a refit for the refined method).
    pub rounds: usize,
}

impl PoseNoise {
    /// As the solver's noise model (rad, m).
    pub fn model(&self) -> NoiseModel {
        NoiseModel {
            rotation_sigma_rad: self.rotation_sigma_deg.to_radians(),
            translation_sigma_m: self.translation_sigma_mm * 1e-3,
        }
    }
}

/// Covariance of both unknowns at the optimum.
#[derive(Debug, Clone, PartialEq)]
pub struct Uncertainty {
    /// 12x12 joint covariance, order: camera mount [rotation (rad), translation (m)], target
    /// mount [rotation, translation]; each pose `T_a_b` perturbed as
    /// `R ← exp(δθ)·R, t ← t + δt` (both in frame `a`).
    pub covariance: SMatrix<f64, 12, 12>,
    /// 1-sigma of the camera mount (`T_flange_camera` or `T_base_camera`).
    pub camera_mount: PoseSigma,
    /// 1-sigma of the target mount (`T_base_target` or `T_flange_target`).
    pub target_mount: PoseSigma,
    /// A-posteriori variance factor `χ²/dof` the covariance was scaled by (≈ 1 if the noise
    /// model is right; floored at 1 only with fewer than 36 residual degrees of freedom, i.e.
    /// 8 pose samples, see [`variance_factor`](crate::refine::variance_factor)).
    pub variance_factor: f64,
}

/// One step of an iteration trace.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TraceStep {
    /// `rotation` or `translation` phase of the iterative method, or `refine`.
    pub phase: Phase,
    /// Size of the update of this step: rad for rotation, m for translation, cost for refine.
    pub update: f64,
}

/// Phase of a [`TraceStep`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Rotation alternation (update in rad).
    Rotation,
    /// Translation alternation (update in m).
    Translation,
    /// Nonlinear refinement (value: half the sum of squared whitened residuals).
    Refine,
}

/// How the solver got its answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverReport {
    /// The method that produced the answer.
    pub method: Method,
    /// Iterations of the iterative method (rotation + translation), or LM evaluations.
    pub iterations: usize,
    /// Whether every stage met its tolerance.
    pub converged: bool,
    /// Restarts of the iterative method after a stall (the paper's s ≈ 0 case).
    pub restarts: usize,
    /// Per-iteration update sizes, for plots.
    pub trace: Vec<TraceStep>,
}

/// The answer: both unknowns, their uncertainty, and the diagnostics.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// The layout solved.
    pub setup: Setup,
    /// eye_in_hand: `T_flange_camera`; eye_to_hand: `T_base_camera`.
    pub camera_mount: Pose,
    /// eye_in_hand: `T_base_target`; eye_to_hand: `T_flange_target`.
    pub target_mount: Pose,
    /// Covariance of both unknowns (refined method with covariance on).
    pub uncertainty: Option<Uncertainty>,
    /// Residuals of the samples used in the final solve, indexed like the input; `normalised`
    /// in sigmas of [`Calibration::noise`].
    pub residuals: Residuals,
    /// The noise of `T_camera_target` the pose-space fit used (estimated or given); `None` for
    /// an answer fitted elsewhere (reprojection space) or read from a file without it.
    pub noise: Option<PoseNoise>,
    /// Indices (into the input) of samples flagged as outliers.
    pub outliers: Vec<usize>,
    /// Indices (into the input) of samples left out of the final solve (dropped outliers).
    pub dropped: Vec<usize>,
    /// How the solver got there.
    pub solver: SolverReport,
    /// Things a person should know (large uncertainty, flagged outliers, ...).
    pub notices: Vec<Notice>,
}

impl Calibration {
    /// Both unknowns with their YAML keys, camera mount first.
    pub fn unknowns(&self) -> [(&'static str, Pose); 2] {
        self.transforms().unknowns()
    }

    /// The two solved transforms, named by setup.
    pub fn transforms(&self) -> CellTransforms {
        CellTransforms {
            setup: self.setup,
            camera_mount: self.camera_mount,
            target_mount: self.target_mount,
        }
    }

    /// The `T_camera_target` this calibration predicts for a robot pose `T_base_flange`.
    pub fn predict_camera_from_target(&self, base_from_flange: &Pose) -> Pose {
        self.transforms().camera_from_target(base_from_flange)
    }
}

impl Calibration {
    /// A short summary for a terminal: solver run, both unknowns with their 1-sigma, residuals,
    /// outliers and warnings.
    pub fn summary(&self) -> String {
        use std::fmt::Write;
        let mut out = String::new();
        let s = &self.solver;
        let _ = writeln!(
            out,
            "setup {}, method {} ({} iterations, {}converged, {} restarts)",
            self.setup,
            s.method.name(),
            s.iterations,
            if s.converged { "" } else { "NOT " },
            s.restarts
        );
        let sigmas = self
            .uncertainty
            .as_ref()
            .map(|u| [u.camera_mount, u.target_mount]);
        for (k, (name, pose)) in self.unknowns().iter().enumerate() {
            let t = pose.translation.vector * 1e3;
            let rv = handeye_core::geometry::rotvec(&pose.rotation);
            let _ = writeln!(
                out,
                "{name}: translation [{:.2}, {:.2}, {:.2}] mm, rotation_vector [{:.5}, {:.5}, {:.5}] rad ({:.3}°)",
                t.x,
                t.y,
                t.z,
                rv.x,
                rv.y,
                rv.z,
                rv.norm().to_degrees()
            );
            if let Some(sigma) = sigmas {
                let _ = writeln!(
                    out,
                    "    1-sigma {:.4}°, {:.3} mm",
                    sigma[k].rotation_deg, sigma[k].translation_mm
                );
            }
        }
        if let Some(noise) = &self.noise {
            let _ = writeln!(
                out,
                "board-pose noise: {:.4}° ({}), {:.3} mm ({}) per axis",
                noise.rotation_sigma_deg,
                noise.rotation.name(),
                noise.translation_sigma_mm,
                noise.translation.name()
            );
        }
        let r = &self.residuals;
        let _ = write!(
            out,
            "residuals: rotation RMS {:.4}° (max {:.4}°), translation RMS {:.3} mm (max {:.3} mm)",
            r.rotation_rms_deg, r.rotation_max_deg, r.translation_rms_mm, r.translation_max_mm
        );
        if !self.outliers.is_empty() {
            let _ = write!(out, "\noutliers (sample indices): {:?}", self.outliers);
        }
        for notice in &self.notices {
            let _ = write!(out, "\n{notice}");
        }
        out
    }
}
