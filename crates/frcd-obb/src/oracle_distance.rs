//! Brute-force distance oracle: every triangle pair, no tree.
//!
//! Independent of [`crate::distance`] on purpose: its point-triangle code is Ericson's
//! Voronoi-region walk (Real-Time Collision Detection §5.1.5), its segment-segment code
//! minimises over the four endpoint-segment distances and the lines' common perpendicular, and
//! the exact label [`within_exact`] computes exact squared distances in rationals
//! (`num_rational::BigRational`). It shares with the tree query only the way B is mapped into
//! A's frame ([`RelativeFrame`]) and the exact intersection test of `frcd-tritri`.
//!
//! ```
//! use frcd_obb::oracle;
//! use frcd_geom::{shapes, DVec3, Pose};
//! let a = shapes::cuboid(DVec3::splat(0.5));
//! let pb = Pose::from_translation(DVec3::new(2.0, 0.0, 0.0));
//! let d = oracle::distance(&a, &Pose::IDENTITY, &a, &pb);
//! assert!((d.distance - 1.0).abs() < 1e-15);
//! assert!(oracle::within_exact(&a, &Pose::IDENTITY, &a, &pb, 1.0));
//! assert!(!oracle::within_exact(&a, &Pose::IDENTITY, &a, &pb, 0.9999999999999999));
//! ```

use crate::query::RelativeFrame;
use frcd_geom::{DVec3, Pose, TriMesh, Triangle};
use num_bigint::BigInt;
use num_rational::BigRational;
use num_traits::{One, Signed, Zero};

/// The oracle's distance answer (points in world coordinates, as [`crate::distance::Distance`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OracleDistance {
    /// Smallest distance over all triangle pairs (0 when some pair intersects).
    pub distance: f64,
    /// The pair it was found on (the first in `(tri_a, tri_b)` order on ties).
    pub triangles: (u32, u32),
    /// Closest points in world coordinates (on A, on B).
    pub points: [DVec3; 2],
}

/// Closest point of triangle `abc` to `p` (Ericson's Voronoi-region walk).
pub fn closest_point_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return a + ab * v;
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return a + ac * w;
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return b + (c - b) * w;
    }
    let denom = va + vb + vc;
    if denom == 0.0 || !denom.is_finite() {
        // Degenerate triangle: the nearest of its edges.
        let cands = [
            closest_point_on_segment(p, a, b),
            closest_point_on_segment(p, b, c),
            closest_point_on_segment(p, c, a),
        ];
        return cands
            .into_iter()
            .min_by(|x, y| x.distance_squared(p).total_cmp(&y.distance_squared(p)))
            .expect("three");
    }
    let v = vb / denom;
    let w = vc / denom;
    a + ab * v + ac * w
}

/// Closest point of segment `[a, b]` to `p`.
pub fn closest_point_on_segment(p: DVec3, a: DVec3, b: DVec3) -> DVec3 {
    let d = b - a;
    let dd = d.dot(d);
    if dd == 0.0 {
        return a;
    }
    let s = ((p - a).dot(d) / dd).clamp(0.0, 1.0);
    a + d * s
}

/// Closest points of two segments: the best of the four endpoint-segment pairs and, when the
/// lines' common perpendicular has both feet inside the segments, that perpendicular.
pub fn closest_points_segments(p1: DVec3, q1: DVec3, p2: DVec3, q2: DVec3) -> (DVec3, DVec3) {
    let mut best = (p1, closest_point_on_segment(p1, p2, q2));
    let mut consider = |x: DVec3, y: DVec3| {
        if x.distance_squared(y) < best.0.distance_squared(best.1) {
            best = (x, y);
        }
    };
    consider(q1, closest_point_on_segment(q1, p2, q2));
    consider(closest_point_on_segment(p2, p1, q1), p2);
    consider(closest_point_on_segment(q2, p1, q1), q2);
    let d1 = q1 - p1;
    let d2 = q2 - p2;
    let r = p2 - p1;
    // Solve [d1·d1, -d1·d2; d1·d2, -d2·d2] [s; t] = [d1·r; d2·r] by Cramer's rule.
    let (a11, a12, a21, a22) = (d1.dot(d1), -d1.dot(d2), d1.dot(d2), -d2.dot(d2));
    let (b1, b2) = (d1.dot(r), d2.dot(r));
    let det = a11 * a22 - a12 * a21;
    if det != 0.0 && det.is_finite() {
        let s = (b1 * a22 - a12 * b2) / det;
        let t = (a11 * b2 - a21 * b1) / det;
        if (0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&t) {
            consider(p1 + d1 * s, p2 + d2 * t);
        }
    }
    best
}

