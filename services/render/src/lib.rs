//! Glint's renderer: how a structured-light camera sees shiny parts.
//!
//! Monochrome throughout (SLI cameras are grey-scale): radiance is one `f32` per pixel in
//! W·sr⁻¹·m⁻² for a projector intensity in W/sr.

#![cfg_attr(not(test), deny(clippy::expect_used, clippy::unwrap_used))]
#![warn(missing_docs)]

pub mod bsdf;
pub mod exr_io;
pub mod integrator;
pub mod pattern_record;
pub mod projector;
pub mod rig;
pub mod scene;
pub mod sensor;
pub mod stereo;
