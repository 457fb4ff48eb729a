//! The one plotting module of the bench tasks: line and scatter charts on linear or log axes,
//! labelled series with a legend, one or more panels side by side, written as SVG (plotters).
//!
//! A bench describes what to draw ([`Chart`], [`Axis`], [`Series`]) and calls [`write_svg`];
//! the look (fonts, markers, line widths, legend box) is decided here once, so every
//! `testdata/bench/*.svg` reads the same way.
//!
//! ```ignore
//! let chart = Chart::new(
//!     "ns per test vs ratio",
//!     Axis::linear("ratio (%)", 0.0..100.0),
//!     Axis::log("ns / test", 1.0..1000.0),
//! )
//! .series(Series::line("exact", plot::RED, vec![(0.0, 30.0), (100.0, 60.0)]));
//! plot::write_svg(Path::new("out.svg"), (800, 500), &[chart])?;
//! ```

use anyhow::Result;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::ops::Range;
use std::path::Path;

pub use plotters::style::{BLACK, BLUE, CYAN, GREEN, MAGENTA, RED, RGBColor};

/// Orange and grey, for charts with more series than the named colours.
pub const ORANGE: RGBColor = RGBColor(255, 140, 0);
pub const GREY: RGBColor = RGBColor(128, 128, 128);

/// One axis: its description, its range (in data units) and its scale.
#[derive(Clone, Debug)]
pub struct Axis {
    pub label: String,
    pub range: Range<f64>,
    pub log: bool,
}

impl Axis {
    /// A linear axis over `range`.
    pub fn linear(label: impl Into<String>, range: Range<f64>) -> Self {
        Axis {
            label: label.into(),
            range,
            log: false,
        }
    }

    /// A logarithmic axis over `range` (both ends positive).
    pub fn log(label: impl Into<String>, range: Range<f64>) -> Self {
        Axis {
            label: label.into(),
            range,
            log: true,
        }
    }
}

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    /// A polyline through the points (2 px) with a dot on each; the legend shows a line.
    Line,
    /// Dots only (4 px radius); the legend shows a dot.
    Scatter,
}

/// One labelled series.
#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub color: RGBColor,
    pub points: Vec<(f64, f64)>,
    pub style: Style,
    /// A text beside each point (same length as `points`), or empty for none.
    pub point_labels: Vec<String>,
}

impl Series {
    /// A line series.
    pub fn line(name: impl Into<String>, color: RGBColor, points: Vec<(f64, f64)>) -> Self {
        Series {
            name: name.into(),
            color,
            points,
            style: Style::Line,
            point_labels: Vec::new(),
        }
    }

    /// A scatter series.
    pub fn scatter(name: impl Into<String>, color: RGBColor, points: Vec<(f64, f64)>) -> Self {
        Series {
            style: Style::Scatter,
            ..Series::line(name, color, points)
        }
    }

    /// Writes `labels[i]` beside point `i`.
    pub fn with_point_labels(mut self, labels: Vec<String>) -> Self {
        self.point_labels = labels;
        self
    }
}

/// Where the legend box goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Legend {
    UpperLeft,
    UpperRight,
    MiddleRight,
    LowerRight,
}

impl Legend {
    fn position(self) -> SeriesLabelPosition {
        match self {
            Legend::UpperLeft => SeriesLabelPosition::UpperLeft,
            Legend::UpperRight => SeriesLabelPosition::UpperRight,
            Legend::MiddleRight => SeriesLabelPosition::MiddleRight,
            Legend::LowerRight => SeriesLabelPosition::LowerRight,
        }
    }
}

/// One chart (one panel of a figure).
#[derive(Clone, Debug)]
pub struct Chart {
    pub caption: String,
    /// Caption font size (px); long captions on narrow panels want less than the default 16.
    pub caption_size: u32,
    pub x: Axis,
    pub y: Axis,
    pub series: Vec<Series>,
    pub legend: Legend,
    /// Space around the panel and for the axis labels (px).
    pub margin: u32,
    pub x_label_area: u32,
    pub y_label_area: u32,
}

impl Chart {
    /// A chart with no series yet, the legend at the upper right.
    pub fn new(caption: impl Into<String>, x: Axis, y: Axis) -> Self {
        Chart {
            caption: caption.into(),
            caption_size: 16,
            x,
            y,
            series: Vec::new(),
            legend: Legend::UpperRight,
            margin: 15,
            x_label_area: 40,
            y_label_area: 60,
        }
    }

    /// Adds a series.
    pub fn series(mut self, s: Series) -> Self {
        self.series.push(s);
        self
    }

    /// Moves the legend.
    pub fn legend(mut self, at: Legend) -> Self {
        self.legend = at;
        self
    }

    /// Sets the caption's font size.
    pub fn caption_size(mut self, px: u32) -> Self {
        self.caption_size = px;
        self
    }
}

