//! What the command line says about itself, generated from its own definition so it can not
//! drift from it: shell completions (`edmd completions SHELL`) and man pages (`edmd man --out
//! DIR`: `edmd(1)` and one page per subcommand, `edmd-run(1)`, `edmd-ctl-hold(1)`, …), which
//! the Debian package ships (`scripts/deb.sh`).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args, ValueEnum};
use clap_complete::Shell;

use super::{EXIT_RUNTIME, write_stdout};

/// The shells completions are made for.
#[derive(ValueEnum, Debug, Clone, Copy)]
pub(super) enum CompletionShell {
    Bash,
    Zsh,
    Fish,
}

#[derive(Args, Debug)]
pub(super) struct CompletionsArgs {
    /// The shell: bash (into /usr/share/bash-completion/completions/edmd), zsh (a `_edmd` in
    /// $fpath) or fish (~/.config/fish/completions/edmd.fish)
    shell: CompletionShell,
}

#[derive(Args, Debug)]
pub(super) struct ManArgs {
    /// Directory the pages are written into (created if needed)
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
}

/// Prints the completion script for `args.shell` on standard output.
pub(super) fn completions(args: &CompletionsArgs, mut cli: clap::Command) -> ExitCode {
    let shell = match args.shell {
        CompletionShell::Bash => Shell::Bash,
        CompletionShell::Zsh => Shell::Zsh,
        CompletionShell::Fish => Shell::Fish,
    };
    let mut out = Vec::new();
    clap_complete::generate(shell, &mut cli, "edmd", &mut out);
    out!("{}", String::from_utf8_lossy(&out));
    ExitCode::SUCCESS
}

/// Writes `edmd.1` and a page per subcommand (nested ones too) into `args.out`.
pub(super) fn man(args: &ManArgs, cli: clap::Command) -> ExitCode {
    match write_pages(&args.out, cli) {
        Ok(n) => {
            eprintln!("edmd: {n} man pages written to {}", args.out.display());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("edmd: error: {}: {e}", args.out.display());
            ExitCode::from(EXIT_RUNTIME)
        }
    }
}

fn write_pages(dir: &Path, cli: clap::Command) -> std::io::Result<usize> {
    std::fs::create_dir_all(dir)?;
    let mut cli = cli;
    // Subcommands named as their page is (`edmd-ctl-hold`), so the SEE ALSO lines and the
    // synopses read as commands.
    cli.build();
    write_page(dir, &cli, "edmd")
}

fn write_page(dir: &Path, cmd: &clap::Command, name: &str) -> std::io::Result<usize> {
    let page = cmd.clone().name(name.to_string());
    let mut text = Vec::new();
    clap_mangen::Man::new(page).render(&mut text)?;
    std::fs::write(dir.join(format!("{name}.1")), text)?;
    let mut written = 1;
    for sub in cmd.get_subcommands().filter(|s| !s.is_hide_set()) {
        if sub.get_name() == "help" {
            continue;
        }
        written += write_page(dir, sub, &format!("{name}-{}", sub.get_name()))?;
    }
    Ok(written)
}
