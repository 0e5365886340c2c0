//! Solving a session folder: `samples.yaml` in, `result.yaml` out, with a summary for people and,
//! in the simulated cell, the error against the ground truth.

use crate::config::CellConfig;
use crate::dataset::Dataset;
use crate::geometry::Pose;
use crate::plan::CellTransforms;
use crate::result::ResultFile;
use crate::solve::{self, Calibration};

use super::{SessionError, SessionFolder};

/// A solved session.
pub struct SolvedSession {
    /// The calibration.
    pub calibration: Calibration,
    /// A short human summary.
    pub summary: String,
}

/// Solves the folder's `samples.yaml` with the config's solver settings and writes `result.yaml`.
pub fn solve_folder(
    folder: &SessionFolder,
    config: &CellConfig,
) -> Result<SolvedSession, SessionError> {
    let dataset =
        Dataset::load(&folder.samples_path()).map_err(|e| SessionError::Solve(e.to_string()))?;
    let options = config.solver.to_options();
    let calibration = solve::solve(dataset.setup, &dataset.pairs, &options)
        .map_err(|e| SessionError::Solve(e.to_string()))?;
    ResultFile::from_calibration(&calibration, &dataset.pairs)
        .save(&folder.result_path())
        .map_err(|e| SessionError::Solve(e.to_string()))?;
    let summary = calibration.summary();
    Ok(SolvedSession {
        calibration,
        summary,
    })
}

impl SolvedSession {
    /// The error of each unknown against the simulator's truth, one line each.
    pub fn compare_with_truth(&self, truth: &CellTransforms) -> String {
        let [(camera_key, camera_mount), (target_key, target_mount)] = self.calibration.unknowns();
        let line = |key: &str, estimate: &Pose, truth: &Pose| {
            format!(
                "  {key}: error {:.3} mm, {:.4}° against the simulator's ground truth",
                (estimate.translation.vector - truth.translation.vector).norm() * 1e3,
                estimate.rotation.angle_to(&truth.rotation).to_degrees()
            )
        };
        format!(
            "ground truth check:\n{}\n{}",
            line(camera_key, &camera_mount, &truth.camera_mount),
            line(target_key, &target_mount, &truth.target_mount)
        )
    }
}
