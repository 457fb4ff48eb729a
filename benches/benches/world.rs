//! The many-body `World::step` on one thread and on two (issue 9: with rayon on 2 cores the
//! step takes at most 1/1.7 of its one-thread time).
//!
//! Scene: a jittered 6×6×6 grid of 216 bodies (icospheres of 1,280 and 320 triangles, boxes,
//! torus knots of 2,048), spaced so that neighbours overlap at most steps, every body moving a
//! little each step (no answer is reused), all-pairs mode with coherence caches. The
//! `world/step_ratio` line times both pools interleaved, step by step, and prints the medians
//! and their ratio (the machine's load moves both alike); the criterion rows time each alone.
//! The `world/timing` lines split the median step ([`frcd_obb::StepTiming`]): sequential
//! broad phase and collection, the narrow phase's wall time, the pair evaluations' summed time
//! and longest pair, and the narrow phase's parallel efficiency `pair time / (threads · narrow
//! wall)`: below 100 % is idle time and scheduling overhead, or a thread that did not get a
//! core (on a loaded machine compare with the load average printed). On a loaded machine the
//! `world/step_least` line is the steadier figure: for each frame of the cycle, the least
//! disturbed of its steps on each pool, summed over the cycle, and their ratio (give it several
//! cycles: `FRCD_WORLD_SECS`).
//!
//! The `world/broad` lines time the broad phase alone ([`World::overlapping_pairs`]) on many
//! small boxes with about 4 neighbours each: scattered through a cube (where a sweep compares
//! every box with about n^(2/3) others) and strung along y, at 4,096 to 65,536 bodies
//! (`FRCD_WORLD_BROAD_MAX` raises the top, e.g. 262144), under three motions
//! (`FRCD_WORLD_MOTIONS=wobble,drift,drift-long,shuffle`, see `bench_broad`). Beside it, on the same boxes
//! in the same steps, parry3d-f64's incremental BVH as rapier drives it, with tight and with
//! grown boxes, its pair count checked equal.
//! `FRCD_WORLD_ONLY=broad|step` runs one part.
//!
//! ```text
//! cargo bench -p frcd-benches --bench world -- --warm-up-time 1 --measurement-time 3
//! FRCD_WORLD_SECS=20 cargo bench -p frcd-benches --bench world -- step_ratio  # longer ratio run
//! FRCD_WORLD_ONLY=broad cargo bench -p frcd-benches --bench world      # the broad phase alone
//! ```

use criterion::{Criterion, criterion_group, criterion_main};
use frcd_benches::scenes::Rng;
use frcd_geom::shapes::{self, TorusKnotParams, torus_knot};
use frcd_geom::{DQuat, DVec3, Pose, TriMesh};
use frcd_obb::{BodyId, BuildOptions, ObbTree, StepTiming, World, WorldOptions};
use parry3d_f64::bounding_volume::BoundingVolume;
use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

const SIDE: usize = 6;
const FRAMES: usize = 64;

struct Scene {
    trees: Vec<Arc<ObbTree>>,
    /// Per body: its tree.
    body_tree: Vec<usize>,
    frames: Vec<Vec<Pose>>,
}

