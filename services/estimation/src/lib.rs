//! Glint's estimation stage: from SLI depth to an object pose and its uncertainty.
//!
//! - [`depth_sigma`]: per-pixel depth variance σ_z² from the pattern images (eq 1–5);
//! - [`points`]: masked depth → camera-frame points → world frame (eq 6–7);
//! - [`depth_alignment`]: a detector's pose moved along the viewing ray onto the depth before
//!   refinement (its worst axis);
//! - [`correlated_error`]: depth errors neighbouring pixels share, and the information left;
//! - [`refine`]: uncertainty-weighted SDF Gauss–Newton / Levenberg–Marquardt over T_o_w
//!   (eq 8–11) and the pose covariance from the Fisher information (eq 18–19);
//! - [`icp`]: the ICP baseline (point-to-point and point-to-plane) on the same inputs;
//! - [`nbv`]: next-best-view planning by minimum pose entropy (eq 20–23) and the heuristics;
//! - [`view_bias`]: a pose error one view's points share, and the multi-view information left;
//! - [`pose_error_model`]: both shared errors as one measured model per part, in a file
//!   (shipped for the built-in parts), as sessions' refinements and planners use it;
//! - [`view`]: one captured view → the part's depth points under a pose hypothesis;
//! - [`multiview`]: a session's views → one refined pose with its information (the two-pass
//!   hypothesis-silhouette masking the in-process stage and the `Refine` RPC share).
//!
//! Conventions are the geometry crate's: metres, `t_a_b` maps b → a, left perturbations
//! `T ← exp(δ)·T` with δ = (ρ, φ). Nothing here reads ground truth.

#![cfg_attr(not(test), deny(clippy::expect_used, clippy::unwrap_used))]
#![warn(missing_docs)]

pub mod correlated_error;
pub mod depth_alignment;
pub mod depth_sigma;
pub mod icp;
pub mod multiview;
pub mod nbv;
pub mod points;
pub mod pose_error_model;
pub mod refine;
#[cfg(feature = "server")]
pub mod server;
pub mod view;
pub mod view_bias;
