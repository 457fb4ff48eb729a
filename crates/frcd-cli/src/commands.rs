//! The subcommands.

use crate::{BackendArg, CheckerArgs, ModeArg};
use anyhow::{Context, Result, bail};
use frcd_geom::Pose;
use frcd_hybrid::{
    Backend, BodySpec, Checker, Contact, CostModel, FrameResult, FrameState, Mode, Options,
    StageBackend,
};
use frcd_io::{FrameReport, Interference, Report, Scene};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `frcd check`.
pub struct CheckRun {
    pub scene: PathBuf,
    pub checker: CheckerArgs,
    pub json: Option<PathBuf>,
    pub csv: Option<PathBuf>,
    pub segments: bool,
    pub first: usize,
    pub count: Option<usize>,
    pub quiet: bool,
    pub pair_times: bool,
}

fn load_scene(path: &Path, trajectory: Option<&Path>) -> Result<Scene> {
    let scene = match trajectory {
        Some(csv) => Scene::load_with_trajectory(path, csv),
        None => Scene::load(path),
    };
    scene.with_context(|| format!("cannot load scene {}", path.display()))
}

/// The cost model: `--cost`, else $FRCD_COST_MODEL, else ./frcd-cost.json, else built in.
fn cost_model(path: Option<&Path>) -> Result<(CostModel, String)> {
    let explicit = path
        .map(Path::to_path_buf)
        .or_else(|| std::env::var_os("FRCD_COST_MODEL").map(PathBuf::from));
    let p = match explicit {
        Some(p) => p,
        None => {
            let d = PathBuf::from("frcd-cost.json");
            if !d.exists() {
                return Ok((CostModel::default(), "built-in".into()));
            }
            d
        }
    };
    let m = CostModel::load(&p)?;
    Ok((m, p.display().to_string()))
}

fn backend_of(b: BackendArg) -> Backend {
    match b {
        BackendArg::Cpu => Backend::Cpu,
        BackendArg::Gpgpu => Backend::Gpgpu,
        BackendArg::Image => Backend::Image,
        BackendArg::Hybrid => Backend::Hybrid,
    }
}

fn mode_of(m: ModeArg) -> Mode {
    match m {
        ModeArg::Exact => Mode::Exact,
        ModeArg::Fast => Mode::Fast,
    }
}

fn options_of(args: &CheckerArgs, segments: bool) -> Result<(Options, String)> {
    if !(16..=4096).contains(&args.resolution) {
        bail!("--resolution {} is outside 16..=4096", args.resolution);
    }
    let (cost, source) = cost_model(args.cost.as_deref())?;
    Ok((
        Options {
            mode: mode_of(args.mode),
            backend: backend_of(args.backend),
            segments,
            image_resolution: args.resolution,
            cost,
            build: frcd_obb::BuildOptions {
                fit: match args.fit {
                    crate::FitArg::Vertex => frcd_obb::FitMethod::VertexCovariance,
                    crate::FitArg::Area => frcd_obb::FitMethod::AreaWeighted,
                    crate::FitArg::Hull => frcd_obb::FitMethod::HullSurface,
                },
                max_leaf_triangles: args.leaf.max(1),
            },
            ..Options::default()
        },
        source,
    ))
}

fn make_checker(scene: &Scene, options: Options) -> Result<Checker> {
    let bodies: Vec<BodySpec> = scene
        .bodies()
        .iter()
        .map(|b| BodySpec {
            name: b.name.clone(),
            mesh: b.mesh.clone(),
            is_static: b.is_static,
        })
        .collect();
    let backend = options.backend.name();
    Checker::new(bodies, scene.exclusions(), options)
        .with_context(|| format!("cannot set up the '{backend}' backend"))
}

/// Every frame's poses (a scene without frames has one: the initial poses).
fn frames_of(scene: &Scene) -> Vec<Vec<Pose>> {
    if scene.frames().is_empty() {
        vec![scene.bodies().iter().map(|b| b.initial_pose).collect()]
    } else {
        scene.frames().iter().map(|f| f.poses.clone()).collect()
    }
}

