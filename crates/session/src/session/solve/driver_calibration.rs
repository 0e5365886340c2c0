//! The camera driver's own calibration against the config's intrinsics file (issue #39): a ROS 2
//! run keeps the `CameraInfo` the driver published (`camera_info_from_topic.yaml`); when the
//! config names a file that differs from it, the result says so, with which of the two the
//! board's corners fit better (each frame's board pose solved again with either lens), so a
//! stale file or a driver streaming another resolution's calibration is named, not guessed.

use handeye_core::camera_model::CameraModel;
use handeye_core::notice::{Notice, NoticeKind};
use handeye_vision::Target;

use super::board_pose;
use super::intrinsics_check::{differing_parameters, median};
use crate::session::{PoseVisit, SessionFolder};

/// The file in a session folder that keeps the calibration a ROS 2 camera driver published on
/// its camera_info topic.
pub const DRIVER_CALIBRATION_FILE: &str = "camera_info_from_topic.yaml";

/// The notice of a config intrinsics `file` (loaded as `file_model`) that differs from the
/// driver's calibration kept in `folder`; `None` when there is none or they agree.
pub(super) fn driver_calibration_notice(
    folder: &SessionFolder,
    file: &std::path::Path,
    file_model: &CameraModel,
    visits: &[PoseVisit],
    board: &Target,
) -> Option<Notice> {
    let kept = folder.root().join(DRIVER_CALIBRATION_FILE);
    let driver = CameraModel::load(&kept).ok()?;
    let rows = differing_parameters(file_model, &driver, "from the driver");
    let sizes_differ = (file_model.width, file_model.height) != (driver.width, driver.height);
    if rows.is_empty() && !sizes_differ {
        return None;
    }
    let (file_rms, driver_rms) = (
        median_fit(file_model, visits, board),
        median_fit(&driver, visits, board),
    );
    let fit = match (file_rms, driver_rms) {
        (Some(f), Some(d)) if d < f => format!(
            "the board's corners fit the driver's better (median {d:.2} px RMS per frame against {f:.2} px with the file): drop `intrinsics:` to use what the driver publishes, or calibrate again"
        ),
        (Some(f), Some(d)) => format!(
            "the board's corners fit the file better (median {f:.2} px RMS per frame against {d:.2} px with the driver's): the driver publishes a calibration that is not this camera's at this resolution; the file was used"
        ),
        _ => "too few frames to tell which fits the corners better; the file was used".into(),
    };
    let what = if sizes_differ {
        format!(
            "the file is for {}x{} px, the driver's for {}x{} px",
            file_model.width, file_model.height, driver.width, driver.height
        )
    } else {
        rows.join("; ")
    };
    Some(Notice::warning(
        NoticeKind::Other,
        format!(
            "the intrinsics in {} differ from the calibration the camera driver publishes (kept in {}): {what}; {fit}",
            file.display(),
            kept.display()
        ),
    ))
}

/// The median per-frame board reprojection RMS of `visits` with the board pose solved by `lens`,
/// px; `None` without three frames to judge by.
fn median_fit(lens: &CameraModel, visits: &[PoseVisit], board: &Target) -> Option<f64> {
    let values: Vec<f64> = visits
        .iter()
        .filter(|v| v.rejected.is_none())
        .filter_map(|v| {
            let points: Vec<_> = v
                .corners_px
                .iter()
                .filter_map(|c| board.observation_point(c).map(|p| (p, c.pixel)))
                .collect();
            let pose = board_pose(lens, &points)?;
            let squares: Vec<f64> = points
                .iter()
                .filter_map(|(p, px)| lens.project(&(pose * p)).map(|q| (q - px).norm_squared()))
                .collect();
            (!squares.is_empty())
                .then(|| (squares.iter().sum::<f64>() / squares.len() as f64).sqrt())
        })
        .collect();
    // Three frames at least to judge by.
    if values.len() < 3 {
        return None;
    }
    median(values)
}
