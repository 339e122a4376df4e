//! Glint's uncertainty stage: the render workers of the active loop (paper §V-D, eq 14–17).
//!
//! For a candidate view `t_w_c` and the current pose hypothesis `t_w_o`, a worker renders the
//! part — its mesh with the *fitted* material, seen through the *calibrated* response — over
//! the part's region of interest only, predicts which depth pixels the camera will lose and how
//! uncertain the others will be, and turns the predicted measurements into the 6×6 Fisher
//! information that view would add to the pose (eq 18, 21–22). Inputs are what a real system
//! knows: never the simulator's ground truth.
//!
//! - [`response`]: the calibrated camera, radiance → intensity (eq 14);
//! - [`predict`]: one candidate's prediction;
//! - `server` (feature `server`): the gRPC server `glint.v1.UncertaintyService` over them.

#![cfg_attr(not(test), deny(clippy::expect_used, clippy::unwrap_used))]
#![warn(missing_docs)]

pub mod predict;
pub mod response;
#[cfg(feature = "server")]
pub mod server;

pub use predict::{
    CandidatePrediction, HypothesisScene, KnownSurface, MissingCounts, PixelCause, PredictionError,
    PredictionSettings, PredictorObject, SigmaModel, candidate_seed, predict_candidate,
    predict_candidate_in,
};
pub use response::CalibratedCamera;
