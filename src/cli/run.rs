//! `handeye run`: turns the arguments into a [`RunRequest`], calls [`cell::run::run`] (validate the
//! plan, drive the cell, record, solve), prints its progress and the result, writes the report.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use handeye_console::ConsoleObserver;
use handeye_core::geometry::Pose;
use handeye_session::cell::run::{
    open_run, RunError, RunObserver, RunRequest, SessionTarget, Strategy,
};
use handeye_session::cell::{self, PreparedCell};
use handeye_session::SessionEvent;
use handeye_solve::verdict::{Level, Verdict};

/// Calibrate a cell: move through the plan, record every frame and pose, solve.
#[derive(Debug, Args)]
pub(super) struct RunArgs {
    /// The cell config (robot, camera, board, plan, limits).
    #[arg(long, required_unless_present = "resume")]
    config: Option<PathBuf>,
    /// Where to write the session folder (default: sessions/YYYY-MM-DD_HH-MM-SS, the start time
    /// in UTC; `-2`, `-3`, ... appended if that folder exists).
    #[arg(
        short = 'o',
        long = "output",
        alias = "out",
        value_name = "DIR",
        conflicts_with = "resume"
    )]
    out: Option<PathBuf>,
    /// Continue an interrupted session in this folder.
    #[arg(long)]
    resume: Option<PathBuf>,
    /// Resume even though the config, board, intrinsics or plan file changed since the session
    /// was recorded (each change is listed).
    #[arg(long, requires = "resume")]
    accept_changed: bool,
    /// Do not ask for confirmation before moving a real robot.
    #[arg(long)]
    yes: bool,
    /// Serve the live console (frames, plan, coverage, estimate, STOP) on ADDR (default
    /// 127.0.0.1:8765; port 0 picks a free one); the URL is printed.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = handeye_console::DEFAULT_ADDR)]
    console: Option<std::net::SocketAddr>,
    /// Allow --console on an address beyond this machine (anyone who reaches it with the printed
    /// URL, whose secret it checks, can stop the run).
    #[arg(long = "public", alias = "console-public", requires = "console")]
    console_public: bool,
    /// After the run, keep serving the console until Enter (or Ctrl-C) so the page can be read.
    #[arg(long = "wait", alias = "console-wait", requires = "console")]
    console_wait: bool,
    /// Detection threads, each with a detector of its own (default: one per core, at most four,
    /// fewer when the memory limit leaves room for fewer).
    #[arg(short = 'j', long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=64))]
    jobs: Option<usize>,
}

/// Runs `handeye run`.
pub(super) fn run(args: RunArgs) -> anyhow::Result<()> {
    let target = match &args.resume {
        Some(dir) => SessionTarget::Resume(dir.clone()),
        None => SessionTarget::New(args.out.clone().unwrap_or_else(default_session_dir)),
    };
    let stop = Arc::new(AtomicBool::new(false));
    let request = RunRequest {
        config: args.config.clone(),
        target,
        motion_confirmed: args.yes,
        accept_changed: args.accept_changed,
        stop: stop.clone(),
        jobs: args.jobs,
    };
    let console = match args.console {
        Some(addr) => Some(super::console::start(
            addr,
            args.console_public,
            stop.clone(),
        )?),
        None => None,
    };
    let mut printer = Printer::new(stop.clone());
    let failed = |console: &Option<handeye_console::Console>, e: RunError| {
        let e = anyhow::Error::from(e);
        if let Some(console) = console {
            super::console::failed(console, &e, args.console_wait);
        }
        e
    };
    // The plan check is printed; the page is shown the cell when the run's strategy is known.
    let opened = open_run(&request, &mut printer).map_err(|e| failed(&console, e))?;
    // A hand-guided session — `plan: {manual: true}` for a new one, a session `handeye console`
    // recorded for a resume — goes on by hand on the console (as `handeye console`).
    if let Some(why) = opened.hand_guided() {
        outln!("{why}: hand-guided capture on the console (as `handeye console`)");
        let console = match console {
            Some(console) => console,
            None => super::console::start(handeye_console::DEFAULT_ADDR.parse()?, false, stop)?,
        };
        return super::console::hand_guided(&console, &request, opened, printer, args.console_wait);
    }
    let done = match &console {
        Some(console) => {
            let mut observer = ConsoleObserver::new(&mut printer, console);
            observer.show_cell(&opened.cell);
            let done = cell::run::run_opened(opened, &request, Strategy::Planned, &mut observer);
            observer.flush();
            done
        }
        None => cell::run::run_opened(opened, &request, Strategy::Planned, &mut printer),
    };
    let done = done.map_err(|e| failed(&console, e))?;
    let (report, next) = finish_run(&done)?;
    if let Some(console) = &console {
        super::console::finished(console, &done, report, next, args.console_wait);
    }
    Ok(())
}

