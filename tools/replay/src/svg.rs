//! The reports' line and scatter plots as SVG, drawn by `plotters` (its SVG backend; no font
//! files, no bitmap stack): axes with ticks and a grid, a title, axis labels, a legend, lines
//! (solid or dashed) or points per series. The calibration, discovery and smoothing reports use
//! it.

use plotters::prelude::*;

/// One series of a plot.
#[derive(Debug, Clone)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub color: &'static str,
    /// Points instead of a line.
    pub markers: bool,
    pub dashed: bool,
}

/// Colours for series in order.
pub const PALETTE: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
];

const WIDTH: u32 = 760;
const HEIGHT: u32 = 520;
/// The legend's column on the right.
const LEGEND_W: u32 = 180;
/// The plot area's size in pixels (for `equal_axes`): the width without the legend and the y-axis
/// labels, the height without the title and the x-axis labels.
const PLOT_W: f64 = 500.0;
const PLOT_H: f64 = 430.0;

fn rgb(hex: &str) -> RGBColor {
    let v = u32::from_str_radix(hex.trim_start_matches('#'), 16).unwrap_or(0);
    RGBColor((v >> 16) as u8, (v >> 8) as u8, v as u8)
}

/// The finite stretches of a series (a line breaks where a value is not finite).
fn finite_runs(points: &[(f64, f64)]) -> Vec<Vec<(f64, f64)>> {
    let mut runs = vec![Vec::new()];
    for &(x, y) in points {
        if x.is_finite() && y.is_finite() {
            if let Some(r) = runs.last_mut() {
                r.push((x, y));
            }
        } else if runs.last().is_some_and(|r| !r.is_empty()) {
            runs.push(Vec::new());
        }
    }
    runs.retain(|r| !r.is_empty());
    runs
}

/// The axis ranges: the finite points' extent (a unit range when there is none or it is flat);
/// with `equal_axes`, widened so that one unit has the same length on both axes.
fn ranges(series: &[Series], equal_axes: bool) -> ((f64, f64), (f64, f64)) {
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for (x, y) in series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|(x, y)| x.is_finite() && y.is_finite())
    {
        x0 = x0.min(*x);
        x1 = x1.max(*x);
        y0 = y0.min(*y);
        y1 = y1.max(*y);
    }
    if !x0.is_finite() {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    if x1 - x0 < 1e-12 {
        x1 = x0 + 1.0;
    }
    if y1 - y0 < 1e-12 {
        y1 = y0 + 1.0;
    }
    if equal_axes {
        let s = ((x1 - x0) / PLOT_W).max((y1 - y0) / PLOT_H);
        let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        (x0, x1) = (cx - s * PLOT_W / 2.0, cx + s * PLOT_W / 2.0);
        (y0, y1) = (cy - s * PLOT_H / 2.0, cy + s * PLOT_H / 2.0);
    }
    ((x0, x1), (y0, y1))
}

