//! Why [`solve`](super::solve) produced no calibration ([`SolveError`]), and what is wrong with
//! one sample ([`SampleProblem`]).

use handeye_core::setup::Setup;

/// Why no calibration could be produced.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    /// Fewer samples than the problem needs.
    #[error("{found} pose pairs given, at least {required} are needed (with rotations about at least two different axes): record more poses")]
    TooFewSamples {
        /// Samples given (after dropping outliers, if any).
        found: usize,
        /// Samples needed.
        required: usize,
    },
    /// All relative robot rotations are about (nearly) one axis: the unknowns are not observable.
    #[error("robot rotations are all about nearly one axis (flange-frame axis [{:.3}, {:.3}, {:.3}], largest rotation off that axis {off_axis_deg:.2}° < {required_deg:.1}°): add poses tilted by 20–40° about flange axes [{:.3}, {:.3}, {:.3}] and [{:.3}, {:.3}, {:.3}]", axis[0], axis[1], axis[2], add_about[0][0], add_about[0][1], add_about[0][2], add_about[1][0], add_about[1][1], add_about[1][2])]
    Coaxial {
        /// Dominant rotation axis, flange frame of the first pose.
        axis: [f64; 3],
        /// Largest rotation component off that axis, degrees.
        off_axis_deg: f64,
        /// Required off-axis rotation, degrees.
        required_deg: f64,
        /// Two axes (flange frame of the first pose) to rotate about in new poses.
        add_about: [[f64; 3]; 2],
    },
    /// All relative robot rotations are tiny.
    #[error("robot rotations span only {span_deg:.2}° (need at least {required_deg:.1}° about two different axes): add poses tilted by 20–40° about two different flange axes")]
    TooLittleRotation {
        /// Largest relative rotation, degrees.
        span_deg: f64,
        /// Needed, degrees.
        required_deg: f64,
    },
    /// A sample with a bad value.
    #[error("sample {index}{}: {problem}", id.as_ref().map(|i| format!(" ({i})")).unwrap_or_default())]
    InvalidSample {
        /// Index of the sample.
        index: usize,
        /// Its id, if any.
        id: Option<String>,
        /// What is wrong.
        problem: SampleProblem,
    },
    /// A sample for the arm's model whose joint angles do not fit the arm's chain.
    #[error("sample {index}{}: {found} joint angles (or one not finite), the arm's model has {expected} joints", id.as_ref().map(|i| format!(" ({i})")).unwrap_or_default())]
    ArmJoints {
        /// Index of the sample.
        index: usize,
        /// Its id, if any.
        id: Option<String>,
        /// Joint angles it has.
        found: usize,
        /// Joints of the chain.
        expected: usize,
    },
    /// An option with a bad value.
    #[error("option `{name}` = {value}: {expected}")]
    InvalidOption {
        /// The option.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// The data fits far better with the robot poses inverted: the input is mislabelled.
    #[error("the data does not fit {setup} as given (rotation residual RMS {given_rms_deg:.2}°) but fits with {alternative_rms_deg:.3}° if the robot poses are inverted: either T_flange_base was given as T_base_flange, or T_target_camera as T_camera_target, or the setup is {} — check the convention of the input poses", setup.other())]
    ConventionMismatch {
        /// Setup as given.
        setup: Setup,
        /// Rotation residual RMS as given, degrees.
        given_rms_deg: f64,
        /// Rotation residual RMS with the robot poses inverted, degrees.
        alternative_rms_deg: f64,
    },
    /// The translations are inconsistent with metres (robot vs camera scale, or an impossible
    /// cell size): most likely one side is in millimetres.
    #[error("the translations are not in metres: {problem}")]
    ImplausibleUnits {
        /// What is inconsistent, and the likely unit mistake.
        problem: UnitsProblem,
    },
    /// The iterative method found no finite answer from any start.
    #[error("the iterative method found no usable answer after {restarts} restarts ({iterations} iterations)")]
    NoConvergence {
        /// Restarts tried.
        restarts: usize,
        /// Iterations spent.
        iterations: usize,
    },
    /// The nonlinear refinement failed numerically.
    #[error("refinement failed: {0}")]
    RefinementFailed(&'static str),
    /// The closed form found no usable rotation.
    #[error("closed form failed: {0}")]
    ClosedFormFailed(&'static str),
    /// The frames do not determine the camera intrinsics (e.g. all boards seen fronto-parallel).
    #[error("the frames do not constrain the camera intrinsics: {frames} frames, board tilt to the image plane {min_tilt_deg:.1}°..{max_tilt_deg:.1}°, board corners cover {coverage_percent:.0} % of the image: add frames with the board tilted by 20–45° about two different axes (left/right and up/down), and frames where the board reaches the image corners")]
    DegenerateIntrinsics {
        /// Frames with enough corners.
        frames: usize,
        /// Smallest board tilt against the image plane over the frames, degrees (estimated).
        min_tilt_deg: f64,
        /// Largest board tilt, degrees (estimated).
        max_tilt_deg: f64,
        /// Share of the image's bounding box covered by corners of all frames, percent.
        coverage_percent: f64,
    },
    /// The intrinsics could not be estimated from the board views.
    #[error("intrinsics estimation failed: {0}")]
    IntrinsicsFailed(String),
}

/// Which translations look like they are not in metres, and by how much.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UnitsProblem {
    /// The flange is farther from the robot base than any robot reaches.
    #[error("T_base_flange puts the flange {median_m:.1} m from the robot base (median over {samples} samples; a flange is within {limit_m} m of its base): the robot translations look like {unit} — give T_base_flange in metres")]
    FlangeTooFar {
        /// Median distance of the flange from the base as given, m.
        median_m: f64,
        /// Samples.
        samples: usize,
        /// The limit, m.
        limit_m: f64,
        /// The units that make the distances plausible (`millimetres`, `centimetres or
        /// inches`, ...).
        unit: String,
    },
    /// The target is farther from the camera than any board can be detected.
    #[error("T_camera_target puts the target {median_m:.1} m from the camera (median over {samples} samples; a calibration board is seen within {limit_m} m): the camera translations look like {unit} — give the board size (tag or square edge) in metres so that T_camera_target is in metres")]
    TargetTooFar {
        /// Median distance of the target from the camera as given, m.
        median_m: f64,
        /// Samples.
        samples: usize,
        /// The limit, m.
        limit_m: f64,
        /// The units that make the distances plausible.
        unit: String,
    },
    /// Robot and camera translations disagree in scale: the data fit when the robot's
    /// translations are multiplied by `scale`.
    #[error("robot and camera translations disagree in scale: the data fit with the T_base_flange translations multiplied by {scale:.4} (±{sigma:.4}), translation residual RMS {scaled_rms_mm:.2} mm, against {given_rms_mm:.1} mm as given: {explanation}")]
    ScaleMismatch {
        /// Factor on the robot translations that fits the data (1 for consistent units).
        scale: f64,
        /// Its standard error.
        sigma: f64,
        /// Translation residual RMS with the fitted factor, mm (camera units read as m).
        scaled_rms_mm: f64,
        /// Translation residual RMS with the data as given, mm.
        given_rms_mm: f64,
        /// The likely mistake, in words.
        explanation: String,
    },
}

/// What is wrong with one sample.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SampleProblem {
    /// NaN or infinity in a pose.
    #[error("{0} contains a non-finite value")]
    NotFinite(&'static str),
    /// A weight that is not a positive finite number.
    #[error("weight {0} must be a positive finite number")]
    BadWeight(f64),
}
