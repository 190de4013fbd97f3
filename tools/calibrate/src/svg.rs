//! A small SVG line and scatter plot (no dependencies): axes with rounded ticks, a legend, lines
//! or points per series. Enough for the calibration report's figures.

use std::fmt::Write as _;

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

fn nice_step(span: f64) -> f64 {
    let raw = span / 6.0;
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    let nice = if f < 1.5 {
        1.0
    } else if f < 3.5 {
        2.0
    } else if f < 7.5 {
        5.0
    } else {
        10.0
    };
    nice * mag
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Renders the plot; `equal_axes` keeps one metre the same length on both axes (for tracks).
// Long on purpose: the hand-written SVG plot (axes, ticks, series, legend); the architecture issue
// replaces it with a maintained plotting crate.
pub fn plot(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    equal_axes: bool,
) -> String {
    let (w, h) = (760.0, 520.0);
    let (left, right, top, bottom) = (80.0, 180.0, 40.0, 60.0);
    let (pw, ph) = (w - left - right, h - top - bottom);
    let finite = series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|(x, y)| x.is_finite() && y.is_finite());
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for (x, y) in finite {
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
        let sx = (x1 - x0) / pw;
        let sy = (y1 - y0) / ph;
        let s = sx.max(sy);
        let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        (x0, x1) = (cx - s * pw / 2.0, cx + s * pw / 2.0);
        (y0, y1) = (cy - s * ph / 2.0, cy + s * ph / 2.0);
    }
    let px = |x: f64| left + (x - x0) / (x1 - x0) * pw;
    let py = |y: f64| top + ph - (y - y0) / (y1 - y0) * ph;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="{w}" height="{h}" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="22" text-anchor="middle" font-size="15">{}</text>"#,
        left + pw / 2.0,
        escape(title)
    );
    let _ = writeln!(
        s,
        r##"<rect x="{left}" y="{top}" width="{pw}" height="{ph}" fill="none" stroke="#444"/>"##
    );
    for (lo, hi, vertical) in [(x0, x1, true), (y0, y1, false)] {
        let step = nice_step(hi - lo);
        let mut t = (lo / step).ceil() * step;
        while t <= hi + 1e-9 * step {
            let label = if step >= 1.0 {
                format!("{t:.0}")
            } else {
                let digits = (-step.log10().floor()) as usize;
                format!("{t:.digits$}")
            };
            if vertical {
                let x = px(t);
                let _ = writeln!(
                    s,
                    r##"<line x1="{x:.1}" y1="{top}" x2="{x:.1}" y2="{}" stroke="#ddd"/><text x="{x:.1}" y="{}" text-anchor="middle">{label}</text>"##,
                    top + ph,
                    top + ph + 16.0
                );
            } else {
                let y = py(t);
                let _ = writeln!(
                    s,
                    r##"<line x1="{left}" y1="{y:.1}" x2="{}" y2="{y:.1}" stroke="#ddd"/><text x="{}" y="{:.1}" text-anchor="end">{label}</text>"##,
                    left + pw,
                    left - 6.0,
                    y + 4.0
                );
            }
            t += step;
        }
    }
    let _ = writeln!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
        left + pw / 2.0,
        h - 18.0,
        escape(x_label)
    );
    let _ = writeln!(
        s,
        r#"<text x="18" y="{}" text-anchor="middle" transform="rotate(-90 18 {})">{}</text>"#,
        top + ph / 2.0,
        top + ph / 2.0,
        escape(y_label)
    );
    for (k, ser) in series.iter().enumerate() {
        let pts: Vec<(f64, f64)> = ser
            .points
            .iter()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|(x, y)| (px(*x), py(*y)))
            .collect();
        if ser.markers {
            for (x, y) in &pts {
                let _ = writeln!(
                    s,
                    r#"<circle cx="{x:.1}" cy="{y:.1}" r="2" fill="{}"/>"#,
                    ser.color
                );
            }
        } else if !pts.is_empty() {
            let d: Vec<String> = pts.iter().map(|(x, y)| format!("{x:.1},{y:.1}")).collect();
            let dash = if ser.dashed {
                r#" stroke-dasharray="6 4""#
            } else {
                ""
            };
            let _ = writeln!(
                s,
                r#"<polyline fill="none" stroke="{}" stroke-width="1.5"{dash} points="{}"/>"#,
                ser.color,
                d.join(" ")
            );
        }
        let ly = top + 10.0 + 18.0 * k as f64;
        let lx = left + pw + 12.0;
        if ser.markers {
            let _ = writeln!(
                s,
                r#"<circle cx="{}" cy="{ly}" r="3" fill="{}"/>"#,
                lx + 10.0,
                ser.color
            );
        } else {
            let dash = if ser.dashed {
                r#" stroke-dasharray="6 4""#
            } else {
                ""
            };
            let _ = writeln!(
                s,
                r#"<line x1="{lx}" y1="{ly}" x2="{}" y2="{ly}" stroke="{}" stroke-width="2"{dash}/>"#,
                lx + 20.0,
                ser.color
            );
        }
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{}">{}</text>"#,
            lx + 26.0,
            ly + 4.0,
            escape(&ser.name)
        );
    }
    s.push_str("</svg>\n");
    s
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
            ],
            true,
        );
        assert!(s.starts_with("<svg") && s.ends_with("</svg>\n"));
        assert!(s.contains("t &lt;1&gt;") && !s.contains("NaN"));
    }
}
