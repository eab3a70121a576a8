//! SVG charts with plotters: mean lines with a ±std band per series.
use anyhow::{anyhow, Result};
use plotters::prelude::*;

/// One series: a mean line and a shaded band of ±std around it, optionally over the raw
/// values it summarises (drawn faint).
#[derive(Debug, Clone, Default)]
pub struct Band {
    pub label: String,
    pub x: Vec<f64>,
    pub mean: Vec<f64>,
    pub std: Vec<f64>,
    /// Raw values at the same x (empty: none).
    pub raw: Vec<f64>,
}

/// Distinct, readable line colours (the common "tab10" set), cycled.
const COLORS: [(u8, u8, u8); 8] = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
];

fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("plotting: {e:?}")
}

/// Renders `bands` into an SVG document.
pub fn bands_svg(title: &str, x_label: &str, y_label: &str, bands: &[Band]) -> Result<String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (760, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let points = bands.iter().flat_map(|b| {
            let band = b.x.iter().zip(b.mean.iter().zip(&b.std)).flat_map(|(&x, (&m, &s))| [(x, m - s), (x, m + s)]);
            band.chain(b.x.iter().copied().zip(b.raw.iter().copied()))
        });
        let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
        for (x, y) in points.filter(|(x, y)| x.is_finite() && y.is_finite()) {
            (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
        }
        if !x0.is_finite() {
            (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
        }
        if x1 <= x0 {
            x1 = x0 + 1.0;
        }
        let pad = ((y1 - y0) * 0.05).max(1e-6);
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(64)
            .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))
            .map_err(err)?;
        chart.configure_mesh().x_desc(x_label).y_desc(y_label).x_labels(8).y_labels(8).draw().map_err(err)?;
        for (i, b) in bands.iter().enumerate() {
            let (red, green, blue) = COLORS[i % COLORS.len()];
            let color = RGBColor(red, green, blue).to_rgba();
            let upper = b.x.iter().zip(b.mean.iter().zip(&b.std)).map(|(&x, (&m, &s))| (x, m + s));
            let lower = b.x.iter().zip(b.mean.iter().zip(&b.std)).rev().map(|(&x, (&m, &s))| (x, m - s));
            let outline: Vec<(f64, f64)> = upper.chain(lower).collect();
            if !b.raw.is_empty() {
                let raw = b.x.iter().copied().zip(b.raw.iter().copied());
                chart.draw_series(LineSeries::new(raw, color.mix(0.3).stroke_width(1))).map_err(err)?;
            }
            if b.std.iter().any(|&s| s > 0.0) {
                chart.draw_series(std::iter::once(Polygon::new(outline, color.mix(0.18).filled()))).map_err(err)?;
            }
            chart
                .draw_series(LineSeries::new(b.x.iter().copied().zip(b.mean.iter().copied()), color.stroke_width(2)))
                .map_err(err)?
                .label(b.label.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2)));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::LowerRight)
            .draw()
            .map_err(err)?;
        root.present().map_err(err)?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn svg_has_a_path_per_series_and_the_labels() {
        let band = |label: &str, k: f64| Band {
            label: label.into(),
            x: vec![0.0, 1.0, 2.0],
            mean: vec![0.0, k, 2.0 * k],
            std: vec![0.1, 0.2, 0.3],
            raw: vec![],
        };
        let svg = bands_svg("returns", "step", "return", &[band("td3", 1.0), band("sac", 2.0)]).unwrap();
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("td3") && svg.contains("sac") && svg.contains("returns"));
        assert!(svg.matches("<polyline").count() + svg.matches("<path").count() >= 2);
    }
}
