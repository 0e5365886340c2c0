//! Intrinsics that are not this camera's (issue #30): the frames' board reprojection RMS far
//! above normal with the file's intrinsics, and intrinsics estimated from the session's own
//! corners (Zhang's closed form, then the joint refinement, as without configured intrinsics)
//! far from the file's and fitting the corners far better. The estimate is written into the
//! session folder (`camera_info.yaml`, which `replay` also reads when the config has no
//! intrinsics) and the advice names it, with the numbers and the replay command.
//!
//! Depends on `solve` (the estimation), the camera model, the session folder and its visits.

use handeye_core::camera_model::CameraModel;
use handeye_core::notice::{Notice, NoticeKind, Severity};
use handeye_core::setup::Setup;
use handeye_solve::intrinsics::{calibrate_from_scratch, MIN_FRAMES};
use handeye_solve::verdict::NEXT_SEPARATOR;
use handeye_solve::Frame;
use handeye_vision::Target;

use super::{frames_from_visits, reprojection_options, CAMERA_INFO_FILE};
use crate::{PoseVisit, SessionError, SessionFolder};
use handeye_config::CellConfig;

/// Median per-frame board reprojection RMS (px, with the file's intrinsics) above which the
/// intrinsics are suspected: a good calibration gives a few tenths of a pixel.
pub(super) const SUSPECT_BOARD_RMS_PX: f64 = 1.0;
/// A parameter differing from the estimate by more than this fraction (of itself for the focal
/// lengths, of the image width for the principal point) is named.
pub(super) const PARAMETER_TOLERANCE: f64 = 0.01;
/// The estimate must fit the corners at least this many times better than the file's intrinsics.
pub(super) const BETTER_FIT_FACTOR: f64 = 3.0;

/// What the check found: the file's intrinsics do not fit the frames, and these do.
#[derive(Debug, Clone)]
pub struct WrongIntrinsics {
    /// The intrinsics as the file gives them.
    pub file_camera: CameraModel,
    /// The intrinsics estimated from the session's corners.
    pub estimated: CameraModel,
    /// Median per-frame board reprojection RMS with the file's intrinsics, px.
    pub file_rms_px: f64,
    /// Reprojection RMS of the joint fit with the estimated intrinsics, px.
    pub estimated_rms_px: f64,
    /// Frames the estimate is from.
    pub frames: usize,
}

impl WrongIntrinsics {
    /// The parameters that differ, `fx in the file 864.0 px, estimated from this session 800.1 px
    /// (-7.4 %)`, largest first.
    pub fn differences(&self) -> String {
        let rows = differing_parameters(
            &self.file_camera,
            &self.estimated,
            "estimated from this session",
        );
        if rows.is_empty() {
            return "the distortion differs (fx, fy, cx, cy agree within 1 %)".into();
        }
        rows.join("; ")
    }

    /// The sentence that says what is wrong, with the numbers.
    pub fn reason(&self, file: &std::path::Path) -> String {
        format!(
            "the intrinsics in {} do not fit this camera: the board reprojects with a median {:.2} px RMS per frame (normal is a few tenths), {:.2} px with intrinsics estimated from this session's {} frames; {}",
            file.display(),
            self.file_rms_px,
            self.estimated_rms_px,
            self.frames,
            self.differences()
        )
    }

    /// What to do, naming the estimate written into the session and the replay command.
    pub fn next_action(&self, folder: &std::path::Path, config: &std::path::Path) -> String {
        let estimate = folder.join(CAMERA_INFO_FILE);
        // Absolute: the config reads its paths relative to its own folder.
        let estimate = std::fs::canonicalize(&estimate).unwrap_or(estimate);
        format!(
            "calibrate the camera (or use the estimate written to {}: set `intrinsics: {}` in {}, or drop `intrinsics:` so the run estimates them), then `handeye replay {} --config {}`",
            estimate.display(),
            estimate.display(),
            config.display(),
            folder.display(),
            config.display()
        )
    }

    /// The error of a solve refused (`why`) on the `accepted` of `visited` poses these intrinsics
    /// let through, with the camera driver's calibration (`driver`) when it needs attention.
    #[allow(clippy::too_many_arguments)]
    pub fn few_samples_error(
        &self,
        folder: &std::path::Path,
        file: &std::path::Path,
        config: &std::path::Path,
        accepted: usize,
        visited: usize,
        why: String,
        driver: Option<&Notice>,
    ) -> SessionError {
        let (reason, next) = super::driver_calibration::with_driver_calibration(
            self.reason(file),
            self.next_action(folder, config),
            driver,
        );
        SessionError::WrongIntrinsicsFewSamples {
            folder: folder.to_path_buf(),
            accepted,
            visited,
            why,
            reason,
            next,
        }
    }

    /// The notice the verdict turns into its `Intrinsics` finding.
    pub fn notice(
        &self,
        file: &std::path::Path,
        folder: &std::path::Path,
        config: &std::path::Path,
    ) -> Notice {
        Notice::new(
            Severity::Error,
            NoticeKind::WrongIntrinsics,
            format!(
                "{}{NEXT_SEPARATOR}{}",
                self.reason(file),
                self.next_action(folder, config)
            ),
        )
    }
}

