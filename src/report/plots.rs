//! SVG charts with plotters: a line per series with a shaded interval band, and points with
//! error bars.
use anyhow::{anyhow, Result};
use plotters::prelude::*;

/// One series: a line through `mean` and a shaded band from `low` to `high` (no band where
/// they equal the mean).
#[derive(Debug, Clone, Default)]
pub(crate) struct Band {
    pub label: String,
    pub x: Vec<f64>,
    pub mean: Vec<f64>,
    pub low: Vec<f64>,
    pub high: Vec<f64>,
}

impl Band {
    /// A band of mean ± `half` at every point.
    #[cfg(test)]
    pub(crate) fn symmetric(label: String, x: Vec<f64>, mean: Vec<f64>, half: &[f64]) -> Band {
        let low = mean.iter().zip(half).map(|(m, h)| m - h).collect();
        let high = mean.iter().zip(half).map(|(m, h)| m + h).collect();
        Band { label, x, mean, low, high }
    }

    /// At most `max_points` points, evenly spaced in index, keeping the last.
    pub(crate) fn thinned(self, max_points: usize) -> Band {
        let n = self.x.len();
        if n <= max_points || max_points < 2 {
            return self;
        }
        let keep: Vec<usize> = (0..max_points).map(|i| i * (n - 1) / (max_points - 1)).collect();
        let pick = |v: &[f64]| keep.iter().map(|&i| v[i]).collect::<Vec<f64>>();
        Band {
            x: pick(&self.x),
            mean: pick(&self.mean),
            low: pick(&self.low),
            high: pick(&self.high),
            label: self.label,
        }
    }
}

/// A point drawn over the curves (a published result, a policy's outcome) with an error bar
/// from `low` to `high`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Marker {
    /// Legend entry; markers with the same label share one.
    pub label: String,
    pub x: f64,
    pub y: f64,
    pub low: f64,
    pub high: f64,
    /// Index of the colour it takes (a band's, to match it).
    pub(crate) color_of: usize,
}

/// Tick label for a step count: `250k`, `1M`, or the plain number below 1000.
pub(crate) fn step_label(x: f64) -> String {
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
pub(crate) fn value_label(y: f64) -> String {
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
pub(crate) fn bands_svg(
    title: &str,
    x_label: &str,
    y_label: &str,
    bands: &[Band],
    markers: &[Marker],
) -> Result<String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (760, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let points = bands
            .iter()
            .flat_map(|b| b.x.iter().zip(b.low.iter().zip(&b.high)).flat_map(|(&x, (&l, &h))| [(x, l), (x, h)]));
        let points = points.chain(bands.iter().flat_map(|b| b.x.iter().copied().zip(b.mean.iter().copied())));
        let points = points.chain(markers.iter().flat_map(|m| [(m.x, m.low), (m.x, m.high), (m.x, m.y)]));
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
            let upper = b.x.iter().copied().zip(b.high.iter().copied());
            let lower = b.x.iter().copied().zip(b.low.iter().copied()).rev();
            let outline: Vec<(f64, f64)> = upper.chain(lower).filter(|(x, y)| x.is_finite() && y.is_finite()).collect();
            let has_band = b.low.iter().zip(&b.mean).chain(b.high.iter().zip(&b.mean)).any(|(a, m)| a != m);
            if has_band {
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
            let bar = PathElement::new(vec![(m.x, m.low), (m.x, m.high)], color.stroke_width(2));
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
        let band = |label: &str, k: f64| {
            Band::symmetric(label.into(), vec![0.0, 1.0, 2.0], vec![0.0, k, 2.0 * k], &[0.1, 0.2, 0.3])
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
        let band = Band::symmetric("sac".into(), vec![0.0, 150_000.0, 300_000.0], vec![0.0, 4000.0, 8000.0], &[0.0; 3]);
        let marker =
            |x: f64| Marker { label: "sac, published".into(), x, y: 5000.0, low: 4600.0, high: 5400.0, color_of: 0 };
        let svg =
            bands_svg("c", "environment steps", "return", &[band], &[marker(100_000.0), marker(300_000.0)]).unwrap();
        let labels: Vec<&str> = svg.lines().map(str::trim).collect();
        assert!(labels.contains(&"150k") && labels.contains(&"300k"), "step ticks in thousands");
        assert!(!svg.contains("150000") && !svg.contains("25000.0"));
        assert_eq!(svg.matches("sac, published").count(), 1);
        assert!(svg.matches("<circle").count() >= 2);
    }

    #[test]
    fn thinning_keeps_the_ends_and_at_most_the_asked_points() {
        let n = 1000;
        let x: Vec<f64> = (0..n).map(f64::from).collect();
        let b = Band::symmetric("a".into(), x.clone(), x.clone(), &vec![1.0; n as usize]).thinned(100);
        assert_eq!(b.x.len(), 100);
        assert_eq!((b.x[0], *b.x.last().unwrap()), (0.0, 999.0));
        assert_eq!(b.low[5], b.mean[5] - 1.0);
        assert_eq!(Band::symmetric("a".into(), vec![1.0], vec![2.0], &[0.0]).thinned(100).x.len(), 1);
    }
}
