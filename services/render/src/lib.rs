//! Glint's renderer: how a structured-light camera sees shiny parts.
//!
//! Monochrome throughout (SLI cameras are grey-scale): radiance is one `f32` per pixel in
//! W·sr⁻¹·m⁻² (relative units scaled by the projector's intensity).

pub mod bsdf;
