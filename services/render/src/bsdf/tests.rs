//! Whole-BSDF tests: Mitsuba reference values, energy, reciprocity, sampling against eval/pdf,
//! dual-number gradients against finite differences, and limits. Monte Carlo tolerances are
//! multiples of the estimated standard error; every RNG is seeded.

use super::*;
use num_dual::Dual32;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use std::f64::consts::PI;

// ---------------------------------------------------------------------------------------------
// Helpers

fn rng(seed: u64) -> Pcg64Mcg {
    Pcg64Mcg::seed_from_u64(seed)
}

/// Unit direction from polar angle θ (degrees from the normal) and azimuth φ (degrees).
fn direction(theta_deg: f32, phi_deg: f32) -> Vec3 {
    let (st, ct) = theta_deg.to_radians().sin_cos();
    let (sp, cp) = phi_deg.to_radians().sin_cos();
    Vec3::new(st * cp, st * sp, ct)
}

fn uniform_hemisphere(rng: &mut Pcg64Mcg) -> Vec3 {
    let z: f32 = rng.random();
    let phi = 2.0 * std::f32::consts::PI * rng.random::<f32>();
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

fn random_params(rng: &mut Pcg64Mcg) -> PrincipledParams<f32> {
    PrincipledParams::from_array(std::array::from_fn(|_| rng.random()))
}

/// A running mean with its standard error.
#[derive(Default)]
struct Estimate {
    n: u64,
    sum: f64,
    sum2: f64,
}

impl Estimate {
    fn push(&mut self, x: f64) {
        self.n += 1;
        self.sum += x;
        self.sum2 += x * x;
    }
    fn mean(&self) -> f64 {
        self.sum / self.n as f64
    }
    fn standard_error(&self) -> f64 {
        let n = self.n as f64;
        ((self.sum2 / n - self.mean().powi(2)).max(0.0) / (n - 1.0)).sqrt()
    }
}

/// Directional albedo ∫ eval dωo as E[weight] under the BSDF's own sampling (lost samples
/// count as 0).
fn albedo_by_sampling(
    p: &PrincipledParams<f32>,
    wi: Vec3,
    n: usize,
    rng: &mut Pcg64Mcg,
) -> Estimate {
    let mut e = Estimate::default();
    for _ in 0..n {
        let s = sample(p, wi, rng.random(), [rng.random(), rng.random()]);
        e.push(s.map_or(0.0, |s| s.weight as f64));
    }
    e
}

/// Directional albedo ∫ eval dωo as E[2π eval] under uniform hemisphere sampling.
fn albedo_by_uniform_sampling(
    p: &PrincipledParams<f32>,
    wi: Vec3,
    n: usize,
    rng: &mut Pcg64Mcg,
) -> Estimate {
    let mut e = Estimate::default();
    for _ in 0..n {
        e.push(2.0 * PI * eval(p, wi, uniform_hemisphere(rng)) as f64);
    }
    e
}

/// Upper tail probability of χ² with `dof` degrees of freedom, by the Wilson–Hilferty cube-root
/// normal approximation (accurate to a few 1e-3 in p for dof ≳ 30).
fn chi2_p_value(chi2: f64, dof: usize) -> f64 {
    let k = dof as f64;
    let z = ((chi2 / k).cbrt() - (1.0 - 2.0 / (9.0 * k))) / (2.0 / (9.0 * k)).sqrt();
    0.5 * erfc(z / std::f64::consts::SQRT_2)
}

/// Complementary error function (Numerical Recipes' erfcc, relative error < 1.2e-7).
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let r = t
        * (-z * z - 1.265_512_23
            + t * (1.000_023_68
                + t * (0.374_091_96
                    + t * (0.096_784_18
                        + t * (-0.186_288_06
                            + t * (0.278_868_07
                                + t * (-1.135_203_98
                                    + t * (1.488_515_87
                                        + t * (-0.822_152_23 + t * 0.170_872_77)))))))))
            .exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

/// ∫ pdf over each (cos θ, φ) bin of the hemisphere (dω = d cos θ dφ), midpoint rule on
/// `sub × sub` points per bin. Returns row-major [cos bin][φ bin].
fn integrate_pdf_over_bins(
    p: &PrincipledParams<f32>,
    wi: Vec3,
    n_cos: usize,
    n_phi: usize,
    sub: usize,
) -> Vec<f64> {
    let d_cos = 1.0 / (n_cos * sub) as f64;
    let d_phi = 2.0 * PI / (n_phi * sub) as f64;
    let mut bins = vec![0.0; n_cos * n_phi];
    for i in 0..n_cos * sub {
        let z = (i as f64 + 0.5) * d_cos;
        let r = (1.0 - z * z).sqrt();
        for j in 0..n_phi * sub {
            let phi = (j as f64 + 0.5) * d_phi;
            let wo = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
            bins[(i / sub) * n_phi + j / sub] += pdf(p, wi, wo) as f64 * d_cos * d_phi;
        }
    }
    bins
}

fn bin_of(wo: Vec3, n_cos: usize, n_phi: usize) -> usize {
    let i = ((wo.z as f64 * n_cos as f64) as usize).min(n_cos - 1);
    let phi = (wo.y as f64).atan2(wo.x as f64).rem_euclid(2.0 * PI);
    let j = ((phi / (2.0 * PI) * n_phi as f64) as usize).min(n_phi - 1);
    i * n_phi + j
}

// ---------------------------------------------------------------------------------------------
// Mitsuba 3 reference values

/// Five parameter sets in the order of `PrincipledParams::NAMES`.
const MITSUBA_CONFIGS: [[f32; 10]; 5] = [
    [0.8, 1.0, 0.3, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.5, 0.0, 0.5, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.6, 0.4, 0.7, 0.9, 0.0, 0.6, 0.0, 0.0, 0.0, 0.0],
    [0.3, 0.2, 0.45, 0.3, 0.7, 0.0, 0.8, 0.0, 0.6, 0.4],
    [0.9, 0.7, 0.15, 0.6, 0.0, 0.3, 0.0, 0.0, 1.0, 0.9],
];

/// (config index, wi, wo, eval, pdf).
type ReferenceRow = (usize, [f32; 3], [f32; 3], f32, f32);

/// Rows printed by Mitsuba 3.9.1 (PyPI), variant `scalar_rgb`: per config,
/// `bsdf = mi.load_dict({'type': 'principled', 'base_color': {'type': 'rgb', 'value': [c, c, c]},
/// …})`, then with `si = mi.SurfaceInteraction3f()`, `si.wi = wi`,
/// `si.sh_frame = mi.Frame3f([0, 0, 1])`: `bsdf.eval(mi.BSDFContext(), si, wo)[0]` and
/// `bsdf.pdf(mi.BSDFContext(), si, wo)`. Three fixed direction pairs and five random ones.
#[rustfmt::skip]
#[allow(clippy::excessive_precision)] // printed by Mitsuba with 8 significant digits
const MITSUBA_REFERENCE: [ReferenceRow; 40] = [
    (0, [0.0000000, 0.0000000, 1.0000000], [0.0000000, 0.0000000, 1.0000000], 7.8595033e+00, 9.8243790e+00),
    (0, [0.6000000, 0.0000000, 0.8000000], [-0.6000000, 0.0000000, 0.8000000], 9.8028469e+00, 1.2266518e+01),
    (0, [0.6000000, 0.0000000, 0.8000000], [-0.5000000, 0.1000000, 0.8602325], 2.7683120e+00, 3.4627385e+00),
    (0, [0.5448698, 0.7584258, 0.3576411], [0.6680956, 0.3269651, 0.6683877], 2.7528289e-03, 3.4496440e-03),
    (0, [-0.5509861, 0.6195442, 0.5590879], [-0.9933766, -0.0464444, 0.1050990], 1.0701122e-03, 1.5472904e-03),
    (0, [-0.9109843, 0.4034559, 0.0856209], [0.8361996, 0.5359383, 0.1163627], 4.8023425e-03, 6.7235450e-03),
    (0, [0.4138844, -0.7894460, 0.4532932], [0.1649858, 0.9719496, 0.1676119], 4.4250144e-03, 5.8105863e-03),
    (0, [0.7224570, -0.2462932, 0.6460616], [-0.6383103, 0.4844166, 0.5982478], 3.5436577e-01, 4.4384021e-01),
    (1, [0.0000000, 0.0000000, 1.0000000], [0.0000000, 0.0000000, 1.0000000], 2.1008453e-01, 7.9577470e-01),
    (1, [0.6000000, 0.0000000, 0.8000000], [-0.6000000, 0.0000000, 0.8000000], 1.9599432e-01, 9.1622484e-01),
    (1, [0.6000000, 0.0000000, 0.8000000], [-0.5000000, 0.1000000, 0.8602325], 1.9127604e-01, 7.7945030e-01),
    (1, [0.5448698, 0.7584258, 0.3576411], [0.6680956, 0.3269651, 0.6683877], 1.1244522e-01, 1.1816007e-01),
    (1, [-0.5509861, 0.6195442, 0.5590879], [-0.9933766, -0.0464444, 0.1050990], 1.9854264e-02, 2.2428822e-02),
    (1, [-0.9109843, 0.4034559, 0.0856209], [0.8361996, 0.5359383, 0.1163627], 1.4896801e-02, 3.4020633e-02),
    (1, [0.4138844, -0.7894460, 0.4532932], [0.1649858, 0.9719496, 0.1676119], 2.6169116e-02, 4.5823693e-02),
    (1, [0.7224570, -0.2462932, 0.6460616], [-0.6383103, 0.4844166, 0.5982478], 1.3856702e-01, 4.7517058e-01),
    (2, [0.0000000, 0.0000000, 1.0000000], [0.0000000, 0.0000000, 1.0000000], 2.0845389e-01, 3.2651290e-01),
    (2, [0.6000000, 0.0000000, 0.8000000], [-0.6000000, 0.0000000, 0.8000000], 1.9544895e-01, 3.3778507e-01),
    (2, [0.6000000, 0.0000000, 0.8000000], [-0.5000000, 0.1000000, 0.8602325], 1.9804111e-01, 3.3004594e-01),
    (2, [0.5448698, 0.7584258, 0.3576411], [0.6680956, 0.3269651, 0.6683877], 9.4991542e-02, 1.0817584e-01),
    (2, [-0.5509861, 0.6195442, 0.5590879], [-0.9933766, -0.0464444, 0.1050990], 2.2211550e-02, 6.3244440e-02),
    (2, [-0.9109843, 0.4034559, 0.0856209], [0.8361996, 0.5359383, 0.1163627], 1.1885906e-02, 2.1136731e-02),
    (2, [0.4138844, -0.7894460, 0.4532932], [0.1649858, 0.9719496, 0.1676119], 5.9008952e-02, 1.4619923e-01),
    (2, [0.7224570, -0.2462932, 0.6460616], [-0.6383103, 0.4844166, 0.5982478], 1.3866092e-01, 2.4025494e-01),
    (3, [0.0000000, 0.0000000, 1.0000000], [0.0000000, 0.0000000, 1.0000000], 3.2301018e-01, 1.4235942e+00),
    (3, [0.6000000, 0.0000000, 0.8000000], [-0.6000000, 0.0000000, 0.8000000], 3.2711631e-01, 1.7136360e+00),
    (3, [0.6000000, 0.0000000, 0.8000000], [-0.5000000, 0.1000000, 0.8602325], 2.3283032e-01, 1.1383051e+00),
    (3, [0.5448698, 0.7584258, 0.3576411], [0.6680956, 0.3269651, 0.6683877], 5.4540463e-02, 9.6425377e-02),
    (3, [-0.5509861, 0.6195442, 0.5590879], [-0.9933766, -0.0464444, 0.1050990], 9.4334353e-03, 1.8162183e-02),
    (3, [-0.9109843, 0.4034559, 0.0856209], [0.8361996, 0.5359383, 0.1163627], 1.0715123e-02, 2.7657440e-02),
    (3, [0.4138844, -0.7894460, 0.4532932], [0.1649858, 0.9719496, 0.1676119], 2.0162329e-02, 3.9228857e-02),
    (3, [0.7224570, -0.2462932, 0.6460616], [-0.6383103, 0.4844166, 0.5982478], 1.2183115e-01, 5.2684385e-01),
    (4, [0.0000000, 0.0000000, 1.0000000], [0.0000000, 0.0000000, 1.0000000], 1.0434362e+02, 1.1342784e+02),
    (4, [0.6000000, 0.0000000, 0.8000000], [-0.6000000, 0.0000000, 0.8000000], 1.2925932e+02, 1.4174471e+02),
    (4, [0.6000000, 0.0000000, 0.8000000], [-0.5000000, 0.1000000, 0.8602325], 6.1418498e-01, 7.8426361e-01),
    (4, [0.5448698, 0.7584258, 0.3576411], [0.6680956, 0.3269651, 0.6683877], 5.6428567e-02, 4.2415757e-02),
    (4, [-0.5509861, 0.6195442, 0.5590879], [-0.9933766, -0.0464444, 0.1050990], 7.7515580e-03, 7.2664190e-03),
    (4, [-0.9109843, 0.4034559, 0.0856209], [0.8361996, 0.5359383, 0.1163627], 5.7703401e-03, 7.9891449e-03),
    (4, [0.4138844, -0.7894460, 0.4532932], [0.1649858, 0.9719496, 0.1676119], 1.2193287e-02, 1.5498334e-02),
    (4, [0.7224570, -0.2462932, 0.6460616], [-0.6383103, 0.4844166, 0.5982478], 7.2025336e-02, 1.0704582e-01),
];

#[test]
fn matches_mitsuba_reference_values() {
    let mut worst = (0.0f32, 0.0f32);
    for (config, wi, wo, mitsuba_eval, mitsuba_pdf) in MITSUBA_REFERENCE {
        let p = PrincipledParams::from_array(MITSUBA_CONFIGS[config])
            .validated()
            .unwrap();
        // The printed directions carry 7 decimals; renormalising moves them by ~1e-7.
        let (wi, wo) = (Vec3::from(wi).normalize(), Vec3::from(wo).normalize());
        let (ours_eval, ours_pdf) = eval_and_pdf(&p, wi, wo);
        let rel_eval = (ours_eval - mitsuba_eval).abs() / mitsuba_eval;
        let rel_pdf = (ours_pdf - mitsuba_pdf).abs() / mitsuba_pdf;
        worst = (worst.0.max(rel_eval), worst.1.max(rel_pdf));
        assert!(
            rel_eval < 1e-4 && rel_pdf < 1e-4,
            "config {config} wi {wi} wo {wo}: eval {ours_eval} vs {mitsuba_eval}, pdf {ours_pdf} vs {mitsuba_pdf}"
        );
    }
    eprintln!(
        "Mitsuba reference: worst relative error eval {:.2e}, pdf {:.2e}",
        worst.0, worst.1
    );
}

// ---------------------------------------------------------------------------------------------
// 1. White furnace

/// White furnace: directional albedo with base_color = 1 over a grid of (metallic, roughness,
/// specular, anisotropic, θi), by E[weight] under the BSDF's own sampling.
///
/// Only the metal is energy conserving in Mitsuba's model, and the test holds it to
/// albedo ≤ 1 + 3σ: Schlick(1, ·) = 1 and separable-Smith GGX only loses energy. With a
/// dielectric part the model is not: its diffuse lobe has no (1 − F) coupling to the specular
/// one, and Burley's retro-reflection raises it above base_color (+3.6 % at normal incidence,
/// more at grazing). Those albedos are reported and held to the maxima measured at this seed
/// (1.12 up to θi = 60°, 1.56 at 88°) plus 4σ, a regression bound, not physics.
#[test]
fn white_furnace() {
    let n = 20_000;
    let mut rng = rng(11);
    // (albedo, standard error, label) maxima: metal; dielectric part up to 60°; beyond 60°.
    let mut maxima = [
        (0.0f64, 0.0f64, String::new()),
        (0.0, 0.0, String::new()),
        (0.0, 0.0, String::new()),
    ];
    for metallic in [0.0f32, 0.5, 1.0] {
        for roughness in [0.05f32, 0.3, 0.6, 1.0] {
            for specular in [0.0f32, 0.5, 1.0] {
                for anisotropic in [0.0f32, 0.9] {
                    for theta in [0.0f32, 30.0, 60.0, 80.0, 88.0] {
                        let p = PrincipledParams {
                            base_color: 1.0,
                            metallic,
                            roughness,
                            specular,
                            anisotropic,
                            ..PrincipledParams::default()
                        };
                        let e = albedo_by_sampling(&p, direction(theta, 20.0), n, &mut rng);
                        let (albedo, sigma) = (e.mean(), e.standard_error());
                        let label = format!(
                            "metallic {metallic} roughness {roughness} specular {specular} anisotropic {anisotropic} θi {theta}°"
                        );
                        // 1e-5: f32 rounding of weights that are exactly F · G1 ≤ 1 for the metal.
                        let (class, limit) = match (metallic == 1.0, theta <= 60.0) {
                            (true, _) => (0, 1.0 + 3.0 * sigma + 1e-5),
                            (false, true) => (1, 1.12 + 4.0 * sigma),
                            (false, false) => (2, 1.56 + 4.0 * sigma),
                        };
                        assert!(albedo <= limit, "{label}: {albedo} ± {sigma}");
                        if albedo > maxima[class].0 {
                            maxima[class] = (albedo, sigma, label);
                        }
                    }
                }
            }
        }
    }
    for ((albedo, sigma, label), what) in maxima.iter().zip([
        "metal",
        "dielectric part, θi ≤ 60°",
        "dielectric part, θi > 60°",
    ]) {
        eprintln!("furnace, {what}: max albedo {albedo:.4} ± {sigma:.4} at {label}");
    }
}

// ---------------------------------------------------------------------------------------------
// 2. Reciprocity

#[test]
fn reciprocity() {
    let mut rng = rng(12);
    let mut worst = 0.0f32;
    for _ in 0..20_000 {
        let p = random_params(&mut rng);
        let (wi, wo) = (uniform_hemisphere(&mut rng), uniform_hemisphere(&mut rng));
        if wi.z < 1e-3 || wo.z < 1e-3 {
            continue;
        }
        let forward = eval(&p, wi, wo) / wo.z;
        let backward = eval(&p, wo, wi) / wi.z;
        let rel = (forward - backward).abs() / forward.abs().max(1e-30);
        worst = worst.max(rel);
        assert!(
            rel <= 1e-4,
            "{p:?} wi {wi} wo {wo}: {forward} vs {backward}"
        );
    }
    eprintln!("reciprocity: worst relative difference {worst:.2e}");
}

// ---------------------------------------------------------------------------------------------
// 3. Sampling agrees with eval and pdf

/// Configurations for the sampling tests: glossy enough to exercise the specular sampler,
/// rough enough for uniform sampling and bin integration to resolve the lobes.
fn sampling_configs() -> Vec<(PrincipledParams<f32>, Vec3)> {
    let p = |base_color, metallic, roughness, specular| {
        PrincipledParams::new(base_color, metallic, roughness, specular).unwrap()
    };
    vec![
        (p(0.5, 0.0, 0.5, 0.5), direction(30.0, 10.0)),
        (p(0.8, 1.0, 0.3, 0.5), direction(50.0, 200.0)),
        (p(0.7, 1.0, 0.6, 0.5), direction(80.0, 0.0)),
        (
            PrincipledParams {
                anisotropic: 0.8,
                ..p(0.6, 0.5, 0.4, 0.8)
            },
            direction(65.0, 45.0),
        ),
        (
            PrincipledParams {
                sheen: 1.0,
                clearcoat: 1.0,
                clearcoat_gloss: 0.0,
                spec_tint: 0.5,
                ..p(0.4, 0.3, 0.6, 0.5)
            },
            direction(40.0, 300.0),
        ),
    ]
}

#[test]
fn sampling_weight_matches_uniform_integral() {
    for (k, (p, wi)) in sampling_configs().into_iter().enumerate() {
        let by_bsdf = albedo_by_sampling(&p, wi, 200_000, &mut rng(100 + k as u64));
        let by_uniform = albedo_by_uniform_sampling(&p, wi, 1_000_000, &mut rng(200 + k as u64));
        let sigma = (by_bsdf.standard_error().powi(2) + by_uniform.standard_error().powi(2)).sqrt();
        let z = (by_bsdf.mean() - by_uniform.mean()) / sigma;
        eprintln!(
            "config {k}: E[weight] {:.5} ± {:.5}, uniform {:.5} ± {:.5}, z {z:+.2}",
            by_bsdf.mean(),
            by_bsdf.standard_error(),
            by_uniform.mean(),
            by_uniform.standard_error()
        );
        assert!(z.abs() < 4.0, "config {k}: z = {z}");
    }
}

#[test]
fn sampled_directions_match_pdf_histogram() {
    let (n_cos, n_phi) = (12, 24);
    let n = 300_000usize;
    for (k, (p, wi)) in sampling_configs().into_iter().enumerate() {
        let expected_mass = integrate_pdf_over_bins(&p, wi, n_cos, n_phi, 16);
        let mut counts = vec![0u64; n_cos * n_phi];
        let mut lost = 0u64;
        let mut rng = rng(300 + k as u64);
        for _ in 0..n {
            match sample(&p, wi, rng.random(), [rng.random(), rng.random()]) {
                Some(s) => {
                    // The sample's own density and weight are pdf() and eval()/pdf().
                    let (value, density) = eval_and_pdf(&p, wi, s.wo);
                    assert!(
                        (s.pdf - density).abs() <= 1e-6 * density
                            && (s.weight - value / density).abs() <= 1e-5 * s.weight.max(1e-6)
                    );
                    counts[bin_of(s.wo, n_cos, n_phi)] += 1;
                }
                None => lost += 1,
            }
        }
        // Bins with an expectation below 5 are pooled, and the lost samples (below the horizon)
        // form one more bin whose expectation is the pdf mass missing from the hemisphere.
        let total_mass: f64 = expected_mass.iter().sum();
        let mut cells = vec![(lost as f64, n as f64 * (1.0 - total_mass))];
        let mut pooled = (0.0, 0.0);
        for (count, mass) in counts.iter().zip(&expected_mass) {
            let expected = mass * n as f64;
            if expected < 5.0 {
                pooled = (pooled.0 + *count as f64, pooled.1 + expected);
            } else {
                cells.push((*count as f64, expected));
            }
        }
        cells.push(pooled);
        cells.retain(|&(_, expected)| expected >= 5.0);
        let chi2: f64 = cells.iter().map(|(o, e)| (o - e).powi(2) / e).sum();
        let dof = cells.len() - 1;
        let p_value = chi2_p_value(chi2, dof);
        eprintln!(
            "config {k}: χ² = {chi2:.1} for {dof} dof, p = {p_value:.3}, ∫pdf = {total_mass:.5}, lost {lost}"
        );
        assert!(
            p_value > 1e-3,
            "config {k}: χ² = {chi2} for {dof} dof, p = {p_value}"
        );
    }
}

#[test]
fn pdf_integrates_to_one_minus_lost_samples() {
    for (k, (p, wi)) in sampling_configs().into_iter().enumerate() {
        let mass: f64 = integrate_pdf_over_bins(&p, wi, 64, 128, 8).iter().sum();
        let n = 200_000;
        let mut rng = rng(400 + k as u64);
        let lost = (0..n)
            .filter(|_| sample(&p, wi, rng.random(), [rng.random(), rng.random()]).is_none())
            .count();
        let lost_fraction = lost as f64 / n as f64;
        let sigma = (lost_fraction * (1.0 - lost_fraction) / n as f64)
            .sqrt()
            .max(1.0 / n as f64);
        eprintln!(
            "config {k}: ∫pdf = {mass:.5}, 1 − lost = {:.5} ± {sigma:.5}",
            1.0 - lost_fraction
        );
        assert!(mass <= 1.0 + 2e-3, "config {k}: ∫pdf = {mass}");
        assert!(
            (mass - (1.0 - lost_fraction)).abs() < 4.0 * sigma + 2e-3,
            "config {k}: {mass} vs {}",
            1.0 - lost_fraction
        );
    }
    // Normal incidence on a metal: the visible-normal density is D(m) cos θ_m, and a reflection
    // leaves the hemisphere iff θ_m > 45°, which GGX gives probability α²/(1 + α²)
    // (P(tan²θ_m ≤ x) = x/(α² + x)). So ∫pdf = 1/(1 + α²) exactly.
    for roughness in [0.5f32, 0.7, 0.9] {
        let p = PrincipledParams::new(0.5, 1.0, roughness, 0.5).unwrap();
        let alpha2 = (roughness as f64).powi(4);
        let mass: f64 = integrate_pdf_over_bins(&p, Vec3::Z, 64, 128, 8)
            .iter()
            .sum();
        eprintln!(
            "normal incidence, roughness {roughness}: ∫pdf = {mass:.5}, 1/(1 + α²) = {:.5}",
            1.0 / (1.0 + alpha2)
        );
        assert!(
            (mass - 1.0 / (1.0 + alpha2)).abs() < 2e-3,
            "roughness {roughness}: ∫pdf = {mass}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// 4. Gradients

/// Checks ∂eval/∂param from `Dual32` against central differences with step h, per parameter
/// index in `params`. The tolerance is what the difference quotient itself can promise:
/// its truncation error, estimated as |D(h) − D(2h)| (≈ 3× the O(h²) error of D(h)), plus the
/// f32 rounding error 8 ε |f| / h.
/// Returns the worst |dual − fd| / tolerance and the worst relative error among derivatives
/// that are not negligible (|∂f| > 1 % of |f|/h·h, i.e. > 0.01 |f|).
fn check_gradient(
    p: PrincipledParams<f32>,
    wi: Vec3,
    wo: Vec3,
    params: &[usize],
    h: f32,
) -> (f32, f32) {
    let mut worst = (0.0f32, 0.0f32);
    for &k in params {
        let mut lifted = p.map(Dual32::from_re).to_array();
        lifted[k].eps = 1.0;
        let dual = eval(&PrincipledParams::from_array(lifted), wi, wo);
        let at = |delta: f32| {
            let mut q = p.to_array();
            q[k] += delta;
            eval(&PrincipledParams::from_array(q), wi, wo)
        };
        let fd = |h: f32| (at(h) - at(-h)) / (2.0 * h);
        let (fd_h, fd_2h) = (fd(h), fd(2.0 * h));
        let tolerance = (fd_h - fd_2h).abs() + 8.0 * f32::EPSILON * dual.re.abs() / h + 1e-7;
        let name = PrincipledParams::<f32>::NAMES[k];
        assert_eq!(dual.re, eval(&p, wi, wo));
        assert!(
            (dual.eps - fd_h).abs() <= tolerance,
            "{name} at {p:?}, wi {wi}, wo {wo}: dual {} vs fd {fd_h} (fd 2h {fd_2h}, tol {tolerance})",
            dual.eps
        );
        worst.0 = worst.0.max((dual.eps - fd_h).abs() / tolerance);
        if dual.eps.abs() > 0.01 * dual.re.abs() {
            worst.1 = worst.1.max((dual.eps - fd_h).abs() / dual.eps.abs());
        }
    }
    worst
}

#[test]
fn dual_gradients_match_finite_differences() {
    let configs = [
        PrincipledParams::new(0.5, 0.5, 0.5, 0.5).unwrap(),
        PrincipledParams::new(0.8, 0.9, 0.2, 0.3).unwrap(),
        PrincipledParams::new(0.3, 0.1, 0.8, 0.7).unwrap(),
        PrincipledParams {
            spec_tint: 0.4,
            anisotropic: 0.5,
            sheen: 0.6,
            sheen_tint: 0.5,
            clearcoat: 0.7,
            clearcoat_gloss: 0.3,
            ..PrincipledParams::new(0.6, 0.4, 0.35, 0.6).unwrap()
        },
    ];
    let directions = [
        (direction(30.0, 0.0), direction(30.0, 180.0)), // mirror configuration
        (direction(45.0, 10.0), direction(20.0, 150.0)),
        (direction(70.0, 80.0), direction(60.0, 300.0)),
        (direction(5.0, 0.0), direction(75.0, 90.0)),
    ];
    let all: Vec<usize> = (0..PARAMETER_COUNT).collect();
    let mut worst = (0.0f32, 0.0f32);
    for p in configs {
        for (wi, wo) in directions {
            let (of_tolerance, relative) = check_gradient(p, wi, wo, &all, 2e-3);
            worst = (worst.0.max(of_tolerance), worst.1.max(relative));
        }
    }
    eprintln!(
        "gradients: worst |dual − fd| = {:.2} × tolerance; worst relative error {:.2e}",
        worst.0, worst.1
    );
}

#[test]
fn gradients_do_not_vanish_at_zero_parameters() {
    // Mitsuba switches lobes off at exactly 0; here metallic, specular, spec_tint, anisotropic,
    // sheen and clearcoat at 0 still have derivatives. Smooth parameters are checked against the
    // one-sided second-order difference D(h) = (−3 f(0) + 4 f(h) − f(2h)) / 2h, error O(h²)
    // estimated by |D(h) − D(2h)|. The dielectric Fresnel is r² g(r) in r = √(0.08 specular),
    // so f has a specular^{3/2} term: there D(h) = (f(h) − f(0))/h = a + b√h + O(h), and
    // a ≈ 2 D(h) − D(4h), with error O(h) estimated by comparing with the same at 4h.
    // metallic and specular at 0 together (the specular lobe then has F = 0); the others at 0
    // on a material whose specular lobe is alive, so that spec_tint and anisotropy matter.
    let both_zero = PrincipledParams::new(0.6, 0.0, 0.4, 0.0).unwrap();
    let lobes_off = PrincipledParams {
        clearcoat_gloss: 0.5,
        ..PrincipledParams::new(0.6, 0.3, 0.4, 0.5).unwrap()
    };
    // h is off both tangent axes, so anisotropy changes D to first order.
    let (wi, wo) = (direction(70.0, 0.0), direction(65.0, 120.0));
    let specular = 3;
    for (k, p) in [
        (1usize, both_zero),
        (specular, both_zero),
        (4, lobes_off),
        (5, lobes_off),
        (6, lobes_off),
        (8, lobes_off),
    ] {
        let mut lifted = p.map(Dual32::from_re).to_array();
        lifted[k].eps = 1.0;
        let dual = eval(&PrincipledParams::from_array(lifted), wi, wo).eps;
        let at = |delta: f32| {
            let mut q = p.to_array();
            q[k] += delta;
            eval(&PrincipledParams::from_array(q), wi, wo) as f64
        };
        let h = if k == specular { 1e-3f32 } else { 1e-2 };
        let rounding = 16.0 * f32::EPSILON as f64 * at(0.0) / h as f64 + 1e-6;
        let (estimate, truncation) = if k == specular {
            let forward = |h: f32| (at(h) - at(0.0)) / h as f64;
            let extrapolated = |h: f32| 2.0 * forward(h) - forward(4.0 * h);
            (
                extrapolated(h),
                (extrapolated(h) - extrapolated(4.0 * h)).abs(),
            )
        } else {
            let one_sided =
                |h: f32| (-3.0 * at(0.0) + 4.0 * at(h) - at(2.0 * h)) / (2.0 * h as f64);
            (one_sided(h), (one_sided(h) - one_sided(2.0 * h)).abs())
        };
        let name = PrincipledParams::<f32>::NAMES[k];
        assert!(dual.is_finite() && dual.abs() > 1e-6, "{name}: {dual}");
        let tolerance = truncation + rounding;
        eprintln!(
            "∂eval/∂{name} at 0: dual {dual:.6}, difference {estimate:.6} (tolerance {tolerance:.1e})"
        );
        assert!(
            (dual as f64 - estimate).abs() <= tolerance,
            "{name}: dual {dual} vs {estimate} (tol {tolerance})"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// 5. Limits

#[test]
fn metal_does_not_depend_on_specular_even_at_zero() {
    // Mitsuba 3.9.1 renders this metal black at specular = 0 exactly (its η = 1 switches the
    // whole specular lobe off) and 9.80285 for any specular > 0; ours is 9.80285 throughout.
    let (wi, wo) = (Vec3::new(0.6, 0.0, 0.8), Vec3::new(-0.6, 0.0, 0.8));
    for specular in [0.0f32, 1e-3, 0.5, 1.0] {
        let p = PrincipledParams::new(0.8, 1.0, 0.3, specular).unwrap();
        let value = eval(&p, wi, wo);
        assert!(
            (value - 9.80285).abs() < 1e-4 * 9.80285,
            "specular {specular}: {value}"
        );
    }
}

#[test]
fn smooth_metal_is_a_sharp_mirror() {
    let p = PrincipledParams::new(0.9, 1.0, 0.05, 0.5).unwrap(); // α = 0.0025
    let wi = direction(40.0, 30.0);
    let mirror = Vec3::new(-wi.x, -wi.y, wi.z);
    let off_peak = direction(45.0, 210.0); // 5° from the mirror direction
    let ratio = eval(&p, wi, mirror) / eval(&p, wi, off_peak);
    let n = 50_000;
    let mut rng = rng(500);
    let mut within_1deg = 0;
    let mut within_5deg = 0;
    let mut energy = Estimate::default();
    for _ in 0..n {
        let s = sample(&p, wi, rng.random(), [rng.random(), rng.random()]);
        energy.push(s.map_or(0.0, |s| s.weight as f64));
        if let Some(s) = s {
            let angle = s.wo.dot(mirror).clamp(-1.0, 1.0).acos().to_degrees();
            within_1deg += (angle < 1.0) as usize;
            within_5deg += (angle < 5.0) as usize;
        }
    }
    let (f1, f5) = (within_1deg as f64 / n as f64, within_5deg as f64 / n as f64);
    // Metal reflects F = Schlick(base_color, cos θ) with G ≈ 1 at this width.
    let fresnel_at_mirror = fresnel::schlick(0.9f32, 40f32.to_radians().cos()) as f64;
    eprintln!(
        "mirror: eval ratio peak/5° = {ratio:.3e}, within 1°: {f1:.4}, within 5°: {f5:.4}, albedo {:.4} ± {:.4} vs F {fresnel_at_mirror:.4}",
        energy.mean(),
        energy.standard_error()
    );
    // GGX: P(θ_m > t) = α²/(α² + tan²t); θ_m < 0.5° ⇔ wo within 1°: 92 %; within 5°: 99.7 %.
    assert!(ratio > 1e4, "{ratio}");
    assert!(f1 > 0.9 && f5 > 0.99, "{f1} {f5}");
    assert!((energy.mean() - fresnel_at_mirror).abs() < 5e-3 + 4.0 * energy.standard_error());
}

#[test]
fn rough_dielectric_without_specular_is_nearly_lambertian() {
    let base_color = 0.6f32;
    let p = PrincipledParams::new(base_color, 0.0, 1.0, 0.0).unwrap();
    let lambert = |wo: Vec3| base_color * std::f32::consts::FRAC_1_PI * wo.z;
    // Exactly Lambertian at normal incidence and exitance (both Schlick weights are 0).
    assert!((eval(&p, Vec3::Z, Vec3::Z) - lambert(Vec3::Z)).abs() < 1e-6);
    // Within 45° of the normal the Schlick weights are ≤ (1 − cos 45°)⁵ = 0.0022, so the diffuse
    // factor f_diff + f_retro stays within ±0.01 of 1 whatever the retro-reflection does.
    let mut worst = 0.0f32;
    for theta_i in [0.0f32, 15.0, 30.0, 45.0] {
        for theta_o in [0.0f32, 20.0, 45.0] {
            for phi in [0.0f32, 90.0, 180.0] {
                let (wi, wo) = (direction(theta_i, 0.0), direction(theta_o, phi));
                let rel = eval(&p, wi, wo) / lambert(wo) - 1.0;
                worst = worst.max(rel.abs());
                assert!(rel.abs() < 0.01, "θi {theta_i} θo {theta_o} φ {phi}: {rel}");
            }
        }
    }
    // Directional albedo at normal incidence, in closed form: F_i = 0 and R_R = 1 + cos θo, so
    // albedo / base_color = ∫ (1 − F_o/2 + (1 + μ) F_o) 2μ dμ = 1 − 1/42 + 2 (1/42 + 1/168)
    // = 1 + 1/28 (μ = cos θo, F_o = (1 − μ)⁵): Burley's retro-reflection adds 3.6 %.
    let e = albedo_by_sampling(&p, Vec3::Z, 200_000, &mut rng(600));
    let expected = base_color as f64 * (1.0 + 1.0 / 28.0);
    eprintln!(
        "Lambert limit θi 0: albedo {:.5} ± {:.5}, closed form {expected:.5}",
        e.mean(),
        e.standard_error()
    );
    assert!((e.mean() - expected).abs() < 4.0 * e.standard_error() + 1e-4);
    // Away from the normal the retro-reflection grows (measured +3.5 % at 30°, +5.6 % at 60°,
    // and Burley's known grazing over-shoot, +40 % at 85°, at roughness 1; Mitsuba 3.9.1 agrees).
    for (theta, bound) in [(30.0f32, 0.05), (60.0, 0.08), (85.0, 0.45)] {
        let e = albedo_by_sampling(
            &p,
            direction(theta, 0.0),
            100_000,
            &mut rng(600 + theta as u64),
        );
        let rel = e.mean() / base_color as f64 - 1.0;
        eprintln!(
            "Lambert limit θi {theta}: albedo {:.4} ± {:.4} ({:+.2} %)",
            e.mean(),
            e.standard_error(),
            100.0 * rel
        );
        assert!(rel.abs() < bound, "θi {theta}: {rel}");
    }
    eprintln!("Lambert limit: worst pointwise deviation within 45°: {worst:.2e}");
}

// ---------------------------------------------------------------------------------------------
// Robustness

#[test]
fn extreme_inputs_stay_finite() {
    let corner = |v: f32| PrincipledParams::<f32>::from_array([v; PARAMETER_COUNT]);
    let materials = [
        corner(0.0),
        corner(1.0),
        PrincipledParams::new(1.0, 1.0, 0.0, 1.0).unwrap(),
        PrincipledParams::new(0.0, 0.0, 0.0, 0.0).unwrap(),
    ];
    let directions = [
        Vec3::Z,
        direction(89.99, 0.0),
        Vec3::new(1.0, 0.0, 1e-7).normalize(),
        direction(30.0, 0.0),
        direction(30.0, 180.0),
    ];
    let mut rng = rng(700);
    for p in &materials {
        for wi in directions {
            for wo in directions
                .into_iter()
                .chain([-wi, Vec3::new(-wi.x, -wi.y, wi.z)])
            {
                let (value, density) = eval_and_pdf(p, wi, wo);
                assert!(
                    value.is_finite() && value >= 0.0 && density.is_finite() && density >= 0.0,
                    "{p:?} {wi} {wo}: {value} {density}"
                );
            }
            for _ in 0..1000 {
                if let Some(s) = sample(p, wi, rng.random(), [rng.random(), rng.random()]) {
                    assert!(
                        s.weight.is_finite() && s.weight >= 0.0 && s.pdf > 0.0 && s.wo.z > 0.0,
                        "{p:?} {wi}: {s:?}"
                    );
                }
            }
        }
    }
    // Below the horizon on either side: black, and nothing to sample.
    let p = PrincipledParams::default();
    assert_eq!(eval(&p, -Vec3::Z, Vec3::Z), 0.0);
    assert_eq!(eval(&p, Vec3::Z, direction(100.0, 0.0)), 0.0);
    assert_eq!(pdf(&p, Vec3::Z, -Vec3::Z), 0.0);
    assert!(sample(&p, -Vec3::Z, 0.5, [0.5, 0.5]).is_none());
}
