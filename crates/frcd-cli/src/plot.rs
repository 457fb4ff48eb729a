//! SVG plot of clearance against frame per body pair (`frcd check --plot-clearance OUT.svg`).

use anyhow::{Result, anyhow};

/// The clearance of one body pair over a run.
pub struct PairSeries {
    /// Legend label (`a / b`).
    pub label: String,
    /// `(frame, distance)` for the frames where the pair was within its threshold, ascending.
    pub points: Vec<(usize, f64)>,
    /// Runs of frames with clearance 0 (interference), `[first, last]` inclusive.
    pub zero_intervals: Vec<[usize; 2]>,
}

/// Per bin of `width` frames, the smallest distance (the minimum survives decimation; a bin
/// without data stays empty, so the line breaks where the pair is beyond its threshold).
fn bin_minima(points: &[(usize, f64)], first: usize, width: usize) -> Vec<(usize, f64)> {
    let mut out: Vec<(usize, f64)> = Vec::new();
    for &(f, d) in points {
        let bin = (f - first.min(f)) / width.max(1);
        let x = first + bin * width.max(1);
        match out.last_mut() {
            Some(last) if last.0 == x => last.1 = last.1.min(d),
            _ => out.push((x, d)),
        }
    }
    out
}

/// The SVG text: one line per pair (broken where the pair is beyond its threshold), the
/// interfering intervals shaded red, a dashed line at the largest threshold. At most
/// `max_points` points per pair: longer runs are reduced to the minimum per bin of frames.
pub fn clearance_svg(
    series: &[PairSeries],
    frames: [usize; 2],
    threshold: f64,
    title: &str,
    max_points: usize,
) -> Result<String> {
    use plotters::prelude::*;
    let err = |e: &dyn std::fmt::Display| anyhow!("plot: {e}");
    let [first, last] = frames;
    let span = last.saturating_sub(first) + 1;
    let width = span.div_ceil(max_points.max(1)).max(1);
    let y_top = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .fold(threshold, f64::max)
        .max(f64::MIN_POSITIVE)
        * 1.08;
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, (960, 540)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 16))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(first as f64..(last as f64 + 1.0), 0.0..y_top)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc(if width > 1 {
                format!("frame (minimum per {width} frames)")
            } else {
                "frame".to_string()
            })
            .y_desc("clearance (scene units)")
            .draw()
            .map_err(|e| err(&e))?;
        let red = RGBColor(220, 30, 30);
        // Interfering intervals, shaded over the full height.
        let mut legend_red = true;
        for s in series {
            for &[a, b] in &s.zero_intervals {
                let r = chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [(a as f64, 0.0), (b as f64 + 1.0, y_top)],
                        red.mix(0.25).filled(),
                    )))
                    .map_err(|e| err(&e))?;
                if legend_red {
                    legend_red = false;
                    r.label("interference (clearance 0)").legend(move |(x, y)| {
                        Rectangle::new([(x, y - 5), (x + 14, y + 5)], red.mix(0.4).filled())
                    });
                }
            }
        }
        chart
            .draw_series(DashedLineSeries::new(
                [(first as f64, threshold), (last as f64 + 1.0, threshold)],
                6,
                4,
                BLACK.mix(0.6).stroke_width(1),
            ))
            .map_err(|e| err(&e))?
            .label(format!("threshold {threshold}"))
            .legend(|(x, y)| PathElement::new([(x, y), (x + 14, y)], BLACK.mix(0.6)));
        let palette = [
            RGBColor(31, 119, 180),
            RGBColor(255, 127, 14),
            RGBColor(44, 160, 44),
            RGBColor(148, 103, 189),
            RGBColor(140, 86, 75),
            RGBColor(227, 119, 194),
            RGBColor(127, 127, 127),
            RGBColor(188, 189, 34),
            RGBColor(23, 190, 207),
        ];
        for (k, s) in series.iter().enumerate() {
            let c = palette[k % palette.len()];
            let pts = bin_minima(&s.points, first, width);
            // Runs of consecutive bins: a gap means beyond the threshold.
            let mut runs: Vec<Vec<(f64, f64)>> = Vec::new();
            let mut prev: Option<usize> = None;
            for &(x, d) in &pts {
                if prev.is_none_or(|p| x != p + width) {
                    runs.push(Vec::new());
                }
                if let Some(r) = runs.last_mut() {
                    r.push((x as f64, d));
                }
                prev = Some(x);
            }
            let mut labelled = false;
            for run in runs {
                let drawn = if run.len() == 1 {
                    chart.draw_series(std::iter::once(Circle::new(run[0], 2, c.filled())))
                } else {
                    chart.draw_series(LineSeries::new(run, c.stroke_width(2)))
                }
                .map_err(|e| err(&e))?;
                if !labelled {
                    labelled = true;
                    drawn.label(s.label.clone()).legend(move |(x, y)| {
                        PathElement::new([(x, y), (x + 14, y)], c.stroke_width(2))
                    });
                }
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 12))
            .draw()
            .map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
    }
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minima_survive_binning_and_gaps_stay() {
        let pts = [(0, 0.004), (1, 0.003), (2, 0.005), (7, 0.001), (9, 0.002)];
        assert_eq!(
            bin_minima(&pts, 0, 3),
            vec![(0, 0.003), (6, 0.001), (3 * 3, 0.002)]
        );
    }

    #[test]
    fn svg_has_one_line_per_pair_and_the_intervals() {
        let s = [
            PairSeries {
                label: "brake / wheel".into(),
                points: (0..100).map(|f| (f, 0.004 - f as f64 * 1e-5)).collect(),
                zero_intervals: vec![],
            },
            PairSeries {
                label: "bearer / body".into(),
                points: (40..60).map(|f| (f, 0.0)).collect(),
                zero_intervals: vec![[40, 59]],
            },
        ];
        let svg = clearance_svg(&s, [0, 99], 0.005, "clearance", 50).unwrap();
        assert!(svg.starts_with("<svg"));
        assert!(svg.contains("brake / wheel") && svg.contains("bearer / body"));
        assert!(svg.contains("interference"));
        assert!(svg.contains("minimum per 2 frames"));
    }
}
