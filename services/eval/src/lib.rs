//! Glint's experiments as a library: the paper's evaluations on mock-camera data (or any BOP
//! scene), shared by `glint eval`, `glint bench`, the servers' tests and `tests/`.
//!
//! - [`scenes`]: mock-camera bins cached as BOP scenes, and the reader that turns a BOP scene
//!   into per-view object points with σ_z (the refiner's input path, eq 1–7);
//! - [`initial_pose`]: initial poses drawn like the paper's template detector, fitted to its
//!   initial row of Table I;
//! - [`metrics`]: symmetry-aware NEES, correlations, McNemar's test;
//! - [`table1`]: Table I, SDF refinement against ICP;
//! - [`depth_uncertainty`]: Fig. 3, predicted σ_z (eq 1–5) against the measured spread;
//! - [`bsdf_check`]: a fitted material against the truth, on fitted and held-out views;
//! - [`active`]: an active session on a mock bin (the demo's and the tests');
//! - [`camera_validation`]: the mock camera against known geometry (depth error by shot
//!   count and window, wrong depth by cause, the plane at 0.6 m);
//! - [`capture_folder`]: mock captures written as BOP folders, and calibration captures;
//! - [`policies`]: the view policies compared over whole sessions (the demo's loop);
//! - [`fig9`]: Fig. 9 as the paper measures it: every policy chooses every view among the
//!   same candidates, from the same detector guesses, on shared captures;
//! - [`thresholds`]: τ_I and τ_σ (eq 16–17) chosen on tuning seeds, by how well the predicted
//!   missing pixels match the capture's lost ones;
//! - [`prediction`]: is the prediction right — every candidate's predicted missing mask,
//!   σ̌_z and Fisher information against the mock camera's capture from that view;
//! - [`progress`]: progress bars for long runs.
//!
//! Evaluation code reads ground truth (to draw initial poses and to score); nothing that
//! estimates or predicts may depend on this crate.

#![cfg_attr(not(test), deny(clippy::expect_used, clippy::unwrap_used))]
#![warn(missing_docs)]

pub mod active;
pub mod bsdf_check;
pub mod camera_validation;
pub mod capture_folder;
pub mod depth_uncertainty;
pub mod fig9;
pub mod initial_pose;
pub mod metrics;
pub mod policies;
pub mod prediction;
pub mod progress;
pub mod scenes;
pub mod table1;
pub mod thresholds;
