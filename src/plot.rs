//! Minimal SVG line and scatter charts for `edmd plan` reports. No dependencies: a chart is a
//! few hundred lines of text a browser opens.
//!
//! Series are collected through [`Decimated`], which keeps memory bounded on long programs:
//! past its capacity it merges neighbouring points pairwise, keeping in each bucket the point
//! with the largest `|y|`, so peaks (the chord error a machinist looks for) survive.

use std::fmt::Write as _;

/// A bounded series of `(x, y)` points.
#[derive(Debug, Clone)]
pub struct Decimated {
    capacity: usize,
    stride: usize,
    pending: Option<(f64, f64)>,
    pending_count: usize,
    points: Vec<(f64, f64)>,
}

impl Decimated {
    pub fn new(capacity: usize) -> Decimated {
        Decimated {
            capacity: capacity.max(16),
            stride: 1,
            pending: None,
            pending_count: 0,
            points: Vec::new(),
        }
    }

    pub fn push(&mut self, x: f64, y: f64) {
        if !(x.is_finite() && y.is_finite()) {
            return;
        }
        self.pending = match self.pending {
            Some(p) if p.1.abs() >= y.abs() => Some(p),
            _ => Some((x, y)),
        };
        self.pending_count += 1;
        if self.pending_count >= self.stride {
            self.flush_pending();
        }
        if self.points.len() >= self.capacity {
            let merged: Vec<(f64, f64)> = self
                .points
                .chunks(2)
                .map(|c| {
                    *c.iter()
                        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
                        .expect("chunks are non-empty")
                })
                .collect();
            self.points = merged;
            self.stride *= 2;
        }
    }

    fn flush_pending(&mut self) {
        if let Some(p) = self.pending.take() {
            self.points.push(p);
        }
        self.pending_count = 0;
    }

    /// The kept points (including a partly filled last bucket).
    pub fn points(&self) -> Vec<(f64, f64)> {
        let mut v = self.points.clone();
        v.extend(self.pending);
        v
    }
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Style {
    Line,
    Dots,
}

#[derive(Debug, Clone)]
pub struct Series {
    pub name: String,
    pub color: &'static str,
    pub style: Style,
    pub points: Vec<(f64, f64)>,
}

/// A chart: series, optional horizontal reference lines (limits), labels.
#[derive(Debug, Clone, Default)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    /// Horizontal reference lines `(y, label)`, drawn dashed (tolerances, limits).
    pub limits: Vec<(f64, String)>,
    /// Same scale on both axes (a path plot).
    pub equal_axes: bool,
}

const WIDTH: f64 = 900.0;
const HEIGHT: f64 = 560.0;
const LEFT: f64 = 90.0;
const RIGHT: f64 = 30.0;
const TOP: f64 = 50.0;
const BOTTOM: f64 = 60.0;

