//! Closest points of two triangles in floating point (the leaf work of [`crate::distance`]).
//!
//! Two closed triangles that do not intersect have their closest pair among the 9 edge pairs
//! (each edge pair's closest points, endpoints included) and the 6 vertex-face pairs whose
//! projection falls inside the face; triangles that intersect are at distance 0 (decided by the
//! exact tri-tri test, so a crossing pair is never reported at a positive distance).
//!
//! Every candidate is a pair of points computed as affine combinations of the triangles'
//! vertices with parameters clamped to the triangles, so each candidate's length is the
//! distance of two points within a few ulps of the triangles: the minimum can only be larger
//! than the true distance by the error of the winning candidate (see [`crate::distance`] for
//! the bound).

use frcd_geom::DVec3;

/// Closest points of two segments `[p1, q1]`, `[p2, q2]` (Ericson, Real-Time Collision Detection
/// §5.1.9, with the denominator taken as `|d1 × d2|²`, which keeps its precision when the
/// segments are nearly parallel). Returns `(squared distance, point on 1, point on 2)`.
#[inline]
pub(crate) fn segment_segment(p1: DVec3, q1: DVec3, p2: DVec3, q2: DVec3) -> (f64, DVec3, DVec3) {
    let d1 = q1 - p1;
    let d2 = q2 - p2;
    let r = p1 - p2;
    let a = d1.dot(d1);
    let e = d2.dot(d2);
    let f = d2.dot(r);
    let (s, t);
    if a == 0.0 && e == 0.0 {
        s = 0.0;
        t = 0.0;
    } else if a == 0.0 {
        s = 0.0;
        t = (f / e).clamp(0.0, 1.0);
    } else {
        let c = d1.dot(r);
        if e == 0.0 {
            t = 0.0;
            s = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = d1.dot(d2);
            let denom = d1.cross(d2).length_squared();
            let s0 = if denom > 0.0 {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let t0 = (b * s0 + f) / e;
            if t0 < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t0 > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            } else {
                t = t0;
                s = s0;
            }
        }
    }
    let c1 = p1 + d1 * s;
    let c2 = p2 + d2 * t;
    ((c1 - c2).length_squared(), c1, c2)
}

/// The face part of a vertex-face test: when the projection of `p` onto the plane of `t`
/// lies in the closed triangle, `Some((squared distance, foot))`. Degenerate (zero-area)
/// triangles return `None`: they are the union of their edges, which the edge pairs cover.
#[inline]
fn point_face(p: DVec3, t: &[DVec3; 3], n: DVec3, nn: f64) -> Option<(f64, DVec3)> {
    if nn.is_nan() || nn <= 0.0 {
        return None;
    }
    let [a, b, c] = *t;
    if (b - a).cross(p - a).dot(n) < 0.0
        || (c - b).cross(p - b).dot(n) < 0.0
        || (a - c).cross(p - c).dot(n) < 0.0
    {
        return None;
    }
    let h = (p - a).dot(n);
    let d2 = h * h / nn;
    Some((d2, p - n * (h / nn)))
}

/// Closest points of two triangles (both in the same frame), ignoring intersection: the minimum
/// over the 9 edge pairs and the 6 vertex-face projections. Returns
/// `(squared distance, point on a, point on b)`. The caller decides intersection separately.
pub(crate) fn triangle_features(a: &[DVec3; 3], b: &[DVec3; 3]) -> (f64, DVec3, DVec3) {
    let mut best = (f64::INFINITY, a[0], b[0]);
    for i in 0..3 {
        let (p1, q1) = (a[i], a[(i + 1) % 3]);
        for j in 0..3 {
            let r = segment_segment(p1, q1, b[j], b[(j + 1) % 3]);
            if r.0 < best.0 {
                best = r;
            }
        }
    }
    let na = (a[1] - a[0]).cross(a[2] - a[0]);
    let nna = na.length_squared();
    for &p in b {
        if let Some((d2, foot)) = point_face(p, a, na, nna)
            && d2 < best.0
        {
            best = (d2, foot, p);
        }
    }
    let nb = (b[1] - b[0]).cross(b[2] - b[0]);
    let nnb = nb.length_squared();
    for &p in a {
        if let Some((d2, foot)) = point_face(p, b, nb, nnb)
            && d2 < best.0
        {
            best = (d2, p, foot);
        }
    }
    best
}

