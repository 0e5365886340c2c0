//! What [`solve`](super::solve) is asked to do: the estimator ([`Method`]), the measurement
//! noise model that weights samples ([`NoiseModel`]), the robust loss ([`RobustLoss`]) and the
//! options that bundle them ([`SolveOptions`]). Plain data; depends on nothing above `solve`.

use serde::{Deserialize, Serialize};

use super::{IterativeOptions, SolveError};

/// Measurement noise of `T_camera_target`: standard deviation per axis of the rotation error
/// (rad, a small rotation vector in the camera frame) and of the translation error (m, camera frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseModel {
    /// Per-axis standard deviation of the rotation error, rad.
    pub rotation_sigma_rad: f64,
    /// Per-axis standard deviation of the translation error, m.
    pub translation_sigma_m: f64,
}

impl Default for NoiseModel {
    /// 0.2° and 1 mm: a typical AprilTag board pose at working distance.
    fn default() -> Self {
        NoiseModel {
            rotation_sigma_rad: 0.2f64.to_radians(),
            translation_sigma_m: 1e-3,
        }
    }
}

/// Which groups of the [`NoiseModel`] [`solve`](super::solve) estimates from the residuals
/// (variance component estimation, see [`super::noise`]); a group not estimated is used as
/// given. The default estimates both: explicit sigmas (command line, config) switch a group off.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EstimateNoise {
    /// Estimate the rotation sigma of `T_camera_target`.
    pub rotation: bool,
    /// Estimate the translation sigma of `T_camera_target`.
    pub translation: bool,
}

impl NoiseModel {
    /// The board-pose noise from optional explicit sigmas (degrees, millimetres): a given group
    /// is used as is and not estimated; a missing one starts from the default and is estimated
    /// when `estimate` is true. One rule for the command line and the config.
    pub fn given_or_estimated(
        rotation_sigma_deg: Option<f64>,
        translation_sigma_mm: Option<f64>,
        estimate: bool,
    ) -> (NoiseModel, EstimateNoise) {
        let start = NoiseModel::default();
        (
            NoiseModel {
                rotation_sigma_rad: rotation_sigma_deg
                    .map_or(start.rotation_sigma_rad, f64::to_radians),
                translation_sigma_m: translation_sigma_mm
                    .map_or(start.translation_sigma_m, |mm| mm * 1e-3),
            },
            EstimateNoise {
                rotation: estimate && rotation_sigma_deg.is_none(),
                translation: estimate && translation_sigma_mm.is_none(),
            },
        )
    }
}

impl EstimateNoise {
    /// Estimate both sigmas (the default).
    pub const BOTH: EstimateNoise = EstimateNoise {
        rotation: true,
        translation: true,
    };
    /// Use the [`NoiseModel`] as given.
    pub const NONE: EstimateNoise = EstimateNoise {
        rotation: false,
        translation: false,
    };

    /// True when at least one sigma is estimated.
    pub fn any(self) -> bool {
        self.rotation || self.translation
    }
}

impl Default for EstimateNoise {
    fn default() -> Self {
        EstimateNoise::BOTH
    }
}

/// Which estimator [`solve`](crate::solve) runs.
///
/// One list of names for the config (`solver.method`), the CLI (`--method`) and the result
/// file: [`Method::name`] of each of [`Method::ALL`], plus [`Method::ALIASES`]; (de)serialized
/// through them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// The paper: alternating quaternion averaging for rotations, then translations.
    Iterative,
    /// Shah (2013) Kronecker/SVD closed form written for `A = X·B·Y` (AX = ZB family).
    ClosedForm,
    /// Joint weighted nonlinear least squares on both unknowns, started from the iterative answer.
    #[default]
    Refined,
    /// Tsai and Lenz (1989), AX = XB on relative motions; `Y` averaged afterwards.
    Tsai,
    /// Park and Martin (1994), AX = XB on relative motions; `Y` averaged afterwards.
    Park,
    /// Horaud and Dornaika (1995), linear quaternion form of AX = XB; `Y` averaged afterwards.
    Horaud,
    /// Andreff, Horaud and Espiau (2001), linear Kronecker form of AX = XB; `Y` averaged afterwards.
    Andreff,
    /// Daniilidis (1999), dual quaternions for AX = XB; `Y` averaged afterwards.
    Daniilidis,
    /// Li, Wang and Wu (2010), Kronecker form of AX = ZB with rotations and translations at once.
    Li,
}

