//! Robust 3D convex hull.
//!
//! [`convex_hull`] is Quickhull (Barber, Dobkin & Huhdanpaa 1996): each face keeps the set of
//! uninserted points strictly above it (its *outside set*, every point in at most one); the
//! point furthest above a face is inserted next, the faces it sees are replaced by a cone from
//! it to their horizon, and the orphaned points are handed to the new faces they see or dropped
//! as inside. Expected `O(n log n)` on the usual distributions (measured by
//! `examples/hull_scaling.rs`; worst case `O(n²)`).
//!
//! Every combinatorial decision is the sign of [`orient3d`] (and, for planar input,
//! [`orient2d`] / [`collinear3`], all from [`crate::predicates`]) on *input* points; there is no
//! epsilon anywhere. Only the choice of *which* outside point to insert uses a rounded distance,
//! and any choice is correct. With exact predicates the result is exactly correct for the f64 input:
//!
//! - a point is inserted only when it lies strictly outside the current hull, so the hull's
//!   vertices are input points on the hull boundary (every extreme point is one; a point on an
//!   edge or face of the final hull may also remain a vertex if it was inserted before the points
//!   that made it non-extreme), never interior points;
//! - every face is a non-degenerate triangle, counter-clockwise seen from outside;
//! - every input point `p` satisfies `orient3d(a, b, c, p) <= 0` for every face `(a, b, c)`;
//! - coplanar neighbouring faces are allowed (a planar facet of the hull is triangulated).
//!
//! Flat input is reported as such ([`Hull3::Point`], [`Hull3::Segment`], [`Hull3::Polygon`])
//! rather than as a zero-volume polytope.
//!
//! ```
//! use frcd_geom::{hull::{convex_hull, Hull3}, DVec3};
//! let mut pts: Vec<DVec3> = (0..8)
//!     .map(|i| DVec3::new((i & 1) as f64, ((i >> 1) & 1) as f64, (i >> 2) as f64))
//!     .collect();
//! pts.push(DVec3::splat(0.5)); // interior
//! pts.push(DVec3::ZERO); // duplicate
//! let Hull3::Polytope { vertices, faces } = convex_hull(&pts).unwrap() else { panic!() };
//! assert_eq!(vertices.len(), 8);
//! assert_eq!(faces.len(), 12);
//! ```

use crate::predicates::{collinear3, orient2d, orient3d};
use crate::{MeshError, TriMesh, Triangle};
use glam::{DVec2, DVec3};

/// The convex hull of a finite point set, by dimension.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Hull3 {
    /// No points.
    Empty,
    /// All points are the same point.
    Point(DVec3),
    /// All points are collinear: the two extreme points.
    Segment(DVec3, DVec3),
    /// All points are coplanar (and not collinear): a convex polygon, vertices in
    /// counter-clockwise order seen from the side `normal` points to, no three consecutive
    /// vertices collinear.
    Polygon {
        /// Polygon vertices (input points), counter-clockwise around `normal`.
        vertices: Vec<DVec3>,
        /// A (rounded, non-normalised) normal of the polygon's plane (Newell's formula).
        normal: DVec3,
    },
    /// A full-dimensional hull: a closed, consistently oriented 2-manifold of triangles
    /// (counter-clockwise seen from outside) with Euler characteristic 2.
    Polytope {
        /// Hull vertices (input points).
        vertices: Vec<DVec3>,
        /// Triangles as indices into `vertices`, counter-clockwise seen from outside.
        faces: Vec<[u32; 3]>,
    },
}

/// Why a hull could not be computed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum HullError {
    /// An input coordinate is NaN or infinite.
    #[error("point {index} has a non-finite coordinate: {value:?}")]
    NonFinitePoint {
        /// Index of the point in the input.
        index: usize,
        /// The point as given.
        value: [f64; 3],
    },
    /// The predicates contradicted each other (the visible region's horizon was not a simple
    /// cycle). Cannot happen with exact predicates; reported instead of a panic in case an
    /// inexact predicate is ever substituted.
    #[error("inconsistent orientation predicates while inserting point {index}")]
    Inconsistent {
        /// Index (in the input) of the point being inserted.
        index: usize,
    },
}

impl Hull3 {
    /// The hull's vertices (empty for [`Hull3::Empty`]).
    pub fn vertices(&self) -> Vec<DVec3> {
        match self {
            Hull3::Empty => Vec::new(),
            Hull3::Point(p) => vec![*p],
            Hull3::Segment(a, b) => vec![*a, *b],
            Hull3::Polygon { vertices, .. } | Hull3::Polytope { vertices, .. } => vertices.clone(),
        }
    }

