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

/// A published point drawn over the curves: mean with a ±std error bar at its step.
#[derive(Debug, Clone, PartialEq)]
pub struct Marker {
    /// Legend entry; markers with the same label share one.
    pub label: String,
    pub x: f64,
    pub y: f64,
    pub err: f64,
    /// Index of the band whose colour it takes.
    pub color_of: usize,
}

/// Tick label for a step count: `250k`, `1M`, or the plain number below 1000.
pub fn step_label(x: f64) -> String {
    let a = x.abs();
    if a >= 1e6 {
        format!("{}M", trim(x / 1e6))
    } else if a >= 1e3 {
        format!("{}k", trim(x / 1e3))
    } else {
        trim(x)
    }
}

/// Tick label for a return: no trailing zeros, at most 3 significant decimals.
pub fn value_label(y: f64) -> String {
    let a = y.abs();
    if a >= 100.0 || a == 0.0 {
        format!("{y:.0}")
    } else if a >= 1.0 {
        trim_dec(format!("{y:.1}"))
    } else {
        trim_dec(format!("{y:.3}"))
    }
}

fn trim(v: f64) -> String {
    trim_dec(format!("{v:.1}"))
}

fn trim_dec(s: String) -> String {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
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

/// Renders `bands` (x: environment steps) and published `markers` into an SVG document.
pub fn bands_svg(title: &str, x_label: &str, y_label: &str, bands: &[Band], markers: &[Marker]) -> Result<String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (760, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let points = bands.iter().flat_map(|b| {
            let band = b.x.iter().zip(b.mean.iter().zip(&b.std)).flat_map(|(&x, (&m, &s))| [(x, m - s), (x, m + s)]);
            band.chain(b.x.iter().copied().zip(b.raw.iter().copied()))
        });
        let points = points.chain(markers.iter().flat_map(|m| [(m.x, m.y - m.err), (m.x, m.y + m.err)]));
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
        // Headroom above the data for the legend (about 18 px per entry in a plot area of about
        // 320 px), so that it never hides a curve.
        // Markers sharing a label (one published curve) have one legend entry, on the first.
        let first_of_its_label = |i: usize| markers.iter().position(|o| o.label == markers[i].label) == Some(i);
        let legend_entries = bands.len() + (0..markers.len()).filter(|&i| first_of_its_label(i)).count();
        let legend_share = ((legend_entries as f64 * 18.0 + 16.0) / 320.0).min(0.6);
        let (bottom, data_top) = (y0 - pad, y1 + pad);
        let top = bottom + (data_top - bottom) / (1.0 - legend_share);
        // Room for the right-most tick label, which plotters centres on the last tick.
        let x1 = x1 + (x1 - x0) * 0.02;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .margin_right(28)
            .x_label_area_size(40)
            .y_label_area_size(72)
            .build_cartesian_2d(x0..x1, bottom..top)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .x_labels(8)
            .y_labels(8)
            .x_label_formatter(&|x| step_label(*x))
            .y_label_formatter(&|y| value_label(*y))
            .draw()
            .map_err(err)?;
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
        for (i, m) in markers.iter().enumerate() {
            let (red, green, blue) = COLORS[m.color_of % COLORS.len()];
            let color = RGBColor(red, green, blue).to_rgba();
            let bar = PathElement::new(vec![(m.x, m.y - m.err), (m.x, m.y + m.err)], color.stroke_width(2));
            chart.draw_series(std::iter::once(bar)).map_err(err)?;
            let dot =
                chart.draw_series(std::iter::once(Circle::new((m.x, m.y), 5, color.stroke_width(2)))).map_err(err)?;
            if first_of_its_label(i) {
                dot.label(m.label.clone()).legend(move |(x, y)| Circle::new((x + 9, y), 5, color.stroke_width(2)));
            }
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
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
        let svg = bands_svg("returns", "step", "return", &[band("td3", 1.0), band("sac", 2.0)], &[]).unwrap();
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("td3") && svg.contains("sac") && svg.contains("returns"));
        assert!(svg.matches("<polyline").count() + svg.matches("<path").count() >= 2);
    }

    #[test]
    fn step_axes_read_in_thousands_and_markers_get_one_legend_entry() {
        assert_eq!(step_label(25_000.0), "25k");
        assert_eq!(step_label(1_000_000.0), "1M");
        assert_eq!(step_label(12_500.0), "12.5k");
        assert_eq!(step_label(500.0), "500");
        assert_eq!(step_label(5000.0), "5k");
        assert_eq!(value_label(2500.0), "2500");
        assert_eq!(value_label(-2.5), "-2.5");
        assert_eq!(value_label(0.125), "0.125");
        assert_eq!(value_label(0.0), "0");
        let band = Band {
            label: "sac".into(),
            x: vec![0.0, 150_000.0, 300_000.0],
            mean: vec![0.0, 4000.0, 8000.0],
            std: vec![0.0; 3],
            raw: vec![],
        };
        let marker = |x: f64| Marker { label: "sac, published".into(), x, y: 5000.0, err: 400.0, color_of: 0 };
        let svg =
            bands_svg("c", "environment steps", "return", &[band], &[marker(100_000.0), marker(300_000.0)]).unwrap();
        let labels: Vec<&str> = svg.lines().map(str::trim).collect();
        assert!(labels.contains(&"150k") && labels.contains(&"300k"), "step ticks in thousands");
        assert!(!svg.contains("150000") && !svg.contains("25000.0"));
        assert_eq!(svg.matches("sac, published").count(), 1);
        assert!(svg.matches("<circle").count() >= 2);
    }
}
