//! What the command line says about itself, generated from its own definition so it can not
//! drift from it: shell completions (`edmd completions SHELL`) and man pages (`edmd man --out
//! DIR`: `edmd(1)` and one page per subcommand, `edmd-run(1)`, `edmd-ctl-hold(1)`, …, with
//! FILES and EXAMPLES on the pages that have them, and `edmd.toml(5)` from the shipped
//! configuration, every key with its default and its comment), which the Debian package
//! ships (`scripts/deb.sh`).

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
    let written = write_page(dir, &cli, "edmd")?;
    std::fs::write(
        dir.join("edmd.toml.5"),
        config_page(crate::config::DEFAULT_CONFIG_TOML),
    )?;
    Ok(written + 1)
}

/// The files the daemon and the commands read and keep (the man pages' FILES).
const FILES: &str = r#".SH FILES
.TP
\fI/etc/edmd/edmd.toml\fR
The configuration (\fBedmd.toml\fR(5)); \fB\-\-config\fR or \fB$EDMD_CONFIG\fR name another.
.TP
\fI/var/lib/edmd\fR
\fBdaemon.state_dir\fR: every file the daemon keeps, unless the configuration gives one its own
path: \fIcheckpoint.json\fR, \fImachine\-state.json\fR (position, homed axes, work offsets),
\fIjobs.jsonl\fR (the job history, \fBedmd ctl jobs\fR), \fIcounters.json\fR (machine and
spark hours), \fIreports/\fR (one folder per program job), \fIjob\-programs/\fR (the checked
copies jobs run), \fIhttp\-token\fR, \fIopcua\-users\fR and \fIopcua\-pki/\fR.
.TP
\fI/var/lib/edmd/programs\fR
\fBdaemon.program_dir\fR: the programs \fBedmd ctl run\fR and the page may run.
.TP
\fI/run/edmd/edmd.sock\fR
\fBdaemon.socket\fR: the control socket of \fBedmd serve\fR (JSON lines).
"#;

/// What the main pages show being done (their EXAMPLES).
const EXAMPLES: &str = r#".SH EXAMPLES
.nf
edmd check part.nc                        # every line read, nothing moves
edmd plan part.nc \-\-passes 3 \-\-out plan/   # the job in the table's three passes, timed
edmd run part.nc                          # one job on the simulated gap
edmd serve                                # the daemon (systemctl start edmd)
edmd ctl home                             # home the axes by their switches
edmd ctl home \-\-here Z                    # Z has no switch: it is home where it stands
edmd ctl touch\-off X 0 \-\-system G55
edmd ctl run die.nc \-\-passes 3            # rough, skim, finish
edmd ctl run die.nc \-\-from\-line 120
edmd ctl status                           # condition, pass n of N, offset, ETA
edmd ctl jobs                             # the job history
edmd ctl hold; edmd ctl resume
.fi
"#;

/// Pages that get FILES and EXAMPLES after clap's sections.
const WITH_SECTIONS: [&str; 3] = ["edmd", "edmd-serve", "edmd-ctl"];

/// `edmd.toml(5)` from the shipped configuration `toml`: each section, each key with its
/// default value and the comment above it, as the file itself says them.
pub(crate) fn config_page(toml: &str) -> String {
    let esc = |s: &str| {
        let s = s.replace('\\', "\\e").replace('-', "\\-");
        match s.chars().next() {
            Some('.') | Some('\'') => format!("\\&{s}"),
            _ => s,
        }
    };
    let mut page = String::from(
        ".TH edmd.toml 5 \"\" \"edmd\" \"File Formats\"\n.SH NAME\nedmd.toml \\- the configuration \
         of edmd\n.SH DESCRIPTION\nTOML, read by every edmd command (\\fB\\-\\-config FILE\\fR, \
         \\fB$EDMD_CONFIG\\fR, or \\fI/etc/edmd/edmd.toml\\fR); a key left out keeps the default \
         shown here, an unknown key is an error with its file:line:col, and \
         \\fB\\-\\-set section.key=value\\fR overrides one for a command. Generated from the \
         shipped configuration, so its defaults and comments are the program's.\n",
    );
    let mut comment: Vec<&str> = Vec::new();
    let mut depth = 0i32;
    for line in toml.lines() {
        let t = line.trim();
        if depth > 0 {
            depth += t.matches('[').count() as i32 - t.matches(']').count() as i32;
            continue;
        }
        if let Some(c) = t.strip_prefix('#') {
            comment.push(c.strip_prefix(' ').unwrap_or(c));
            continue;
        }
        if t.is_empty() {
            comment.clear();
            continue;
        }
        if t.starts_with('[') {
            page.push_str(&format!(".SH {}\n", esc(&t.to_uppercase())));
            for c in comment.drain(..) {
                page.push_str(&format!("{}\n", esc(c)));
            }
            continue;
        }
        let Some((key, value)) = t.split_once('=') else {
            continue;
        };
        let value = value.trim();
        depth = value.matches('[').count() as i32 - value.matches(']').count() as i32;
        let shown = if depth > 0 { "[ … ]" } else { value };
        page.push_str(&format!(
            ".TP\n\\fB{}\\fR = {}\n",
            esc(key.trim()),
            esc(shown)
        ));
        // Prose flows; an indented line (a table of the comment's) starts a line of its own.
        for c in comment.drain(..) {
            if c.starts_with(' ') {
                page.push_str(".br\n");
            }
            page.push_str(&format!("{}\n", esc(c.trim_start())));
        }
    }
    page.push_str(".SH SEE ALSO\n\\fBedmd\\fR(1), \\fBedmd\\-serve\\fR(1)\n");
    page
}

fn write_page(dir: &Path, cmd: &clap::Command, name: &str) -> std::io::Result<usize> {
    let page = cmd.clone().name(name.to_string());
    let mut text = Vec::new();
    clap_mangen::Man::new(page).render(&mut text)?;
    if WITH_SECTIONS.contains(&name) {
        text.extend_from_slice(FILES.as_bytes());
        text.extend_from_slice(EXAMPLES.as_bytes());
    }
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
