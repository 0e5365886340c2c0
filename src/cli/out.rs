//! Standard output for every subcommand: [`outln!`] and [`out!`] write to the locked stdout and
//! never panic. When the reader has gone (`handeye run … | head -1`: the write fails with
//! `BrokenPipe`), the text is dropped, the fact is remembered (nothing more is written) and the command
//! carries on — a run still finishes, moves the arm home and writes its session files.
//! `println!` would panic instead ("failed printing to stdout", exit 101).
//!
//! Other write errors (a full disk behind a redirect) are treated the same way: printing is a
//! courtesy to the person watching; the files a command writes carry the results and report
//! their own errors. Progress bars and logs go to stderr and are not affected.
//! Depends on nothing of ours.

use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};

static CLOSED: AtomicBool = AtomicBool::new(false);

/// Writes formatted text to stdout; a failure marks stdout closed and is otherwise ignored.
/// Once stdout is known closed nothing more is attempted.
pub(crate) fn write(args: std::fmt::Arguments<'_>, newline: bool) {
    if CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let stdout = std::io::stdout();
    let mut lock = stdout.lock();
    let result = lock.write_fmt(args).and_then(|()| {
        if newline {
            lock.write_all(b"\n")
        } else {
            Ok(())
        }
    });
    if result.is_err() {
        CLOSED.store(true, Ordering::Relaxed);
    }
}

/// Flushes stdout (after a prompt without a newline); failures are handled as in [`write`].
pub(crate) fn flush() {
    if CLOSED.load(Ordering::Relaxed) {
        return;
    }
    if std::io::stdout().lock().flush().is_err() {
        CLOSED.store(true, Ordering::Relaxed);
    }
}

/// `println!` that survives a closed stdout (see the module docs).
macro_rules! outln {
    () => {
        $crate::cli::out::write(format_args!(""), true)
    };
    ($($arg:tt)*) => {
        $crate::cli::out::write(format_args!($($arg)*), true)
    };
}

/// `print!` that survives a closed stdout (see the module docs).
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::cli::out::write(format_args!($($arg)*), false)
    };
}
