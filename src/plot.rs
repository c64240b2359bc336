//! Minimal SVG line and scatter charts for `edmd plan` reports. No dependencies: a chart is a
//! few hundred lines of text a browser opens.
//!
//! Series are collected through [`Decimated`], which keeps memory bounded on long programs:
//! past its capacity it merges neighbouring points pairwise, keeping in each bucket the point
//! with the largest `|y|`, so peaks (the chord error a machinist looks for) survive.

use std::fmt::Write as _;

use crate::decimal;

/// A bounded series of `(x, y)` points.
#[derive(Debug, Clone)]
pub struct Decimated {
    capacity: usize,
    stride: usize,
    /// The point the open bucket keeps so far (meaningful when `pending_count > 0`), and its
    /// `|y|`, kept so each push compares one number instead of taking two magnitudes.
    pending: (f64, f64),
    pending_magnitude: f64,
    /// Points pushed into the open bucket.
    pending_count: usize,
    points: Vec<(f64, f64)>,
}

impl Decimated {
    pub fn new(capacity: usize) -> Decimated {
        Decimated {
            capacity: capacity.max(16),
            stride: 1,
            pending: (0.0, 0.0),
            pending_magnitude: 0.0,
            pending_count: 0,
            points: Vec::new(),
        }
    }

    /// Inlined: a plan pushes five series a segment, and the call cost as much as the push.
    /// A bucket keeps its first point of the largest `|y|`.
    #[inline]
    pub fn push(&mut self, x: f64, y: f64) {
        if !(x.is_finite() && y.is_finite()) {
            return;
        }
        let magnitude = y.abs();
        if self.pending_count == 0 || magnitude > self.pending_magnitude {
            self.pending = (x, y);
            self.pending_magnitude = magnitude;
        }
        self.pending_count += 1;
        // The kept points grow only here, so only here can they reach the capacity.
        if self.pending_count >= self.stride {
            self.points.push(self.pending);
            self.pending_count = 0;
            if self.points.len() >= self.capacity {
                self.merge_pairs();
            }
        }
    }

    /// Halves the kept points, each pair to its larger magnitude (the later of two equal
    /// ones), and doubles the stride. In place: pair `i` is read before slot `i` is written,
    /// and the buffer keeps its capacity, so the pushes that refill it never reallocate.
    #[cold]
    fn merge_pairs(&mut self) {
        let halves = self.points.len().div_ceil(2);
        for i in 0..halves {
            let pair = &self.points[2 * i..(2 * i + 2).min(self.points.len())];
            self.points[i] = *pair
                .iter()
                .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
                .expect("pairs are non-empty");
        }
        self.points.truncate(halves);
        self.stride *= 2;
    }

    /// The kept points (including a partly filled last bucket).
    pub fn points(&self) -> Vec<(f64, f64)> {
        let mut v = self.points.clone();
        if self.pending_count > 0 {
            v.push(self.pending);
        }
        v
    }
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Style {
    Line,
    /// A dashed line (rapids).
    Dashed,
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
    /// A start point and the direction the path leaves it in (a path plot): a ring and an
    /// arrow.
    pub start: Option<((f64, f64), (f64, f64))>,
    /// A band of states under the plot, on its x axis (the gap state under the feed).
    pub band: Option<Band>,
}

/// A state over x, drawn as a strip of coloured spans under a chart's plot, its states named
/// in the legend.
#[derive(Debug, Clone, Default)]
pub struct Band {
    /// Written left of the strip.
    pub label: String,
    /// Each state's name and colour.
    pub states: Vec<(String, &'static str)>,
    /// `(x, state)` where each state begins; it lasts until the next one (the last until the
    /// data's end).
    pub changes: Vec<(f64, usize)>,
}

/// Height of a [`Band`]'s strip, and the room it takes under the plot with its gap.
const BAND_HEIGHT: f64 = 16.0;
const BAND_ROOM: f64 = 26.0;

/// A point that breaks a [`Style::Line`] or [`Style::Dashed`] series: the next point starts a
/// new stroke.
pub const BREAK: (f64, f64) = (f64::NAN, f64::NAN);

const WIDTH: f64 = 900.0;
const HEIGHT: f64 = 560.0;
const LEFT: f64 = 90.0;
const RIGHT: f64 = 30.0;
/// Room above the plot for the title and, below it, the legend (never over the data).
const TOP: f64 = 72.0;
const BOTTOM: f64 = 60.0;

impl Chart {
    pub fn render(&self) -> String {
        let f = self.frame();
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
        self.grid_svg(&mut svg, &f);
        self.series_svg(&mut svg, &f);
        self.band_svg(&mut svg, &f);
        self.start_svg(&mut svg, &f);
        svg.push_str("</svg>\n");
        svg
    }

