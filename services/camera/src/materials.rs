//! Ground-truth materials of the mock camera's parts, chosen to resemble the paper's objects
//! (Chrome Screw mirror-like; Gear and Tube Fitting shiny metal; Eye Bolt and Zigzag less
//! specular). Ground truth: estimators never read these; they are written beside captures
//! for evaluation only.

use glint_geometry::parts::Part;
use glint_render::bsdf::PrincipledParams;

/// The ground-truth principled parameters of a part.
pub fn ground_truth(part: Part) -> PrincipledParams<f32> {
    // (base_color, metallic, roughness, specular)
    let (base, metallic, roughness, specular) = match part {
        Part::ChromeScrew => (0.92, 1.0, 0.06, 0.5),
        Part::Gear => (0.78, 1.0, 0.16, 0.5),
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
