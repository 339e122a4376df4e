//! The fit's figures, like the paper's Fig. 7b (loss curve and parameter trajectories) and
//! Fig. 7c (error map between target and fitted radiance).

use plotters::prelude::*;

use super::{FREE, FREE_NAMES, FitResult};
use glint_plot::{FONT, PlotError, encode_rgb_png, padded_range, png};

const COLOURS: [RGBColor; FREE] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
];

/// Loss (log scale) and the free parameters over the iterations; `truth`, if given, as dashed
/// horizontal lines (evaluation only).
pub fn fit_history_png(
    result: &FitResult,
    title: &str,
    truth: Option<[f32; FREE]>,
) -> Result<Vec<u8>, PlotError> {
    let n = result.loss.len().max(2) as f64 - 1.0;
    png(1100, 440, |root| {
        let (left, right) = root.split_horizontally(520);
        let finite = result
            .loss
            .iter()
            .copied()
            .filter(|l| l.is_finite() && *l > 0.0);
        let (lo, hi) = padded_range(finite.map(f64::log10), 0.05);
        let mut chart = ChartBuilder::on(&left)
            .caption(format!("{title}: loss"), (FONT, 18))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(56)
            .build_cartesian_2d(0.0..n, lo..hi)?;
        chart
            .configure_mesh()
            .x_desc("iteration")
            .y_desc("log10 L (normalised L2)")
            .label_style((FONT, 13))
            .draw()?;
        chart.draw_series(LineSeries::new(
            result
                .loss
                .iter()
                .enumerate()
                .filter(|(_, l)| l.is_finite() && **l > 0.0)
                .map(|(k, l)| (k as f64, l.log10())),
            BLACK.stroke_width(2),
        ))?;

        let mut chart = ChartBuilder::on(&right)
            .caption(format!("{title}: parameters"), (FONT, 18))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(44)
            .build_cartesian_2d(0.0..n, 0.0..1.0)?;
        chart
            .configure_mesh()
            .x_desc("iteration")
            .label_style((FONT, 13))
            .draw()?;
        for (i, colour) in COLOURS.iter().enumerate() {
            chart
                .draw_series(LineSeries::new(
                    result
                        .trajectory
                        .iter()
                        .enumerate()
                        .map(|(k, x)| (k as f64, x[i] as f64)),
                    colour.stroke_width(2),
                ))?
                .label(FREE_NAMES[i])
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour));
            if let Some(t) = truth {
                let t = t[i] as f64;
                chart.draw_series(DashedLineSeries::new(
                    vec![(0.0, t), (n, t)],
                    6,
                    4,
                    colour.stroke_width(1),
                ))?;
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font((FONT, 13))
            .draw()?;
        Ok(())
    })
}

/// |rendered − target| / max target over an image of `width × height`, object pixels only
/// (others black), in a blue → yellow ramp (0 … `full_scale` of the brightest target).
pub fn error_map_png(
    width: u32,
    height: u32,
    pixels: &[(u32, u32)],
    rendered: &[f32],
    target: &[f32],
    full_scale: f32,
) -> Result<Vec<u8>, PlotError> {
    let max_t = target
        .iter()
        .copied()
        .filter(|t| t.is_finite())
        .fold(0.0f32, f32::max);
    let scale = (max_t * full_scale).max(f32::MIN_POSITIVE);
    let mut rgb = vec![0u8; (width * height * 3) as usize];
    for ((&(u, v), &r), &t) in pixels.iter().zip(rendered).zip(target) {
        if u >= width || v >= height {
            continue;
        }
        let e = if r.is_finite() && t.is_finite() {
            ((r - t).abs() / scale).clamp(0.0, 1.0)
        } else {
            1.0
        };
        // A simple perceptual-ish ramp: dark blue (0) → teal → yellow (1).
        let colour = [
            (255.0 * e.powf(0.8)) as u8,
            (40.0 + 200.0 * e.sqrt()) as u8,
            (120.0 * (1.0 - e)) as u8 + 30,
        ];
        let i = ((v * width + u) * 3) as usize;
        rgb[i..i + 3].copy_from_slice(&colour);
    }
    encode_rgb_png(&rgb, width, height)
}
