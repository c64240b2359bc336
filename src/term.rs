//! The terminal: one progress bar at the bottom and the log lines printed above it.
//!
//! A bar redrawn with `\r` shares its line with whatever else writes to standard error, so a
//! log line printed during a job used to land on the end of the bar, and the scrollback
//! filled with bar fragments. Here the bar is `indicatif`'s, drawn on standard error (hidden
//! when that is not a terminal), and the log writes through [`LogWriter`]: each line is
//! printed with the bar lifted out of the way and redrawn under it, so a line is always whole
//! and on its own, and one bar remains. [`local_time`] stamps terminal log lines in the shop's
//! own hours.

use std::io::Write;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// The bar on standard error, while one is up: log lines lift it to print.
static BAR: parking_lot::Mutex<Option<ProgressBar>> = parking_lot::Mutex::new(None);

/// A progress bar of `len` steps on standard error, `{msg}` after the bar: hidden when
/// standard error is not a terminal or `shown` is false (`--quiet`).
pub fn bar(len: u64, shown: bool) -> ProgressBar {
    if !shown {
        return ProgressBar::hidden();
    }
    let style = ProgressStyle::with_template("[{bar:30}] {percent:>3} %  {msg}")
        .expect("a valid template")
        .progress_chars("#>-");
    let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr_with_hz(5))
        .with_style(style);
    *BAR.lock() = Some(bar.clone());
    bar
}

/// The job is over: its bar stays as it last stood, on a line of its own, and what is
/// printed next goes below it.
pub fn finish() {
    if let Some(bar) = BAR.lock().take() {
        bar.abandon();
        // Whoever still holds the bar (the job's progress callback, until it is dropped)
        // draws nowhere now: a redraw would climb onto the lines printed after it.
        bar.set_draw_target(ProgressDrawTarget::hidden());
        // The bar's line ends here: the cursor stood at its end.
        let _ = writeln!(std::io::stderr());
    }
}

/// Takes the bar down altogether (a plan's, which its summary replaces).
pub fn clear() {
    if let Some(bar) = BAR.lock().take() {
        bar.finish_and_clear();
    }
}

/// Standard error for the log: what one event writes is printed whole, with the bar lifted.
#[derive(Debug, Clone, Copy, Default)]
pub struct LogWriter;

/// One log event's text, printed when the logger lets go of it.
#[derive(Debug, Default)]
pub struct LogLine(Vec<u8>);

impl Write for LogLine {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Drop for LogLine {
    fn drop(&mut self) {
        if self.0.is_empty() {
            return;
        }
        let text = std::mem::take(&mut self.0);
        let write = || {
            let _ = std::io::stderr().lock().write_all(&text);
        };
        let bar = BAR.lock().clone();
        match bar {
            Some(bar) => bar.suspend(write),
            None => write(),
        }
    }
}

impl<'a> tracing_subscriber::fmt::MakeWriter<'a> for LogWriter {
    type Writer = LogLine;

    fn make_writer(&'a self) -> LogLine {
        LogLine::default()
    }
}

/// A timer for terminal log lines: the local date and time to the millisecond
/// (`2026-11-23 20:10:03.512`), where the journal keeps its own UTC stamps.
#[derive(Debug, Clone, Copy, Default)]
pub struct LocalTime;

impl tracing_subscriber::fmt::time::FormatTime for LocalTime {
    fn format_time(&self, w: &mut tracing_subscriber::fmt::format::Writer<'_>) -> std::fmt::Result {
        write!(w, "{}", local_time())
    }
}

/// The wall clock in the local time zone as `2026-11-23 20:10:03.512`.
pub fn local_time() -> String {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    let stamp = crate::sys::local_stamp_of(now.as_secs() as i64);
    // `2026-11-23T20-10-03` → `2026-11-23 20:10:03`
    let (date, time) = stamp.split_once('T').unwrap_or((&stamp, ""));
    format!(
        "{date} {}.{:03}",
        time.replace('-', ":"),
        now.subsec_millis()
    )
}
