//! `cargo xtask stress [--pairs N] [--seed S] [--show K]`: numerical stability of the
//! triangle-triangle tests.
//!
//! Generates near-degenerate families (near-coplanar, vertex on face, edge on edge, shared vertex
//! / edge, one-ulp near misses, needles, tiny and subnormal, huge offsets, zero-area triangles),
//! each as built and again under a random rotation (rotated, then rounded to f64; the label is
//! computed on the rounded coordinates). Every pair is labelled by an independent exact decision,
//! rational LP feasibility (`frcd_benches::tritri_oracle`, which shares no code with
//! `frcd_tritri::exact`). Prints false positives / false negatives per method and family, and
//! fails (non-zero exit) if the exact method (one pair, prepared one pair, or batched:
//! `frcd_tritri::{exact, exact_prepared, TriangleBatch}`), or the topology of
//! `intersection_segment`, is ever wrong.
use anyhow::{Context, Result, bail};
use frcd_benches::tritri_oracle::lp_intersects;
use frcd_geom::{DQuat, DVec3, Triangle};
use frcd_tritri::{
    Method, PreparedTriangle, TriangleBatch, exact_prepared, intersection_segment, intersects,
};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::time::Instant;

type Pair = ([DVec3; 3], [DVec3; 3]);

/// Options of `cargo xtask stress`.
#[derive(clap::Args, Debug)]
pub struct Opts {
    /// Pairs per family and variant (as built, rotated).
    #[arg(long, value_name = "N", default_value_t = 400, value_parser = crate::positive::<usize>)]
    pub pairs: usize,
    /// Seed of the pair generators.
    #[arg(long, value_name = "S", default_value_t = 2024)]
    pub seed: u64,
    /// Failures printed per method and family.
    #[arg(long, value_name = "K", default_value_t = 3)]
    pub show: usize,
}

// ---------------------------------------------------------------------------------------------
// Generators.

fn unit(rng: &mut StdRng) -> DVec3 {
    DVec3::new(rng.random(), rng.random(), rng.random())
}

fn sym(rng: &mut StdRng) -> DVec3 {
    DVec3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    )
}

fn tri(rng: &mut StdRng) -> [DVec3; 3] {
    loop {
        let t = [unit(rng), unit(rng), unit(rng)];
        if (t[1] - t[0]).cross(t[2] - t[0]).length() > 1e-3 {
            return t;
        }
    }
}

/// Moves a float by `k` ulps.
fn ulps(x: f64, k: i64) -> f64 {
    if k == 0 {
        return x;
    }
    let mut y = x;
    for _ in 0..k.unsigned_abs() {
        y = if k > 0 { y.next_up() } else { y.next_down() };
    }
    y
}

fn nudge(rng: &mut StdRng, p: DVec3, max_ulps: i64) -> DVec3 {
    DVec3::new(
        ulps(p.x, rng.random_range(-max_ulps..=max_ulps)),
        ulps(p.y, rng.random_range(-max_ulps..=max_ulps)),
        ulps(p.z, rng.random_range(-max_ulps..=max_ulps)),
    )
}

fn normal(t: &[DVec3; 3]) -> DVec3 {
    (t[1] - t[0]).cross(t[2] - t[0]).normalize()
}

/// A point of the triangle (barycentric, rounded), inside or on its boundary.
fn point_on(rng: &mut StdRng, t: &[DVec3; 3]) -> DVec3 {
    let (mut u, mut v): (f64, f64) = (rng.random(), rng.random());
    if u + v > 1.0 {
        (u, v) = (1.0 - u, 1.0 - v);
    }
    match rng.random_range(0..4) {
        0 => t[0] + (t[1] - t[0]) * u,  // on an edge
        1 => t[rng.random_range(0..3)], // a vertex
        _ => t[0] + (t[1] - t[0]) * u + (t[2] - t[0]) * v,
    }
}

fn near_coplanar(rng: &mut StdRng) -> Pair {
    let a = tri(rng);
    let e1 = a[1] - a[0];
    let e2 = a[2] - a[0];
    let mut p = || {
        let (u, v) = (rng.random_range(-0.5..1.5), rng.random_range(-0.5..1.5));
        a[0] + e1 * u + e2 * v
    };
    let b = [p(), p(), p()];
    let k = rng.random_range(0..3);
    (a, b.map(|x| nudge(rng, x, k)))
}

fn vertex_on_face(rng: &mut StdRng) -> Pair {
    let a = tri(rng);
    let x = point_on(rng, &a);
    let n = normal(&a) * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    let b1 = x + n * rng.random_range(0.1..1.0) + sym(rng) * 0.3;
    let b2 = x + n * rng.random_range(0.1..1.0) + sym(rng) * 0.3;
    (a, [x, b1, b2])
}