/// [`triangle_features`] with an early exit (PQP's `TriDist` idea): as soon as a candidate
/// improves, it is returned when the slab between the planes through its two points, square to
/// their difference `v`, separates the triangles (every vertex of `a` at most `tol` beyond
/// the plane through the point on `a`, every vertex of `b` at most `tol` before the other
/// plane): then no pair of points is closer than `|v| - 2 tol` less the rounding of those
/// few dot products, so the candidate is the minimum to within that (the vertex-face
/// candidates come first: cheaper, and the usual answer between fine meshes). Checking all
/// six vertices (not only the two off the edges, as PQP does) keeps the exit sound however
/// the candidate was computed (nearly parallel edges included). Returns
/// `(squared distance, point on a, point on b)`.
pub(crate) fn triangle_features_early(
    a: &[DVec3; 3],
    b: &[DVec3; 3],
    tol: f64,
) -> (f64, DVec3, DVec3) {
    let separated = |c1: DVec3, c2: DVec3| {
        let v = c2 - c1;
        let lim = tol * v.length();
        a.iter().all(|&x| v.dot(x - c1) <= lim) && b.iter().all(|&y| v.dot(y - c2) >= -lim)
    };
    let mut best = (f64::INFINITY, a[0], b[0]);
    let na = (a[1] - a[0]).cross(a[2] - a[0]);
    let nna = na.length_squared();
    for &p in b {
        if let Some((d2, foot)) = point_face(p, a, na, nna)
            && d2 < best.0
        {
            best = (d2, foot, p);
            if d2 == 0.0 || separated(foot, p) {
                return best;
            }
        }
    }
    let nb = (b[1] - b[0]).cross(b[2] - b[0]);
    let nnb = nb.length_squared();
    for &p in a {
        if let Some((d2, foot)) = point_face(p, b, nb, nnb)
            && d2 < best.0
        {
            best = (d2, p, foot);
            if d2 == 0.0 || separated(p, foot) {
                return best;
            }
        }
    }
    for i in 0..3 {
        let (p1, q1) = (a[i], a[(i + 1) % 3]);
        for j in 0..3 {
            let r = segment_segment(p1, q1, b[j], b[(j + 1) % 3]);
            if r.0 < best.0 {
                best = r;
                if r.0 == 0.0 || separated(r.1, r.2) {
                    return best;
                }
            }
        }
    }
    best
}

/// Closest points of two triangles: `(distance, point on a, point on b)`; distance 0 with a point
/// of the intersection when they intersect (exact test).
/// `tol` as in [`triangle_features_early`].
pub(crate) fn triangle_distance(a: &[DVec3; 3], b: &[DVec3; 3], tol: f64) -> (f64, DVec3, DVec3) {
    let ta = frcd_geom::Triangle { v: *a };
    let tb = frcd_geom::Triangle { v: *b };
    if frcd_tritri::exact(&ta, &tb) {
        let p = contact_point(&ta, &tb);
        return (0.0, p, p);
    }
    let (d2, pa, pb) = triangle_features_early(a, b, tol);
    (d2.sqrt(), pa, pb)
}

/// A point where two intersecting triangles meet.
pub(crate) fn contact_point(a: &frcd_geom::Triangle, b: &frcd_geom::Triangle) -> DVec3 {
    match frcd_tritri::intersection_segment(a, b) {
        Some(frcd_tritri::Contact::Point(p)) => p,
        Some(frcd_tritri::Contact::Segment(p, q)) => (p + q) * 0.5,
        Some(frcd_tritri::Contact::Polygon(ps)) if !ps.is_empty() => ps[0],
        // The exact test said they meet: the closest feature pair is (within rounding) a
        // common point.
        _ => {
            let (_, pa, pb) = triangle_features(&a.v, &b.v);
            (pa + pb) * 0.5
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The early exit returns one of the full test's candidates (so never less than the full
    /// minimum) and, when it exits, one within its slab allowance of that minimum.
    #[test]
    fn early_exit_agrees_with_every_candidate() {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut r = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let tol = 4.0 * f64::EPSILON * 0.5 * 8.0;
        let mut exits = 0;
        for k in 0..20_000 {
            let a = [0; 3].map(|_| DVec3::new(r(), r(), r()));
            let off = DVec3::new(r(), r(), r()) * (1.0 + (k % 5) as f64);
            // Every fifth pair nearly parallel (edges and faces), where candidates are
            // ill-conditioned.
            let b = if k % 5 == 0 {
                a.map(|p| p + off * 1e-3 + DVec3::new(r(), r(), r()) * 1e-9)
            } else {
                [0; 3].map(|_| DVec3::new(r(), r(), r()) + off)
            };
            let full = triangle_features(&a, &b);
            let early = triangle_features_early(&a, &b, tol);
            assert!(early.0 >= full.0, "pair {k}: {} < {}", early.0, full.0);
            let (de, df) = (early.0.sqrt(), full.0.sqrt());
            assert!(de - df <= 1e-12, "pair {k}: early {de} vs full {df}");
            exits += usize::from(early.0 > full.0);
        }
        // Exits that picked a different (equally close) candidate are allowed; most agree.
        assert!(exits < 2_000, "{exits}");
    }
}