fn scene() -> Scene {
    let meshes: Vec<TriMesh> = vec![
        shapes::icosphere(0.5, 3),
        shapes::cuboid(DVec3::new(0.45, 0.3, 0.35)),
        torus_knot(&TorusKnotParams {
            radius: 0.3,
            offset: 0.12,
            tube_radius: 0.05,
            tubular_segments: 128,
            radial_segments: 8,
            ..TorusKnotParams::default()
        })
        .expect("valid knot"),
        shapes::icosphere(0.45, 2),
    ];
    let trees: Vec<Arc<ObbTree>> = meshes
        .iter()
        .map(|m| Arc::new(ObbTree::build(m, &BuildOptions::default())))
        .collect();
    let n = SIDE * SIDE * SIDE;
    let mut rng = Rng::new(0x5eed);
    let spacing = 0.9;
    let base: Vec<(DVec3, DQuat, DVec3, DQuat)> = (0..n)
        .map(|i| {
            let g = DVec3::new(
                (i % SIDE) as f64,
                ((i / SIDE) % SIDE) as f64,
                (i / (SIDE * SIDE)) as f64,
            );
            let p = g * spacing
                + DVec3::new(
                    rng.range(-0.1, 0.1),
                    rng.range(-0.1, 0.1),
                    rng.range(-0.1, 0.1),
                );
            let v = rng.unit() * 0.004;
            let w = DQuat::from_axis_angle(rng.unit(), 0.01);
            (p, rng.rotation(), v, w)
        })
        .collect();
    let frames = (0..FRAMES)
        .map(|k| {
            // Back and forth, so that the sequence can be cycled coherently.
            let s = (k as f64 * std::f64::consts::TAU / FRAMES as f64).sin() * 8.0;
            base.iter()
                .map(|(p, q, v, w)| {
                    let spin = DQuat::from_axis_angle(
                        w.xyz().try_normalize().unwrap_or(DVec3::Z),
                        0.01 * s,
                    );
                    Pose::new(*p + *v * s, (spin * *q).normalize())
                })
                .collect()
        })
        .collect();
    Scene {
        body_tree: (0..n).map(|i| i % trees.len()).collect(),
        trees,
        frames,
    }
}

fn world(s: &Scene, threads: usize) -> (World, Vec<BodyId>) {
    let mut w = World::new(WorldOptions::default());
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("thread pool");
    w.set_thread_pool(Some(Arc::new(pool)));
    let ids = s.frames[0]
        .iter()
        .enumerate()
        .map(|(i, p)| {
            w.add_body(s.trees[s.body_tree[i]].clone(), *p, false)
                .expect("valid pose")
        })
        .collect();
    (w, ids)
}

/// One step at frame `k` (cycled).
fn step(w: &mut World, ids: &[BodyId], s: &Scene, k: usize) -> usize {
    let f = &s.frames[k % FRAMES];
    let updates: Vec<(BodyId, Pose)> = ids.iter().copied().zip(f.iter().copied()).collect();
    w.set_poses(&updates).expect("valid poses");
    w.step().contacts.len()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Medians (and minima: the least disturbed steps) of each part of the step's timing, and the
/// median efficiency.
fn timing_line(label: &str, t: &[StepTiming]) -> String {
    let us = |f: &dyn Fn(&StepTiming) -> f64| {
        let v: Vec<f64> = t.iter().map(f).collect();
        let min = v.iter().copied().fold(f64::INFINITY, f64::min);
        format!("{:.0} us (min {:.0})", median(v) * 1e6, min * 1e6)
    };
    let eff = median(
        t.iter()
            .map(|x| {
                x.pair_time.as_secs_f64() / (x.threads as f64 * x.narrow.as_secs_f64()).max(1e-12)
            })
            .collect(),
    );
    format!(
        "{label}: broad {}, narrow {} (pairs {}, longest pair {}, efficiency {:.1} %), collect {}",
        us(&|x| x.broad.as_secs_f64()),
        us(&|x| x.narrow.as_secs_f64()),
        us(&|x| x.pair_time.as_secs_f64()),
        us(&|x| x.max_pair.as_secs_f64()),
        eff * 100.0,
        us(&|x| x.collect.as_secs_f64()),
    )
}

fn load() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "?".into())
}

