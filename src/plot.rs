//! Plots people would rather see than read: rate–distortion curves, drift over time, drift
//! and shown error against bandwidth (PNG, drawn with plotters and an embedded font).

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;

static FONT: Once = Once::new();

/// A plot's size in pixels.
const SIZE: (u32, u32) = (900, 560);

fn font() {
    FONT.call_once(|| {
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            include_bytes!("../assets/DejaVuSans.ttf"),
        );
    });
}

const COLORS: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// A named series of (x, y) points.
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
}

fn range(series: &[Series], f: impl Fn(&(f64, f64)) -> f64, log: bool) -> (f64, f64) {
    let vals: Vec<f64> = series
        .iter()
        .flat_map(|s| s.points.iter().map(&f))
        .filter(|v| v.is_finite() && (!log || *v > 0.0))
        .collect();
    let (lo, hi) = vals
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    if vals.is_empty() {
        return (0.0, 1.0);
    }
    if log {
        let (lo, hi) = (lo / 1.3, hi * 1.3);
        // Under a decade (one size alone), plotters puts no tick on a log axis: widen it
        // to the decades around the points.
        if hi / lo < 10.0 {
            (
                10f64.powf(lo.log10().floor()),
                10f64.powf(hi.log10().ceil()),
            )
        } else {
            (lo, hi)
        }
    } else {
        // A flat series (no drift at all) gets a unit of room; values that are never
        // negative get no negative axis.
        let pad = if hi - lo < 1e-12 {
            (hi.abs() * 0.1).max(1.0)
        } else {
            (hi - lo) * 0.08
        };
        let low = if lo >= 0.0 {
            (lo - pad).max(0.0)
        } else {
            lo - pad
        };
        (low, hi + pad)
    }
}

/// Line-and-point plot of several series; `log_x` for rates.
pub fn lines(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    log_x: bool,
) -> Result<(), String> {
    font();
    // Drawn into memory and written as one PNG through `write_file` (an interrupted run
    // leaves no half-written plot), with the image crate the rest of `vbim` writes with.
    let mut rgb = vec![0u8; (SIZE.0 * SIZE.1 * 3) as usize];
    let root = BitMapBackend::with_buffer(&mut rgb, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let (x0, x1) = range(series, |p| p.0, log_x);
    let (y0, y1) = range(series, |p| p.1, false);
    let mut chart = ChartBuilder::on(&root);
    chart
        .caption(title, ("sans-serif", 22))
        .margin(16)
        .x_label_area_size(44)
        .y_label_area_size(60);
    macro_rules! draw {
        ($c:expr) => {{
            let mut c = $c.map_err(|e| e.to_string())?;
            c.configure_mesh()
                // Shortest form of a rounded value: a log axis ticks at 0.3, 0.4, … whose
                // default labels printed every binary digit of 0.30000000000000004.
                .x_label_formatter(&|x| format!("{}", (x * 1000.0).round() / 1000.0))
                .x_desc(x_label)
                .y_desc(y_label)
                .label_style(("sans-serif", 14))
                .draw()
                .map_err(|e| e.to_string())?;
            for (i, s) in series.iter().enumerate() {
                let col = COLORS[i % COLORS.len()];
                let pts: Vec<(f64, f64)> = s
                    .points
                    .iter()
                    .copied()
                    .filter(|p| p.0.is_finite() && p.1.is_finite())
                    .collect();
                // One pixel wide: plotters draws wider lines with a polygon that can reach
                // past the plotting area on a near-vertical step (plotters issue #549; the
                // demo's drift plot showed a line below its x-axis at the catch-up).
                c.draw_series(LineSeries::new(pts.clone(), col.stroke_width(1)))
                    .map_err(|e| e.to_string())?
                    .label(s.name.clone())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], col.stroke_width(2))
                    });
                c.draw_series(pts.iter().map(|&p| Circle::new(p, 3, col.filled())))
                    .map_err(|e| e.to_string())?;
            }
            c.configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 14))
                .position(SeriesLabelPosition::LowerRight)
                .draw()
                .map_err(|e| e.to_string())?;
        }};
    }
    if log_x {
        draw!(chart.build_cartesian_2d((x0..x1).log_scale(), y0..y1));
    } else {
        draw!(chart.build_cartesian_2d(x0..x1, y0..y1));
    }
    root.present()
        .map_err(|e| format!("{}: {e}", path.display()))?;
    drop(root);
    vbim_bake::write_file(path, |tmp| {
        image::save_buffer(tmp, &rgb, SIZE.0, SIZE.1, image::ExtendedColorType::Rgb8)
            .map_err(|e| e.to_string())
    })
    .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_ranges_of_flat_and_non_negative_series() {
        let s = |pts: &[(f64, f64)]| Series {
            name: "s".into(),
            points: pts.to_vec(),
        };
        let y = |p: &(f64, f64)| p.1;
        assert_eq!(range(&[s(&[(1.0, 0.0), (2.0, 0.0)])], y, false), (0.0, 1.0));
        let (lo, hi) = range(&[s(&[(1.0, 0.5), (2.0, 3.0)])], y, false);
        assert!((0.0..0.5).contains(&lo) && hi > 3.0, "{lo} {hi}");
        let (lo, _) = range(&[s(&[(1.0, -1.0), (2.0, 3.0)])], y, false);
        assert!(lo < -1.0);
        let x = |p: &(f64, f64)| p.0;
        assert_eq!(range(&[s(&[(4e6, 1.0)])], x, true), (1e6, 1e7));
        assert_eq!(
            range(&[s(&[(1e3, 1.0), (1e6, 1.0)])], x, true),
            (1e3 / 1.3, 1.3e6)
        );
    }
}
