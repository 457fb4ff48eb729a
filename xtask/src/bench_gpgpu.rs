//! `cargo xtask bench gpgpu`: the GPGPU pipeline against the CPU OBB traversal by scene size,
//! written to `testdata/bench/gpgpu.md` (table) and `testdata/bench/gpgpu.svg` (plot).
//!
//! Pair queries: a step queries `--pairs K` body pairs (default 8), each two icospheres of
//! `20·4^level` triangles crossing each other at a different pose, every touching triangle pair
//! wanted. Timed per step (median of `--runs N`, default 5):
//! - CPU, one thread: `frcd_obb::collide` (all pairs) on each body pair in turn;
//! - CPU, all threads: the same body pairs on rayon's pool;
//! - GPU: `GpuContext::collide` on each body pair in turn, transfers included (pose upload,
//!   submission, readback, CPU re-decision of uncertain pairs). Mesh uploads happen once and are
//!   reported separately;
//! - GPU batch: the step's body pairs in one `GpuContext::collide_batch` (one submission, one
//!   readback), its answers checked equal to the CPU's first.
//!
//! Every GPU answer is checked against the CPU's (a difference aborts the run).
//!
//! Many-body frames (`--frame-parts 2,8,64`): parts of 20k-55k triangles (64 parts: about 2M
//! triangles) jittering on a grid; each frame a CPU sort-and-sweep broad phase, then every
//! candidate body pair: on the CPU (`frcd_obb::collide` one pair after another, or on rayon's
//! pool) or on the GPU (`GpuContext::collide_batch`: one dispatch chain, one submission, one
//! readback per frame). Answers checked equal on every frame.
//!
//! Many bodies (`--bodies 1,16,256,1024,4096,16384`): the rough colliding set of n boxes scattered
//! with about 4 neighbours each, by four methods, answers checked equal: the CPU all-pairs test,
//! the CPU broad phase (`frcd_obb::overlapping_boxes`, the `World`'s: a sweep along the widest
//! axis, or a uniform grid where the boxes fill a volume; one thread; before 2026-11-27 this
//! column was a sweep along x, which grows as n^1.6 on this scatter), the GPU all-pairs pass
//! (`overlapping_bodies_all_pairs`) and the GPU
//! sort-and-sweep (`overlapping_bodies`: bitonic sort in WGSL, scan, one submission). The
//! all-pairs columns are left out above 4,096 bodies. `--boxes-only` runs this section alone
//! (plus the checker section when asked for).
//!
//! Checker (`--checker-parts 16,64`, off by default): the many-body frames through
//! `frcd_hybrid::Checker`, 8 distinct frames in sequence, time per frame: the CPU backend, the
//! GPGPU backend with `check` (box pass and one pair batch per frame) and with
//! `check_pipelined` (frame k+1's batch submitted before frame k is finished). Answers checked
//! equal on every frame.
//!
//! The crossover (the smallest size where the GPU is faster) is printed for each comparison.
//! Options: `--levels 1,2,3,4,5`, `--pairs K`, `--bodies 100,400,...`, `--runs N`, `--out DIR`.
//!
//! GPU clocks: a hardware GPU's driver picks its clock from how busy it has been. An H200
//! idles at 345 MHz (boost 1,980) and stays there through a few milliseconds of work after a
//! few seconds of CPU-side setup, so every GPU timing first repeats its work for
//! `--gpu-warmup-ms` (500 on hardware, 0 on a software driver), and on NVIDIA adapters the
//! breakdown table records the SM clock after each row (`nvidia-smi`).

use anyhow::{Context, Result, bail};
use frcd_geom::{Aabb, DQuat, DVec3, Pose, shapes};
use frcd_gpgpu::{BoxScratch, GpuContext, GpuMesh, QueryScratch};
use frcd_obb::{BuildOptions, Mode, ObbTree, Request, collide};
use rayon::prelude::*;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Options of `cargo xtask bench gpgpu`.
#[derive(clap::Args, Debug)]
pub struct Opts {
    /// Icosphere subdivision levels of the pair queries (20·4^level triangles per body).
    #[arg(
        long,
        value_name = "L,..",
        value_delimiter = ',',
        default_value = "1,2,3,4,5"
    )]
    pub levels: Vec<u32>,
    /// Body pairs per step.
    #[arg(long, value_name = "K", default_value_t = 8, value_parser = crate::positive::<usize>)]
    pub pairs: usize,
    /// Body counts of the many-body box pass.
    #[arg(
        long,
        value_name = "N,..",
        value_delimiter = ',',
        default_value = "1,16,256,1024,4096,16384"
    )]
    pub bodies: Vec<usize>,
    /// Part counts of the many-body frames.
    #[arg(
        long = "frame-parts",
        value_name = "N,..",
        value_delimiter = ',',
        default_value = "2,8,64"
    )]
    pub frames: Vec<usize>,
    /// Timed runs per point (the median is reported).
    #[arg(long, value_name = "N", default_value_t = 5, value_parser = crate::positive::<usize>)]
    pub runs: usize,
    /// Folder for gpgpu.md and gpgpu.svg.
    #[arg(long, value_name = "DIR", default_value_os_t = crate::workspace_path("testdata/bench"))]
    pub out: PathBuf,
    /// Only the many-body box pass (no pair queries, no frames).
    #[arg(long)]
    pub boxes_only: bool,
    /// Part counts of the checker section (CPU backend, GPGPU `check`, `check_pipelined`);
    /// empty: skipped.
    #[arg(long = "checker-parts", value_name = "N,..", value_delimiter = ',')]
    pub checker: Vec<usize>,
    /// Checker section: also time GPGPU `check` and `check_pipelined` with GPU trees of these
    /// leaf sizes (`frcd_hybrid::Options::gpu_build`), alternated run by run with the default's
    /// in one process (answers checked equal to the CPU backend's); empty: skipped.
    #[arg(
        long = "checker-gpu-leaves",
        value_name = "N,..",
        value_delimiter = ','
    )]
    pub checker_gpu_leaves: Vec<u32>,
    /// Checker section: also time GPGPU `check` and `check_pipelined` with these CPU fronts
    /// (box tests per level, `frcd_hybrid::Options::gpu_host_front`; 0: the GPU starts at the
    /// roots), alternated run by run with the default's in one process (answers checked
    /// equal); empty: skipped.
    #[arg(
        long = "checker-host-front",
        value_name = "TESTS,..",
        value_delimiter = ','
    )]
    pub checker_host_front: Vec<u32>,
    /// Checker section: also time GPGPU `check` and `check_pipelined` with the pair batch's
    /// traversal in one dispatch of these workgroups (`frcd_hybrid::Options::gpu_one_pass`; 0:
    /// one dispatch per level), each with the default CPU front and with every front of
    /// `--checker-host-front`, alternated run by run with the default's in one process (answers
    /// checked equal).
    #[arg(
        long = "checker-one-pass",
        value_name = "WORKGROUPS,..",
        value_delimiter = ','
    )]
    pub checker_one_pass: Vec<u32>,
    /// Checker section: also time GPGPU `check` and `check_pipelined` re-deciding only the
    /// pairs the GPU left uncertain (`frcd_hybrid::Options::gpu_recheck_certified` false),
    /// alternated run by run with the default's in one process (answers checked equal).
    #[arg(long = "checker-recheck-uncertain")]
    pub checker_recheck_uncertain: bool,
    /// Checker section: also time GPGPU `check` and `check_pipelined` with the box pass on the
    /// GPU from these body counts on (`frcd_hybrid::Options::gpgpu_box_pass_min_bodies`; 0: the
    /// GPU box pass always), alternated run by run with the default's in one process (answers
    /// checked equal).
    #[arg(
        long = "checker-box-pass-min",
        value_name = "BODIES,..",
        value_delimiter = ','
    )]
    pub checker_box_pass_min: Vec<usize>,
    /// Checker section: also time GPGPU `check` and `check_pipelined` with these variants of the
    /// traversal shader (`frcd_gpgpu::SHADER_VARIANT_ENV`, set while each variant's checker is
    /// built: `traverse.wgsl`'s `VARIANT`, which only a contrast build of the shader reads),
    /// alternated run by run with variant 0 in one process (answers checked equal).
    #[arg(
        long = "checker-shader-variants",
        value_name = "VARIANT,..",
        value_delimiter = ','
    )]
    pub checker_shader_variants: Vec<u32>,
    /// Checker section: also time GPGPU `check_pipelined` in both orders of a call's work
    /// (`frcd_hybrid::Pipeline::set_decide_first`: frame k re-decided before or after frame
    /// k+1's batch is submitted), alternated run by run in one process (answers checked equal).
    #[arg(long = "checker-pipeline-orders")]
    pub checker_pipeline_orders: bool,
    /// Checker section: after the timings, run only GPGPU `check` on the frames, over and over,
    /// for this many seconds (for a profiler such as `perf record` to see the GPGPU frame alone,
    /// without the CPU backend's frames or the scene's setup in its samples); prints the wall
    /// and CPU time per frame. Left out: not run.
    #[arg(long = "checker-soak-s", value_name = "SECONDS")]
    pub checker_soak_s: Option<f64>,
    /// Time every GPU pass of the batches with GPU timestamps (where the adapter has
    /// timestamps inside passes) for the breakdown table; the host's split (waiting for the
    /// GPU, the CPU's re-decision) is always written.
    #[arg(long)]
    pub pass_timers: bool,
    /// The triangle pass's exact reference-point offsets (`GpuContext::set_exact_offsets`):
    /// `on` or `off`; left out, the context's default (on for hardware adapters, off for
    /// software ones, or `FRCD_GPGPU_EXACT_OFFSETS`).
    #[arg(long, value_name = "on|off", value_parser = parse_on_off)]
    pub exact_offsets: Option<bool>,
    /// Box tests per level the CPU may take off the GPU at the top of each batch's pair trees
    /// (`GpuContext::set_host_front`; 0: none); left out, the context's default (1,024 on a
    /// software adapter, 0 on a hardware one).
    #[arg(long = "host-front", value_name = "TESTS")]
    pub host_front: Option<u32>,
    /// Before each GPU timing, repeat the timed work for this many milliseconds, so that a
    /// hardware GPU has left its idle clock (an H200 idles at 345 MHz against 1,980 under load,
    /// and a few milliseconds of work every few seconds never raise it). Left out: 500 on a
    /// hardware adapter, 0 on a software one; 0 measures a cold GPU.
    #[arg(long = "gpu-warmup-ms", value_name = "MS")]
    pub gpu_warmup_ms: Option<u64>,
}

