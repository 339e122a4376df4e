//! Glint's orchestrator: active pose-refinement sessions (paper §VI) over the pipeline's
//! stages. [`session`] is the state machine (capture → refine → predict → choose, repeated);
//! [`stages`] the traits it runs on; [`local`] their in-process implementations over the
//! libraries. Nothing here reads ground truth: the mock camera's set-up holds it, and only
//! `glint-eval` looks.

#![cfg_attr(not(test), deny(clippy::expect_used, clippy::unwrap_used))]
#![warn(missing_docs)]

pub mod local;
#[cfg(feature = "server")]
pub mod remote;
#[cfg(feature = "server")]
pub mod server;
pub mod service;
pub mod session;
pub mod stages;
pub mod store;
