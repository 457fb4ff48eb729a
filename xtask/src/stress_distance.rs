//! Distance stress (part of `cargo xtask stress`): near-degenerate triangle pairs for
//! `frcd_obb::distance::{distance, within}`.
//!
//! Families: parallel edges, coplanar offsets (and exactly coplanar pairs separated in the
//! plane), a vertex over a face at 1e-12, skew edges crossing at a small gap, huge offsets
//! (1e6 to 1e12 added to every coordinate) and subnormal gaps; each as built and again under a
//! random rotation (rotated, then rounded: labels are computed on the rounded coordinates).
//! Every pair becomes two one-triangle meshes, so the tree query (box bounds included) is what is
//! tested.
//!
//! Labels come from `frcd_obb::oracle::triangles_within_exact` and
//! `triangles_distance_exact` (exact rationals, `num-rational`), which share no code with the
//! query's float filter and its big-integer fallback. For each pair, `within` is asked at eight
//! tolerances straddling the distance (0, the exact distance rounded, its neighbouring floats,
//! the computed distance and its neighbours, ±1e-9 relative); `distance` is compared with the
//! exact distance against its stated `error_bound`. Fails on any wrong `within` or any bound
//! violation.

use anyhow::{Result, bail};
use frcd_geom::{DQuat, DVec3, Pose, TriMesh, Triangle};
use frcd_obb::distance::{DistanceRequest, distance, within_counted};
use frcd_obb::{BuildOptions, ObbTree, oracle};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::time::Instant;

type Pair = ([DVec3; 3], [DVec3; 3]);

fn log_uniform(rng: &mut StdRng, lo: f64, hi: f64) -> f64 {
    10f64.powf(rng.random_range(lo..hi))
}

/// A triangle in `z = 0` whose top edge is `[0,0,0]-[1,0,0]` and which lies below it (`y <= 0`).
fn base(rng: &mut StdRng) -> [DVec3; 3] {
    [
        DVec3::ZERO,
        DVec3::X,
        DVec3::new(rng.random_range(0.0..1.0), -rng.random_range(0.2..1.0), 0.0),
    ]
}

fn parallel_edges(rng: &mut StdRng) -> Pair {
    let a = base(rng);
    let g = log_uniform(rng, -15.0, -1.0);
    let gz = if rng.random_bool(0.5) { 0.0 } else { g };
    let (x0, x1) = (rng.random_range(-0.5..0.5), rng.random_range(0.5..1.5));
    let b = [
        DVec3::new(x0, g, gz),
        DVec3::new(x1, g, gz),
        DVec3::new(
            rng.random_range(0.0..1.0),
            g + 1.0,
            gz + rng.random_range(0.0..1.0),
        ),
    ];
    (a, b)
}

fn coplanar_offset(rng: &mut StdRng) -> Pair {
    let a = base(rng);
    let h = if rng.random_bool(0.3) {
        0.0
    } else {
        log_uniform(rng, -16.0, -2.0)
    };
    // In-plane shift: overlapping projections, or separated by a small in-plane gap.
    let shift = if rng.random_bool(0.5) {
        DVec3::new(rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3), h)
    } else {
        DVec3::new(0.0, log_uniform(rng, -15.0, -1.0), h)
    };
    // B: A reflected across its top edge (so it lies at y >= 0), then shifted.
    let b = a.map(|p| DVec3::new(p.x, -p.y, p.z) + shift);
    (a, b)
}

fn vertex_over_face(rng: &mut StdRng) -> Pair {
    let a = base(rng);
    let (u, v): (f64, f64) = (rng.random_range(0.05..0.45), rng.random_range(0.05..0.45));
    let p = a[0] + (a[1] - a[0]) * u + (a[2] - a[0]) * v;
    let h = 1e-12 * rng.random_range(0.5..2.0);
    let apex = DVec3::new(p.x, p.y, h);
    let b = [
        apex,
        apex + DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            1.0,
        ),
        apex + DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            1.5,
        ),
    ];
    (a, b)
}

fn skew_edges(rng: &mut StdRng) -> Pair {
    let a = base(rng);
    let g = log_uniform(rng, -15.0, -1.0);
    let x = rng.random_range(0.1..0.9);
    // B's lowest edge runs along y above the point (x, 0, 0) of A's top edge, at height g.
    let b = [
        DVec3::new(x, -0.5, g),
        DVec3::new(x, 0.5, g),
        DVec3::new(x + rng.random_range(-0.5..0.5), 0.0, g + 1.0),
    ];
    (a, b)
}

fn huge_offset(rng: &mut StdRng) -> Pair {
    let (a, b) = match rng.random_range(0..3) {
        0 => parallel_edges(rng),
        1 => vertex_over_face(rng),
        _ => skew_edges(rng),
    };
    let o = DVec3::new(
        log_uniform(rng, 6.0, 12.0),
        -log_uniform(rng, 6.0, 12.0),
        log_uniform(rng, 6.0, 12.0),
    );
    (a.map(|p| p + o), b.map(|p| p + o))
}

fn subnormal_gap(rng: &mut StdRng) -> Pair {
    let k = rng.random_range(1..1000u64);
    let g = f64::from_bits(k); // k · 2^-1074
    let a = base(rng);
    match rng.random_range(0..3) {
        0 => {
            let p = DVec3::new(0.3, -0.1, g);
            (
                a,
                [
                    p,
                    p + DVec3::new(0.2, 0.1, 1.0),
                    p + DVec3::new(-0.2, 0.1, 1.0),
                ],
            )
        }
        1 => {
            let b = [
                DVec3::new(0.2, g, 0.0),
                DVec3::new(0.8, g, 0.0),
                DVec3::new(0.5, 1.0, 0.0),
            ];
            (a, b)
        }
        _ => {
            // Everything tiny: a pair scaled into the subnormal range.
            let (a, b) = vertex_over_face(rng);
            let s = 2f64.powi(-1040);
            (a.map(|p| p * s), b.map(|p| p * s))
        }
    }
}

