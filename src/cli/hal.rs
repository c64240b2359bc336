//! The two HAL file commands around `loadusr -W edmd serve`, both reading edmd's record of
//! who holds the component ([`crate::hal::owner`]):
//!
//! - `edmd hal-reap`, the line before it: removes the component a killed edmd left in a HAL
//!   that kept running, so the name is free for the edmd loaded next. (`loadusr -W` would
//!   take the dead component, still marked ready, for the new one and return at once.)
//! - `edmd hal-wait`, the service file's last line, in place of `waitusr edmd`: `waitusr`
//!   waits for the component to leave HAL, which a killed edmd never does, so HAL would stay
//!   up, the drives' enables with it (unless a `watchdog` drops them), and systemd would see
//!   nothing wrong. This waits for edmd's process instead and, when edmd ended without a clean
//!   stop, removes the component it left and exits 1: `halcmd` stops the HAL file there,
//!   `halrun` unloads HAL and exits with the failure, and systemd restarts the service.

use std::process::ExitCode;
use std::time::Duration;

use clap::Args;

use super::{ConfigArgs, EXIT_RUNTIME, load_config};
use crate::hal::HalSettings;
use crate::hal::owner::{End, Owner, wait_for_end};

#[derive(Args, Debug)]
pub(super) struct HalWaitArgs {
    /// How long to wait for edmd's record when it is not there yet (seconds): edmd writes it
    /// before `loadusr -W` returns, so only a file run out of order needs this
    #[arg(long, value_name = "S", default_value_t = 5.0)]
    settle: f64,
    #[command(flatten)]
    config: ConfigArgs,
}

#[derive(Args, Debug)]
pub(super) struct HalReapArgs {
    #[command(flatten)]
    config: ConfigArgs,
}

pub(super) fn run_hal_reap(args: &HalReapArgs) -> ExitCode {
    let cfg = match load_config(&args.config) {
        Ok(c) => c,
        Err(code) => return code,
    };
    let settings = HalSettings::from_config(&cfg);
    let Some(owner) = Owner::read(&settings.owner_file) else {
        return ExitCode::SUCCESS;
    };
    if owner.component != settings.component || owner.alive() {
        // Another component's record, or a live edmd: nothing of a dead one to remove.
        return ExitCode::SUCCESS;
    }
    match crate::hal::remove_left_component(&settings, &owner) {
        Ok(true) => {
            eprintln!(
                "edmd hal-reap: component {} of edmd pid {}, which did not stop, removed from \
                 HAL (its pins unlinked: the file's nets link the next one's)",
                owner.component, owner.pid
            );
            ExitCode::SUCCESS
        }
        Ok(false) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!(
                "edmd hal-reap: component {} of edmd pid {} not removed: {e}",
                owner.component, owner.pid
            );
            ExitCode::from(EXIT_RUNTIME)
        }
    }
}

pub(super) fn run_hal_wait(args: &HalWaitArgs) -> ExitCode {
    let cfg = match load_config(&args.config) {
        Ok(c) => c,
        Err(code) => return code,
    };
    let settings = HalSettings::from_config(&cfg);
    let settle = Duration::from_secs_f64(args.settle.clamp(0.0, 3600.0));
    match wait_for_end(&settings.owner_file, settle) {
        End::Clean => {
            eprintln!(
                "edmd hal-wait: edmd stopped cleanly (component {})",
                settings.component
            );
            ExitCode::SUCCESS
        }
        End::Unclean(owner) => {
            let removed = crate::hal::remove_left_component(&settings, &owner);
            eprintln!(
                "edmd hal-wait: edmd (pid {}) ended without a clean stop; component {} {}",
                owner.pid,
                owner.component,
                match removed {
                    Ok(true) => "removed from HAL".to_string(),
                    Ok(false) => "already gone".to_string(),
                    Err(e) => format!("not removed: {e}"),
                }
            );
            ExitCode::from(EXIT_RUNTIME)
        }
    }
}
