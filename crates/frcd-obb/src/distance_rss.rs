//! Rectangle swept spheres (RSS, Larsen et al. 1999, the volume PQP uses for distance): a
//! rectangle `c + s u + t v` (`|s| <= a`, `|t| <= b`) grown by a ball of radius `r`. Far tighter
//! than a box lower bound at range: the distance of two RSS is the distance of their rectangles
//! less both radii, and the rectangles' distance is found (from any direction) without the
//! `sqrt(3)` loss of the 15 separating axes when corners face corners.
//!
//! The volumes are built lazily, once per tree, on the first distance query
//! ([`ObbTree::distance_volumes`]), from the crate-internal view of the hierarchy
//! (`node_obb`, `node_children`, `node_triangles`, `triangle`), so collision-only users pay no
//! memory and the node layout stays free to change.
//!
//! # Why the lower bound is certified
//!
//! [`lower_bound`] does not trust any closest-point computation: it uses the rectangles'
//! approximate closest points only to pick a direction `n`, then returns the gap between the
//! two volumes' projections on `n` (support functions: exact for a parallelogram, whatever `u`
//! and `v` are), which is a lower bound on their distance for every direction. Rounding of the
//! projections and of `|n|` is of size `ε M` (`M` the scene magnitude) and is covered by the
//! caller's slack, like the box bounds'. Containment is certified at build: `r` is the largest
//! distance from a vertex to a point *of the rectangle* (an upper bound on its distance to the
//! rectangle), grown by a relative few ulp.

use crate::tree::ObbTree;
use frcd_geom::{DMat3, DVec3};

/// One rectangle swept sphere in its tree's local frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Rss {
    /// Centre of the rectangle.
    pub c: DVec3,
    /// Unit axes of the rectangle.
    pub u: DVec3,
    pub v: DVec3,
    /// Half lengths along `u` and `v`.
    pub a: f64,
    pub b: f64,
    /// Radius of the swept sphere.
    pub r: f64,
}

/// One node of the distance hierarchy: its volume and its children (same node ids as the
/// tree's internal view), so the distance search reads one compact array.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct DNode {
    pub rss: Rss,
    /// Children, or `[LEAF, LEAF]` for a leaf.
    pub kids: [u32; 2],
}

/// The `kids` of a leaf.
pub(crate) const LEAF: u32 = u32::MAX;

impl DNode {
    #[inline(always)]
    pub fn is_leaf(&self) -> bool {
        self.kids[0] == LEAF
    }
}

/// An RSS of B mapped into A's frame.
pub(crate) type Placed = Rss;

impl Rss {
    /// Maps the volume by `m`, `t` (B's frame into A's).
    #[inline]
    pub fn mapped(&self, m: &DMat3, t: DVec3) -> Placed {
        Rss {
            c: *m * self.c + t,
            u: *m * self.u,
            v: *m * self.v,
            ..*self
        }
    }

    /// The point of the rectangle nearest to `p` (clamped projection).
    #[inline(always)]
    fn clamp(&self, p: DVec3) -> DVec3 {
        let d = p - self.c;
        let s = d.dot(self.u).clamp(-self.a, self.a);
        let t = d.dot(self.v).clamp(-self.b, self.b);
        self.c + self.u * s + self.v * t
    }

    /// Half width of the rectangle's projection on `n`.
    #[inline(always)]
    fn extent(&self, n: DVec3) -> f64 {
        self.a * n.dot(self.u).abs() + self.b * n.dot(self.v).abs()
    }
}

/// Lower bound on the distance between two volumes (same frame), not yet reduced by the
/// caller's rounding slack; negative when they may overlap. Alternating projections between the
/// rectangles (from B's centre; three projections with `refine`, else two) give a direction;
/// the bound is the volumes' separation along it. When that bound is clearly at least
/// `prune_at` (decided on squares, with a relative `8 ε` to spare, so without the square root
/// and the division) the result is `+∞`: the caller prunes the pair either way.
#[inline(always)]
pub(crate) fn lower_bound(a: &Rss, b: &Placed, refine: bool, prune_at: f64) -> f64 {
    let mut p = a.clamp(b.c);
    let q = b.clamp(p);
    // A third projection sharpens the direction near contact (measured: a fourth made the
    // near searches slower); at range two give as good a bound for less.
    if refine {
        p = a.clamp(q);
    }
    let n = q - p;
    let len2 = n.length_squared();
    // Also catches NaN (not finite).
    if len2 <= 0.0 || !len2.is_finite() {
        return -(a.r + b.r);
    }
    let proj = n.dot(b.c - a.c) - a.extent(n) - b.extent(n);
    let k = prune_at + a.r + b.r;
    if k > 0.0 && proj > 0.0 && proj * proj >= k * k * len2 * (1.0 + 8.0 * f64::EPSILON) {
        return f64::INFINITY;
    }
    proj / len2.sqrt() - a.r - b.r
}

