//! `handeye run`: validate the plan, drive the cell, record, solve, report.

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use handeye::cell;
use handeye::geometry::Pose;
use handeye::plan::nbv::AdaptivePlanner;
use handeye::robot::Joints;
use handeye::session::{self, SessionEvent, SessionFolder};

/// Calibrate a cell: move through the plan, record every frame and pose, solve.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// The cell config (robot, camera, board, plan, limits).
    #[arg(long, required_unless_present = "resume")]
    config: Option<PathBuf>,
    /// Where to write the session folder (default: sessions/<date-time>).
    #[arg(long, conflicts_with = "resume")]
    out: Option<PathBuf>,
    /// Continue an interrupted session in this folder.
    #[arg(long)]
    resume: Option<PathBuf>,
    /// Do not ask for confirmation before moving a real robot.
    #[arg(long)]
    yes: bool,
}

/// Runs `handeye run`.
pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let (folder, config_path) = match &args.resume {
        Some(dir) => {
            let folder = SessionFolder::open(dir)?;
            let manifest = folder.read_manifest()?;
            let config = args.config.clone().unwrap_or(manifest.config);
            (Some(folder), config)
        }
        None => (None, args.config.clone().expect("clap requires --config")),
    };
    let mut prepared = cell::prepare(&config_path)
        .with_context(|| format!("preparing the cell from {}", config_path.display()))?;
    println!("{}", prepared.report);
    // Adaptive: the plan's poses are candidates; the ones that fail their checks are skipped.
    let adaptive = prepared.config.plan.adaptive;
    if adaptive && !prepared.intrinsics_known {
        bail!("an adaptive plan needs the camera intrinsics (it chooses poses from board poses as they come): give `intrinsics:` or use a fixed plan");
    }
    if adaptive && prepared.report.passing().is_empty() {
        bail!("no pose of the plan passes its checks (see the table above); nothing was moved");
    }
    if !adaptive && !prepared.report.ok() {
        bail!("the plan failed its checks (see the table above); nothing was moved");
    }
    let poses = prepared.plan.waypoints.len();
    if !prepared.is_simulated() && !args.yes {
        super::confirm_motion(&prepared, poses)?;
    }
    let mut hardware = prepared
        .open_hardware()
        .context("opening the robot and camera")?;
    super::ensure_robot_ready(hardware.robot.as_mut())?;
    // The plan was checked from an assumed start; check it again from where the arm really is
    // before the first move.
    let start = hardware
        .robot
        .joint_positions()
        .context("reading the arm's joint positions")?;
    let plan = if adaptive {
        let _ = prepared.recheck_from(start);
        let candidates = prepared.report.passing();
        if candidates.is_empty() {
            bail!("from the arm's actual position no pose of the plan passes its checks; nothing was moved:\n{}", prepared.report);
        }
        candidates
    } else {
        match prepared.recheck_from(start) {
            Ok(plan) => plan,
            Err(report) => bail!("from the arm's actual position the plan fails its checks; nothing was moved:\n{report}"),
        }
    };

    let folder = match folder {
        Some(folder) => {
            // An adaptive session's plan is what it chose so far: it continues from there.
            if !adaptive {
                same_plan_as_recorded(&folder, &plan)?;
            }
            folder
        }
        None => {
            let out = args.out.clone().unwrap_or_else(default_session_dir);
            let folder = SessionFolder::create(&out)?;
            // An adaptive session writes its manifest as the plan grows.
            if !adaptive {
                folder.write_manifest(&prepared.manifest(&plan))?;
            }
            folder
        }
    };
    let stop = super::stop_on_ctrl_c();

    let setup = prepared.session_setup(folder.clone(), plan.clone(), stop);
    let bar = progress_bar(poses as u64);
    let mut on_event = |event: SessionEvent| match event {
        SessionEvent::Moving { plan_index } => {
            bar.set_message(format!("moving to pose {plan_index}"))
        }
        SessionEvent::Recorded {
            plan_index,
            reprojection_rms_px,
            tags,
            rejected,
            will_retry,
        } => {
            let line = match (&rejected, reprojection_rms_px) {
                (None, Some(rms)) => {
                    format!("pose {plan_index:>3}: ok, {tags} tags, board RMS {rms:.3} px")
                }
                (Some(why), _) if will_retry => {
                    format!("pose {plan_index:>3}: {why}; will retry once")
                }
                (Some(why), _) => format!("pose {plan_index:>3}: skipped: {why}"),
                (None, None) => format!("pose {plan_index:>3}: ok"),
            };
            bar.println(line);
            if !will_retry {
                bar.inc(1);
            }
        }
    };
    let mut adaptive_note = None;
    let outcome = if adaptive {
        let mut planner = AdaptivePlanner::new(
            prepared.config.setup,
            prepared.config.nominal.camera_mount,
            prepared.config.nominal.target_mount,
            plan.clone(),
            prepared.config.solver.to_options(),
            prepared.config.plan.target_uncertainty_mm,
            plan.len(),
        );
        let outcome = session::run_adaptive_session(
            setup,
            prepared.config_path(),
            &mut planner,
            hardware.robot.as_mut(),
            hardware.camera.as_mut(),
            &mut on_event,
        );
        let in_session = folder.read_manifest().map(|m| m.plan.len()).unwrap_or(0);
        adaptive_note = Some(format!(
            "adaptive plan: {in_session} of {} candidate poses in the session ({} chosen in this run); target 1-sigma {:.3} mm {}",
            plan.len(),
            planner.log.iter().filter(|s| s.chose.is_some()).count(),
            prepared.config.plan.target_uncertainty_mm,
            match planner.log.last().and_then(|s| s.solved_sigma_mm) {
                Some(s) if planner.reached_target() => format!("reached ({s:.3} mm)"),
                Some(s) => format!("NOT reached ({s:.3} mm): candidates ran out"),
                None => "NOT reached (no solve)".into(),
            }
        ));
        outcome
    } else {
        session::run_session(
            setup,
            hardware.robot.as_mut(),
            hardware.camera.as_mut(),
            &mut on_event,
        )
    };
    bar.finish_and_clear();
    if let Some(note) = adaptive_note {
        println!("{note}");
    }
    let outcome = outcome?;
    if !outcome.skipped.is_empty() {
        println!(
            "skipped poses: {}",
            outcome
                .skipped
                .iter()
                .map(|(i, why)| format!("{i} ({why})"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let result = session::solve_folder(&folder, &prepared.config)?;
    println!("{}", result.summary);
    if let Some(truth) = &prepared.config.simulation {
        println!("{}", result.compare_with_truth(truth));
    }
    let mut answers = Vec::new();
    if result.reprojection.is_some() {
        answers.push(("reprojection space".to_string(), result.calibration.clone()));
    }
    answers.push(("pose space".to_string(), result.pose_space.clone()));
    match handeye::report::session::write_session_report(&folder, Some(&prepared.config), answers) {
        Ok(path) => println!("report: {}", path.display()),
        // The calibration is saved; a report problem must not hide it.
        Err(e) => eprintln!("warning: the report could not be written: {e:#}"),
    }
    println!("session folder: {}", folder.root().display());
    Ok(())
}

/// A resumed session must visit the poses it was started with: the config may not have changed.
fn same_plan_as_recorded(folder: &SessionFolder, plan: &[(Pose, Joints)]) -> anyhow::Result<()> {
    let manifest = folder.read_manifest()?;
    let same = manifest.plan.len() == plan.len()
        && manifest
            .plan
            .iter()
            .zip(plan)
            .enumerate()
            .all(|(i, (recorded, (pose, _)))| {
                recorded
                    .base_from_flange
                    .to_pose(&format!("plan[{i}]"))
                    .map(|r| {
                        r.rotation.angle_to(&pose.rotation) < 1e-9
                            && (r.translation.vector - pose.translation.vector).norm() < 1e-9
                    })
                    .unwrap_or(false)
            });
    if !same {
        bail!(
            "the plan from the config differs from the one {} was started with; resume with the same config, or start a new session",
            folder.root().display()
        );
    }
    Ok(())
}

fn default_session_dir() -> PathBuf {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    PathBuf::from(format!("sessions/session-{now}"))
}

fn progress_bar(len: u64) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} poses  ETA {eta}  {msg}")
            .expect("valid template"),
    );
    bar
}
