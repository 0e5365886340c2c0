//! Replay: detect the board again in a session's saved frames and solve again, offline — to
//! check a result, or to re-run with other detector or solver settings.

use std::path::{Path, PathBuf};

use handeye_core::camera_model::CameraModel;
use handeye_records::dataset::Dataset;
use handeye_vision::{DetectorOptions, Target, TargetDetector};

use crate::driver::measure;
use handeye_records::{PoseVisit, SessionError, SessionFolder};

/// A replay's result file in the session folder when no other is asked for.
pub const REPLAY_RESULT_FILE: &str = "replay-result.yaml";
/// The folder beside a replay's result that holds its estimates of wrong files.
pub const REPLAY_ESTIMATES_FOLDER: &str = "replay-estimates";

/// `name` in the folder of the file `file` (the working folder for a bare file name).
pub fn beside(file: &Path, name: &str) -> PathBuf {
    match file.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir.join(name),
        _ => PathBuf::from(name),
    }
}

/// Re-detects every saved frame of `folder` and returns the dataset the frames give now, with the
/// visits as re-measured (in plan order).
pub fn redetect(
    folder: &SessionFolder,
    board: &Target,
    camera_model: &CameraModel,
    detector: DetectorOptions,
    max_rms: f64,
) -> Result<(Dataset, Vec<PoseVisit>), SessionError> {
    let manifest = folder.read_manifest()?;
    let detector =
        TargetDetector::spawn(board, detector).map_err(|e| SessionError::Detector(Box::new(e)))?;
    let mut samples = Vec::new();
    let mut visits = Vec::new();
    for recorded in folder.read_visits()? {
        let frame_path = folder.root().join(&recorded.frame);
        let image = image::open(&frame_path)
            .map_err(|source| SessionError::Frame {
                path: frame_path.clone(),
                source: Box::new(source),
            })?
            .into_luma8();
        let visit = measure(
            &detector,
            board,
            Some(camera_model),
            &image,
            max_rms,
            PoseVisit::new(
                recorded.plan_index,
                &recorded.base_from_flange,
                recorded.frame.clone(),
            ),
        )?;
        samples.extend(visit.sample());
        visits.push(visit);
    }
    Ok((
        Dataset {
            setup: manifest.setup,
            pairs: samples,
        },
        visits,
    ))
}