/// Separation of a volume from a direction `n` (unit) and B's placed volume, as [`lower_bound`]
/// along a given direction (both signs are taken).
#[inline]
pub(crate) fn gap_along(a: &Rss, b: &Placed, n: DVec3) -> f64 {
    n.dot(b.c - a.c).abs() - a.extent(n) - b.extent(n) - a.r - b.r
}

/// `x` above `limit`, or either NaN (then nothing is certified).
#[inline(always)]
pub(crate) fn past(x: f64, limit: f64) -> bool {
    !matches!(
        x.partial_cmp(&limit),
        Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
    )
}

/// True when no vertex under `root` has a computed `n · x` above `limit`: a depth-first
/// branch and bound on the volumes' support `n · c + a|n · u| + b|n · v| + r`, which skips
/// every node whose computed support is at most `limit` (the rounding of that bound, a few
/// `ε M`, is part of the caller's allowance) and stops at the first vertex above it, so a
/// failing certificate costs little. False also when more than `budget` nodes would be
/// visited. Nodes whose support ties the limit (a face square to `n`) are skipped whole, which
/// is what makes the certificate cheap on flat faces. `found` receives the first vertex above
/// the limit and its triangle (the caller tries it first next time: in a concavity the same
/// far vertex keeps failing the certificate).
#[allow(clippy::too_many_arguments)] // one call site; a struct would only rename them
pub(crate) fn support_below(
    nodes: &[DNode],
    tree: &ObbTree,
    root: u32,
    n: DVec3,
    limit: f64,
    budget: u32,
    stack: &mut Vec<u32>,
    found: &mut Option<(DVec3, u32)>,
) -> bool {
    if let Some((p, _)) = *found
        && past(n.dot(p), limit)
    {
        return false;
    }
    let ub = |id: u32| {
        let v = &nodes[id as usize].rss;
        n.dot(v.c) + v.extent(n) + v.r
    };
    // NaN limits and bounds decide nothing: `past` treats them as above.
    if !past(ub(root), limit) {
        return true;
    }
    stack.clear();
    stack.push(root);
    let mut visits = 0u32;
    while let Some(id) = stack.pop() {
        visits += 1;
        if visits > budget {
            return false;
        }
        let d = &nodes[id as usize];
        if d.is_leaf() {
            for &t in tree.node_triangles(id) {
                for p in tree.triangle(t).v {
                    if past(n.dot(p), limit) {
                        *found = Some((p, t));
                        return false;
                    }
                }
            }
            continue;
        }
        let [k0, k1] = d.kids;
        let (u0, u1) = (ub(k0), ub(k1));
        // The child with the larger bound (the likelier to hold a vertex above the limit) is
        // visited first: pushed last.
        let (first, second) = if u0 >= u1 {
            ((k0, u0), (k1, u1))
        } else {
            ((k1, u1), (k0, u0))
        };
        if past(second.1, limit) {
            stack.push(second.0);
        }
        if past(first.1, limit) {
            stack.push(first.0);
        }
    }
    true
}

/// Builds one volume per node, indexed by node id.
pub(crate) fn build(tree: &ObbTree) -> Vec<DNode> {
    // Node ids of the internal view: collect them (and the largest id) from the root.
    let mut ids = Vec::new();
    let mut stack = vec![tree.root_node()];
    while let Some(n) = stack.pop() {
        ids.push(n);
        stack.extend(tree.node_children(n));
    }
    let len = ids.iter().copied().max().map_or(0, |m| m as usize + 1);
    let empty = Rss {
        c: DVec3::ZERO,
        u: DVec3::X,
        v: DVec3::Y,
        a: 0.0,
        b: 0.0,
        r: f64::INFINITY,
    };
    let mut out = vec![
        DNode {
            rss: empty,
            kids: [LEAF, LEAF],
        };
        len
    ];
    let mut points: Vec<DVec3> = Vec::new();
    let mut under = Vec::new();
    for &id in &ids {
        points.clear();
        under.clear();
        under.push(id);
        while let Some(n) = under.pop() {
            for &t in tree.node_triangles(n) {
                points.extend_from_slice(&tree.triangle(t).v);
            }
            under.extend(tree.node_children(n));
        }
        let mut kids = [LEAF, LEAF];
        for (k, c) in tree.node_children(id).take(2).enumerate() {
            kids[k] = c;
        }
        out[id as usize] = DNode {
            rss: fit(&tree.node_obb(id).axes, &points),
            kids,
        };
    }
    out
}