/// A stress family: its name and its generator.
type Family = (&'static str, fn(&mut StdRng) -> Pair);

const FAMILIES: &[Family] = &[
    ("parallel_edges", parallel_edges),
    ("coplanar_offset", coplanar_offset),
    ("vertex_over_face_1e-12", vertex_over_face),
    ("skew_edges", skew_edges),
    ("huge_offset", huge_offset),
    ("subnormal_gap", subnormal_gap),
];

fn rotate(rng: &mut StdRng, (a, b): Pair) -> Pair {
    let q = DQuat::from_axis_angle(
        DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalize_or(DVec3::Z),
        rng.random_range(0.0..std::f64::consts::TAU),
    );
    let c = a[0];
    let r = |p: DVec3| c + q * (p - c);
    (a.map(r), b.map(r))
}

fn one(t: [DVec3; 3]) -> Option<ObbTree> {
    let m = TriMesh::new(t.to_vec(), vec![[0, 1, 2]]).ok()?;
    Some(ObbTree::build(&m, &BuildOptions::default()))
}

#[derive(Default)]
struct Row {
    pairs: usize,
    decisions: usize,
    yes: usize,
    wrong: usize,
    exact_stage: u64,
    tri_tests: u64,
    worst_ratio: f64,
    violations: usize,
}

/// Runs the distance families and prints the table: `pairs / 4` pairs per family and variant
/// (each pair costs eight exact rational labels; `--pairs 400` runs in about two minutes).
pub fn run(pairs: usize, seed: u64, show: usize) -> Result<()> {
    let pairs = (pairs / 4).max(1);
    let t0 = Instant::now();
    let mut rng = StdRng::seed_from_u64(seed ^ 0xD157);
    let mut failures: Vec<String> = Vec::new();
    let mut rows: Vec<(String, Row)> = Vec::new();
    let id = Pose::IDENTITY;
    for (name, gen_pair) in FAMILIES {
        for rotated in [false, true] {
            let label = if rotated {
                format!("{name}/rot")
            } else {
                name.to_string()
            };
            let mut row = Row::default();
            for _ in 0..pairs {
                let mut p = gen_pair(&mut rng);
                if rotated {
                    p = rotate(&mut rng, p);
                }
                let (a, b) = p;
                let (Some(ta), Some(tb)) = (one(a), one(b)) else {
                    continue;
                };
                let (xa, xb) = (Triangle { v: a }, Triangle { v: b });
                row.pairs += 1;
                let exact = oracle::triangles_distance_exact(&xa, &xb);
                let d = distance(&ta, &id, &tb, &id, &DistanceRequest::default());
                let err = (d.distance - exact).abs();
                let ratio = err / d.error_bound;
                row.worst_ratio = row.worst_ratio.max(ratio);
                if ratio > 1.0 {
                    row.violations += 1;
                    failures.push(format!(
                        "{label}: distance {} exact {exact} bound {} a={a:?} b={b:?}",
                        d.distance, d.error_bound
                    ));
                }
                let tols = [
                    0.0,
                    exact,
                    exact.next_down(),
                    exact.next_up(),
                    d.distance,
                    d.distance.next_down(),
                    d.distance * (1.0 + 1e-9),
                    d.distance * (1.0 - 1e-9),
                ];
                for tol in tols {
                    if tol < 0.0 {
                        continue;
                    }
                    let (got, c) = within_counted(&ta, &id, &tb, &id, tol);
                    let want = oracle::triangles_within_exact(&xa, &xb, tol);
                    row.decisions += 1;
                    row.yes += want as usize;
                    row.exact_stage += c.exact_fallbacks;
                    row.tri_tests += c.tri_tests;
                    if got != want {
                        row.wrong += 1;
                        failures.push(format!(
                            "{label}: within({tol:e}) = {got}, exact {want}; a={a:?} b={b:?}"
                        ));
                    }
                }
            }
            rows.push((label, row));
        }
    }
    println!(
        "\ndistance stress: {pairs} pairs per family and variant, seed {seed}; within vs exact rational labels at 8 tolerances per pair; distance vs exact distance in units of its error_bound"
    );
    println!(
        "{:<28} {:>6} {:>9} {:>7} {:>7} {:>11} {:>14} {:>10}",
        "family",
        "pairs",
        "decisions",
        "within",
        "wrong",
        "exact stage",
        "max err/bound",
        "violations"
    );
    let (mut wrong, mut viol) = (0, 0);
    for (label, r) in &rows {
        println!(
            "{:<28} {:>6} {:>9} {:>7} {:>7} {:>10.1}% {:>14.3} {:>10}",
            label,
            r.pairs,
            r.decisions,
            r.yes,
            r.wrong,
            100.0 * r.exact_stage as f64 / r.tri_tests.max(1) as f64,
            r.worst_ratio,
            r.violations
        );
        wrong += r.wrong;
        viol += r.violations;
    }
    println!(
        "distance stress: {wrong} wrong within, {viol} bound violations; {:.1} s",
        t0.elapsed().as_secs_f64()
    );
    if wrong > 0 || viol > 0 {
        for f in failures.iter().take(show.max(1)) {
            eprintln!("DISTANCE WRONG: {f}");
        }
        bail!("distance stress: {wrong} wrong within answers, {viol} distance bound violations");
    }
    Ok(())
}
