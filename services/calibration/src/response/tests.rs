//! Recovery of known responses from synthetic stacks read out by the render crate's `Sensor`
//! (shot and read noise on), radiance maps, file round trips and bad input.

use super::*;
use glint_render::sensor::Sensor;

/// Radiances of a test chart: `blocks` flat 4 × 4 px patches, log-uniform over
/// [`L_MIN`, `L_MAX`] W·sr⁻¹·m⁻², in a 16-block-wide grid. With the default sensor
/// (9·10⁵ e⁻ per unit radiance and second, 10⁴ e⁻ full well) and 0.25 … 8 ms, L_MIN reads
/// 72 e⁻ at the longest exposure and L_MAX 90 % of full well at the shortest.
const L_MIN: f32 = 0.01;
const L_MAX: f32 = 40.0;
const BLOCK_PX: u32 = 4;

fn chart(blocks: u32) -> Image<f32> {
    chart_over(blocks, L_MIN, L_MAX)
}

fn chart_over(blocks: u32, l_min: f32, l_max: f32) -> Image<f32> {
    let cols = 16;
    let rows = blocks.div_ceil(cols);
    let (w, h) = (cols * BLOCK_PX, rows * BLOCK_PX);
    let mut data = vec![0f32; (w * h) as usize];
    for v in 0..h {
        for u in 0..w {
            let b = ((v / BLOCK_PX) * cols + u / BLOCK_PX).min(blocks - 1);
            let t = b as f32 / (blocks - 1) as f32;
            data[(v * w + u) as usize] = l_min * (l_max / l_min).powf(t);
        }
    }
    Image::new(w, h, data).unwrap()
}

/// 0.25 … 8 ms, doubling: the `--exposure-stack 0.25,0.5,1,2,4,8` of the issue.
fn exposures_s() -> Vec<f64> {
    (0..6).map(|k| 0.25e-3 * 2f64.powi(k)).collect()
}

fn stack_of(radiance: &Image<f32>, sensor: &Sensor, seed: u64) -> ExposureStack {
    ExposureStack::read_out(sensor, radiance, &exposures_s(), seed).unwrap()
}

/// The resolution of the data itself: the width, in ln X, of the widest single DN step of the
/// true response over `range`. Readings are quantised to whole DN, so no method can place a
/// level's ln X more precisely than the step it spans.
fn widest_dn_step(truth: &ResponseCurve, max_dn: u16, range: (f64, f64)) -> f64 {
    let m = max_dn as f64;
    let lo = (range.0 * m).floor() as u32;
    let hi = (range.1 * m).ceil() as u32;
    (lo..=hi)
        .map(|z| {
            let a = truth.invert(((z as f64 - 0.5) / m) as f32) as f64;
            let b = truth.invert(((z as f64 + 0.5) / m) as f32) as f64;
            (b / a).ln()
        })
        .fold(0.0, f64::max)
}

/// Well-exposed range used in the accuracy checks: 10 % … 90 % of full scale.
const WELL_EXPOSED: (f64, f64) = (0.1, 0.9);

fn recovers(response: ResponseCurve) -> (ResponseComparison, f64) {
    let sensor = Sensor {
        response: response.clone(),
        ..Sensor::default()
    };
    let stack = stack_of(&chart(256), &sensor, 7);
    let table = calibrate(&stack, &DebevecConfig::default()).unwrap();
    let cmp = table.compare_with(&response, WELL_EXPOSED);
    let tolerance = widest_dn_step(&response, sensor.max_dn(), WELL_EXPOSED);
    (cmp, tolerance)
}

#[test]
fn recovers_the_mock_cameras_s_curve() {
    let (cmp, tol) = recovers(Sensor::default().response);
    assert!(cmp.levels > 180, "{cmp:?}");
    assert!(cmp.max_abs_ln_error < tol, "{cmp:?}, tolerance {tol}");
}

#[test]
fn recovers_a_gamma_curve() {
    let (cmp, tol) = recovers(ResponseCurve::Gamma { gamma: 2.2 });
    assert!(cmp.max_abs_ln_error < tol, "{cmp:?}, tolerance {tol}");
}