    /// The hull's surface as triangles: the faces of a polytope, a fan over a polygon (one
    /// side), nothing for lower dimensions.
    pub fn surface_triangles(&self) -> Vec<Triangle> {
        match self {
            Hull3::Polytope { vertices, faces } => faces
                .iter()
                .map(|f| {
                    Triangle::new(
                        vertices[f[0] as usize],
                        vertices[f[1] as usize],
                        vertices[f[2] as usize],
                    )
                })
                .collect(),
            Hull3::Polygon { vertices, .. } => (1..vertices.len() - 1)
                .map(|i| Triangle::new(vertices[0], vertices[i], vertices[i + 1]))
                .collect(),
            _ => Vec::new(),
        }
    }

    /// The hull as a validated [`TriMesh`] (only for [`Hull3::Polytope`]; `None` otherwise).
    pub fn to_mesh(&self) -> Option<Result<TriMesh, MeshError>> {
        match self {
            Hull3::Polytope { vertices, faces } => {
                Some(TriMesh::new(vertices.clone(), faces.clone()))
            }
            _ => None,
        }
    }

    /// 0 for empty, point; 1 for a segment; 2 for a polygon; 3 for a polytope (`-1` for empty).
    pub fn dimension(&self) -> i32 {
        match self {
            Hull3::Empty => -1,
            Hull3::Point(_) => 0,
            Hull3::Segment(..) => 1,
            Hull3::Polygon { .. } => 2,
            Hull3::Polytope { .. } => 3,
        }
    }
}

/// Computes the convex hull of `points` (see the [module docs](self) for guarantees).
///
/// Duplicates are allowed (exact equality; `-0.0 == 0.0`, and output coordinates carry `+0.0`).
/// The result is deterministic. Non-finite coordinates are refused with the point's index.
pub fn convex_hull(points: &[DVec3]) -> Result<Hull3, HullError> {
    if let Some((index, p)) = points.iter().enumerate().find(|(_, p)| !p.is_finite()) {
        return Err(HullError::NonFinitePoint {
            index,
            value: p.to_array(),
        });
    }
    // Deduplicate exactly (sort, then drop equal neighbours), remembering an input index of each.
    let mut order: Vec<u32> = (0..points.len() as u32).collect();
    // total_cmp orders -0.0 before 0.0; fold signed zeros first so they compare equal.
    let fold = |x: f64| if x == 0.0 { 0.0 } else { x };
    let folded: Vec<DVec3> = points
        .iter()
        .map(|p| DVec3::new(fold(p.x), fold(p.y), fold(p.z)))
        .collect();
    order.sort_unstable_by(|a, b| {
        let (p, q) = (folded[*a as usize], folded[*b as usize]);
        p.x.total_cmp(&q.x)
            .then(p.y.total_cmp(&q.y))
            .then(p.z.total_cmp(&q.z))
    });
    order.dedup_by(|a, b| folded[*a as usize] == folded[*b as usize]);
    let pts: Vec<DVec3> = order.iter().map(|&i| folded[i as usize]).collect();

    match pts.len() {
        0 => return Ok(Hull3::Empty),
        1 => return Ok(Hull3::Point(pts[0])),
        _ => {}
    }
    // A large initial simplex (rounded distances choose, exact predicates confirm): the
    // lexicographic extremes, the point furthest from their line, the point furthest from that
    // plane.
    let far = |score: &dyn Fn(DVec3) -> f64, ok: &dyn Fn(DVec3) -> bool| -> Option<usize> {
        let best = (0..pts.len())
            .max_by(|&i, &j| score(pts[i]).total_cmp(&score(pts[j])))
            .filter(|&i| ok(pts[i]));
        best.or_else(|| (0..pts.len()).find(|&i| ok(pts[i])))
    };
    let (i0, i1) = (0, pts.len() - 1);
    let (p0, p1) = (pts[i0], pts[i1]);
    let Some(i2) = far(&|p| (p1 - p0).cross(p - p0).length_squared(), &|p| {
        !collinear3(p0, p1, p)
    }) else {
        return Ok(segment_hull(&pts, p1 - p0));
    };
    let p2 = pts[i2];
    let n = (p1 - p0).cross(p2 - p0);
    let Some(i3) = far(&|p| n.dot(p - p0).abs(), &|p| orient3d(p0, p1, p2, p) != 0) else {
        return Ok(polygon_hull(&pts, [p0, p1, p2]));
    };
    Quickhull::run(&pts, [i0, i1, i2, i3])
        .map_err(|local| HullError::Inconsistent {
            index: order[local as usize] as usize,
        })
        .map(|(vertices, faces)| Hull3::Polytope { vertices, faces })
}