fn segment_points(c: &Contact) -> Vec<[frcd_geom::DVec3; 2]> {
    match c {
        Contact::Point(p) => vec![[*p, *p]],
        Contact::Segment(p, q) => vec![[*p, *q]],
        Contact::Polygon(v) => (0..v.len()).map(|i| [v[i], v[(i + 1) % v.len()]]).collect(),
    }
}

fn frame_report(
    checker: &Checker,
    index: usize,
    time_us: f64,
    r: &FrameResult,
    poses: &[Pose],
) -> FrameReport {
    let interferences = r
        .contacts
        .iter()
        .map(|c| {
            let pose_a = poses[c.a];
            let segments = c
                .segments
                .iter()
                .flatten()
                .flat_map(segment_points)
                .map(|[p, q]| {
                    let (p, q) = (pose_a.transform_point(p), pose_a.transform_point(q));
                    [p.to_array(), q.to_array()]
                })
                .collect();
            Interference {
                a: checker.body_name(c.a).unwrap_or("?").to_string(),
                b: checker.body_name(c.b).unwrap_or("?").to_string(),
                triangle_pairs: c.pairs.len() as u64,
                contained: c.contained.is_some(),
                segments,
            }
        })
        .collect();
    FrameReport {
        index,
        time_us,
        interferences,
    }
}

/// Per stage: frames per backend and total time.
#[derive(Default, Clone, serde::Serialize)]
struct StageTally {
    skipped: usize,
    cpu: usize,
    gpu: usize,
    mixed: usize,
    total_us: f64,
}