/// The `world/broad` lines: median time of `overlapping_pairs` per step, beside parry3d-f64's
/// incremental BVH on the same boxes, under three motions:
/// - `wobble`: every body moves a little about a fixed place (coherent; the bodies stay in
///   their grown boxes);
/// - `drift`: every body moves on at its own speed (0 to 0.02 per step), so a few % of them
///   leave their grown boxes each step; 12 steps, right after the first build, where each
///   body leaves its grown box at most once;
/// - `drift-long`: the same motion for 60 steps, timed over the last 40: the steady state of a
///   long run, where bodies leave their (re-grown) boxes again and again;
/// - `shuffle`: every body is placed anew each step (incoherent: every candidate found afresh).
///
/// parry3d-f64 runs as Rapier drives it (`insert_or_update_partially` for every box,
/// `optimize_incremental`, `refit`, `traverse_bvtt_single_tree`; under `shuffle` a fresh
/// `Bvh::from_leaves` instead), with tight boxes (margin 0) and with boxes grown by 0.1 (the
/// unit boxes' slack under frcd's default `box_slack_percent`), its pairs filtered by the
/// exact box test and counted against frcd's.
fn bench_broad() {
    let cube = Arc::new(ObbTree::build(
        &shapes::cuboid(DVec3::splat(0.5)),
        &BuildOptions::default(),
    ));
    let top: usize = std::env::var("FRCD_WORLD_BROAD_MAX")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(65_536);
    let motions =
        std::env::var("FRCD_WORLD_MOTIONS").unwrap_or("wobble,drift,drift-long,shuffle".into());
    for motion in motions.split(',') {
        for layout in ["cube", "along y"] {
            if motion != "wobble" && layout != "cube" {
                continue;
            }
            let mut n = 4096;
            while n <= top {
                bench_broad_scene(&cube, motion, layout, n);
                n *= 4;
            }
        }
    }
}