/// Collinear points: the extremes along a coordinate in which the line is not constant (exact:
/// along such a coordinate the points are strictly ordered).
fn segment_hull(pts: &[DVec3], d: DVec3) -> Hull3 {
    let k = (0..3).find(|&k| d[k] != 0.0).unwrap_or(0);
    let mut lo = pts[0];
    let mut hi = pts[0];
    for &p in pts {
        if p[k] < lo[k] {
            lo = p;
        }
        if p[k] > hi[k] {
            hi = p;
        }
    }
    Hull3::Segment(lo, hi)
}

/// Projection dropping coordinate `k`, cyclic so that 2D orientation equals the sign of the
/// normal's `k` component: k=0 -> (y, z), k=1 -> (z, x), k=2 -> (x, y).
fn project(p: DVec3, k: usize) -> DVec2 {
    match k {
        0 => DVec2::new(p.y, p.z),
        1 => DVec2::new(p.z, p.x),
        _ => DVec2::new(p.x, p.y),
    }
}

/// Coplanar points: Andrew's monotone chain in a projection where the plane is not edge-on
/// (there, the projection is injective on the plane and orient2d has the sign of orient in the
/// plane).
fn polygon_hull(pts: &[DVec3], tri: [DVec3; 3]) -> Hull3 {
    // Any axis with an exactly non-zero projected orientation works; prefer the one the plane
    // faces most (by the rounded normal) so the projection is well spread.
    let ok = |k: usize| orient2d(project(tri[0], k), project(tri[1], k), project(tri[2], k)) != 0;
    let rough = (tri[1] - tri[0]).cross(tri[2] - tri[0]).abs();
    let best = (0..3)
        .max_by(|&i, &j| rough[i].total_cmp(&rough[j]))
        .unwrap_or(2);
    let k = if ok(best) {
        best
    } else {
        (0..3)
            .find(|&k| ok(k))
            .expect("three non-collinear points have a non-degenerate projection")
    };
    let mut idx: Vec<usize> = (0..pts.len()).collect();
    let q: Vec<DVec2> = pts.iter().map(|p| project(*p, k)).collect();
    idx.sort_unstable_by(|&a, &b| q[a].x.total_cmp(&q[b].x).then(q[a].y.total_cmp(&q[b].y)));
    let mut hull: Vec<usize> = Vec::with_capacity(idx.len() + 1);
    // Lower chain then upper chain; pop on non-left turns (drops collinear points).
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &usize>> = if pass == 0 {
            Box::new(idx.iter())
        } else {
            Box::new(idx.iter().rev())
        };
        for &i in iter {
            while hull.len() >= start + 2
                && orient2d(q[hull[hull.len() - 2]], q[hull[hull.len() - 1]], q[i]) <= 0
            {
                hull.pop();
            }
            hull.push(i);
        }
        hull.pop(); // the last point starts the other chain
    }
    let vertices: Vec<DVec3> = hull.iter().map(|&i| pts[i]).collect();
    let mut normal = DVec3::ZERO;
    for i in 0..vertices.len() {
        let (a, b) = (vertices[i], vertices[(i + 1) % vertices.len()]);
        normal += DVec3::new(
            (a.y - b.y) * (a.z + b.z),
            (a.z - b.z) * (a.x + b.x),
            (a.x - b.x) * (a.y + b.y),
        );
    }
    // The polygon is counter-clockwise in projection k, i.e. around any normal with a positive
    // k component; keep that true even if rounding spoilt Newell's sum.
    if normal[k].partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        normal = DVec3::ZERO;
        normal[k] = 1.0;
    }
    Hull3::Polygon { vertices, normal }
}

const NONE: u32 = u32::MAX;

struct Face {
    v: [u32; 3],
    /// `nb[k]`: the face across edge `(v[k], v[(k+1)%3])`.
    nb: [u32; 3],
    alive: bool,
    /// Uninserted points strictly above this face (each point is in at most one face's set).
    outside: Vec<u32>,
    /// Rounded normal `(b-a)×(c-a)`, only to pick the furthest outside point.
    normal: DVec3,
    /// The outside point with the largest rounded height, and that height.
    furthest: u32,
    height: f64,
}

