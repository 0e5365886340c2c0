//! The `handeye` command line: parses arguments into library types, calls the library, and
//! chooses the exit code. One file per subcommand under `cli/`.

mod cli;

use std::io::Write;
use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // Under `ulimit -v`, before any thread allocates: one allocator arena (see the function).
    handeye_vision::detect::fit_allocator_to_limits();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("HANDEYE_LOG")
                // The DDS stack (ROS 2 backends) warns about every peer it cannot reach at once
                // while discovery settles, and about sockets as it shuts down; our backends report what
                // failed in their own errors.
                .unwrap_or_else(|_| {
                    tracing_subscriber::EnvFilter::new("warn,rustdds=off,ros2_client=error")
                }),
        )
        .with_writer(std::io::stderr)
        .init();
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            // Not eprintln!: with stderr closed too, the exit code is all that is left to say.
            // Each cause once: `{:#}` repeats a source its wrapper's message already quotes.
            let _ = writeln!(
                std::io::stderr(),
                "error: {}",
                handeye_core::error_text::error_chain(error.as_ref())
            );
            if error.downcast_ref::<cli::NothingFound>().is_some() {
                ExitCode::from(cli::NothingFound::EXIT_CODE)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}