impl Method {
    /// Every method, the paper's first, then the refined default, then the closed forms.
    pub const ALL: [Method; 9] = [
        Method::Iterative,
        Method::Refined,
        Method::Tsai,
        Method::Park,
        Method::Horaud,
        Method::Andreff,
        Method::Daniilidis,
        Method::ClosedForm,
        Method::Li,
    ];

    /// Other accepted spellings: `closed-form` (the config's and CLI's older spelling) and
    /// `shah` (the paper) for [`Method::ClosedForm`].
    pub const ALIASES: [(&'static str, Method); 2] = [
        ("closed-form", Method::ClosedForm),
        ("shah", Method::ClosedForm),
    ];

    /// Every accepted name: the name of each of [`Method::ALL`], then the aliases.
    pub const NAMES: [&'static str; 11] = {
        let mut names = [""; 11];
        let mut i = 0;
        while i < Method::ALL.len() {
            names[i] = Method::ALL[i].name();
            i += 1;
        }
        let mut k = 0;
        while k < Method::ALIASES.len() {
            names[Method::ALL.len() + k] = Method::ALIASES[k].0;
            k += 1;
        }
        names
    };

    /// The method of a name or alias (exact spelling), `None` for anything else.
    pub fn from_name(name: &str) -> Option<Method> {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == name)
            .or_else(|| {
                Method::ALIASES
                    .into_iter()
                    .find(|(alias, _)| *alias == name)
                    .map(|(_, m)| m)
            })
    }

    /// One line on what the method is, for `--help`.
    pub fn summary(self) -> &'static str {
        match self {
            Method::Iterative => "the paper's iterative quaternion-averaging method",
            Method::ClosedForm => "Shah's Kronecker closed form (AX = ZB)",
            Method::Refined => {
                "weighted nonlinear least squares from the iterative answer (default)"
            }
            Method::Tsai => "Tsai–Lenz closed form (AX = XB on relative motions)",
            Method::Park => "Park–Martin closed form (AX = XB on relative motions)",
            Method::Horaud => "Horaud–Dornaika quaternion closed form (AX = XB)",
            Method::Andreff => "Andreff's linear Kronecker form (AX = XB)",
            Method::Daniilidis => "Daniilidis' dual-quaternion closed form (AX = XB)",
            Method::Li => "Li's Kronecker form of AX = ZB (rotations and translations at once)",
        }
    }

    /// The YAML / CLI name.
    pub const fn name(self) -> &'static str {
        match self {
            Method::Iterative => "iterative",
            Method::ClosedForm => "closed_form",
            Method::Refined => "refined",
            Method::Tsai => "tsai",
            Method::Park => "park",
            Method::Horaud => "horaud",
            Method::Andreff => "andreff",
            Method::Daniilidis => "daniilidis",
            Method::Li => "li",
        }
    }

    /// True for the closed forms (every method but the iterative and the refined one).
    pub fn is_closed_form(self) -> bool {
        !matches!(self, Method::Iterative | Method::Refined)
    }

    /// The paper behind a closed form, for tables (`closed_form` is Shah's).
    pub fn label(self) -> &'static str {
        match self {
            Method::Iterative => "iterative (Hirsh)",
            Method::Refined => "refined",
            Method::ClosedForm => "shah (closed_form)",
            other => other.name(),
        }
    }
}

impl std::str::FromStr for Method {
    type Err = String;

    /// [`Method::from_name`], with the accepted names in the error.
    fn from_str(name: &str) -> Result<Method, String> {
        Method::from_name(name).ok_or_else(|| {
            format!(
                "unknown method `{name}`, expected one of {}",
                Method::NAMES.map(|n| format!("`{n}`")).join(", ")
            )
        })
    }
}

