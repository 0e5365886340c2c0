//! The several-camera ends of `handeye run`, `replay` and `solve` (a config with `cameras:`, a
//! session folder with `rig.yaml`): every camera's answer printed. The run itself is
//! `cell::run::run` and the replay `cell::replay::replay_session`, as for one camera, and their
//! pages are written as one camera's are.

use std::path::Path;

use handeye_records::result::CellResult;
use handeye_session::cell::replay::AnswerOutput;
use handeye_session::cell::run::CellRun;
use handeye_solve::verdict::Verdict;

/// What `handeye run` of a several-camera cell prints before its report (the run itself is
/// `cell::run::run`, its report `write_run_report`, as for one camera): what the run did and
/// every camera's answer. Returns the line printed last, after the report's path.
pub(super) fn print_run(done: &CellRun) -> String {
    outln!(
        "{} poses visited in this run, arm time {:.1} s (shared by all cameras)",
        done.outcome.visited_now,
        done.outcome.arm_time_s()
    );
    let output = AnswerOutput::run(&done.root);
    print_result(&done.result, &output.result);
    format!(
        "next: handeye export {} --format ros2|urdf|opencv",
        output.result.display()
    )
}

/// Prints every camera's mount, the boards and the camera-to-camera transforms.
pub(super) fn print_result(result: &CellResult, result_file: &Path) {
    let line = |t: &handeye_records::result::NamedTransform| {
        let p = t.pose.translation.vector;
        let sigma = t.sigma.map_or_else(String::new, |s| {
            format!("  ±{:.3} mm ±{:.4}°", s.translation_mm, s.rotation_deg)
        });
        let truth = match (t.truth_error_mm, t.truth_error_deg) {
            (Some(mm), Some(deg)) => format!("  (vs simulator truth: {mm:.3} mm, {deg:.4}°)"),
            _ => String::new(),
        };
        format!(
            "{:<24} t = [{:.4}, {:.4}, {:.4}] m{sigma}{truth}",
            t.name, p.x, p.y, p.z
        )
    };
    for camera in &result.cameras {
        let (level, reason) = verdict(camera.verdict.as_ref());
        match &camera.joint {
            Some(t) => outln!(
                "{}   [{level}: {} samples, {reason}]",
                line(t),
                camera.samples
            ),
            None => outln!(
                "camera `{}`: {level} ({})",
                camera.name,
                camera.left_out.as_deref().unwrap_or(reason)
            ),
        }
    }
    for t in result.boards.iter().chain(&result.camera_to_camera) {
        outln!("{}", line(t));
    }
    let (level, reason) = verdict(result.verdict.as_ref());
    outln!("cell: {level} — {reason}");
    outln!("result: {}", result_file.display());
}

/// A verdict's level and reason as printed; a file without one says so.
fn verdict(verdict: Option<&Verdict>) -> (String, &str) {
    verdict.map_or(("no verdict".into(), ""), |v| {
        (v.level.to_string(), v.reason.as_str())
    })
}

/// The line saying how many of the plan's poses each camera should see its board at (nominal
/// cell): the run's before it moves, and `plan check`'s.
pub(super) fn planned_views_line(views: &[handeye_session::cell::cameras::PlannedViews]) -> String {
    let seen: Vec<String> = views
        .iter()
        .map(|v| format!("{} {}/{}", v.camera, v.poses, v.of))
        .collect();
    format!(
        "poses where each camera should see its board (nominal cell): {}",
        seen.join(" · ")
    )
}
