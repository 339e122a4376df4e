//! The parameters of the principled BSDF, generic over the scalar so that the same struct carries
//! plain `f32` values (rendering) or dual numbers (forward-mode differentiation in the BSDF fit).

use num_dual::DualNum;

/// A scalar the BSDF can be evaluated with: `f32` itself or any `num_dual` dual number over `f32`
/// (`Dual32`, `Dual2_32`, `HyperDual32`, …). Directions stay `f32`: only parameters carry
/// derivatives.
pub trait BsdfScalar: DualNum<Primitive = f32> + Copy {}
impl<T: DualNum<Primitive = f32> + Copy> BsdfScalar for T {}

/// Parameters of Mitsuba 3's `principled` BSDF without its transmission part (`spec_trans`,
/// `eta`, `flatness` are absent: Glint's parts are opaque metal).
///
/// Every parameter is dimensionless and lives in [0, 1]. Glint is monochrome (grey-scale SLI
/// cameras), so `base_color` is one reflectance instead of an RGB triple; for a grey colour
/// Mitsuba's tint colour `base_color / luminance(base_color)` is exactly 1, which is why the two
/// tints act as follows here:
/// - `spec_tint` does not tint anything. It still blends the dielectric specular Fresnel from
///   the exact dielectric formula towards a Schlick approximation with the same F0 — a
///   difference of a few per cent at grazing angles, kept for parity with Mitsuba.
/// - `sheen_tint` has no effect at all; it is kept so that parameter sets transfer both ways.
///
/// `PrincipledParams<f32>` is the everyday type; [`PrincipledParams::map`] lifts it to dual
/// numbers for differentiation.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PrincipledParams<T> {
    /// Diffuse albedo and metallic F0 (grey reflectance).
    pub base_color: T,
    /// Blend from dielectric (0) to metal (1).
    pub metallic: T,
    /// Perceptual roughness; the GGX width is α = roughness² (floored at 0.001 like Mitsuba).
    pub roughness: T,
    /// Dielectric specular: normal-incidence reflectance F0 = 0.08 · specular (0.5 ↔ IOR 1.5).
    pub specular: T,
    /// Dielectric Fresnel blend from exact (0) to Schlick (1); no colour effect in monochrome.
    pub spec_tint: T,
    /// Anisotropy of the GGX lobe, rougher along the shading frame's tangent.
    pub anisotropic: T,
    /// Weight of the retro-reflective sheen lobe at grazing angles (dielectric part only).
    pub sheen: T,
    /// No effect in monochrome (see the type's doc); kept for parity.
    pub sheen_tint: T,
    /// Weight of the secondary GTR1 clearcoat lobe.
    pub clearcoat: T,
    /// Clearcoat glossiness: GTR1 width α = lerp(0.1, 0.001, clearcoat_gloss).
    pub clearcoat_gloss: T,
}

/// A parameter outside [0, 1] or not finite.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("principled BSDF parameter `{name}` is {value}, but must be a finite number in [0, 1]")]
pub struct InvalidParameter {
    /// The parameter's field name, as in [`PrincipledParams::NAMES`].
    pub name: &'static str,
    /// The offending value (its real part for dual numbers).
    pub value: f32,
}

/// Number of parameters in [`PrincipledParams`].
pub const PARAMETER_COUNT: usize = 10;

impl<T> PrincipledParams<T> {
    /// Field names, in the order of [`PrincipledParams::to_array`].
    pub const NAMES: [&'static str; PARAMETER_COUNT] = [
        "base_color",
        "metallic",
        "roughness",
        "specular",
        "spec_tint",
        "anisotropic",
        "sheen",
        "sheen_tint",
        "clearcoat",
        "clearcoat_gloss",
    ];

    /// All parameters in the order of [`PrincipledParams::NAMES`].
    pub fn to_array(self) -> [T; PARAMETER_COUNT] {
        [
            self.base_color,
            self.metallic,
            self.roughness,
            self.specular,
            self.spec_tint,
            self.anisotropic,
            self.sheen,
            self.sheen_tint,
            self.clearcoat,
            self.clearcoat_gloss,
        ]
    }

    /// Inverse of [`PrincipledParams::to_array`] (not validated).
    pub fn from_array(values: [T; PARAMETER_COUNT]) -> Self {
        let [
            base_color,
            metallic,
            roughness,
            specular,
            spec_tint,
            anisotropic,
            sheen,
            sheen_tint,
            clearcoat,
            clearcoat_gloss,
        ] = values;
        Self {
            base_color,
            metallic,
            roughness,
            specular,
            spec_tint,
            anisotropic,
            sheen,
            sheen_tint,
            clearcoat,
            clearcoat_gloss,
        }
    }