/// Gram-Schmidt on the columns (the box axes may carry rounding from a compact layout).
fn orthonormal(m: &DMat3) -> Option<[DVec3; 3]> {
    let x = m.x_axis.normalize_or_zero();
    let y = (m.y_axis - x * x.dot(m.y_axis)).normalize_or_zero();
    let z = x.cross(y).normalize_or_zero();
    (x != DVec3::ZERO && y != DVec3::ZERO && z != DVec3::ZERO && z.is_finite()).then_some([x, y, z])
}

/// The RSS with the box's axes (its thinnest axis as the rectangle's normal) holding `points`.
fn fit(axes: &DMat3, points: &[DVec3]) -> Rss {
    let frame = orthonormal(axes).unwrap_or([DVec3::X, DVec3::Y, DVec3::Z]);
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            let x = p.dot(frame[k]);
            lo[k] = lo[k].min(x);
            hi[k] = hi[k].max(x);
        }
    }
    // Thinnest axis: the normal; the other two span the rectangle.
    let w = (0..3)
        .min_by(|&i, &j| (hi[i] - lo[i]).total_cmp(&(hi[j] - lo[j])))
        .unwrap_or(2);
    let (i, j) = ((w + 1) % 3, (w + 2) % 3);
    let (u, v, n) = (frame[i], frame[j], frame[w]);
    let zc = 0.5 * (lo[w] + hi[w]);
    let r0 = 0.5 * (hi[w] - lo[w]);
    // Shrink the rectangle where the swept sphere's rounded sides still cover the points
    // (PQP's idea): a point at height dz off the mid-plane is covered up to sqrt(r0² - dz²)
    // beyond the rectangle's side.
    let (mut xl, mut xh, mut yl, mut yh) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for p in points {
        let (x, y, z) = (p.dot(u), p.dot(v), p.dot(n));
        let dz = z - zc;
        let h = (r0 * r0 - dz * dz).max(0.0).sqrt();
        xl = xl.min(x + h);
        xh = xh.max(x - h);
        yl = yl.min(y + h);
        yh = yh.max(y - h);
    }
    if xl > xh {
        let m = 0.5 * (xl + xh);
        (xl, xh) = (m, m);
    }
    if yl > yh {
        let m = 0.5 * (yl + yh);
        (yl, yh) = (m, m);
    }
    let mut rss = Rss {
        c: u * (0.5 * (xl + xh)) + v * (0.5 * (yl + yh)) + n * zc,
        u,
        v,
        a: 0.5 * (xh - xl),
        b: 0.5 * (yh - yl),
        r: 0.0,
    };
    // Certified radius: the largest distance from a point to a point of the rectangle (at least
    // its distance to the rectangle), grown by a relative few ulp for the rounding of that
    // length and of the rectangle's corners.
    let mut r2 = 0.0f64;
    let mut mag = rss.c.length() + rss.a + rss.b;
    for p in points {
        r2 = r2.max((*p - rss.clamp(*p)).length_squared());
        mag = mag.max(p.length());
    }
    rss.r = r2.sqrt() * (1.0 + 1e-12) + 16.0 * f64::EPSILON * mag;
    if !rss.r.is_finite() || !rss.c.is_finite() {
        // Non-finite geometry: a volume that prunes nothing.
        rss.r = f64::INFINITY;
    }
    rss
}

impl ObbTree {
    /// The distance volumes (one RSS per node), built on first use.
    pub(crate) fn distance_volumes(&self) -> &[DNode] {
        self.distance_volumes.get_or_init(|| build(self))
    }