impl Serialize for Method {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for Method {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Method, D::Error> {
        let name = String::deserialize(deserializer)?;
        Method::from_name(&name)
            .ok_or_else(|| serde::de::Error::unknown_variant(&name, &Method::NAMES))
    }
}

/// Robust loss of the refinement, applied to each sample's whitened residual norm. The scale is in
/// sigmas of the [`NoiseModel`].
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RobustLoss {
    /// Plain least squares (the maximum-likelihood estimate under Gaussian noise).
    #[default]
    None,
    /// Huber loss with this threshold (sigmas).
    Huber(f64),
    /// Cauchy loss with this scale (sigmas).
    Cauchy(f64),
}

impl RobustLoss {
    /// The losses by name with a line on each: what `handeye solve --robust` and Python's
    /// `robust=` take ([`RobustLoss::named`]).
    pub const NAMES: [(&'static str, &'static str); 3] = [
        ("none", "plain least squares"),
        ("huber", "Huber loss"),
        ("cauchy", "Cauchy loss"),
    ];

    /// The loss called `name` (one of [`RobustLoss::NAMES`]) at `scale` sigmas (unused by
    /// `none`); an unknown name is refused listing them.
    pub fn named(name: &str, scale: f64) -> Result<RobustLoss, String> {
        match name {
            "none" => Ok(RobustLoss::None),
            "huber" => Ok(RobustLoss::Huber(scale)),
            "cauchy" => Ok(RobustLoss::Cauchy(scale)),
            other => {
                let names: Vec<String> =
                    Self::NAMES.iter().map(|(n, _)| format!("`{n}`")).collect();
                Err(format!(
                    "robust `{other}`: expected one of {}",
                    names.join(", ")
                ))
            }
        }
    }

    /// Checks the loss's scale is a positive finite number; the names are the option keys of
    /// the Huber and Cauchy scales in the caller's configuration.
    pub(super) fn validate(
        self,
        huber_name: &'static str,
        cauchy_name: &'static str,
    ) -> Result<(), SolveError> {
        match self {
            RobustLoss::Huber(k) => require_positive(huber_name, k),
            RobustLoss::Cauchy(k) => require_positive(cauchy_name, k),
            RobustLoss::None => Ok(()),
        }
    }

    /// The iteratively-reweighted-least-squares weight of a residual of `e` sigmas.
    pub fn weight(self, e: f64) -> f64 {
        match self {
            RobustLoss::None => 1.0,
            RobustLoss::Huber(k) if e <= k => 1.0,
            RobustLoss::Huber(k) => k / e,
            RobustLoss::Cauchy(k) => 1.0 / (1.0 + (e / k) * (e / k)),
        }
    }
}

/// What a person chooses of a solve, in the units they write it: a config's `solver:` section,
/// `handeye solve`'s flags and the Python keywords all become [`SolveOptions`] through
/// [`SolverChoice::options`], the one place the choice meets the solver's defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverChoice {
    /// The estimator.
    pub method: Method,
    /// Board-pose rotation noise given, degrees (1-sigma per axis); `None`: estimated.
    pub rotation_sigma_deg: Option<f64>,
    /// Board-pose translation noise given, mm; `None`: estimated.
    pub translation_sigma_mm: Option<f64>,
    /// Estimate the sigmas not given from the residuals (`false`: the defaults as given).
    pub estimate_noise: bool,
    /// Robust loss of the refinement.
    pub robust: RobustLoss,
    /// Leave outliers out of the final fit (`false`: only flag them).
    pub drop_outliers: bool,
    /// Weigh each sample by its view's precision (`false`: every view alike, as before samples
    /// recorded it).
    pub weigh_views: bool,
    /// Start the iterative method from the closed form.
    pub warm_start: bool,
}

impl Default for SolverChoice {
    fn default() -> Self {
        let options = SolveOptions::default();
        SolverChoice {
            method: options.method,
            rotation_sigma_deg: None,
            translation_sigma_mm: None,
            estimate_noise: true,
            robust: options.robust,
            drop_outliers: options.drop_outliers,
            weigh_views: options.weigh_views,
            warm_start: options.iterative.warm_start,
        }
    }
}

