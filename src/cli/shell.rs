//! `handeye completions SHELL` and `handeye man`: written from the command-line definition
//! itself (clap_complete, clap_mangen), so they never fall behind it.

use std::path::PathBuf;

use clap::{Args, CommandFactory};

/// Print shell completions (bash, zsh, fish, elvish, powershell) to standard output.
#[derive(Debug, Args)]
pub(super) struct CompletionsArgs {
    /// The shell, e.g. `handeye completions bash > ~/.local/share/bash-completion/completions/handeye`.
    #[arg(value_enum)]
    shell: clap_complete::Shell,
}

/// Write the man pages: `handeye.1` and one per subcommand (`handeye-run.1`, ...).
#[derive(Debug, Args)]
pub(super) struct ManArgs {
    /// The folder to write them into (created if missing), e.g. `~/.local/share/man/man1`.
    #[arg(short = 'o', long = "output", default_value = ".")]
    output: PathBuf,
}

pub(super) fn completions(args: CompletionsArgs) -> anyhow::Result<()> {
    let mut command = super::Cli::command();
    clap_complete::generate(args.shell, &mut command, "handeye", &mut std::io::stdout());
    Ok(())
}

pub(super) fn man(args: ManArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.output)
        .map_err(|e| anyhow::anyhow!("{}: cannot create the folder: {e}", args.output.display()))?;
    let command = super::Cli::command();
    clap_mangen::generate_to(command, &args.output).map_err(|e| {
        anyhow::anyhow!("{}: cannot write the man pages: {e}", args.output.display())
    })?;
    outln!(
        "wrote the man pages into {} (`man -l {}`)",
        args.output.display(),
        args.output.join("handeye.1").display()
    );
    Ok(())
}
