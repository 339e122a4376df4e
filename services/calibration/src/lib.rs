//! Glint's photometric calibration (paper §IV-A, §IV-B), transport-free:
//! - [`response`]: the camera response g (eq 12–13) by Debevec–Malik from an exposure stack,
//!   and radiance maps E = g⁻¹(I)/Δt;
//! - [`bsdf_fit`]: principled-BSDF parameters by differentiable rendering (dual numbers
//!   through the renderer's own single- or multi-path tracing), L2 loss, Adam;
//! - principled parameters as name → value maps ([`material_map`]), the material files
//!   ([`material_file`]: fitted, and the mock camera's ground truth).

#![cfg_attr(not(test), deny(clippy::expect_used, clippy::unwrap_used))]
#![warn(missing_docs)]

pub mod bsdf_fit;
pub mod material_file;
pub mod material_map;
pub mod response;
#[cfg(feature = "server")]
pub mod server;
pub mod shipped;
