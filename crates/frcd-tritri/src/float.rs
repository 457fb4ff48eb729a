//! The floating-point family: Zou (reconstructed), Möller, Guigue-Devillers, Shen, Tropp.
//!
//! All five evaluate their formulas in plain f64 and branch on the signs of the results; they are
//! fast and right on generic input, and can be wrong when a sign is within rounding of zero
//! (near-coplanar, touching, tiny or huge-offset pairs). `cargo xtask stress` counts how often.
use frcd_geom::{DVec2, DVec3};

/// Möller's absolute epsilon on plane distances (`EPSILON` in `opttritri.c`, units length³).
pub const MOLLER_EPSILON: f64 = 1e-6;
/// Shen, Heng & Tang's absolute snapping epsilon on plane distances (units length³).
pub const SHEN_EPSILON: f64 = 1e-7;

/// All three strictly positive or all strictly negative (non-short-circuit: one branch).
#[inline(always)]
fn all_same_strict(a: f64, b: f64, c: f64) -> bool {
    ((a > 0.0) & (b > 0.0) & (c > 0.0)) | ((a < 0.0) & (b < 0.0) & (c < 0.0))
}

// ---------------------------------------------------------------------------------------------
// Shared float coplanar test.

/// The two coordinates kept when projecting along the largest component of `n`.
#[inline]
fn proj_max(n: DVec3) -> (usize, usize) {
    let a = n.abs();
    if a.x > a.y && a.x > a.z {
        (1, 2)
    } else if a.y > a.z {
        (0, 2)
    } else {
        (0, 1)
    }
}

#[inline]
fn o2f(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
}

fn seg_seg_2d_float(p: DVec2, q: DVec2, r: DVec2, s: DVec2) -> bool {
    let o1 = o2f(p, q, r);
    let o2 = o2f(p, q, s);
    if o1 * o2 > 0.0 {
        return false;
    }
    let o3 = o2f(r, s, p);
    let o4 = o2f(r, s, q);
    if o3 * o4 > 0.0 {
        return false;
    }
    if o1 == 0.0 && o2 == 0.0 && o3 == 0.0 && o4 == 0.0 {
        let (a0, a1) = (p.min(q), p.max(q));
        let (b0, b1) = (r.min(s), r.max(s));
        return a0.x <= b1.x && b0.x <= a1.x && a0.y <= b1.y && b0.y <= a1.y;
    }
    true
}

fn point_in_tri_2d_float(x: DVec2, t: &[DVec2; 3]) -> bool {
    let s0 = o2f(t[0], t[1], x);
    let s1 = o2f(t[1], t[2], x);
    let s2 = o2f(t[2], t[0], x);
    (s0 >= 0.0 && s1 >= 0.0 && s2 >= 0.0) || (s0 <= 0.0 && s1 <= 0.0 && s2 <= 0.0)
}

/// Coplanar triangles in floating point: project along the largest component of `n` and test
/// the nine edge pairs and two vertex containments (as Möller's `coplanar_tri_tri` does).
pub(crate) fn coplanar_float(a: &[DVec3; 3], b: &[DVec3; 3], n: DVec3) -> bool {
    let (i, j) = proj_max(n);
    let pa = a.map(|p| DVec2::new(p[i], p[j]));
    let pb = b.map(|p| DVec2::new(p[i], p[j]));
    for x in 0..3 {
        for y in 0..3 {
            if seg_seg_2d_float(pa[x], pa[(x + 1) % 3], pb[y], pb[(y + 1) % 3]) {
                return true;
            }
        }
    }
    point_in_tri_2d_float(pa[0], &pb) || point_in_tri_2d_float(pb[0], &pa)
}

// ---------------------------------------------------------------------------------------------
// Möller 1997 / 2001 (division-free).

#[inline(always)]
fn moller_intervals(
    vv: [f64; 3],
    d: [f64; 3],
    d0d1: f64,
    d0d2: f64,
) -> Option<(f64, f64, f64, f64, f64)> {
    let [v0, v1, v2] = vv;
    let [d0, d1, d2] = d;
    Some(if d0d1 > 0.0 {
        (v2, (v0 - v2) * d2, (v1 - v2) * d2, d2 - d0, d2 - d1)
    } else if d0d2 > 0.0 {
        (v1, (v0 - v1) * d1, (v2 - v1) * d1, d1 - d0, d1 - d2)
    } else if d1 * d2 > 0.0 || d0 != 0.0 {
        (v0, (v1 - v0) * d0, (v2 - v0) * d0, d0 - d1, d0 - d2)
    } else if d1 != 0.0 {
        (v1, (v0 - v1) * d1, (v2 - v1) * d1, d1 - d0, d1 - d2)
    } else if d2 != 0.0 {
        (v2, (v0 - v2) * d2, (v1 - v2) * d2, d2 - d0, d2 - d1)
    } else {
        return None;
    })
}

