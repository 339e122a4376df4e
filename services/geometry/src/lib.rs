//! Glint's geometry core: triangle meshes and their file formats, the five parametric parts of
//! the paper's evaluation, signed distance grids, SE(3) and symmetry-aware pose errors, camera
//! models and image buffers.
//!
//! Conventions (see `shared/DESIGN.md`):
//! - lengths are metres and angles radians, unless a name says otherwise (`_mm`, `_deg`);
//! - `t_a_b: Isometry3<f64>` maps a point from frame b to frame a: `p_a = t_a_b * p_b`;
//! - poses are perturbed on the left, `T ← exp(δ)·T`, with `δ = (ρ, φ)`, translation first;
//! - meshes are `f32` (rendering precision), estimation is `f64`.

#![cfg_attr(not(test), deny(clippy::expect_used, clippy::unwrap_used))]
#![warn(missing_docs)]

pub mod camera;
pub mod glam_interop;
pub mod image;
pub mod io;
pub mod mesh;
pub mod parts;
pub mod pose_deviation;
pub mod sampling;
pub mod sdf;
pub mod se3;
pub mod silhouette;
pub mod symmetry;

pub use mesh::{LengthUnit, MeshError, MeshReport, TriMesh};
pub use parts::Part;
pub use symmetry::Symmetry;

/// SHA-256 of `bytes`, lowercase hex: the content keys of meshes, objects and blobs.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}