/// Closest points of two triangles (same frame): 0 and a common point when they intersect
/// (exact test), else the best of the 6 vertex-triangle and 9 edge-edge pairs.
pub fn closest_points_triangles(a: &Triangle, b: &Triangle) -> (f64, DVec3, DVec3) {
    if frcd_tritri::exact(a, b) {
        let p = match frcd_tritri::intersection_segment(a, b) {
            Some(frcd_tritri::Contact::Point(p)) => p,
            Some(frcd_tritri::Contact::Segment(p, _)) => p,
            Some(frcd_tritri::Contact::Polygon(ps)) if !ps.is_empty() => ps[0],
            _ => a.v[0],
        };
        return (0.0, p, p);
    }
    let mut best = (f64::INFINITY, a.v[0], b.v[0]);
    let mut consider = |x: DVec3, y: DVec3| {
        let d = x.distance(y);
        if d < best.0 {
            best = (d, x, y);
        }
    };
    for &p in &a.v {
        consider(p, closest_point_on_triangle(p, b.v[0], b.v[1], b.v[2]));
    }
    for &p in &b.v {
        consider(closest_point_on_triangle(p, a.v[0], a.v[1], a.v[2]), p);
    }
    for i in 0..3 {
        for j in 0..3 {
            let (x, y) =
                closest_points_segments(a.v[i], a.v[(i + 1) % 3], b.v[j], b.v[(j + 1) % 3]);
            consider(x, y);
        }
    }
    best
}

/// Distance between two meshes at two poses, every triangle pair evaluated (B mapped into A's
/// frame as in [`crate::collide`]). `O(n_a · n_b)`: for tests and `cargo xtask verify`.
pub fn distance(a: &TriMesh, pose_a: &Pose, b: &TriMesh, pose_b: &Pose) -> OracleDistance {
    let frame = RelativeFrame::new(pose_a, pose_b);
    let ta: Vec<Triangle> = a.triangles().collect();
    let tb: Vec<Triangle> = b.triangles().map(|t| frame.triangle(&t)).collect();
    let mut best = (f64::INFINITY, (0u32, 0u32), DVec3::NAN, DVec3::NAN);
    'outer: for (i, x) in ta.iter().enumerate() {
        for (j, y) in tb.iter().enumerate() {
            let (d, p, q) = closest_points_triangles(x, y);
            if d < best.0 {
                best = (d, (i as u32, j as u32), p, q);
                if d == 0.0 {
                    break 'outer;
                }
            }
        }
    }
    OracleDistance {
        distance: best.0,
        triangles: best.1,
        points: [
            pose_a.transform_point(best.2),
            pose_a.transform_point(best.3),
        ],
    }
}

// --- Exact labels ---------------------------------------------------------------------------

type Q = BigRational;

fn q(x: f64) -> Q {
    Q::from_float(x).unwrap_or_else(Q::zero)
}

#[derive(Clone)]
struct QV([Q; 3]);

impl QV {
    fn of(p: DVec3) -> Self {
        QV([q(p.x), q(p.y), q(p.z)])
    }
    fn sub(&self, o: &QV) -> QV {
        QV([
            &self.0[0] - &o.0[0],
            &self.0[1] - &o.0[1],
            &self.0[2] - &o.0[2],
        ])
    }
    fn add_scaled(&self, d: &QV, s: &Q) -> QV {
        QV([
            &self.0[0] + &d.0[0] * s,
            &self.0[1] + &d.0[1] * s,
            &self.0[2] + &d.0[2] * s,
        ])
    }
    fn dot(&self, o: &QV) -> Q {
        &self.0[0] * &o.0[0] + &self.0[1] * &o.0[1] + &self.0[2] * &o.0[2]
    }
    fn norm2(&self) -> Q {
        self.dot(self)
    }
}

fn clamp01(x: Q) -> Q {
    if x.is_negative() {
        Q::zero()
    } else if x > Q::one() {
        Q::one()
    } else {
        x
    }
}

/// Exact squared distance from `p` to segment `[a, b]`.
fn q_point_segment(p: &QV, a: &QV, b: &QV) -> Q {
    let d = b.sub(a);
    let dd = d.norm2();
    if dd.is_zero() {
        return p.sub(a).norm2();
    }
    let s = clamp01(p.sub(a).dot(&d) / &dd);
    p.sub(&a.add_scaled(&d, &s)).norm2()
}

/// Exact squared distance from `p` to the closed triangle `t`: the plane projection when it
/// lies inside (barycentric coordinates, exact), else the nearest edge.
fn q_point_triangle(p: &QV, t: &[QV; 3]) -> Q {
    let e = [
        q_point_segment(p, &t[0], &t[1]),
        q_point_segment(p, &t[1], &t[2]),
        q_point_segment(p, &t[2], &t[0]),
    ];
    let mut best = e.into_iter().min().expect("three");
    // Solve the 2x2 normal equations for the projection's barycentric coordinates.
    let u = t[1].sub(&t[0]);
    let v = t[2].sub(&t[0]);
    let w = p.sub(&t[0]);
    let (uu, uv, vv) = (u.norm2(), u.dot(&v), v.norm2());
    let (wu, wv) = (w.dot(&u), w.dot(&v));
    let det = &uu * &vv - &uv * &uv;
    if !det.is_zero() {
        let s = (&vv * &wu - &uv * &wv) / &det;
        let r = (&uu * &wv - &uv * &wu) / &det;
        if !s.is_negative() && !r.is_negative() && &s + &r <= Q::one() {
            let foot = t[0].add_scaled(&u, &s).add_scaled(&v, &r);
            let d = p.sub(&foot).norm2();
            if d < best {
                best = d;
            }
        }
    }
    best
}