/// The parameters of `other` (`other_is`: where it comes from) that differ from `file`'s by
/// more than [`PARAMETER_TOLERANCE`], `fx in the file 864.0 px, estimated from this session
/// 800.1 px (-7.4 %)`, largest first.
pub(super) fn differing_parameters(
    file: &CameraModel,
    other: &CameraModel,
    other_is: &str,
) -> Vec<String> {
    let width = f64::from(file.width.max(1));
    let mut rows: Vec<(f64, String)> = [
        ("fx", file.fx, other.fx, file.fx),
        ("fy", file.fy, other.fy, file.fy),
        ("cx", file.cx, other.cx, width),
        ("cy", file.cy, other.cy, width),
    ]
    .into_iter()
    .map(|(name, in_file, theirs, scale)| {
        (
            ((theirs - in_file) / scale).abs(),
            format!(
                "{name} in the file {in_file:.1} px, {other_is} {theirs:.1} px ({:+.1} %)",
                (theirs - in_file) / in_file * 100.0
            ),
        )
    })
    .filter(|(relative, _)| *relative > PARAMETER_TOLERANCE)
    .collect();
    rows.sort_by(|a, b| b.0.total_cmp(&a.0));
    rows.into_iter().map(|(_, r)| r).collect()
}

/// Two lenses' distortion differing by more than this at some point of the image, px, is a
/// difference worth naming (the board's corners are located to ~0.1 px).
pub(super) const DISTORTION_TOLERANCE_PX: f64 = 1.0;

/// How far `other`'s distortion (`other_is`: where it comes from) moves a pixel from where
/// `file`'s puts it, at worst over the image (both with `file`'s focal lengths and principal
/// point, so only the distortion differs): `distortion in the file … against …: up to 6.3 px
/// apart over the image`; `None` within [`DISTORTION_TOLERANCE_PX`]. A file with no distortion
/// for a lens that has some is the classic case.
pub(super) fn differing_distortion(
    file: &CameraModel,
    other: &CameraModel,
    other_is: &str,
) -> Option<String> {
    let mut same_pinhole = *other;
    (same_pinhole.fx, same_pinhole.fy) = (file.fx, file.fy);
    (same_pinhole.cx, same_pinhole.cy) = (file.cx, file.cy);
    let worst = ray_displacement_px(file, &same_pinhole);
    (worst > DISTORTION_TOLERANCE_PX).then(|| {
        format!(
            "distortion in the file {} against {other_is} {}: up to {worst:.1} px apart over the image",
            describe_distortion(file),
            describe_distortion(other)
        )
    })
}

/// How far apart, at worst, the two lenses put the image of one ray, px: over the rays of a
/// 17×17 grid of `file`'s pixels.
pub(super) fn ray_displacement_px(file: &CameraModel, other: &CameraModel) -> f64 {
    let steps = 16;
    (0..=steps)
        .flat_map(|i| (0..=steps).map(move |j| (i, j)))
        .filter_map(|(i, j)| {
            let u = f64::from(file.width) * f64::from(i) / f64::from(steps);
            let v = f64::from(file.height) * f64::from(j) / f64::from(steps);
            let ray = nalgebra::Point3::new((u - file.cx) / file.fx, (v - file.cy) / file.fy, 1.0);
            Some((file.project(&ray)? - other.project(&ray)?).norm())
        })
        .fold(0.0f64, f64::max)
}

fn describe_distortion(lens: &CameraModel) -> String {
    let coefficients = lens.distortion.coefficients();
    if coefficients.iter().all(|c| *c == 0.0) {
        return "none".into();
    }
    let list: Vec<String> = coefficients.iter().map(|c| format!("{c:.4}")).collect();
    format!("[{}]", list.join(", "))
}

/// The median of the visits' board reprojection RMS (rejected visits too), px; `None` without
/// any.
fn median_board_rms(visits: &[PoseVisit]) -> Option<f64> {
    let values: Vec<f64> = visits
        .iter()
        .filter_map(|v| v.reprojection_rms_px)
        .collect();
    (!values.is_empty()).then(|| handeye_solve::diagnostics::median(&values))
}

/// Checks the file's intrinsics against the session's frames: when the median board RMS is
/// above [`SUSPECT_BOARD_RMS_PX`] and at least [`MIN_FRAMES`] frames have corners, estimates
/// the intrinsics from them; `Some` (with the estimate written to the folder's
/// `camera_info.yaml`) when the estimate differs and fits [`BETTER_FIT_FACTOR`] times better.
pub fn check_intrinsics(
    folder: &SessionFolder,
    setup: Setup,
    visits: &[PoseVisit],
    board: &Target,
    camera: &CameraModel,
    config: &CellConfig,
) -> Result<Option<WrongIntrinsics>, SessionError> {
    let Some(file_rms_px) = median_board_rms(visits) else {
        return Ok(None);
    };
    if file_rms_px <= SUSPECT_BOARD_RMS_PX {
        return Ok(None);
    }
    let frames: Vec<Frame> = frames_from_visits(visits, board, false)?
        .into_iter()
        .map(|(_, f)| f)
        .collect();
    if frames.len() < MIN_FRAMES {
        return Ok(None);
    }
    let options = config.solver.to_options();
    let Ok(scratch) = calibrate_from_scratch(
        setup,
        &frames,
        camera.width,
        camera.height,
        &options,
        &reprojection_options(config),
    ) else {
        return Ok(None);
    };
    let estimated_rms_px = scratch.joint.errors.rms_px;
    let found = WrongIntrinsics {
        file_camera: *camera,
        estimated: scratch.joint.camera,
        file_rms_px,
        estimated_rms_px,
        frames: frames.len(),
    };
    if estimated_rms_px * BETTER_FIT_FACTOR > file_rms_px {
        return Ok(None);
    }
    let path = folder.root().join(CAMERA_INFO_FILE);
    found
        .estimated
        .save_camera_info(&path)
        .map_err(|source| SessionError::Intrinsics {
            file: path.clone(),
            source: Box::new(source),
        })?;
    Ok(Some(found))
}
