//! `cargo xtask bench hybrid`: run time against error of every backend and mode of the hybrid
//! scheduler, on the bogie demo (`testdata/bogie/scene.json`, when present) and on generated
//! scenes; written to `testdata/bench/hybrid.md` (table) and `testdata/bench/hybrid.svg` (plot).
//!
//! Per scene and row (backend × mode): the median, mean and 95th-percentile time per frame
//! (`Checker::check`, everything included), and the error against the CPU exact row (itself
//! checked against the brute-force oracle on every `--oracle-every`-th frame): body-pair frames
//! missed, and the fraction of touching triangle pairs missed. Exact rows must have zero error.
//!
//! Options: `--frames N` (default 1000), `--bogie PATH`, `--cost FILE`, `--out DIR`,
//! `--oracle-every K` (default 100).

use anyhow::{Result, bail};
use frcd_benches::scenes;
use frcd_geom::{Pose, TriMesh};
use frcd_hybrid::{
    Accuracy, Backend, BodySpec, Checker, CostModel, FrameState, GpuPolicy, Options,
};
use frcd_obb::oracle;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

/// Options of `cargo xtask bench hybrid`.
#[derive(clap::Args, Debug)]
pub struct Opts {
    /// Frames per scene.
    #[arg(long, value_name = "N", default_value_t = 1000)]
    pub frames: usize,
    /// The bogie demo scene (skipped when absent).
    #[arg(long, value_name = "PATH", default_value_os_t = crate::workspace_path("testdata/bogie/scene.json"))]
    pub bogie: PathBuf,
    /// A cost model file (`frcd calibrate`); the built-in model otherwise.
    #[arg(long, value_name = "FILE")]
    pub cost: Option<PathBuf>,
    /// Folder for hybrid.md and hybrid.svg.
    #[arg(long, value_name = "DIR", default_value_os_t = crate::workspace_path("testdata/bench"))]
    pub out: PathBuf,
    /// Check the CPU exact row against the brute-force oracle every K-th frame (0 counts as 1).
    #[arg(long, value_name = "K", default_value_t = 100)]
    pub oracle_every: usize,
}

/// A scene for the benchmark: bodies, exclusions, frames.
struct BenchScene {
    name: String,
    bodies: Vec<BodySpec>,
    exclude: Vec<(usize, usize)>,
    frames: Vec<Vec<Pose>>,
}

fn bogie(path: &std::path::Path, frames: usize) -> Result<Option<BenchScene>> {
    if !path.exists() {
        println!(
            "SKIP bogie: {} not found (run `cargo xtask gen-bogie`)",
            path.display()
        );
        return Ok(None);
    }
    let s = frcd_io::Scene::load(path)?;
    Ok(Some(BenchScene {
        name: "bogie demo".into(),
        bodies: s
            .bodies()
            .iter()
            .map(|b| BodySpec {
                name: b.name.clone(),
                mesh: b.mesh.clone(),
                is_static: b.is_static,
            })
            .collect(),
        exclude: s.exclusions().to_vec(),
        frames: s
            .frames()
            .iter()
            .take(frames)
            .map(|f| f.poses.clone())
            .collect(),
    }))
}

fn generated(s: scenes::Scene, frames: usize) -> BenchScene {
    BenchScene {
        name: s.name.clone(),
        bodies: s
            .bodies
            .iter()
            .map(|b| BodySpec {
                name: b.name.clone(),
                mesh: b.mesh.clone(),
                is_static: b.is_static,
            })
            .collect(),
        exclude: Vec::new(),
        frames: s.frames.into_iter().take(frames).collect(),
    }
}

type Answer = Vec<(usize, usize, Vec<(u32, u32)>, bool)>;

struct Row {
    scene: String,
    backend: &'static str,
    mode: &'static str,
    median_us: f64,
    mean_us: f64,
    p95_us: f64,
    missed_bodies: usize,
    body_frames: usize,
    missed_tri_fraction: f64,
    stages: String,
}

type RowRun = (Vec<f64>, Vec<Answer>, String, Vec<String>);

fn run_row(s: &BenchScene, options: Options) -> Result<RowRun> {
    let checker = Checker::new(s.bodies.clone(), &s.exclude, options)?;
    let mut state = FrameState::default();
    let mut times = Vec::with_capacity(s.frames.len());
    let mut answers = Vec::with_capacity(s.frames.len());
    let mut stage_us = [0f64; 3];
    let mut stage_kind: [Vec<String>; 3] = Default::default();
    for poses in &s.frames {
        let t = Instant::now();
        let r = checker.check(poses, &mut state)?;
        times.push(t.elapsed().as_secs_f64() * 1e6);
        for (k, st) in r.stages.iter().enumerate() {
            stage_us[k] += st.time_us;
            let name = format!("{:?}", st.backend).to_lowercase();
            if !stage_kind[k].contains(&name) {
                stage_kind[k].push(name);
            }
        }
        answers.push(
            r.contacts
                .into_iter()
                .map(|c| (c.a, c.b, c.pairs, c.contained.is_some()))
                .collect(),
        );
    }
    let n = s.frames.len().max(1) as f64;
    let stages = ["broad", "image", "narrow"]
        .iter()
        .enumerate()
        .map(|(k, name)| {
            format!(
                "{name} {} {:.0}µs",
                stage_kind[k].join("/"),
                stage_us[k] / n
            )
        })
        .collect::<Vec<_>>()
        .join(", ");
    Ok((times, answers, stages, checker.adapters()))
}

