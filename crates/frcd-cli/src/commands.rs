//! The subcommands.

use crate::{BackendArg, CheckerArgs, ModeArg};
use anyhow::{Context, Result, bail};
use frcd_geom::Pose;
use frcd_hybrid::{
    Accuracy, Backend, BodySpec, Checker, Contact, CostModel, FrameResult, FrameState, Options,
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
    pub pairs: bool,
    pub clearance: crate::clearance_run::ClearanceArgs,
    /// `frcd plot-clearance`: print only the clearance summary (and write the plot).
    pub plot_only: bool,
}

fn load_scene(path: &Path, args: &CheckerArgs) -> Result<Scene> {
    let options = frcd_io::SceneOptions {
        allow_outside: args.allow_outside,
        trajectories: args.trajectory.iter().cloned().collect(),
        ..Default::default()
    };
    Scene::load_with(path, &options)
        .with_context(|| format!("cannot load scene {}", term(&path.display().to_string())))
}

/// The text of a name or path as shown on a terminal: control characters (escape sequences,
/// newlines, carriage returns) are shown escaped, never sent raw.
pub fn term(s: &str) -> String {
    if !s.chars().any(char::is_control) {
        return s.to_owned();
    }
    s.chars()
        .flat_map(|c| {
            if c.is_control() {
                c.escape_default().collect::<Vec<_>>()
            } else {
                vec![c]
            }
        })
        .collect()
}

/// The cost model: `--cost`, else $FRCD_COST_MODEL, else the built-in figures. A model file
/// in the working folder is never picked up by itself (only named); when one is there and
/// unused, a note says so.
fn cost_model(path: Option<&Path>, quiet: bool) -> Result<(CostModel, String)> {
    let explicit = path
        .map(Path::to_path_buf)
        .or_else(|| std::env::var_os("FRCD_COST_MODEL").map(PathBuf::from));
    let Some(p) = explicit else {
        if !quiet && Path::new("frcd-cost.json").is_file() {
            eprintln!(
                "note: ./frcd-cost.json is not used unless named: pass --cost frcd-cost.json or set FRCD_COST_MODEL"
            );
        }
        return Ok((CostModel::default(), "built-in".into()));
    };
    // A regular file within the JSON limit (never a FIFO or /dev/zero), then the model's own
    // reader and checks.
    frcd_io::read_limited(&p, frcd_io::MAX_JSON_BYTES).context("cannot read the cost model")?;
    let m = CostModel::load(&p)?;
    Ok((m, term(&p.display().to_string())))
}

/// Output files of a run, checked before any work: each can be written (folder exists and
/// takes a file, not a directory or FIFO), none is another output, none is an input.
fn check_outputs(outputs: &[(&str, &Path)], inputs: &[PathBuf]) -> Result<()> {
    for (i, (flag, out)) in outputs.iter().enumerate() {
        let shown = term(&out.display().to_string());
        for input in inputs {
            if frcd_io::same_file(out, input) {
                bail!(
                    "{flag} {shown} is one of the run's inputs ({}): refusing to overwrite it",
                    term(&input.display().to_string())
                );
            }
        }
        for (flag2, out2) in &outputs[..i] {
            if frcd_io::same_file(out, out2) {
                bail!("{flag} {shown} is also given to {flag2}: each output needs its own file");
            }
        }
        frcd_io::check_output_path(out).with_context(|| format!("{flag} {shown}"))?;
    }
    Ok(())
}

