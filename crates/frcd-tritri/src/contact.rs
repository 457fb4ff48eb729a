//! The contact between two intersecting triangles: topology decided with exact predicates,
//! coordinates constructed in f64.
use crate::Triangle;
use crate::exact::{self, Shape, classify, drop_axis, point_in_tri_3d, point_on_seg, proj};
use frcd_geom::predicates::{collinear3, orient3d};
use frcd_geom::{DVec2, DVec3};

/// Where two closed triangles meet.
#[derive(Clone, Debug, PartialEq)]
pub enum Contact {
    /// They touch in a single point.
    Point(DVec3),
    /// They meet along a segment (the usual transversal case, or an edge lying in the other face).
    Segment(DVec3, DVec3),
    /// Coplanar overlap with positive area: the convex overlap polygon, in order.
    Polygon(Vec<DVec3>),
}

/// The contact of two triangles, or `None` when [`crate::exact`] says they are disjoint.
///
/// Which case applies (disjoint, point, segment, polygon; which vertices lie on which plane,
/// which edges cross it) is decided with exact predicates, so the topology is right for every
/// finite input. Coordinates are then constructed in f64: crossing points of edges with a plane
/// by linear interpolation of the (float) plane distances, the overlap of the two cuts along the
/// line `nA × nB` by float projections, and the coplanar polygon by clipping one triangle against
/// the other's edges (Sutherland-Hodgman in the exact drop-axis projection). Constructed points
/// are therefore off by rounding (relative to the pair's size; more for near-parallel planes), and
/// in a near-degenerate touching configuration a contact the exact test reports may come back as
/// a single point where the exact contact is a very short segment. Vertices that lie exactly on
/// the other triangle are returned unchanged.
///
/// ```
/// use frcd_tritri::{intersection_segment, Contact, Triangle};
/// use frcd_geom::DVec3;
/// let a = Triangle::new(DVec3::new(-1.0, -1.0, 0.0), DVec3::new(3.0, -1.0, 0.0), DVec3::new(-1.0, 3.0, 0.0));
/// let b = Triangle::new(DVec3::new(0.0, 0.0, -1.0), DVec3::new(0.0, 0.0, 1.0), DVec3::new(1.0, 0.0, 1.0));
/// match intersection_segment(&a, &b) {
///     Some(Contact::Segment(p, q)) => assert!((p - q).length() > 0.4),
///     other => panic!("{other:?}"),
/// }
/// ```
pub fn intersection_segment(a: &Triangle, b: &Triangle) -> Option<Contact> {
    if !exact::exact(&a.v, &b.v) {
        return None;
    }
    use Shape::*;
    Some(match (classify(&a.v), classify(&b.v)) {
        (Tri(ta), Tri(tb)) => tri_tri(&ta, &tb),
        (Tri(t), Seg(p, q)) | (Seg(p, q), Tri(t)) => seg_tri(p, q, &t),
        (Seg(p, q), Seg(r, s)) => seg_seg(p, q, r, s),
        (_, Pt(x)) | (Pt(x), _) => Contact::Point(x),
    })
}

fn from_points(mut pts: Vec<DVec3>) -> Contact {
    pts.dedup();
    while pts.len() > 1 && pts.first() == pts.last() {
        pts.pop();
    }
    match pts.len() {
        0 => unreachable!("callers pass at least one point"),
        1 => Contact::Point(pts[0]),
        2 => Contact::Segment(pts[0], pts[1]),
        _ => Contact::Polygon(pts),
    }
}

/// Points where the triangle `t` meets the plane with float distances `v` and exact signs `s`.
fn plane_cut(t: &[DVec3; 3], s: [i8; 3], v: [f64; 3]) -> Vec<DVec3> {
    let mut out = Vec::with_capacity(3);
    for i in 0..3 {
        let j = (i + 1) % 3;
        if s[i] == 0 {
            out.push(t[i]);
        }
        if s[i] * s[j] < 0 {
            let den = v[i] - v[j];
            let u = if den != 0.0 {
                (v[i] / den).clamp(0.0, 1.0)
            } else {
                0.5
            };
            out.push(t[i] + (t[j] - t[i]) * u);
        }
    }
    out
}

/// Overlap of two point sets lying on one line (each one or two points), along `dir`.
fn overlap_on_line(sa: &[DVec3], sb: &[DVec3], dir: DVec3) -> Contact {
    let key = |p: &DVec3| dir.dot(*p);
    let ends = |s: &[DVec3]| {
        let lo = *s
            .iter()
            .min_by(|x, y| key(x).total_cmp(&key(y)))
            .expect("non-empty");
        let hi = *s
            .iter()
            .max_by(|x, y| key(x).total_cmp(&key(y)))
            .expect("non-empty");
        (lo, hi)
    };
    let (alo, ahi) = ends(sa);
    let (blo, bhi) = ends(sb);
    let lo = if key(&alo) >= key(&blo) { alo } else { blo };
    let hi = if key(&ahi) <= key(&bhi) { ahi } else { bhi };
    if key(&lo) >= key(&hi) {
        // Touching (or rounding made the overlap empty although the exact test says they meet).
        Contact::Point(if key(&lo) == key(&hi) {
            lo
        } else {
            (lo + hi) * 0.5
        })
    } else {
        Contact::Segment(lo, hi)
    }
}

