//! `gap.kind = "iio"`: the generator's average gap voltage through a Linux IIO ADC.
//!
//! Linux exposes an ADC channel as sysfs attributes of its device directory
//! (`/sys/bus/iio/devices/iio:deviceN`): `in_voltageK_raw` (counts), `in_voltageK_scale` or the
//! shared `in_voltage_scale` (millivolts per count) and, on some ADCs, `in_voltageK_offset`
//! (counts added before scaling). The gap voltage is `(raw + offset) × scale / 1000 × gain`,
//! `gain` being the divider in front of the ADC (gap volts per ADC volt).
//!
//! A sysfs read costs tens of microseconds, too much for a tick, so a **sampler thread** reads
//! the channel at `gap.iio_rate_hz` and publishes the latest value in an atomic; the consumer's
//! thread loop takes it from there ([`GapSensor::sample`], no I/O) and the tick core gets the
//! state as a value. The voltage is a gap state by the gap's two thresholds ([`GapVolts`]:
//! `gap.short_below_v`, `gap.open_above_v`): below the first a short, above the second open,
//! sparking in between.
//!
//! Failures are named: a missing device directory or channel, an unreadable or non-numeric
//! attribute at startup ([`IioError`]); a read that fails later, or a sampler whose value is
//! older than ten sampling periods (at least 100 ms), stops the job with a [`GapError`].

use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use parking_lot::Mutex;

use super::{GapError, GapSensor, GapState};
use crate::vocab::GapVolts;

/// The IIO input's settings (`[gap]`, validated by the configuration).
#[derive(Debug, Clone, PartialEq)]
pub struct IioSettings {
    /// The device's sysfs directory.
    pub device: PathBuf,
    /// Channel name as in the attribute names: `voltage0`.
    pub channel: String,
    /// Gap volts per ADC volt.
    pub gain: f64,
    pub rate_hz: f64,
}

/// The IIO input could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum IioError {
    #[error(
        "{path}: no such IIO device (gap.iio_device): `ls /sys/bus/iio/devices` lists the \
         devices; load the ADC's driver"
    )]
    NoDevice { path: String },
    #[error("{path}: the ADC has no channel {channel} (gap.iio_channel): {source}")]
    NoChannel {
        path: String,
        channel: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: `{text}` is not a number")]
    NotANumber { path: String, text: String },
    #[error("{path}: cannot start the IIO sampler thread: {source}")]
    Thread {
        path: String,
        #[source]
        source: std::io::Error,
    },
}

/// What the sampler publishes.
#[derive(Debug, Default)]
struct Shared {
    volts: AtomicU64,
    /// Samples taken so far.
    samples: AtomicU64,
    /// Nanoseconds since `start` of the last sample.
    at_ns: AtomicU64,
    failed: Mutex<Option<std::io::Error>>,
    stop: AtomicBool,
}

/// The IIO gap input: a sampler thread and the latest voltage.
#[derive(Debug)]
pub struct IioGap {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    raw_path: PathBuf,
    start: Instant,
    stale_after: Duration,
    volts: GapVolts,
}

/// One sysfs attribute, opened and read whole for every sample (as `cat` does: a driver
/// computes the value on each read from offset 0, and a reopened file follows a replaced one).
struct Attribute {
    path: PathBuf,
    buf: String,
}

impl Attribute {
    fn open(path: PathBuf) -> std::io::Result<Attribute> {
        crate::sys::open_regular(&path)?;
        Ok(Attribute {
            path,
            buf: String::with_capacity(32),
        })
    }

    /// The attribute's value; `Ok(None)` when it is not a number. A sysfs attribute is a
    /// regular file: anything else in its place (a FIFO) is an error at once, never a read
    /// that waits for ever.
    fn read(&mut self) -> std::io::Result<Option<f64>> {
        self.buf.clear();
        crate::sys::open_regular(&self.path)?.read_to_string(&mut self.buf)?;
        Ok(self.buf.trim().parse().ok())
    }
}

fn number(path: &Path) -> Result<Option<f64>, IioError> {
    match crate::sys::read_regular(path) {
        Err(_) => Ok(None),
        Ok(text) => text
            .trim()
            .parse()
            .map(Some)
            .map_err(|_| IioError::NotANumber {
                path: path.display().to_string(),
                text: text.trim().to_string(),
            }),
    }
}

