//! The status as people read it: one line (the log's periodic status, systemd's
//! `STATUS=`, `edmd ctl monitor`) and the block `edmd ctl status` prints.

use super::*;

impl Status {
    /// One line: the log's periodic status, systemd's `STATUS=`, `edmd ctl monitor`.
    pub fn line(&self) -> String {
        match &self.job {
            None => {
                let check = self
                    .check
                    .as_ref()
                    .filter(|c| !c.decided())
                    .map(|c| format!("; {} {}", c.phase, c.program))
                    .unwrap_or_default();
                match &self.last_job {
                    Some(last) => format!(
                        "{}{check}; last job {}: {}",
                        self.state.name(),
                        last.program,
                        last.outcome.name()
                    ),
                    None => format!("{}{check}", self.state.name()),
                }
            }
            Some(j) => {
                let position = axis_list(&j.position_mm, &self.axes, |x| format!("{x:.4}"));
                let cutting = j.condition.map(|e| format!(" E{e}")).unwrap_or_default()
                    + &j.pass
                        .map(|p| format!(" pass {p}/{}", j.passes))
                        .unwrap_or_default();
                format!(
                    "{} {}:{} ({}){cutting}, {position} mm, {:.2} mm/min, {:.1} %{}, buffer {}/{}, \
                     {} shorts, {} starvations, {} overruns",
                    self.state.name(),
                    j.program,
                    j.line,
                    j.servo.name(),
                    j.feed_mm_per_min,
                    j.progress * 100.0,
                    j.eta_s
                        .map(|s| format!(" ETA {}", duration_text(s)))
                        .unwrap_or_default(),
                    j.buffer_unprocessed,
                    j.buffer_capacity,
                    j.servo_counters.shorts,
                    j.servo_counters.starvations,
                    j.overruns
                )
            }
        }
    }

    /// The human-readable form `edmd ctl` prints.
    pub fn text(&self) -> String {
        use std::fmt::Write;
        let mut t = String::new();
        let _ = writeln!(t, "state:        {}", self.state.name());
        if let Some(c) = self.check.as_ref().filter(|c| !c.decided()) {
            let _ = writeln!(
                t,
                "check:        {} {}: {} of {} bytes",
                c.phase, c.program, c.bytes_done, c.bytes_total
            );
        }
        if let Some(j) = &self.job {
            self.job_text(&mut t, j);
        }
        self.machine_text(&mut t);
        if self.single_block {
            let _ = writeln!(t, "single block: on");
        }
        let o = self.overrides;
        if o != OverrideStatus::default() {
            let _ = writeln!(
                t,
                "overrides:    feed {} %, rapid {} %",
                o.feed_pct, o.rapid_pct
            );
        }
        if let Some(last) = &self.last_job {
            let _ = writeln!(
                t,
                "last job:     {}: {}{}",
                last.program,
                last.outcome.name(),
                last.error
                    .as_ref()
                    .map(|e| format!(" ({e})"))
                    .unwrap_or_default()
            );
        }
        // While a job runs the checkpoint is its own: nothing to resume.
        if let Some(c) = self.checkpoint.as_ref().filter(|c| c.resumable) {
            let _ = writeln!(
                t,
                "checkpoint:   {} line {} ({}{}); {}",
                c.program,
                c.line,
                c.reason,
                if c.still {
                    ""
                } else {
                    ", written while cutting"
                },
                if c.still {
                    "`edmd ctl resume` continues it"
                } else {
                    "the electrode may be past it: check the position, then \
                     `edmd ctl resume --force` continues it"
                }
            );
        }
        if let Some(k) = &self.kept_checkpoint {
            let _ = writeln!(
                t,
                "kept aside:   {} line {} ({}); the checkpoint again once no other is \
                 (`edmd ctl discard --yes` the current one, or let its job end)",
                k.program, k.line, k.reason
            );
        }
        let h = &self.hours;
        if h.jobs > 0 || h.machine_s > 0.0 {
            let _ = writeln!(
                t,
                "hours:        machine {:.2} h, sparking {:.2} h, {} jobs (over the machine's life)",
                h.machine_s / 3600.0,
                h.spark_s / 3600.0,
                h.jobs
            );
        }
        if let Some(m) = &self.mqtt {
            let _ = writeln!(
                t,
                "mqtt:         {} as {} on {}: {} births, {} messages, {} dropped",
                if m.connected {
                    "connected"
                } else {
                    "not connected"
                },
                m.node,
                m.broker,
                m.births,
                m.published,
                m.dropped
            );
        }
        if let Some(e) = &self.history_write_error {
            let _ = writeln!(t, "warning:      the job history was not written: {e}");
        }
        for r in &self.rt_refused {
            let _ = writeln!(t, "warning:      {r}");
        }
        t
    }

