//! Every method against an independent exact oracle (rational LP feasibility, shared with
//! `cargo xtask stress`), on generic pairs and on each degenerate family.
use frcd_geom::DVec3;
use frcd_tritri::{Method, PreparedTriangle, Triangle, TriangleBatch, exact_prepared, intersects};
use proptest::prelude::*;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

#[path = "../../../benches/src/tritri_oracle.rs"]
mod oracle;

fn t(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> Triangle {
    Triangle::new(DVec3::from(a), DVec3::from(b), DVec3::from(c))
}

fn lp(a: &Triangle, b: &Triangle) -> bool {
    oracle::lp_intersects(&a.v, &b.v)
}

/// Every variant of a pair that must give the same answer: swapped, cyclic and odd vertex
/// permutations of either triangle.
fn variants(a: &Triangle, b: &Triangle) -> Vec<(Triangle, Triangle)> {
    let perms: [[usize; 3]; 6] = [
        [0, 1, 2],
        [1, 2, 0],
        [2, 0, 1],
        [0, 2, 1],
        [2, 1, 0],
        [1, 0, 2],
    ];
    let p = |x: &Triangle, q: [usize; 3]| Triangle::new(x.v[q[0]], x.v[q[1]], x.v[q[2]]);
    let mut out = Vec::new();
    for pa in perms {
        for pb in perms {
            out.push((p(a, pa), p(b, pb)));
            out.push((p(b, pb), p(a, pa)));
        }
    }
    out
}

/// The prepared one-pair test both ways, and `y` as lane 2 of a batch tested against `x`
/// (the other lanes hold `x` itself and copies of `y` moved away, so the batch mixes answers).
fn prepared_answers(x: &Triangle, y: &Triangle) -> [bool; 3] {
    let (px, py) = (PreparedTriangle::new(x), PreparedTriangle::new(y));
    let far = |d: f64| {
        let o = DVec3::new(d, -d, 0.5 * d);
        PreparedTriangle::new(&Triangle::new(y.v[0] + o, y.v[1] + o, y.v[2] + o))
    };
    let batch = TriangleBatch::from_prepared(&[px, far(3.0), py, far(-7.0)]).expect("4 lanes");
    let mask = batch.intersect_mask(&px);
    assert_eq!(mask & 1, 1, "a triangle always meets itself: {x:?}");
    [
        exact_prepared(&px, &py),
        exact_prepared(&py, &px),
        mask >> 2 & 1 == 1,
    ]
}

fn check_exact(a: &Triangle, b: &Triangle, expect: bool, what: &str) {
    assert_eq!(
        lp(a, b),
        expect,
        "oracle disagrees with the hand label: {what}"
    );
    for (x, y) in variants(a, b) {
        assert_eq!(frcd_tritri::exact(&x, &y), expect, "{what}: {x:?} {y:?}");
        assert_eq!(
            prepared_answers(&x, &y),
            [expect; 3],
            "{what} (prepared / batch): {x:?} {y:?}"
        );
    }
}

#[test]
fn degenerate_families_hand_labelled() {
    let base = t([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
    // Coplanar: overlap, disjoint, touching at a vertex, sharing an edge, one inside the other.
    check_exact(
        &base,
        &t([0.2, 0.2, 0.0], [2.0, 0.2, 0.0], [0.2, 2.0, 0.0]),
        true,
        "coplanar overlap",
    );
    check_exact(
        &base,
        &t([1.0, 1.0, 0.0], [2.0, 1.0, 0.0], [1.0, 2.0, 0.0]),
        false,
        "coplanar disjoint",
    );
    check_exact(
        &base,
        &t([0.5, 0.5, 0.0], [2.0, 1.0, 0.0], [1.0, 2.0, 0.0]),
        true,
        "coplanar vertex on edge",
    );
    check_exact(
        &base,
        &t([1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.0]),
        true,
        "coplanar shared vertex",
    );
    check_exact(
        &base,
        &t([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]),
        true,
        "coplanar shared edge",
    );
    check_exact(
        &base,
        &t([0.1, 0.1, 0.0], [0.3, 0.1, 0.0], [0.1, 0.3, 0.0]),
        true,
        "coplanar inside",
    );
    check_exact(
        &base,
        &t(
            [0.5, 0.5000000000000001, 0.0],
            [2.0, 1.0, 0.0],
            [1.0, 2.0, 0.0],
        ),
        false,
        "coplanar one-ulp miss",
    );
    // Vertex on face, vertex on edge, edge-edge, shared vertex, shared edge (non-coplanar).
    check_exact(
        &base,
        &t([0.25, 0.25, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]),
        true,
        "vertex on face",
    );
    check_exact(
        &base,
        &t([0.25, 0.25, 1e-300], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]),
        false,
        "vertex 1e-300 above face",
    );
    check_exact(
        &base,
        &t([0.5, 0.0, 0.0], [0.5, -1.0, 1.0], [0.5, 1.0, 1.0]),
        true,
        "vertex on edge",
    );
    check_exact(
        &base,
        &t([0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [0.5, 0.0, 1.0]).clone(),
        true,
        "edge crossing edge (coplanar edge through face)",
    );
    check_exact(
        &base,
        &t([0.5, -1.0, 1.0], [0.5, 1.0, -1.0], [0.5, -1.0, -1.0]),
        true,
        "edge-edge touching",
    );
    check_exact(
        &base,
        &t([0.0, 0.0, 0.0], [-1.0, 0.0, 1.0], [0.0, -1.0, 1.0]),
        true,
        "shared vertex only",
    );
    check_exact(
        &base,
        &t([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
        true,
        "shared edge",
    );
    check_exact(
        &base,
        &t([1.0, 1e-16, 0.0], [1e-16, 1.0, 0.0], [0.0, 0.0, 1.0]),
        false,
        "near shared edge outside",
    );
    // Zero-area triangles: segments and points.
    check_exact(
        &base,
        &t([0.2, 0.2, -1.0], [0.2, 0.2, 1.0], [0.2, 0.2, 0.5]),
        true,
        "segment through face",
    );
    check_exact(
        &base,
        &t([0.2, 0.2, 0.1], [0.2, 0.2, 1.0], [0.2, 0.2, 0.5]),
        false,
        "segment above face",
    );
    check_exact(
        &base,
        &t([-1.0, 0.5, 0.0], [2.0, 0.5, 0.0], [0.5, 0.5, 0.0]),
        true,
        "coplanar segment across",
    );
    check_exact(
        &base,
        &t([-1.0, 2.0, 0.0], [2.0, 2.0, 0.0], [0.5, 2.0, 0.0]),
        false,
        "coplanar segment outside",
    );
    check_exact(
        &base,
        &t([0.3, 0.3, 0.0], [0.3, 0.3, 0.0], [0.3, 0.3, 0.0]),
        true,
        "point in face",
    );
    check_exact(
        &base,
        &t([0.5, 0.5, 0.0], [0.5, 0.5, 0.0], [0.5, 0.5, 0.0]),
        true,
        "point on edge",
    );
    check_exact(
        &base,
        &t([0.6, 0.6, 0.0], [0.6, 0.6, 0.0], [0.6, 0.6, 0.0]),
        false,
        "point outside",
    );
    let seg = t([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [0.5, 0.5, 0.5]);
    check_exact(
        &seg,
        &t([0.0, 1.0, 0.0], [1.0, 0.0, 1.0], [0.5, 0.5, 0.5]),
        true,
        "segments crossing",
    );
    check_exact(
        &seg,
        &t([0.0, 1.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 0.0]),
        true,
        "segments crossing (dup vertex)",
    );
    check_exact(
        &seg,
        &t(
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 1.000000000000001],
            [0.0, 1.0, 0.0],
        ),
        false,
        "skew segments",
    );
    check_exact(
        &seg,
        &t([1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [1.5, 1.5, 1.5]),
        true,
        "collinear segments touching",
    );
    check_exact(
        &seg,
        &t(
            [1.0000000000000002, 1.0000000000000002, 1.0000000000000002],
            [2.0, 2.0, 2.0],
            [2.0, 2.0, 2.0],
        ),
        false,
        "collinear segments one ulp apart",
    );
    check_exact(
        &seg,
        &t([0.25, 0.25, 0.25], [0.25, 0.25, 0.25], [0.25, 0.25, 0.25]),
        true,
        "point on segment",
    );
    let p = t([1.0, 2.0, 3.0], [1.0, 2.0, 3.0], [1.0, 2.0, 3.0]);
    check_exact(&p, &p.clone(), true, "same point");
    // Tiny, subnormal and offset copies of a touching configuration.
    for s in [1e-300, 1e-310, 4.9e-322, 1e300] {
        let sc = |x: &Triangle| Triangle::new(x.v[0] * s, x.v[1] * s, x.v[2] * s);
        let touch = t([0.5, 0.0, 0.0], [0.5, -1.0, 1.0], [0.5, 1.0, 1.0]);
        check_exact(&sc(&base), &sc(&touch), true, "scaled vertex on edge");
    }
}

#[test]
fn exact_matches_oracle_on_integer_grid() {
    // Small integer coordinates: coplanar, touching and shared features are everywhere.
    let mut rng = StdRng::seed_from_u64(1);
    let mut hits = 0;
    for i in 0..3000 {
        let r = if i % 2 == 0 { 2 } else { 3 };
        let mut v = || {
            DVec3::new(
                rng.random_range(-r..=r) as f64,
                rng.random_range(-r..=r) as f64,
                rng.random_range(-r..=r) as f64 * (i % 3 != 0) as i32 as f64,
            )
        };
        let a = Triangle::new(v(), v(), v());
        let b = Triangle::new(v(), v(), v());
        let want = lp(&a, &b);
        hits += want as u32;
        // Exact is invariant under swapping and every vertex permutation, degenerate or not.
        for (x, y) in variants(&a, &b).into_iter().step_by(7) {
            assert_eq!(frcd_tritri::exact(&x, &y), want, "{x:?} {y:?}");
            assert_eq!(prepared_answers(&x, &y), [want; 3], "{x:?} {y:?}");
        }
    }
    assert!(
        hits > 300 && hits < 2700,
        "degenerate mix too one-sided: {hits}"
    );
}

#[test]
fn exact_matches_oracle_near_degenerate() {
    let mut rng = StdRng::seed_from_u64(2);
    for i in 0..3000 {
        let off = [0.0, 1e3, 1e8][i % 3];
        let o = DVec3::splat(off);
        let r = |rng: &mut StdRng| DVec3::new(rng.random(), rng.random(), rng.random());
        let a = Triangle::new(o + r(&mut rng), o + r(&mut rng), o + r(&mut rng));
        // A vertex of b on (rounded) a's plane, or on an edge, nudged by at most an ulp.
        let (u, w): (f64, f64) = (rng.random(), rng.random());
        let on =
            a.v[0] + (a.v[1] - a.v[0]) * u + (a.v[2] - a.v[0]) * if i % 2 == 0 { w } else { 0.0 };
        let b = Triangle::new(on, o + r(&mut rng), o + r(&mut rng));
        let want = lp(&a, &b);
        assert_eq!(frcd_tritri::exact(&a, &b), want, "{a:?} {b:?}");
        assert_eq!(prepared_answers(&a, &b), [want; 3], "{a:?} {b:?}");
    }
}

/// A pair far from every degeneracy: every orientation of four of its six vertices is large.
fn generic(a: &Triangle, b: &Triangle) -> bool {
    let p = [a.v[0], a.v[1], a.v[2], b.v[0], b.v[1], b.v[2]];
    for i in 0..6 {
        for j in i + 1..6 {
            for k in j + 1..6 {
                for l in k + 1..6 {
                    let v = (p[l] - p[i]).dot((p[j] - p[i]).cross(p[k] - p[i]));
                    if v.abs() < 1e-4 {
                        return false;
                    }
                }
            }
        }
    }
    true
}

fn arb_tri() -> impl Strategy<Value = Triangle> {
    prop::array::uniform9(-1.0f64..1.0)
        .prop_map(|c| t([c[0], c[1], c[2]], [c[3], c[4], c[5]], [c[6], c[7], c[8]]))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn all_methods_agree_with_exact_on_generic_pairs(a in arb_tri(), b in arb_tri()) {
        prop_assume!(generic(&a, &b));
        let want = lp(&a, &b);
        for (x, y) in variants(&a, &b) {
            for m in Method::ALL {
                prop_assert_eq!(intersects(m, &x, &y), want, "{} on {:?} {:?}", m.name(), x, y);
            }
        }
    }

    #[test]
    fn exact_is_invariant_under_pow2_scaling_and_exact_translation(
        c in prop::array::uniform18(-64i64..=64),
        k in -1000i32..1000,
        off in prop::array::uniform3(-(1i64 << 30)..(1i64 << 30)),
    ) {
        // Grid coordinates (many exact degeneracies), scaled by 2^k, then moved by an offset on a
        // coarser grid so every translated coordinate is still exactly representable.
        let v = |i: usize| DVec3::new(c[i] as f64, c[i + 1] as f64, c[i + 2] as f64);
        let a = Triangle::new(v(0), v(3), v(6));
        let b = Triangle::new(v(9), v(12), v(15));
        let base = frcd_tritri::exact(&a, &b);
        prop_assert_eq!(base, lp(&a, &b));
        let s = 2f64.powi(k);
        let sc = |x: &Triangle| Triangle::new(x.v[0] * s, x.v[1] * s, x.v[2] * s);
        prop_assert_eq!(prepared_answers(&a, &b), [base; 3]);
        prop_assert_eq!(frcd_tritri::exact(&sc(&a), &sc(&b)), base, "scale 2^{}", k);
        prop_assert_eq!(prepared_answers(&sc(&a), &sc(&b)), [base; 3], "scale 2^{}", k);
        // Translation: coordinates are multiples of 2^-6 below 2^7, offsets multiples of 1 below
        // 2^30: sums need < 43 bits.
        let o = DVec3::new(off[0] as f64, off[1] as f64, off[2] as f64);
        let q = 1.0 / 64.0;
        let tr = |x: &Triangle| Triangle::new(x.v[0] * q + o, x.v[1] * q + o, x.v[2] * q + o);
        prop_assert_eq!(frcd_tritri::exact(&tr(&a), &tr(&b)), base, "offset {:?}", o);
        prop_assert_eq!(prepared_answers(&tr(&a), &tr(&b)), [base; 3], "offset {:?}", o);
        // Offsets up to 1e8 with the unit grid.
        let o8 = DVec3::new(1e8, -1e8, 3e7);
        let tr8 = |x: &Triangle| Triangle::new(x.v[0] + o8, x.v[1] + o8, x.v[2] + o8);
        prop_assert_eq!(frcd_tritri::exact(&tr8(&a), &tr8(&b)), base);
        prop_assert_eq!(prepared_answers(&tr8(&a), &tr8(&b)), [base; 3]);
    }
}
