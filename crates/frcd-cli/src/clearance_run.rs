//! Clearance over a `frcd check` run: thresholds from the scene and `--clearance`, the records
//! of every frame, the text summary, the JSON and CSV additions and the SVG plot.

use crate::clearance::{Thresholds, Work, frame_clearances};
use crate::commands::term;
use anyhow::{Context, Result, bail};
use frcd_geom::Pose;
use frcd_hybrid::FrameResult;
use frcd_io::{ClearanceRecord, ClearanceSummary, Report, Scene};
use frcd_obb::ObbTree;
use std::path::Path;
use std::time::Instant;

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

/// The clearance state of one run.
pub struct ClearanceRun {
    thresholds: Thresholds,
    names: Vec<String>,
    /// Per body, its tree (one per distinct mesh, shared).
    body_tree: Vec<usize>,
    trees: Vec<ObbTree>,
    /// Per frame checked, its records.
    pub frames: Vec<Vec<ClearanceRecord>>,
    /// Total time of the clearance computation (µs), included in the frame times.
    pub total_us: f64,
    /// Summed work counters.
    pub work: Work,
}

impl ClearanceRun {
    /// The run's thresholds (`--clearance` replaces the scene-wide one; per-pair ones stay), and
    /// the trees; `None` when no pair has a threshold. The threshold is checked like the
    /// scene's (finite, `>= 0`).
    pub fn new(
        scene: &Scene,
        args: &ClearanceArgs,
        build: &frcd_obb::BuildOptions,
    ) -> Result<Option<Self>> {
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
                    "--plot-clearance needs a clearance threshold: give --clearance METRES or set \"clearance\" in the scene"
                );
            }
            return Ok(None);
        }
        let trees: Vec<ObbTree> = scene
            .meshes()
            .iter()
            .map(|m| ObbTree::build(m, build))
            .collect();
        Ok(Some(Self {
            thresholds: Thresholds {
                clearances,
                excluded: scene.exclusions().iter().copied().collect(),
                is_static: scene.bodies().iter().map(|b| b.is_static).collect(),
            },
            names: scene.bodies().iter().map(|b| b.name.clone()).collect(),
            body_tree: scene.bodies().iter().map(|b| b.mesh_index).collect(),
            trees,
            frames: Vec::new(),
            total_us: 0.0,
            work: Work::default(),
        }))
    }

    /// Computes and stores one frame's clearances; the checker's answer gives the contained
    /// pairs (distance 0).
    pub fn frame(&mut self, poses: &[Pose], r: &FrameResult) {
        let t = Instant::now();
        let contained: Vec<(usize, usize)> = r
            .contacts
            .iter()
            .filter(|c| c.contained.is_some())
            .map(|c| (c.a.min(c.b), c.a.max(c.b)))
            .collect();
        let touching: Vec<(usize, usize, u32, u32)> = r
            .contacts
            .iter()
            .filter(|c| c.a < c.b)
            .filter_map(|c| c.pairs.first().map(|&(x, y)| (c.a, c.b, x, y)))
            .collect();
        let trees: Vec<&ObbTree> = self.body_tree.iter().map(|&m| &self.trees[m]).collect();
        let (records, work) =
            frame_clearances(&trees, poses, &self.thresholds, &contained, &touching);
        self.work.candidates += work.candidates;
        self.work.distance_queries += work.distance_queries;
        self.work.exact_decisions += work.exact_decisions;
        self.frames.push(
            records
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
        self.total_us += t.elapsed().as_secs_f64() * 1e6;
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
        let c = &self.thresholds.clearances;
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
    pub fn print(&self, report: &Report, frames: usize) {
        let summary = self.summary(report);
        println!(
            "clearance (threshold {}; {:.1} µs/frame mean, {} box candidates, {} distance queries, {} exact decisions):",
            self.threshold_text(),
            self.total_us / frames.max(1) as f64,
            self.work.candidates,
            self.work.distance_queries,
            self.work.exact_decisions
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
            let c = &self.thresholds.clearances;
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
        let c = &self.thresholds.clearances;
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
