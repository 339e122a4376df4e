//! Glint's photometric calibration (paper §IV-A, §IV-B), transport-free:
//! - [`response`]: the camera response g (eq 12–13) by Debevec–Malik from an exposure stack,
//!   and radiance maps E = g⁻¹(I)/Δt;
//! - plots as PNG ([`plot`]).

pub mod plot;
pub mod response;
