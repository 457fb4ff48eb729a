//! frcd-obb against parry3d-f64 on the same meshes and poses, in one run.
//!
//! ```text
//! cargo bench -p frcd-benches --bench obb -- --warm-up-time 1 --measurement-time 3
//! FRCD_BENCH_ONLY=knots_near,cad cargo bench -p frcd-benches --bench obb -- obb/
//! ```
//!
//! Before timing, every scene is answered by frcd (plain and cached), by parry3d-f64 and by the
//! exact oracle ([`frcd_obb::oracle`]) on a subset of its steps; frcd must equal the oracle,
//! parry's differences are reported, not asserted. Then a per-step pass prints, for each
//! scene and mode, the medians of the disjoint and of the touching steps for frcd, frcd cached
//! and parry3d-f64, the sequence totals and ratios, and frcd's work per query (box tests,
//! triangle tests, ns per box test on the disjoint steps). One criterion iteration = the whole
//! step sequence.
//!
//! ns per box test = the summed per-step time of plain `collide` (best of four runs) over the
//! disjoint steps, divided by the summed `Counters::box_tests` of those steps: everything a
//! query does (top volume, placements, stack, the few triangle tests) is charged to its box
//! tests. The wide traversal decides up to four box pairs per four-lane test and counts each
//! lane in use as one box test.
//!
//! - `build/*`: tree construction (frcd OBB tree vs parry's BVH inside `TriMesh::new`);
//! - `dense` (class 1): two 20,480-triangle icospheres, B sliding through A in 200 steps;
//! - `knots_near` (class 2): two 49,920-triangle torus knots in near contact, small rotations,
//!   500 steps, 292 of them disjoint;
//! - `cad_*` (class 3): real meshes from `../shared/meshes` at random poses near first contact
//!   (incoherent), 100 steps each (SKIP when the folder is absent): the intermodal wagon
//!   underframe (18,824 triangles) against the bogie frame (5,268), two bogie frames, two
//!   fandisks (5,750);
//! - `knots_slow` (class 4): the knots turning slowly and steadily (coherent), 200 steps;
//! - `sparse/*` (class 5): every body pair of 1,000 sparse bodies, and a `World` over 10,000.
//!
//! Step-by-step tools (environment variables, read by the per-step pass of each pair class):
//!
//! - `FRCD_BENCH_STEPS=DIR` writes `DIR/<scene>.<first|all>`, one line per step: index,
//!   touching (0/1), µs plain, cached and parry3d-f64, box tests, triangle tests, placements.
//!   `benches/peers/pqp_collide.cpp` writes the same steps for PQP with `PQP_STEPS=DIR`
//!   (`<file>.txt.<first|all>`: index, touching, µs, OBB tests, triangle tests), so the two
//!   can be joined step by step (`join`) to see where one library loses;
//! - `FRCD_BENCH_COUNT=1` prints only the work of plain first contact (box and triangle tests
//!   per touching and per disjoint query, no timing) and skips everything else: time-free
//!   counts for comparing traversal orders or trees;
//! - `FRCD_BENCH_HOT=3,17,...` times plain first contact on those steps alone, each repeated
//!   200 times back to back (data hot in the caches), before the per-step pass: set against
//!   the per-step pass (the sequence's order, caches as the previous step left them) it shows
//!   what memory costs;
//! - `FRCD_BENCH_PAIR=NAME` keeps only the scenes whose name contains `NAME` (one CAD pair,
//!   e.g. `cad_fandisk`), for a profiler or callgrind on one pair.

#[path = "common/cad.rs"]
mod cad;

use criterion::{Criterion, criterion_group, criterion_main};
use frcd_benches::scenes::{self, Scene};
use frcd_obb::{
    BuildOptions, FitMethod, Mode, ObbTree, PairCache, Request, TopVolume, World, WorldOptions,
    collide, collide_cached, oracle,
};
use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

