//! The exact test: Guigue-Devillers structure on orientation predicates of input vertices, with
//! one cheap floating-point filter for the whole pair and exact fallback per uncertain sign.
//!
//! # Why it is exact
//!
//! Every decision is the sign of `orient3d` of four input vertices (or `orient2d` of projected
//! input vertices in the coplanar / degenerate branch). Each `orient3d` is first evaluated in f64
//! exactly as Shewchuk's stage A does (`u·(v×w)` of three rounded differences), and its sign is
//! trusted only when `|value| > B` with
//!
//! `B = 400ε·m³`, `m` = the largest magnitude of the 15 coordinates of `q2−p2`, `r2−p2`,
//! `p1−p2`, `q1−p2`, `r1−p2` (differences the first plane test computes anyway; one bound per
//! pair, 15 `abs` and 14 `max`).
//!
//! Shewchuk's bound is `(7+56ε)ε·perm` where `perm` is the permanent of the computed differences.
//! All six vertices lie within `m/(1−ε)` of `p2` (∞-norm), so every computed difference of two of
//! them is at most `Δ = 2m(1+3ε)` and `perm ≤ 6Δ³ ≤ 48.0001·m³`, giving an error below
//! `336.1ε·m³`; 400 leaves room for the roundings of `m³` and for underflow. The bound is only
//! used when `2⁻³⁰⁰ ≤ m ≤ 2³⁰⁰`: then nothing overflows, and the absolute error of underflowing
//! products (a few `2⁻¹⁰⁷⁵·(2m+1)`) is far below the slack `64ε·m³`. Outside that range (tiny,
//! subnormal or astronomically large pairs) `B = ∞` and every sign comes from the exact
//! predicates of `frcd_geom::predicates` (expansions with exact power-of-two scaling, big
//! integers for extreme dynamic range).
//!
//! # Speed
//!
//! In the common case every sign is certain and the cost over a plain float Guigue-Devillers is
//! the bound (15 `abs`, 14 `max`, a few multiplies) and a few comparisons; the Guigue-Devillers
//! permutation is index arithmetic instead of nested branches. Uncertain
//! signs take `exact_slow`, which recomputes only the uncertain ones exactly. Where the same
//! triangles meet many others, [`crate::PreparedTriangle`] caches the bound's magnitudes and
//! the normals instead.
//!
//! A sign within the bound is recomputed by [`orient3d_exact`]; the branch structure is then the
//! exact Guigue-Devillers decision. Coplanar pairs and zero-area triangles (segments, points) go
//! to [`general`], which classifies each triangle exactly and runs the matching exact primitive.
use frcd_geom::predicates::{EPS, collinear3, orient2d, orient3d, orient3d_exact};
use frcd_geom::{DVec2, DVec3};

const BOUND_FACTOR: f64 = 400.0 * EPS;
const MIN_EXTENT: f64 = f64::from_bits((1023 - 300) << 52);
const MAX_EXTENT: f64 = f64::from_bits((1023 + 300) << 52);

