//! The files `edmd plan` writes: `summary.json`, `summary.txt` and the SVG charts (path with
//! rapids and the start, chord error, feed, tangential acceleration, the fluctuation in period
//! mode, Z along the path on a machine with Z; on a four-axis wire machine the upper guide's
//! path over the lower one's and the wire's angle along the path).

use std::path::Path;

use super::{Collector, PLOT_POINTS, PlanError, PlanSummary, io_err};
use crate::geometry::Point;
use crate::plot::{Chart, Decimated, Series, Style};
use crate::preprocess::PlanSettings;
use crate::vocab::{Axis, Guides};

pub(super) fn write_reports(
    out_dir: &Path,
    summary: &PlanSummary,
    c: &Collector,
    settings: &PlanSettings,
) -> Result<(), PlanError> {
    let write = |file: &str, text: &str| {
        let path = out_dir.join(file);
        std::fs::write(&path, text).map_err(io_err(&path))
    };
    let json = serde_json::to_string_pretty(summary).expect("summary serialises");
    write("summary.json", &(json + "\n"))?;
    write("summary.txt", &summary.text())?;
    let series = |name: &str, color: &'static str, style: Style, d: &Decimated| Series {
        name: name.into(),
        color,
        style,
        points: d.points(),
    };
    let mode = &summary.segmentation;
    write("path.svg", &path_chart(summary, c).render())?;
    write(
        "chord_error.svg",
        &Chart {
            title: format!("True chord error per segment ({mode} mode)"),
            x_label: "path length (mm)".into(),
            y_label: "chord error (mm)".into(),
            series: vec![series("chord error", "#1f5fbf", Style::Dots, &c.chord)],
            limits: vec![(settings.tolerance_mm, "tolerance".into())],
            ..Chart::default()
        }
        .render(),
    )?;
    let feed = series("feed", "#1f8f3f", Style::Line, &c.feed);
    write(
        "feed.svg",
        &feed_chart(feed, settings.max_feed_mm_per_s).render(),
    )?;
    let a = settings.max_tangential_accel_mm_per_s2;
    write(
        "tangential_accel.svg",
        &Chart {
            title: "Tangential acceleration".into(),
            x_label: "time (s)".into(),
            y_label: "a_T (mm/s²)".into(),
            series: vec![series("a_T", "#bf5f1f", Style::Line, &c.accel)],
            limits: vec![(a, "+a_T limit".into()), (-a, "-a_T limit".into())],
            ..Chart::default()
        }
        .render(),
    )?;
    // The fluctuation is a period-mode figure: in chord mode there is none to draw, so no
    // chart (and none left over from an earlier period-mode plan in the same directory).
    let fluctuation = out_dir.join("fluctuation.svg");
    if c.period_mode {
        write(
            "fluctuation.svg",
            &Chart {
                title: "Feed fluctuation per period (Jin, Zhu & Li, eq. 16)".into(),
                x_label: "time (s)".into(),
                y_label: "|L - ΔL| / ΔL".into(),
                series: vec![series("fluctuation", "#7f1fbf", Style::Dots, &c.fluct)],
                limits: vec![(
                    settings.fluctuation_tolerance,
                    "fluctuation tolerance".into(),
                )],
                ..Chart::default()
            }
            .render(),
        )?;
    } else if fluctuation.exists() {
        std::fs::remove_file(&fluctuation).map_err(io_err(&fluctuation))?;
    }
    if let Some(wire) = &c.wire {
        write("wire_angle.svg", &wire.angle_chart().render())?;
    }
    // A path plot shows X and Y; Z gets its own chart against the path length.
    if let Some(z) = &c.z {
        write(
            "path_z.svg",
            &Chart {
                title: "Z along the path".into(),
                x_label: "path length (mm)".into(),
                y_label: "Z (mm)".into(),
                series: vec![series("Z", "#1f5fbf", Style::Line, z)],
                ..Chart::default()
            }
            .render(),
        )?;
    }
    Ok(())
}

