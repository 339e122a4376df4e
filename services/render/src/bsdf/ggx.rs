//! The anisotropic GGX (Trowbridge–Reitz) microfacet distribution with Smith masking, as
//! Mitsuba's `MicrofacetDistribution(GGX, α_u, α_v)` (Walter et al. 2007; Heitz 2014).
//!
//! Local frame: z is the macro-surface normal, α_x acts along x (the tangent), α_y along y.

use glam::Vec3;
use std::f32::consts::PI;

use super::is_positive;
use super::params::BsdfScalar;
use super::warp::square_to_uniform_disk_concentric;

/// Smallest GGX width, as Mitsuba's principled `calc_dist_params` floors α.
pub const MIN_ALPHA: f32 = 0.001;

/// An anisotropic GGX distribution of microfacet normals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ggx<T> {
    /// Width along the tangent (local x).
    pub alpha_x: T,
    /// Width along the bitangent (local y).
    pub alpha_y: T,
}

impl<T: BsdfScalar> Ggx<T> {
    /// Disney's mapping, as Mitsuba's `calc_dist_params`: aspect = √(1 − 0.9 · anisotropic),
    /// α_x = max(0.001, roughness² / aspect), α_y = max(0.001, roughness² · aspect).
    ///
    /// The floor is Mitsuba's; below roughness ≈ 0.032 the derivative with respect to roughness
    /// is therefore 0 (a clamp, not a switch: values stay continuous).
    #[inline]
    pub fn from_roughness(roughness: T, anisotropic: T) -> Self {
        let r2 = roughness * roughness;
        let aspect = (anisotropic * -0.9 + 1.0).sqrt();
        Self {
            alpha_x: floor_alpha(r2 / aspect),
            alpha_y: floor_alpha(r2 * aspect),
        }
    }

    /// D(m) = 1 / (π α_x α_y ((m_x/α_x)² + (m_y/α_y)² + m_z²)²) for m above the horizon, else 0.
    /// Normalised so that ∫ D(m) cos θ_m dω_m = 1. `m` must be unit length.
    #[inline]
    pub fn d(&self, m: Vec3) -> T {
        if !is_positive(m.z) {
            return T::from(0.0);
        }
        let x = self.alpha_x.recip() * m.x;
        let y = self.alpha_y.recip() * m.y;
        let s = x * x + y * y + m.z * m.z;
        (self.alpha_x * self.alpha_y * s * s * PI).recip()
    }

    /// Smith's masking G1(v, m) = 2 / (1 + √(1 + (α_x² v_x² + α_y² v_y²)/v_z²)), and 0 when `v`
    /// sees the back of the microfacet (v·m and v_z of opposite signs) — Mitsuba's `smith_g1`.
    #[inline]
    pub fn smith_g1(&self, v: Vec3, m: Vec3) -> T {
        if !is_positive(v.dot(m) * v.z) {
            return T::from(0.0);
        }
        let ax = self.alpha_x * v.x;
        let ay = self.alpha_y * v.y;
        let tan2_alpha = (ax * ax + ay * ay) * (v.z * v.z).recip();
        ((tan2_alpha + 1.0).sqrt() + 1.0).recip() * 2.0
    }

    /// Separable Smith shadowing–masking G(wi, wo, m) = G1(wi, m) · G1(wo, m), Mitsuba's
    /// `MicrofacetDistribution::G` (not the height-correlated form).
    #[inline]
    pub fn smith_g(&self, wi: Vec3, wo: Vec3, m: Vec3) -> T {
        self.smith_g1(wi, m) * self.smith_g1(wo, m)
    }

    /// Density of visible normals D_wi(m) = G1(wi, m) max(0, wi·m) D(m) / cos θi (Heitz &
    /// d'Eon 2014), the density of [`Ggx::sample_visible_normal`] over microfacet normals.
    #[inline]
    pub fn visible_normal_pdf(&self, wi: Vec3, m: Vec3) -> T {
        let cos_im = wi.dot(m);
        if !(is_positive(cos_im) && is_positive(wi.z)) {
            return T::from(0.0);
        }
        self.d(m) * self.smith_g1(wi, m) * (cos_im / wi.z)
    }
}