fn edge_edge(rng: &mut StdRng) -> Pair {
    let a = tri(rng);
    let i = rng.random_range(0..3);
    let x = a[i] + (a[(i + 1) % 3] - a[i]) * rng.random::<f64>();
    let w = sym(rng);
    let n = normal(&a);
    // The edge b0-b1 passes (up to rounding) through x, crossing A's plane or lying in it.
    let w = if rng.random_bool(0.3) {
        w - n * w.dot(n)
    } else {
        w
    };
    let side = n * rng.random_range(-1.0..1.0) + sym(rng) * 0.2;
    (a, [x + w, x - w, x + side])
}

fn shared_vertex(rng: &mut StdRng) -> Pair {
    let a = tri(rng);
    let i = rng.random_range(0..3);
    let n = normal(&a) * rng.random_range(-0.3..0.3);
    let b = [a[i], a[i] + sym(rng) * 0.5 + n, a[i] + sym(rng) * 0.5 + n];
    (a, b)
}

fn shared_edge(rng: &mut StdRng) -> Pair {
    let a = tri(rng);
    let i = rng.random_range(0..3);
    let j = (i + 1) % 3;
    // A mesh neighbour (opposite orientation), folded by a random, sometimes tiny, angle.
    let mid = (a[i] + a[j]) * 0.5;
    let away = mid - a[(i + 2) % 3];
    let fold =
        normal(&a) * [1.0, 1e-9, 1e-15, 0.0][rng.random_range(0..4)] * rng.random_range(-1.0..1.0);
    (a, [a[j], a[i], mid + away + fold])
}

fn ulp_near_miss(rng: &mut StdRng) -> Pair {
    let (a, mut b) = vertex_on_face(rng);
    b[0] = nudge(rng, b[0], 1);
    (a, b)
}

fn needle(rng: &mut StdRng) -> Pair {
    let c = unit(rng);
    let d = sym(rng).normalize();
    let perp = d.any_orthonormal_vector();
    let aspect = [1e6, 1e8, 1e10][rng.random_range(0..3)];
    let a = [c, c + d, c + d * 0.5 + perp / aspect];
    // B touches or nearly touches the needle.
    let x = point_on(rng, &a);
    let n = sym(rng);
    let b = if rng.random_bool(0.5) {
        [x, x + n + perp * 0.5, x + n - perp * 0.5]
    } else {
        [x + perp * 1e-12, x - n, x + n.cross(d)]
    };
    let b = b.map(|p| nudge(rng, p, 1));
    if rng.random_bool(0.5) { (a, b) } else { (b, a) }
}

fn zero_area(rng: &mut StdRng) -> Pair {
    let a = tri(rng);
    let x = point_on(rng, &a);
    let n = normal(&a);
    let b = match rng.random_range(0..5) {
        // A point triangle at (or one ulp off) a point of A.
        0 => {
            let p = nudge(rng, x, 1);
            [p, p, p]
        }
        // A segment through a point of A (duplicate vertex).
        1 => {
            let w = n * rng.random_range(-1.0..1.0) + sym(rng) * 0.3;
            [x + w, x - w, x + w]
        }
        // Axis-aligned collinear segment: exactly collinear, three distinct points.
        2 => {
            let k = rng.random_range(0..3);
            let mut p = [x, x, x];
            p[0][k] -= rng.random::<f64>();
            p[1][k] += rng.random::<f64>();
            p[2][k] += rng.random::<f64>() * 0.5;
            p
        }
        // A segment in A's plane (up to rounding), through a point of A.
        3 => {
            let w = (a[1] - a[0]) * rng.random_range(-1.0..1.0);
            [x + w, x - w, x - w]
        }
        // Two segments: A degenerate as well.
        _ => {
            let w = sym(rng);
            let v = sym(rng);
            return (
                [x + w, x - w, x + w],
                [x + v, x - v, x - v].map(|p| nudge(rng, p, 1)),
            );
        }
    };
    (a, b)
}

fn generic(rng: &mut StdRng) -> Pair {
    (tri(rng), tri(rng))
}

/// A near-degenerate configuration drawn from the touching families.
fn touching(rng: &mut StdRng) -> Pair {
    match rng.random_range(0..6) {
        0 => near_coplanar(rng),
        1 => vertex_on_face(rng),
        2 => edge_edge(rng),
        3 => shared_vertex(rng),
        4 => ulp_near_miss(rng),
        _ => zero_area(rng),
    }
}

fn scaled(rng: &mut StdRng, s: f64) -> Pair {
    let (a, b) = touching(rng);
    (a.map(|p| p * s), b.map(|p| p * s))
}

