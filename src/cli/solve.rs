//! `handeye solve <samples.yaml> [-o result.yaml] [--method ...] [--compare]`: solves a dataset
//! file (or a session folder), prints a short summary, and writes the result file atomically
//! (nothing is written on any error). `--compare` also prints every method's answer, residuals
//! and distance to the chosen method's answer in one table (`solve::compare`).

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, ValueEnum};

use handeye_config::{validate, SolveSpace};
use handeye_records::dataset::Dataset;
use handeye_records::result::ResultFile;
use handeye_records::SessionFolder;
use handeye_session::cell::{cameras, config_of_camera_folder, session_config};
use handeye_solve::{self as solve, Method, RobustLoss, SolveOptions, SolverChoice};

/// `--method`: the solver's one list of names ([`Method::NAMES`], the same the config's
/// `solver.method` takes), each with its one-line summary in `--help`.
fn method_parser() -> impl clap::builder::TypedValueParser<Value = Method> {
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    let values = Method::ALL.map(|m| {
        let aliases = Method::ALIASES
            .iter()
            .filter(move |(_, target)| *target == m)
            .map(|(alias, _)| *alias);
        PossibleValue::new(m.name())
            .help(m.summary())
            .aliases(aliases)
    });
    PossibleValuesParser::new(values).try_map(|name| name.parse::<Method>())
}

/// `--robust`: the solver's names of its losses ([`RobustLoss::NAMES`], as Python's `robust=`).
fn robust_parser() -> clap::builder::PossibleValuesParser {
    use clap::builder::{PossibleValue, PossibleValuesParser};
    PossibleValuesParser::new(
        RobustLoss::NAMES.map(|(name, help)| PossibleValue::new(name).help(help)),
    )
}

/// Solve space on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(super) enum SpaceArg {
    /// One board pose per frame, the `A = X·B·Y` solver.
    Pose,
    /// Every detected corner of every frame (needs a session folder), from the pose-space answer.
    Reprojection,
}

impl From<SpaceArg> for SolveSpace {
    fn from(space: SpaceArg) -> SolveSpace {
        match space {
            SpaceArg::Pose => SolveSpace::Pose,
            SpaceArg::Reprojection => SolveSpace::Reprojection,
        }
    }
}

/// Arguments of `handeye solve`.
#[derive(Debug, Args)]
pub(super) struct SolveArgs {
    /// Dataset file (setup + samples of T_base_flange and T_camera_target), or a session folder
    /// (a several-camera cell's: the joint solve of its records).
    samples: PathBuf,
    /// Session folder only: solve in this space (default: the session config's `solver.space`).
    /// The pose-space options below apply to dataset files; a session uses its config's solver.
    #[arg(long, value_enum)]
    space: Option<SpaceArg>,
    /// Session folder only: use this cell config instead of the one the session was run with.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Write the result YAML here.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Estimator.
    #[arg(long, value_parser = method_parser(), default_value = Method::Refined.name())]
    method: Method,
    /// Per-axis rotation noise of T_camera_target, degrees: used as given (default: estimated
    /// from the residuals, starting from 0.2°).
    #[arg(long)]
    rotation_sigma_deg: Option<f64>,
    /// Per-axis translation noise of T_camera_target, mm: used as given (default: estimated
    /// from the residuals, starting from 1 mm).
    #[arg(long)]
    translation_sigma_mm: Option<f64>,
    /// Robust loss of the refinement.
    #[arg(long, value_parser = robust_parser(), default_value = "none")]
    robust: String,
    /// Scale of the robust loss, in sigmas.
    #[arg(long, default_value_t = 3.0)]
    robust_scale: f64,
    /// Drop samples whose residual is an outlier against the fit of the rest (the default; kept
    /// for old command lines).
    #[arg(long, conflicts_with = "keep_outliers")]
    drop_outliers: bool,
    /// Fit every sample, only flag outliers (the default leaves them out, each named).
    #[arg(long)]
    keep_outliers: bool,
    /// Take every view as equally precise (the default weighs each sample by how precisely its
    /// view fixed its board pose, when the samples record it).
    #[arg(long)]
    every_view_alike: bool,
    /// Start the iterative method from the closed form instead of the identity.
    #[arg(long)]
    warm_start: bool,
    /// Also solve with every method and print their answers, residuals and distances to the
    /// chosen method's answer in one table (pose space).
    #[arg(long)]
    compare: bool,
}

impl SolveArgs {
    fn options(&self) -> anyhow::Result<SolveOptions> {
        // Checked as the Python package and the config's `solver:` section check them.
        validate::check_solver_choice(
            self.rotation_sigma_deg,
            self.translation_sigma_mm,
            self.robust_scale,
            &|setting| format!("--{}", setting.replace('_', "-")),
        )
        .map_err(anyhow::Error::msg)?;
        Ok(SolverChoice {
            method: self.method,
            rotation_sigma_deg: self.rotation_sigma_deg,
            translation_sigma_mm: self.translation_sigma_mm,
            estimate_noise: true,
            robust: RobustLoss::named(&self.robust, self.robust_scale)
                .map_err(anyhow::Error::msg)?,
            drop_outliers: !self.keep_outliers,
            weigh_views: !self.every_view_alike,
            warm_start: self.warm_start,
        }
        .options())
    }
}

