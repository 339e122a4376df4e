//! Ground-truth materials of the mock camera's parts. Ground truth: estimators never read
//! these; they are written beside captures for evaluation only.
//!
//! Where each number comes from (`docs/results/materials-sources.md` has the tables):
//! - metal F0 (`base_color`) at the N35's 465 nm projector from measured optical constants,
//!   `F0 = ((n−1)² + k²)/((n+1)² + k²)`: chromium 0.56–0.70 (Johnson & Christy 1974, Rakić
//!   1998, Sytchkova 2021) → the Chrome Screw's 0.62; iron 0.50–0.59 and stainless steel
//!   0.57–0.61 (Johnson & Christy, Querry 1985, Karlsson & Ribbing 1982) → the Gear's 0.55.
//!   Both were set by eye before (0.92, 0.78: aluminium's and silver's range);
//! - the Chrome Screw's roughness 0.06 matches fits of MERL's measured `chrome` BRDF (GGX
//!   α ≈ 0.004, at the measurement's angular resolution);
//! - no published measurement was found for the rest, which stay as first chosen and are
//!   marked so: the Gear's and the Tube Fitting's roughness (machined surfaces), the Tube
//!   Fitting's alloy (0.82 fits zinc plating, not brass at 465 nm), and the Eye Bolt's and
//!   Zigzag's partial `metallic` (no physical basis: a bare metal has no diffuse lobe; it
//!   stands for a passivation film or dirt until their BRDFs are fitted to real images).

use glint_geometry::parts::Part;
use glint_render::bsdf::PrincipledParams;

/// The ground-truth principled parameters of a part.
pub fn ground_truth(part: Part) -> PrincipledParams<f32> {
    // (base_color, metallic, roughness, specular)
    let (base, metallic, roughness, specular) = match part {
        Part::ChromeScrew => (0.62, 1.0, 0.06, 0.5),
        Part::Gear => (0.55, 1.0, 0.16, 0.5),
        Part::TubeFitting => (0.82, 1.0, 0.14, 0.5),
        Part::EyeBolt => (0.55, 0.7, 0.38, 0.5),
        Part::Zigzag => (0.6, 0.4, 0.5, 0.4),
    };
    principled(base, metallic, roughness, specular)
}

/// The same part painted matte grey: the "diffuse twin" that shows what shininess costs.
pub fn diffuse_twin() -> PrincipledParams<f32> {
    principled(0.6, 0.0, 1.0, 0.0)
}

/// The bin: grey, diffuse, slightly glossy plastic.
pub fn bin() -> PrincipledParams<f32> {
    principled(0.35, 0.0, 0.8, 0.3)
}

/// What [`PrincipledParams::new`] makes of the four parameters a metal fit frees (the other
/// lobes off), without its range check: every caller here passes constants in [0, 1].
const fn principled(
    base_color: f32,
    metallic: f32,
    roughness: f32,
    specular: f32,
) -> PrincipledParams<f32> {
    PrincipledParams {
        base_color,
        metallic,
        roughness,
        specular,
        spec_tint: 0.0,
        anisotropic: 0.0,
        sheen: 0.0,
        sheen_tint: 0.0,
        clearcoat: 0.0,
        clearcoat_gloss: 0.0,
    }
}
