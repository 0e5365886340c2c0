//! `handeye plan generate|check`: make a plan, or validate one with the arm standing still.

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::{Args, Subcommand};

use handeye_plan::{generate, GenerateSpec, Plan, Waypoint};
use handeye_session::cell;

/// Generate or check pose plans.
#[derive(Debug, Args)]
pub(super) struct PlanArgs {
    #[command(subcommand)]
    command: PlanCommand,
}

#[derive(Debug, Subcommand)]
enum PlanCommand {
    /// Sample views on a spherical cap above the board and write them as a scripted plan.
    Generate {
        /// Number of views.
        #[arg(short = 'n', long, default_value_t = 20)]
        count: usize,
        /// Nearest camera-to-board distance, m.
        #[arg(long, default_value_t = 0.45)]
        near: f64,
        /// Farthest camera-to-board distance, m.
        #[arg(long, default_value_t = 0.65)]
        far: f64,
        /// Largest tilt from the board normal, degrees.
        #[arg(long, default_value_t = 30.0)]
        max_tilt_deg: f64,
        /// Largest roll about the optical axis, degrees.
        #[arg(long, default_value_t = 30.0)]
        max_roll_deg: f64,
        /// Jitter seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Fit the views to this cell's camera and board: push the board across the image by
        /// `--image-spread` (default: 0.8 when the config has no intrinsics, 0 otherwise).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Share (0–1) of the room between the centred board and the image border the views
        /// push the board towards (needs --config).
        #[arg(long, requires = "config")]
        image_spread: Option<f64>,
        /// Where to write the plan.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Check the plan a cell config names: reach, joint limits, workspace box, board in view,
    /// rotation diversity, move times. Exits non-zero when any check fails. Nothing moves.
    Check {
        /// The cell config.
        #[arg(long)]
        config: PathBuf,
    },
}

/// Runs `handeye plan`.
pub(super) fn run(args: PlanArgs) -> anyhow::Result<()> {
    match args.command {
        PlanCommand::Generate {
            count,
            near,
            far,
            max_tilt_deg,
            max_roll_deg,
            seed,
            config,
            image_spread,
            output,
        } => {
            let spec = GenerateSpec {
                count,
                distance: [near, far],
                max_tilt_deg,
                max_roll_deg,
                seed,
                image_spread,
            };
            if let Err(problem) = spec.validate() {
                bail!("{problem}");
            }
            let views = match &config {
                Some(config) => cell::prepare(config)
                    .context("preparing the cell")?
                    .generate_views(&spec),
                None => generate(&spec),
            };
            let plan = Plan {
                waypoints: views.into_iter().map(Waypoint::LookAt).collect(),
            };
            plan.save(&output)?;
            outln!(
                "wrote {count} look-at views to {}; check them with `handeye plan check`",
                output.display()
            );
            Ok(())
        }
        PlanCommand::Check { config } => {
            let prepared = cell::prepare(&config).context("preparing the cell")?;
            outln!("{}", prepared.report);
            // An adaptive generated plan chooses among more views than its own: every one it
            // may visit is listed, with the number the run names it by.
            let extra = cell::run::extra_candidates(&prepared);
            if let Some(extra) = &extra {
                let plan_poses = prepared.report.poses.len();
                outln!(
                    "adaptive plan: the run visits at most {} of these {} candidates, the next-best one at each step; the {} poses above and these {} more (numbered from {plan_poses}):",
                    prepared.config.plan.max_poses.unwrap_or(plan_poses),
                    plan_poses + extra.poses.len(),
                    plan_poses,
                    extra.poses.len(),
                );
                outln!("{extra}");
            }
            // Good enough to check views with, never to calibrate: `run` refuses it.
            if let Some((file, name)) = prepared.placeholder_intrinsics() {
                outln!(
                    "warning: {} is the shipped placeholder (camera_name: {name}), not this camera's calibration: `handeye run` refuses it; calibrate the camera and point `intrinsics:` at its camera_info file, or drop `intrinsics:` so the run estimates them",
                    file.display()
                );
            }
            // The checks the run makes before anything moves (`check_plan`): a plan it would
            // refuse fails here with the run's words. Each camera of several: the share of the
            // plan it should see its board at (the plan is made for one camera).
            if let Some(views) = cell::run::check_plan(&prepared)? {
                outln!("{}", super::cameras::planned_views_line(&views));
            }
            // An adaptive plan's poses (and its extra candidates) are candidates: the run skips
            // the ones that fail.
            if prepared.config.adaptive() && !prepared.report.ok() {
                let every: Vec<_> = prepared
                    .report
                    .poses
                    .iter()
                    .chain(extra.iter().flat_map(|e| e.poses.iter()))
                    .collect();
                let skipped: Vec<String> = every
                    .iter()
                    .filter(|p| !p.problems.is_empty())
                    .map(|p| p.index.to_string())
                    .collect();
                let passing = every.len() - skipped.len();
                outln!(
                    "adaptive plan: {passing} of its {} candidates pass; the run skips the {} that fail (poses {})",
                    every.len(),
                    skipped.len(),
                    skipped.join(", ")
                );
            }
            Ok(())
        }
    }
}
