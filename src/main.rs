//! `edmd`: see the library crate and README.md.

fn main() -> std::process::ExitCode {
    edmd::cli::main()
}