struct Quickhull<'a> {
    pts: &'a [DVec3],
    faces: Vec<Face>,
}

impl<'a> Quickhull<'a> {
    #[inline]
    fn sees(&self, f: [u32; 3], p: u32) -> bool {
        let q = |i: u32| self.pts[i as usize];
        orient3d(q(f[0]), q(f[1]), q(f[2]), q(p)) > 0
    }

    fn add_face(&mut self, v: [u32; 3], nb: [u32; 3]) -> u32 {
        let q = |i: u32| self.pts[i as usize];
        self.faces.push(Face {
            v,
            nb,
            alive: true,
            outside: Vec::new(),
            normal: (q(v[1]) - q(v[0])).cross(q(v[2]) - q(v[0])),
            furthest: NONE,
            height: f64::NEG_INFINITY,
        });
        (self.faces.len() - 1) as u32
    }

    /// Gives `p` to face `f` (the caller has checked that `p` sees `f`).
    fn assign(&mut self, f: u32, p: u32) {
        let pt = self.pts[p as usize];
        let face = &mut self.faces[f as usize];
        let h = face.normal.dot(pt - self.pts[face.v[0] as usize]);
        if face.furthest == NONE || h > face.height {
            face.furthest = p;
            face.height = h;
        }
        face.outside.push(p);
    }