    /// Bytes held by the distance volumes (0 until the first distance or tolerance query on
    /// this tree builds them): the memory distance queries add to a tree.
    ///
    /// ```
    /// use frcd_obb::{BuildOptions, ObbTree, distance::distance};
    /// use frcd_geom::{shapes, DVec3, Pose};
    /// let t = ObbTree::build(&shapes::icosphere(1.0, 2), &BuildOptions::default());
    /// assert_eq!(t.distance_memory_bytes(), 0);
    /// let far = Pose::from_translation(DVec3::new(3.0, 0.0, 0.0));
    /// distance(&t, &Pose::IDENTITY, &t, &far, &Default::default());
    /// assert!(t.distance_memory_bytes() > 0);
    /// ```
    pub fn distance_memory_bytes(&self) -> usize {
        self.distance_volumes
            .get()
            .map_or(0, |v| v.capacity() * std::mem::size_of::<DNode>())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BuildOptions;
    use frcd_geom::{DQuat, shapes};

    /// Every vertex under a node lies in its RSS, and the lower bound never exceeds the distance
    /// of sampled points of two volumes.
    #[test]
    fn volumes_contain_their_triangles_and_bounds_hold() {
        let mesh = shapes::icosphere(1.0, 3);
        let tree = ObbTree::build(&mesh, &BuildOptions::default());
        let vols = tree.distance_volumes();
        let mut stack = vec![(tree.root_node(), Vec::<u32>::new())];
        let mut checked = 0;
        while let Some((n, _)) = stack.pop() {
            let mut under = vec![n];
            while let Some(m) = under.pop() {
                for &t in tree.node_triangles(m) {
                    for p in tree.triangle(t).v {
                        let r = &vols[n as usize].rss;
                        let d = (p - r.clamp(p)).length();
                        assert!(d <= r.r, "node {n}: vertex {p} at {d} > r {}", r.r);
                        checked += 1;
                    }
                }
                under.extend(tree.node_children(m));
            }
            for k in tree.node_children(n) {
                stack.push((k, Vec::new()));
            }
        }
        assert!(checked > mesh.triangle_count() * 3);
        // Bounds against brute-force vertex distances for node pairs of two posed copies.
        let m = DMat3::from_quat(DQuat::from_axis_angle(
            DVec3::new(1.0, 2.0, 3.0).normalize(),
            0.7,
        ));
        let t = DVec3::new(2.1, 0.3, -0.2);
        for na in 0..40u32 {
            for nb in 0..40u32 {
                let lb = lower_bound(
                    &vols[na as usize].rss,
                    &vols[nb as usize].rss.mapped(&m, t),
                    true,
                    f64::INFINITY,
                );
                let mut best = f64::INFINITY;
                let (mut ua, mut ub) = (vec![na], vec![nb]);
                let mut pa = Vec::new();
                while let Some(x) = ua.pop() {
                    for &tr in tree.node_triangles(x) {
                        pa.extend(tree.triangle(tr).v);
                    }
                    ua.extend(tree.node_children(x));
                }
                while let Some(x) = ub.pop() {
                    for &tr in tree.node_triangles(x) {
                        for p in tree.triangle(tr).v {
                            let q = m * p + t;
                            for a in &pa {
                                best = best.min((q - *a).length());
                            }
                        }
                    }
                    ub.extend(tree.node_children(x));
                }
                assert!(lb <= best + 1e-12, "nodes {na} {nb}: bound {lb} > {best}");
            }
        }
    }

    /// Parts apart (where the support certificate usually ends the search) and a concave part
    /// whose closest points may lie in a concavity (where it must not): every answer within its
    /// bound of the oracle, cold and warm-started.
    #[test]
    fn certified_early_ends_agree_with_the_oracle() {
        use crate::distance::{DistanceCache, DistanceRequest, distance, distance_cached};
        let knot = shapes::torus_knot(&shapes::TorusKnotParams {
            tubular_segments: 48,
            radial_segments: 6,
            ..Default::default()
        })
        .expect("knot");
        let ball = shapes::icosphere(0.3, 2);
        let (ta, tb) = (
            ObbTree::build(&knot, &BuildOptions::default()),
            ObbTree::build(&ball, &BuildOptions::default()),
        );
        let mut cache = DistanceCache::new();
        let mut k = 0u32;
        for i in 0..24 {
            let f = i as f64;
            let dir = DVec3::new((f * 1.7).sin(), (f * 0.9).cos(), (f * 0.4).sin()).normalize();
            // From inside the knot's hole (concave closest points) out to several sizes away.
            let reach = 0.2 * f;
            let pb = frcd_geom::Pose::new(dir * reach, DQuat::from_rotation_z(f));
            let pa = frcd_geom::Pose::IDENTITY;
            let o = crate::oracle::distance(&knot, &pa, &ball, &pb);
            for d in [
                distance(&ta, &pa, &tb, &pb, &DistanceRequest::default()),
                distance_cached(&ta, &pa, &tb, &pb, &DistanceRequest::default(), &mut cache),
            ] {
                assert!(
                    (d.distance - o.distance).abs() <= d.error_bound,
                    "setup {i}: {} vs oracle {}",
                    d.distance,
                    o.distance
                );
                k += 1;
            }
        }
        assert_eq!(k, 48);
    }
}