    /// The data's extents (and the limits'), padded, made equal in X and Y if asked.
    fn frame(&self) -> Frame {
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
        for (x, _) in self.band.iter().flat_map(|b| b.changes.iter()) {
            x0 = x0.min(*x);
            x1 = x1.max(*x);
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
        let (pw, ph) = (
            WIDTH - LEFT - RIGHT,
            HEIGHT - TOP - BOTTOM - self.band_room(),
        );
        if self.equal_axes {
            let scale = (pw / (x1 - x0)).min(ph / (y1 - y0));
            let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
            let (hx, hy) = (0.5 * pw / scale, 0.5 * ph / scale);
            (x0, x1, y0, y1) = (cx - hx, cx + hx, cy - hy, cy + hy);
        }
        Frame {
            x0,
            x1,
            y0,
            y1,
            pw,
            ph,
        }
    }

    /// The grid, the ticks, the frame, the axis labels and the limit lines.
    fn grid_svg(&self, svg: &mut String, f: &Frame) {
        let (x0, x1, y0, y1, pw, ph) = (f.x0, f.x1, f.y0, f.y1, f.pw, f.ph);
        // Grid and ticks.
        for t in ticks(x0, x1) {
            let x = f.sx(t);
            let _ = writeln!(
                svg,
                r##"<line x1="{x:.1}" y1="{TOP}" x2="{x:.1}" y2="{:.1}" stroke="#ddd"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
                TOP + ph,
                TOP + ph + self.band_room() + 18.0,
                fmt_tick(t)
            );
        }
        for t in ticks(y0, y1) {
            let y = f.sy(t);
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
            let py = f.sy(*y);
            let _ = writeln!(
                svg,
                r##"<line x1="{LEFT}" y1="{py:.1}" x2="{:.1}" y2="{py:.1}" stroke="#c00" stroke-dasharray="6 4"/><text x="{:.1}" y="{:.1}" fill="#c00" text-anchor="end">{}</text>"##,
                LEFT + pw,
                LEFT + pw - 4.0,
                py - 4.0,
                escape(label)
            );
        }
    }

    /// The series, each with its legend entry (between the title and the plot).
    fn series_svg(&self, svg: &mut String, f: &Frame) {
        let places = self.legend_places();
        for (s, &(legend_x, ly)) in self.series.iter().zip(&places) {
            match s.style {
                Style::Line | Style::Dashed => {
                    // Built as bytes through `decimal`: a long plan's path has hundreds of
                    // thousands of coordinates, and `core::fmt` spent more on them than on
                    // the rest of the chart.
                    let mut d = Vec::new();
                    let mut pen_up = true;
                    for &(x, y) in &s.points {
                        if x.is_nan() || y.is_nan() {
                            pen_up = true;
                            continue;
                        }
                        d.push(if pen_up { b'M' } else { b'L' });
                        decimal::push_fixed(&mut d, f.sx(x), 2);
                        d.push(b',');
                        decimal::push_fixed(&mut d, f.sy(y), 2);
                        d.push(b' ');
                        pen_up = false;
                    }
                    let dash = if matches!(s.style, Style::Dashed) {
                        r#" stroke-dasharray="5 4""#
                    } else {
                        ""
                    };
                    svg.push_str(r#"<path d=""#);
                    push_ascii(svg, &d);
                    let _ = writeln!(
                        svg,
                        r#"" fill="none" stroke="{}" stroke-width="1.2"{dash}/>"#,
                        s.color
                    );
                }
                Style::Dots => {
                    // As bytes through `decimal` too: a chord-error chart has a dot a
                    // segment, up to the decimation's cap, two numbers each.
                    let mut dots = Vec::new();
                    for &(x, y) in &s.points {
                        dots.extend_from_slice(br#"<circle cx=""#);
                        decimal::push_fixed(&mut dots, f.sx(x), 2);
                        dots.extend_from_slice(br#"" cy=""#);
                        decimal::push_fixed(&mut dots, f.sy(y), 2);
                        dots.extend_from_slice(br#"" r="1.6" fill=""#);
                        dots.extend_from_slice(s.color.as_bytes());
                        dots.extend_from_slice(b"\"/>\n");
                    }
                    push_ascii(svg, &dots);
                }
            }
            let _ = writeln!(
                svg,
                r#"<rect x="{:.1}" y="{:.1}" width="12" height="4" fill="{}"/><text x="{:.1}" y="{:.1}">{}</text>"#,
                legend_x,
                ly - 4.0,
                s.color,
                legend_x + 18.0,
                ly,
                escape(&s.name)
            );
        }
    }

    /// Where each series' legend entry goes: rows between the title and the plot, left to
    /// right, a second row when the first is full, so no entry runs off the right edge.
    fn legend_places(&self) -> Vec<(f64, f64)> {
        let names: Vec<&str> = self.legend_names().collect();
        let width = |name: &str| 40.0 + 7.0 * name.chars().count() as f64;
        let fits_one = LEFT + names.iter().map(|n| width(n)).sum::<f64>() <= WIDTH - RIGHT + 20.0;
        let (mut x, mut y) = (LEFT, if fits_one { TOP - 12.0 } else { TOP - 26.0 });
        let mut places = Vec::with_capacity(names.len());
        for name in names {
            if x > LEFT && x + width(name) > WIDTH - RIGHT + 20.0 {
                x = LEFT;
                y += 14.0;
            }
            places.push((x, y));
            x += width(name);
        }
        places
    }

    /// The legend's entries: the series, then the band's states.
    fn legend_names(&self) -> impl Iterator<Item = &str> {
        let series = self.series.iter().map(|s| s.name.as_str());
        let states = self
            .band
            .iter()
            .flat_map(|b| b.states.iter().map(|s| s.0.as_str()));
        series.chain(states)
    }

    fn band_room(&self) -> f64 {
        if self.band.is_some() { BAND_ROOM } else { 0.0 }
    }

    /// The band: a span per state from where it begins to where the next does, its label at
    /// the left, its states in the legend after the series.
    fn band_svg(&self, svg: &mut String, f: &Frame) {
        let Some(band) = &self.band else {
            return;
        };
        let top = TOP + f.ph + (BAND_ROOM - BAND_HEIGHT) / 2.0;
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"#,
            LEFT - 6.0,
            top + BAND_HEIGHT - 4.0,
            escape(&band.label)
        );
        for (k, &(x, state)) in band.changes.iter().enumerate() {
            let end = band.changes.get(k + 1).map_or(f.x1, |c| c.0);
            let (a, b) = (f.sx(x.max(f.x0)), f.sx(end.min(f.x1)));
            if let Some((_, color)) = band.states.get(state)
                && b > a
            {
                let _ = writeln!(
                    svg,
                    r#"<rect x="{a:.2}" y="{top:.1}" width="{:.2}" height="{BAND_HEIGHT}" fill="{color}"/>"#,
                    (b - a).max(0.5)
                );
            }
        }
        let _ = writeln!(
            svg,
            r#"<rect x="{LEFT}" y="{top:.1}" width="{:.1}" height="{BAND_HEIGHT}" fill="none" stroke="black"/>"#,
            f.pw
        );
        let places = self.legend_places();
        for ((name, color), &(lx, ly)) in band.states.iter().zip(&places[self.series.len()..]) {
            let _ = writeln!(
                svg,
                r#"<rect x="{lx:.1}" y="{:.1}" width="12" height="8" fill="{color}"/><text x="{:.1}" y="{ly:.1}">{}</text>"#,
                ly - 8.0,
                lx + 18.0,
                escape(name)
            );
        }
    }

    /// The start marker: a circle and an arrow along the first move.
    fn start_svg(&self, svg: &mut String, f: &Frame) {
        if let Some(((x, y), (dx, dy))) = self.start {
            let (px, py) = (f.sx(x), f.sy(y));
            // Screen y grows downwards.
            let norm = (dx * dx + dy * dy).sqrt();
            let (ux, uy) = if norm > 0.0 {
                (dx / norm, -dy / norm)
            } else {
                (1.0, 0.0)
            };
            let (tx, ty) = (px + 34.0 * ux, py + 34.0 * uy);
            let (bx, by) = (tx - 9.0 * ux, ty - 9.0 * uy);
            let (nx, ny) = (-uy * 4.5, ux * 4.5);
            let _ = writeln!(
                svg,
                r##"<circle cx="{px:.2}" cy="{py:.2}" r="5" fill="none" stroke="#1f8f3f" stroke-width="2"/><line x1="{px:.2}" y1="{py:.2}" x2="{bx:.2}" y2="{by:.2}" stroke="#1f8f3f" stroke-width="2"/><polygon points="{tx:.2},{ty:.2} {:.2},{:.2} {:.2},{:.2}" fill="#1f8f3f"/><text x="{:.2}" y="{:.2}" fill="#1f8f3f">start</text>"##,
                bx + nx,
                by + ny,
                bx - nx,
                by - ny,
                px + 8.0,
                py - 8.0
            );
        }
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

/// Appends text built as bytes through [`decimal`] (ASCII throughout) to the SVG. The UTF-8
/// check passes over ASCII a word at a time; a lossy conversion went byte by byte.
fn push_ascii(svg: &mut String, bytes: &[u8]) {
    match std::str::from_utf8(bytes) {
        Ok(text) => svg.push_str(text),
        Err(_) => svg.push_str(&String::from_utf8_lossy(bytes)),
    }
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// The plot area and the data range it shows.
struct Frame {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
    /// Plot width and height (px).
    pw: f64,
    ph: f64,
}

impl Frame {
    fn sx(&self, x: f64) -> f64 {
        LEFT + (x - self.x0) / (self.x1 - self.x0) * self.pw
    }

    fn sy(&self, y: f64) -> f64 {
        TOP + self.ph - (y - self.y0) / (self.y1 - self.y0) * self.ph
    }
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
    fn merging_in_place_keeps_each_pairs_larger_point() {
        // Against the pairs merged into a new vector: odd lengths, equal magnitudes (the
        // later point is kept), signs.
        let mut rng = crate::rng::SplitMix64::new(5);
        for len in 0..40 {
            let points: Vec<(f64, f64)> = (0..len)
                .map(|i| (i as f64, rng.below(5) as f64 - 2.0))
                .collect();
            let want: Vec<(f64, f64)> = points
                .chunks(2)
                .map(|c| {
                    *c.iter()
                        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
                        .unwrap()
                })
                .collect();
            let mut d = Decimated::new(16);
            d.points = points;
            let capacity = d.points.capacity();
            d.merge_pairs();
            assert_eq!(d.points, want, "{len} points");
            assert_eq!(d.points.capacity(), capacity);
            assert_eq!(d.stride, 2);
        }
    }

    /// A bucket of `stride` finite pushes keeps its first point of the largest `|y|`; a full
    /// series halves its points pairwise. Written plainly, against which `push` is held.
    struct PlainSeries {
        capacity: usize,
        stride: usize,
        bucket: Vec<(f64, f64)>,
        points: Vec<(f64, f64)>,
    }

    impl PlainSeries {
        fn push(&mut self, x: f64, y: f64) {
            if !x.is_finite() || !y.is_finite() {
                return;
            }
            self.bucket.push((x, y));
            if self.bucket.len() == self.stride {
                let kept = self.bucket.iter().fold(self.bucket[0], |best, &p| {
                    if p.1.abs() > best.1.abs() { p } else { best }
                });
                self.points.push(kept);
                self.bucket.clear();
                if self.points.len() == self.capacity {
                    self.points = self
                        .points
                        .chunks(2)
                        .map(|c| {
                            if c[1].1.abs() >= c[0].1.abs() {
                                c[1]
                            } else {
                                c[0]
                            }
                        })
                        .collect();
                    self.stride *= 2;
                }
            }
        }

        fn points(&self) -> Vec<(f64, f64)> {
            let mut v = self.points.clone();
            if let Some(&first) = self.bucket.first() {
                v.push(self.bucket.iter().fold(first, |best, &p| {
                    if p.1.abs() > best.1.abs() { p } else { best }
                }));
            }
            v
        }
    }

    #[test]
    fn decimation_keeps_what_plain_buckets_keep() {
        // Ties of magnitude (small integers of both signs), non-finite values that must be
        // skipped, and lengths that end mid-bucket after several merges.
        let mut rng = crate::rng::SplitMix64::new(11);
        for len in [0, 1, 15, 16, 17, 100, 1_000, 4_099] {
            let mut d = Decimated::new(16);
            let mut plain = PlainSeries {
                capacity: 16,
                stride: 1,
                bucket: Vec::new(),
                points: Vec::new(),
            };
            for i in 0..len {
                let y = match rng.below(20) {
                    0 => f64::NAN,
                    1 => f64::NEG_INFINITY,
                    k => k as f64 % 7.0 - 3.0,
                };
                let x = if rng.below(50) == 0 {
                    f64::INFINITY
                } else {
                    i as f64
                };
                d.push(x, y);
                plain.push(x, y);
                assert_eq!(d.points(), plain.points(), "{len} points, after {i}");
            }
        }
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
