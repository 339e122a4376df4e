//! The mock structured-light camera and dataset formats.

pub mod dataset;