macro_rules! parry_backend {
    ($m:ident, $krate:ident, $real:ty) => {
        mod $m {
            use $krate::bounding_volume::BoundingVolume;
            use $krate::math::{Pose, Rotation, Vector};
            use $krate::query::details::intersection_test_support_map_support_map;
            use $krate::shape::TriMesh;

            pub fn mesh(m: &frcd_geom::TriMesh) -> TriMesh {
                let v = m
                    .vertices()
                    .iter()
                    .map(|p| Vector::new(p.x as $real, p.y as $real, p.z as $real))
                    .collect();
                TriMesh::new(v, m.indices().to_vec()).expect("parry accepts the mesh")
            }

            pub fn pose(p: &frcd_geom::Pose) -> Pose {
                let (t, q) = (p.translation, p.rotation);
                Pose::from_parts(
                    Vector::new(t.x as $real, t.y as $real, t.z as $real),
                    Rotation::from_xyzw(q.x as $real, q.y as $real, q.z as $real, q.w as $real)
                        .normalize(),
                )
            }

            /// parry's boolean composite-composite test (`query::intersection_test`).
            pub fn intersection_test(m1: &TriMesh, p1: &Pose, m2: &TriMesh, p2: &Pose) -> bool {
                $krate::query::intersection_test(p1, m1, p2, m2)
                    .expect("trimesh pairs are supported")
                    .intersecting
            }

            /// First contact by parry's lazy simultaneous BVH traversal (`Bvh::leaf_pairs`),
            /// stopping at the first intersecting triangle pair: on near-contact scenes much
            /// faster than `intersection_test`, so it is the one timed.
            pub fn first_contact(m1: &TriMesh, p1: &Pose, m2: &TriMesh, p2: &Pose) -> bool {
                let pos12 = p1.inv_mul(p2);
                m1.bvh()
                    .leaf_pairs(m2.bvh(), |n1, n2| {
                        n1.aabb().intersects(&n2.aabb().transform_by(&pos12))
                    })
                    .any(|(i, j)| {
                        intersection_test_support_map_support_map(
                            &pos12,
                            &m1.triangle(i),
                            &m2.triangle(j),
                        )
                    })
            }

            /// Every intersecting triangle pair: parry's simultaneous BVH traversal
            /// (`Bvh::leaf_pairs`, B's boxes mapped into A's frame) and its triangle test (GJK on
            /// support maps), sorted.
            pub fn all_pairs(m1: &TriMesh, p1: &Pose, m2: &TriMesh, p2: &Pose) -> Vec<(u32, u32)> {
                let pos12 = p1.inv_mul(p2);
                let mut out: Vec<(u32, u32)> = m1
                    .bvh()
                    .leaf_pairs(m2.bvh(), |n1, n2| {
                        n1.aabb().intersects(&n2.aabb().transform_by(&pos12))
                    })
                    .filter(|&(i, j)| {
                        intersection_test_support_map_support_map(
                            &pos12,
                            &m1.triangle(i),
                            &m2.triangle(j),
                        )
                    })
                    .collect();
                out.sort_unstable();
                out
            }
        }
    };
}

parry_backend!(p64, parry3d_f64, f64);

/// Two-body scene prepared for both backends.
struct Pair {
    scene: Scene,
    frcd: [Arc<ObbTree>; 2],
    m64: [parry3d_f64::shape::TriMesh; 2],
    poses64: Vec<[parry3d_f64::math::Pose; 2]>,
}

