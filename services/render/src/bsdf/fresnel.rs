//! Fresnel reflectance: the exact dielectric formula parameterised by Disney's `specular`, and
//! Schlick's approximation.

use super::params::BsdfScalar;

/// Normal-incidence reflectance per unit `specular`: F0 = 0.08 · specular (Burley 2012, §5.6),
/// so specular = 0.5 is F0 = 0.04, an IOR of 1.5.
pub const F0_PER_SPECULAR: f32 = 0.08;

/// Added to F0 under the square root in [`dielectric_from_specular`] so that the derivative with
/// respect to `specular` stays finite at specular = 0 (the square root's slope is infinite
/// there). It makes specular = 0 an IOR of 1 + 2e-10 instead of 1: F0 = 1e-20, and F stays
/// below 1e-12 unless cos θ < 1e-4 (where any IOR > 1 reflects everything).
const F0_FLOOR: f32 = 1e-20;

/// Schlick's weight (1 − cos θ)⁵, with cos θ clamped to [0, 1] (Mitsuba's `schlick_weight`).
#[inline]
pub fn schlick_weight(cos_theta: f32) -> f32 {
    let m = (1.0 - cos_theta).clamp(0.0, 1.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// Schlick's approximation F0 + (1 − F0)(1 − cos θ)⁵ (Schlick 1994), the form Mitsuba's
/// `calc_schlick` takes on the outside of a surface (relative IOR ≥ 1, always so here).
#[inline]
pub fn schlick<T: BsdfScalar>(f0: T, cos_theta: f32) -> T {
    let w = schlick_weight(cos_theta);
    f0 * (1.0 - w) + w
}

/// The relative IOR that Mitsuba derives from `specular`: η = 2 / (1 − √(0.08 · specular)) − 1,
/// the inverse of F0 = ((η − 1)/(η + 1))².
#[inline]
pub fn ior_from_specular(specular: f32) -> f32 {
    2.0 / (1.0 - (F0_PER_SPECULAR * specular).sqrt()) - 1.0
}

/// Exact unpolarised Fresnel reflectance of a dielectric seen from outside (Mitsuba's
/// `fresnel(cos θi, η)`, the one its principled BSDF uses for the dielectric specular), with
/// η = [`ior_from_specular`]`(specular)` and `cos_theta_i` ∈ [0, 1] taken on the microfacet.
///
/// Written in r = √F0 = (η − 1)/(η + 1) instead of η so that nothing cancels as η → 1
/// (specular → 0): with S = cos θt + cos θi and Δ = cos θt − cos θi = sin²θi · 4r/(1 + r)² / S,
/// the amplitude ratios are
///   r_s = −(Δ + r S)/(S + r Δ),  r_p = (Δ − r S)/(S − r Δ),  F = (r_s² + r_p²)/2,
/// algebraically identical to the textbook (cos θi − η cos θt)/(cos θi + η cos θt) and
/// (cos θt − η cos θi)/(cos θt + η cos θi). F is then smooth in `specular` down to 0 and so is its
/// derivative, where Mitsuba's η-based form loses all digits (and its lobe, at exactly 0).
#[inline]
pub fn dielectric_from_specular<T: BsdfScalar>(specular: T, cos_theta_i: f32) -> T {
    let r = (specular * F0_PER_SPECULAR + F0_FLOOR).sqrt();
    let one_plus_r = r + 1.0;
    // 1 − 1/η² = 4r/(1 + r)², so cos²θt = 1 − sin²θi/η² = cos²θi + sin²θi · 4r/(1 + r)².
    let k = r * 4.0 / (one_plus_r * one_plus_r);
    let cos_i = cos_theta_i.clamp(0.0, 1.0);
    let sin2_i = 1.0 - cos_i * cos_i;
    let cos_t = (k * sin2_i + cos_i * cos_i).sqrt();
    let sum = cos_t + cos_i;
    let diff = k * sin2_i / sum;
    let r_s = (diff + r * sum) / (sum + r * diff);
    let r_p = (diff - r * sum) / (sum - r * diff);
    (r_s * r_s + r_p * r_p) * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_dual::Dual32;

    /// Textbook Fresnel in f64 (e.g. Pharr et al., PBRT 4e, eq. 9.6).
    fn fresnel_reference(cos_i: f64, eta: f64) -> f64 {
        let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
        let cos_t = (1.0 - sin2_t).sqrt();
        let r_s = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
        let r_p = (cos_t - eta * cos_i) / (cos_t + eta * cos_i);
        0.5 * (r_s * r_s + r_p * r_p)
    }

    #[test]
    fn matches_textbook_fresnel_and_schlick_f0() {
        for specular in [0.05f32, 0.25, 0.5, 0.75, 1.0] {
            let eta = 2.0 / (1.0 - (0.08 * specular as f64).sqrt()) - 1.0;
            assert!((ior_from_specular(specular) as f64 - eta).abs() < 1e-5);
            // Normal incidence gives F0 = 0.08 · specular.
            let f0 = dielectric_from_specular(specular, 1.0);
            assert!((f0 - 0.08 * specular).abs() < 1e-6 * specular, "{f0}");
            for i in 0..=100 {
                let cos_i = i as f32 / 100.0;
                let ours = dielectric_from_specular(specular, cos_i) as f64;
                let reference = if i == 0 {
                    1.0
                } else {
                    fresnel_reference(cos_i as f64, eta)
                };
                assert!(
                    (ours - reference).abs() <= 2e-6 * reference.max(1e-3),
                    "specular {specular} cos {cos_i}: {ours} vs {reference}"
                );
            }
        }
    }

    #[test]
    fn derivative_is_finite_at_zero_specular() {
        // F = r² g(r) with r = √(0.08 s) and g smooth, so F(s)/s = a + b√s + O(s) and the
        // derivative at 0 is a = 2 F(h)/h − F(4h)/(4h) + O(h).
        // The expansion in r needs r ≪ cos²θ/4, hence the small step and no grazing angles.
        for cos_i in [1.0f32, 0.7, 0.4, 0.2] {
            let d = dielectric_from_specular(Dual32::new(0.0, 1.0), cos_i);
            let slope = |s: f32| (dielectric_from_specular(s, cos_i) / s) as f64;
            let h = 1e-8;
            let extrapolated = 2.0 * slope(h) - slope(4.0 * h);
            assert!(d.re < 1e-10);
            assert!(d.eps.is_finite() && d.eps > 0.0);
            let rel = (d.eps as f64 - extrapolated).abs() / extrapolated;
            assert!(rel < 1e-3, "cos {cos_i}: {} vs {extrapolated}", d.eps);
        }
    }

    #[test]
    fn schlick_endpoints() {
        assert_eq!(schlick(0.04f32, 1.0), 0.04);
        assert_eq!(schlick(0.04f32, 0.0), 1.0);
        assert_eq!(schlick_weight(1.5), 0.0);
        assert_eq!(schlick_weight(-0.5), 1.0);
    }
}