/// The f64 value of `orient3d(a, b, c, d)` = `(d-a)·((b-a)×(c-a))`, evaluated like Shewchuk's
/// stage A (three differences, a cross product, a dot product).
#[inline(always)]
fn o3_value(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> f64 {
    (d - a).dot((b - a).cross(c - a))
}

/// `max` that compiles to one instruction (no NaN fix-up: a NaN input makes the float values
/// NaN, which never pass the `|v| > bound` test, so NaN cannot be trusted by accident).
#[inline(always)]
pub(crate) fn fmax(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

#[inline(always)]
pub(crate) fn fmin(a: f64, b: f64) -> f64 {
    if a < b { a } else { b }
}

/// Exact sign of `orient3d(a, b, c, d)` given its f64 value `v` and the pair bound.
#[inline(always)]
fn sgn(v: f64, bound: f64, a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> i8 {
    if v > bound {
        1
    } else if v < -bound {
        -1
    } else {
        orient3d_exact(a, b, c, d)
    }
}

#[inline(always)]
fn all_same_sign(s: [i8; 3]) -> bool {
    s[0] != 0 && s[0] == s[1] && s[0] == s[2]
}

/// For three non-zero values not all of one sign: (the index of the lone vertex, whether it is
/// on the positive side). Table lookup instead of Guigue-Devillers' nested branches.
#[inline(always)]
pub(crate) fn lone_nonzero(s0: f64, s1: f64, s2: f64) -> (usize, bool) {
    const LONE: [u8; 8] = [0, 0, 1, 2, 2, 1, 0, 0];
    let bits = (s0 > 0.0) as usize | ((s1 > 0.0) as usize) << 1 | ((s2 > 0.0) as usize) << 2;
    let l = LONE[bits] as usize;
    (l, (bits >> l) & 1 == 1)
}

/// The exact test. See [`crate::exact`].
#[inline]
pub(crate) fn exact(ta: &[DVec3; 3], tb: &[DVec3; 3]) -> bool {
    let [p1, q1, r1] = *ta;
    let [p2, q2, r2] = *tb;

    let f1 = q2 - p2;
    let f2 = r2 - p2;
    let dp = p1 - p2;
    let dq = q1 - p2;
    let dr = r1 - p2;
    // `m` bounds the magnitude of all 15 coordinates; every vertex is within m/(1-ε) of p2, so
    // every computed difference of two vertices is at most Δ = 2m(1+3ε) (module docs).
    let am = |v: DVec3| fmax(fmax(v.x.abs(), v.y.abs()), v.z.abs());
    let m = fmax(fmax(fmax(am(f1), am(f2)), fmax(am(dp), am(dq))), am(dr));
    let bound = if (MIN_EXTENT..=MAX_EXTENT).contains(&m) {
        BOUND_FACTOR * (m * m * m)
    } else {
        f64::INFINITY
    };

    // Vertices of A against the plane of B: orient3d(p2, q2, r2, x) = (x-p2)·((q2-p2)×(r2-p2)).
    // (Sequential plane tests measured faster here than one combined branch: the second plane
    // needs its own cross product and differences.)
    let n2 = f1.cross(f2);
    let s = [dp.dot(n2), dq.dot(n2), dr.dot(n2)];
    if separation(s[0], s[1], s[2], bound) > 0.0 {
        return false; // certainly all on one side
    }
    if !is_positive(certainty(s[0], s[1], s[2], bound)) {
        return exact_slow(ta, tb, bound);
    }
    // Vertices of B against the plane of A (p2 - p1 = -(p1 - p2) exactly).
    let n1 = (q1 - p1).cross(r1 - p1);
    let t = [(-dp).dot(n1), (q2 - p1).dot(n1), (r2 - p1).dot(n1)];
    if separation(t[0], t[1], t[2], bound) > 0.0 {
        return false;
    }
    if !is_positive(certainty(t[0], t[1], t[2], bound)) {
        return exact_slow(ta, tb, bound);
    }
    gd_final(ta, tb, s, t, bound)
}

/// `x > 0`: false for NaN (an uncertain value never passes).
#[inline(always)]
pub(crate) fn is_positive(x: f64) -> bool {
    x > 0.0
}

#[inline(always)]
fn min3(a: f64, b: f64, c: f64) -> f64 {
    fmin(fmin(a, b), c)
}

#[inline(always)]
fn max3(a: f64, b: f64, c: f64) -> f64 {
    fmax(fmax(a, b), c)
}

/// Positive iff the three values certainly have one strict sign: `min > bound` or
/// `max < −bound` (`fl(x − y) > 0` iff `x > y`). Never positive for a NaN or `+∞` bound.
#[inline(always)]
pub(crate) fn separation(s0: f64, s1: f64, s2: f64, bound: f64) -> f64 {
    fmax(min3(s0, s1, s2) - bound, -max3(s0, s1, s2) - bound)
}

/// Positive iff all three signs are certain (`|s_i| > bound`). Never positive for a `+∞`
/// bound; callers never pass a NaN one.
#[inline(always)]
pub(crate) fn certainty(s0: f64, s1: f64, s2: f64, bound: f64) -> f64 {
    min3(s0.abs(), s1.abs(), s2.abs()) - bound
}

/// For three non-zero values not all of one sign: (the index of the lone vertex, whether it is
/// on the positive side), from a table packed into a constant (no memory load on the critical
/// path).
#[inline(always)]
fn lone_packed(s: [f64; 3]) -> (usize, bool) {
    // LONE[bits] = [0, 0, 1, 2, 2, 1, 0, 0] in 2-bit fields.
    const LONE: u32 = (1 << 4) | (2 << 6) | (2 << 8) | (1 << 10);
    let bits = (s[0] > 0.0) as u32 | ((s[1] > 0.0) as u32) << 1 | ((s[2] > 0.0) as u32) << 2;
    let l = (LONE >> (2 * bits)) & 3;
    (l as usize, (bits >> l) & 1 == 1)
}

/// `(i + 1) % 3` and `(i + 2) % 3` for `i < 3`, from packed tables.
#[inline(always)]
fn next_prev(i: usize) -> (usize, usize) {
    const NEXT: usize = 1 | (2 << 2);
    const PREV: usize = 2 | (1 << 4);
    ((NEXT >> (2 * i)) & 3, (PREV >> (2 * i)) & 3)
}

/// The end of the filtered test, once both triangles cross the other's plane with every
/// plane-side sign certain and non-zero. `s`: A's vertices against plane(B), `t`: B's against
/// plane(A) (only their signs are used).
///
/// Guigue-Devillers: with `p1` A's lone vertex and `p2` B's, A's other two vertices `q1, r1`
/// in A's order (swapped when `p2` is on the negative side of plane(A)), and B's `q2, r2` in B's
/// order (swapped when `p1` is on the negative side of plane(B)), the triangles meet iff
/// `orient3d(q1, p2, p1, q2) ≤ 0` and `orient3d(p1, p2, r1, r2) ≤ 0`. The permutation is index
/// arithmetic; both orientations are computed from the differences to `p1`
/// (`det[p2−q1, p1−q1, q2−q1] = −P·(Q1×Q2)` and `det[p2−p1, r1−p1, r2−p1] = P·(R1×R2)` with
/// `P = p2−p1`, `Q1 = q1−p1`, ...), Shewchuk's stage-A form, so `bound` (a valid stage-A
/// bound for any `orient3d` of the six vertices) certifies them; an uncertain one is
/// recomputed exactly.
#[inline(always)]
pub(crate) fn gd_final(
    ta: &[DVec3; 3],
    tb: &[DVec3; 3],
    s: [f64; 3],
    t: [f64; 3],
    bound: f64,
) -> bool {
    let (la, pa) = lone_packed(s);
    let (lb, pb) = lone_packed(t);
    let (na, pra) = next_prev(la);
    let (nb, prb) = next_prev(lb);
    let (iq1, ir1) = if pb { (na, pra) } else { (pra, na) };
    let (iq2, ir2) = if pa { (nb, prb) } else { (prb, nb) };
    let (p1, q1, r1) = (ta[la], ta[iq1], ta[ir1]);
    let (p2, q2, r2) = (tb[lb], tb[iq2], tb[ir2]);

    let pp = p2 - p1;
    let v1 = -pp.dot((q1 - p1).cross(q2 - p1));
    let v2 = pp.dot((r1 - p1).cross(r2 - p1));
    // Overlap iff both <= 0. A NaN bound is never passed.
    if (v1.abs() > bound) & (v2.abs() > bound) {
        return (v1 < 0.0) & (v2 < 0.0);
    }
    sgn(v1, bound, q1, p2, p1, q2) <= 0 && sgn(v2, bound, p1, p2, r1, r2) <= 0
}

/// The exact test when some plane-side sign is within the float bound (or the pair is outside
/// the filter's range): Guigue-Devillers with each uncertain sign recomputed exactly.
#[cold]
#[inline(never)]
pub(crate) fn exact_slow(ta: &[DVec3; 3], tb: &[DVec3; 3], bound: f64) -> bool {
    let [p1, q1, r1] = *ta;
    let [p2, q2, r2] = *tb;
    let d1 = [
        sgn(o3_value(p2, q2, r2, p1), bound, p2, q2, r2, p1),
        sgn(o3_value(p2, q2, r2, q1), bound, p2, q2, r2, q1),
        sgn(o3_value(p2, q2, r2, r1), bound, p2, q2, r2, r1),
    ];
    if all_same_sign(d1) {
        return false;
    }
    let d2 = [
        sgn(o3_value(p1, q1, r1, p2), bound, p1, q1, r1, p2),
        sgn(o3_value(p1, q1, r1, q2), bound, p1, q1, r1, q2),
        sgn(o3_value(p1, q1, r1, r2), bound, p1, q1, r1, r2),
    ];
    if all_same_sign(d2) {
        return false;
    }
    let check = |p1: DVec3, q1: DVec3, r1: DVec3, p2: DVec3, q2: DVec3, r2: DVec3| -> bool {
        sgn(o3_value(q1, p2, p1, q2), bound, q1, p2, p1, q2) <= 0
            && sgn(o3_value(p1, p2, r1, r2), bound, p1, p2, r1, r2) <= 0
    };
    crate::gd_dispatch(
        *ta,
        *tb,
        d1.map(f64::from),
        d2.map(f64::from),
        check,
        || general(ta, tb),
    )
}

// ---------------------------------------------------------------------------------------------
// Coplanar and degenerate configurations, all signs exact.

/// What a triangle is as a point set, decided exactly.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Shape {
    /// A proper triangle (non-collinear vertices).
    Tri([DVec3; 3]),
    /// Collinear vertices, not all equal: the segment between the two extreme ones.
    Seg(DVec3, DVec3),
    /// Three equal vertices.
    Pt(DVec3),
}

fn lex_lt(a: DVec3, b: DVec3) -> bool {
    (a.x, a.y, a.z) < (b.x, b.y, b.z)
}

pub(crate) fn classify(t: &[DVec3; 3]) -> Shape {
    if !collinear3(t[0], t[1], t[2]) {
        return Shape::Tri(*t);
    }
    // On a line, lexicographic order is the order along the line.
    let mut lo = t[0];
    let mut hi = t[0];
    for &p in &t[1..] {
        if lex_lt(p, lo) {
            lo = p;
        }
        if lex_lt(hi, p) {
            hi = p;
        }
    }
    if lo == hi {
        Shape::Pt(lo)
    } else {
        Shape::Seg(lo, hi)
    }
}

/// Drops coordinate `k` (keeps the cyclic pair `(k+1, k+2)`, so the 2D orientation of a
/// projected triangle is the sign of the k-th normal component).
#[inline]
pub(crate) fn proj(p: DVec3, k: usize) -> DVec2 {
    match k {
        0 => DVec2::new(p.y, p.z),
        1 => DVec2::new(p.z, p.x),
        _ => DVec2::new(p.x, p.y),
    }
}

/// An axis along which the projection of the (non-degenerate) triangle keeps its area, with the
/// exact sign of the projected orientation.
pub(crate) fn drop_axis(t: &[DVec3; 3]) -> (usize, i8) {
    let n = (t[1] - t[0]).cross(t[2] - t[0]).abs();
    // Try the largest float component first: almost always exactly non-zero.
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| n[j].total_cmp(&n[i]));
    for k in order {
        let s = orient2d(proj(t[0], k), proj(t[1], k), proj(t[2], k));
        if s != 0 {
            return (k, s);
        }
    }
    (2, 0) // only for collinear input, which callers exclude
}

/// Closed 2D segments `[p, q]` and `[r, s]` meet (either may be a single point).
pub(crate) fn seg_seg_2d(p: DVec2, q: DVec2, r: DVec2, s: DVec2) -> bool {
    let o1 = orient2d(p, q, r);
    let o2 = orient2d(p, q, s);
    if o1 * o2 > 0 {
        return false;
    }
    let o3 = orient2d(r, s, p);
    let o4 = orient2d(r, s, q);
    if o3 * o4 > 0 {
        return false;
    }
    if o1 == 0 && o2 == 0 && o3 == 0 && o4 == 0 {
        // Collinear: the boxes overlap iff the segments do.
        let (a0, a1) = (p.min(q), p.max(q));
        let (b0, b1) = (r.min(s), r.max(s));
        return a0.x <= b1.x && b0.x <= a1.x && a0.y <= b1.y && b0.y <= a1.y;
    }
    true
}

/// `x` lies in the closed 2D triangle `t` of orientation `o` (±1).
pub(crate) fn point_in_tri_2d(x: DVec2, t: &[DVec2; 3], o: i8) -> bool {
    (0..3).all(|i| orient2d(t[i], t[(i + 1) % 3], x) * o >= 0)
}

fn tri_tri_2d(a: &[DVec2; 3], oa: i8, b: &[DVec2; 3], ob: i8) -> bool {
    for i in 0..3 {
        for j in 0..3 {
            if seg_seg_2d(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3]) {
                return true;
            }
        }
    }
    point_in_tri_2d(a[0], b, ob) || point_in_tri_2d(b[0], a, oa)
}