impl Chart {
    pub fn render(&self) -> String {
        let pts = self.series.iter().flat_map(|s| s.points.iter().copied());
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for (x, y) in pts {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        for (y, _) in &self.limits {
            y0 = y0.min(*y);
            y1 = y1.max(*y);
        }
        if x0 > x1 {
            (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
        }
        if x1 - x0 <= 0.0 {
            x1 = x0 + 1.0;
        }
        if y1 - y0 <= 0.0 {
            y1 = y0 + 1.0;
        }
        let pad = 0.04 * (y1 - y0);
        (y0, y1) = (y0 - pad, y1 + pad);
        let (pw, ph) = (WIDTH - LEFT - RIGHT, HEIGHT - TOP - BOTTOM);
        if self.equal_axes {
            let scale = (pw / (x1 - x0)).min(ph / (y1 - y0));
            let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
            let (hx, hy) = (0.5 * pw / scale, 0.5 * ph / scale);
            (x0, x1, y0, y1) = (cx - hx, cx + hx, cy - hy, cy + hy);
        }
        let sx = |x: f64| LEFT + (x - x0) / (x1 - x0) * pw;
        let sy = |y: f64| TOP + ph - (y - y0) / (y1 - y0) * ph;

        let mut svg = String::new();
        let _ = writeln!(
            svg,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{HEIGHT}" viewBox="0 0 {WIDTH} {HEIGHT}" font-family="sans-serif" font-size="12">"#
        );
        let _ = writeln!(svg, r#"<rect width="100%" height="100%" fill="white"/>"#);
        let _ = writeln!(
            svg,
            r#"<text x="{}" y="28" font-size="16" text-anchor="middle">{}</text>"#,
            WIDTH / 2.0,
            escape(&self.title)
        );
        // Grid and ticks.
        for t in ticks(x0, x1) {
            let x = sx(t);
            let _ = writeln!(
                svg,
                r##"<line x1="{x:.1}" y1="{TOP}" x2="{x:.1}" y2="{:.1}" stroke="#ddd"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
                TOP + ph,
                TOP + ph + 18.0,
                fmt_tick(t)
            );
        }
        for t in ticks(y0, y1) {
            let y = sy(t);
            let _ = writeln!(
                svg,
                r##"<line x1="{LEFT}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
                LEFT + pw,
                LEFT - 6.0,
                y + 4.0,
                fmt_tick(t)
            );
        }
        let _ = writeln!(
            svg,
            r#"<rect x="{LEFT}" y="{TOP}" width="{pw}" height="{ph}" fill="none" stroke="black"/>"#
        );
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            LEFT + pw / 2.0,
            HEIGHT - 15.0,
            escape(&self.x_label)
        );
        let _ = writeln!(
            svg,
            r#"<text x="20" y="{:.1}" text-anchor="middle" transform="rotate(-90 20 {:.1})">{}</text>"#,
            TOP + ph / 2.0,
            TOP + ph / 2.0,
            escape(&self.y_label)
        );
        for (y, label) in &self.limits {
            let py = sy(*y);
            let _ = writeln!(
                svg,
                r##"<line x1="{LEFT}" y1="{py:.1}" x2="{:.1}" y2="{py:.1}" stroke="#c00" stroke-dasharray="6 4"/><text x="{:.1}" y="{:.1}" fill="#c00" text-anchor="end">{}</text>"##,
                LEFT + pw,
                LEFT + pw - 4.0,
                py - 4.0,
                escape(label)
            );
        }
        for (i, s) in self.series.iter().enumerate() {
            match s.style {
                Style::Line => {
                    let mut d = String::new();
                    for (k, &(x, y)) in s.points.iter().enumerate() {
                        let _ = write!(
                            d,
                            "{}{:.2},{:.2} ",
                            if k == 0 { "M" } else { "L" },
                            sx(x),
                            sy(y)
                        );
                    }
                    let _ = writeln!(
                        svg,
                        r#"<path d="{d}" fill="none" stroke="{}" stroke-width="1.2"/>"#,
                        s.color
                    );
                }
                Style::Dots => {
                    for &(x, y) in &s.points {
                        let _ = writeln!(
                            svg,
                            r#"<circle cx="{:.2}" cy="{:.2}" r="1.6" fill="{}"/>"#,
                            sx(x),
                            sy(y),
                            s.color
                        );
                    }
                }
            }
            let ly = TOP + 16.0 + 16.0 * i as f64;
            let _ = writeln!(
                svg,
                r#"<rect x="{:.1}" y="{:.1}" width="12" height="4" fill="{}"/><text x="{:.1}" y="{:.1}">{}</text>"#,
                LEFT + 10.0,
                ly - 6.0,
                s.color,
                LEFT + 28.0,
                ly,
                escape(&s.name)
            );
        }
        svg.push_str("</svg>\n");
        svg
    }
}

/// About six "nice" tick values (1, 2, 5 × 10^k) covering `[lo, hi]`.
fn ticks(lo: f64, hi: f64) -> Vec<f64> {
    let raw = (hi - lo) / 6.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut out = vec![];
    while t <= hi + 1e-9 * step && out.len() < 50 {
        out.push(if t.abs() < 1e-12 * step { 0.0 } else { t });
        t += step;
    }
    out
}

fn fmt_tick(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{v:.1e}")
    } else {
        let s = format!("{v:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimation_is_bounded_and_keeps_the_peak() {
        let mut d = Decimated::new(100);
        for i in 0..100_000 {
            let y = if i == 54_321 {
                7.0
            } else {
                (i % 10) as f64 * 0.1
            };
            d.push(i as f64, y);
        }
        let pts = d.points();
        assert!(pts.len() <= 101, "{}", pts.len());
        assert!(pts.iter().any(|&(x, y)| y == 7.0 && x == 54_321.0));
    }

    #[test]
    fn ticks_are_nice() {
        assert_eq!(
            ticks(0.0, 1.0),
            vec![0.0, 0.2, 0.4, 0.6000000000000001, 0.8, 1.0]
        );
        assert_eq!(fmt_tick(0.6000000000000001), "0.6");
        assert_eq!(fmt_tick(2.5e-7), "2.5e-7");
    }

    #[test]
    fn renders_a_valid_looking_document() {
        let chart = Chart {
            title: "a < b".into(),
            series: vec![Series {
                name: "s".into(),
                color: "blue",
                style: Style::Line,
                points: vec![(0.0, 0.0), (1.0, 2.0)],
            }],
            limits: vec![(1.5, "limit".into())],
            ..Chart::default()
        };
        let svg = chart.render();
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("a &lt; b") && svg.contains("<path d=\"M"));
    }
}