    /// Applies `f` to every parameter, e.g. `p.map(Dual32::from_re)` to lift to dual numbers.
    pub fn map<U>(self, f: impl FnMut(T) -> U) -> PrincipledParams<U> {
        PrincipledParams::from_array(self.to_array().map(f))
    }
}

impl PrincipledParams<f32> {
    /// Validated parameters for the four that a fit of a metal part usually frees; the others
    /// are 0 (their lobes off: no sheen, no clearcoat, isotropic, no tint).
    pub fn new(
        base_color: f32,
        metallic: f32,
        roughness: f32,
        specular: f32,
    ) -> Result<Self, InvalidParameter> {
        Self {
            base_color,
            metallic,
            roughness,
            specular,
            ..Self::ZERO
        }
        .validated()
    }

    /// The paper's starting point for a fit: every parameter at the medium value 0.5.
    pub const MIDPOINT: Self = Self::splat(0.5);

    const ZERO: Self = Self::splat(0.0);

    const fn splat(v: f32) -> Self {
        Self {
            base_color: v,
            metallic: v,
            roughness: v,
            specular: v,
            spec_tint: v,
            anisotropic: v,
            sheen: v,
            sheen_tint: v,
            clearcoat: v,
            clearcoat_gloss: v,
        }
    }
}

/// Mitsuba's defaults: base_color 0.5, roughness 0.5, specular 0.5, everything else 0.
impl Default for PrincipledParams<f32> {
    fn default() -> Self {
        Self {
            base_color: 0.5,
            roughness: 0.5,
            specular: 0.5,
            ..Self::ZERO
        }
    }
}

impl<T: BsdfScalar> PrincipledParams<T> {
    /// `self` if every parameter (its real part) is finite and in [0, 1], else the first
    /// offending one, by name.
    pub fn validated(self) -> Result<Self, InvalidParameter> {
        for (name, value) in Self::NAMES.iter().zip(self.to_array()) {
            let value = value.re();
            if !(0.0..=1.0).contains(&value) {
                return Err(InvalidParameter { name, value });
            }
        }
        Ok(self)
    }

    /// Projects every parameter onto [0, 1], for an optimiser's step. A clamped dual number
    /// becomes a constant (zero derivative), as a projection should; NaN stays NaN so that
    /// [`PrincipledParams::validated`] still reports it.
    pub fn clamped(self) -> Self {
        self.map(|v| {
            if v.re() < 0.0 {
                T::from(0.0)
            } else if v.re() > 1.0 {
                T::from(1.0)
            } else {
                v
            }
        })
    }

    /// The real parts, dropping derivatives.
    pub fn re(&self) -> PrincipledParams<f32> {
        self.map(|v| v.re())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_dual::Dual32;

    #[test]
    fn validation_names_the_offending_field() {
        assert!(PrincipledParams::new(0.5, 1.0, 0.2, 0.5).is_ok());
        let err = PrincipledParams::new(0.5, 1.0, 1.2, 0.5).unwrap_err();
        assert_eq!(err.name, "roughness");
        assert!(err.to_string().contains("`roughness` is 1.2"), "{err}");
        let err = PrincipledParams::new(f32::NAN, 1.0, 0.2, 0.5).unwrap_err();
        assert_eq!(err.name, "base_color");
        let p = PrincipledParams {
            clearcoat_gloss: -0.1,
            ..PrincipledParams::default()
        };
        assert_eq!(p.validated().unwrap_err().name, "clearcoat_gloss");
        let inf = PrincipledParams {
            sheen: f32::INFINITY,
            ..PrincipledParams::default()
        };
        assert_eq!(inf.validated().unwrap_err().name, "sheen");
    }

    #[test]
    fn clamping_projects_onto_the_unit_interval() {
        let p = PrincipledParams {
            base_color: -0.3,
            metallic: 1.7,
            roughness: 0.25,
            ..PrincipledParams::default()
        };
        let c = p.clamped();
        assert_eq!((c.base_color, c.metallic, c.roughness), (0.0, 1.0, 0.25));
        assert!(c.validated().is_ok());
        let nan = PrincipledParams {
            sheen: f32::NAN,
            ..PrincipledParams::default()
        };
        assert!(nan.clamped().validated().is_err());

        let d = p.map(|v| Dual32::new(v, 1.0)).clamped();
        assert_eq!(d.base_color.eps, 0.0);
        assert_eq!(d.roughness.eps, 1.0);
        assert_eq!(d.re(), c);
    }

    #[test]
    fn array_round_trip_follows_names() {
        let p = PrincipledParams::from_array(std::array::from_fn(|i| i as f32 / 10.0));
        assert_eq!(p.roughness, 0.2);
        assert_eq!(PrincipledParams::<f32>::NAMES[2], "roughness");
        assert_eq!(PrincipledParams::from_array(p.to_array()), p);
    }
}