fn tri_tri(ta: &[DVec3; 3], tb: &[DVec3; 3]) -> Contact {
    let sa = ta.map(|x| orient3d(tb[0], tb[1], tb[2], x));
    if sa == [0, 0, 0] {
        return coplanar(ta, tb);
    }
    let sb = tb.map(|x| orient3d(ta[0], ta[1], ta[2], x));
    let n1 = (ta[1] - ta[0]).cross(ta[2] - ta[0]);
    let n2 = (tb[1] - tb[0]).cross(tb[2] - tb[0]);
    let va = ta.map(|x| n2.dot(x - tb[0]));
    let vb = tb.map(|x| n1.dot(x - ta[0]));
    let cut_a = plane_cut(ta, sa, va);
    let cut_b = plane_cut(tb, sb, vb);
    let mut dir = n1.cross(n2);
    if dir == DVec3::ZERO {
        dir = [&cut_a, &cut_b]
            .iter()
            .filter(|c| c.len() > 1)
            .map(|c| c[c.len() - 1] - c[0])
            .find(|d| *d != DVec3::ZERO)
            .unwrap_or(DVec3::X);
    }
    overlap_on_line(&cut_a, &cut_b, dir)
}

/// Coplanar proper triangles: clip A by B's edges in the projection that keeps B's area.
fn coplanar(ta: &[DVec3; 3], tb: &[DVec3; 3]) -> Contact {
    let (k, ob) = drop_axis(tb);
    let o = ob as f64;
    let pb = tb.map(|p| proj(p, k));
    let mut poly: Vec<DVec3> = ta.to_vec();
    for e in 0..3 {
        let (u, w) = (pb[e], pb[(e + 1) % 3]);
        let f = |x: DVec3| o * (w - u).perp_dot(proj(x, k) - u);
        let mut out = Vec::with_capacity(poly.len() + 1);
        for i in 0..poly.len() {
            let (x, y) = (poly[i], poly[(i + 1) % poly.len()]);
            let (fx, fy) = (f(x), f(y));
            if fx >= 0.0 {
                out.push(x);
            }
            if (fx >= 0.0) != (fy >= 0.0) {
                let u = (fx / (fx - fy)).clamp(0.0, 1.0);
                out.push(x + (y - x) * u);
            }
        }
        poly = out;
        if poly.is_empty() {
            break;
        }
    }
    if poly.is_empty() {
        return Contact::Point(touch_point_coplanar(ta, tb));
    }
    from_points(poly)
}

/// A point common to two coplanar triangles that only touch (used when float clipping lost it).
fn touch_point_coplanar(ta: &[DVec3; 3], tb: &[DVec3; 3]) -> DVec3 {
    for &x in ta {
        if point_in_tri_3d(x, tb) {
            return x;
        }
    }
    for &x in tb {
        if point_in_tri_3d(x, ta) {
            return x;
        }
    }
    for i in 0..3 {
        for j in 0..3 {
            let (p, q) = (ta[i], ta[(i + 1) % 3]);
            let (r, s) = (tb[j], tb[(j + 1) % 3]);
            if exact::general(&[p, q, q], &[r, s, s])
                && let Contact::Point(x) = seg_seg(p, q, r, s)
            {
                return x;
            }
        }
    }
    ta[0]
}

fn seg_tri(p: DVec3, q: DVec3, t: &[DVec3; 3]) -> Contact {
    let sp = orient3d(t[0], t[1], t[2], p);
    let sq = orient3d(t[0], t[1], t[2], q);
    if sp == 0 && sq == 0 {
        let (k, o) = drop_axis(t);
        let o = o as f64;
        let pt = t.map(|v| proj(v, k));
        let (pp, pq) = (proj(p, k), proj(q, k));
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for e in 0..3 {
            let (u, w) = (pt[e], pt[(e + 1) % 3]);
            let f = |x: DVec2| o * (w - u).perp_dot(x - u);
            let (f0, f1) = (f(pp), f(pq));
            if f0 < 0.0 && f1 >= 0.0 {
                t0 = t0.max(f0 / (f0 - f1));
            } else if f1 < 0.0 && f0 >= 0.0 {
                t1 = t1.min(f0 / (f0 - f1));
            }
        }
        let a = p + (q - p) * t0;
        let b = p + (q - p) * t1;
        return if t0 >= t1 {
            Contact::Point(a)
        } else {
            from_points(vec![a, b])
        };
    }
    if sp == 0 {
        return Contact::Point(p);
    }
    if sq == 0 {
        return Contact::Point(q);
    }
    let n = (t[1] - t[0]).cross(t[2] - t[0]);
    let (vp, vq) = (n.dot(p - t[0]), n.dot(q - t[0]));
    let den = vp - vq;
    let u = if den != 0.0 {
        (vp / den).clamp(0.0, 1.0)
    } else {
        0.5
    };
    Contact::Point(p + (q - p) * u)
}

fn seg_seg(p: DVec3, q: DVec3, r: DVec3, s: DVec3) -> Contact {
    if collinear3(p, q, r) && collinear3(p, q, s) {
        return overlap_on_line(&[p, q], &[r, s], q - p);
    }
    for (x, a, b) in [(p, r, s), (q, r, s), (r, p, q), (s, p, q)] {
        if point_on_seg(x, a, b) {
            return Contact::Point(x);
        }
    }
    // Proper crossing: closest point of the two lines, in the projection keeping the most area.
    let d1 = q - p;
    let d2 = s - r;
    let n = d1.cross(d2);
    let k = n.abs().max_position();
    let (a, b, c) = (proj(d1, k), proj(d2, k), proj(r - p, k));
    let den = a.perp_dot(b);
    let u = if den != 0.0 {
        (c.perp_dot(b) / den).clamp(0.0, 1.0)
    } else {
        0.5
    };
    Contact::Point(p + d1 * u)
}