/// The smallest and largest of `values` (`None` when there is none).
pub fn extent(values: impl IntoIterator<Item = f64>) -> Option<(f64, f64)> {
    values.into_iter().fold(None, |acc, v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

/// Writes `panels` side by side (equal widths) into an SVG file of `size` pixels.
pub fn write_svg(path: &Path, size: (u32, u32), panels: &[Chart]) -> Result<()> {
    let root = SVGBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE)?;
    let areas = root.split_evenly((1, panels.len().max(1)));
    for (area, chart) in areas.iter().zip(panels) {
        draw(area, chart)?;
    }
    root.present()?;
    Ok(())
}

/// Draws one chart; the four scale combinations give four coordinate types, hence the macro.
fn draw(area: &DrawingArea<SVGBackend<'_>, Shift>, c: &Chart) -> Result<()> {
    let mut builder = ChartBuilder::on(area);
    builder
        .caption(&c.caption, ("sans-serif", c.caption_size))
        .margin(c.margin)
        .x_label_area_size(c.x_label_area)
        .y_label_area_size(c.y_label_area);
    let (xr, yr) = (c.x.range.clone(), c.y.range.clone());
    macro_rules! finish {
        ($x:expr, $y:expr) => {{
            let mut chart = builder.build_cartesian_2d($x, $y)?;
            chart
                .configure_mesh()
                .x_desc(c.x.label.as_str())
                .y_desc(c.y.label.as_str())
                .draw()?;
            for s in c.series.iter().filter(|s| !s.points.is_empty()) {
                let color = s.color;
                match s.style {
                    Style::Line => {
                        chart
                            .draw_series(LineSeries::new(
                                s.points.iter().copied(),
                                color.stroke_width(2),
                            ))?
                            .label(s.name.as_str())
                            .legend(move |(x, y)| {
                                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                            });
                        chart.draw_series(
                            s.points.iter().map(|&p| Circle::new(p, 3, color.filled())),
                        )?;
                    }
                    Style::Scatter => {
                        chart
                            .draw_series(
                                s.points.iter().map(|&p| Circle::new(p, 4, color.filled())),
                            )?
                            .label(s.name.as_str())
                            .legend(move |(x, y)| Circle::new((x, y), 4, color.filled()));
                    }
                }
                chart.draw_series(s.points.iter().zip(&s.point_labels).map(|(&p, l)| {
                    Text::new(l.clone(), p, ("sans-serif", 11).into_font().color(&color))
                }))?;
            }
            chart
                .configure_series_labels()
                .position(c.legend.position())
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()?;
        }};
    }
    match (c.x.log, c.y.log) {
        (false, false) => finish!(xr, yr),
        (true, false) => finish!(xr.log_scale(), yr),
        (false, true) => finish!(xr, yr.log_scale()),
        (true, true) => finish!(xr.log_scale(), yr.log_scale()),
    }
    Ok(())
}

/// Test helper for the plot tests here and in the bench modules: a file path (in the system
/// temp folder, named by the caller, unique per process and test) that is removed when the
/// guard drops, at the end of the test, pass or fail.
#[cfg(test)]
pub(crate) struct TempFile(pub(crate) std::path::PathBuf);

#[cfg(test)]
impl std::ops::Deref for TempFile {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

#[cfg(test)]
impl AsRef<Path> for TempFile {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

#[cfg(test)]
impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str) -> TempFile {
        TempFile(
            std::env::temp_dir().join(format!("frcd-xtask-plot-{}-{name}.svg", std::process::id())),
        )
    }

    #[test]
    fn every_scale_and_style_draws_its_series_and_legend() {
        for (xlog, ylog) in [(false, false), (true, false), (false, true), (true, true)] {
            let axis = |log: bool, label: &str| {
                if log {
                    Axis::log(label, 1.0..1000.0)
                } else {
                    Axis::linear(label, 0.0..1000.0)
                }
            };
            let chart = Chart::new("caption here", axis(xlog, "x label"), axis(ylog, "y label"))
                .series(Series::line(
                    "first series",
                    RED,
                    vec![(1.0, 2.0), (10.0, 20.0)],
                ))
                .series(
                    Series::scatter("second series", BLUE, vec![(3.0, 4.0), (30.0, 40.0)])
                        .with_point_labels(vec!["p one".into(), "p two".into()]),
                )
                .series(Series::line("empty series", GREEN, vec![]))
                .legend(Legend::LowerRight);
            let path = temp(&format!("{xlog}-{ylog}"));
            write_svg(&path, (400, 300), &[chart.clone(), chart]).unwrap();
            let svg = std::fs::read_to_string(&path).unwrap();
            assert!(svg.starts_with("<svg"));
            for s in ["caption here", "x label", "y label", "p one", "p two"] {
                assert_eq!(svg.matches(s).count(), 2, "{s} once per panel");
            }
            // Series names appear in the legend only; an empty series has none.
            assert_eq!(svg.matches("first series").count(), 2);
            assert_eq!(svg.matches("second series").count(), 2);
            assert!(!svg.contains("empty series"));
            assert!(svg.contains("<polyline"));
            assert!(svg.contains("<circle"));
        }
    }

    #[test]
    fn extent_of_values() {
        assert_eq!(extent([3.0, -1.0, 2.0]), Some((-1.0, 3.0)));
        assert_eq!(extent(std::iter::empty()), None);
    }
}