impl Ggx<f32> {
    /// Samples a microfacet normal from the distribution of normals visible from `wi`
    /// (wi.z > 0), Heitz 2018, "Sampling the GGX Distribution of Visible Normals" (JCGT 7(4)):
    /// stretch wi to the α = 1 configuration, sample the projected hemisphere (a disk, the part
    /// behind the hemisphere's silhouette warped by s = (1 + cos θ)/2), unstretch. The disk
    /// point comes from the concentric map, as in Mitsuba's `sample_visible_11`.
    #[inline]
    pub fn sample_visible_normal(&self, wi: Vec3, u: [f32; 2]) -> Vec3 {
        let vh = Vec3::new(self.alpha_x * wi.x, self.alpha_y * wi.y, wi.z).normalize();
        let length_squared = vh.x * vh.x + vh.y * vh.y;
        let t1 = if length_squared > 0.0 {
            Vec3::new(-vh.y, vh.x, 0.0) / length_squared.sqrt()
        } else {
            Vec3::X
        };
        let t2 = vh.cross(t1);
        let p = square_to_uniform_disk_concentric(u);
        let s = 0.5 * (1.0 + vh.z);
        let p1 = p.x;
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p.y;
        let nh = t1 * p1 + t2 * p2 + vh * (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
        Vec3::new(self.alpha_x * nh.x, self.alpha_y * nh.y, nh.z.max(0.0)).normalize()
    }
}

#[inline]
fn floor_alpha<T: BsdfScalar>(alpha: T) -> T {
    if alpha > MIN_ALPHA {
        alpha
    } else {
        T::from(MIN_ALPHA)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64Mcg;

    fn uniform_hemisphere(rng: &mut Pcg64Mcg) -> Vec3 {
        let z: f32 = rng.random();
        let phi = 2.0 * PI * rng.random::<f32>();
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }

    /// Mean and standard error of 2π · f(ω) over uniform hemisphere samples.
    fn hemisphere_integral(n: usize, seed: u64, f: impl Fn(Vec3) -> f64) -> (f64, f64) {
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let (mut sum, mut sum2) = (0.0, 0.0);
        for _ in 0..n {
            let x = 2.0 * std::f64::consts::PI * f(uniform_hemisphere(&mut rng));
            sum += x;
            sum2 += x * x;
        }
        let mean = sum / n as f64;
        (
            mean,
            ((sum2 / n as f64 - mean * mean) / (n - 1) as f64).sqrt(),
        )
    }

    #[test]
    fn distribution_and_visible_normals_are_normalised() {
        for (roughness, anisotropic) in [(0.5f32, 0.0f32), (0.7, 0.8), (1.0, 0.5)] {
            let ggx = Ggx::from_roughness(roughness, anisotropic);
            let (projected_area, se) = hemisphere_integral(400_000, 1, |m| (ggx.d(m) * m.z) as f64);
            assert!(
                (projected_area - 1.0).abs() < 4.0 * se,
                "{projected_area} ± {se}"
            );
            let wi = Vec3::new(0.5, -0.3, 0.6).normalize();
            let (visible, se) =
                hemisphere_integral(400_000, 2, |m| ggx.visible_normal_pdf(wi, m) as f64);
            assert!((visible - 1.0).abs() < 4.0 * se, "{visible} ± {se}");
        }
    }

    #[test]
    fn mapping_matches_mitsuba() {
        let g = Ggx::from_roughness(0.5f32, 0.0);
        assert_eq!((g.alpha_x, g.alpha_y), (0.25, 0.25));
        let g = Ggx::from_roughness(0.5f32, 1.0);
        let aspect = 0.1f32.sqrt();
        assert!(
            (g.alpha_x - 0.25 / aspect).abs() < 1e-6 && (g.alpha_y - 0.25 * aspect).abs() < 1e-6
        );
        let g = Ggx::from_roughness(0.01f32, 0.0);
        assert_eq!(g.alpha_x, MIN_ALPHA);
    }

    #[test]
    fn visible_normal_samples_follow_their_density() {
        // Compare the first two moments of m_x, m_y and m_z under sampling and under the density.
        let ggx = Ggx::from_roughness(0.6f32, 0.7);
        let wi = Vec3::new(-0.6, 0.2, 0.4).normalize();
        let n = 400_000;
        let mut rng = Pcg64Mcg::seed_from_u64(3);
        for component in 0..3 {
            let (mut sum, mut sum2) = (0.0f64, 0.0f64);
            for _ in 0..n {
                let m = ggx.sample_visible_normal(wi, [rng.random(), rng.random()]);
                assert!(m.z >= 0.0 && (m.length() - 1.0).abs() < 1e-5);
                let x = m[component] as f64;
                sum += x;
                sum2 += x * x;
            }
            let sampled = sum / n as f64;
            let se_sampled = ((sum2 / n as f64 - sampled * sampled) / n as f64).sqrt();
            let (integrated, se_integrated) = hemisphere_integral(n, 4 + component as u64, |m| {
                (ggx.visible_normal_pdf(wi, m) * m[component]) as f64
            });
            let combined = (se_sampled * se_sampled + se_integrated * se_integrated).sqrt();
            assert!(
                (sampled - integrated).abs() < 4.0 * combined,
                "component {component}: {sampled} vs {integrated} ± {combined}"
            );
        }
    }
}