#[inline(always)]
fn eps_snap(x: f64, eps: f64) -> f64 {
    if x.abs() < eps { 0.0 } else { x }
}

/// Möller's division-free interval overlap test (`NoDivTriTriIsect`, JGT 1997 / opttritri.c).
pub(crate) fn moller(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    let [v0, v1, v2] = *a;
    let [u0, u1, u2] = *b;
    let n1 = (v1 - v0).cross(v2 - v0);
    let d1 = -n1.dot(v0);
    let du0 = eps_snap(n1.dot(u0) + d1, MOLLER_EPSILON);
    let du1 = eps_snap(n1.dot(u1) + d1, MOLLER_EPSILON);
    let du2 = eps_snap(n1.dot(u2) + d1, MOLLER_EPSILON);
    let du0du1 = du0 * du1;
    let du0du2 = du0 * du2;
    if du0du1 > 0.0 && du0du2 > 0.0 {
        return false;
    }
    let n2 = (u1 - u0).cross(u2 - u0);
    let d2 = -n2.dot(u0);
    let dv0 = eps_snap(n2.dot(v0) + d2, MOLLER_EPSILON);
    let dv1 = eps_snap(n2.dot(v1) + d2, MOLLER_EPSILON);
    let dv2 = eps_snap(n2.dot(v2) + d2, MOLLER_EPSILON);
    let dv0dv1 = dv0 * dv1;
    let dv0dv2 = dv0 * dv2;
    if dv0dv1 > 0.0 && dv0dv2 > 0.0 {
        return false;
    }
    let dd = n1.cross(n2).abs();
    let index = if dd.y > dd.x {
        if dd.z > dd.y { 2 } else { 1 }
    } else if dd.z > dd.x {
        2
    } else {
        0
    };
    let vp = [v0[index], v1[index], v2[index]];
    let up = [u0[index], u1[index], u2[index]];
    let Some((a_, b_, c_, x0, x1)) = moller_intervals(vp, [dv0, dv1, dv2], dv0dv1, dv0dv2) else {
        return coplanar_float(a, b, n1);
    };
    let Some((d_, e_, f_, y0, y1)) = moller_intervals(up, [du0, du1, du2], du0du1, du0du2) else {
        return coplanar_float(a, b, n1);
    };
    let xx = x0 * x1;
    let yy = y0 * y1;
    let xxyy = xx * yy;
    let tmp = a_ * xxyy;
    let mut i1 = [tmp + b_ * x1 * yy, tmp + c_ * x0 * yy];
    let tmp = d_ * xxyy;
    let mut i2 = [tmp + e_ * xx * y1, tmp + f_ * xx * y0];
    if i1[0] > i1[1] {
        i1.swap(0, 1);
    }
    if i2[0] > i2[1] {
        i2.swap(0, 1);
    }
    !(i1[1] < i2[0] || i2[1] < i1[0])
}

// ---------------------------------------------------------------------------------------------
// Guigue-Devillers 2003, float orientation.

/// Guigue & Devillers' test with every orientation in f64 (one normal per triangle reused for
/// its three plane-side signs, as in their code).
pub(crate) fn guigue_devillers(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    let [p1, q1, r1] = *a;
    let [p2, q2, r2] = *b;
    let n2 = (p2 - r2).cross(q2 - r2);
    let dp1 = (p1 - r2).dot(n2);
    let dq1 = (q1 - r2).dot(n2);
    let dr1 = (r1 - r2).dot(n2);
    if dp1 * dq1 > 0.0 && dp1 * dr1 > 0.0 {
        return false;
    }
    let n1 = (p1 - r1).cross(q1 - r1);
    let dp2 = (p2 - r1).dot(n1);
    let dq2 = (q2 - r1).dot(n1);
    let dr2 = (r2 - r1).dot(n1);
    if dp2 * dq2 > 0.0 && dp2 * dr2 > 0.0 {
        return false;
    }
    let check = |p1: DVec3, q1: DVec3, r1: DVec3, p2: DVec3, q2: DVec3, r2: DVec3| -> bool {
        let n = (p2 - q1).cross(p1 - q1);
        if (q2 - q1).dot(n) > 0.0 {
            return false;
        }
        let n = (p2 - p1).cross(r1 - p1);
        (r2 - p1).dot(n) <= 0.0
    };
    crate::gd_dispatch(*a, *b, [dp1, dq1, dr1], [dp2, dq2, dr2], check, || {
        coplanar_float(a, b, n1)
    })
}

