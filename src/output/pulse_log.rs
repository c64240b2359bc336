//! The pulse log (`output.kind = "file"`): every step the consumer emitted, replayable.
//!
//! ```text
//! # edmd pulse log; axes=X,Y; step_mm=0.001,0.001; tick_us=50; start=0,0
//! tick,x,y,gap,spark,condition
//! 0,0,0,normal,1,0
//! 17,1,0,normal,1,2
//! 3012,-1,-1,short,1,2
//! ```
//!
//! One row per tick that stepped on some axis or whose gap state, spark or machining condition
//! differs from the previous row's (before the first row: `normal`, spark off, condition 0);
//! each axis column holds that tick's signed step (-1, 0 or 1). The sum of a column plus the
//! start is the axis' final position: the log is the pulse ledger, written down. `spark` is 1
//! while the generator sparks (off on rapids, holds and after the end) and `condition` the
//! `E<number>` in force (0: none). A log of the older format (no `spark,condition`) reads too.

use std::fs::File;
use std::io::{BufRead, BufWriter, Write};
use std::path::Path;

use super::{OutputError, PulseOutput};
use crate::decimal::push_u64;
use crate::gap::GapState;
use crate::vocab::Axis;
use crate::vocab::MAX_AXES;

/// What the `#` line says.
#[derive(Debug, Clone, PartialEq)]
pub struct PulseLogHeader {
    pub axes: Vec<Axis>,
    pub step_mm: Vec<f64>,
    pub tick_us: u32,
    pub start: Vec<i64>,
}

/// Writes the pulse log.
#[derive(Debug)]
pub struct PulseLog {
    out: BufWriter<File>,
    path: String,
    axes: usize,
    last_gap: GapState,
    /// What the rows say now, and what the last row said.
    now: super::Activity,
    last: (bool, u16),
    line: Vec<u8>,
}

impl PulseLog {
    pub fn create(path: &Path, header: &PulseLogHeader) -> Result<PulseLog, OutputError> {
        let name = path.display().to_string();
        let io = |source| OutputError::Io {
            path: name.clone(),
            source,
        };
        let file = File::create(path).map_err(io)?;
        let mut log = PulseLog {
            out: BufWriter::with_capacity(1 << 16, file),
            path: name.clone(),
            axes: header.axes.len(),
            last_gap: GapState::Normal,
            now: super::Activity::default(),
            last: (false, 0),
            line: Vec::with_capacity(64),
        };
        let join = |v: Vec<String>| v.join(",");
        let text = format!(
            "# edmd pulse log; axes={}; step_mm={}; tick_us={}; start={}\ntick,{},gap,spark,condition\n",
            join(header.axes.iter().map(|a| a.to_string()).collect()),
            join(header.step_mm.iter().map(|s| s.to_string()).collect()),
            header.tick_us,
            join(header.start.iter().map(|s| s.to_string()).collect()),
            join(
                header
                    .axes
                    .iter()
                    .map(|a| a.letter().to_ascii_lowercase().to_string())
                    .collect()
            ),
        );
        log.out.write_all(text.as_bytes()).map_err(io)?;
        Ok(log)
    }

    fn io(&self, source: std::io::Error) -> OutputError {
        OutputError::Io {
            path: self.path.clone(),
            source,
        }
    }
}

impl PulseOutput for PulseLog {
    fn write(
        &mut self,
        tick: u64,
        steps: &[i8; MAX_AXES],
        gap: GapState,
    ) -> Result<(), OutputError> {
        let moved = steps[..self.axes].iter().any(|&s| s != 0);
        let state = (self.now.spark, self.now.condition);
        if !moved && gap == self.last_gap && state == self.last {
            return Ok(());
        }
        self.last_gap = gap;
        self.last = state;
        self.line.clear();
        push_u64(&mut self.line, tick);
        for &s in &steps[..self.axes] {
            self.line.extend_from_slice(match s {
                -1 => b",-1",
                1 => b",1",
                _ => b",0",
            });
        }
        self.line.push(b',');
        self.line.extend_from_slice(gap.name().as_bytes());
        self.line
            .extend_from_slice(if state.0 { b",1," } else { b",0," });
        push_u64(&mut self.line, state.1 as u64);
        self.line.push(b'\n');
        let result = self.out.write_all(&self.line);
        result.map_err(|e| self.io(e))
    }

    fn finish(&mut self, _why: super::StopReason) -> Result<(), OutputError> {
        self.sync()
    }

    fn moving_in(&mut self, now: super::Activity) {
        self.now = now;
    }

    fn sync(&mut self) -> Result<(), OutputError> {
        let result = self.out.flush().and_then(|()| {
            match self.out.get_ref().sync_data() {
                // A pipe or a terminal (`/dev/stdout`) has no disk to reach: flushed is all.
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::InvalidInput | std::io::ErrorKind::Unsupported
                    ) =>
                {
                    Ok(())
                }
                other => other,
            }
        });
        result.map_err(|e| self.io(e))
    }
}

/// One row of a pulse log.
#[derive(Debug, Clone, PartialEq)]
pub struct PulseLogRow {
    pub tick: u64,
    pub steps: Vec<i8>,
    pub gap: GapState,
    /// The generator sparks (`false` in logs of the older format).
    pub spark: bool,
    /// The machining condition (`E<number>`; 0 none).
    pub condition: u16,
}