    /// Returns hull vertices and faces, or the (local) index of a point whose insertion found
    /// the predicates inconsistent.
    #[allow(clippy::type_complexity)]
    fn run(pts: &'a [DVec3], simplex: [usize; 4]) -> Result<(Vec<DVec3>, Vec<[u32; 3]>), u32> {
        let [a, mut b, mut c, d] = simplex.map(|i| i as u32);
        let q = |i: u32| pts[i as usize];
        if orient3d(q(a), q(b), q(c), q(d)) > 0 {
            std::mem::swap(&mut b, &mut c);
        }
        // With orient(a,b,c,d) < 0 these four faces all have the opposite vertex below them;
        // neighbours across each edge (v[k], v[k+1]) written out by hand.
        let mut h = Quickhull {
            pts,
            faces: Vec::with_capacity(64),
        };
        h.add_face([a, b, c], [1, 2, 3]);
        h.add_face([b, a, d], [0, 3, 2]);
        h.add_face([c, b, d], [0, 1, 3]);
        h.add_face([a, c, d], [0, 2, 1]);
        debug_assert!((0..4).all(|f| (0..3).all(|k| {
            let (u, w) = (h.faces[f].v[k], h.faces[f].v[(k + 1) % 3]);
            let g = &h.faces[h.faces[f].nb[k] as usize];
            (0..3).any(|j| g.v[j] == w && g.v[(j + 1) % 3] == u)
        })));
        let first = [a, b, c, d];
        for p in 0..pts.len() as u32 {
            if first.contains(&p) {
                continue;
            }
            if let Some(f) = (0..4u32).find(|&f| h.sees(h.faces[f as usize].v, p)) {
                h.assign(f, p);
            }
        }

        let mut pending: Vec<u32> = (0..4).collect();
        let mut visible_stamp: Vec<u32> = Vec::new();
        let mut start_of: Vec<u32> = vec![NONE; pts.len()];
        let mut start_stamp: Vec<u32> = vec![0; pts.len()];
        let mut stamp = 0u32;
        let mut visible: Vec<u32> = Vec::new();
        let mut stack: Vec<u32> = Vec::new();
        let mut horizon: Vec<(u32, u32, u32)> = Vec::new();
        let mut new_faces: Vec<u32> = Vec::new();
        while let Some(f0) = pending.pop() {
            let face = &h.faces[f0 as usize];
            if !face.alive || face.outside.is_empty() {
                continue;
            }
            let r = face.furthest;
            stamp += 1;
            if visible_stamp.len() < h.faces.len() {
                visible_stamp.resize(2 * h.faces.len(), 0);
            }
            // Visible region: connected, found from f0 through neighbours.
            visible.clear();
            horizon.clear();
            stack.clear();
            stack.push(f0);
            visible_stamp[f0 as usize] = stamp;
            while let Some(f) = stack.pop() {
                visible.push(f);
                for k in 0..3 {
                    let g = h.faces[f as usize].nb[k];
                    if visible_stamp[g as usize] == stamp {
                        continue;
                    }
                    if h.sees(h.faces[g as usize].v, r) {
                        visible_stamp[g as usize] = stamp;
                        stack.push(g);
                    }
                }
            }
            for &f in &visible {
                let face = &h.faces[f as usize];
                for k in 0..3 {
                    let g = face.nb[k];
                    if visible_stamp[g as usize] != stamp {
                        horizon.push((face.v[k], face.v[(k + 1) % 3], g));
                    }
                }
            }
            // New faces (u, w, r) over the horizon edges, linked to the kept neighbour.
            new_faces.clear();
            for &(u, w, g) in &horizon {
                if start_stamp[u as usize] == stamp {
                    return Err(r); // u starts two horizon edges: not a simple cycle
                }
                let n = h.add_face([u, w, r], [g, NONE, NONE]);
                start_stamp[u as usize] = stamp;
                start_of[u as usize] = n;
                let gf = &mut h.faces[g as usize];
                let Some(j) = (0..3).find(|&j| gf.v[j] == w && gf.v[(j + 1) % 3] == u) else {
                    return Err(r);
                };
                gf.nb[j] = n;
                new_faces.push(n);
            }
            // Around r: (u, w, r) meets (w, x, r) across edge (w, r).
            for &n in &new_faces {
                let w = h.faces[n as usize].v[1];
                if start_stamp[w as usize] != stamp {
                    return Err(r);
                }
                let m = start_of[w as usize];
                h.faces[n as usize].nb[1] = m;
                h.faces[m as usize].nb[2] = n;
            }
            // Orphans: a point above a removed face is either inside the new hull or above
            // one of the new faces (the segment from it to the removed face's centroid leaves
            // the new hull through a new face).
            for &f in &visible {
                h.faces[f as usize].alive = false;
                let orphans = std::mem::take(&mut h.faces[f as usize].outside);
                for p in orphans {
                    if p == r {
                        continue;
                    }
                    if let Some(&n) = new_faces
                        .iter()
                        .find(|&&n| h.sees(h.faces[n as usize].v, p))
                    {
                        h.assign(n, p);
                    }
                }
            }
            pending.extend(
                new_faces
                    .iter()
                    .copied()
                    .filter(|&n| !h.faces[n as usize].outside.is_empty()),
            );
        }

        // Compact: keep used vertices in first-use order.
        let mut remap = vec![NONE; pts.len()];
        let mut vertices = Vec::new();
        let mut faces = Vec::new();
        for f in h.faces.iter().filter(|f| f.alive) {
            faces.push(f.v.map(|i| {
                if remap[i as usize] == NONE {
                    remap[i as usize] = vertices.len() as u32;
                    vertices.push(pts[i as usize]);
                }
                remap[i as usize]
            }));
        }
        Ok((vertices, faces))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degenerate_inputs() {
        assert_eq!(convex_hull(&[]).unwrap(), Hull3::Empty);
        let p = DVec3::new(1.0, 2.0, 3.0);
        assert_eq!(convex_hull(&[p, p, p]).unwrap(), Hull3::Point(p));
        let line: Vec<DVec3> = (0..10)
            .map(|i| p + DVec3::new(0.0, 1.0, 2.0) * i as f64)
            .collect();
        let Hull3::Segment(a, b) = convex_hull(&line).unwrap() else {
            panic!()
        };
        assert_eq!((a, b), (line[0], line[9]));
        assert!(matches!(
            convex_hull(&[p, DVec3::new(f64::NAN, 0.0, 0.0)]),
            Err(HullError::NonFinitePoint { index: 1, .. })
        ));
    }

    #[test]
    fn planar_grid_gives_ccw_square() {
        let mut pts = Vec::new();
        for i in 0..5 {
            for j in 0..5 {
                pts.push(DVec3::new(i as f64, j as f64, 0.0));
            }
        }
        let Hull3::Polygon { vertices, normal } = convex_hull(&pts).unwrap() else {
            panic!()
        };
        assert_eq!(vertices.len(), 4);
        assert!(normal.z > 0.0);
        for i in 0..4 {
            let (a, b, c) = (vertices[i], vertices[(i + 1) % 4], vertices[(i + 2) % 4]);
            assert!((b - a).cross(c - b).dot(normal) > 0.0);
        }
    }
}