// ---------------------------------------------------------------------------------------------
// Shen, Heng & Tang 2003, signed distances.

/// Shen, Heng & Tang: signed vertex-plane distances (snapped to zero below [`SHEN_EPSILON`]),
/// then two signed line-line distances between the edges of each triangle that leave its lone
/// vertex: `sd(L1, L2) = (p2 - p1)·((q1 - p1) × (q2 - p2))`.
pub(crate) fn shen(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    let [p1, q1, r1] = *a;
    let [p2, q2, r2] = *b;
    let n2 = (q2 - p2).cross(r2 - p2);
    let dp1 = eps_snap((p1 - p2).dot(n2), SHEN_EPSILON);
    let dq1 = eps_snap((q1 - p2).dot(n2), SHEN_EPSILON);
    let dr1 = eps_snap((r1 - p2).dot(n2), SHEN_EPSILON);
    if all_same_strict(dp1, dq1, dr1) {
        return false;
    }
    let n1 = (q1 - p1).cross(r1 - p1);
    let dp2 = eps_snap((p2 - p1).dot(n1), SHEN_EPSILON);
    let dq2 = eps_snap((q2 - p1).dot(n1), SHEN_EPSILON);
    let dr2 = eps_snap((r2 - p1).dot(n1), SHEN_EPSILON);
    if all_same_strict(dp2, dq2, dr2) {
        return false;
    }
    let check = |p1: DVec3, q1: DVec3, r1: DVec3, p2: DVec3, q2: DVec3, r2: DVec3| -> bool {
        let w = p2 - p1;
        // Signed distance (times |d1 × d2|) between the lines (p1,q1) and (p2,q2).
        if w.dot((q1 - p1).cross(q2 - p2)) < 0.0 {
            return false;
        }
        // ... and between the lines (p1,r1) and (p2,r2).
        w.dot((r1 - p1).cross(r2 - p2)) <= 0.0
    };
    crate::gd_dispatch(*a, *b, [dp1, dq1, dr1], [dp2, dq2, dr2], check, || {
        coplanar_float(a, b, n1)
    })
}

// ---------------------------------------------------------------------------------------------
// Zou (reconstruction) and Tropp: the segment A ∩ plane(B) in B's affine frame, vs the canonical
// triangle.

/// Picks the lone vertex `l` of A with respect to plane(B) (strictly on one side, the other two
/// on the other side or on the plane); when the plane only touches A at one vertex, that vertex.
#[inline(always)]
fn lone(s: [f64; 3]) -> (usize, usize, usize) {
    let [s0, s1, s2] = s;
    if (s0 != 0.0) & (s1 != 0.0) & (s2 != 0.0) {
        // The common case: a table lookup on the sign bits.
        let (l, _) = crate::exact::lone_nonzero(s0, s1, s2);
        return (l, (l + 1) % 3, (l + 2) % 3);
    }
    if (s0 > 0.0 && s1 <= 0.0 && s2 <= 0.0) || (s0 < 0.0 && s1 >= 0.0 && s2 >= 0.0) {
        (0, 1, 2)
    } else if (s1 > 0.0 && s0 <= 0.0 && s2 <= 0.0) || (s1 < 0.0 && s0 >= 0.0 && s2 >= 0.0) {
        (1, 2, 0)
    } else if (s2 > 0.0 && s0 <= 0.0 && s1 <= 0.0) || (s2 < 0.0 && s0 >= 0.0 && s1 >= 0.0) {
        (2, 0, 1)
    } else if s0 == 0.0 {
        (0, 1, 2)
    } else if s1 == 0.0 {
        (1, 2, 0)
    } else {
        (2, 0, 1)
    }
}