impl SolverChoice {
    /// The solver options this choice means: a sigma given is used as is, one absent is
    /// estimated from the residuals (from the solver's default start) unless `estimate_noise`
    /// is off; everything not chosen is the solver's default.
    pub fn options(&self) -> SolveOptions {
        let (noise, estimate_noise) = NoiseModel::given_or_estimated(
            self.rotation_sigma_deg,
            self.translation_sigma_mm,
            self.estimate_noise,
        );
        let mut options = SolveOptions {
            method: self.method,
            noise,
            estimate_noise,
            robust: self.robust,
            drop_outliers: self.drop_outliers,
            weigh_views: self.weigh_views,
            ..SolveOptions::default()
        };
        options.iterative.warm_start = self.warm_start;
        options
    }
}

/// Everything [`solve`](crate::solve) can be told.
#[derive(Debug, Clone, PartialEq)]
pub struct SolveOptions {
    /// The estimator (default [`Method::Refined`]).
    pub method: Method,
    /// Noise of `T_camera_target`, used to weight and whiten residuals: the starting value of
    /// the groups in [`SolveOptions::estimate_noise`], the value used for the others. Also the
    /// expected noise the convention check compares the fit against.
    pub noise: NoiseModel,
    /// Which sigmas of [`SolveOptions::noise`] are estimated from the residuals (default both).
    pub estimate_noise: EstimateNoise,
    /// Robust loss of the refinement.
    pub robust: RobustLoss,
    /// Robust by default: start from a consensus over small subsets, leave out of the final fit
    /// every sample whose residual is an outlier against the fit of the rest (each named in a
    /// [`DroppedOutliers`](handeye_core::notice::NoticeKind::DroppedOutliers) notice), and fit the
    /// inliers; a clean data set keeps every sample and gives the plain fit. `false`: one fit of
    /// every sample, outliers only flagged.
    pub drop_outliers: bool,
    /// Weigh each sample by how precisely its view fixed its board pose, relative to the
    /// typical view ([`view_weighted`](crate::view_weighted); default). `false`: every view
    /// alike, each sample at its own `weight` only.
    pub weigh_views: bool,
    /// Outlier threshold: a sample is flagged when its normalised residual exceeds
    /// `median + outlier_mad_factor · 1.4826 · MAD` and [`SolveOptions::outlier_floor_sigma`].
    pub outlier_mad_factor: f64,
    /// Normalised residual (sigmas, 6 dof) below which a sample is never an outlier.
    pub outlier_floor_sigma: f64,
    /// Options of the iterative method (also the start of the refinement).
    pub iterative: IterativeOptions,
    /// Compute the covariance of the unknowns (refined method only).
    pub covariance: bool,
    /// Warn when a 1-sigma rotation uncertainty exceeds this, degrees.
    pub warn_rotation_sigma_deg: f64,
    /// Warn when a 1-sigma translation uncertainty exceeds this, mm.
    pub warn_translation_sigma_mm: f64,
    /// Check whether the data fits far better under another convention (inverted poses, other
    /// setup), refuse translations inconsistent with metres, and flag swapped-looking answers.
    pub check_conventions: bool,
}

impl Default for SolveOptions {
    fn default() -> Self {
        SolveOptions {
            method: Method::Refined,
            noise: NoiseModel::default(),
            estimate_noise: EstimateNoise::BOTH,
            robust: RobustLoss::None,
            drop_outliers: true,
            weigh_views: true,
            outlier_mad_factor: 5.0,
            // sqrt of the 99.9 % quantile of chi-square with 6 dof (22.46).
            outlier_floor_sigma: 4.74,
            iterative: IterativeOptions::default(),
            covariance: true,
            warn_rotation_sigma_deg: 0.5,
            warn_translation_sigma_mm: 5.0,
            check_conventions: true,
        }
    }
}

/// An option that must be a positive finite number, named `name` in the error.
pub(super) fn require_positive(name: &'static str, value: f64) -> Result<(), SolveError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(SolveError::InvalidOption {
            name,
            value,
            expected: "must be a positive finite number",
        })
    }
}