/// Reads a pulse log back (for replay in tests and tools). Errors are `line: message`.
pub fn read_pulse_log(path: &Path) -> Result<(PulseLogHeader, Vec<PulseLogRow>), String> {
    let file = File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut lines = std::io::BufReader::new(file).lines();
    let mut next = |what: &str| -> Result<String, String> {
        lines
            .next()
            .ok_or_else(|| format!("missing {what}"))?
            .map_err(|e| e.to_string())
    };
    let comment = next("the # header line")?;
    let fields: std::collections::HashMap<&str, &str> = comment
        .trim_start_matches('#')
        .split(';')
        .filter_map(|f| f.trim().split_once('='))
        .collect();
    let get = |key: &str| {
        fields
            .get(key)
            .copied()
            .ok_or_else(|| format!("line 1: no {key}="))
    };
    let axes = get("axes")?
        .split(',')
        .map(|a| {
            a.chars()
                .next()
                .and_then(Axis::from_letter)
                .ok_or_else(|| format!("line 1: bad axis {a}"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let numbers = |key: &str| -> Result<Vec<f64>, String> {
        get(key)?
            .split(',')
            .map(|v| {
                v.parse()
                    .map_err(|_| format!("line 1: bad {key} value {v}"))
            })
            .collect()
    };
    let header = PulseLogHeader {
        step_mm: numbers("step_mm")?,
        tick_us: get("tick_us")?
            .parse()
            .map_err(|_| "line 1: bad tick_us".to_string())?,
        start: numbers("start")?.iter().map(|&v| v as i64).collect(),
        axes,
    };
    let columns = next("the column header")?;
    let expected = format!(
        "tick,{},gap",
        header
            .axes
            .iter()
            .map(|a| a.letter().to_ascii_lowercase().to_string())
            .collect::<Vec<_>>()
            .join(",")
    );
    let with_spark = match columns.strip_prefix(expected.as_str()) {
        Some("") => false,
        Some(",spark,condition") => true,
        _ => {
            return Err(format!(
                "line 2: columns {columns:?}, expected {expected:?} (and ,spark,condition)"
            ));
        }
    };
    let mut rows = Vec::new();
    for (index, line) in lines.enumerate() {
        let line = line.map_err(|e| e.to_string())?;
        let bad = |what: &str| format!("line {}: {what}: {line}", index + 3);
        let mut cells = line.split(',');
        let tick = cells
            .next()
            .and_then(|t| t.parse().ok())
            .ok_or_else(|| bad("bad tick"))?;
        let mut steps = Vec::with_capacity(header.axes.len());
        for _ in &header.axes {
            let s: i8 = cells
                .next()
                .and_then(|t| t.parse().ok())
                .ok_or_else(|| bad("bad step"))?;
            if !(-1..=1).contains(&s) {
                return Err(bad("step out of -1..=1"));
            }
            steps.push(s);
        }
        let gap = cells
            .next()
            .and_then(GapState::from_name)
            .ok_or_else(|| bad("bad gap state"))?;
        let (spark, condition) = if with_spark {
            let spark = match cells.next() {
                Some("1") => true,
                Some("0") => false,
                _ => return Err(bad("bad spark (0 or 1)")),
            };
            let condition = cells
                .next()
                .and_then(|c| c.parse().ok())
                .ok_or_else(|| bad("bad condition"))?;
            (spark, condition)
        } else {
            (false, 0)
        };
        rows.push(PulseLogRow {
            tick,
            steps,
            gap,
            spark,
            condition,
        });
    }
    Ok((header, rows))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_only_on_steps_and_state_changes_and_it_reads_back() {
        let dir = std::env::temp_dir().join(format!("edmd-pulse-log-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("p.csv");
        let header = PulseLogHeader {
            axes: vec![Axis::X, Axis::Z],
            step_mm: vec![0.001, 0.0005],
            tick_us: 50,
            start: vec![3, -4],
        };
        let mut log = PulseLog::create(&path, &header).unwrap();
        let s = |x: i8, z: i8| [x, z, 0, 0, 0, 0];
        log.write(0, &s(0, 0), GapState::Normal).unwrap();
        log.write(1, &s(1, 0), GapState::Normal).unwrap();
        log.write(2, &s(0, 0), GapState::Short).unwrap();
        log.write(3, &s(0, 0), GapState::Short).unwrap();
        log.write(4, &s(-1, 1), GapState::Short).unwrap();
        // The spark comes on with condition E2: a row even without a step.
        log.moving_in(crate::output::Activity {
            spark: true,
            condition: 2,
            ..Default::default()
        });
        log.write(5, &s(0, 0), GapState::Short).unwrap();
        log.write(6, &s(0, 0), GapState::Normal).unwrap();
        log.finish(crate::output::StopReason::Ended).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(
            text,
            "# edmd pulse log; axes=X,Z; step_mm=0.001,0.0005; tick_us=50; start=3,-4\n\
             tick,x,z,gap,spark,condition\n1,1,0,normal,0,0\n2,0,0,short,0,0\n\
             4,-1,1,short,0,0\n5,0,0,short,1,2\n6,0,0,normal,1,2\n"
        );
        let (read, rows) = read_pulse_log(&path).unwrap();
        assert_eq!(read, header);
        assert_eq!(rows.len(), 5);
        assert_eq!(rows[2].steps, vec![-1, 1]);
        assert_eq!((rows[3].spark, rows[3].condition), (true, 2));
        // The older format (no spark and condition columns) still reads.
        std::fs::write(
            &path,
            "# edmd pulse log; axes=X,Z; step_mm=0.001,0.0005; tick_us=50; start=3,-4\n\
             tick,x,z,gap\n1,1,0,normal\n",
        )
        .unwrap();
        let (_, rows) = read_pulse_log(&path).unwrap();
        assert_eq!((rows[0].steps.clone(), rows[0].spark), (vec![1, 0], false));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