fn bench_broad_scene(cube: &Arc<ObbTree>, motion: &str, layout: &str, n: usize) {
    let mut rng = Rng::new(n as u64 + layout.len() as u64);
    // Unit boxes at density 4 / (4/3 π 2³) per unit volume: about 4 neighbours each.
    let volume = n as f64 * (4.0 / 3.0 * std::f64::consts::PI * 8.0) / 4.0;
    let extent = match layout {
        "cube" => DVec3::splat(volume.cbrt()),
        _ => {
            let side = (volume / 400.0).sqrt();
            DVec3::new(side, 400.0, side)
        }
    };
    let place = |rng: &mut Rng| {
        DVec3::new(
            rng.range(0.0, extent.x),
            rng.range(0.0, extent.y),
            rng.range(0.0, extent.z),
        )
    };
    let centres: Vec<DVec3> = (0..n).map(|_| place(&mut rng)).collect();
    let velocities: Vec<DVec3> = (0..n)
        .map(|_| {
            let d = DVec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            d.normalize_or(DVec3::X) * rng.range(0.0, 0.02)
        })
        .collect();
    let mut w = World::new(WorldOptions::default());
    let ids: Vec<BodyId> = centres
        .iter()
        .map(|&c| {
            w.add_body(cube.clone(), Pose::from_translation(c), false)
                .expect("valid pose")
        })
        .collect();
    let mut times = Vec::new();
    let (mut set_times, mut box_times) = (Vec::new(), Vec::new());
    let mut parry_times = [Vec::new(), Vec::new()];
    let mut pairs = 0;
    let mut bvh = [
        parry3d_f64::partitioning::Bvh::new(),
        parry3d_f64::partitioning::Bvh::new(),
    ];
    let mut workspace = parry3d_f64::partitioning::BvhWorkspace::default();
    let start = w.broad_stats();
    // Steps run, and steps left out of the medians (the first build, a long run's start).
    let (steps, skip) = if motion == "drift-long" {
        (60, 20)
    } else {
        (12, 2)
    };
    for k in 0..steps {
        let t = k as f64 * 0.05;
        let updates: Vec<(BodyId, Pose)> = ids
            .iter()
            .zip(&centres)
            .enumerate()
            .map(|(i, (&id, &c))| {
                let at = match motion {
                    "wobble" => {
                        let phase = i as f64 * 0.37 + t;
                        c + 0.05 * DVec3::new(phase.sin(), phase.cos(), (2.0 * phase).sin())
                    }
                    "drift" | "drift-long" => c + velocities[i] * k as f64,
                    _ => place(&mut rng),
                };
                (id, Pose::from_translation(at))
            })
            .collect();
        let t0 = Instant::now();
        w.set_poses(&updates).expect("valid poses");
        let frcd_set = t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        pairs = black_box(w.overlapping_pairs(0.0)).len();
        let frcd = t0.elapsed().as_secs_f64();
        // The peer's boxes from the same poses, as the World computes them (the body's box
        // turned and moved, grown by 10^-12 of its magnitude), timed apart: "from poses" adds
        // this to the peer as `set_poses` is added to frcd.
        let t0 = Instant::now();
        let local = cube.aabb();
        let boxes: Vec<parry3d_f64::bounding_volume::Aabb> = updates
            .iter()
            .map(|(_, pose)| {
                let b = local.transformed(pose);
                let mag = b.min.abs().max(b.max.abs()).max_element();
                let b = b.inflated(mag * 1e-12 + f64::MIN_POSITIVE);
                let v = |p: DVec3| parry3d_f64::math::Vector::new(p.x, p.y, p.z);
                parry3d_f64::bounding_volume::Aabb::new(v(b.min), v(b.max))
            })
            .collect();
        let parry_boxes = t0.elapsed().as_secs_f64();
        for (&(id, _), b) in updates.iter().zip(&boxes) {
            let f = w.body_aabb(id).expect("live");
            let same = [f.min.x, f.min.y, f.min.z, f.max.x, f.max.y, f.max.z]
                == [b.mins.x, b.mins.y, b.mins.z, b.maxs.x, b.maxs.y, b.maxs.z];
            assert!(same, "the peer's boxes are the World's");
        }
        for (p, margin) in [0.0, 0.1].into_iter().enumerate() {
            let t0 = Instant::now();
            if motion == "shuffle" {
                use parry3d_f64::bounding_volume::BoundingVolume;
                // Every box moved far: a fresh build, as a user of parry would do here (its
                // incremental updates took 8.5 s a step at 65,536 bodies).
                let grown: Vec<_> = boxes.iter().map(|b| b.loosened(margin)).collect();
                bvh[p] = parry3d_f64::partitioning::Bvh::from_leaves(
                    parry3d_f64::partitioning::BvhBuildStrategy::Binned,
                    &grown,
                );
            } else {
                for (i, b) in boxes.iter().enumerate() {
                    bvh[p].insert_or_update_partially(*b, i as u32, margin);
                }
                bvh[p].optimize_incremental(&mut workspace);
                bvh[p].refit(&mut workspace);
            }
            let mut peer_pairs = 0usize;
            bvh[p].traverse_bvtt_single_tree::<false>(&mut workspace, &mut |a, b| {
                peer_pairs += usize::from(boxes[a as usize].intersects(&boxes[b as usize]));
            });
            let parry = t0.elapsed().as_secs_f64();
            assert_eq!(peer_pairs, pairs, "parry3d-f64 finds other pairs");
            if k >= skip {
                parry_times[p].push(parry);
            }
        }
        if k >= skip {
            times.push(frcd);
            set_times.push(frcd_set);
            box_times.push(parry_boxes);
        }
    }
    let stats = w.broad_stats();
    let (m, mp0, mp1) = (
        median(times.clone()),
        median(parry_times[0].clone()),
        median(parry_times[1].clone()),
    );
    let (ms, mb) = (median(set_times), median(box_times));
    println!(
        "world/broad {motion} {layout}: {n} bodies, {pairs} overlapping pairs, frcd {:.3} ms, parry3d-f64 Bvh {:.3} ms tight (parry / frcd {:.2}x), {:.3} ms grown by 0.1 ({:.2}x); from poses: frcd {:.3} ms (set_poses {:.3}), parry3d-f64 tight {:.3} ms (boxes {:.3}), parry / frcd {:.2}x; frcd re-inserted {:.0} bodies and rebuilt {} times in {steps} steps; medians of {} steps (load average {})",
        m * 1e3,
        mp0 * 1e3,
        mp0 / m,
        mp1 * 1e3,
        mp1 / m,
        (m + ms) * 1e3,
        ms * 1e3,
        (mp0 + mb) * 1e3,
        mb * 1e3,
        (mp0 + mb) / (m + ms),
        (stats.reinserted - start.reinserted) as f64,
        stats.rebuilds - start.rebuilds,
        times.len(),
        load()
    );
}

