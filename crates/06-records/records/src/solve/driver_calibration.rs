//! The camera driver's own calibration against the config's intrinsics file (issue #39): a ROS 2
//! run keeps the `CameraInfo` the driver published (`camera_info_from_topic.yaml`); when the
//! config names a file that differs from it, the verdict says so (CHECK, unless something worse
//! decides), with which of the two the board's corners fit better (each frame's board pose
//! solved again with either lens), so a stale file or a driver streaming another resolution's
//! calibration is named, not guessed.

use handeye_core::camera_model::CameraModel;
use handeye_core::notice::{Notice, NoticeKind};
use handeye_solve::verdict::NEXT_SEPARATOR;
use handeye_vision::Target;

use super::board_fit;
use super::intrinsics_check::{
    differing_distortion, differing_parameters, ray_displacement_px, DISTORTION_TOLERANCE_PX,
};
use crate::{PoseVisit, SessionFolder};
use handeye_config::CellConfig;
use handeye_solve::diagnostics::median;

/// The file in a session folder that keeps the calibration a ROS 2 camera driver published on
/// its camera_info topic.
pub const DRIVER_CALIBRATION_FILE: &str = "camera_info_from_topic.yaml";

/// One lens fits the corners better than the other when its median per-frame RMS is lower by
/// more than this fraction of it…
const FIT_MARGIN: f64 = 0.05;
/// …and by more than this, px.
const FIT_MARGIN_PX: f64 = 0.01;

/// The notice of the config's intrinsics file (loaded as `file_model`) that differs from the
/// driver's calibration kept in `folder` (`NoticeKind::DriverCalibration`: the verdict's finding
/// when it is a warning); `None` when there is none or they agree.
///
/// A run's solve and a replay both hand it to the verdict with the notices of the solve.
pub fn driver_calibration_notice(
    folder: &SessionFolder,
    config: &CellConfig,
    file_model: &CameraModel,
    visits: &[PoseVisit],
    board: &Target,
) -> Option<Notice> {
    let file = folder.shown(config.camera().intrinsics.as_deref()?);
    let kept = folder.root().join(DRIVER_CALIBRATION_FILE);
    let driver = CameraModel::load(&kept).ok()?;
    let mut rows = differing_parameters(file_model, &driver, "from the driver");
    rows.extend(differing_distortion(file_model, &driver, "the driver's"));
    // Each parameter within its tolerance can still add up to pixels (a principal point 10 px
    // off is under 1 % of the width).
    let apart_px = ray_displacement_px(file_model, &driver);
    if rows.is_empty() && apart_px > DISTORTION_TOLERANCE_PX {
        rows.push(format!(
            "fx, fy, cx, cy within 1 % and the distortion alike, but the two lenses image a ray up to {apart_px:.1} px apart"
        ));
    }
    let sizes_differ = (file_model.width, file_model.height) != (driver.width, driver.height);
    if rows.is_empty() && !sizes_differ {
        return None;
    }
    let (file_rms, driver_rms) = (
        median_fit(file_model, visits, board),
        median_fit(&driver, visits, board),
    );
    let what = if sizes_differ {
        format!(
            "the file is for {}x{} px, the driver's for {}x{} px",
            file_model.width, file_model.height, driver.width, driver.height
        )
    } else {
        rows.join("; ")
    };
    let differ = format!(
        "the intrinsics in {} differ from the calibration the camera driver publishes (kept in {}): {what}",
        file.display(),
        folder.shown(&kept).display()
    );
    // The verdict's finding when the file may be the stale one (the corners fit the driver's
    // better, or too few frames tell); information when the corners fit the file better (the
    // answer used the better lens; the driver's topic is what misleads other nodes).
    // Which fits better only when the two fits differ by more than the corners' own noise
    // could make them (a principal point a few px off is largely absorbed by each frame's
    // board pose): otherwise these views cannot tell.
    let apart = |a: f64, b: f64| b - a > (FIT_MARGIN * a).max(FIT_MARGIN_PX);
    Some(match (file_rms, driver_rms) {
        (Some(f), Some(d)) if apart(d, f) => Notice::warning(
            NoticeKind::DriverCalibration,
            format!(
                "{differ}; the board's corners fit the driver's better (median {d:.2} px RMS per frame against {f:.2} px with the file){NEXT_SEPARATOR}drop `intrinsics:` from the config to use what the driver publishes (or calibrate the camera again), then replay the session"
            ),
        ),
        (Some(f), Some(d)) if apart(f, d) => Notice::info(
            NoticeKind::DriverCalibration,
            format!(
                "{differ}; the board's corners fit the file better (median {f:.2} px RMS per frame against {d:.2} px with the driver's): the file was used; the driver publishes a calibration that is not this camera's at this resolution, which misleads every other node reading its camera_info"
            ),
        ),
        (Some(f), Some(d)) => Notice::warning(
            NoticeKind::DriverCalibration,
            format!(
                "{differ}; the board's corners fit both alike (median {f:.2} px RMS per frame with the file, {d:.2} px with the driver's): these views cannot tell which is this camera's (the file was used){NEXT_SEPARATOR}find out which calibration is this camera's at this resolution (calibrate again if unsure), then replay the session"
            ),
        ),
        _ => Notice::warning(
            NoticeKind::DriverCalibration,
            format!(
                "{differ}; too few frames to tell which fits the board's corners better (the file was used){NEXT_SEPARATOR}find out which calibration is this camera's at this resolution (calibrate again if unsure), then replay the session"
            ),
        ),
    })
}

/// The `reason` and `next` action of an error that stops before any solve (every pose rejected
/// by the file's lens) with the driver's calibration `notice` added when it needs attention: its
/// finding joins the reason and its next action (use what the driver publishes) leads.
pub fn with_driver_calibration(
    reason: String,
    next: String,
    notice: Option<&Notice>,
) -> (String, String) {
    match notice.filter(|n| n.needs_attention()) {
        Some(n) => match n.message.split_once(NEXT_SEPARATOR) {
            Some((finding, theirs)) => (
                format!("{reason}; {finding}"),
                format!("{theirs}; or {next}"),
            ),
            None => (format!("{reason}; {}", n.message), next),
        },
        None => (reason, next),
    }
}

/// The median per-frame board reprojection RMS of `visits` with the board pose solved by `lens`,
/// px; `None` without three frames to judge by.
fn median_fit(lens: &CameraModel, visits: &[PoseVisit], board: &Target) -> Option<f64> {
    // Every frame with corners, rejected ones too: a rejection was made with the file's lens,
    // the very thing judged here (a file that rejects every pose is the clearest case).
    let values: Vec<f64> = visits
        .iter()
        .filter_map(|v| {
            let points: Vec<_> = v
                .corners_px
                .iter()
                .filter_map(|c| board.observation_point(c).map(|p| (p, c.pixel)))
                .collect();
            board_fit(lens, &points).map(|fit| fit.rms_px)
        })
        .collect();
    // Three frames at least to judge by.
    (values.len() >= 3).then(|| median(&values))
}
