//! `handeye console`: a hand-guided session of a cell on the live console (capture where the arm
//! stands, freedrive, go to the suggested view, finish and solve); also the console start-up and
//! ending that `handeye run --console` shares.

use std::io::{BufRead, IsTerminal};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use clap::Args;

use handeye_console::manual::run_manual;
use handeye_console::{Command, Console, ConsoleEvent, ConsoleOptions};
use handeye_session::cell::run::{open_run, OpenedRun, RunRequest, SessionTarget};

/// Capture by hand: jog or hand-guide the arm, capture on the console page (or Enter here).
#[derive(Debug, Args)]
pub(super) struct ConsoleArgs {
    /// The cell config; its plan's poses (if any) are only suggested, never driven.
    #[arg(long, required_unless_present = "resume")]
    pub(super) config: Option<PathBuf>,
    /// Where to write the session folder (default: sessions/YYYY-MM-DD_HH-MM-SS).
    #[arg(
        short = 'o',
        long = "output",
        alias = "out",
        value_name = "DIR",
        conflicts_with = "resume"
    )]
    pub(super) out: Option<PathBuf>,
    /// Continue a hand-guided session in this folder.
    #[arg(long)]
    pub(super) resume: Option<PathBuf>,
    /// Resume even though the config, board or intrinsics changed since the session was
    /// recorded (each change is listed).
    #[arg(long, requires = "resume")]
    pub(super) accept_changed: bool,
    /// The console's address (port 0 picks a free one); the URL is printed.
    #[arg(long, value_name = "ADDR", default_value = handeye_console::DEFAULT_ADDR)]
    pub(super) addr: SocketAddr,
    /// Allow an address beyond this machine (anyone who reaches it with the printed URL, whose
    /// secret it checks, can move the arm).
    #[arg(long)]
    pub(super) public: bool,
    /// Do not ask before the first move of a real arm to a suggested view.
    #[arg(long)]
    pub(super) yes: bool,
    /// After the session, keep serving the page until Enter (or Ctrl-C).
    #[arg(long)]
    pub(super) wait: bool,
}

/// Runs `handeye console`.
pub(super) fn run(args: ConsoleArgs) -> anyhow::Result<()> {
    let target = match &args.resume {
        Some(dir) => SessionTarget::Resume(dir.clone()),
        None => SessionTarget::New(
            args.out
                .clone()
                .unwrap_or_else(super::run::default_session_dir),
        ),
    };
    let stop = Arc::new(AtomicBool::new(false));
    super::stop_on_signals(stop.clone());
    let console = start(args.addr, args.public, stop.clone())?;
    let request = RunRequest {
        config: args.config.clone(),
        target,
        motion_confirmed: args.yes,
        accept_changed: args.accept_changed,
        stop,
        jobs: None,
    };
    let mut printer = super::run::Printer::new(request.stop.clone());
    let opened = match open_run(&request, &mut printer) {
        Ok(opened) => opened,
        Err(e) => {
            let e = anyhow::Error::from(e);
            failed(&console, &e, args.wait);
            return Err(e);
        }
    };
    hand_guided(&console, &request, opened, printer, args.wait)
}

/// A hand-guided session of a run opened already (by `handeye console`, or by `handeye run` of a
/// hand-guided config or session) on `console`, to its end: the verdict, the report.
pub(super) fn hand_guided(
    console: &Console,
    request: &RunRequest,
    opened: OpenedRun,
    mut printer: super::run::Printer,
    wait: bool,
) -> anyhow::Result<()> {
    terminal_commands(console);
    let done = match run_manual(opened, request, console, &mut printer) {
        Ok(done) => done,
        Err(e) => {
            let e = anyhow::Error::from(e);
            failed(console, &e, wait);
            return Err(e);
        }
    };
    let (report, next) = super::run::finish_run(&done)?;
    finished(console, &done, report, next, wait);
    Ok(())
}