/// `on` / `off` as a bool (clap value parser).
fn parse_on_off(s: &str) -> std::result::Result<bool, String> {
    match s {
        "on" => Ok(true),
        "off" => Ok(false),
        _ => Err(format!("want on or off, got {s:?}")),
    }
}

/// Where the time of one row's batches went: medians over the timed batches.
struct Breakdown {
    what: String,
    body_pairs: usize,
    /// Triangle pairs the GPU reported (touching or uncertain), all re-decided on the CPU.
    reported: usize,
    uncertain: usize,
    batch_ms: f64,
    wait_ms: f64,
    decide_ms: f64,
    /// The CPU's descent of the top of the pair trees (`GpuContext::set_host_front`).
    front_ms: f64,
    /// Levels the CPU descended, then those the GPU ran.
    host_levels: u32,
    gpu_levels: u32,
    /// GPU chain, its traversal levels, its triangle pass (pass timers only).
    gpu_ms: Option<[f64; 3]>,
    /// Each traversal level's GPU time (pass timers only; else empty).
    levels_ms: Vec<f64>,
    /// The GPU's SM clock right after the timed runs (NVIDIA only, see [`gpu_clock_mhz`]).
    clock_mhz: Option<u32>,
}

impl Breakdown {
    fn new(
        what: String,
        batch_ms: f64,
        got: &frcd_gpgpu::GpuBatch,
        samples: &[frcd_gpgpu::BatchTimings],
        clock_mhz: Option<u32>,
    ) -> Self {
        let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
        let med = |f: &dyn Fn(&frcd_gpgpu::BatchTimings) -> f64| {
            let mut v: Vec<f64> = samples.iter().map(f).collect();
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
        };
        let timed = samples.iter().all(|t| t.gpu_total.is_some()) && !samples.is_empty();
        Self {
            what,
            body_pairs: got.results.len(),
            reported: got
                .results
                .iter()
                .map(|r| r.gpu_decided + r.gpu_refuted + r.uncertain)
                .sum(),
            uncertain: got.results.iter().map(|r| r.uncertain).sum(),
            batch_ms,
            wait_ms: med(&|t| ms(t.wait)),
            decide_ms: med(&|t| ms(t.decide)),
            front_ms: med(&|t| ms(t.host_front)),
            host_levels: got.host_levels,
            gpu_levels: got.levels,
            gpu_ms: timed.then(|| {
                [
                    med(&|t| ms(t.gpu_total.unwrap_or_default())),
                    med(&|t| t.gpu_levels.iter().map(|&d| ms(d)).sum()),
                    med(&|t| ms(t.gpu_triangles.unwrap_or_default())),
                ]
            }),
            levels_ms: if timed {
                let n = samples
                    .iter()
                    .map(|t| t.gpu_levels.len())
                    .max()
                    .unwrap_or(0);
                (0..n)
                    .map(|i| med(&|t| t.gpu_levels.get(i).map_or(0.0, |&d| ms(d))))
                    .collect()
            } else {
                Vec::new()
            },
            clock_mhz,
        }
    }

    fn line(&self) -> String {
        let gpu = match self.gpu_ms {
            Some([all, lv, tr]) => {
                format!("GPU chain {all:.2} ms (levels {lv:.2}, triangles {tr:.2})")
            }
            None => "no pass timers".into(),
        };
        let clock = self
            .clock_mhz
            .map_or(String::new(), |c| format!(", SM clock after {c} MHz"));
        format!(
            "{}: batch {:.2} ms = CPU front {:.2} ms ({} levels) + wait {:.2} ms ({} GPU levels; {gpu}) + CPU re-decision {:.2} ms of {} reported pairs ({} uncertain){clock}",
            self.what,
            self.batch_ms,
            self.front_ms,
            self.host_levels,
            self.wait_ms,
            self.gpu_levels,
            self.decide_ms,
            self.reported,
            self.uncertain
        )
    }
}

/// The first NVIDIA GPU's SM clock in MHz from `nvidia-smi`, or `None` (another vendor, no
/// `nvidia-smi`, or no answer within [`CLOCK_QUERY_TIMEOUT`]: a hung driver tool must not hang
/// the bench). GPU timings follow the clock the driver's governor picks: an H200 idles at
/// 345 MHz and runs short batches with host round trips at 345-1,400 MHz, far from its 1,980.
fn gpu_clock_mhz(vendor: u32) -> Option<u32> {
    const NVIDIA: u32 = 0x10de;
    if vendor != NVIDIA {
        return None;
    }
    let mut cmd = std::process::Command::new("nvidia-smi");
    cmd.args([
        "--query-gpu=clocks.sm",
        "--format=csv,noheader,nounits",
        "-i",
        "0",
    ]);
    parse_clock(&output_within(cmd, CLOCK_QUERY_TIMEOUT)?)
}

/// How long the bench waits for `nvidia-smi` to print a clock (it answers in tens of ms).
const CLOCK_QUERY_TIMEOUT: Duration = Duration::from_secs(3);

/// The standard output of `cmd` when it exits successfully within `timeout`; otherwise the
/// process is killed and reaped, and `None`. The output is read after the exit, so it is for
/// tools that print less than a pipe holds (64 KiB on Linux): a longer answer would block the
/// tool until the timeout.
fn output_within(mut cmd: std::process::Command, timeout: Duration) -> Option<Vec<u8>> {
    use std::io::Read;
    let mut child = cmd
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .ok()?;
    let deadline = Instant::now() + timeout;
    loop {
        match child.try_wait() {
            Ok(Some(status)) => {
                let mut out = Vec::new();
                child.stdout.take()?.read_to_end(&mut out).ok()?;
                return status.success().then_some(out);
            }
            Ok(None) if Instant::now() < deadline => {
                std::thread::sleep(Duration::from_millis(5));
            }
            _ => {
                let _ = child.kill();
                let _ = child.wait();
                return None;
            }
        }
    }
}

/// The first line of `nvidia-smi`'s answer as MHz.
fn parse_clock(out: &[u8]) -> Option<u32> {
    std::str::from_utf8(out)
        .ok()?
        .lines()
        .next()?
        .trim()
        .parse()
        .ok()
}

/// [`median_ms`] of GPU work, after repeating it for `warm` (at least once): a hardware GPU
/// left idle runs at its idle clock until it has been busy for a while. Returns the median and
/// how many untimed calls came first (callers that record a sample per call drop those).
fn gpu_median_ms(runs: usize, warm: Duration, mut f: impl FnMut()) -> (f64, usize) {
    let t0 = Instant::now();
    let mut untimed = 0;
    while untimed == 0 || t0.elapsed() < warm {
        f();
        untimed += 1;
    }
    // `median_ms` makes one untimed call of its own.
    (median_ms(runs, f), untimed + 1)
}