impl IioGap {
    /// Checks the device and channel, reads the scale and offset, takes a first sample and
    /// starts the sampler.
    pub fn open(settings: &IioSettings, volts: GapVolts) -> Result<IioGap, IioError> {
        let dir = &settings.device;
        if !dir.is_dir() {
            return Err(IioError::NoDevice {
                path: dir.display().to_string(),
            });
        }
        let ch = &settings.channel;
        let raw_path = dir.join(format!("in_{ch}_raw"));
        let mut raw = Attribute::open(raw_path.clone()).map_err(|source| IioError::NoChannel {
            path: raw_path.display().to_string(),
            channel: ch.clone(),
            source,
        })?;
        // The channel's own scale, else the type's shared one (`in_voltage_scale`), else 1.
        let kind: String = ch
            .trim_end_matches(|c: char| c.is_ascii_digit())
            .to_string();
        let scale = match number(&dir.join(format!("in_{ch}_scale")))? {
            Some(s) => s,
            None => number(&dir.join(format!("in_{kind}_scale")))?.unwrap_or(1.0),
        };
        let offset = number(&dir.join(format!("in_{ch}_offset")))?.unwrap_or(0.0);
        let gain = settings.gain;
        let to_volts = move |counts: f64| (counts + offset) * scale / 1000.0 * gain;
        let first = raw
            .read()
            .map_err(|source| IioError::NoChannel {
                path: raw_path.display().to_string(),
                channel: ch.clone(),
                source,
            })?
            .ok_or_else(|| IioError::NotANumber {
                path: raw_path.display().to_string(),
                text: raw.buf.trim().to_string(),
            })?;
        let shared = Arc::new(Shared::default());
        shared
            .volts
            .store(to_volts(first).to_bits(), Ordering::Relaxed);
        shared.samples.store(1, Ordering::Relaxed);
        let start = Instant::now();
        let period = Duration::from_secs_f64(1.0 / settings.rate_hz);
        let sampler = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("edmd-iio".into())
            .spawn(move || {
                let mut next = Instant::now() + period;
                while !sampler.stop.load(Ordering::Relaxed) {
                    std::thread::sleep(next.saturating_duration_since(Instant::now()));
                    next += period;
                    match raw.read() {
                        Ok(Some(counts)) => {
                            sampler
                                .volts
                                .store(to_volts(counts).to_bits(), Ordering::Relaxed);
                            sampler
                                .at_ns
                                .store(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
                            sampler.samples.fetch_add(1, Ordering::Release);
                        }
                        Ok(None) => {
                            *sampler.failed.lock() = Some(std::io::Error::new(
                                std::io::ErrorKind::InvalidData,
                                format!("`{}` is not a number", raw.buf.trim()),
                            ));
                            return;
                        }
                        Err(e) => {
                            *sampler.failed.lock() = Some(e);
                            return;
                        }
                    }
                }
            })
            .map_err(|source| IioError::Thread {
                path: raw_path.display().to_string(),
                source,
            })?;
        Ok(IioGap {
            shared,
            thread: Some(thread),
            raw_path,
            start,
            stale_after: (period * 10).max(Duration::from_millis(100)),
            volts,
        })
    }

    /// The latest gap voltage (V).
    pub fn volts(&self) -> f64 {
        f64::from_bits(self.shared.volts.load(Ordering::Relaxed))
    }

    /// The gap state a voltage means.
    pub fn state_of(&self, volts: f64) -> GapState {
        self.volts.state_of(volts)
    }
}

impl GapSensor for IioGap {
    fn sample(&mut self, _tick: u64) -> Result<GapState, GapError> {
        let path = || self.raw_path.display().to_string();
        if let Some(e) = self.shared.failed.lock().take() {
            return Err(GapError::Device {
                path: path(),
                source: e,
            });
        }
        // Before the sampler's first own sample the value is the one `open` read.
        if self.shared.samples.load(Ordering::Acquire) > 1 {
            let at = Duration::from_nanos(self.shared.at_ns.load(Ordering::Relaxed));
            let age = self.start.elapsed().saturating_sub(at);
            if age > self.stale_after {
                return Err(GapError::Stale {
                    path: path(),
                    ms: age.as_millis() as u64,
                });
            }
        } else if self.start.elapsed() > self.stale_after * 10 {
            return Err(GapError::Stale {
                path: path(),
                ms: self.start.elapsed().as_millis() as u64,
            });
        }
        Ok(self.state_of(self.volts()))
    }