/// The terminal's keys for a manual session: Enter captures, `f`/`F` switch freedrive on/off,
/// `g` goes to the suggestion, `q` finishes.
fn terminal_commands(console: &Console) {
    if !std::io::stdin().is_terminal() {
        return;
    }
    outln!("keys: Enter = capture, f = freedrive on, F = freedrive off, g = go to the suggested view, q = finish and solve");
    let sender = console.command_sender();
    // Reading stdin blocks: a thread of its own, left to end with the process.
    let _ = std::thread::Builder::new()
        .name("terminal".into())
        .spawn(move || {
            for line in std::io::stdin().lock().lines() {
                let Ok(line) = line else { break };
                let command = match line.trim() {
                    "" => Command::Capture,
                    "f" => Command::Freedrive { on: true },
                    "F" => Command::Freedrive { on: false },
                    "g" => Command::GoToSuggestion,
                    "q" => Command::Finish,
                    "yes" => Command::Confirm,
                    other => {
                        eprintln!("unknown key {other:?}: Enter, f, F, g or q");
                        continue;
                    }
                };
                sender.send(command);
            }
        });
}

/// Starts the console and prints its URL (loudly, when it serves beyond this machine).
pub(super) fn start(
    addr: SocketAddr,
    public: bool,
    stop: Arc<AtomicBool>,
) -> anyhow::Result<Console> {
    let console = Console::start(
        &ConsoleOptions {
            addr,
            allow_remote: public,
        },
        stop,
    )?;
    if console.is_remote() {
        eprintln!(
            "WARNING: the console serves on {} — beyond this machine. It asks every request for the secret in the URL below: anyone who has that URL can STOP the run and, in a manual session, move the arm. Share it only with the people at the cell.",
            console.addr()
        );
    }
    // The URL carries the secret the page needs (a new one at every start).
    outln!("console: {}", console.url());
    Ok(console)
}

/// Tells the page the run failed (with its causes), then ends as [`linger`] says.
pub(super) fn failed(console: &Console, error: &anyhow::Error, wait: bool) {
    console.publish(&ConsoleEvent::Failed {
        message: format!("{error:#}"),
    });
    linger(console, wait);
}

/// The end of a run on the console (one camera or several): its verdict and summary
/// (`CellRun::verdict_and_summary`), the report, the next step.
pub(super) fn finished(
    console: &Console,
    done: &handeye_session::cell::run::CellRun,
    report: Option<PathBuf>,
    next: String,
    wait: bool,
) {
    let (verdict, summary) = done.verdict_and_summary();
    publish_finished(
        console,
        (verdict.map(|v| v.level.word().to_string()), summary),
        report,
        next,
        wait,
    );
}

/// Publishes the end of a run (its verdict and summary, where the report is, the next step),
/// then ends as [`linger`] says.
fn publish_finished(
    console: &Console,
    (verdict, summary): (Option<String>, String),
    report: Option<PathBuf>,
    next: String,
    wait: bool,
) {
    let has_report = report.is_some();
    if let Some(path) = report {
        console.set_report(path);
    }
    console.publish(&ConsoleEvent::Finished {
        verdict,
        summary,
        next,
        report: has_report,
    });
    linger(console, wait);
}

/// With `wait`, serves the page until Enter (or Ctrl-C); otherwise lets connected pages receive
/// the last events first.
fn linger(console: &Console, wait: bool) {
    if wait {
        outln!(
            "console: still serving {} — press Enter to quit",
            console.url()
        );
        let (tx, rx) = std::sync::mpsc::channel();
        let _ = std::thread::Builder::new().spawn(move || {
            let mut line = String::new();
            let _ = std::io::stdin().lock().read_line(&mut line);
            let _ = tx.send(());
        });
        let _ = rx.recv();
    } else {
        // The pages get the last events, then the connections close (at once with no page).
        console.close(Duration::from_secs(1));
    }
}
