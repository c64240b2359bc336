//! A job assembled: its spec read once from the configuration, its devices, the producer, the
//! precheck, the fine thread that runs its ticks, its events and its summary.

pub mod devices;
pub mod error;
pub mod events;
pub mod fine_thread;
pub mod precheck;
pub mod producer;
pub mod spec;
pub mod summary;