fn bench_world(c: &mut Criterion) {
    let only = std::env::var("FRCD_WORLD_ONLY").unwrap_or_default();
    if only != "step" {
        bench_broad();
    }
    if only == "broad" {
        return;
    }
    let s = scene();
    let (mut w1, ids1) = world(&s, 1);
    let (mut w2, ids2) = world(&s, 2);
    // Warm both (caches, broad-phase order), and count the work.
    let (mut contacts, mut candidates) = (0, 0);
    for k in 0..FRAMES {
        contacts += step(&mut w1, &ids1, &s, k);
        candidates += w1.last_step().candidates;
        step(&mut w2, &ids2, &s, k);
    }
    // Interleaved: both pools see the same load.
    let (mut t1, mut t2) = (Vec::new(), Vec::new());
    let (mut s1, mut s2) = (Vec::new(), Vec::new());
    let secs = std::env::var("FRCD_WORLD_SECS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(4.0);
    let t_end = Instant::now() + Duration::from_secs_f64(secs);
    let mut k = 0;
    while Instant::now() < t_end || t1.len() < 20 {
        let t = Instant::now();
        black_box(step(&mut w1, &ids1, &s, k));
        t1.push(t.elapsed().as_secs_f64());
        s1.push(w1.last_step_timing());
        let t = Instant::now();
        black_box(step(&mut w2, &ids2, &s, k));
        t2.push(t.elapsed().as_secs_f64());
        s2.push(w2.last_step_timing());
        k += 1;
    }
    // Per frame of the cycle, the least disturbed step of each pool; summed over the frames.
    let least = |t: &[f64]| -> f64 {
        (0..FRAMES)
            .map(|f| {
                t.iter()
                    .skip(f)
                    .step_by(FRAMES)
                    .copied()
                    .fold(f64::INFINITY, f64::min)
            })
            .filter(|x| x.is_finite())
            .sum()
    };
    let (l1, l2) = (least(&t1), least(&t2));
    let (m1, m2) = (median(t1), median(t2));
    println!(
        "world/step_ratio: {} bodies, {:.1} candidate pairs and {:.1} touching pairs per step; 1 thread {:.3} ms, 2 threads {:.3} ms median over {} steps each: {:.2}x (load average {})",
        s.frames[0].len(),
        candidates as f64 / FRAMES as f64,
        contacts as f64 / FRAMES as f64,
        m1 * 1e3,
        m2 * 1e3,
        k,
        m1 / m2,
        load()
    );
    println!(
        "world/step_least: per frame of the {FRAMES}-frame cycle the least disturbed step ({:.1} cycles), summed: 1 thread {:.2} ms, 2 threads {:.2} ms: {:.2}x",
        k as f64 / FRAMES as f64,
        l1 * 1e3,
        l2 * 1e3,
        l1 / l2
    );
    println!("{}", timing_line("world/timing 1 thread", &s1));
    println!("{}", timing_line("world/timing 2 threads", &s2));
    let mut g = c.benchmark_group("world");
    g.sample_size(20);
    let mut k1 = 0;
    g.bench_function("step_1_thread", |b| {
        b.iter(|| {
            k1 += 1;
            step(&mut w1, &ids1, &s, k1)
        })
    });
    let mut k2 = 0;
    g.bench_function("step_2_threads", |b| {
        b.iter(|| {
            k2 += 1;
            step(&mut w2, &ids2, &s, k2)
        })
    });
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(3));
    targets = bench_world
}
criterion_main!(benches);