/// Two proper triangles in one plane.
fn coplanar_tri_tri(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    let (k, oa) = drop_axis(a);
    let pa = a.map(|p| proj(p, k));
    let pb = b.map(|p| proj(p, k));
    let ob = orient2d(pb[0], pb[1], pb[2]);
    tri_tri_2d(&pa, oa, &pb, ob)
}

pub(crate) fn point_in_tri_3d(x: DVec3, t: &[DVec3; 3]) -> bool {
    if orient3d(t[0], t[1], t[2], x) != 0 {
        return false;
    }
    let (k, o) = drop_axis(t);
    point_in_tri_2d(proj(x, k), &t.map(|p| proj(p, k)), o)
}

fn seg_tri(p: DVec3, q: DVec3, t: &[DVec3; 3]) -> bool {
    let sp = orient3d(t[0], t[1], t[2], p);
    let sq = orient3d(t[0], t[1], t[2], q);
    if sp * sq > 0 {
        return false;
    }
    if sp == 0 && sq == 0 {
        let (k, o) = drop_axis(t);
        let pt = t.map(|v| proj(v, k));
        let (pp, pq) = (proj(p, k), proj(q, k));
        return point_in_tri_2d(pp, &pt, o)
            || (0..3).any(|i| seg_seg_2d(pp, pq, pt[i], pt[(i + 1) % 3]));
    }
    // The segment meets the plane in one point; it lies in the triangle iff the line pq passes
    // through it: no two edge orientations of opposite strict sign.
    let o0 = orient3d(p, q, t[0], t[1]);
    let o1 = orient3d(p, q, t[1], t[2]);
    let o2 = orient3d(p, q, t[2], t[0]);
    !((o0 > 0 || o1 > 0 || o2 > 0) && (o0 < 0 || o1 < 0 || o2 < 0))
}