/// Exact squared distance between two segments (exact clamped minimisation: the interior
/// stationary point when it lies in the unit square, else the best endpoint-segment pair).
fn q_segment_segment(p1: &QV, q1: &QV, p2: &QV, q2: &QV) -> Q {
    let mut best = [
        q_point_segment(p1, p2, q2),
        q_point_segment(q1, p2, q2),
        q_point_segment(p2, p1, q1),
        q_point_segment(q2, p1, q1),
    ]
    .into_iter()
    .min()
    .expect("four");
    let d1 = q1.sub(p1);
    let d2 = q2.sub(p2);
    let r = p1.sub(p2);
    let (a, b, c) = (d1.norm2(), d1.dot(&d2), d2.norm2());
    let (d, e) = (d1.dot(&r), d2.dot(&r));
    let den = &a * &c - &b * &b;
    if den.is_positive() {
        let s = (&b * &e - &c * &d) / &den;
        let t = (&a * &e - &b * &d) / &den;
        let unit = |x: &Q| !x.is_negative() && *x <= Q::one();
        if unit(&s) && unit(&t) {
            let x = p1.add_scaled(&d1, &s);
            let y = p2.add_scaled(&d2, &t);
            let dist = x.sub(&y).norm2();
            if dist < best {
                best = dist;
            }
        }
    }
    best
}

/// Exact squared distance between two non-intersecting triangles' features (the intersection
/// is decided separately).
fn q_triangle_features(a: &[QV; 3], b: &[QV; 3]) -> Q {
    let mut best: Option<Q> = None;
    let mut take = |d: Q| {
        if best.as_ref().is_none_or(|b| d < *b) {
            best = Some(d);
        }
    };
    for p in a {
        take(q_point_triangle(p, b));
    }
    for p in b {
        take(q_point_triangle(p, a));
    }
    for i in 0..3 {
        for j in 0..3 {
            take(q_segment_segment(
                &a[i],
                &a[(i + 1) % 3],
                &b[j],
                &b[(j + 1) % 3],
            ));
        }
    }
    best.expect("fifteen")
}

/// Exact label: are two triangles (same frame) within `tol` of each other? Rationals throughout.
pub fn triangles_within_exact(a: &Triangle, b: &Triangle, tol: f64) -> bool {
    if tol.is_nan() || tol < 0.0 {
        return false;
    }
    if frcd_tritri::exact(a, b) {
        return true;
    }
    if tol == f64::INFINITY {
        return true;
    }
    let qa = a.v.map(QV::of);
    let qb = b.v.map(QV::of);
    let t = q(tol);
    q_triangle_features(&qa, &qb) <= &t * &t
}

/// Exact squared distance of two triangles (same frame) as a rational, 0 when they intersect.
pub fn triangles_distance2_exact(a: &Triangle, b: &Triangle) -> BigRational {
    if frcd_tritri::exact(a, b) {
        return Q::zero();
    }
    q_triangle_features(&a.v.map(QV::of), &b.v.map(QV::of))
}

/// Exact label for [`crate::distance::within`]: every triangle pair (B mapped into A's frame as
/// the tree query does), a float prefilter that only skips pairs whose float distance exceeds
/// `tol` by a wide margin (`1e-6` relative to the pair's size), and [`triangles_within_exact`]
/// on the rest. Slow; for tests, verify and stress.
pub fn within_exact(a: &TriMesh, pose_a: &Pose, b: &TriMesh, pose_b: &Pose, tol: f64) -> bool {
    if tol.is_nan() || tol < 0.0 {
        return false;
    }
    let frame = RelativeFrame::new(pose_a, pose_b);
    let ta: Vec<Triangle> = a.triangles().collect();
    let tb: Vec<Triangle> = b.triangles().map(|t| frame.triangle(&t)).collect();
    for x in &ta {
        for y in &tb {
            let (d, _, _) = closest_points_triangles(x, y);
            let size =
                x.v.iter()
                    .chain(y.v.iter())
                    .map(|p| p.abs().max_element())
                    .fold(0.0, f64::max);
            // Float distances are off by far less than 1e-6 of the coordinates' size.
            if d > tol + 1e-6 * size {
                continue;
            }
            if triangles_within_exact(x, y, tol) {
                return true;
            }
        }
    }
    false
}

/// Exact squared distance of two meshes as a rational (every pair exactly): for small tests.
pub fn distance2_exact(a: &TriMesh, pose_a: &Pose, b: &TriMesh, pose_b: &Pose) -> BigRational {
    let frame = RelativeFrame::new(pose_a, pose_b);
    let ta: Vec<Triangle> = a.triangles().collect();
    let tb: Vec<Triangle> = b.triangles().map(|t| frame.triangle(&t)).collect();
    let mut best: Option<Q> = None;
    for x in &ta {
        for y in &tb {
            let d = triangles_distance2_exact(x, y);
            if best.as_ref().is_none_or(|b| d < *b) {
                best = Some(d);
            }
        }
    }
    best.unwrap_or_else(|| Q::from_integer(BigInt::from(-1)))
}