/// Median wall time in ms of `runs` calls (after one warm-up call).
fn median_ms(runs: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..runs)
        .map(|_| {
            let t0 = Instant::now();
            f();
            t0.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

struct PairRow {
    level: u32,
    triangles: usize,
    touching: usize,
    uncertain: usize,
    cpu1: f64,
    cpu_all: f64,
    gpu: f64,
    /// All body pairs of the step in one `collide_batch` (one submission, one readback).
    gpu_batch: f64,
    upload: f64,
}

struct FrameRow {
    parts: usize,
    triangles: usize,
    /// Per frame, averaged over the frames (a count below one frame's worth is not 0).
    candidates: f64,
    touching_bodies: f64,
    touching: f64,
    cpu1: f64,
    cpu_all: f64,
    gpu: f64,
    submissions: u32,
}

/// The parts of a many-body frame: CAD-sized closed meshes of 20k-55k triangles (about 31k on
/// average), of size ~2.
fn frame_part(i: usize) -> frcd_geom::TriMesh {
    match i % 4 {
        0 => shapes::icosphere(1.0, 5),
        1 => shapes::torus(0.8, 0.3, 200, 70).expect("torus"),
        2 => shapes::torus(0.85, 0.25, 300, 90).expect("torus"),
        _ => shapes::torus(0.75, 0.35, 250, 80).expect("torus"),
    }
}

/// Poses of frame `f`: parts (radius about 1.1) on a square grid of spacing 2.25, jittered by
/// up to 0.12 and turned by up to 0.5 rad, so many neighbours' boxes overlap (candidates) and
/// some of them touch.
fn frame_poses(n: usize, f: usize) -> Vec<Pose> {
    let side = (n as f64).sqrt().ceil() as usize;
    let mut seed = 0x9e37_79b9_7f4a_7c15u64 ^ (f as u64 * 0x1000_0001);
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    (0..n)
        .map(|i| {
            let c = DVec3::new(2.25 * (i % side) as f64, 2.25 * (i / side) as f64, 0.0);
            let j = DVec3::new(rnd(), rnd(), rnd()) * 0.12;
            let axis = DVec3::new(rnd(), rnd(), rnd()).normalize_or(DVec3::Z);
            Pose::new(c + j, DQuat::from_axis_angle(axis, 0.5 * rnd()))
        })
        .collect()
}

/// The CPU broad phase both backends share: world boxes of the trees' local boxes, pairs by
/// a sort on x and a sweep (f64, exact for the boxes).
fn broad_phase(trees: &[&ObbTree], poses: &[Pose]) -> Vec<(usize, usize)> {
    let boxes: Vec<Aabb> = trees
        .iter()
        .zip(poses)
        .map(|(t, p)| t.aabb().transformed(p))
        .collect();
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    order.sort_by(|&a, &b| boxes[a].min.x.total_cmp(&boxes[b].min.x));
    let mut out = Vec::new();
    for (k, &i) in order.iter().enumerate() {
        for &j in &order[k + 1..] {
            if boxes[j].min.x > boxes[i].max.x {
                break;
            }
            if boxes[i].intersects(&boxes[j]) {
                out.push((i.min(j), i.max(j)));
            }
        }
    }
    out.sort_unstable();
    out
}

struct BoxRow {
    bodies: usize,
    pairs: usize,
    /// CPU all-pairs (None above the all-pairs limit).
    cpu_all: Option<f64>,
    /// CPU broad phase (`frcd_obb::overlapping_boxes`), one thread.
    cpu: f64,
    /// GPU all-pairs pass (None above the all-pairs limit).
    gpu_all: Option<f64>,
    /// GPU sort-and-sweep.
    gpu: f64,
}

/// Largest body count timed with the O(n²) methods.
const ALL_PAIRS_LIMIT: usize = 4096;

/// Body-pair poses of a step: B crossing A at `0.9 + 0.1 k / K` along a turning direction.
fn step_poses(k: usize) -> Vec<(Pose, Pose)> {
    (0..k)
        .map(|i| {
            let s = i as f64 / k as f64;
            let dir = DVec3::new((6.0 * s).cos(), (6.0 * s).sin(), 0.3 - s).normalize();
            (
                Pose::new(
                    DVec3::new(10.0 * i as f64, 0.0, 0.0),
                    DQuat::from_rotation_z(s),
                ),
                Pose::new(
                    DVec3::new(10.0 * i as f64, 0.0, 0.0) + (0.9 + 0.1 * s) * dir,
                    DQuat::from_rotation_x(1.0 + s),
                ),
            )
        })
        .collect()
}

/// Milliseconds below which a time says nothing about a ratio (the timer's reach, 10 µs).
const TIMER_REACH_MS: f64 = 0.01;

fn crossover(label: &str, sizes: &[String], cpu: &[f64], gpu: &[f64]) -> String {
    // The smallest size from which the GPU is faster at every larger size; rows where both
    // times are below the timer's reach say nothing: they end the run and give no best ratio
    // (two near-zero times made a 1-body row's 0.50× the "best").
    let timed = |i: usize| cpu[i].max(gpu[i]) >= TIMER_REACH_MS;
    let faster = |i: usize| gpu[i] < cpu[i] && timed(i);
    match (0..sizes.len()).rev().take_while(|&i| faster(i)).last() {
        Some(i) => format!(
            "crossover ({label}): GPU faster from {} on ({:.2} ms vs {:.2} ms)",
            sizes[i], gpu[i], cpu[i]
        ),
        None => format!(
            "crossover ({label}): none in the measured range (GPU slower at the largest size; best ratio {:.2}×)",
            (0..sizes.len())
                .filter(|&i| cpu[i] > 0.0 && timed(i))
                .map(|i| gpu[i] / cpu[i])
                .fold(f64::INFINITY, f64::min)
        ),
    }
}

/// Runs the suite.
pub fn run(mut o: Opts) -> Result<()> {
    if o.boxes_only {
        o.levels.clear();
        o.frames.clear();
    }
    // Refused before any work (`from_secs_f64` would panic on infinity and on overflow).
    let soak = o
        .checker_soak_s
        .map(|s| {
            Duration::try_from_secs_f64(s).map_err(|e| {
                anyhow::anyhow!("--checker-soak-s {s}: not a duration in seconds ({e})")
            })
        })
        .transpose()?;
    let load_start = load_average();
    let mut ctx = GpuContext::headless_with(&frcd_gpgpu::HeadlessOptions {
        pass_timers: o.pass_timers,
        ..Default::default()
    })
    .context("bench gpgpu needs a GPU adapter")?;
    if o.pass_timers && !ctx.has_pass_timers() {
        println!("pass timers asked for, but the adapter has no timestamps inside passes");
    }
    if let Some(on) = o.exact_offsets {
        ctx.set_exact_offsets(on);
    }
    if let Some(tests) = o.host_front {
        ctx.set_host_front(tests);
    }
    let warm_ms = o
        .gpu_warmup_ms
        .unwrap_or(if ctx.is_software() { 0 } else { 500 });
    let warm = Duration::from_millis(warm_ms);
    let mut breakdowns: Vec<Breakdown> = Vec::new();
    let info = ctx.adapter_info().clone();
    let threads = rayon::current_num_threads();
    let request = Request {
        mode: Mode::AllPairs,
        ..Request::default()
    };
    let poses = step_poses(o.pairs);
    let mut rows = Vec::new();
    for &level in &o.levels {
        let mesh = shapes::icosphere(1.0, level);
        let tree = ObbTree::build(&mesh, &BuildOptions::default());
        let t0 = Instant::now();
        let gpu_mesh = ctx.upload(&tree)?;
        // The upload is queued; the first query's submission carries it. Time it with a
        // throw-away query so `upload` includes the transfer.
        let mut scratch = QueryScratch::default();
        ctx.collide(
            &gpu_mesh,
            &Pose::IDENTITY,
            &gpu_mesh,
            &Pose::from_translation(DVec3::splat(5.0)),
            &mut scratch,
        )?;
        let upload = t0.elapsed().as_secs_f64() * 1e3;
        // Correctness first: the GPU's pair sets equal the CPU's.
        let mut touching = 0;
        let mut uncertain = 0;
        for (pa, pb) in &poses {
            let cpu = collide(&tree, pa, &tree, pb, &request);
            let gpu = ctx.collide(&gpu_mesh, pa, &gpu_mesh, pb, &mut scratch)?;
            if cpu.pairs != gpu.pairs {
                bail!(
                    "level {level}: GPU found {} pairs, CPU {}",
                    gpu.pairs.len(),
                    cpu.pairs.len()
                );
            }
            touching += cpu.pairs.len();
            uncertain += gpu.uncertain;
        }
        let cpu1 = median_ms(o.runs, || {
            for (pa, pb) in &poses {
                std::hint::black_box(collide(&tree, pa, &tree, pb, &request));
            }
        });
        let cpu_all = median_ms(o.runs, || {
            poses.par_iter().for_each(|(pa, pb)| {
                std::hint::black_box(collide(&tree, pa, &tree, pb, &request));
            });
        });
        let (gpu, _) = gpu_median_ms(o.runs, warm, || {
            for (pa, pb) in &poses {
                std::hint::black_box(
                    ctx.collide(&gpu_mesh, pa, &gpu_mesh, pb, &mut scratch)
                        .expect("checked above"),
                );
            }
        });
        // The same step as one batch, with each re-decision policy: checked equal to the CPU's
        // answers first, then timed. The row's `GPU batch` column is the default (`All`).
        let batch: Vec<_> = poses
            .iter()
            .map(|(pa, pb)| (&gpu_mesh, pa, &gpu_mesh, pb))
            .collect();
        let want: Vec<_> = poses
            .iter()
            .map(|(pa, pb)| collide(&tree, pa, &tree, pb, &request).pairs)
            .collect();
        let mut gpu_batch = f64::NAN;
        for (recheck, label) in [
            (frcd_gpgpu::Recheck::All, ""),
            (frcd_gpgpu::Recheck::Uncertain, ", `Recheck::Uncertain`"),
        ] {
            ctx.set_recheck(recheck);
            let got = ctx.collide_batch(&batch, &mut scratch)?;
            if let Some(k) = (0..want.len()).find(|&k| got.results[k].pairs != want[k]) {
                bail!("level {level}{label}: the batch differs from the CPU on body pair {k}");
            }
            let mut samples = Vec::new();
            let (ms, untimed) = gpu_median_ms(o.runs, warm, || {
                let got = ctx
                    .collide_batch(&batch, &mut scratch)
                    .expect("checked above");
                samples.push(got.timings.clone());
                std::hint::black_box(got);
            });
            samples.drain(..untimed);
            if recheck == frcd_gpgpu::Recheck::All {
                gpu_batch = ms;
            }
            let b = Breakdown::new(
                format!("pair batch, level {level}{label}"),
                ms,
                &got,
                &samples,
                gpu_clock_mhz(info.vendor),
            );
            println!("{}", b.line());
            breakdowns.push(b);
        }
        ctx.set_recheck(frcd_gpgpu::Recheck::All);
        println!(
            "level {level}: {} triangles/body, {touching} pairs, cpu1 {cpu1:.2} ms, cpu{threads} {cpu_all:.2} ms, gpu {gpu:.2} ms, gpu batch {gpu_batch:.2} ms",
            mesh.triangle_count()
        );
        rows.push(PairRow {
            level,
            triangles: mesh.triangle_count(),
            touching,
            uncertain,
            cpu1,
            cpu_all,
            gpu,
            gpu_batch,
            upload,
        });
    }

    let mut frame_rows = Vec::new();
    for &n in &o.frames {
        let meshes: Vec<frcd_geom::TriMesh> = (0..n.min(4)).map(frame_part).collect();
        let trees_unique: Vec<ObbTree> = meshes
            .iter()
            .map(|m| ObbTree::build(m, &BuildOptions::default()))
            .collect();
        let gpu_unique: Vec<GpuMesh> = trees_unique
            .iter()
            .map(|t| ctx.upload(t))
            .collect::<Result<_, _>>()?;
        // Parts share meshes (as instances of a CAD part do); each body still has its pose.
        let trees: Vec<&ObbTree> = (0..n).map(|i| &trees_unique[i % 4]).collect();
        let triangles: usize = trees.iter().map(|t| t.triangles().len()).sum();
        let mut scratch = QueryScratch::default();
        // Eight fixed frames, cycled through by every timed run (same frames for each side).
        let frames: Vec<Vec<Pose>> = (0..8).map(|f| frame_poses(n, f)).collect();
        let (mut candidates, mut touching_bodies, mut touching, mut submissions) = (0, 0, 0, 0);
        // Correctness first, on every frame: the GPU's pairs equal the CPU's.
        for poses in &frames {
            let cand = broad_phase(&trees, poses);
            let batch: Vec<_> = cand
                .iter()
                .map(|&(i, j)| (&gpu_unique[i % 4], &poses[i], &gpu_unique[j % 4], &poses[j]))
                .collect();
            let got = ctx.collide_batch(&batch, &mut scratch)?;
            for (k, &(i, j)) in cand.iter().enumerate() {
                let cpu = collide(trees[i], &poses[i], trees[j], &poses[j], &request);
                if cpu.pairs != got.results[k].pairs {
                    bail!("frame of {n} parts: pair ({i}, {j}) differs between GPU and CPU");
                }
                touching += cpu.pairs.len();
                touching_bodies += usize::from(!cpu.pairs.is_empty());
            }
            candidates += cand.len();
            // Steady state: the first frame may grow the buffers (overflow re-runs).
            submissions = got.submissions;
        }
        let nf = frames.len();
        let mut f = 0;
        let cpu1 = median_ms(o.runs, || {
            let poses = &frames[f % nf];
            f += 1;
            for (i, j) in broad_phase(&trees, poses) {
                std::hint::black_box(collide(trees[i], &poses[i], trees[j], &poses[j], &request));
            }
        });
        f = 0;
        let cpu_all = median_ms(o.runs, || {
            let poses = &frames[f % nf];
            f += 1;
            broad_phase(&trees, poses).par_iter().for_each(|&(i, j)| {
                std::hint::black_box(collide(trees[i], &poses[i], trees[j], &poses[j], &request));
            });
        });
        f = 0;
        let (mut samples, mut last) = (Vec::new(), None);
        let (gpu, untimed) = gpu_median_ms(o.runs, warm, || {
            let poses = &frames[f % nf];
            f += 1;
            let cand = broad_phase(&trees, poses);
            let batch: Vec<_> = cand
                .iter()
                .map(|&(i, j)| (&gpu_unique[i % 4], &poses[i], &gpu_unique[j % 4], &poses[j]))
                .collect();
            let got = ctx.collide_batch(&batch, &mut scratch).expect("checked");
            samples.push(got.timings.clone());
            last = Some(got);
        });
        samples.drain(..untimed);
        if let Some(got) = &last {
            let b = Breakdown::new(
                format!("frame, {n} parts (last frame's counts)"),
                gpu,
                got,
                &samples,
                gpu_clock_mhz(info.vendor),
            );
            println!("{}", b.line());
            breakdowns.push(b);
        }
        println!(
            "frame of {n} parts ({triangles} triangles): {:.1} candidates, {:.1} touching body pairs / frame, cpu1 {cpu1:.2} ms, cpu{threads} {cpu_all:.2} ms, gpu {gpu:.2} ms",
            candidates as f64 / nf as f64,
            touching_bodies as f64 / nf as f64
        );
        frame_rows.push(FrameRow {
            parts: n,
            triangles,
            candidates: candidates as f64 / nf as f64,
            touching_bodies: touching_bodies as f64 / nf as f64,
            touching: touching as f64 / nf as f64,
            cpu1,
            cpu_all,
            gpu,
            submissions,
        });
    }

    // Variants of the GPGPU options the checker section times against the default, in one
    // process.
    let (gpu, _) = checker_options();
    // (name, options, shader variant): every change is timed against the default.
    let mut changes: Vec<(String, frcd_hybrid::Options, u32)> = Vec::new();
    for &l in &o.checker_gpu_leaves {
        let options = frcd_hybrid::Options {
            gpu_build: Some(frcd_obb::BuildOptions {
                max_leaf_triangles: l,
                ..gpu.build
            }),
            ..gpu.clone()
        };
        changes.push((format!("GPU leaves of {l}"), options, 0));
    }
    for &t in &o.checker_host_front {
        let options = frcd_hybrid::Options {
            gpu_host_front: Some(t),
            ..gpu.clone()
        };
        changes.push((
            format!("a CPU front of {t} box tests per level"),
            options,
            0,
        ));
    }
    for &g in &o.checker_one_pass {
        for front in std::iter::once(None).chain(o.checker_host_front.iter().map(|&t| Some(t))) {
            let options = frcd_hybrid::Options {
                gpu_one_pass: Some(g),
                gpu_host_front: front,
                ..gpu.clone()
            };
            let front = front.map_or("the default CPU front".into(), |t| {
                format!("a CPU front of {t} box tests per level")
            });
            changes.push((format!("one pass of {g} workgroups, {front}"), options, 0));
        }
    }
    if o.checker_recheck_uncertain {
        let options = frcd_hybrid::Options {
            gpu_recheck_certified: false,
            ..gpu.clone()
        };
        changes.push(("only the uncertain pairs re-decided".into(), options, 0));
    }
    for &m in &o.checker_box_pass_min {
        let options = frcd_hybrid::Options {
            gpgpu_box_pass_min_bodies: m,
            ..gpu.clone()
        };
        changes.push((
            format!("the box pass on the GPU from {m} bodies"),
            options,
            0,
        ));
    }
    for &v in &o.checker_shader_variants {
        changes.push((format!("shader variant {v}"), gpu.clone(), v));
    }
    let mut checker_rows: Vec<CheckerRow> = Vec::new();
    for &n in &o.checker {
        checker_rows.push(checker_row(n, o.runs, warm)?);
        if !changes.is_empty() {
            checker_variants(n, o.runs, warm, &changes)?;
        }
        if o.checker_pipeline_orders {
            checker_pipeline_orders(n, o.runs, warm)?;
        }
        if let Some(time) = soak {
            checker_soak(n, time)?;
        }
    }

    let mut box_rows = Vec::new();
    let mut box_scratch = BoxScratch::default();
    let mut all_scratch = BoxScratch::default();
    for &n in &o.bodies {
        // Bodies of size ~1 scattered in a cube holding about 4 neighbours each.
        let side = (n as f64 / 4.0).cbrt() * 2.0;
        let mut seed = 0x1234_5678_9abc_def0u64 ^ n as u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let boxes: Vec<Aabb> = (0..n)
            .map(|_| {
                let c = DVec3::new(rnd(), rnd(), rnd()) * side;
                let h = DVec3::new(rnd(), rnd(), rnd()) * 0.5 + DVec3::splat(0.1);
                Aabb::new(c - h, c + h)
            })
            .collect();
        let cpu_pairs = || {
            let mut out = Vec::new();
            for i in 0..boxes.len() {
                for j in i + 1..boxes.len() {
                    if boxes[i].intersects(&boxes[j]) {
                        out.push((i as u32, j as u32));
                    }
                }
            }
            out
        };
        let small = n <= ALL_PAIRS_LIMIT;
        let want = frcd_obb::overlapping_boxes(&boxes, 0.0);
        let got = ctx.overlapping_bodies(&boxes, &mut box_scratch)?;
        if got.pairs != want {
            bail!("{n} bodies: GPU sweep pairs differ from the CPU's");
        }
        if small {
            if cpu_pairs() != want {
                bail!("{n} bodies: the CPU broad phase differs from CPU all-pairs");
            }
            let all = ctx.overlapping_bodies_all_pairs(&boxes, &mut all_scratch)?;
            if all.pairs != want {
                bail!("{n} bodies: GPU all-pairs pairs differ from the CPU's");
            }
        }
        let cpu_all = small.then(|| {
            median_ms(o.runs, || {
                std::hint::black_box(cpu_pairs());
            })
        });
        let cpu = median_ms(o.runs, || {
            std::hint::black_box(frcd_obb::overlapping_boxes(&boxes, 0.0));
        });
        let gpu_all = small.then(|| {
            gpu_median_ms(o.runs, warm, || {
                std::hint::black_box(
                    ctx.overlapping_bodies_all_pairs(&boxes, &mut all_scratch)
                        .expect("checked above"),
                );
            })
            .0
        });
        let (gpu, _) = gpu_median_ms(o.runs, warm, || {
            std::hint::black_box(
                ctx.overlapping_bodies(&boxes, &mut box_scratch)
                    .expect("checked above"),
            );
        });
        println!(
            "{n} bodies: {} pairs, cpu all-pairs {cpu_all:?} ms, cpu broad phase {cpu:.2} ms, gpu all-pairs {gpu_all:?} ms, gpu sweep {gpu:.2} ms",
            want.len()
        );
        box_rows.push(BoxRow {
            bodies: n,
            pairs: want.len(),
            cpu_all,
            cpu,
            gpu_all,
            gpu,
        });
    }

    let load_end = load_average();
    let mut md = String::new();
    writeln!(md, "# GPGPU pipeline vs CPU OBB traversal\n")?;
    writeln!(
        md,
        "Adapter: **{}** ({:?}, {:?}, driver {} {}). CPU: {} rayon threads. `cargo xtask bench gpgpu`, median of {} runs. Triangle pass: exact reference-point offsets {}. CPU front: {} (`--host-front`). GPU warm-up: {} ms of the timed work before each GPU timing (`--gpu-warmup-ms`; 0: a cold GPU, at whatever clock idling left it).\n",
        info.name,
        info.backend,
        info.device_type,
        info.driver,
        info.driver_info,
        threads,
        o.runs,
        if ctx.exact_offsets() { "on" } else { "off" },
        match ctx.host_front() {
            0 => "off (the GPU starts at the roots)".to_string(),
            t => format!(
                "the CPU descends the top of each batch's pair trees while a level takes at most {t} box tests"
            ),
        },
        warm_ms
    )?;
    if let (Some(a), Some(b)) = (&load_start, &load_end) {
        writeln!(
            md,
            "Machine load (1-minute load average) at start / end: {a} / {b}; timings on a \
             shared machine are noisy.\n"
        )?;
    }
    if ctx.is_software() {
        writeln!(
            md,
            "This adapter is a **software** driver (the GPU work runs on the same CPU cores as the CPU \
             columns); no real GPU was available for this measurement.\n"
        )?;
    }
    let header_len = md.len();
    writeln!(
        md,
        "## Pair queries ({} body pairs per step, all touching pairs, equal answers checked)\n",
        o.pairs
    )?;
    writeln!(
        md,
        "| icosphere level | triangles / body | touching pairs / step | GPU uncertain / step | CPU 1 thread ms | CPU {threads} threads ms | GPU ms (transfers incl.) | GPU / CPU 1 | GPU / CPU {threads} | GPU batch ms | batch / CPU 1 | upload ms / mesh |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|---|")?;
    for r in &rows {
        writeln!(
            md,
            "| {} | {} | {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.1} |",
            r.level,
            r.triangles,
            r.touching,
            r.uncertain,
            r.cpu1,
            r.cpu_all,
            r.gpu,
            r.gpu / r.cpu1,
            r.gpu / r.cpu_all,
            r.gpu_batch,
            r.gpu_batch / r.cpu1,
            r.upload
        )?;
    }
    let sizes: Vec<String> = rows
        .iter()
        .map(|r| format!("{} triangles/body", r.triangles))
        .collect();
    let gpu: Vec<f64> = rows.iter().map(|r| r.gpu).collect();
    let c1 = crossover(
        "vs CPU 1 thread",
        &sizes,
        &rows.iter().map(|r| r.cpu1).collect::<Vec<_>>(),
        &gpu,
    );
    let cn = crossover(
        &format!("vs CPU {threads} threads"),
        &sizes,
        &rows.iter().map(|r| r.cpu_all).collect::<Vec<_>>(),
        &gpu,
    );
    let cb = crossover(
        "batch vs CPU 1 thread",
        &sizes,
        &rows.iter().map(|r| r.cpu1).collect::<Vec<_>>(),
        &rows.iter().map(|r| r.gpu_batch).collect::<Vec<_>>(),
    );
    writeln!(md, "\n- {c1}\n- {cn}\n- {cb}")?;
    writeln!(
        md,
        "- GPU ms: per step, each body pair one query (pose upload, one submission, one readback, \
         exact CPU re-decision of the uncertain pairs). GPU batch ms: the step's body pairs in one \
         `collide_batch` (one submission, one readback). Upload: one-time packing, texture upload \
         and first submission per mesh.\n"
    )?;
    if !frame_rows.is_empty() {
        writeln!(
            md,
            "## Many-body frames (parts of 20k-55k triangles jittering on a grid; CPU broad phase, then every candidate pair: GPU `collide_batch` = one submission and one readback per frame)\n"
        )?;
        writeln!(
            md,
            "| parts | triangles | candidate pairs / frame | touching body pairs | touching triangle pairs | CPU 1 thread ms | CPU {threads} threads ms | GPU ms | GPU / CPU 1 | GPU / CPU {threads} | GPU submissions / frame |"
        )?;
        writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|")?;
        for r in &frame_rows {
            writeln!(
                md,
                "| {} | {} | {:.1} | {:.1} | {:.1} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {} |",
                r.parts,
                r.triangles,
                r.candidates,
                r.touching_bodies,
                r.touching,
                r.cpu1,
                r.cpu_all,
                r.gpu,
                r.gpu / r.cpu1,
                r.gpu / r.cpu_all,
                r.submissions
            )?;
        }
        let sizes: Vec<String> = frame_rows
            .iter()
            .map(|r| format!("{} triangles ({} parts)", r.triangles, r.parts))
            .collect();
        let gpu: Vec<f64> = frame_rows.iter().map(|r| r.gpu).collect();
        let c1 = crossover(
            "frames vs CPU 1 thread",
            &sizes,
            &frame_rows.iter().map(|r| r.cpu1).collect::<Vec<_>>(),
            &gpu,
        );
        let cn = crossover(
            &format!("frames vs CPU {threads} threads"),
            &sizes,
            &frame_rows.iter().map(|r| r.cpu_all).collect::<Vec<_>>(),
            &gpu,
        );
        writeln!(md, "\n- {c1}\n- {cn}\n")?;
    }
    if !breakdowns.is_empty() {
        writeln!(
            md,
            "## Where a batch's time goes (medians of the timed batches above)\n\n\
             Wait: from the submission until the answer is on the host (GPU work, copy, map). \
             GPU columns: GPU timestamps around the passes ({}). Re-decision: the CPU's exact \
             test of every triangle pair the GPU reported (touching or uncertain; rows marked `Recheck::Uncertain`: \
             the uncertain ones only), then the sort of each answer.\n",
            if ctx.has_pass_timers() {
                "`--pass-timers`"
            } else {
                "not taken: run with `--pass-timers` on an adapter with timestamps inside passes"
            }
        )?;
        writeln!(
            md,
            "| batch | body pairs | reported triangle pairs | of which uncertain | batch ms | wait ms | GPU chain ms | GPU traversal levels ms | GPU triangle pass ms | CPU re-decision ms | SM clock after, MHz |"
        )?;
        writeln!(
            md,
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        )?;
        for b in &breakdowns {
            let [all, lv, tr] = match b.gpu_ms {
                Some(g) => g.map(|x| format!("{x:.2}")),
                None => ["—", "—", "—"].map(String::from),
            };
            let clock = b.clock_mhz.map_or("—".to_string(), |c| c.to_string());
            writeln!(
                md,
                "| {} | {} | {} | {} | {:.2} | {:.2} | {all} | {lv} | {tr} | {:.2} | {clock} |",
                b.what, b.body_pairs, b.reported, b.uncertain, b.batch_ms, b.wait_ms, b.decide_ms
            )?;
        }
        writeln!(md)?;
        if breakdowns.iter().any(|b| !b.levels_ms.is_empty()) {
            writeln!(
                md,
                "GPU time of each traversal level in µs (medians; the first level starts at the roots):
"
            )?;
            for b in breakdowns.iter().filter(|b| !b.levels_ms.is_empty()) {
                let levels: Vec<String> = b
                    .levels_ms
                    .iter()
                    .map(|x| format!("{:.0}", x * 1e3))
                    .collect();
                writeln!(md, "- {}: {}", b.what, levels.join(", "))?;
            }
            writeln!(md)?;
        }
    }
    let checker_start = md.len();
    if !checker_rows.is_empty() {
        writeln!(
            md,
            "## Checker frames: plain against pipelined (parts of 20k-55k triangles on a jittered grid, 8 distinct frames in sequence)\n"
        )?;
        writeln!(
            md,
            "The three alternate run by run (every other run in reverse order); times are medians of the runs, ratios medians of the per-run ratios (robust to the host's drift during the measurement).\n"
        )?;
        writeln!(
            md,
            "| parts | triangles | contacts / frame | CPU backend ms / frame | GPGPU `check` ms / frame | GPGPU `check_pipelined` ms / frame | pipelined / plain | plain / CPU | pipelined / CPU |"
        )?;
        writeln!(md, "|---:|---:|---:|---:|---:|---:|---:|---:|---:|")?;
        for r in &checker_rows {
            writeln!(
                md,
                "| {} | {} | {:.1} | {:.2} | {:.2} | {:.2} | {:.2}× | {:.2}× | {:.2}× |",
                r.parts,
                r.triangles,
                r.contacts,
                r.cpu,
                r.plain,
                r.piped,
                r.piped_vs_plain,
                r.plain_vs_cpu,
                r.piped_vs_cpu
            )?;
        }
        writeln!(md)?;
    }
    if !box_rows.is_empty() {
        writeln!(
            md,
            "## Many bodies: box overlap of all body pairs (rough colliding set)\n"
        )?;
        writeln!(
            md,
            "Boxes scattered with about 4 neighbours each; every method's pairs checked equal. \
             CPU columns on one thread (the broad phase: `frcd_obb::overlapping_boxes`, a sweep along the widest axis or a uniform grid); GPU columns include the upload, sort, sweep, readback, \
             f64 re-check of uncertain pairs and the final sort of the pairs.\n"
        )?;
        writeln!(
            md,
            "| bodies | overlapping pairs | CPU all-pairs ms | CPU broad phase ms | GPU all-pairs ms | GPU sort-and-sweep ms | GPU sweep / CPU broad phase | GPU sweep / GPU all-pairs |"
        )?;
        writeln!(md, "|---:|---:|---:|---:|---:|---:|---:|---:|")?;
        let opt = |x: Option<f64>| x.map_or("—".to_string(), |v| format!("{v:.2}"));
        // A ratio of two times below the timer's reach says nothing.
        let ratio = |gpu: f64, cpu: f64| {
            if gpu.max(cpu) < TIMER_REACH_MS {
                "—".to_string()
            } else {
                format!("{:.2}×", gpu / cpu)
            }
        };
        for r in &box_rows {
            writeln!(
                md,
                "| {} | {} | {} | {:.2} | {} | {:.2} | {} | {} |",
                r.bodies,
                r.pairs,
                opt(r.cpu_all),
                r.cpu,
                opt(r.gpu_all),
                r.gpu,
                ratio(r.gpu, r.cpu),
                r.gpu_all.map_or("—".to_string(), |a| ratio(r.gpu, a))
            )?;
        }
        let sizes: Vec<String> = box_rows
            .iter()
            .map(|r| format!("{} bodies", r.bodies))
            .collect();
        let cb = crossover(
            "GPU sort-and-sweep vs CPU broad phase",
            &sizes,
            &box_rows.iter().map(|r| r.cpu).collect::<Vec<_>>(),
            &box_rows.iter().map(|r| r.gpu).collect::<Vec<_>>(),
        );
        writeln!(md, "\n- {cb}")?;
    }
    std::fs::create_dir_all(&o.out).with_context(|| format!("creating {}", o.out.display()))?;
    if o.boxes_only {
        let md = format!("{}{}", &md[..header_len], &md[checker_start..]);
        print!("\n{md}");
        let md_path = o.out.join("gpgpu-boxes.md");
        std::fs::write(&md_path, &md).with_context(|| format!("writing {}", md_path.display()))?;
        println!("\nwrote {}", md_path.display());
        return Ok(());
    }
    print!("\n{md}");
    let md_path = o.out.join("gpgpu.md");
    std::fs::write(&md_path, &md).with_context(|| format!("writing {}", md_path.display()))?;
    let svg_path = o.out.join("gpgpu.svg");
    plot(&svg_path, &rows, threads, &info.name)?;
    println!("\nwrote {} and {}", md_path.display(), svg_path.display());
    Ok(())
}

/// The 1-minute load average (Linux), to put the timings in context.
fn load_average() -> Option<String> {
    let s = std::fs::read_to_string("/proc/loadavg").ok()?;
    s.split_whitespace().next().map(str::to_string)
}

fn plot(path: &std::path::Path, rows: &[PairRow], threads: usize, adapter: &str) -> Result<()> {
    use crate::plot::{self, Axis, Chart, Legend, Series};
    // Log-log, drawn as log10 values on linear axes (the axes say "log10").
    let xs: Vec<f64> = rows.iter().map(|r| (r.triangles as f64).log10()).collect();
    let all = rows
        .iter()
        .flat_map(|r| [r.cpu1, r.cpu_all, r.gpu, r.gpu_batch]);
    let ymax = all.clone().fold(f64::MIN, f64::max).max(1e-3).log10() + 0.3;
    let ymin = all.fold(f64::MAX, f64::min).max(1e-4).log10() - 0.3;
    let (x0, x1) = plot::extent(xs.iter().copied()).unwrap_or((0.0, 1.0));
    let series = |name: String, y: fn(&PairRow) -> f64, color| {
        let pts = xs
            .iter()
            .zip(rows)
            .map(|(&x, r)| (x, y(r).max(1e-4).log10()));
        Series::line(name, color, pts.collect())
    };
    let chart = Chart::new(
        format!("pair queries per step: ms vs triangles/body (log-log), GPU = {adapter}"),
        Axis::linear("log10 triangles per body", x0 - 0.2..x1 + 0.2),
        Axis::linear("log10 ms per step", ymin..ymax),
    )
    .series(series("CPU 1 thread".into(), |r| r.cpu1, plot::BLUE))
    .series(series(
        format!("CPU {threads} threads"),
        |r| r.cpu_all,
        plot::GREEN,
    ))
    .series(series("GPU (transfers incl.)".into(), |r| r.gpu, plot::RED))
    .series(series(
        "GPU, one batch per step".into(),
        |r| r.gpu_batch,
        plot::ORANGE,
    ))
    .legend(Legend::UpperLeft);
    plot::write_svg(path, (860, 520), &[chart])
}

/// A contact as compared between modes: body pair and its triangle pairs.
type ContactKey = (usize, usize, Vec<(u32, u32)>);

/// A checker frame's contacts as `(a, b, triangle pairs)`, for comparing answers.
fn contact_keys(r: &frcd_hybrid::FrameResult) -> Vec<ContactKey> {
    r.contacts
        .iter()
        .map(|c| (c.a, c.b, c.pairs.clone()))
        .collect()
}

/// The median (upper middle) of a non-empty list.
fn median_of(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The median of the per-run ratios `a[i] / b[i]` (robust to a host's drift during the runs,
/// which falls on both alike).
fn median_ratio(a: &[f64], b: &[f64]) -> f64 {
    median_of(a.iter().zip(b).map(|(x, y)| x / y).collect())
}

/// Times `slots` kinds of work alternated run by run, as the checker sections do: untimed
/// rounds of every slot while `warm` lasts (at least one: a hardware GPU leaves its idle
/// clock), then `runs` rounds that time each slot once, every other round in reverse order so
/// that no slot always goes first. `sequence(slot, timed)` runs one unit of a slot's work and
/// returns its time; the result holds each slot's times, run by run.
fn alternate(
    runs: usize,
    warm: Duration,
    slots: usize,
    mut sequence: impl FnMut(usize, bool) -> f64,
) -> Vec<Vec<f64>> {
    let t0 = Instant::now();
    loop {
        (0..slots).for_each(|k| {
            sequence(k, false);
        });
        if t0.elapsed() >= warm {
            break;
        }
    }
    let mut times = vec![Vec::with_capacity(runs); slots];
    for run in 0..runs {
        let mut order: Vec<usize> = (0..slots).collect();
        if run % 2 == 1 {
            order.reverse();
        }
        for k in order {
            times[k].push(sequence(k, true));
        }
    }
    times
}

struct CheckerRow {
    parts: usize,
    triangles: usize,
    contacts: f64,
    cpu: f64,
    plain: f64,
    piped: f64,
    /// Medians of the per-run ratios (the three alternate run by run).
    plain_vs_cpu: f64,
    piped_vs_cpu: f64,
    piped_vs_plain: f64,
}

/// The checker section for `n` parts: per-frame time of a sequence of 8 frames, median of
/// `runs` sequences, for the CPU backend, GPGPU `check` and GPGPU `check_pipelined`, alternated
/// run by run, with the medians of the per-run ratios; answers checked equal frame by frame.
fn checker_row(n: usize, runs: usize, warm: Duration) -> Result<CheckerRow> {
    use frcd_hybrid::{Checker, FrameState, Pipeline};
    let (bodies, frames) = checker_scene(n);
    let triangles: usize = bodies.iter().map(|b| b.mesh.triangle_count()).sum();
    let (gpu, cpu) = checker_options();
    let c_cpu = Checker::new(bodies.clone(), &[], cpu)?;
    let c_gpu = Checker::new(bodies.clone(), &[], gpu.clone())?;
    let c_pipe = Checker::new(bodies, &[], gpu)?;
    let key = contact_keys;
    // Correctness first (and warm-up): the three agree on every frame.
    let mut contacts = 0usize;
    // Where the GPGPU checker's broad phase ran (`Options::gpgpu_box_pass_min_bodies`).
    let mut gpu_broad = "no frame";
    {
        let (mut s1, mut s2, mut pipe) = (
            FrameState::default(),
            FrameState::default(),
            Pipeline::new(),
        );
        let mut piped = Vec::new();
        for poses in &frames {
            let a = c_cpu.check(poses, &mut s1)?;
            let b = c_gpu.check(poses, &mut s2)?;
            if key(&a) != key(&b) {
                bail!("checker, {n} parts: GPGPU check differs from the CPU backend");
            }
            gpu_broad = match b.stages[0].backend {
                frcd_hybrid::StageBackend::Gpu => "GPU box pass",
                _ => "CPU broad phase",
            };
            contacts += a.contacts.len();
            piped.extend(c_pipe.check_pipelined(poses, &mut pipe)?);
            if let Some(p) = piped.last() {
                let k = piped.len() - 1;
                if key(p) != key(&c_cpu.check(&frames[k], &mut FrameState::default())?) {
                    bail!("checker, {n} parts: pipelined frame {k} differs");
                }
            }
        }
        piped.extend(c_pipe.flush_pipelined(&mut pipe)?);
        if piped.len() != frames.len() {
            bail!("checker: pipelined returned {} frames", piped.len());
        }
    }
    let nf = frames.len() as f64;
    // Where a frame's time goes: the reported stage times (broad, narrow) of every timed frame.
    let (mut cpu_stages, mut gpu_stages) = (Vec::new(), Vec::new());
    let stages = |r: &frcd_hybrid::FrameResult| (r.stages[0].time_us, r.stages[2].time_us);
    let (mut s1, mut s2, mut pipe) = (
        FrameState::default(),
        FrameState::default(),
        Pipeline::new(),
    );
    // One 8-frame sequence of the CPU backend (0), GPGPU `check` (1) or `check_pipelined` and
    // its flush (2), in ms per frame; `record`: keep its frames' stage times.
    let sequence = |k: usize, record: bool| {
        let t0 = Instant::now();
        for poses in &frames {
            match k {
                0 => {
                    let r = c_cpu.check(poses, &mut s1).expect("checked");
                    if record {
                        cpu_stages.push(stages(&r));
                    }
                    std::hint::black_box(r);
                }
                1 => {
                    let r = c_gpu.check(poses, &mut s2).expect("checked");
                    if record {
                        gpu_stages.push(stages(&r));
                    }
                    std::hint::black_box(r);
                }
                _ => {
                    std::hint::black_box(
                        c_pipe.check_pipelined(poses, &mut pipe).expect("checked"),
                    );
                }
            }
        }
        if k == 2 {
            std::hint::black_box(c_pipe.flush_pipelined(&mut pipe).expect("checked"));
        }
        t0.elapsed().as_secs_f64() * 1e3 / nf
    };
    // The three alternate run by run, so that the host's drift during the measurement falls
    // on all three alike and each run gives its own ratios.
    let times = alternate(runs, warm, 3, sequence);
    let ratio = |a: usize, b: usize| median_ratio(&times[a], &times[b]);
    let (plain_vs_cpu, piped_vs_cpu, piped_vs_plain) = (ratio(1, 0), ratio(2, 0), ratio(2, 1));
    let [cpu_ms, plain, piped] = [0, 1, 2].map(|k| median_of(times[k].clone()));
    let median_stages = |v: &[(f64, f64)]| {
        let mid = |mut x: Vec<f64>| {
            x.sort_by(f64::total_cmp);
            x.get(x.len() / 2).copied().unwrap_or(0.0) / 1e3
        };
        (
            mid(v.iter().map(|s| s.0).collect()),
            mid(v.iter().map(|s| s.1).collect()),
        )
    };
    let (cb, cn) = median_stages(&cpu_stages);
    let (gb, gn) = median_stages(&gpu_stages);
    println!(
        "checker, {n} parts, median stage times per frame: CPU backend broad {cb:.2} ms, narrow {cn:.2} ms; GPGPU check broad ({gpu_broad}) {gb:.2} ms, narrow (one pair batch, exact re-decision, containment) {gn:.2} ms"
    );
    println!(
        "checker, {n} parts ({triangles} triangles): cpu {cpu_ms:.2} ms, gpgpu check {plain:.2} ms, pipelined {piped:.2} ms per frame; per-run ratios (medians): check / cpu {plain_vs_cpu:.3}, pipelined / cpu {piped_vs_cpu:.3}, pipelined / check {piped_vs_plain:.3}"
    );
    Ok(CheckerRow {
        parts: n,
        triangles,
        contacts: contacts as f64 / nf,
        cpu: cpu_ms,
        plain,
        piped,
        plain_vs_cpu,
        piped_vs_cpu,
        piped_vs_plain,
    })
}

/// The checker section's options: GPGPU (GPU required) and CPU backend, defaults otherwise.
fn checker_options() -> (frcd_hybrid::Options, frcd_hybrid::Options) {
    use frcd_hybrid::{Backend, GpuPolicy, Options};
    let gpu = Options {
        backend: Backend::Gpgpu,
        gpu: GpuPolicy::Require,
        ..Options::default()
    };
    let cpu = Options {
        backend: Backend::Cpu,
        gpu: GpuPolicy::Off,
        ..Options::default()
    };
    (gpu, cpu)
}

/// Frames of the checker section, `n` parts: the bodies and the 8 frames' poses.
fn checker_scene(n: usize) -> (Vec<frcd_hybrid::BodySpec>, Vec<Vec<Pose>>) {
    let meshes: Vec<std::sync::Arc<frcd_geom::TriMesh>> = (0..n.min(4))
        .map(|i| std::sync::Arc::new(frame_part(i)))
        .collect();
    let bodies = (0..n)
        .map(|i| frcd_hybrid::BodySpec {
            name: format!("part{i}"),
            mesh: meshes[i % 4].clone(),
            is_static: false,
        })
        .collect();
    (bodies, (0..8).map(|f| frame_poses(n, f)).collect())
}

/// GPGPU `check` per frame of the checker section with each of `variants` (a name and how it
/// changes the GPGPU options) against the default options, in one process: after `warm` of
/// untimed sequences, every run times one 8-frame sequence of each variant in turn, every other
/// run in reverse order (so host noise falls on all alike); prints each variant's median and
/// the median of its per-run ratios to the default.
fn checker_variants(
    n: usize,
    runs: usize,
    warm: Duration,
    changes: &[(String, frcd_hybrid::Options, u32)],
) -> Result<()> {
    use frcd_hybrid::{Checker, FrameState, Pipeline};
    if changes.iter().any(|(_, _, shader)| *shader != 0) {
        refuse_ambient_shader_variant(std::env::var_os(frcd_gpgpu::SHADER_VARIANT_ENV))?;
    }
    let (bodies, frames) = checker_scene(n);
    let (gpu, cpu) = checker_options();
    let reference = Checker::new(bodies.clone(), &[], cpu)?;
    let mut variants = vec![(
        "default".to_string(),
        Checker::new(bodies.clone(), &[], gpu.clone())?,
    )];
    for (name, o, shader) in changes {
        // The variant's pipelines read the variable when its context is created, here.
        // SAFETY: `set_var` is sound only while no other thread reads or writes the
        // environment. The bench's own threads (rayon's pool) are idle between timings; the
        // software driver's worker threads exist by now, and Mesa reads its environment when
        // a device is created, which happens on this thread. A measurement tool's shortcut:
        // passing the variant through the context's options would remove the `unsafe`.
        if *shader != 0 {
            unsafe { std::env::set_var(frcd_gpgpu::SHADER_VARIANT_ENV, shader.to_string()) };
        }
        let checker = Checker::new(bodies.clone(), &[], o.clone());
        if *shader != 0 {
            unsafe { std::env::remove_var(frcd_gpgpu::SHADER_VARIANT_ENV) };
        }
        variants.push((name.clone(), checker?));
    }
    let key = contact_keys;
    let mut states: Vec<FrameState> = variants.iter().map(|_| FrameState::default()).collect();
    let mut cpu_state = FrameState::default();
    for poses in &frames {
        let want = key(&reference.check(poses, &mut cpu_state)?);
        for ((name, c), st) in variants.iter().zip(&mut states) {
            if key(&c.check(poses, st)?) != want {
                bail!("checker, {n} parts: GPGPU check with {name} differs from the CPU backend");
            }
        }
    }
    let nf = frames.len() as f64;
    let mut pipes: Vec<Pipeline> = variants.iter().map(|_| Pipeline::new()).collect();
    // One 8-frame sequence of variant k (k < variants: `check`; else variant k - variants
    // through `check_pipelined` and the flush), in ms per frame.
    let nv = variants.len();
    let mut sequence = |k: usize| {
        let t0 = Instant::now();
        if k < nv {
            for poses in &frames {
                std::hint::black_box(variants[k].1.check(poses, &mut states[k]).expect("checked"));
            }
        } else {
            let (c, pipe) = (&variants[k - nv].1, &mut pipes[k - nv]);
            for poses in &frames {
                std::hint::black_box(c.check_pipelined(poses, pipe).expect("checked"));
            }
            std::hint::black_box(c.flush_pipelined(pipe).expect("checked"));
        }
        t0.elapsed().as_secs_f64() * 1e3 / nf
    };
    let times = alternate(runs, warm, 2 * nv, |k, _| sequence(k));
    let median = median_of;
    for (k, (name, _)) in variants.iter().enumerate() {
        for (call, slot, base) in [("check", k, 0), ("check_pipelined", nv + k, nv)] {
            let ratio = median_ratio(&times[slot], &times[base]);
            println!(
                "checker, {n} parts, GPGPU {call} with {name}: {:.2} ms per frame (median of {runs}), {ratio:.3}x the default (median of per-run ratios)",
                median(times[slot].clone())
            );
        }
    }
    Ok(())
}

/// Refuses `--checker-shader-variants` while [`frcd_gpgpu::SHADER_VARIANT_ENV`] is already set
/// (`ambient`, the variable's value at start): the default checker would be built with that
/// variant instead of the shipped shader, and every ratio would compare two variants.
fn refuse_ambient_shader_variant(ambient: Option<std::ffi::OsString>) -> Result<()> {
    match ambient {
        Some(v) => bail!(
            "{}={v:?} is set: --checker-shader-variants sets it per variant itself and times each against the shipped shader (variant 0), built without it; unset it first",
            frcd_gpgpu::SHADER_VARIANT_ENV
        ),
        None => Ok(()),
    }
}

/// GPGPU `check` alone on the checker section's frames, over and over for `time`, after one
/// sequence checked against the CPU backend (`--checker-soak-s`); prints the wall and CPU time
/// per frame.
fn checker_soak(n: usize, time: Duration) -> Result<()> {
    use frcd_hybrid::{Checker, FrameState};
    let (bodies, frames) = checker_scene(n);
    let (gpu, cpu) = checker_options();
    let reference = Checker::new(bodies.clone(), &[], cpu)?;
    let checker = Checker::new(bodies, &[], gpu)?;
    let (mut s_cpu, mut s_gpu) = (FrameState::default(), FrameState::default());
    for poses in &frames {
        if contact_keys(&checker.check(poses, &mut s_gpu)?)
            != contact_keys(&reference.check(poses, &mut s_cpu)?)
        {
            bail!("checker soak, {n} parts: GPGPU check differs from the CPU backend");
        }
    }
    drop(reference);
    let t0 = Instant::now();
    let cpu0 = process_cpu_seconds();
    let mut count = 0u64;
    while t0.elapsed() < time {
        for poses in &frames {
            std::hint::black_box(checker.check(poses, &mut s_gpu)?);
            count += 1;
        }
    }
    let secs = t0.elapsed().as_secs_f64();
    let per_frame = |s: f64| s * 1e3 / count.max(1) as f64;
    // The process's CPU time (all threads: the software driver's included) is steadier than
    // the wall clock on a shared host; not known off Linux.
    let cpu = match (cpu0, process_cpu_seconds()) {
        (Some(a), Some(b)) => format!(", CPU time {:.3} ms per frame", per_frame(b - a)),
        _ => String::new(),
    };
    println!(
        "checker soak, {n} parts: {count} GPGPU check frames in {secs:.1} s, {:.3} ms per frame{cpu}",
        per_frame(secs)
    );
    Ok(())
}

/// CPU time this process has used, all threads (user and system), from `/proc/self/stat`;
/// `None` where that file is missing or unreadable (not Linux).
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may hold spaces, closed by the last ')'): utime and
    // stime are the 12th and 13th, in clock ticks (USER_HZ, 100 on Linux).
    let rest = stat.get(stat.rfind(')')? + 2..)?;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

/// GPGPU `check_pipelined` per frame of the checker section in both orders of a call's work
/// (re-deciding frame k first, or submitting frame k+1's batch first), in one process: one
/// checker, one pipeline per order, every run one 8-frame sequence (and the flush) of each in
/// turn, every other run in reverse order; prints each order's median and the median of the
/// per-run ratios. The answers are checked equal to `check`'s first.
fn checker_pipeline_orders(n: usize, runs: usize, warm: Duration) -> Result<()> {
    use frcd_hybrid::{Checker, FrameState, Pipeline};
    let (bodies, frames) = checker_scene(n);
    let (gpu, _) = checker_options();
    let checker = Checker::new(bodies, &[], gpu)?;
    let key = contact_keys;
    let mut state = FrameState::default();
    let want: Vec<Vec<ContactKey>> = frames
        .iter()
        .map(|p| checker.check(p, &mut state).map(|r| key(&r)))
        .collect::<Result<_, _>>()?;
    let orders = [true, false];
    let mut pipes: Vec<Pipeline> = orders
        .iter()
        .map(|&o| {
            let mut p = Pipeline::new();
            p.set_decide_first(o);
            p
        })
        .collect();
    for (pipe, order) in pipes.iter_mut().zip(orders) {
        let mut got = Vec::new();
        for poses in &frames {
            got.extend(checker.check_pipelined(poses, pipe)?.map(|r| key(&r)));
        }
        got.extend(checker.flush_pipelined(pipe)?.map(|r| key(&r)));
        if got != want {
            bail!("checker, {n} parts: pipelined (decide first: {order}) differs from check");
        }
    }
    let nf = frames.len() as f64;
    let mut sequence = |k: usize| {
        let t0 = Instant::now();
        for poses in &frames {
            std::hint::black_box(
                checker
                    .check_pipelined(poses, &mut pipes[k])
                    .expect("checked"),
            );
        }
        std::hint::black_box(checker.flush_pipelined(&mut pipes[k]).expect("checked"));
        t0.elapsed().as_secs_f64() * 1e3 / nf
    };
    let times = alternate(runs, warm, 2, |k, _| sequence(k));
    let median = median_of;
    let ratio = median_ratio(&times[0], &times[1]);
    println!(
        "checker, {n} parts, GPGPU check_pipelined: re-deciding first {:.2} ms, submitting first {:.2} ms per frame (medians of {runs}); first / second {ratio:.3} (median of per-run ratios)",
        median(times[0].clone()),
        median(times[1].clone())
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `alternate` warms every slot up once untimed (no warm-up time asked), then times each
    /// slot once per run, every other run in reverse order, and files each time under its
    /// slot; `median_ratio` takes the per-run ratios' median.
    #[test]
    fn alternate_times_every_slot_once_a_run_in_alternating_order() {
        let mut calls = Vec::new();
        let mut clock = 0.0;
        let times = alternate(3, Duration::ZERO, 3, |k, timed| {
            calls.push((k, timed));
            clock += 1.0;
            clock + 10.0 * k as f64
        });
        let (f, t) = (false, true);
        let order = [(0, f), (1, f), (2, f), (0, t), (1, t), (2, t)];
        let back = [(2, t), (1, t), (0, t), (0, t), (1, t), (2, t)];
        assert_eq!(calls, [&order[..], &back[..]].concat());
        assert_eq!(times[0], [4.0, 9.0, 10.0]);
        assert_eq!(times[2], [26.0, 27.0, 32.0]);
        assert_eq!(median_ratio(&[2.0, 9.0, 3.0], &[1.0, 3.0, 3.0]), 2.0);
    }

    /// A shader variant already in the environment stops `--checker-shader-variants` with an
    /// error naming the variable (its default checker would not be the shipped shader); an
    /// unset one passes.
    #[test]
    fn an_ambient_shader_variant_is_refused() {
        let e = refuse_ambient_shader_variant(Some("2".into()))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(frcd_gpgpu::SHADER_VARIANT_ENV) && e.contains("\"2\""),
            "{e}"
        );
        assert!(refuse_ambient_shader_variant(None).is_ok());
    }

    /// The clock query gives up on a tool that hangs (killing it) and reads one that answers.
    #[cfg(unix)]
    #[test]
    fn a_hung_clock_tool_times_out_and_a_quick_one_is_read() {
        let mut hung = std::process::Command::new("sh");
        hung.args(["-c", "exec sleep 30"]);
        let t0 = Instant::now();
        assert_eq!(output_within(hung, Duration::from_millis(200)), None);
        assert!(t0.elapsed() < Duration::from_secs(10), "{:?}", t0.elapsed());
        let mut quick = std::process::Command::new("sh");
        quick.args(["-c", "echo ' 1410'; echo 345"]);
        let out = output_within(quick, Duration::from_secs(10)).expect("answered");
        assert_eq!(parse_clock(&out), Some(1410));
        let mut failing = std::process::Command::new("sh");
        failing.args(["-c", "echo 1410; exit 3"]);
        assert_eq!(output_within(failing, Duration::from_secs(10)), None);
        assert_eq!(parse_clock(b"N/A\n"), None);
    }

    #[test]
    fn gpu_timings_warm_up_first_and_count_the_untimed_calls() {
        // No warm-up: the one call `gpu_median_ms` always makes, and `median_ms`'s own.
        let mut calls = 0;
        let (_, untimed) = gpu_median_ms(3, Duration::ZERO, || calls += 1);
        assert_eq!((untimed, calls), (2, 2 + 3));
        // A warm-up repeats the work until its time is up; the caller drops exactly the
        // untimed samples and keeps the timed ones.
        let mut samples = Vec::new();
        let (_, untimed) = gpu_median_ms(5, Duration::from_millis(20), || {
            std::thread::sleep(Duration::from_millis(2));
            samples.push(());
        });
        assert!(
            untimed > 2,
            "{untimed} untimed calls in 20 ms of 2 ms calls"
        );
        samples.drain(..untimed);
        assert_eq!(samples.len(), 5);
    }

    #[test]
    fn the_crossover_is_where_the_gpu_stays_faster() {
        let sizes: Vec<String> = ["1", "16", "256", "4096"].map(String::from).to_vec();
        // Tied at zero, then slower, then faster for good.
        let line = crossover("t", &sizes, &[0.0, 0.02, 0.5, 9.0], &[0.0, 0.5, 0.3, 1.0]);
        assert!(line.contains("from 256 on"), "{line}");
        // Faster at one small size only, slower at the largest: none.
        let line = crossover("t", &sizes, &[0.0, 0.5, 0.5, 1.0], &[0.0, 0.1, 0.9, 2.0]);
        assert!(line.contains("none in the measured range"), "{line}");
        assert!(line.contains("0.20×"), "{line}");
        // Both times below the timer's reach: no ratio from that row.
        let line = crossover("t", &sizes, &[4e-6, 0.5, 0.5, 1.0], &[2e-6, 0.6, 0.9, 2.0]);
        assert!(line.contains("best ratio 1.20×"), "{line}");
    }

    #[test]
    fn plot_writes_every_series() {
        let rows: Vec<PairRow> = (1..=4)
            .map(|l| PairRow {
                level: l,
                triangles: 20 * 4usize.pow(l),
                touching: 10,
                uncertain: 0,
                cpu1: 0.01 * 3f64.powi(l as i32),
                cpu_all: 0.006 * 3f64.powi(l as i32),
                gpu: 0.5 + 0.1 * l as f64,
                gpu_batch: 0.3 + 0.05 * l as f64,
                upload: 1.0,
            })
            .collect();
        let path = crate::plot::TempFile(
            std::env::temp_dir().join(format!("frcd-xtask-gpgpu-{}.svg", std::process::id())),
        );
        plot(&path, &rows, 2, "test adapter").unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        for s in [
            "CPU 1 thread",
            "CPU 2 threads",
            "GPU (transfers incl.)",
            "GPU, one batch per step",
            "test adapter",
        ] {
            assert!(svg.contains(s), "{s} missing");
        }
    }
}
