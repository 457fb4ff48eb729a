//! The prepared and batched exact tests against the one-pair exact test and the independent
//! rational-LP oracle, on random and near-degenerate batches (1 to 8 triangles, i.e. one or two
//! `TriangleBatch`es as a tree leaf would hold them).
use frcd_geom::DVec3;
use frcd_tritri::{
    BATCH_LANES, PreparedTriangle, Triangle, TriangleBatch, exact, exact_prepared, intersects_batch,
};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

#[path = "../../../benches/src/tritri_oracle.rs"]
mod oracle;

fn r3(rng: &mut StdRng) -> DVec3 {
    DVec3::new(rng.random(), rng.random(), rng.random())
}

/// Nudges each coordinate by up to `k` ulps.
fn nudge(rng: &mut StdRng, p: DVec3, k: i64) -> DVec3 {
    let f = |x: f64, d: i64| {
        if x == 0.0 || d == 0 {
            return x;
        }
        f64::from_bits((x.to_bits() as i64 + d) as u64)
    };
    DVec3::new(
        f(p.x, rng.random_range(-k..=k)),
        f(p.y, rng.random_range(-k..=k)),
        f(p.z, rng.random_range(-k..=k)),
    )
}

/// A leaf-mate of `t` in one of the degenerate relations a mesh leaf is full of: sharing a
/// vertex or an edge, coplanar, a vertex (nearly) on its plane or edge, zero-area, or random.
fn relative(rng: &mut StdRng, t: &Triangle, family: usize) -> Triangle {
    let [a, b, c] = t.v;
    let on_plane = |rng: &mut StdRng| {
        let (u, w): (f64, f64) = (rng.random_range(-0.5..1.5), rng.random_range(-0.5..1.5));
        a + (b - a) * u + (c - a) * w
    };
    match family % 9 {
        0 => Triangle::new(a, r3(rng), r3(rng)), // shared vertex
        1 => Triangle::new(a, b, r3(rng)),       // shared edge
        2 => Triangle::new(on_plane(rng), on_plane(rng), on_plane(rng)), // coplanar (rounded)
        3 => {
            let p = on_plane(rng);
            Triangle::new(nudge(rng, p, 2), r3(rng), r3(rng)) // vertex within ulps of the plane
        }
        4 => {
            let u: f64 = rng.random();
            Triangle::new(a + (b - a) * u, r3(rng), r3(rng)) // vertex on an edge
        }
        5 => {
            let p = r3(rng);
            let q = r3(rng);
            Triangle::new(p, q, p + (q - p) * 0.5) // zero-area: a segment
        }
        6 => {
            let p = on_plane(rng);
            Triangle::new(p, p, p) // a point on the plane
        }
        7 => Triangle::new(nudge(rng, b, 1), nudge(rng, c, 1), r3(rng)), // near-shared edge
        _ => Triangle::new(r3(rng), r3(rng), r3(rng)),
    }
}

/// Applies scale and offset to a whole configuration (the same map for every triangle).
fn place(t: &Triangle, s: f64, o: DVec3) -> Triangle {
    Triangle::new(t.v[0] * s + o, t.v[1] * s + o, t.v[2] * s + o)
}

/// Tests `t` against `leaf` every way: batch mask, `intersects_batch`, `exact_prepared` both
/// ways, all equal to `exact`; returns the answers.
fn check_leaf(t: &Triangle, leaf: &[Triangle]) -> Vec<bool> {
    let pt = PreparedTriangle::new(t);
    let prepared: Vec<PreparedTriangle> = leaf.iter().map(PreparedTriangle::new).collect();
    let batches = TriangleBatch::pack(&prepared);
    assert_eq!(batches.len(), leaf.len().div_ceil(BATCH_LANES));
    let want: Vec<bool> = leaf.iter().map(|x| exact(t, x)).collect();
    for (i, (x, px)) in leaf.iter().zip(&prepared).enumerate() {
        assert_eq!(exact_prepared(&pt, px), want[i], "prepared {t:?} {x:?}");
        assert_eq!(
            exact_prepared(px, &pt),
            want[i],
            "prepared swapped {t:?} {x:?}"
        );
        let mask = batches[i / BATCH_LANES].intersect_mask(&pt);
        assert_eq!(
            mask >> (i % BATCH_LANES) & 1 == 1,
            want[i],
            "mask {t:?} {x:?}"
        );
    }
    let mut got = Vec::new();
    assert!(intersects_batch(&pt, &batches, &mut |i| {
        got.push(i);
        true
    }));
    let expect: Vec<usize> = (0..leaf.len()).filter(|&i| want[i]).collect();
    assert_eq!(got, expect, "reported indices");
    want
}