/// `handeye solve <session>`: both answers side by side; writes `-o` or `<session>/result-<space>.yaml`.
fn run_session(args: &SolveArgs) -> anyhow::Result<()> {
    let folder = SessionFolder::open(&cameras::session_to_read(&args.samples))?;
    let manifest = folder.read_manifest()?;
    let config = config_of_camera_folder(
        session_config(args.config.as_deref(), &manifest.config)?,
        folder.root(),
    )
    .context("reading the cell config")?;
    let space = args.space.map_or(config.solver.space, SolveSpace::from);
    let inputs = handeye_records::SolveInputs::load(config)?;
    // A run still recording: said before the solve (whose failure with few samples so far is
    // then read as such) and after the answer; the result file holds it too, as the solve's
    // first notice.
    let provisional = folder
        .live_run()
        .map(|run| format!("provisional: {run}; this answer is of the samples so far: solve again when the run has ended"));
    if let Some(line) = &provisional {
        outln!("{line}");
    }
    let (solved, dataset) = handeye_records::load_and_solve(&folder, &inputs, space)
        .with_context(|| format!("solving session {}", args.samples.display()))?;
    let config = &inputs.config;
    outln!("{}", solved.summary);
    if let Some(truth) = &config.camera().simulation {
        outln!("{}", solved.compare_with_truth(truth));
    }
    if args.compare {
        let comparison =
            solve::compare::compare(dataset.setup, &dataset.pairs, &config.solver.to_options())
                .with_context(|| format!("comparing methods on {}", args.samples.display()))?;
        outln!("{}", comparison.table());
    }
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| args.samples.join(format!("result-{}.yaml", space.name())));
    handeye_records::create_parent_dir(&output)?;
    solved.result_file(&dataset.pairs, config).save(&output)?;
    outln!("wrote {}", output.display());
    if let Some(line) = &provisional {
        outln!("{line}");
    }
    Ok(())
}

/// `handeye solve <several-camera session>`: the joint solve of the measurements its pose
/// records hold, as the run's own solve (`handeye replay` measures the frames again); writes
/// `-o` or `<session>/result-<space>.yaml`, the estimates of a blamed file in
/// `replay-estimates/` beside it, never over the run's files.
fn run_cameras_session(args: &SolveArgs) -> anyhow::Result<()> {
    let root = &args.samples;
    anyhow::ensure!(
        !args.compare,
        "--compare compares the methods on one camera's samples; {} is a several-camera session: compare a camera's, `handeye solve {} --compare`",
        root.display(),
        cameras::camera_folder(root, "<name>").join("samples.yaml").display()
    );
    handeye_records::refuse_live(
        root,
        "solve it when the run has ended: its joint answer is written then",
    )?;
    let recorded = cameras::read_manifest(root)?.config;
    let mut config = session_config(args.config.as_deref(), &recorded)?;
    if let Some(space) = args.space {
        config.solver.space = space.into();
    }
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| root.join(format!("result-{}.yaml", config.solver.space.name())));
    let visits = cameras::recorded_visits(root, &config)?;
    let written = handeye_session::cell::replay::AnswerOutput::replay(root, Some(&output));
    let result = cameras::solve_cameras_folder(root, &config, visits, &written)
        .with_context(|| format!("solving session {}", root.display()))?;
    super::cameras::print_result(&result, &output);
    Ok(())
}

/// Runs `handeye solve`.
pub(super) fn run(args: SolveArgs) -> anyhow::Result<()> {
    if cameras::is_cameras_folder(&cameras::session_to_read(&args.samples)) {
        return run_cameras_session(&args);
    }
    if args.samples.is_dir() {
        return run_session(&args);
    }
    anyhow::ensure!(
        args.space != Some(SpaceArg::Reprojection),
        "--space reprojection needs a session folder (the corners are recorded in <session>/poses/NNN.yaml); {} is a dataset file",
        args.samples.display()
    );
    let options = args.options()?;
    // A session's samples.yaml, given as a file, while its run records more.
    if let Some(folder) = args.samples.parent() {
        super::say_if_live(folder)?;
    }
    let dataset = Dataset::load(&args.samples)?;
    let result = solve::solve(dataset.setup, &dataset.pairs, &options);
    // The verdict comes first, also when the solve is refused (REDO, with the reason).
    let verdict = handeye_solve::verdict::assess_result(
        result.as_ref(),
        &dataset.pairs,
        &options,
        Default::default(),
    );
    outln!("{}", verdict.terminal_lines());
    let calibration = result.with_context(|| format!("solving {}", args.samples.display()))?;

    outln!("{} samples", dataset.pairs.len());
    outln!("{}", calibration.summary());
    if args.compare {
        let comparison = solve::compare::compare(dataset.setup, &dataset.pairs, &options)
            .with_context(|| format!("comparing methods on {}", args.samples.display()))?;
        outln!("{}", comparison.table());
    }
    if let Some(output) = &args.output {
        handeye_records::create_parent_dir(output)?;
        ResultFile::from_calibration(&calibration, &dataset.pairs)
            .with_verdict(verdict)
            .save(output)?;
        outln!("wrote {}", output.display());
    }
    Ok(())
}