#[test]
fn radiance_map_is_proportional_to_radiance() {
    let sensor = Sensor::default();
    // The response comes from the full chart; the radiance map is checked on patches that read
    // ≥ 1000 e⁻ unsaturated in some exposure: L ≥ 1000 / (8 ms · 9·10⁵) ≈ 0.14.
    let table = calibrate(
        &stack_of(&chart(256), &sensor, 3),
        &DebevecConfig::default(),
    )
    .unwrap();
    let radiance = chart_over(256, 0.14, L_MAX);
    let stack = stack_of(&radiance, &sensor, 4);
    let e = table.radiance_map(&stack).unwrap();
    let ratios: Vec<f64> = e
        .data()
        .iter()
        .zip(radiance.data())
        .map(|(&e, &l)| (e as f64 / l as f64).ln())
        .collect();
    assert!(
        ratios.iter().all(|r| r.is_finite()),
        "every patch is well exposed somewhere"
    );
    let mean = ratios.iter().sum::<f64>() / ratios.len() as f64;
    let worst = ratios.iter().fold(0.0f64, |m, r| m.max((r - mean).abs()));
    // Per pixel: the response error (below one DN step in ln X) plus shot noise; every pixel
    // has a reading of ≥ ~1000 e⁻ at weight ≥ 0.2 of the maximum, so 3σ of the ln noise is
    // ≤ 3/√1000 ≈ 0.095 before averaging over exposures.
    let tol = widest_dn_step(&sensor.response, sensor.max_dn(), WELL_EXPOSED) + 0.095;
    assert!(worst < tol, "worst |Δ ln E| {worst}, tolerance {tol}");
}

#[test]
fn samples_are_stratified_and_skip_unusable_pixels() {
    let stack = stack_of(&chart(256), &Sensor::default(), 1);
    let samples = select_samples(&stack, 70);
    assert!(samples.len() >= 60, "{}", samples.len());
    let mut keys: Vec<u64> = samples
        .iter()
        .map(|s| {
            stack
                .images()
                .iter()
                .map(|i| i.get(s.u, s.v).unwrap() as u64)
                .sum()
        })
        .collect();
    keys.sort();
    keys.dedup();
    assert_eq!(
        keys.len(),
        samples.len(),
        "one sample per intensity stratum"
    );
    for s in &samples {
        let well = stack
            .images()
            .iter()
            .filter(|i| (1..255).contains(&i.get(s.u, s.v).unwrap()))
            .count();
        assert!(well >= 2);
    }
}

#[test]
fn bad_input_is_named() {
    let img = Image::filled(8, 8, 10u16).unwrap();
    let err = ExposureStack::new(vec![img.clone()], vec![0.01], 8).unwrap_err();
    assert!(err.to_string().contains("at least 2 exposures"), "{err}");
    let small = Image::filled(4, 8, 10u16).unwrap();
    let err = ExposureStack::new(vec![img.clone(), small], vec![0.01, 0.02], 8).unwrap_err();
    assert!(err.to_string().contains("images[1] is 4×8"), "{err}");
    for dt in [0.0, -1.0, f64::NAN] {
        let err =
            ExposureStack::new(vec![img.clone(), img.clone()], vec![0.01, dt], 8).unwrap_err();
        assert!(err.to_string().contains("images[1].exposure_s"), "{err}");
    }
    let err = ExposureStack::new(vec![img.clone(), img.clone()], vec![0.01, 0.01], 8).unwrap_err();
    assert!(err.to_string().contains("same exposure_s"), "{err}");
    let err = ExposureStack::new(vec![img.clone(), img.clone()], vec![0.01], 8).unwrap_err();
    assert!(err.to_string().contains("2 images but 1 exposure"), "{err}");
    let hot = Image::filled(8, 8, 300u16).unwrap();
    let err = ExposureStack::new(vec![img.clone(), hot], vec![0.01, 0.02], 8).unwrap_err();
    assert!(err.to_string().contains("DN 300"), "{err}");

    let saturated = Image::filled(8, 8, 255u16).unwrap();
    let stack =
        ExposureStack::new(vec![saturated.clone(), saturated], vec![0.01, 0.02], 8).unwrap();
    let err = calibrate(&stack, &DebevecConfig::default()).unwrap_err();
    assert!(
        matches!(err, ResponseError::NoUsablePixels { found: 0 }),
        "{err}"
    );
    let ok = stack_of(&chart(64), &Sensor::default(), 1);
    let err = calibrate(
        &ok,
        &DebevecConfig {
            lambda: -1.0,
            ..DebevecConfig::default()
        },
    )
    .unwrap_err();
    assert!(err.to_string().contains("lambda"), "{err}");
}