/// The path in the XY plane, the segment ends on it and the rapids.
fn path_chart(summary: &PlanSummary, c: &Collector) -> Chart {
    let path_points = c.path.points();
    let mut chart = Chart {
        title: format!("Path and segment points ({} segments)", summary.segments),
        x_label: "X (mm)".into(),
        y_label: "Y (mm)".into(),
        series: vec![
            Series {
                name: "path".into(),
                color: "#999",
                style: Style::Line,
                points: path_points.clone(),
            },
            Series {
                name: "segment ends".into(),
                color: "#1f5fbf",
                style: Style::Dots,
                points: path_points,
            },
            Series {
                name: "rapids (G0)".into(),
                color: "#d08000",
                style: Style::Dashed,
                points: c.rapids.clone(),
            },
        ],
        equal_axes: true,
        start: c.start.map(|p| (p, c.direction.unwrap_or((1.0, 0.0)))),
        ..Chart::default()
    };
    if let Some(wire) = &c.wire {
        // A top view: the upper guide's path over the lower one's.
        chart.title = format!(
            "Lower (X/Y) and upper (X+U/Y+V) guide paths ({} segments)",
            summary.segments
        );
        chart.series.insert(
            1,
            Series {
                name: "upper guide".into(),
                color: "#bf1f5f",
                style: Style::Line,
                points: wire.upper.points(),
            },
        );
    }
    chart
}

/// What a plan draws of a four-axis wire machine (X, Y, U and V): the upper guide's path
/// (X + U, Y + V) and the wire's angle from vertical along the path.
#[derive(Debug)]
pub(super) struct WireView {
    axes: [usize; 4],
    span_mm: f64,
    upper: Decimated,
    angle: Decimated,
}

impl WireView {
    pub(super) fn new(axes: &[Axis], guides: Guides) -> Option<WireView> {
        let index = |a: Axis| axes.iter().position(|&x| x == a);
        Some(WireView {
            axes: [
                index(Axis::X)?,
                index(Axis::Y)?,
                index(Axis::U)?,
                index(Axis::V)?,
            ],
            span_mm: guides.span_mm(),
            upper: Decimated::new(PLOT_POINTS),
            angle: Decimated::new(PLOT_POINTS),
        })
    }

    /// A segment ending at `end`, `s` mm along the path.
    pub(super) fn push(&mut self, s: f64, end: &Point) {
        let [x, y, u, v] = self.axes;
        self.upper.push(end[x] + end[u], end[y] + end[v]);
        let lean = end[u].hypot(end[v]);
        self.angle
            .push(s, (lean / self.span_mm).atan().to_degrees());
    }

    fn angle_chart(&self) -> Chart {
        Chart {
            title: "The wire's angle from vertical".into(),
            x_label: "path length (mm)".into(),
            y_label: "angle (°)".into(),
            series: vec![Series {
                name: "angle".into(),
                color: "#bf1f5f",
                style: Style::Line,
                points: self.angle.points(),
            }],
            ..Chart::default()
        }
    }
}

/// The planned feed against time, in mm/min (the series is), with the machine's maximum in
/// the same unit.
fn feed_chart(feed: Series, max_feed_mm_per_s: f64) -> Chart {
    Chart {
        title: "Planned feed".into(),
        x_label: "time (s)".into(),
        y_label: "feed (mm/min)".into(),
        series: vec![feed],
        limits: vec![(max_feed_mm_per_s * 60.0, "max feed".into())],
        ..Chart::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_feed_charts_maximum_is_in_the_series_unit() {
        let feed = Series {
            name: "feed".into(),
            color: "#1f8f3f",
            style: Style::Line,
            points: vec![(0.0, 0.0), (1.0, 600.0)],
        };
        let chart = feed_chart(feed, 10.0);
        assert_eq!(chart.limits[0].0, 600.0, "10 mm/s is 600 mm/min");
    }
}
