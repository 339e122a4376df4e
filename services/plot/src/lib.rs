//! Glint's one home for plots: PNG plots with plotters' bitmap backend and an embedded font
//! (DejaVu Sans Mono, in `assets/`), so plotting needs no system fonts. Every report (the
//! calibration's, the experiments', the demo's) draws through [`png`].

#![cfg_attr(not(test), deny(clippy::expect_used, clippy::unwrap_used))]
#![warn(missing_docs)]

use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;

/// The font family every plot uses; registered on first use.
pub const FONT: &str = "sans-serif";

static FONT_BYTES: &[u8] = include_bytes!("../assets/DejaVuSansMono.ttf");

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The embedded font is a valid TTF; a failure would only leave text out.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES);
    });
}

/// Why a plot could not be made (plotters' errors borrow their backend, so they are kept as
/// text).
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// Drawing on the canvas failed (e.g. a degenerate axis range).
    #[error("plotting failed: {0}")]
    Draw(String),
    /// The finished image could not be encoded as PNG.
    #[error("encoding the plot as PNG failed: {0}")]
    Encode(String),
}

/// The area a plot draws on.
pub type Canvas<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// Draws a `width × height` px RGB plot with `draw` and encodes it as PNG.
pub fn png(
    width: u32,
    height: u32,
    draw: impl FnOnce(&Canvas<'_>) -> Result<(), Box<dyn std::error::Error>>,
) -> Result<Vec<u8>, PlotError> {
    register_font();
    let mut rgb = vec![255u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        root.fill(&WHITE)
            .map_err(|e| PlotError::Draw(e.to_string()))?;
        draw(&root).map_err(|e| PlotError::Draw(e.to_string()))?;
        root.present().map_err(|e| PlotError::Draw(e.to_string()))?;
    }
    encode_rgb_png(&rgb, width, height)
}

/// Encodes an RGB8 buffer as PNG.
pub fn encode_rgb_png(rgb: &[u8], width: u32, height: u32) -> Result<Vec<u8>, PlotError> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| PlotError::Encode(e.to_string()))?;
    Ok(out)
}

/// (min, max) of finite values, widened by `pad` of the span on each side; (0, 1) if none.
pub fn padded_range(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if lo > hi {
        return (0.0, 1.0);
    }
    let span = (hi - lo).max(1e-9);
    (lo - pad * span, hi + pad * span)
}

/// A colour for `t` in [0, 1] (clamped) on a perceptually ordered dark-blue → yellow ramp
/// (viridis' end points and three stops between, linearly interpolated).
pub fn ramp_rgb(t: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 5] = [
        [68.0, 1.0, 84.0],
        [59.0, 82.0, 139.0],
        [33.0, 145.0, 140.0],
        [94.0, 201.0, 98.0],
        [253.0, 231.0, 37.0],
    ];
    let x = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    } * (STOPS.len() - 1) as f64;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - i as f64;
    let mix = |c: usize| (STOPS[i][c] * (1.0 - f) + STOPS[i + 1][c] * f).round() as u8;
    [mix(0), mix(1), mix(2)]
}

/// A scalar image (row-major, `width × height` values) as a colour-mapped PNG: `lo..=hi` on
/// [`ramp_rgb`], non-finite values (missing) in `missing_rgb`.
pub fn scalar_image_png(
    values: &[f32],
    width: u32,
    height: u32,
    lo: f64,
    hi: f64,
    missing_rgb: [u8; 3],
) -> Result<Vec<u8>, PlotError> {
    let span = (hi - lo).max(f64::MIN_POSITIVE);
    let rgb: Vec<u8> = values
        .iter()
        .flat_map(|&v| {
            if v.is_finite() {
                ramp_rgb((f64::from(v) - lo) / span)
            } else {
                missing_rgb
            }
        })
        .collect();
    if rgb.len() != (width as usize) * (height as usize) * 3 {
        return Err(PlotError::Encode(format!(
            "{} values for a {width}×{height} image",
            values.len()
        )));
    }
    encode_rgb_png(&rgb, width, height)
}
