//! The tick's thread: the consumer's loop (inputs, gap, tick core, output), the controls the
//! daemon steers it with, what it publishes (snapshot, events, latency), its real-time
//! settings, the probe's result and the latency measurement.

pub mod consumer;
pub mod controls;
pub mod histogram;
pub mod idle;
pub mod latency;
pub mod probe;
pub mod published;
pub mod realtime;
pub mod snapshot;