/// Closed segment `[P, Q]` (homogeneous 2D points, `w > 0`) against the canonical triangle
/// `α ≥ 0, β ≥ 0, α + β ≤ 1`: the four-axis separating test of seed-algorithms §1 step 4.
#[inline(always)]
fn seg_vs_canonical(p: DVec3, q: DVec3) -> bool {
    let p3 = p.z - p.x - p.y;
    let q3 = q.z - q.x - q.y;
    // (a) both endpoints outside one edge of the triangle.
    if ((p.x < 0.0) & (q.x < 0.0)) | ((p.y < 0.0) & (q.y < 0.0)) | ((p3 < 0.0) & (q3 < 0.0)) {
        return false;
    }
    // (b) an endpoint inside.
    if ((p.x >= 0.0) & (p.y >= 0.0) & (p3 >= 0.0)) | ((q.x >= 0.0) & (q.y >= 0.0) & (q3 >= 0.0)) {
        return true;
    }
    // (c) the three corners strictly on one side of the line PQ (one 2D cross product).
    let l = p.cross(q);
    let c0 = l.z;
    let c1 = l.x + l.z;
    let c2 = l.y + l.z;
    !all_same_strict(c0, c1, c2)
}

/// Zou et al. 2008 as reconstructed in seed-algorithms.md §1.
pub(crate) fn zou(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    let [a0, a1, a2] = *a;
    let [b0, b1, b2] = *b;
    // Step 1: plane of B, by linear dependence of A's edges.
    let f1 = b1 - b0;
    let f2 = b2 - b0;
    let nb = f1.cross(f2);
    let e1 = a1 - a0;
    let e2 = a2 - a0;
    let g = a0 - b0;
    let s0 = nb.dot(g);
    let s1 = s0 + nb.dot(e1);
    let s2 = s0 + nb.dot(e2);
    if all_same_strict(s0, s1, s2) {
        return false;
    }
    // Step 2: plane of A, reusing e1, e2.
    let na = e1.cross(e2);
    let t0 = -na.dot(g);
    let t1 = t0 + na.dot(f1);
    let t2 = t0 + na.dot(f2);
    if all_same_strict(t0, t1, t2) {
        return false;
    }
    if s0 == 0.0 && s1 == 0.0 && s2 == 0.0 {
        return coplanar_float(a, b, na);
    }
    // Step 3: drop the largest component k of nB; 2D affine coordinates in B's frame, kept as
    // numerators over nB_k (the 2×2 denominator is that normal component).
    let an = nb.abs();
    let k = if an.x > an.y {
        if an.x > an.z { 0 } else { 2 }
    } else if an.y > an.z {
        1
    } else {
        2
    };
    let (i, j) = ((k + 1) % 3, (k + 2) % 3);
    let nbk = nb[k];
    let alpha = |v: DVec3| v[i] * f2[j] - v[j] * f2[i];
    let beta = |v: DVec3| f1[i] * v[j] - f1[j] * v[i];
    let al0 = alpha(g);
    let be0 = beta(g);
    let al = [al0, al0 + alpha(e1), al0 + alpha(e2)];
    let be = [be0, be0 + beta(e1), be0 + beta(e2)];
    let s = [s0, s1, s2];
    let (l, m, n) = lone(s);
    // Crossing points as homogeneous (α·w, β·w, w), w = nB_k (s_l - s_m), made positive.
    let cross = |m: usize| {
        let w = nbk * (s[l] - s[m]);
        let v = DVec3::new(s[l] * al[m] - s[m] * al[l], s[l] * be[m] - s[m] * be[l], w);
        if w < 0.0 { -v } else { v }
    };
    // Step 4.
    seg_vs_canonical(cross(m), cross(n))
}

/// Tropp, Tal & Shimshoni 2006: Cramer's rule for `α1 f1 + α2 f2 − β e = a_l − b0` on the two
/// edges of A that leave its lone vertex, sharing the cofactors `r × f2` and `f1 × r`.
pub(crate) fn tropp(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    let [b0, b1, b2] = *b;
    let f1 = b1 - b0;
    let f2 = b2 - b0;
    let nb = f1.cross(f2);
    let s = a.map(|x| nb.dot(x - b0));
    if all_same_strict(s[0], s[1], s[2]) {
        return false;
    }
    if s[0] == 0.0 && s[1] == 0.0 && s[2] == 0.0 {
        return coplanar_float(a, b, nb);
    }
    let (l, m, n) = lone(s);
    let r = a[l] - b0;
    let c1 = r.cross(f2);
    let c2 = f1.cross(r);
    // det[f1, f2, -e] = s_l - s_m; numerators det[r, f2, -e] = -e·c1, det[f1, r, -e] = -e·c2.
    let edge = |m: usize| {
        let e = a[m] - a[l];
        let w = s[l] - s[m];
        let v = DVec3::new(-e.dot(c1), -e.dot(c2), w);
        if w < 0.0 { -v } else { v }
    };
    seg_vs_canonical(edge(m), edge(n))
}
