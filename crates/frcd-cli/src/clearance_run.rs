//! Clearance over a `frcd check` run: thresholds from the scene and `--clearance`, the records
//! of every frame, the text summary, the JSON and CSV additions and the SVG plot.

use crate::commands::term;
use anyhow::{Context, Result, bail};
use frcd_hybrid::{FrameResult, Options};
use frcd_io::{ClearanceRecord, ClearanceSummary, Clearances, Report, Scene};
use frcd_obb::ClearanceWork;
use std::path::Path;

/// Clearance options of `frcd check`.
#[derive(Clone, Debug, Default)]
pub struct ClearanceArgs {
    /// `--clearance`: scene-wide threshold replacing the scene's `"clearance"`.
    pub threshold: Option<f64>,
    /// `--plot-clearance`: SVG output.
    pub plot: Option<std::path::PathBuf>,
    /// `--plot-pairs`: plot only pairs with a body name containing one of these.
    pub plot_pairs: Vec<String>,
    /// `--plot-points`: most points per pair in the plot.
    pub plot_points: usize,
}

/// The clearance state of one run: the thresholds (given to the checker, which computes the
/// clearances) and the records of every frame.
pub struct ClearanceRun {
    clearances: Clearances,
    names: Vec<String>,
    /// Per frame checked, its records.
    pub frames: Vec<Vec<ClearanceRecord>>,
    /// Summed work counters.
    pub work: ClearanceWork,
}

impl ClearanceRun {
    /// The run's thresholds (`--clearance` replaces the scene-wide one; per-pair ones stay);
    /// `None` when no pair has a threshold. The threshold is checked like the scene's (finite,
    /// `>= 0`).
    pub fn new(scene: &Scene, args: &ClearanceArgs) -> Result<Option<Self>> {
        let cli = args
            .threshold
            .map(|t| frcd_io::check_clearance(t).map_err(|m| anyhow::anyhow!("--clearance: {m}")))
            .transpose()?;
        let clearances = scene
            .clearances()
            .with_default(cli.or(scene.clearances().default));
        if clearances.is_empty() {
            if args.plot.is_some() {
                bail!(
                    "the clearance plot needs a clearance threshold: give --clearance METRES or set \"clearance\" in the scene"
                );
            }
            return Ok(None);
        }
        Ok(Some(Self {
            clearances,
            names: scene.bodies().iter().map(|b| b.name.clone()).collect(),
            frames: Vec::new(),
            work: ClearanceWork::default(),
        }))
    }

    /// Asks the checker for the run's clearances.
    pub fn apply(&self, options: &mut Options) {
        crate::clearance::apply(&self.clearances, options);
    }

    /// Stores one frame's clearances, as the checker found them.
    pub fn frame(&mut self, r: &FrameResult) {
        self.work += r.clearance_work;
        self.frames.push(
            crate::clearance::records(r)
                .iter()
                .map(|r| ClearanceRecord {
                    a: self.names[r.a].clone(),
                    b: self.names[r.b].clone(),
                    distance: r.distance,
                    points: [r.points[0].to_array(), r.points[1].to_array()],
                    triangles: [r.triangles.0, r.triangles.1],
                    contained: r.contained,
                })
                .collect(),
        );
    }

    /// Per pair, the minimum over the run (see [`frcd_io::summarize_clearances`]).
    pub fn summary(&self, report: &Report) -> Vec<ClearanceSummary> {
        frcd_io::summarize_clearances(
            report
                .frames
                .iter()
                .zip(&self.frames)
                .map(|(f, r)| (f.index, r.as_slice())),
        )
    }

    fn threshold_text(&self) -> String {
        let c = &self.clearances;
        let mut s = match c.default {
            Some(d) => format!("{d} for every checked pair"),
            None => "none scene-wide".to_string(),
        };
        if !c.pairs.is_empty() {
            s.push_str(&format!(", {} pairs with their own", c.pairs.len()));
        }
        s
    }

