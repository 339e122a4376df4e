//! The response plot, like the paper's Fig. 6 right: DN over ln exposure.

use plotters::prelude::*;

use super::ResponseTable;
use glint_plot::{FONT, PlotError, padded_range, png};

/// PNG of the recovered g (DN over ln X) and, if given, a reference curve as (ln X, DN) points
/// already expressed in the recovered exposure unit.
pub fn response_png(
    table: &ResponseTable,
    reference: Option<(&str, &[(f64, f64)])>,
) -> Result<Vec<u8>, PlotError> {
    let n = table.inverse.dn.len();
    // The end levels carry no data (weight 0): leave them out of the plot's range.
    let inner = 1..n.saturating_sub(1).max(1);
    let recovered: Vec<(f64, f64)> = inner
        .clone()
        .map(|z| (table.inverse.ln_exposure[z], table.inverse.dn[z]))
        .collect();
    let (x0, x1) = padded_range(
        recovered
            .iter()
            .map(|p| p.0)
            .chain(reference.iter().flat_map(|(_, r)| r.iter().map(|p| p.0))),
        0.03,
    );
    let max_dn = table.max_dn as f64;
    png(720, 540, |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(
                format!(
                    "Recovered response g (λ = {}, {} samples, {} exposures)",
                    table.solve.lambda,
                    table.solve.samples,
                    table.solve.exposures_s.len()
                ),
                (FONT, 18),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(56)
            .build_cartesian_2d(x0..x1, 0.0..max_dn * 1.02)?;
        chart
            .configure_mesh()
            .x_desc("ln exposure X = ln(E·Δt) (relative units)")
            .y_desc("pixel value (DN)")
            .label_style((FONT, 14))
            .draw()?;
        chart
            .draw_series(LineSeries::new(
                recovered.iter().copied(),
                BLUE.stroke_width(2),
            ))?
            .label("recovered (Debevec–Malik)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE.stroke_width(2)));
        if let Some((name, points)) = reference {
            chart
                .draw_series(LineSeries::new(points.iter().copied(), RED.stroke_width(1)))?
                .label(name.to_owned())
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font((FONT, 14))
            .draw()?;
        Ok(())
    })
}
