pub mod geometry;
pub mod config;