fn seg_seg_3d(p: DVec3, q: DVec3, r: DVec3, s: DVec3) -> bool {
    if orient3d(p, q, r, s) != 0 {
        return false;
    }
    // Coplanar: some axis projection is injective on the common plane (or line), and every
    // projection of meeting sets meets, so "all three projections meet" is exact.
    (0..3).all(|k| seg_seg_2d(proj(p, k), proj(q, k), proj(r, k), proj(s, k)))
}

pub(crate) fn point_on_seg(x: DVec3, p: DVec3, q: DVec3) -> bool {
    collinear3(p, q, x) && {
        let (lo, hi) = (p.min(q), p.max(q));
        x.cmpge(lo).all() && x.cmple(hi).all()
    }
}

/// Exact answer for any pair whose plane-side signs could not separate them: coplanar proper
/// triangles and every pair with a zero-area triangle.
pub(crate) fn general(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    use Shape::*;
    match (classify(a), classify(b)) {
        (Tri(ta), Tri(tb)) => {
            // Reached from the Guigue-Devillers branches only when coplanar; check to be safe.
            let s = tb.map(|x| orient3d(ta[0], ta[1], ta[2], x));
            if s.iter().all(|&v| v > 0) || s.iter().all(|&v| v < 0) {
                return false;
            }
            if s.iter().all(|&v| v == 0) {
                coplanar_tri_tri(&ta, &tb)
            } else {
                exact_all_signs(&ta, &tb)
            }
        }
        (Tri(t), Seg(p, q)) | (Seg(p, q), Tri(t)) => seg_tri(p, q, &t),
        (Tri(t), Pt(x)) | (Pt(x), Tri(t)) => point_in_tri_3d(x, &t),
        (Seg(p, q), Seg(r, s)) => seg_seg_3d(p, q, r, s),
        (Seg(p, q), Pt(x)) | (Pt(x), Seg(p, q)) => point_on_seg(x, p, q),
        (Pt(x), Pt(y)) => x == y,
    }
}

/// The Guigue-Devillers decision for two proper, non-coplanar triangles, every sign exact
/// (no float filter). Used as a safety net by [`general`].
fn exact_all_signs(ta: &[DVec3; 3], tb: &[DVec3; 3]) -> bool {
    let [p1, q1, r1] = *ta;
    let [p2, q2, r2] = *tb;
    let d1 = [p1, q1, r1].map(|x| orient3d(p2, q2, r2, x) as f64);
    let d2 = [p2, q2, r2].map(|x| orient3d(p1, q1, r1, x) as f64);
    if (d1.iter().all(|&v| v > 0.0) || d1.iter().all(|&v| v < 0.0))
        || (d2.iter().all(|&v| v > 0.0) || d2.iter().all(|&v| v < 0.0))
    {
        return false;
    }
    let check = |p1: DVec3, q1: DVec3, r1: DVec3, p2: DVec3, q2: DVec3, r2: DVec3| -> bool {
        orient3d(q1, p2, p1, q2) <= 0 && orient3d(p1, p2, r1, r2) <= 0
    };
    crate::gd_dispatch(*ta, *tb, d1, d2, check, || coplanar_tri_tri(ta, tb))
}
