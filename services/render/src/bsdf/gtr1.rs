//! The GTR1 ("Berry") distribution of the clearcoat lobe, as Mitsuba's `GTR1Isotropic`
//! (Burley 2012, "Physically Based Shading at Disney", eq. 4 with γ = 1, and its App. B).

use glam::Vec3;
use std::f32::consts::PI;

use super::is_positive;
use super::params::BsdfScalar;

/// Isotropic GTR1 distribution D(m) = (α² − 1) / (π ln(α²) (1 + (α² − 1) cos²θ_m)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gtr1<T> {
    /// Width; Mitsuba's principled maps clearcoat_gloss ∈ [0, 1] to α ∈ [0.1, 0.001].
    pub alpha: T,
}

impl<T: BsdfScalar> Gtr1<T> {
    /// α = lerp(0.1, 0.001, clearcoat_gloss), Mitsuba's (and Burley's) mapping.
    #[inline]
    pub fn from_clearcoat_gloss(clearcoat_gloss: T) -> Self {
        Self {
            alpha: clearcoat_gloss * (0.001 - 0.1) + 0.1,
        }
    }

    /// D(m) for m above the horizon, else 0; ∫ D(m) cos θ_m dω_m = 1. The denominator's
    /// 1 + (α² − 1) cos²θ is evaluated as sin²θ + α² cos²θ (equal for unit m), which keeps f32
    /// digits at the narrow peak of a glossy coat (α² down to 1e-6). `m` must be unit length.
    #[inline]
    pub fn d(&self, m: Vec3) -> T {
        if !is_positive(m.z) {
            return T::from(0.0);
        }
        let alpha2 = self.alpha * self.alpha;
        let sin2 = m.x * m.x + m.y * m.y;
        (alpha2 - 1.0) / (alpha2.ln() * (alpha2 * (m.z * m.z) + sin2) * PI)
    }

    /// Density of [`Gtr1::sample`] over microfacet normals: D(m) cos θ_m.
    #[inline]
    pub fn pdf(&self, m: Vec3) -> T {
        self.d(m) * m.z
    }
}

impl Gtr1<f32> {
    /// Samples m with density D(m) cos θ_m (Burley 2012, App. B.2):
    /// φ = 2π u₀, cos²θ = (1 − α^{2(1 − u₁)}) / (1 − α²); Mitsuba's sample order.
    #[inline]
    pub fn sample(&self, u: [f32; 2]) -> Vec3 {
        let (sin_phi, cos_phi) = (2.0 * PI * u[0]).sin_cos();
        let alpha2 = self.alpha * self.alpha;
        // sin²θ = 1 − cos²θ computed directly, to keep digits near the peak.
        let sin2 = ((alpha2.powf(1.0 - u[1]) - alpha2) / (1.0 - alpha2)).clamp(0.0, 1.0);
        let sin = sin2.sqrt();
        let cos = (1.0 - sin2).sqrt();
        Vec3::new(cos_phi * sin, sin_phi * sin, cos)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// π ∫ D dt over t = sin²θ ∈ [t_lo, t_hi] (the measure: cos θ dω = π d(cos²θ) after the
    /// azimuth), trapezoid on a logarithmic grid that resolves the peak at t = 0.
    fn projected_mass(gtr1: &Gtr1<f32>, t_lo: f64, t_hi: f64) -> f64 {
        let n = 100_000;
        let (a, b) = (t_lo.max(1e-14).ln(), t_hi.ln());
        let density = |t: f64| {
            let m = Vec3::new(t.sqrt() as f32, 0.0, (1.0 - t).sqrt() as f32);
            std::f64::consts::PI * gtr1.d(m) as f64
        };
        let mut total = 0.0;
        let (mut t0, mut f0) = (a.exp(), density(a.exp()));
        for i in 1..=n {
            let t1 = (a + (b - a) * i as f64 / n as f64).exp();
            let f1 = density(t1);
            total += 0.5 * (f0 + f1) * (t1 - t0);
            (t0, f0) = (t1, f1);
        }
        total
    }

    #[test]
    fn gtr1_is_normalised_and_sampling_inverts_its_cdf() {
        for gloss in [0.0f32, 0.5, 1.0] {
            let gtr1 = Gtr1::from_clearcoat_gloss(gloss);
            let total = projected_mass(&gtr1, 0.0, 1.0);
            assert!((total - 1.0).abs() < 1e-3, "gloss {gloss}: {total}");
            // θ grows with u₁ (u₁ = 1 is grazing): P(sin²θ ≥ sin²θ(u₁)) = 1 − u₁.
            for u1 in [0.1f32, 0.5, 0.9] {
                let m = gtr1.sample([0.3, u1]);
                assert!((m.length() - 1.0).abs() < 1e-5);
                let sin2 = (m.x as f64).powi(2) + (m.y as f64).powi(2);
                let above = projected_mass(&gtr1, sin2, 1.0);
                assert!(
                    (above - (1.0 - u1 as f64)).abs() < 2e-3,
                    "gloss {gloss} u1 {u1}: {above}"
                );
            }
        }
    }
}