    /// The text summary: per pair the minimum clearance and the frame where it occurs.
    pub fn print(&self, report: &Report) {
        let summary = self.summary(report);
        let w = &self.work;
        println!(
            "clearance (threshold {}; {} pair evaluations: {} proved far by the motion bound, {} by the meridian bound, {} distance queries ({} warm-started), {} exact decisions; {} node pairs, {} triangle pairs in the searches that came below their limit):",
            self.threshold_text(),
            w.pairs,
            w.skipped,
            w.spin_skipped,
            w.distance_queries,
            w.warm_starts,
            w.exact_decisions,
            w.box_tests,
            w.tri_tests
        );
        if summary.is_empty() {
            println!("  no checked pair came within its threshold");
        }
        for s in &summary {
            let zero = if s.zero_intervals.is_empty() {
                String::new()
            } else {
                let iv: Vec<String> = s
                    .zero_intervals
                    .iter()
                    .map(|[a, b]| {
                        if a == b {
                            format!("{a}")
                        } else {
                            format!("{a}-{b}")
                        }
                    })
                    .collect();
                format!("; interferes (0) in frames {}", iv.join(", "))
            };
            println!(
                "  {} / {}: min {:.6} at frame {} (within threshold in {} frames){zero}",
                term(&s.a),
                term(&s.b),
                s.min_distance,
                s.min_frame,
                s.frames
            );
        }
    }

    /// Adds `"clearances"` to every frame of the JSON report, the thresholds and the per-pair
    /// summary.
    pub fn add_json(&self, value: &mut serde_json::Value, report: &Report) -> Result<()> {
        if let Some(frames) = value.get_mut("frames").and_then(|f| f.as_array_mut()) {
            for (f, r) in frames.iter_mut().zip(&self.frames) {
                if let Some(obj) = f.as_object_mut() {
                    obj.insert(
                        "clearances".into(),
                        serde_json::to_value(r).context("clearances to JSON")?,
                    );
                }
            }
        }
        if let Some(obj) = value.as_object_mut() {
            let c = &self.clearances;
            let pairs: Vec<serde_json::Value> = c
                .pairs
                .iter()
                .map(|&(a, b, t)| {
                    serde_json::json!({"a": self.names[a], "b": self.names[b], "threshold": t})
                })
                .collect();
            obj.insert(
                "clearance".into(),
                serde_json::json!({"default": c.default, "pairs": pairs}),
            );
            obj.insert(
                "clearance_pairs".into(),
                serde_json::to_value(self.summary(report)).context("clearance summary to JSON")?,
            );
        }
        Ok(())
    }

    /// The CSV report with a row per pair and frame.
    pub fn csv(&self, report: &Report) -> String {
        frcd_io::clearance_csv(report, &self.frames)
    }

    /// Writes the SVG plot (atomically) of the pairs that came within their threshold (those
    /// matching `filters`, when given).
    pub fn plot(&self, path: &Path, report: &Report, args: &ClearanceArgs) -> Result<usize> {
        let summary = self.summary(report);
        let wanted = |s: &ClearanceSummary| {
            args.plot_pairs.is_empty()
                || args
                    .plot_pairs
                    .iter()
                    .any(|f| s.a.contains(f.as_str()) || s.b.contains(f.as_str()))
        };
        let mut series: Vec<crate::plot::PairSeries> = summary
            .iter()
            .filter(|s| wanted(s))
            .map(|s| crate::plot::PairSeries {
                label: format!(
                    "{} / {} (min {:.4} at {})",
                    s.a, s.b, s.min_distance, s.min_frame
                ),
                points: Vec::new(),
                zero_intervals: s.zero_intervals.clone(),
            })
            .collect();
        let keys: Vec<(String, String)> = summary
            .iter()
            .filter(|s| wanted(s))
            .map(|s| (s.a.clone(), s.b.clone()))
            .collect();
        for (f, recs) in report.frames.iter().zip(&self.frames) {
            for r in recs {
                if let Some(k) = keys.iter().position(|(a, b)| *a == r.a && *b == r.b) {
                    series[k].points.push((f.index, r.distance));
                }
            }
        }
        let [first, last] = report.frame_range.unwrap_or([0, 0]);
        let c = &self.clearances;
        let threshold = c.max_threshold().unwrap_or(0.0);
        let title = format!(
            "{}: clearance per body pair (threshold {})",
            report.scene.as_deref().unwrap_or("scene"),
            c.default
                .map_or_else(|| "per pair".to_string(), |d| d.to_string())
        );
        let svg = crate::plot::clearance_svg(
            &series,
            [first, last],
            threshold,
            &title,
            args.plot_points,
        )?;
        frcd_io::write_atomic(path, svg.as_bytes())?;
        Ok(series.len())
    }
}
