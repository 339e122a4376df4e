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
