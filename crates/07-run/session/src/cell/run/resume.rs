//! A resumed session: its input files checked against the ones it recorded, and its recorded
//! plan matched with today's.

use handeye_core::geometry::Pose;
use handeye_records::{changed_inputs, SessionError, SessionFolder};
use handeye_robot::Joints;

use super::{RunError, RunObserver};

/// The resume check of every session kind (planned, adaptive, hand-guided): refuses, naming
/// each changed file, when the input files (`inputs`, hashed now) differ from those `manifest`
/// recorded, unless `accept` says why they are accepted (`--accept-changed`, or a session that
/// recorded nothing yet; then each change is noted and `manifest` takes the files
/// used now, which the next resume compares against). Returns whether `manifest` changed (the
/// caller writes it).
pub(super) fn check_resumed_inputs(
    folder: &SessionFolder,
    manifest: &mut handeye_records::SessionManifest,
    inputs: &[handeye_records::InputFile],
    accept: Option<&str>,
    observer: &mut dyn RunObserver,
) -> Result<bool, RunError> {
    if manifest.inputs.is_empty() {
        observer.note(&format!(
            "{}: records no input hashes (an older session): changes to the config, board, intrinsics or plan since it was recorded cannot be detected",
            folder.manifest_path().display()
        ));
        return Ok(false);
    }
    let changes = changed_inputs(&manifest.inputs, inputs);
    if !changes.is_empty() && accept.is_none() {
        return Err(SessionError::InputsChanged {
            folder: folder.root().to_path_buf(),
            changes,
        }
        .into());
    }
    for change in &changes {
        observer.note(&format!(
            "input changed, accepted ({}): {change}",
            accept.unwrap_or_default()
        ));
    }
    if manifest.inputs == inputs {
        return Ok(false);
    }
    manifest.inputs = inputs.to_vec();
    Ok(true)
}

/// A session a run continues.
#[derive(Debug)]
pub struct ResumedSession {
    /// Its folder, locked for this run.
    pub folder: SessionFolder,
    /// Its manifest, with the input files of this run when changes were accepted.
    pub manifest: handeye_records::SessionManifest,
    /// Whether `manifest` changed (accepted input changes, or the mark of a hand-guided session
    /// a planned resume handed over) and is not written to the folder yet.
    pub manifest_changed: bool,
    /// Pose records the session holds (none: it stopped before its first capture, and takes
    /// today's inputs and plan without `--accept-changed`).
    pub recorded_poses: usize,
}

/// A resumed fixed plan whose poses are `plan`'s in another order (a plan ordered for travel
/// time from where the arm stood when the session started): the recorded order, with the joints
/// of today's check. `None` when the poses differ.
pub(super) fn recorded_order(
    manifest: &handeye_records::SessionManifest,
    plan: &[(Pose, Joints)],
) -> Option<Vec<(Pose, Joints)>> {
    if manifest.plan.len() != plan.len() {
        return None;
    }
    let mut used = vec![false; plan.len()];
    manifest
        .plan
        .iter()
        .map(|recorded| {
            let r = recorded.base_from_flange;
            let k = (0..plan.len()).find(|&k| {
                !used[k]
                    && r.rotation.angle_to(&plan[k].0.rotation) < 1e-9
                    && (r.translation.vector - plan[k].0.translation.vector).norm() < 1e-9
            })?;
            used[k] = true;
            Some(plan[k])
        })
        .collect()
}

/// Whether a resumed session's recorded plan is `plan` (same flange poses, in order).
pub(super) fn same_plan(
    manifest: &handeye_records::SessionManifest,
    plan: &[(Pose, Joints)],
) -> bool {
    manifest.plan.len() == plan.len()
        && manifest.plan.iter().zip(plan).all(|(recorded, (pose, _))| {
            let r = recorded.base_from_flange;
            r.rotation.angle_to(&pose.rotation) < 1e-9
                && (r.translation.vector - pose.translation.vector).norm() < 1e-9
        })
}