#[test]
fn table_files_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let sensor = Sensor::default();
    let stack = stack_of(&chart(128), &sensor, 5);
    let table = calibrate(&stack, &DebevecConfig::default()).unwrap();
    let path = dir.path().join("g.json");
    table.save(&path).unwrap();
    let back = ResponseTable::load(&path).unwrap();
    // JSON keeps f64 to within an ulp or so.
    for (a, b) in back
        .inverse
        .ln_exposure
        .iter()
        .zip(&table.inverse.ln_exposure)
    {
        assert!((a - b).abs() < 1e-12);
    }
    assert_eq!(back.solve.samples, table.solve.samples);
    // Forward and inverse agree: g(g⁻¹(z)) = z where the inverse is increasing.
    let z = 128usize;
    let x = table.inverse.ln_exposure[z];
    let k = table
        .forward
        .ln_exposure
        .iter()
        .position(|&l| l >= x)
        .unwrap();
    let dn = table.forward.intensity[k] * 255.0;
    // The forward grid has 256 points over ~250 levels: within about one level.
    assert!((dn - table.inverse.dn[z]).abs() < 1.5, "{dn}");
    let png = response_png(&table, None).unwrap();
    assert_eq!(&png[1..4], b"PNG");
}

#[test]
fn the_forward_response_inverts_the_recovered_inverse() {
    // g(g⁻¹(z)) reads z back within the DN step the level spans, over the well-exposed
    // range; g is monotone and saturates above its table.
    let sensor = Sensor::default();
    let table = calibrate(
        &stack_of(&chart(256), &sensor, 5),
        &DebevecConfig::default(),
    )
    .unwrap();
    let m = sensor.max_dn() as f64;
    for z in [(0.1 * m) as u16, (0.5 * m) as u16, (0.9 * m) as u16] {
        let i = table.intensity(table.ln_exposure(z));
        // The level containing z spans a few DN at most at this bit depth: 1 % of full scale.
        assert!((i - z as f64 / m).abs() < 0.01, "z {z}: g(g⁻¹) = {}", i * m);
    }
    let grid = &table.forward.ln_exposure;
    let samples: Vec<f64> = (0..200)
        .map(|k| table.intensity(grid[0] - 2.0 + k as f64 * 0.05))
        .collect();
    assert!(samples.windows(2).all(|w| w[1] >= w[0]));
    assert!(table.intensity(grid[grid.len() - 1] + 5.0) > 0.99);
    assert!(table.intensity(grid[0] - 20.0) < 1e-6);
}

/// Found by fuzzing (`fuzz/corpus/calibration_files/regression-response-short-forward-table`):
/// a response file whose forward table had fewer intensities than grid points was read, and
/// `intensity` then indexed past its end. Every forward-table defect is now refused on reading,
/// naming the field.
#[test]
fn a_response_file_with_a_broken_forward_table_is_refused_naming_the_field() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/calibration/zigzag/response.json");
    let text = std::fs::read_to_string(&path).unwrap();
    let good = ResponseTable::parse(&text, &path).unwrap();
    let refused = |edit: &dyn Fn(&mut ResponseTable)| {
        let mut table = good.clone();
        edit(&mut table);
        let text = serde_json::to_string(&table).unwrap();
        ResponseTable::parse(&text, &path).unwrap_err().to_string()
    };
    let e = refused(&|t| t.forward.intensity.truncate(3));
    assert!(e.contains("forward.intensity"), "{e}");
    let e = refused(&|t| t.forward.ln_exposure[4] += 0.5);
    assert!(e.contains("forward.ln_exposure"), "{e}");
    let e = refused(&|t| t.forward.intensity[2] = 1.5);
    assert!(e.contains("forward.intensity"), "{e}");
    let e = refused(&|t| {
        t.forward.ln_exposure.truncate(1);
        t.forward.intensity.truncate(1);
    });
    assert!(e.contains("forward.ln_exposure"), "{e}");
}