fn prepare(scene: Scene, opts: &BuildOptions) -> Pair {
    // The trees share the scene's meshes (no copy), so mesh + tree is what a user holds.
    // FRCD_BENCH_NO_QUADS=1: trees without the wide traversal's quad layer (memory-bound
    // engines' choice), to measure what the layer buys.
    let quads = std::env::var("FRCD_BENCH_NO_QUADS").map_or(true, |v| v != "1");
    let tree = |i: usize| {
        Arc::new(ObbTree::build_shared(scene.bodies[i].mesh.clone(), opts).with_quad_layer(quads))
    };
    let frcd = [tree(0), tree(1)];
    for t in &frcd {
        // A first query (each tree against itself, so it traverses) builds the wide
        // traversal's quad layer, which `memory_bytes` counts.
        let id = frcd_geom::Pose::IDENTITY;
        black_box(collide(t, &id, t, &id, &Request::default()));
        let n = t.triangle_count() as f64;
        eprintln!(
            "[memory] {}: {} triangles, leaf {}: mesh {:.1} + tree {:.1} = {:.1} B per triangle",
            scene.name,
            t.triangle_count(),
            opts.max_leaf_triangles,
            t.mesh().memory_bytes() as f64 / n,
            t.memory_bytes() as f64 / n,
            (t.mesh().memory_bytes() + t.memory_bytes()) as f64 / n,
        );
    }
    let m64 = [
        p64::mesh(&scene.bodies[0].mesh),
        p64::mesh(&scene.bodies[1].mesh),
    ];
    let poses64 = scene
        .frames
        .iter()
        .map(|f| [p64::pose(&f[0]), p64::pose(&f[1])])
        .collect();
    Pair {
        scene,
        frcd,
        m64,
        poses64,
    }
}

fn req(mode: Mode) -> Request {
    Request {
        mode,
        method: bench_method(),
        ..Request::default()
    }
}

/// The triangle test: exact unless `FRCD_BENCH_METHOD` names a float method (`tropp`,
/// `moller`, ...) to compare Exact with it inside the tree (the oracle check is skipped then).
fn bench_method() -> frcd_obb::Method {
    use frcd_obb::Method;
    match std::env::var("FRCD_BENCH_METHOD")
        .unwrap_or_default()
        .to_ascii_lowercase()
        .as_str()
    {
        "tropp" => Method::Tropp,
        "moller" => Method::Moller,
        "guigue_devillers" => Method::GuigueDevillers,
        "shen" => Method::Shen,
        "zou" => Method::Zou,
        _ => Method::Exact,
    }
}