    /// The machine's lines of [`Status::text`]: a DRO in machine and work coordinates, the
    /// unhomed axes marked `?`.
    fn machine_text(&self, t: &mut String) {
        use std::fmt::Write;
        let m = &self.machine;
        let dro = |v: &[f64]| {
            v.iter()
                .zip(&self.axes)
                .enumerate()
                .map(|(i, (x, a))| {
                    let mark = if m.homed.get(i).copied().unwrap_or(false) {
                        ""
                    } else {
                        "?"
                    };
                    format!("{a}{mark} {x:.4}")
                })
                .collect::<Vec<_>>()
                .join("  ")
        };
        let _ = writeln!(t, "machine:      {} mm", dro(&m.position_machine_mm));
        let _ = writeln!(
            t,
            "work {:<6}   {} mm",
            m.work_system,
            dro(&m.position_work_mm)
        );
        if m.homed.iter().any(|h| !h) {
            let _ = writeln!(
                t,
                "homed:        not all axes (marked ?): positions are only believed"
            );
        }
        if let Some(f) = &m.find {
            let label = format!("find {}:", f.id);
            let _ = writeln!(t, "{label:<14}{}: {}", f.state, f.message);
        }
        if let Some(e) = &m.state_write_error {
            let _ = writeln!(t, "warning:      {e}");
        }
    }

    /// The job in hand's lines of [`Status::text`].
    fn job_text(&self, t: &mut String, j: &JobStatus) {
        use std::fmt::Write;
        let list = |v: &[f64]| axis_list(v, &self.axes, |x| format!("{x:.4}"));
        let _ = writeln!(
            t,
            "job:          {} line {} (segment {}, step {}){}{}",
            j.program,
            j.line,
            j.segment,
            j.step,
            if j.resumed { ", resumed" } else { "" },
            if j.dry_run {
                "; DRY RUN: spark off, nothing is cut"
            } else {
                ""
            }
        );
        let mut cutting = Vec::new();
        if let Some(e) = j.condition {
            cutting.push(format!("E{e}"));
        }
        if let Some(p) = j.pass {
            cutting.push(format!("pass {p} of {}", j.passes));
        }
        if let Some(w) = &j.wire_offset {
            cutting.push(format!("offset {} {:.4} mm", w.side, w.mm));
        }
        if !cutting.is_empty() {
            let _ = writeln!(t, "cutting:      {}", cutting.join(", "));
        }
        if let Some(g) = &j.generator {
            let _ = writeln!(t, "generator:    {}", g.describe());
        }
        if let Some(tech) = &j.technology {
            let _ = writeln!(t, "technology:   {tech}");
        }
        if let Some(line) = j.paused_before_line {
            let why = j.pause.as_deref().unwrap_or("program stop (M0/M1)");
            let _ = writeln!(
                t,
                "paused:       {why} before line {line}; `edmd ctl resume` continues"
            );
            if let Some(message) = &j.pause_message {
                let _ = writeln!(t, "message:      {message}");
            }
        }
        match self.state {
            DaemonState::WireBreak => {
                let _ = writeln!(
                    t,
                    "wire:         broken; `edmd ctl rethread` goes back to the start hole \
                     (`--here`: thread here), then `edmd ctl resume`"
                );
            }
            DaemonState::Threading => {
                let _ = writeln!(
                    t,
                    "wire:         parked for threading; `edmd ctl resume` returns to the \
                     break point and cuts on"
                );
            }
            _ => {}
        }
        let c = &j.servo_counters;
        if c.jumps + c.wire_breaks + c.probes > 0 {
            let _ = writeln!(
                t,
                "excursions:   {} jumps, {} wire breaks, {} probes{}",
                c.jumps,
                c.wire_breaks,
                c.probes,
                j.last_probe
                    .probe_mm
                    .as_ref()
                    .map(|mm| format!("; last probe {} mm", list(mm)))
                    .unwrap_or_default()
            );
        }
        let _ = writeln!(
            t,
            "position:     {} mm; servo {}, feed {:.2} mm/min",
            list(&j.position_mm),
            j.servo.name(),
            j.feed_mm_per_min
        );
        let eta = match j.eta_s {
            Some(s) => format!("ETA {}", duration_text(s)),
            None => "ETA unknown".to_string(),
        };
        let _ = writeln!(
            t,
            "progress:     {:.1} % of {:.3} mm, {eta}{}",
            j.progress * 100.0,
            j.path_total_mm,
            j.recent_feed_mm_per_min
                .map(|f| format!(" (recent feed {f:.2} mm/min)"))
                .unwrap_or_default()
        );
        let _ = writeln!(
            t,
            "buffer:       {} ahead, {} reserved, of {}",
            j.buffer_unprocessed, j.buffer_reserved, j.buffer_capacity
        );
        let _ = writeln!(
            t,
            "servo:        {} shorts, {} turn-backs (deepest {} blocks), {} alarms, {} starvations",
            c.shorts, c.turn_backs, c.deepest_turn_back_blocks, c.alarms, c.starvations
        );
        let latency = match (j.latency_mean_us, j.latency_max_us) {
            (Some(mean), Some(max)) => {
                format!("latency mean {mean:.1} µs, max {max:.1} µs")
            }
            _ => "virtual time".to_string(),
        };
        let _ = writeln!(
            t,
            "time:         {:.3} s machine, {:.1} s elapsed; {}; {} overruns",
            j.machine_time_s, j.elapsed_s, latency, j.overruns
        );
    }
}

/// `3 h 02 min`, `4 min 10 s`, `12 s`: a duration as an operator reads it.
pub fn duration_text(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    match (s / 3600, s / 60 % 60, s % 60) {
        (0, 0, s) => format!("{s} s"),
        (0, m, s) => format!("{m} min {s:02} s"),
        (h, m, _) => format!("{h} h {m:02} min"),
    }
}