fn oracle_frame(s: &BenchScene, poses: &[Pose]) -> Answer {
    let mut out = Vec::new();
    for a in 0..s.bodies.len() {
        for b in a + 1..s.bodies.len() {
            if (s.bodies[a].is_static && s.bodies[b].is_static) || s.exclude.contains(&(a, b)) {
                continue;
            }
            let (ma, mb): (&Arc<TriMesh>, &Arc<TriMesh>) = (&s.bodies[a].mesh, &s.bodies[b].mesh);
            let wa = ma.aabb().transformed(&poses[a]).inflated(1e-6);
            let wb = mb.aabb().transformed(&poses[b]).inflated(1e-6);
            if !wa.intersects(&wb) {
                continue;
            }
            let ans = oracle::answer(ma, &poses[a], mb, &poses[b], true);
            if ans.collide() {
                out.push((a, b, ans.pairs, ans.contained.is_some()));
            }
        }
    }
    out
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// Runs the suite.
pub fn run(mut o: Opts) -> Result<()> {
    o.oracle_every = o.oracle_every.max(1);
    let cost = match &o.cost {
        Some(p) => CostModel::load(p)?,
        None => CostModel::default(),
    };
    let mut all = Vec::new();
    if let Some(b) = bogie(&o.bogie, o.frames)? {
        all.push(b);
    }
    all.push(generated(
        scenes::sparse(200, o.frames.min(200), 7),
        o.frames,
    ));
    all.push(generated(
        scenes::wheelset_on_rails(o.frames.min(100)),
        o.frames,
    ));
    let rows_spec: [(Backend, Accuracy); 5] = [
        (Backend::Cpu, Accuracy::Exact),
        (Backend::Hybrid, Accuracy::Exact),
        (Backend::Gpgpu, Accuracy::Exact),
        (Backend::Hybrid, Accuracy::Fast),
        (Backend::Image, Accuracy::Fast),
    ];
    let mut rows = Vec::new();
    let mut adapter = String::from("none");
    for s in &all {
        println!(
            "{}: {} bodies, {} frames",
            s.name,
            s.bodies.len(),
            s.frames.len()
        );
        let mut truth: Option<Vec<Answer>> = None;
        for (backend, mode) in rows_spec {
            let options = Options {
                backend,
                mode,
                cost: cost.clone(),
                gpu: if backend == Backend::Cpu {
                    GpuPolicy::Off
                } else {
                    GpuPolicy::Auto
                },
                ..Options::default()
            };
            let (mut times, answers, stages, devices) = match run_row(s, options) {
                Ok(x) => x,
                Err(e) => {
                    println!("  {:<7} {:<6} skipped: {e}", backend.name(), mode.name());
                    continue;
                }
            };
            if let Some(d) = devices.first() {
                adapter = d.clone();
            }

            let t = match &truth {
                Some(t) => t,
                None => {
                    // The CPU exact row, checked against the oracle on sampled frames.
                    for (i, poses) in s.frames.iter().enumerate().step_by(o.oracle_every) {
                        if oracle_frame(s, poses) != answers[i] {
                            bail!("{}: cpu exact differs from the oracle at frame {i}", s.name);
                        }
                    }
                    truth = Some(answers.clone());
                    truth.as_ref().expect("set")
                }
            };
            let (mut missed, mut body_frames, mut tri_total, mut tri_missed) =
                (0, 0, 0usize, 0usize);
            for (tf, gf) in t.iter().zip(&answers) {
                for (a, b, pairs, _) in tf {
                    body_frames += 1;
                    tri_total += pairs.len();
                    match gf.iter().find(|g| g.0 == *a && g.1 == *b) {
                        None => {
                            missed += 1;
                            tri_missed += pairs.len();
                        }
                        Some(g) => {
                            tri_missed += pairs
                                .iter()
                                .filter(|p| g.2.binary_search(p).is_err())
                                .count()
                        }
                    }
                }
            }
            let mean = times.iter().sum::<f64>() / times.len() as f64;
            times.sort_by(f64::total_cmp);
            let row = Row {
                scene: s.name.clone(),
                backend: backend.name(),
                mode: mode.name(),
                median_us: percentile(&times, 0.5),
                mean_us: mean,
                p95_us: percentile(&times, 0.95),
                missed_bodies: missed,
                body_frames,
                missed_tri_fraction: if tri_total == 0 {
                    0.0
                } else {
                    tri_missed as f64 / tri_total as f64
                },
                stages,
            };
            println!(
                "  {:<7} {:<6} median {:>9.1} µs  mean {:>9.1} µs  p95 {:>9.1} µs  missed {}/{} pair-frames, {:.2}% triangle pairs  [{}]",
                row.backend,
                row.mode,
                row.median_us,
                row.mean_us,
                row.p95_us,
                row.missed_bodies,
                row.body_frames,
                100.0 * row.missed_tri_fraction,
                row.stages
            );
            if mode == Accuracy::Exact && (row.missed_bodies > 0 || row.missed_tri_fraction > 0.0) {
                bail!("{}: exact row {} lost pairs", s.name, row.backend);
            }
            rows.push(row);
        }
    }
    std::fs::create_dir_all(&o.out)?;
    let mut md = String::new();
    writeln!(
        md,
        "# Hybrid scheduler: run time against error\n\n`cargo xtask bench hybrid` on {} threads, GPU: {adapter}. Error against cpu exact (itself checked against the brute-force oracle every {} frames).\n",
        rayon::current_num_threads(),
        o.oracle_every
    )?;
    writeln!(
        md,
        "| scene | backend | mode | median µs/frame | mean µs | p95 µs | missed pair-frames | missed triangle pairs | stages (mean per frame) |"
    )?;
    writeln!(
        md,
        "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | --- |"
    )?;
    for r in &rows {
        writeln!(
            md,
            "| {} | {} | {} | {:.1} | {:.1} | {:.1} | {}/{} | {:.2}% | {} |",
            r.scene,
            r.backend,
            r.mode,
            r.median_us,
            r.mean_us,
            r.p95_us,
            r.missed_bodies,
            r.body_frames,
            100.0 * r.missed_tri_fraction,
            r.stages
        )?;
    }
    let md_path = o.out.join("hybrid.md");
    std::fs::write(&md_path, md)?;
    let svg_path = o.out.join("hybrid.svg");
    plot(&svg_path, &rows, &adapter)?;
    println!("wrote {} and {}", md_path.display(), svg_path.display());
    Ok(())
}

fn plot(path: &std::path::Path, rows: &[Row], adapter: &str) -> Result<()> {
    use crate::plot::{self, Axis, Chart, Series};
    if rows.is_empty() {
        return Ok(());
    }
    // Time on a log scale, drawn as log10 values (the axis says "log10").
    let x = |r: &Row| r.median_us.max(0.1).log10();
    let y = |r: &Row| 100.0 * r.missed_tri_fraction;
    let (x0, x1) = plot::extent(rows.iter().map(x)).unwrap_or((0.0, 1.0));
    let y1 = rows.iter().map(y).fold(0.0, f64::max).max(1.0) * 1.15;
    let mut chart = Chart::new(
        format!("hybrid scheduler: error vs time per frame (GPU = {adapter})"),
        Axis::linear("log10 median µs per frame", x0 - 0.3..x1 + 0.3),
        Axis::linear("% touching triangle pairs missed", -0.05 * y1..y1),
    );
    let mut scenes: Vec<&str> = rows.iter().map(|r| r.scene.as_str()).collect();
    scenes.dedup();
    let colors = [
        plot::BLUE,
        plot::RED,
        plot::GREEN,
        plot::MAGENTA,
        plot::CYAN,
    ];
    for (k, sc) in scenes.iter().enumerate() {
        let mine: Vec<&Row> = rows.iter().filter(|r| r.scene == *sc).collect();
        chart = chart.series(
            Series::scatter(
                *sc,
                colors[k % colors.len()],
                mine.iter().map(|r| (x(r), y(r))).collect(),
            )
            .with_point_labels(
                mine.iter()
                    .map(|r| format!("{} {}", r.backend, r.mode))
                    .collect(),
            ),
        );
    }
    plot::write_svg(path, (900, 520), &[chart])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plot_writes_every_series() {
        let row = |scene: &str, backend, mode, us, miss| Row {
            scene: scene.to_string(),
            backend,
            mode,
            median_us: us,
            mean_us: us,
            p95_us: us,
            missed_bodies: 0,
            body_frames: 10,
            missed_tri_fraction: miss,
            stages: String::new(),
        };
        let rows = vec![
            row("bogie", "cpu", "exact", 120.0, 0.0),
            row("bogie", "image", "fast", 900.0, 0.02),
            row("grid", "cpu", "exact", 40.0, 0.0),
            row("grid", "gpgpu", "exact", 300.0, 0.0),
        ];
        let path = crate::plot::TempFile(
            std::env::temp_dir().join(format!("frcd-xtask-hybrid-{}.svg", std::process::id())),
        );
        plot(&path, &rows, "test adapter").unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        for s in ["bogie", "grid", "image fast", "gpgpu exact", "test adapter"] {
            assert!(svg.contains(s), "{s} missing");
        }
    }
}