/// frcd (plain and cached) against the oracle on every `stride`-th step (the cache sees every
/// step); parry3d-f64's differences printed.
fn agreement(p: &Pair, stride: usize) {
    let (ma, mb) = (&p.scene.bodies[0].mesh, &p.scene.bodies[1].mesh);
    let (ta, tb) = (&p.frcd[0], &p.frcd[1]);
    let mut caches = [PairCache::new(), PairCache::new()];
    let (mut checked, mut touching, mut total) = (0, 0, 0);
    let (mut bool_diff, mut missing, mut extra) = (0, 0, 0);
    for (k, f) in p.scene.frames.iter().enumerate() {
        let all = collide(ta, &f[0], tb, &f[1], &req(Mode::AllPairs));
        let first = collide(ta, &f[0], tb, &f[1], &req(Mode::FirstContact));
        let all_c = collide_cached(ta, &f[0], tb, &f[1], &req(Mode::AllPairs), &mut caches[0]);
        let first_c = collide_cached(
            ta,
            &f[0],
            tb,
            &f[1],
            &req(Mode::FirstContact),
            &mut caches[1],
        );
        assert_eq!(all.pairs, all_c.pairs, "{} step {k}: cached", p.scene.name);
        assert_eq!(first.collide, first_c.collide, "{} step {k}", p.scene.name);
        if k % stride != 0 {
            continue;
        }
        let truth = oracle::pairs(ma, &f[0], mb, &f[1]);
        assert_eq!(
            all.pairs, truth,
            "{} step {k}: frcd differs from the oracle",
            p.scene.name
        );
        for w in [first.witness, first_c.witness].into_iter().flatten() {
            assert!(truth.binary_search(&w).is_ok(), "{} step {k}", p.scene.name);
        }
        assert_eq!(first.collide, !truth.is_empty());
        assert_eq!(first_c.collide, !truth.is_empty());
        let q = &p.poses64[k];
        let got = p64::all_pairs(&p.m64[0], &q[0], &p.m64[1], &q[1]);
        bool_diff +=
            (p64::first_contact(&p.m64[0], &q[0], &p.m64[1], &q[1]) == truth.is_empty()) as usize;
        bool_diff += (p64::intersection_test(&p.m64[0], &q[0], &p.m64[1], &q[1])
            == truth.is_empty()) as usize;
        missing += truth
            .iter()
            .filter(|x| got.binary_search(x).is_err())
            .count();
        extra += got
            .iter()
            .filter(|x| truth.binary_search(x).is_err())
            .count();
        checked += 1;
        touching += !truth.is_empty() as usize;
        total += truth.len();
    }
    eprintln!(
        "[agreement] {}: {checked} of {} steps checked, {touching} touching, {total} pairs; frcd == oracle (both modes, cached and not); parry3d-f64: first contact wrong in {bool_diff}, all pairs {missing} missing, {extra} extra",
        p.scene.name,
        p.scene.steps()
    );
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// FRCD_BENCH_PROFILE=SECONDS: runs the plain first-contact queries of the disjoint steps
/// (FRCD_BENCH_PROFILE_MODE=all: all pairs) in a loop for that long, for a sampling profiler,
/// instead of the class's checks and benchmarks. FRCD_BENCH_PROFILE_MODE=cached (cached-all:
/// all pairs) runs the whole sequence in order with a coherence cache instead, emptied at each
/// repetition, as the split runs do; `touching` (`touching-all`: all pairs) runs the plain
/// queries of the touching steps instead of the disjoint ones. True when it ran.
fn profile_loop(p: &Pair) -> bool {
    let Some(secs) = std::env::var("FRCD_BENCH_PROFILE")
        .ok()
        .and_then(|v| v.parse::<f64>().ok())
    else {
        return false;
    };
    if !(secs.is_finite() && secs > 0.0) {
        eprintln!("[profile] FRCD_BENCH_PROFILE={secs}: want a positive number of seconds");
        return true;
    }
    let which = std::env::var("FRCD_BENCH_PROFILE_MODE").unwrap_or_default();
    let mode = match which.as_str() {
        "all" | "cached-all" | "touching-all" => Mode::AllPairs,
        _ => Mode::FirstContact,
    };
    let (ta, tb) = (&p.frcd[0], &p.frcd[1]);
    let r = req(mode);
    if which.starts_with("cached") {
        let start = Instant::now();
        let (mut queries, mut entries) = (0u64, 0u64);
        let mut work = frcd_obb::Counters::default();
        while start.elapsed().as_secs_f64() < secs {
            let mut cache = PairCache::new();
            for f in &p.scene.frames {
                work += black_box(collide_cached(ta, &f[0], tb, &f[1], &r, &mut cache)).counters;
                entries += cache.front_len() as u64;
            }
            queries += p.scene.frames.len() as u64;
        }
        eprintln!(
            "[profile] {}: {queries} cached queries (whole sequences), {:.2} us each, \
             per query (mean): {} front entries after it, {} box tests, {} placements, \
             {} triangle tests",
            p.scene.name,
            start.elapsed().as_secs_f64() * 1e6 / queries as f64,
            entries / queries,
            work.box_tests / queries,
            work.placements / queries,
            work.tri_tests / queries,
        );
        return true;
    }
    let touching = which.starts_with("touching");
    let kind = if touching { "touching" } else { "disjoint" };
    let steps: Vec<_> = p
        .scene
        .frames
        .iter()
        .filter(|f| collide(ta, &f[0], tb, &f[1], &r).collide == touching)
        .collect();
    if steps.is_empty() {
        eprintln!("[profile] {}: no {kind} steps to profile", p.scene.name);
        return true;
    }
    let start = Instant::now();
    let mut queries = 0u64;
    while start.elapsed().as_secs_f64() < secs {
        for f in &steps {
            black_box(collide(ta, &f[0], tb, &f[1], &r));
        }
        queries += steps.len() as u64;
    }
    eprintln!(
        "[profile] {}: {queries} {kind} queries, {:.2} us each",
        p.scene.name,
        start.elapsed().as_secs_f64() * 1e6 / queries as f64
    );
    true
}

/// Per-step times (best of four runs of the sequence) of frcd, frcd cached and parry3d-f64;
/// prints disjoint and touching medians, totals, ratios and frcd's work per query.
fn split(p: &Pair) {
    let (ta, tb) = (&p.frcd[0], &p.frcd[1]);
    let n = p.scene.steps();
    // FRCD_BENCH_COUNT and FRCD_BENCH_HOT: module docs.
    if std::env::var("FRCD_BENCH_COUNT").is_ok() {
        let r = req(Mode::FirstContact);
        let (mut nt, mut bt, mut tt, mut nd, mut bd) = (0u64, 0u64, 0u64, 0u64, 0u64);
        let s = Instant::now();
        for f in &p.scene.frames {
            let c = collide(ta, &f[0], tb, &f[1], &r);
            if c.collide {
                nt += 1;
                bt += c.counters.box_tests;
                tt += c.counters.tri_tests;
            } else {
                nd += 1;
                bd += c.counters.box_tests;
            }
        }
        eprintln!(
            "[count] {} touching {nt} box/q {:.0} tri/q {:.1} | disjoint {nd} box/q {:.0} | {:.2} ms",
            p.scene.name,
            bt as f64 / nt.max(1) as f64,
            tt as f64 / nt.max(1) as f64,
            bd as f64 / nd.max(1) as f64,
            s.elapsed().as_secs_f64() * 1e3
        );
        return;
    }
    if let Ok(hot) = std::env::var("FRCD_BENCH_HOT") {
        let steps = hot
            .split(',')
            .filter_map(|x| x.trim().parse::<usize>().ok());
        for k in steps.filter(|&k| k < n) {
            let f = &p.scene.frames[k];
            let r = req(Mode::FirstContact);
            let mut best = f64::INFINITY;
            let mut c0 = None;
            for _ in 0..200 {
                let s = Instant::now();
                let c = collide(ta, &f[0], tb, &f[1], &r);
                best = best.min(s.elapsed().as_secs_f64());
                c0 = Some(c.counters);
            }
            let c0 = c0.unwrap_or_default();
            eprintln!(
                "[hot] {} step {k}: {:.1} us, box {} ({:.1} ns each) tri {} placements {}",
                p.scene.name,
                best * 1e6,
                c0.box_tests,
                best * 1e9 / c0.box_tests.max(1) as f64,
                c0.tri_tests,
                c0.placements
            );
        }
    }
    for mode in [Mode::FirstContact, Mode::AllPairs] {
        let r = req(mode);
        let mut t = [
            vec![f64::INFINITY; n],
            vec![f64::INFINITY; n],
            vec![f64::INFINITY; n],
        ];
        let mut touching = vec![false; n];
        let mut work = vec![frcd_obb::Counters::default(); n];
        for run in 0..4 {
            let mut cache = PairCache::new();
            for (k, f) in p.scene.frames.iter().enumerate() {
                // Alternate which of plain and cached runs first (the second finds the data
                // in the CPU caches).
                let mut cached = || {
                    let s = Instant::now();
                    let c = collide_cached(ta, &f[0], tb, &f[1], &r, &mut cache);
                    let e = s.elapsed().as_secs_f64();
                    black_box(c);
                    e
                };
                let e = if run % 2 == 1 { cached() } else { 0.0 };
                let s = Instant::now();
                let c = collide(ta, &f[0], tb, &f[1], &r);
                t[0][k] = t[0][k].min(s.elapsed().as_secs_f64());
                touching[k] = c.collide;
                work[k] = c.counters;
                black_box(c);
                let e = if run % 2 == 0 { cached() } else { e };
                t[1][k] = t[1][k].min(e);
                let q = &p.poses64[k];
                let s = Instant::now();
                match mode {
                    Mode::FirstContact => {
                        black_box(p64::first_contact(&p.m64[0], &q[0], &p.m64[1], &q[1]));
                    }
                    Mode::AllPairs => {
                        black_box(p64::all_pairs(&p.m64[0], &q[0], &p.m64[1], &q[1]));
                    }
                }
                t[2][k] = t[2][k].min(s.elapsed().as_secs_f64());
            }
        }
        let med = |i: usize, touch: bool| {
            median(
                (0..n)
                    .filter(|&k| touching[k] == touch)
                    .map(|k| t[i][k] * 1e6)
                    .collect(),
            )
        };
        let total = |i: usize| t[i].iter().sum::<f64>() * 1e3;
        let sum_where = |touch: bool| {
            let mut c = frcd_obb::Counters::default();
            let mut secs = 0.0;
            let mut m = 0;
            for k in (0..n).filter(|&k| touching[k] == touch) {
                c += work[k];
                secs += t[0][k];
                m += 1;
            }
            (c, secs, m.max(1) as f64)
        };
        let (cd, sd, nd) = sum_where(false);
        let (ct, _, nt) = sum_where(true);
        let label = match mode {
            Mode::FirstContact => "first",
            Mode::AllPairs => "all",
        };
        // FRCD_BENCH_STEPS=DIR: per-step times and work (one line per step: index, touching,
        // µs plain, cached, parry3d-f64, box tests, triangle tests, placements), to compare
        // step by step with the peers' drivers.
        if let Ok(dir) = std::env::var("FRCD_BENCH_STEPS") {
            let lines: String = (0..n)
                .map(|k| {
                    format!(
                        "{k} {} {:.3} {:.3} {:.3} {} {} {}\n",
                        touching[k] as u8,
                        t[0][k] * 1e6,
                        t[1][k] * 1e6,
                        t[2][k] * 1e6,
                        work[k].box_tests,
                        work[k].tri_tests,
                        work[k].placements
                    )
                })
                .collect();
            let path = std::path::Path::new(&dir).join(format!("{}.{label}", p.scene.name));
            if let Err(e) = std::fs::write(&path, lines) {
                eprintln!("[split] cannot write {}: {e}", path.display());
            }
        }
        eprintln!(
            "[split] {} {label}: steps disjoint {} touching {} | median us disjoint/touching: frcd {:.1}/{:.1}, cached {:.1}/{:.1}, parry3d-f64 {:.1}/{:.1} | total ms: frcd {:.2}, cached {:.2}, parry3d-f64 {:.2} | parry/frcd {:.2}x (best of frcd, cached {:.2}x) | frcd per query: disjoint {:.0} box {:.0} tri {:.0} placements, touching {:.0} box {:.0} tri; {:.1} ns per box test (disjoint steps, all work)",
            p.scene.name,
            touching.iter().filter(|x| !**x).count(),
            touching.iter().filter(|x| **x).count(),
            med(0, false),
            med(0, true),
            med(1, false),
            med(1, true),
            med(2, false),
            med(2, true),
            total(0),
            total(1),
            total(2),
            total(2) / total(0).min(total(1)),
            total(1) / total(0),
            cd.box_tests as f64 / nd,
            cd.tri_tests as f64 / nd,
            cd.placements as f64 / nd,
            ct.box_tests as f64 / nt,
            ct.tri_tests as f64 / nt,
            sd * 1e9 / cd.box_tests.max(1) as f64,
        );
    }
}

fn pair_group(c: &mut Criterion, group: &str, p: &Pair) {
    let mut g = c.benchmark_group(format!("obb/{group}"));
    g.sample_size(10);
    for (mode, label) in [(Mode::FirstContact, "first"), (Mode::AllPairs, "all")] {
        let r = req(mode);
        g.bench_function(format!("frcd_{label}"), |b| {
            b.iter(|| {
                let mut n = 0usize;
                for f in &p.scene.frames {
                    let c = collide(&p.frcd[0], &f[0], &p.frcd[1], &f[1], &r);
                    n += c.pairs.len() + c.collide as usize;
                }
                black_box(n)
            })
        });
        g.bench_function(format!("frcd_{label}_cached"), |b| {
            b.iter(|| {
                let mut cache = PairCache::new();
                let mut n = 0usize;
                for f in &p.scene.frames {
                    let c = collide_cached(&p.frcd[0], &f[0], &p.frcd[1], &f[1], &r, &mut cache);
                    n += c.pairs.len() + c.collide as usize;
                }
                black_box(n)
            })
        });
        g.bench_function(format!("parry3d_f64_{label}"), |b| {
            b.iter(|| {
                let mut n = 0usize;
                for q in &p.poses64 {
                    n += match mode {
                        Mode::FirstContact => {
                            p64::first_contact(&p.m64[0], &q[0], &p.m64[1], &q[1]) as usize
                        }
                        Mode::AllPairs => p64::all_pairs(&p.m64[0], &q[0], &p.m64[1], &q[1]).len(),
                    };
                }
                black_box(n)
            })
        });
    }
    g.finish();
}

fn bench_build(c: &mut Criterion) {
    let mut g = c.benchmark_group("obb/build");
    g.sample_size(10);
    let meshes = [
        ("icosphere_20k", frcd_geom::shapes::icosphere(1.0, 5)),
        (
            "knot_50k",
            scenes::torus_knots(1040, 24, 1).bodies[0]
                .mesh
                .as_ref()
                .clone(),
        ),
    ];
    for (name, mesh) in &meshes {
        // Topology is cached in the mesh after its first use (it is the mesh's, not the tree's).
        let _ = mesh.topology();
        g.bench_function(format!("frcd_{name}"), |b| {
            b.iter(|| black_box(ObbTree::build(mesh, &BuildOptions::default())))
        });
        g.bench_function(format!("parry3d_f64_{name}"), |b| {
            b.iter(|| black_box(p64::mesh(mesh)))
        });
    }
    g.finish();
}

fn bench_pairs(c: &mut Criterion) {
    let only = std::env::var("FRCD_BENCH_ONLY").unwrap_or_default();
    let want = |n: &str| only.is_empty() || only.split(',').any(|o| n.contains(o));
    // FRCD_BENCH_LEAF overrides the leaf size (to compare leaf sizes across the classes).
    let mut opts = BuildOptions::default();
    if let Some(leaf) = std::env::var("FRCD_BENCH_LEAF")
        .ok()
        .and_then(|v| v.parse().ok())
    {
        opts.max_leaf_triangles = leaf;
        eprintln!("[leaf] max_leaf_triangles = {leaf}");
    }
    // The wide traversal's build (AVX2 or baseline), to report beside the timings.
    eprintln!("[isa] wide traversal: {}", frcd_obb::wide_traversal_isa());
    let mut list: Vec<(Scene, usize)> = Vec::new();
    if want("dense") {
        let mut s = scenes::icospheres_sweep(5, 200);
        s.name = format!("dense_{}", s.name);
        list.push((s, 4));
    }
    if want("knots_near") {
        list.push((scenes::knots_near_contact(500), 10));
    }
    if want("cad") {
        list.extend(cad::cad_scenes().into_iter().map(|s| (s, 2)));
    }
    if want("knots_slow") {
        list.push((scenes::knots_slow_rotation(200), 10));
    }
    // FRCD_BENCH_PAIR=NAME keeps only the scenes whose name contains NAME (one CAD pair).
    let pair = std::env::var("FRCD_BENCH_PAIR").unwrap_or_default();
    for (scene, stride) in list {
        let name = scene.name.clone();
        if !name.contains(&pair) {
            continue;
        }
        let p = prepare(scene, &opts);
        if profile_loop(&p) {
            continue;
        }
        if bench_method() == frcd_obb::Method::Exact {
            agreement(&p, stride);
        } else {
            eprintln!("[method] {:?}: oracle check skipped", bench_method());
        }
        split(&p);
        pair_group(c, &name, &p);
    }
}

fn bench_fit(c: &mut Criterion) {
    let mut g = c.benchmark_group("obb/fit");
    g.sample_size(10);
    for (name, scene) in [
        ("spheres_l5", scenes::icospheres_sweep(5, 50)),
        ("knots", scenes::torus_knots(1040, 24, 50)),
    ] {
        for fit in [
            FitMethod::VertexCovariance,
            FitMethod::AreaWeighted,
            FitMethod::HullSurface,
        ] {
            let opts = BuildOptions {
                fit,
                ..BuildOptions::default()
            };
            let ta = ObbTree::build(&scene.bodies[0].mesh, &opts);
            let tb = ObbTree::build(&scene.bodies[1].mesh, &opts);
            for (mode, label) in [(Mode::FirstContact, "first"), (Mode::AllPairs, "all")] {
                let r = req(mode);
                g.bench_function(format!("{name}_{label}_{fit:?}"), |b| {
                    b.iter(|| {
                        let mut n = 0;
                        for f in &scene.frames {
                            n += collide(&ta, &f[0], &tb, &f[1], &r).pairs.len();
                        }
                        black_box(n)
                    })
                });
            }
        }
    }
    g.finish();
}

fn bench_sparse(c: &mut Criterion) {
    let mut g = c.benchmark_group("obb/sparse");
    g.sample_size(10);
    // All body pairs of 1,000 bodies, no broad phase: the top volume is the only cull.
    let scene = scenes::sparse(1000, 2, 7);
    let trees: Vec<Arc<ObbTree>> = {
        let mut cache: Vec<(*const frcd_geom::TriMesh, Arc<ObbTree>)> = Vec::new();
        scene
            .bodies
            .iter()
            .map(|b| {
                let key = Arc::as_ptr(&b.mesh);
                if let Some((_, t)) = cache.iter().find(|(k, _)| *k == key) {
                    return t.clone();
                }
                let t = Arc::new(ObbTree::build(&b.mesh, &BuildOptions::default()));
                cache.push((key, t.clone()));
                t
            })
            .collect()
    };
    let pairs = scene.body_pairs();
    for (top, label) in [
        (TopVolume::Hybrid, "hybrid"),
        (TopVolume::RootObb, "root_obb"),
    ] {
        let r = Request {
            top_volume: top,
            ..Request::default()
        };
        g.bench_function(format!("pairs_1000_{label}"), |b| {
            b.iter(|| {
                let f = &scene.frames[0];
                let mut n = 0;
                for &(i, j) in &pairs {
                    n += collide(&trees[i], &f[i], &trees[j], &f[j], &r).collide as usize;
                }
                black_box(n)
            })
        });
    }
    // A World over 10,000 bodies, 10 steps per iteration.
    let big = scenes::sparse(10_000, 10, 11);
    let big_trees: Vec<Arc<ObbTree>> = {
        let t: Vec<Arc<ObbTree>> = (0..3)
            .map(|k| {
                Arc::new(ObbTree::build(
                    &big.bodies[k].mesh,
                    &BuildOptions::default(),
                ))
            })
            .collect();
        (0..big.bodies.len()).map(|i| t[i % 3].clone()).collect()
    };
    for (top, label) in [
        (TopVolume::Hybrid, "hybrid"),
        (TopVolume::RootObb, "root_obb"),
    ] {
        g.bench_function(format!("world_10000_{label}"), |b| {
            b.iter(|| {
                let mut options = WorldOptions::default();
                options.request.top_volume = top;
                let mut w = World::new(options);
                let ids: Vec<_> = big
                    .bodies
                    .iter()
                    .enumerate()
                    .map(|(i, body)| {
                        w.add_body(big_trees[i].clone(), big.frames[0][i], body.is_static)
                            .expect("valid pose")
                    })
                    .collect();
                let mut n = 0;
                for f in &big.frames {
                    for (id, p) in ids.iter().zip(f) {
                        w.set_pose(*id, *p).expect("valid pose");
                    }
                    n += w.step().contacts.len();
                }
                black_box(n)
            })
        });
    }
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(3));
    targets = bench_build, bench_pairs, bench_sparse, bench_fit
}
criterion_main!(benches);
