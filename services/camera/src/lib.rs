//! The mock structured-light camera: bins of shiny parts, simulated SLI captures with real
//! stereo matching, and the dataset formats captures are written in.

#![cfg_attr(not(test), deny(clippy::expect_used, clippy::unwrap_used))]
#![warn(missing_docs)]

pub mod bin;
pub mod capture;
pub mod dataset;
pub mod edge_errors;
pub mod effects;
pub mod exposure;
pub mod materials;
pub mod record;
#[cfg(feature = "server")]
pub mod server;
pub mod setup;
pub mod views;
pub mod visibility;