/// Notes on the meshes a scene loaded: degenerate or duplicate triangles, open or
/// non-manifold surfaces (and what that means for solid mode).
fn mesh_notes(scene: &Scene, solid: bool) -> Vec<String> {
    let mut notes = Vec::new();
    for (i, m) in scene.meshes().iter().enumerate() {
        let file = term(&scene.mesh_paths()[i].display().to_string());
        let r = m.report();
        let t = m.topology();
        let mut found = Vec::new();
        if !r.degenerate.is_empty() {
            found.push(format!(
                "{} degenerate (zero-area) triangles",
                r.degenerate.len()
            ));
        }
        if !r.duplicates.is_empty() {
            found.push(format!("{} duplicate triangles", r.duplicates.len()));
        }
        if t.boundary_edges > 0 {
            found.push(format!("open ({} boundary edges)", t.boundary_edges));
        }
        if !t.is_manifold() {
            found.push(format!(
                "non-manifold ({} edges, {} vertices)",
                t.non_manifold_edges, t.non_manifold_vertices
            ));
        } else if !t.is_oriented() {
            found.push(format!(
                "inconsistently oriented ({} edges)",
                t.orientation_conflicts
            ));
        }
        if found.is_empty() {
            continue;
        }
        let mut note = format!("mesh {file}: {}", found.join(", "));
        if solid && !t.is_closed() {
            note.push_str(
                "; it is not closed, so containment in it cannot be decided: only surface contact is reported for its bodies",
            );
        }
        notes.push(note);
    }
    notes
}

