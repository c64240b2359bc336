//! Validation of `[servo]`: the feeds of the laws, the turn-back's acceleration and short
//! rules, the jumps and the rethread.

use super::raw::RawServo;
use super::validate::{Invalid, at_most, feed, fraction, in_range, positive};
use super::{Jumps, MachineConfig, ServoConfig};

impl RawServo {
    /// `[servo]`, its reversal acceleration defaulting to the machine's largest.
    pub(super) fn validate(self, machine: &MachineConfig) -> Result<ServoConfig, Invalid> {
        servo(self, machine)
    }
}

fn servo(s: RawServo, machine: &MachineConfig) -> Result<ServoConfig, Invalid> {
    let servo = ServoConfig {
        normal_feed_mm_per_min: feed(
            "servo.normal_feed_mm_per_min",
            s.normal_feed_mm_per_min,
            1e6,
        )?,
        open_feed_mm_per_min: feed("servo.open_feed_mm_per_min", s.open_feed_mm_per_min, 1e6)?,
        retract_feed_mm_per_min: feed(
            "servo.retract_feed_mm_per_min",
            s.retract_feed_mm_per_min,
            1e6,
        )?,
        reverse_accel_mm_per_s2: match at_most(
            "servo.reverse_accel_mm_per_s2",
            s.reverse_accel_mm_per_s2,
            1e7,
            "mm/s²",
        )? {
            // The machine's largest: the servo's own motion is the one to be quick.
            0.0 => machine
                .max_tangential_accel_mm_per_s2
                .max(machine.max_normal_accel_mm_per_s2),
            a => a,
        },
        short_confirm_ticks: in_range("servo.short_confirm_ticks", s.short_confirm_ticks, 1, 1000)?
            as u32,
        min_retract_mm: at_most("servo.min_retract_um", s.min_retract_um, 1e4, "µm")? / 1000.0,
        max_short_s: if s.max_short_s.is_finite() && (0.0..=86_400.0).contains(&s.max_short_s) {
            s.max_short_s
        } else {
            return Err((
                "servo.max_short_s",
                format!("must be 0 (off) to 86400 s, got {}", s.max_short_s),
            ));
        },
        law: s.law,
        v_ref: positive("servo.v_ref", s.v_ref, 1e4, "V")?,
        voltage_gain_mm_per_min_per_v: positive(
            "servo.voltage_gain_mm_per_min_per_v",
            s.voltage_gain_mm_per_min_per_v,
            1e6,
            "mm/min per V",
        )?,
        voltage_filter_ms: if s.voltage_filter_ms.is_finite()
            && (0.0..=10_000.0).contains(&s.voltage_filter_ms)
        {
            s.voltage_filter_ms
        } else {
            return Err((
                "servo.voltage_filter_ms",
                format!("must be 0 to 10000 ms, got {}", s.voltage_filter_ms),
            ));
        },
        ratio_ref: fraction("servo.ratio_ref", s.ratio_ref)?,
        ratio_gain_mm_per_min: positive(
            "servo.ratio_gain_mm_per_min",
            s.ratio_gain_mm_per_min,
            1e6,
            "mm/min",
        )?,
        ratio_short_limit: fraction("servo.ratio_short_limit", s.ratio_short_limit)?,
        ratio_open_limit: fraction("servo.ratio_open_limit", s.ratio_open_limit)?,
        jumps: Jumps {
            interval_s: at_most("servo.jump_interval_s", s.jump_interval_s, 86_400.0, "s")?,
            height_mm: at_most("servo.jump_height_mm", s.jump_height_mm, 1000.0, "mm")?,
            feed_mm_per_min: feed("servo.jump_feed_mm_per_min", s.jump_feed_mm_per_min, 1e6)?,
        },
        max_open_mm: at_most("servo.max_open_mm", s.max_open_mm, 1e6, "mm")?,
        rethread_feed_mm_per_min: feed(
            "servo.rethread_feed_mm_per_min",
            s.rethread_feed_mm_per_min,
            1e6,
        )?,
    };
    if servo.jumps.interval_s > 0.0 && servo.jumps.height_mm <= 0.0 {
        return Err((
            "servo.jump_height_mm",
            "must be above 0 when servo.jump_interval_s turns jumps on".to_string(),
        ));
    }
    Ok(servo)
}