/// A tick label: at most three decimals, without trailing zeros (`500`, `0.25`, `-1.5`).
fn tick(v: f64) -> String {
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

fn draw(
    svg: &mut String,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    equal_axes: bool,
) -> Result<(), Box<dyn std::error::Error>> {
    let root = SVGBackend::with_string(svg, (WIDTH, HEIGHT)).into_drawing_area();
    root.fill(&WHITE)?;
    let (plot_area, legend_area) = root.split_horizontally(WIDTH - LEGEND_W);
    let (xr, yr) = ranges(series, equal_axes);
    let mut chart = ChartBuilder::on(&plot_area)
        .caption(title, ("sans-serif", 15))
        .margin(10)
        .x_label_area_size(50)
        .y_label_area_size(70)
        .build_cartesian_2d(xr.0..xr.1, yr.0..yr.1)?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .x_label_formatter(&|v| tick(*v))
        .y_label_formatter(&|v| tick(*v))
        .light_line_style(RGBColor(240, 240, 240))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()?;
    for (k, ser) in series.iter().enumerate() {
        let color = rgb(ser.color);
        for run in finite_runs(&ser.points) {
            if ser.markers {
                chart.draw_series(run.into_iter().map(|p| Circle::new(p, 2, color.filled())))?;
            } else if ser.dashed {
                chart.draw_series(DashedLineSeries::new(run, 6, 4, color.stroke_width(2)))?;
            } else {
                chart.draw_series(LineSeries::new(run, color.stroke_width(2)))?;
            }
        }
        // The legend: a sample of the series and its name, one row per series.
        let y = 40 + 18 * k as i32;
        if ser.markers {
            legend_area.draw(&Circle::new((22, y), 3, color.filled()))?;
        } else if ser.dashed {
            for (from, to) in [(12, 20), (24, 32)] {
                legend_area.draw(&PathElement::new(
                    vec![(from, y), (to, y)],
                    color.stroke_width(2),
                ))?;
            }
        } else {
            legend_area.draw(&PathElement::new(
                vec![(12, y), (32, y)],
                color.stroke_width(2),
            ))?;
        }
        legend_area.draw(&Text::new(
            ser.name.clone(),
            (38, y - 6),
            ("sans-serif", 12).into_font(),
        ))?;
    }
    root.present()?;
    Ok(())
}

/// Renders the plot as an SVG document; `equal_axes` keeps one unit the same length on both axes
/// (for tracks). A plot that cannot be drawn (never expected) is an SVG that says why.
pub fn plot(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    equal_axes: bool,
) -> String {
    let mut svg = String::new();
    let drawn = draw(&mut svg, title, x_label, y_label, series, equal_axes);
    match drawn {
        Ok(()) => {
            if !svg.ends_with('\n') {
                svg.push('\n');
            }
            svg
        }
        Err(e) => {
            let text = e
                .to_string()
                .replace('&', "&amp;")
                .replace('<', "&lt;")
                .replace('>', "&gt;");
            format!(
                "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{WIDTH}\" height=\"{HEIGHT}\">\
                 <text x=\"10\" y=\"20\">plot failed: {text}</text></svg>\n"
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plots_are_well_formed_with_empty_and_degenerate_series() {
        let s = plot(
            "t <1>",
            "x",
            "y",
            &[
                Series {
                    name: "a".into(),
                    points: vec![(0.0, 1.0), (1.0, f64::NAN), (2.0, 3.0)],
                    color: PALETTE[0],
                    markers: false,
                    dashed: true,
                },
                Series {
                    name: "b".into(),
                    points: vec![],
                    color: PALETTE[1],
                    markers: true,
                    dashed: false,
                },
                Series {
                    name: "c".into(),
                    points: vec![(0.5, 2.0), (1.5, 2.5)],
                    color: PALETTE[2],
                    markers: false,
                    dashed: false,
                },
            ],
            true,
        );
        assert!(
            s.starts_with("<svg") && s.trim_end().ends_with("</svg>"),
            "{s}"
        );
        assert!(s.contains("t &lt;1&gt;"), "the title, escaped: {s}");
        assert!(!s.contains("NaN") && !s.contains("plot failed"), "{s}");
        // The legend names the series drawn.
        assert!(
            s.contains("\na\n</text>") && s.contains("\nc\n</text>"),
            "{s}"
        );
    }

    #[test]
    fn tick_labels_have_no_trailing_zeros() {
        assert_eq!(tick(500.0), "500");
        assert_eq!(tick(0.25), "0.25");
        assert_eq!(tick(-1.5), "-1.5");
        assert_eq!(tick(-0.0001), "0");
    }

    #[test]
    fn a_line_breaks_where_a_value_is_not_finite() {
        let runs = finite_runs(&[(0.0, 1.0), (1.0, f64::NAN), (2.0, 3.0), (3.0, 4.0)]);
        assert_eq!(runs, vec![vec![(0.0, 1.0)], vec![(2.0, 3.0), (3.0, 4.0)]]);
    }

    #[test]
    fn equal_axes_give_one_unit_the_same_length_on_both_axes() {
        let s = [Series {
            name: "track".into(),
            points: vec![(0.0, 0.0), (100.0, 10.0)],
            color: PALETTE[0],
            markers: false,
            dashed: false,
        }];
        let ((x0, x1), (y0, y1)) = ranges(&s, true);
        assert!(((x1 - x0) / PLOT_W - (y1 - y0) / PLOT_H).abs() < 1e-12);
        assert!(x0 <= 0.0 && x1 >= 100.0 && y0 <= 0.0 && y1 >= 10.0);
    }
}