/// Progress on a terminal only: a line on stderr refreshed every 250 ms by its own thread (so
/// it moves during one long frame too), erased at the end. Nothing when stderr is not a
/// terminal or with `-q`.
struct Progress {
    done: std::sync::Arc<std::sync::atomic::AtomicUsize>,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Progress {
    fn start(total: usize, enabled: bool) -> Self {
        use std::io::IsTerminal;
        use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
        let done = std::sync::Arc::new(AtomicUsize::new(0));
        let stop = std::sync::Arc::new(AtomicBool::new(false));
        let thread = (enabled && std::io::stderr().is_terminal()).then(|| {
            let (done, stop) = (done.clone(), stop.clone());
            std::thread::spawn(move || {
                let t0 = Instant::now();
                let mut shown = false;
                while !stop.load(Ordering::Relaxed) {
                    std::thread::sleep(std::time::Duration::from_millis(250));
                    if stop.load(Ordering::Relaxed) {
                        break;
                    }
                    let k = done.load(Ordering::Relaxed);
                    eprint!(
                        "\r\x1b[Kframe {k}/{total} ({:.0}%), {:.1} s",
                        100.0 * k as f64 / total.max(1) as f64,
                        t0.elapsed().as_secs_f64()
                    );
                    let _ = std::io::stderr().flush();
                    shown = true;
                }
                if shown {
                    eprint!("\r\x1b[K");
                    let _ = std::io::stderr().flush();
                }
            })
        });
        Self { done, stop, thread }
    }

    fn set(&self, k: usize) {
        self.done.store(k, std::sync::atomic::Ordering::Relaxed);
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// A measured time in microseconds, rounded to 0.1 µs (the clock and the call around it are
/// not finer than that).
fn round_us(us: f64) -> f64 {
    (us * 10.0).round() / 10.0
}

fn backend_of(b: BackendArg) -> Backend {
    match b {
        BackendArg::Cpu => Backend::Cpu,
        BackendArg::Gpgpu => Backend::Gpgpu,
        BackendArg::Image => Backend::Image,
        BackendArg::Hybrid => Backend::Hybrid,
    }
}

fn mode_of(m: ModeArg) -> Accuracy {
    match m {
        ModeArg::Exact => Accuracy::Exact,
        ModeArg::Fast => Accuracy::Fast,
    }
}

fn fit_of(f: crate::FitArg) -> frcd_obb::FitMethod {
    match f {
        crate::FitArg::Vertex => frcd_obb::FitMethod::VertexCovariance,
        crate::FitArg::Area => frcd_obb::FitMethod::AreaWeighted,
        crate::FitArg::Hull => frcd_obb::FitMethod::HullSurface,
    }
}

fn split_of(s: crate::SplitArg) -> frcd_obb::SplitMethod {
    match s {
        crate::SplitArg::Surface => frcd_obb::SplitMethod::SurfaceCost,
        crate::SplitArg::Mean => frcd_obb::SplitMethod::MajorAxisMean,
    }
}

fn options_of(args: &CheckerArgs, segments: bool, quiet: bool) -> Result<(Options, String)> {
    if !(16..=4096).contains(&args.resolution) {
        bail!("--resolution {} is outside 16..=4096", args.resolution);
    }
    let (cost, source) = cost_model(args.cost.as_deref(), quiet)?;
    Ok((
        Options {
            mode: mode_of(args.mode),
            backend: backend_of(args.backend),
            segments,
            image_resolution: args.resolution,
            cost,
            build: frcd_obb::BuildOptions {
                fit: fit_of(args.fit),
                max_leaf_triangles: args.leaf.max(1),
                split: split_of(args.split),
            },
            clearance_build: Some(frcd_obb::BuildOptions {
                fit: fit_of(args.fit),
                max_leaf_triangles: args.clearance_leaf.max(1),
                split: split_of(args.split),
            }),
            clearance_spin: !args.no_spin_bound,
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
    pairs: bool,
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
                triangles: if pairs {
                    c.pairs.iter().map(|&(x, y)| [x, y]).collect()
                } else {
                    Vec::new()
                },
            }
        })
        .collect();
    FrameReport {
        index,
        time_us: round_us(time_us),
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
    if run.count == Some(0) {
        bail!("--count 0 checks nothing: give at least 1 (or leave it out for every frame)");
    }
    // Outputs first: a typo or an output over an input costs nothing.
    let mut outputs: Vec<(&str, &Path)> = Vec::new();
    if let Some(p) = &run.json {
        outputs.push(("--json", p));
    }
    if let Some(p) = &run.csv {
        outputs.push(("--csv", p));
    }
    if let Some(p) = &run.clearance.plot {
        outputs.push((
            if run.plot_only {
                "--output"
            } else {
                "--plot-clearance"
            },
            p,
        ));
    }
    if let Some(t) = run.clearance.threshold {
        frcd_io::check_clearance(t).map_err(|m| anyhow::anyhow!("--clearance: {m}"))?;
    }
    let mut early_inputs = vec![run.scene.clone()];
    early_inputs.extend(run.checker.trajectory.iter().cloned());
    early_inputs.extend(run.checker.cost.iter().cloned());
    check_outputs(&outputs, &early_inputs)?;
    let scene = load_scene(&run.scene, &run.checker)?;
    let mut inputs = scene.input_paths();
    inputs.extend(early_inputs);
    check_outputs(&outputs, &inputs)?;

    let n = scene.frame_count();
    if run.first >= n {
        bail!(
            "--first {} is past the last frame (the scene has {n})",
            run.first
        );
    }
    // A count past the end (even one that would overflow) means "to the last frame".
    let end = match run.count {
        Some(c) => run.first.saturating_add(c).min(n),
        None => n,
    };
    let (mut options, cost_source) = options_of(&run.checker, run.segments, run.quiet)?;
    let mode = options.mode;
    let solid = options.solid;
    let t_setup = Instant::now();
    let mut clearance = crate::clearance_run::ClearanceRun::new(&scene, &run.clearance)?;
    if let Some(c) = &clearance {
        c.apply(&mut options);
    }
    let checker = make_checker(&scene, options)?;
    let setup_ms = t_setup.elapsed().as_secs_f64() * 1e3;
    let mut notes: Vec<String> = checker.notes().iter().map(|n| term(n)).collect();
    notes.extend(mesh_notes(&scene, solid));
    if !run.quiet {
        for note in &notes {
            eprintln!("note: {note}");
        }
    }
    let mut report = Report::new(checker.options().backend.name(), mode.name());
    report.scene = Some(run.scene.display().to_string());
    report.frame_range = Some([run.first, end - 1]);
    let mut state = FrameState::default();
    let mut tallies: [StageTally; 3] = Default::default();
    let mut pair_time: std::collections::HashMap<(usize, usize), (f64, usize)> = Default::default();
    let total = end - run.first;
    let progress = Progress::start(total, !run.quiet);
    for (k, frame) in scene.frames().range(run.first..end).enumerate() {
        let index = run.first + k;
        let poses = &frame.poses;
        let t = Instant::now();
        let r = checker
            .check(poses, &mut state)
            .with_context(|| format!("frame {index}"))?;
        let time_us = t.elapsed().as_secs_f64() * 1e6;
        if let Some(c) = clearance.as_mut() {
            c.frame(&r);
        }
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
            .push(frame_report(&checker, index, time_us, &r, poses, run.pairs));
        progress.set(k + 1);
    }
    drop(progress);
    report.summarize();
    let mut times: Vec<f64> = report.frames.iter().map(|f| f.time_us).collect();
    times.sort_by(f64::total_cmp);
    let median = percentile(&times, 0.5);
    let name = |i: usize| term(checker.body_name(i).unwrap_or("?"));
    if !run.quiet && !run.plot_only {
        println!(
            "{}: {} bodies, {} triangles, frames {}..={} ({} checked); backend {}, mode {}, cost model {}",
            term(&run.scene.display().to_string()),
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
            println!("  device {}", term(&a));
        }
        println!(
            "  time per frame: median {:.1} µs, p95 {:.1} µs, max {:.1} µs (setup {:.0} ms)",
            median,
            percentile(&times, 0.95),
            percentile(&times, 1.0),
            setup_ms
        );
        for (stage, t) in ["broad", "image", "narrow"].iter().zip(&tallies) {
            println!("  stage {stage:<6}: {}", t.describe());
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
                    name(*a),
                    name(*b)
                );
            }
        }
        if report.pairs.is_empty() {
            println!("no interference");
        } else {
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
                let what = match (p.max_triangle_pairs, p.contained) {
                    (0, true) => "contained".to_string(),
                    (n, true) => format!("up to {n} triangle pairs, or contained"),
                    (n, false) => format!("up to {n} triangle pairs"),
                };
                println!(
                    "  {} / {}: frames {}..={} ({} frames, {what}): {}",
                    term(&p.a),
                    term(&p.b),
                    p.first_frame,
                    p.last_frame,
                    p.frames,
                    intervals.join(", ")
                );
            }
        }
    }
    if !run.quiet
        && let Some(c) = &clearance
    {
        c.print(&report);
    }
    if let (Some(c), Some(path)) = (&clearance, &run.clearance.plot) {
        let n = c.plot(path, &report, &run.clearance)?;
        if !run.quiet {
            println!(
                "{}: clearance of {n} pairs plotted",
                term(&path.display().to_string())
            );
        }
    }
    if let Some(path) = &run.json {
        /// The report plus the run's figures, serialised straight to text (no JSON tree in
        /// memory: a million frames would take a gigabyte as `serde_json::Value`).
        #[derive(serde::Serialize)]
        struct Full<'a> {
            #[serde(flatten)]
            report: &'a Report,
            median_time_us: f64,
            setup_ms: f64,
            stages: serde_json::Value,
            devices: Vec<String>,
            notes: &'a [String],
        }
        let full = Full {
            report: &report,
            median_time_us: median,
            setup_ms: setup_ms.round(),
            stages: serde_json::json!({"broad": tallies[0], "image": tallies[1], "narrow": tallies[2]}),
            devices: checker.adapters(),
            notes: &notes,
        };
        let mut text = match &clearance {
            // Clearance goes into every frame: through a JSON tree (the streamed form when the
            // run has no clearance).
            Some(c) => {
                let mut value = serde_json::to_value(&full).context("report to JSON")?;
                c.add_json(&mut value, &report)?;
                serde_json::to_vec_pretty(&value).context("report to JSON")?
            }
            None => serde_json::to_vec_pretty(&full).context("report to JSON")?,
        };
        text.push(b'\n');
        frcd_io::write_atomic(path, &text)?;
    }
    if let Some(path) = &run.csv {
        match &clearance {
            Some(c) => frcd_io::write_atomic(path, c.csv(&report).as_bytes())?,
            None => report.write_csv(path)?,
        }
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
    let early_inputs: Vec<PathBuf> = std::iter::once(scene_path.to_path_buf())
        .chain(args.trajectory.iter().cloned())
        .chain(args.cost.iter().cloned())
        .collect();
    check_outputs(&[("--output", output)], &early_inputs)?;
    let scene = load_scene(scene_path, args)?;
    let mut inputs = scene.input_paths();
    inputs.extend(early_inputs);
    check_outputs(&[("--output", output)], &inputs)?;
    let Some(frame_poses) = scene.frames().get(frame) else {
        bail!(
            "--frame {frame} is past the last frame (the scene has {})",
            scene.frame_count()
        );
    };
    let poses = &frame_poses.poses;
    let (options, _) = options_of(args, false, false)?;
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
            term(&output.display().to_string()),
            r.contacts.len(),
            r.contacts.iter().map(|c| c.pairs.len()).sum::<usize>()
        );
        for c in &r.contacts {
            println!(
                "  {} / {}: {} triangle pairs{}",
                term(checker.body_name(c.a).unwrap_or("?")),
                term(checker.body_name(c.b).unwrap_or("?")),
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
    allow_outside: bool,
) -> Result<()> {
    let early_inputs: Vec<PathBuf> = std::iter::once(scene_path.to_path_buf())
        .chain(cost.map(Path::to_path_buf))
        .collect();
    let outputs: Vec<(&str, &Path)> = json.map(|p| ("--json", p)).into_iter().collect();
    check_outputs(&outputs, &early_inputs)?;
    let scene = Scene::load_with(
        scene_path,
        &frcd_io::SceneOptions {
            allow_outside,
            ..Default::default()
        },
    )
    .with_context(|| {
        format!(
            "cannot load scene {}",
            term(&scene_path.display().to_string())
        )
    })?;
    let mut inputs = scene.input_paths();
    inputs.extend(early_inputs);
    check_outputs(&outputs, &inputs)?;
    if frames == 0 {
        bail!("--frames 0 times nothing: give at least 1");
    }
    let frames = frames.min(scene.frame_count());
    let all: Vec<Vec<Pose>> = scene.frames().range(0..frames).map(|f| f.poses).collect();
    let (cost, source) = cost_model(cost, false)?;
    println!(
        "{}: {} bodies, {} triangles, {} frames timed per row; cost model {source}",
        term(&scene_path.display().to_string()),
        scene.bodies().len(),
        scene.triangle_count(),
        frames
    );
    let rows = [
        (Backend::Cpu, Accuracy::Exact),
        (Backend::Hybrid, Accuracy::Exact),
        (Backend::Gpgpu, Accuracy::Exact),
        (Backend::Hybrid, Accuracy::Fast),
        (Backend::Image, Accuracy::Fast),
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
        frcd_io::write_atomic(path, (text + "\n").as_bytes())?;
    }
    Ok(())
}

pub fn calibrate(output: &Path, repetitions: usize, cpu_only: bool) -> Result<()> {
    if repetitions == 0 {
        bail!("--repetitions must be at least 1");
    }
    check_outputs(&[("--output", output)], &[])?;
    let t = Instant::now();
    let model = frcd_hybrid::calibrate::measure(&frcd_hybrid::calibrate::CalibrateOptions {
        repetitions,
        gpu: !cpu_only,
    });
    let text = serde_json::to_string_pretty(&model).context("model to JSON")?;
    frcd_io::write_atomic(output, (text + "\n").as_bytes())?;
    println!(
        "{} written in {:.1} s{}",
        term(&output.display().to_string()),
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
    println!(
        "use it with `frcd check --cost {0}` (or FRCD_COST_MODEL={0}); it is never picked up by itself",
        term(&output.display().to_string())
    );
    Ok(())
}