/// Prints a finished run's result, writes its report; returns the report's path (when it could
/// be written) and the next step, printed last.
pub(super) fn finish_run(done: &cell::run::CellRun) -> anyhow::Result<(Option<PathBuf>, String)> {
    if !done.outcome.skipped.is_empty() {
        outln!(
            "skipped poses: {}",
            done.outcome
                .skipped
                .iter()
                .map(|(i, why)| format!("{i} ({why})"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    // A cell with several cameras: the joint answer, every camera named.
    let Some(solved) = &done.solved else {
        let next = super::cameras::print_run(done);
        let report = write_report(done);
        if let Some(report) = &report {
            outln!("report: {}", report.display());
        }
        outln!("{next}");
        return Ok((report, next));
    };
    outln!("{}", solved.summary);
    if let Some(truth) = &done.cell.config.camera().simulation {
        outln!("{}", solved.compare_with_truth(truth));
    }
    if let (Some(arm), Some(errors)) = (&solved.arm, &done.cell.config.arm_errors) {
        outln!("{}", arm.compare_with_truth(errors));
    }
    let report = write_report(done);
    // The session's own folder (a listed cell of one camera's root, where its answer is too).
    let result_path = done.root.join(handeye_records::RESULT_FILE);
    outln!();
    outln!("session: {}", done.root.display());
    outln!("result:  {}", result_path.display());
    if let Some(report) = &report {
        outln!("report:  {}", report.display());
    }
    let next = next_step(
        solved.verdict.as_ref(),
        &result_path,
        Stack::of(&done.cell.config.robot),
    );
    outln!("{next}");
    Ok((report, next))
}

/// The run's tail ([`cell::run::RunReport`]): its report, one camera or several; its path, or
/// why it could not be written.
pub(super) fn run_report(done: &cell::run::CellRun) -> Result<PathBuf, String> {
    handeye_report::session::write_run_report(done)
        .map_err(|e| format!("{:#}", anyhow::Error::from(e)))
}

/// Writes a finished run's report; its path, or `None` with a warning: the calibration is
/// saved, and a report problem must not hide it.
fn write_report(done: &cell::run::CellRun) -> Option<PathBuf> {
    run_report(done)
        .map_err(|e| eprintln!("warning: the report could not be written: {e}"))
        .ok()
}

/// The last line after a run: the export command, or what the verdict says to do first.
pub(super) fn next_step(
    verdict: Option<&Verdict>,
    result: &std::path::Path,
    stack: Stack,
) -> String {
    let result = shell_word(result);
    let export = match stack {
        // A ROS 2 cell wants the transforms on /tf_static (or in its launch files).
        Stack::Ros2 => format!(
            "handeye publish {result} (latched on /tf_static), or handeye export {result} --format ros2-launch|ros2|urdf|json"
        ),
        Stack::Controller => {
            format!("handeye export {result} --format ros2|urdf|ur|json|opencv")
        }
    };
    match verdict {
        Some(v) if v.level == Level::Redo => format!(
            "next: {} (the verdict is {}; do not export this result)",
            v.next_action,
            v.level.word()
        ),
        Some(v) if v.level == Level::Check => format!(
            "next: {} (the verdict is {}), then: {export}",
            v.next_action,
            v.level.word()
        ),
        _ => format!("next: {export}"),
    }
}

/// Where the answer goes next: a ROS 2 graph (a ROS 2 arm, a bag), or anything else (the
/// exports a UR controller, URDF or OpenCV read).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Stack {
    /// The arm's poses came over ROS 2.
    Ros2,
    /// A UR controller over RTDE, a simulated or recorded arm.
    Controller,
}

impl Stack {
    /// The stack of a cell whose arm is `robot`.
    pub(super) fn of(robot: &handeye_config::RobotConfig) -> Stack {
        match robot {
            handeye_config::RobotConfig::Ros2(_) => Stack::Ros2,
            _ => Stack::Controller,
        }
    }
}

/// `path` as one POSIX shell word (quoted by `shlex` where the shell would interpret it).
fn shell_word(path: &std::path::Path) -> String {
    let text = path.to_string_lossy();
    match shlex::try_quote(&text) {
        Ok(word) => word.into_owned(),
        // Only a NUL byte cannot be quoted, and a path holds none.
        Err(_) => text.into_owned(),
    }
}

/// Prints the run's progress: a bar with the per-pose lines above it on a terminal; one plain
/// line per pose on stdout when the output goes to a pipe or file (where indicatif hides the bar
/// and everything printed through it).
pub(super) struct Printer {
    bar: Option<ProgressBar>,
    stop: Arc<AtomicBool>,
    /// stdout or stderr is not a terminal: plain lines, no bar.
    plain: bool,
    /// Every pose the run may visit with its number in `handeye plan check`'s listing (the
    /// plan's poses; an adaptive plan's extra candidates too).
    listed: Vec<(Pose, usize)>,
    /// The session's poses (plan index) by their plan check number, as the arm moves to them.
    numbers: std::collections::HashMap<usize, usize>,
    /// A several-camera cell: the planner camera (a pose is done when its record is in).
    planner_camera: Option<String>,
}

impl Printer {
    /// A printer; from the session's start Ctrl-C, SIGTERM and SIGHUP set `stop`.
    pub(super) fn new(stop: Arc<AtomicBool>) -> Printer {
        Printer {
            bar: None,
            stop,
            plain: !(std::io::stdout().is_terminal() && std::io::stderr().is_terminal()),
            listed: Vec::new(),
            numbers: Default::default(),
            planner_camera: None,
        }
    }

    /// ` (plan check #N)` for a session pose that `handeye plan check` lists, else nothing: one
    /// numbering for a safety review, whatever order the session visits the poses in.
    fn listed_as(&self, plan_index: usize) -> String {
        self.numbers
            .get(&plan_index)
            .map(|n| format!(" (plan check #{n})"))
            .unwrap_or_default()
    }

    fn line(&self, line: String) {
        match &self.bar {
            Some(bar) => bar.println(line),
            None => outln!("{line}"),
        }
    }
}

impl RunObserver for Printer {
    fn plan_checked(&mut self, cell: &PreparedCell) {
        outln!("{}", cell.report);
        self.listed = cell
            .report
            .poses
            .iter()
            .chain(
                cell::run::extra_candidates(cell)
                    .iter()
                    .flat_map(|extra| &extra.poses),
            )
            .map(|p| (p.base_from_flange, p.index))
            .collect();
        self.planner_camera = cell
            .config
            .listed
            .then(|| cell.config.camera().name.clone());
    }

    fn cameras_planned(&mut self, views: &[cell::cameras::PlannedViews]) {
        outln!("{}", super::cameras::planned_views_line(views));
    }

    fn confirm_motion(
        &mut self,
        cell: &PreparedCell,
        poses: usize,
    ) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
        super::confirm_motion(cell, poses).map_err(Into::into)
    }

    fn note(&mut self, message: &str) {
        match &self.bar {
            Some(bar) => bar.println(format!("note: {message}")),
            None => eprintln!("note: {message}"),
        }
    }

    fn session_started(&mut self, poses: usize) {
        // From here on Ctrl-C, SIGTERM and SIGHUP stop the arm and keep the samples.
        super::stop_on_signals(self.stop.clone());
        if self.plain {
            outln!("session: up to {poses} poses");
        } else {
            self.bar = Some(progress_bar(poses as u64));
        }
    }

    fn event(&mut self, event: SessionEvent) {
        match event {
            SessionEvent::Moving { plan_index, target } => {
                // The same flange pose as listed (copied, or read back from the manifest).
                let listed = self.listed.iter().find(|(pose, _)| {
                    handeye_core::geometry::translation_distance(pose, &target) < 1e-9
                        && pose.rotation.angle_to(&target.rotation) < 1e-9
                });
                if let Some((_, number)) = listed {
                    self.numbers.insert(plan_index, *number);
                }
                if let Some(bar) = &self.bar {
                    bar.set_message(format!(
                        "moving to pose {plan_index}{}",
                        self.listed_as(plan_index)
                    ))
                }
            }
            SessionEvent::Recorded {
                plan_index,
                camera,
                reprojection_rms_px,
                tags,
                rejected,
                will_retry,
                ..
            } => {
                let mut pose = format!("pose {plan_index:>3}{}", self.listed_as(plan_index));
                if let Some(camera) = &camera {
                    pose.push_str(&format!(" {camera}"));
                }
                let line = match (&rejected, reprojection_rms_px) {
                    (None, Some(rms)) => {
                        format!("{pose}: ok, {tags} tags, board RMS {rms:.3} px")
                    }
                    (Some(why), _) if will_retry => format!("{pose}: {why}; will retry once"),
                    (Some(why), _) => format!("{pose}: skipped: {why}"),
                    (None, None) => format!("{pose}: ok"),
                };
                self.line(line);
                // Of several cameras, the planner camera's record counts the pose.
                let counts = camera.is_none() || camera == self.planner_camera;
                if let (Some(bar), false, true) = (&self.bar, will_retry, counts) {
                    bar.inc(1);
                }
            }
            SessionEvent::CameraLost(failure) => self.line(format!(
                "camera `{}` stopped delivering frames at plan pose {} ({}): its samples until then are kept and solved, the other cameras go on; `handeye run --resume` asks it again for the poses it missed",
                failure.camera, failure.plan_index, failure.error
            )),
        }
    }

    fn session_ended(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }
}

pub(super) fn default_session_dir() -> PathBuf {
    handeye_records::dated_session_path(
        std::path::Path::new("sessions"),
        "",
        std::time::SystemTime::now(),
    )
}

fn progress_bar(len: u64) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        // "of up to": an adaptive plan stops as soon as the answer is good enough.
        ProgressStyle::with_template("{bar:30} {pos} of up to {len} poses  {elapsed}  {msg}")
            .expect("valid template"),
    );
    bar
}