    fn volts(&self) -> Option<f64> {
        Some(IioGap::volts(self))
    }
}

/// How long dropping the input waits for its sampler to end before leaving it behind.
const SAMPLER_JOIN: Duration = Duration::from_millis(500);

impl Drop for IioGap {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        let Some(thread) = self.thread.take() else {
            return;
        };
        // A sampler stuck in a driver's read must not hold up the job's end (and with it
        // the daemon's control loop): it is waited for a while, then left to end on its own.
        let deadline = Instant::now() + SAMPLER_JOIN;
        while !thread.is_finished() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(2));
        }
        if thread.is_finished() {
            let _ = thread.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fake_device(name: &str, raw: &str, scale: Option<&str>) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("edmd-iio-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("in_voltage0_raw"), raw).unwrap();
        if let Some(s) = scale {
            std::fs::write(dir.join("in_voltage_scale"), s).unwrap();
        }
        dir
    }

    fn settings(dir: &Path) -> IioSettings {
        IioSettings {
            device: dir.to_path_buf(),
            channel: "voltage0".into(),
            gain: 20.0,
            rate_hz: 2000.0,
        }
    }

    const VOLTS: GapVolts = GapVolts {
        short_below: 5.0,
        open_above: 60.0,
    };

    /// Replaces the raw attribute atomically (a real attribute never reads half-written).
    fn set_raw(dir: &Path, raw: &str) {
        let tmp = dir.join("raw.tmp");
        std::fs::write(&tmp, raw).unwrap();
        std::fs::rename(tmp, dir.join("in_voltage0_raw")).unwrap();
    }

    /// Waits until the sampler has published `volts`.
    fn settle(gap: &IioGap, volts: f64) {
        let deadline = Instant::now() + Duration::from_secs(5);
        while (gap.volts() - volts).abs() > 1e-9 {
            assert!(
                Instant::now() < deadline,
                "still {} V, not {volts}",
                gap.volts()
            );
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    #[test]
    fn raw_counts_become_gap_volts_and_states() {
        // 12-bit ADC, 0.805664 mV per count, a 1:20 divider: 1500 counts = 24.17 V at the gap.
        let dir = fake_device("states", "1500\n", Some("0.805664\n"));
        let mut gap = IioGap::open(&settings(&dir), VOLTS).unwrap();
        let v = 1500.0 * 0.805664 / 1000.0 * 20.0;
        assert!((gap.volts() - v).abs() < 1e-9);
        assert_eq!(gap.sample(0).unwrap(), GapState::Normal);
        for (raw, volts, state) in [
            ("200", 200.0 * 0.805664 / 50.0, GapState::Short),
            ("4000", 4000.0 * 0.805664 / 50.0, GapState::Open),
            ("1860", 1860.0 * 0.805664 / 50.0, GapState::Normal),
        ] {
            set_raw(&dir, raw);
            settle(&gap, volts);
            assert_eq!(gap.sample(1).unwrap(), state, "{raw} counts");
        }
    }

    #[test]
    fn missing_device_channel_and_bad_values_are_named() {
        let dir = fake_device("errors", "12", None);
        let mut s = settings(&dir);
        s.device = dir.join("nope");
        let e = IioGap::open(&s, VOLTS).unwrap_err().to_string();
        assert!(e.contains("no such IIO device (gap.iio_device)"), "{e}");
        let mut s = settings(&dir);
        s.channel = "voltage3".into();
        let e = IioGap::open(&s, VOLTS).unwrap_err().to_string();
        assert!(
            e.contains("in_voltage3_raw") && e.contains("no channel voltage3"),
            "{e}"
        );
        std::fs::write(dir.join("in_voltage0_raw"), "n/a").unwrap();
        let e = IioGap::open(&settings(&dir), VOLTS)
            .unwrap_err()
            .to_string();
        assert!(e.contains("`n/a` is not a number"), "{e}");
        // No scale attribute: 1 mV per count.
        std::fs::write(dir.join("in_voltage0_raw"), "1000").unwrap();
        let gap = IioGap::open(&settings(&dir), VOLTS).unwrap();
        assert!((gap.volts() - 20.0).abs() < 1e-12);
    }

    /// The first error the input reports, within 5 s.
    fn first_error(gap: &mut IioGap) -> String {
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            match gap.sample(0) {
                Err(e) => return e.to_string(),
                Ok(_) => {
                    assert!(Instant::now() < deadline, "no error");
                    std::thread::sleep(Duration::from_millis(2));
                }
            }
        }
    }

    #[test]
    fn a_reading_that_turns_bad_stops_the_job_with_the_file_named() {
        let dir = fake_device("runtime", "1500", Some("1"));
        let mut gap = IioGap::open(&settings(&dir), VOLTS).unwrap();
        set_raw(&dir, "garbage");
        let e = first_error(&mut gap);
        assert!(
            e.contains("in_voltage0_raw") && e.contains("garbage"),
            "{e}"
        );
    }

    /// The channel's file replaced by a FIFO (which `open` would wait on for a writer): the
    /// sampler fails at once with the file named, and dropping the input does not wait.
    #[test]
    fn a_fifo_in_the_channels_place_fails_at_once() {
        let dir = fake_device("fifo", "1500", Some("1"));
        let mut gap = IioGap::open(&settings(&dir), VOLTS).unwrap();
        // Made aside and renamed over the channel: the sampler sees the file or the FIFO.
        let fifo = dir.join("fifo");
        assert!(
            std::process::Command::new("mkfifo")
                .arg(&fifo)
                .status()
                .unwrap()
                .success()
        );
        std::fs::rename(&fifo, dir.join("in_voltage0_raw")).unwrap();
        let e = first_error(&mut gap);
        assert!(e.contains("in_voltage0_raw") && e.contains("FIFO"), "{e}");
        let dropping = Instant::now();
        drop(gap);
        assert!(dropping.elapsed() < Duration::from_secs(1));
        // Opened on a FIFO from the start: refused with the channel named.
        let e = IioGap::open(&settings(&dir), VOLTS)
            .unwrap_err()
            .to_string();
        assert!(e.contains("a FIFO, not a regular file"), "{e}");
    }
}