#[test]
fn batches_match_one_pair_and_oracle_random_and_near_degenerate() {
    let mut rng = StdRng::seed_from_u64(9);
    let mut hits = 0usize;
    let mut total = 0usize;
    for round in 0..1500 {
        // Scales and offsets: unit, tiny, subnormal, huge (past the filter's range), and
        // offsets where the cached bound is looser than the pair's extent.
        let (s, o) = match round % 7 {
            0..=2 => (1.0, DVec3::ZERO),
            3 => (1e-300, DVec3::ZERO),
            4 => (1e-315, DVec3::ZERO),
            5 => (1e301, DVec3::ZERO),
            _ => (1.0, DVec3::new(1e8, -3e7, 5e5)),
        };
        let base = Triangle::new(r3(&mut rng), r3(&mut rng), r3(&mut rng));
        let n = 1 + round % 8;
        let leaf: Vec<Triangle> = (0..n)
            .map(|i| place(&relative(&mut rng, &base, round + i), s, o))
            .collect();
        let t = place(&base, s, o);
        let want = check_leaf(&t, &leaf);
        // The oracle on every pair whose coordinates it can take exactly (all of them).
        for (x, &w) in leaf.iter().zip(&want) {
            assert_eq!(oracle::lp_intersects(&t.v, &x.v), w, "oracle {t:?} {x:?}");
        }
        hits += want.iter().filter(|&&w| w).count();
        total += n;
    }
    assert!(
        hits > total / 5 && hits < total * 4 / 5,
        "mix too one-sided: {hits} of {total}"
    );
}

#[test]
fn batches_match_on_integer_grid() {
    // Small integer coordinates: exact coplanarity, shared features and touching everywhere.
    let mut rng = StdRng::seed_from_u64(10);
    for round in 0..3000 {
        let mut v = || {
            DVec3::new(
                rng.random_range(-2..=2) as f64,
                rng.random_range(-2..=2) as f64,
                rng.random_range(-2..=2) as f64 * (round % 3 != 0) as i32 as f64,
            )
        };
        let t = Triangle::new(v(), v(), v());
        let leaf: Vec<Triangle> = (0..1 + round % 8)
            .map(|_| Triangle::new(v(), v(), v()))
            .collect();
        let want = check_leaf(&t, &leaf);
        for (x, &w) in leaf.iter().zip(&want) {
            assert_eq!(oracle::lp_intersects(&t.v, &x.v), w, "oracle {t:?} {x:?}");
        }
    }
}

#[test]
fn batch_stops_when_asked_and_handles_partial_and_empty_input() {
    let t = Triangle::new(
        DVec3::new(-1.0, 0.2, -1.0),
        DVec3::new(10.0, 0.2, -1.0),
        DVec3::new(-1.0, 0.2, 1.0),
    );
    // Six triangles, every one crossed by t (the plane y = 0.2).
    let leaf: Vec<PreparedTriangle> = (0..6)
        .map(|i| {
            let x = i as f64;
            PreparedTriangle::new(&Triangle::new(
                DVec3::new(x, 0.0, -0.5),
                DVec3::new(x, 1.0, -0.5),
                DVec3::new(x, 0.5, 0.5),
            ))
        })
        .collect();
    let batches = TriangleBatch::pack(&leaf);
    let pt = PreparedTriangle::new(&t);
    let mut seen = Vec::new();
    let finished = intersects_batch(&pt, &batches, &mut |i| {
        seen.push(i);
        i < 4
    });
    assert!(!finished);
    assert_eq!(seen, vec![0, 1, 2, 3, 4]);
    assert_eq!(batches[1].len(), 2);
    assert_eq!(
        batches[1].intersect_mask(&pt),
        0b11,
        "unused lanes never reported"
    );
    assert!(intersects_batch(&pt, &[], &mut |_| unreachable!()));
    assert!(TriangleBatch::from_prepared(&[]).is_none());
    assert!(TriangleBatch::from_prepared(&leaf[..5]).is_none());
    let mut b = TriangleBatch::new();
    assert!(b.is_empty());
    for (i, p) in leaf.iter().take(4).enumerate() {
        assert_eq!(b.push(p), Some(i));
    }
    assert_eq!(b.push(&leaf[4]), None);
    assert_eq!(b.get(3), Some(leaf[3]));
    assert_eq!(b.get(4), None);
    assert_eq!(b.intersect_mask(&PreparedTriangle::new(&t)), 0b1111);
}

#[test]
fn non_finite_input_gives_an_answer_without_panicking() {
    let good = Triangle::new(DVec3::ZERO, DVec3::X, DVec3::Y);
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, f64::MAX] {
        let t = Triangle::new(DVec3::new(bad, 0.0, 0.0), DVec3::X, DVec3::Z);
        let (pg, pt) = (PreparedTriangle::new(&good), PreparedTriangle::new(&t));
        let _ = exact_prepared(&pg, &pt);
        let _ = exact_prepared(&pt, &pg);
        let batch = TriangleBatch::from_prepared(&[pg, pt]).expect("2 lanes");
        let _ = batch.intersect_mask(&pt);
        let m = batch.intersect_mask(&pg);
        assert_eq!(m & 1, 1, "the finite triangle still meets itself");
    }
    // f64::MAX coordinates are finite: past the filter's range, decided exactly.
    let big = f64::MAX;
    let a = Triangle::new(
        DVec3::ZERO,
        DVec3::new(big, 0.0, 0.0),
        DVec3::new(0.0, big, 0.0),
    );
    let b = Triangle::new(
        DVec3::new(1.0, 1.0, -big),
        DVec3::new(1.0, 1.0, big),
        DVec3::new(2.0, 2.0, 0.0),
    );
    let want = oracle::lp_intersects(&a.v, &b.v);
    assert!(want);
    assert_eq!(check_leaf(&a, &[b]), vec![want]);
}