fn tiny(rng: &mut StdRng) -> Pair {
    let s = [1e-300, 1e-310, 2f64.powi(-1040), 1e-320][rng.random_range(0..4)];
    scaled(rng, s)
}

fn huge(rng: &mut StdRng) -> Pair {
    let s = [1e150, 1e300][rng.random_range(0..2)];
    scaled(rng, s)
}

fn offset(rng: &mut StdRng) -> Pair {
    let (a, b) = touching(rng);
    let o = sym(rng) * [1e4, 1e6, 1e8][rng.random_range(0..3)];
    (a.map(|p| p + o), b.map(|p| p + o))
}

type Gen = fn(&mut StdRng) -> Pair;

const FAMILIES: [(&str, Gen); 14] = [
    ("generic", generic),
    ("near_coplanar", near_coplanar),
    ("vertex_on_face", vertex_on_face),
    ("edge_edge", edge_edge),
    ("shared_vertex", shared_vertex),
    ("shared_edge", shared_edge),
    ("ulp_near_miss", ulp_near_miss),
    ("needle", needle),
    ("zero_area", zero_area),
    ("tiny", tiny),
    ("huge_scale", huge),
    ("offset_1e8", offset),
    ("touching_mix", touching),
    ("subnormal", |rng| scaled(rng, 2f64.powi(-1070))),
];

fn rotate(rng: &mut StdRng, (a, b): Pair) -> Pair {
    let q = DQuat::from_axis_angle(
        sym(rng).normalize(),
        rng.random_range(0.0..std::f64::consts::TAU),
    );
    // Rotate about the pair's first vertex so offset families keep their offset.
    let c = a[0];
    let r = |p: DVec3| c + q * (p - c);
    (a.map(r), b.map(r))
}

// ---------------------------------------------------------------------------------------------

#[derive(Default, Clone)]
struct Tally {
    pairs: usize,
    hits: usize,
    fp: [usize; 6],
    fneg: [usize; 6],
    contact_wrong: usize,
    /// Disagreements of the prepared / batched exact forms with the label.
    prepared_wrong: usize,
    exact_ns: u128,
    prepared_ns: u128,
}