impl StageTally {
    fn add(&mut self, b: StageBackend, us: f64) {
        match b {
            StageBackend::Skipped => self.skipped += 1,
            StageBackend::Cpu => self.cpu += 1,
            StageBackend::Gpu => self.gpu += 1,
            StageBackend::Mixed => self.mixed += 1,
        }
        self.total_us += us;
    }
    fn describe(&self) -> String {
        let mut parts = Vec::new();
        for (n, name) in [
            (self.cpu, "cpu"),
            (self.gpu, "gpu"),
            (self.mixed, "cpu+gpu"),
            (self.skipped, "skipped"),
        ] {
            if n > 0 {
                parts.push(format!("{name} {n}"));
            }
        }
        format!("{} frames, {:.1} ms", parts.join(", "), self.total_us / 1e3)
    }
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

pub fn check(run: &CheckRun) -> Result<()> {
    let scene = load_scene(&run.scene, run.checker.trajectory.as_deref())?;
    let (options, cost_source) = options_of(&run.checker, run.segments)?;
    let mode = options.mode;
    let t_setup = Instant::now();
    let checker = make_checker(&scene, options)?;
    let setup_ms = t_setup.elapsed().as_secs_f64() * 1e3;
    for note in checker.notes() {
        eprintln!("note: {note}");
    }
    let frames = frames_of(&scene);
    let n = frames.len();
    if run.first >= n {
        bail!(
            "--first {} is past the last frame (the scene has {n})",
            run.first
        );
    }
    let end = match run.count {
        Some(c) => (run.first + c).min(n),
        None => n,
    };
    let mut report = Report::new(checker.options().backend.name(), mode.name());
    report.scene = Some(run.scene.display().to_string());
    let mut state = FrameState::default();
    let mut tallies: [StageTally; 3] = Default::default();
    let mut pair_time: std::collections::HashMap<(usize, usize), (f64, usize)> = Default::default();
    let progress = !run.quiet && end - run.first > 200;
    let mut last_progress = Instant::now();
    let total = end - run.first;
    for (k, index) in (run.first..end).enumerate() {
        let poses = &frames[index];
        let t = Instant::now();
        let r = checker
            .check(poses, &mut state)
            .with_context(|| format!("frame {index}"))?;
        let time_us = t.elapsed().as_secs_f64() * 1e6;
        for (tally, s) in tallies.iter_mut().zip(&r.stages) {
            tally.add(s.backend, s.time_us);
        }
        if run.pair_times {
            for &(a, b, us) in &r.pair_times_us {
                let e = pair_time.entry((a, b)).or_default();
                e.0 += us;
                e.1 += 1;
            }
        }
        report
            .frames
            .push(frame_report(&checker, index, time_us, &r, poses));
        if progress && last_progress.elapsed().as_millis() >= 250 {
            last_progress = Instant::now();
            eprint!(
                "\rframe {}/{} ({:.0}%)",
                k + 1,
                total,
                100.0 * (k + 1) as f64 / total as f64
            );
            let _ = std::io::stderr().flush();
        }
    }
    if progress {
        eprintln!("\rframe {total}/{total} (100%)");
    }
    report.summarize();
    let mut times: Vec<f64> = report.frames.iter().map(|f| f.time_us).collect();
    times.sort_by(f64::total_cmp);
    let median = percentile(&times, 0.5);
    println!(
        "{}: {} bodies, {} triangles, frames {}..{} ({} checked); backend {}, mode {}, cost model {}",
        run.scene.display(),
        scene.bodies().len(),
        scene.triangle_count(),
        run.first,
        end - 1,
        total,
        checker.options().backend.name(),
        mode.name(),
        cost_source
    );
    for a in checker.adapters() {
        println!("  device {a}");
    }
    println!(
        "  time per frame: median {:.1} µs, p95 {:.1} µs, max {:.1} µs (setup {:.0} ms)",
        median,
        percentile(&times, 0.95),
        percentile(&times, 1.0),
        setup_ms
    );
    for (name, t) in ["broad", "image", "narrow"].iter().zip(&tallies) {
        println!("  stage {name:<6}: {}", t.describe());
    }
    if run.pair_times {
        let mut v: Vec<_> = pair_time.into_iter().collect();
        v.sort_by(|x, y| y.1.0.total_cmp(&x.1.0));
        println!("  narrow-phase time by body pair (total over frames, CPU time of the pair):");
        for ((a, b), (us, n)) in v.iter().take(12) {
            println!(
                "    {:>9.1} ms  {:>7.1} µs/frame  {} / {} ({n} frames)",
                us / 1e3,
                us / total as f64,
                checker.body_name(*a).unwrap_or("?"),
                checker.body_name(*b).unwrap_or("?")
            );
        }
    }
    if report.pairs.is_empty() {
        println!("no interference");
    } else if !run.quiet {
        println!("interferences:");
        for p in &report.pairs {
            let intervals: Vec<String> = p
                .intervals
                .iter()
                .map(|[a, b]| {
                    if a == b {
                        format!("{a}")
                    } else {
                        format!("{a}-{b}")
                    }
                })
                .collect();
            println!(
                "  {} / {}: frames {}..{} ({} frames, up to {} triangle pairs): {}",
                p.a,
                p.b,
                p.first_frame,
                p.last_frame,
                p.frames,
                p.max_triangle_pairs,
                intervals.join(", ")
            );
        }
    }
    if let Some(path) = &run.json {
        let mut value = serde_json::to_value(&report).context("report to JSON")?;
        if let Some(obj) = value.as_object_mut() {
            obj.insert("median_time_us".into(), serde_json::json!(median));
            obj.insert("setup_ms".into(), serde_json::json!(setup_ms));
            obj.insert(
                "stages".into(),
                serde_json::json!({"broad": tallies[0], "image": tallies[1], "narrow": tallies[2]}),
            );
            obj.insert("devices".into(), serde_json::json!(checker.adapters()));
            obj.insert("notes".into(), serde_json::json!(checker.notes()));
        }
        let text = serde_json::to_string_pretty(&value).context("report to JSON")?;
        std::fs::write(path, text + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    if let Some(path) = &run.csv {
        report.write_csv(path)?;
    }
    Ok(())
}

pub fn render(
    scene_path: &Path,
    frame: usize,
    output: &Path,
    width: u32,
    height: u32,
    all: bool,
    args: &CheckerArgs,
) -> Result<()> {
    if !(16..=8192).contains(&width) || !(16..=8192).contains(&height) {
        bail!("image size {width}x{height} is outside 16..=8192 pixels per side");
    }
    let scene = load_scene(scene_path, args.trajectory.as_deref())?;
    let frames = frames_of(&scene);
    let Some(poses) = frames.get(frame) else {
        bail!(
            "--frame {frame} is past the last frame (the scene has {})",
            frames.len()
        );
    };
    let (options, _) = options_of(args, false)?;
    let checker = make_checker(&scene, options)?;
    let r = checker
        .check(poses, &mut FrameState::default())
        .with_context(|| format!("frame {frame}"))?;
    #[cfg(feature = "gpu")]
    {
        let mut marks: Vec<crate::render::Marks> = scene
            .bodies()
            .iter()
            .map(|b| crate::render::Marks {
                triangles: vec![false; b.mesh.triangle_count()],
                contained: false,
            })
            .collect();
        for c in &r.contacts {
            for &(x, y) in &c.pairs {
                marks[c.a].triangles[x as usize] = true;
                marks[c.b].triangles[y as usize] = true;
            }
            if c.contained.is_some() {
                marks[c.a].contained = true;
                marks[c.b].contained = true;
            }
        }
        crate::render::render_png(&scene, poses, &marks, width, height, all, output)?;
        println!(
            "{}: frame {frame}, {} interfering pairs ({} triangle pairs) highlighted",
            output.display(),
            r.contacts.len(),
            r.contacts.iter().map(|c| c.pairs.len()).sum::<usize>()
        );
        for c in &r.contacts {
            println!(
                "  {} / {}: {} triangle pairs{}",
                checker.body_name(c.a).unwrap_or("?"),
                checker.body_name(c.b).unwrap_or("?"),
                c.pairs.len(),
                if c.contained.is_some() {
                    " (contained)"
                } else {
                    ""
                }
            );
        }
        Ok(())
    }
    #[cfg(not(feature = "gpu"))]
    {
        let _ = (r, output, all);
        bail!("this frcd was built without the 'gpu' feature: rendering needs wgpu")
    }
}

/// One row of `frcd bench`.
#[derive(serde::Serialize)]
struct BenchRow {
    backend: String,
    mode: String,
    frames: usize,
    median_us: f64,
    mean_us: f64,
    p95_us: f64,
    max_us: f64,
    /// Interfering (frame, pair) entries.
    interferences: usize,
    /// (frame, pair) entries that differ from cpu exact (missing or extra body pairs, or a
    /// different triangle-pair count).
    differences_from_cpu_exact: usize,
    devices: Vec<String>,
    note: String,
}

pub fn bench(
    scene_path: &Path,
    frames: usize,
    cost: Option<&Path>,
    json: Option<&Path>,
) -> Result<()> {
    let scene = load_scene(scene_path, None)?;
    let all = frames_of(&scene);
    let frames = frames.clamp(1, all.len());
    let (cost, source) = cost_model(cost)?;
    println!(
        "{}: {} bodies, {} triangles, {} frames timed per row; cost model {source}",
        scene_path.display(),
        scene.bodies().len(),
        scene.triangle_count(),
        frames
    );
    let rows = [
        (Backend::Cpu, Mode::Exact),
        (Backend::Hybrid, Mode::Exact),
        (Backend::Gpgpu, Mode::Exact),
        (Backend::Hybrid, Mode::Fast),
        (Backend::Image, Mode::Fast),
    ];
    let mut truth: Option<Vec<Vec<(usize, usize, usize)>>> = None;
    let mut out = Vec::new();
    println!(
        "{:<8} {:<6} {:>10} {:>10} {:>10} {:>10} {:>7} {:>6}  devices / note",
        "backend", "mode", "median µs", "mean µs", "p95 µs", "max µs", "hits", "diffs"
    );
    for (backend, mode) in rows {
        let options = Options {
            backend,
            mode,
            cost: cost.clone(),
            ..Options::default()
        };
        let checker = match make_checker(&scene, options) {
            Ok(c) => c,
            Err(e) => {
                println!("{:<8} {:<6} skipped: {e:#}", backend.name(), mode.name());
                continue;
            }
        };
        let mut state = FrameState::default();
        let mut times = Vec::with_capacity(frames);
        let mut answers = Vec::with_capacity(frames);
        let mut failed = None;
        for (i, poses) in all.iter().take(frames).enumerate() {
            let t = Instant::now();
            match checker.check(poses, &mut state) {
                Ok(r) => {
                    times.push(t.elapsed().as_secs_f64() * 1e6);
                    answers.push(
                        r.contacts
                            .iter()
                            .map(|c| (c.a, c.b, c.pairs.len() + c.contained.is_some() as usize))
                            .collect::<Vec<_>>(),
                    );
                }
                Err(e) => {
                    failed = Some(format!("frame {i}: {e}"));
                    break;
                }
            }
        }
        if let Some(e) = failed {
            println!("{:<8} {:<6} failed: {e}", backend.name(), mode.name());
            continue;
        }
        let hits: usize = answers.iter().map(Vec::len).sum();
        let diffs = match &truth {
            None => {
                truth = Some(answers.clone());
                0
            }
            Some(t) => t
                .iter()
                .zip(&answers)
                .map(|(t, g)| {
                    t.iter().filter(|x| !g.contains(x)).count()
                        + g.iter().filter(|x| !t.contains(x)).count()
                })
                .sum(),
        };
        let mean = times.iter().sum::<f64>() / times.len() as f64;
        times.sort_by(f64::total_cmp);
        let row = BenchRow {
            backend: backend.name().into(),
            mode: mode.name().into(),
            frames,
            median_us: percentile(&times, 0.5),
            mean_us: mean,
            p95_us: percentile(&times, 0.95),
            max_us: percentile(&times, 1.0),
            interferences: hits,
            differences_from_cpu_exact: diffs,
            devices: checker.adapters(),
            note: checker.notes().join("; "),
        };
        println!(
            "{:<8} {:<6} {:>10.1} {:>10.1} {:>10.1} {:>10.1} {:>7} {:>6}  {} {}",
            row.backend,
            row.mode,
            row.median_us,
            row.mean_us,
            row.p95_us,
            row.max_us,
            row.interferences,
            row.differences_from_cpu_exact,
            row.devices.join(", "),
            row.note
        );
        out.push(row);
    }
    if let Some(path) = json {
        let text = serde_json::to_string_pretty(&out).context("bench table to JSON")?;
        std::fs::write(path, text + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

pub fn calibrate(output: &Path, repetitions: usize, cpu_only: bool) -> Result<()> {
    if repetitions == 0 {
        bail!("--repetitions must be at least 1");
    }
    let t = Instant::now();
    let model = frcd_hybrid::calibrate::measure(&frcd_hybrid::calibrate::CalibrateOptions {
        repetitions,
        gpu: !cpu_only,
    });
    model.save(output)?;
    println!(
        "{} written in {:.1} s{}",
        output.display(),
        t.elapsed().as_secs_f64(),
        if model.adapter.is_empty() {
            String::from(" (no GPU figures)")
        } else {
            format!(" (GPU: {})", model.adapter)
        }
    );
    println!(
        "{}",
        serde_json::to_string_pretty(&model).context("model to JSON")?
    );
    match model.gpu_broad_min_bodies() {
        Some(n) => println!("GPU box pass from {n} bodies"),
        None => println!("GPU box pass: never"),
    }
    match model.gpu_narrow_min_triangles() {
        Some(n) => println!("GPU pair query from {n} triangles per pair"),
        None => println!("GPU pair query: never"),
    }
    Ok(())
}
