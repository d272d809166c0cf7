//! Time-against-error charts for the benchmark reports: log-log line charts as self-contained
//! SVG text, with the default of each knob marked and optional target lines.

#![warn(missing_docs)]

use std::fmt::Write as _;

/// One curve: points (x, y) in the order they are joined, and which one is the default.
#[derive(Clone, Debug, Default)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Points (x, y), joined in this order; both coordinates must be positive (log axes).
    pub points: Vec<(f64, f64)>,
    /// Index into `points` of the knob's default, drawn as a ring and labelled "default".
    pub default: Option<usize>,
}

/// A chart: both axes logarithmic (decades from the data), horizontal target lines.
#[derive(Clone, Debug, Default)]
pub struct Chart {
    /// Chart title.
    pub title: String,
    /// Horizontal axis label, with its unit.
    pub x_label: String,
    /// Vertical axis label, with its unit.
    pub y_label: String,
    /// The curves.
    pub series: Vec<Series>,
    /// (y, label) lines, e.g. an accuracy goal.
    pub targets: Vec<(f64, String)>,
}

const COLOURS: [&str; 8] = [
    "#1f6fb4", "#e08a1e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf",
];

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Whole decades covering the positive, finite values of `v` (at least one decade).
fn decades(v: impl Iterator<Item = f64>) -> (i32, i32) {
    let (lo, hi) = v
        .filter(|x| x.is_finite() && *x > 0.0)
        .fold((f64::MAX, f64::MIN), |(a, b), x| {
            (a.min(x.log10()), b.max(x.log10()))
        });
    if lo > hi {
        return (0, 1);
    }
    let (lo, hi) = (lo.floor() as i32, hi.ceil() as i32);
    (lo, hi.max(lo + 1))
}

impl Chart {
    /// The chart as SVG text (720×440).
    pub fn to_svg(&self) -> String {
        let (w, h, left, right, top, bottom) = (720.0, 440.0, 70.0, 190.0, 40.0, 50.0);
        let xs = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0));
        let ys = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.1))
            .chain(self.targets.iter().map(|t| t.0));
        let (x0, x1) = decades(xs);
        let (y0, y1) = decades(ys);
        let px = |x: f64| {
            left + (x.max(1e-300).log10() - x0 as f64) / (x1 - x0) as f64 * (w - left - right)
        };
        let py = |y: f64| {
            h - bottom - (y.max(1e-300).log10() - y0 as f64) / (y1 - y0) as f64 * (h - top - bottom)
        };
        let mut s = String::new();
        let _ = writeln!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="11">"#
        );
        let _ = writeln!(s, r#"<rect width="{w}" height="{h}" fill="white"/>"#);
        let _ = writeln!(
            s,
            r#"<text x="{}" y="22" text-anchor="middle" font-size="13">{}</text>"#,
            (left + w - right) / 2.0,
            escape(&self.title)
        );
        for e in x0..=x1 {
            let x = px(10f64.powi(e));
            let _ = writeln!(
                s,
                r##"<line x1="{x:.1}" y1="{top}" x2="{x:.1}" y2="{}" stroke="#ddd"/><text x="{x:.1}" y="{}" text-anchor="middle">1e{e}</text>"##,
                h - bottom,
                h - bottom + 14.0
            );
        }
        for e in y0..=y1 {
            let y = py(10f64.powi(e));
            let _ = writeln!(
                s,
                r##"<line x1="{left}" y1="{y:.1}" x2="{}" y2="{y:.1}" stroke="#ddd"/><text x="{}" y="{:.1}" text-anchor="end">1e{e}</text>"##,
                w - right,
                left - 5.0,
                y + 4.0
            );
        }
        for (y, label) in &self.targets {
            let yy = py(*y);
            let _ = writeln!(
                s,
                r##"<line x1="{left}" y1="{yy:.1}" x2="{}" y2="{yy:.1}" stroke="#c33" stroke-dasharray="5 3"/><text x="{}" y="{:.1}" fill="#c33" text-anchor="end">{}</text>"##,
                w - right,
                w - right - 4.0,
                yy - 4.0,
                escape(label)
            );
        }
        for (k, series) in self.series.iter().enumerate() {
            let c = COLOURS[k % COLOURS.len()];
            let pts: Vec<String> = series
                .points
                .iter()
                .filter(|p| p.0 > 0.0 && p.1 > 0.0)
                .map(|p| format!("{:.1},{:.1}", px(p.0), py(p.1)))
                .collect();
            let _ = writeln!(
                s,
                r#"<polyline points="{}" fill="none" stroke="{c}" stroke-width="1.8"/>"#,
                pts.join(" ")
            );
            for (i, p) in series
                .points
                .iter()
                .enumerate()
                .filter(|(_, p)| p.0 > 0.0 && p.1 > 0.0)
            {
                let _ = writeln!(
                    s,
                    r#"<circle cx="{:.1}" cy="{:.1}" r="3" fill="{c}"/>"#,
                    px(p.0),
                    py(p.1)
                );
                if series.default == Some(i) {
                    let _ = writeln!(
                        s,
                        r#"<circle cx="{:.1}" cy="{:.1}" r="7" fill="none" stroke="{c}" stroke-width="2"/><text x="{:.1}" y="{:.1}" fill="{c}">default</text>"#,
                        px(p.0),
                        py(p.1),
                        px(p.0) + 9.0,
                        py(p.1) - 8.0
                    );
                }
            }
            let _ = writeln!(
                s,
                r#"<rect x="{}" y="{}" width="12" height="3" fill="{c}"/><text x="{}" y="{}">{}</text>"#,
                w - right + 12.0,
                top + 16.0 * k as f64 + 4.0,
                w - right + 30.0,
                top + 16.0 * k as f64 + 9.0,
                escape(&series.label)
            );
        }
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{}" text-anchor="middle">{} (log)</text>"#,
            (left + w - right) / 2.0,
            h - 12.0,
            escape(&self.x_label)
        );
        let _ = writeln!(
            s,
            r#"<text x="16" y="{0}" transform="rotate(-90 16 {0})" text-anchor="middle">{1} (log)</text>"#,
            (top + h - bottom) / 2.0,
            escape(&self.y_label)
        );
        s.push_str("</svg>\n");
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn svg_has_every_series_point_and_default_ring() {
        let chart = Chart {
            title: "t <a>".into(),
            x_label: "time (s)".into(),
            y_label: "error".into(),
            series: vec![Series {
                label: "fis".into(),
                points: vec![(0.01, 0.1), (0.1, 0.01), (1.0, 0.001)],
                default: Some(1),
            }],
            targets: vec![(0.005, "goal".into())],
        };
        let svg = chart.to_svg();
        assert_eq!(svg.matches("<circle").count(), 4, "3 points and 1 ring");
        assert!(svg.contains("t &lt;a&gt;") && svg.contains(">default<") && svg.contains(">goal<"));
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
    }

    #[test]
    fn empty_and_nonpositive_data_still_draw() {
        let chart = Chart {
            series: vec![Series {
                label: "x".into(),
                points: vec![(0.0, -1.0)],
                default: None,
            }],
            ..Default::default()
        };
        assert!(chart.to_svg().contains("</svg>"));
    }
}
