//! Glint's photometric calibration (paper §IV-A, §IV-B), transport-free:
//! - [`response`]: the camera response g (eq 12–13) by Debevec–Malik from an exposure stack,
//!   and radiance maps E = g⁻¹(I)/Δt;
//! - [`bsdf_fit`]: principled-BSDF parameters by differentiable rendering (dual numbers
//!   through the renderer's own single-path shading), L2 loss, Adam;
//! - the calibration scene file ([`scene_file`]) and plots as PNG ([`plot`]).

pub mod bsdf_fit;
pub mod plot;
pub mod response;
pub mod scene_file;
