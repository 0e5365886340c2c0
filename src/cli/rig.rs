//! The several-camera forms of `handeye run` and `handeye replay` (a config with `cameras:`, a
//! session folder with `rig.yaml`): turns the arguments into a call of
//! [`cell::rig::run_rig`] / [`cell::rig::solve_rig_folder`] and prints every camera's answer.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use anyhow::Context;

use handeye::cell::rig::{self, RigEvent, RigResultFile};
use handeye::config::rig::RigConfig;

/// `handeye run` of a several-camera config (new, or resuming `resume`).
pub(super) fn run(config: Option<&Path>, out: PathBuf, resume: bool) -> anyhow::Result<()> {
    let config = match config {
        Some(c) => c.to_path_buf(),
        None => {
            rig::read_manifest(&out)
                .with_context(|| format!("{}: reading the several-camera session", out.display()))?
                .config
        }
    };
    let stop = Arc::new(AtomicBool::new(false));
    super::stop_on_signals(stop.clone());
    let mut progress = |event: &RigEvent| {
        let p = match event {
            RigEvent::Planned(views) => {
                let seen: Vec<String> = views
                    .iter()
                    .map(|v| format!("{} {}/{}", v.camera, v.poses, v.of))
                    .collect();
                outln!(
                    "poses where each camera should see its board (nominal cell): {}",
                    seen.join(" · ")
                );
                return;
            }
            RigEvent::Pose(p) => p,
        };
        let cameras: Vec<String> = p
            .captures
            .iter()
            .map(|c| match (&c.rejected, c.reprojection_rms_px) {
                (None, Some(rms)) => format!("{} {rms:.2} px", c.camera),
                (Some(why), _) => format!("{} no sample ({why})", c.camera),
                (None, None) => format!("{} no sample", c.camera),
            })
            .collect();
        outln!(
            "pose {:>3}/{}: {}",
            p.plan_index + 1,
            p.of,
            cameras.join(" · ")
        );
    };
    let done = rig::run_rig(&config, &out, resume, stop, &mut progress)?;
    for f in &done.failed_cameras {
        outln!(
            "camera `{}` stopped delivering frames at plan pose {} ({}): its samples until then are kept and solved; `handeye run --resume {}` asks it again for the poses it missed",
            f.camera,
            f.plan_index,
            f.error,
            done.folder.display()
        );
    }
    outln!(
        "{} poses visited in this run, arm time {:.1} s (shared by all cameras)",
        done.visited_now,
        done.arm_time_s
    );
    print_result(&done.result, &done.folder);
    let report = handeye::report::rig::write_rig_report(&done.folder)?;
    outln!("report: {}", report.display());
    Ok(())
}

/// `handeye replay` of a several-camera session folder: the joint solve again from its records.
pub(super) fn replay(folder: &Path, config: Option<&Path>) -> anyhow::Result<()> {
    let config = match config {
        Some(c) => c.to_path_buf(),
        None => rig::read_manifest(folder)?.config,
    };
    let rig_config = RigConfig::load(&config)?;
    let result = rig::solve_rig_folder(folder, &rig_config)?;
    print_result(&result, folder);
    let report = handeye::report::rig::write_rig_report(folder)?;
    outln!("report: {}", report.display());
    Ok(())
}

/// Prints every camera's mount, the boards and the camera-to-camera transforms.
pub(super) fn print_result(result: &RigResultFile, folder: &Path) {
    let line = |t: &rig::solve::NamedTransform| {
        let p = t.pose.translation.vector;
        let truth = match (t.truth_error_mm, t.truth_error_deg) {
            (Some(mm), Some(deg)) => format!("  (vs simulator truth: {mm:.3} mm, {deg:.4}°)"),
            _ => String::new(),
        };
        format!(
            "{:<24} t = [{:.4}, {:.4}, {:.4}] m  ±{:.3} mm ±{:.4}°{truth}",
            t.name, p.x, p.y, p.z, t.sigma.translation_mm, t.sigma.rotation_deg
        )
    };
    for camera in &result.cameras {
        match &camera.joint {
            Some(t) => outln!(
                "{}   [{}: {} samples, {}]",
                line(t),
                camera.verdict,
                camera.samples,
                camera.reason
            ),
            None => outln!(
                "camera `{}`: {} ({})",
                camera.name,
                camera.verdict,
                camera.left_out.as_deref().unwrap_or(&camera.reason)
            ),
        }
    }
    for t in result.boards.iter().chain(&result.camera_to_camera) {
        outln!("{}", line(t));
    }
    outln!("cell: {} — {}", result.verdict, result.reason);
    outln!("result: {}", folder.join("result.yaml").display());
}