/// Entry point of `cargo xtask stress`.
pub fn run(o: Opts) -> Result<()> {
    let t0 = Instant::now();
    let mut rng = StdRng::seed_from_u64(o.seed);
    let mut rows: Vec<(String, Tally)> = Vec::new();
    let mut exact_failures: Vec<String> = Vec::new();
    for (name, gen_pair) in FAMILIES {
        for rotated in [false, true] {
            let label = if rotated {
                format!("{name}/rot")
            } else {
                name.to_string()
            };
            let mut t = Tally::default();
            let mut set: Vec<(Triangle, Triangle)> = Vec::with_capacity(o.pairs);
            for _ in 0..o.pairs {
                let mut p = gen_pair(&mut rng);
                if rotated {
                    p = rotate(&mut rng, p);
                }
                let (a, b) = p;
                if !a.iter().chain(&b).all(|v| v.is_finite()) {
                    continue;
                }
                set.push((Triangle { v: a }, Triangle { v: b }));
                let want = lp_intersects(&a, &b);
                let (ta, tb) = (Triangle { v: a }, Triangle { v: b });
                t.pairs += 1;
                t.hits += want as usize;
                for (mi, m) in Method::ALL.iter().enumerate() {
                    let got = intersects(*m, &ta, &tb);
                    if got && !want {
                        t.fp[mi] += 1;
                    }
                    if !got && want {
                        t.fneg[mi] += 1;
                    }
                    if m.is_exact() && got != want && exact_failures.len() < o.show.max(1) * 10 {
                        exact_failures.push(format!(
                            "{label}: exact={got} oracle={want} a={a:?} b={b:?}"
                        ));
                    }
                }
                // Swapped order must agree too, and the contact must exist iff they meet.
                if frcd_tritri::exact(&tb, &ta) != want {
                    t.fp[5] += (!want) as usize;
                    t.fneg[5] += want as usize;
                    exact_failures
                        .push(format!("{label} (swapped): oracle={want} a={a:?} b={b:?}"));
                }
                // The prepared one-pair test both ways, and each triangle against a batch
                // holding the other: the same exact answer.
                let (pa, pb) = (PreparedTriangle::new(&ta), PreparedTriangle::new(&tb));
                let batch = TriangleBatch::from_prepared(&[pa, pb]).context("two lanes")?;
                let prepared = [
                    exact_prepared(&pa, &pb),
                    exact_prepared(&pb, &pa),
                    batch.intersect_mask(&pa) >> 1 & 1 == 1,
                    batch.intersect_mask(&pb) & 1 == 1,
                ];
                for (k, &got) in prepared.iter().enumerate() {
                    if got != want {
                        t.prepared_wrong += 1;
                        exact_failures.push(format!(
                            "{label} (prepared form {k}): got={got} oracle={want} a={a:?} b={b:?}"
                        ));
                    }
                }
                if intersection_segment(&ta, &tb).is_some() != want {
                    t.contact_wrong += 1;
                }
            }
            // Cost of the exact test on this family: best of three timed passes.
            t.exact_ns = (0..3)
                .map(|_| {
                    let s = Instant::now();
                    let n = set.iter().filter(|(a, b)| frcd_tritri::exact(a, b)).count();
                    std::hint::black_box(n);
                    s.elapsed().as_nanos()
                })
                .min()
                .unwrap_or(0);
            let prep: Vec<(PreparedTriangle, PreparedTriangle)> = set
                .iter()
                .map(|(a, b)| (PreparedTriangle::new(a), PreparedTriangle::new(b)))
                .collect();
            t.prepared_ns = (0..3)
                .map(|_| {
                    let s = Instant::now();
                    let n = prep.iter().filter(|(a, b)| exact_prepared(a, b)).count();
                    std::hint::black_box(n);
                    s.elapsed().as_nanos()
                })
                .min()
                .unwrap_or(0);
            rows.push((label, t));
        }
    }

    // Table.
    let names: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
    println!(
        "tri-tri stress: {} pairs per family and variant, seed {}; each cell is false positives / false negatives against rational LP",
        o.pairs, o.seed
    );
    print!("{:<22} {:>6} {:>6}", "family", "pairs", "meet");
    for n in &names {
        print!(" {:>16}", n);
    }
    println!(
        " {:>8} {:>9} {:>8} {:>7}",
        "contact", "exact ns", "prep ns", "prep ok"
    );
    let mut total = Tally::default();
    for (label, t) in &rows {
        print!("{:<22} {:>6} {:>6}", label, t.pairs, t.hits);
        for mi in 0..6 {
            print!(" {:>16}", format!("{}/{}", t.fp[mi], t.fneg[mi]));
            total.fp[mi] += t.fp[mi];
            total.fneg[mi] += t.fneg[mi];
        }
        println!(
            " {:>8} {:>9.0} {:>8.0} {:>7}",
            t.contact_wrong,
            t.exact_ns as f64 / t.pairs.max(1) as f64,
            t.prepared_ns as f64 / t.pairs.max(1) as f64,
            if t.prepared_wrong == 0 { "yes" } else { "NO" }
        );
        total.prepared_wrong += t.prepared_wrong;
        total.pairs += t.pairs;
        total.hits += t.hits;
        total.contact_wrong += t.contact_wrong;
    }
    print!("{:<22} {:>6} {:>6}", "TOTAL", total.pairs, total.hits);
    for mi in 0..6 {
        print!(" {:>16}", format!("{}/{}", total.fp[mi], total.fneg[mi]));
    }
    println!(" {:>8}", total.contact_wrong);
    for (mi, name) in names.iter().enumerate().take(5) {
        let wrong = total.fp[mi] + total.fneg[mi];
        println!(
            "  {:<18} wrong on {:>6} of {} pairs ({:.2} %)",
            name,
            wrong,
            total.pairs,
            100.0 * wrong as f64 / total.pairs as f64
        );
    }
    println!(
        "exact: {:.0} ns per test over all families (the 'exact ns' column: per family, best of 3 passes); total run {:.1} s",
        rows.iter().map(|(_, t)| t.exact_ns).sum::<u128>() as f64 / total.pairs.max(1) as f64,
        t0.elapsed().as_secs_f64()
    );
    println!(
        "exact_prepared: {:.0} ns per test over all families (triangles prepared beforehand, as a tree caches them)",
        rows.iter().map(|(_, t)| t.prepared_ns).sum::<u128>() as f64 / total.pairs.max(1) as f64,
    );
    let exact_wrong = total.fp[5] + total.fneg[5];
    if exact_wrong > 0 || total.contact_wrong > 0 || total.prepared_wrong > 0 {
        for f in exact_failures.iter().take(o.show.max(1)) {
            eprintln!("EXACT WRONG: {f}");
        }
        bail!(
            "exact method wrong on {exact_wrong} pairs, its prepared / batched forms on {}, intersection_segment topology wrong on {} pairs",
            total.prepared_wrong,
            total.contact_wrong
        );
    }
    println!("exact (one pair, prepared, batched): 0 wrong answers");
    crate::stress_distance::run(o.pairs, o.seed, o.show)
}
