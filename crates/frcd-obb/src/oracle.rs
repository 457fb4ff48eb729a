//! The exact oracle: every pair of triangles whose boxes overlap gets the exact test.
//!
//! Independent of the OBB tree on purpose: it shares only the way B's triangles are mapped into
//! A's frame ([`RelativeFrame`]), so the exact test sees the same f64 coordinates. The per-triangle
//! box culling (sort by `min.x`, sweep) is exact: a touching pair always has overlapping boxes.
//! Other backends' agreement tests compare with these functions.
//!
//! ```
//! use frcd_obb::oracle;
//! use frcd_geom::{shapes, DVec3, Pose};
//! let a = shapes::icosphere(1.0, 2);
//! let b = shapes::icosphere(1.0, 2);
//! let pairs = oracle::pairs(&a, &Pose::IDENTITY, &b, &Pose::from_translation(DVec3::X));
//! assert!(!pairs.is_empty());
//! assert!(pairs.windows(2).all(|w| w[0] < w[1]));
//! ```

#[path = "oracle_distance.rs"]
mod distance_oracle;
use crate::query::{Containment, RelativeFrame};
use crate::solid::point_inside;
pub use distance_oracle::*;
use frcd_geom::{Aabb, DVec3, Pose, TriMesh, Triangle};
use frcd_tritri::Method;

/// Every touching pair `(tri_a, tri_b)` of two triangle lists (each in its body's local frame),
/// sorted ascending, by the exact test.
pub fn pairs_of_triangles(
    a: &[Triangle],
    pose_a: &Pose,
    b: &[Triangle],
    pose_b: &Pose,
) -> Vec<(u32, u32)> {
    let frame = RelativeFrame::new(pose_a, pose_b);
    let mapped: Vec<Triangle> = b.iter().map(|t| frame.triangle(t)).collect();
    let boxes_a: Vec<Aabb> = a.iter().map(|t| t.aabb()).collect();
    let boxes_b: Vec<Aabb> = mapped.iter().map(|t| t.aabb()).collect();
    // Sweep along x over both lists merged by min.x.
    let mut ia: Vec<u32> = (0..a.len() as u32).collect();
    let mut ib: Vec<u32> = (0..b.len() as u32).collect();
    ia.sort_unstable_by(|&x, &y| {
        boxes_a[x as usize]
            .min
            .x
            .total_cmp(&boxes_a[y as usize].min.x)
    });
    ib.sort_unstable_by(|&x, &y| {
        boxes_b[x as usize]
            .min
            .x
            .total_cmp(&boxes_b[y as usize].min.x)
    });
    let mut out = Vec::new();
    let mut check = |x: u32, y: u32| {
        let (ba, bb) = (&boxes_a[x as usize], &boxes_b[y as usize]);
        if ba.intersects(bb)
            && frcd_tritri::intersects(Method::Exact, &a[x as usize], &mapped[y as usize])
        {
            out.push((x, y));
        }
    };
    let (mut p, mut q) = (0, 0);
    while p < ia.len() && q < ib.len() {
        let x = ia[p];
        let y = ib[q];
        if boxes_a[x as usize].min.x <= boxes_b[y as usize].min.x {
            // Every B box starting within x's span.
            let hi = boxes_a[x as usize].max.x;
            for &y2 in &ib[q..] {
                if boxes_b[y2 as usize].min.x > hi {
                    break;
                }
                check(x, y2);
            }
            p += 1;
        } else {
            let hi = boxes_b[y as usize].max.x;
            for &x2 in &ia[p..] {
                if boxes_a[x2 as usize].min.x > hi {
                    break;
                }
                check(x2, y);
            }
            q += 1;
        }
    }
    out.sort_unstable();
    out
}

/// Every touching pair of two meshes placed at two poses, sorted ascending.
pub fn pairs(a: &TriMesh, pose_a: &Pose, b: &TriMesh, pose_b: &Pose) -> Vec<(u32, u32)> {
    let ta: Vec<Triangle> = a.triangles().collect();
    let tb: Vec<Triangle> = b.triangles().collect();
    pairs_of_triangles(&ta, pose_a, &tb, pose_b)
}

/// Solid-mode containment of two meshes whose surfaces do not touch (call it only then): a
/// connected component of B inside closed A, or of A inside closed B, by ray parity on exact
/// predicates, every triangle tested (no tree). Meshes that are not closed contain nothing.
pub fn containment(a: &TriMesh, pose_a: &Pose, b: &TriMesh, pose_b: &Pose) -> Option<Containment> {
    let frame = RelativeFrame::new(pose_a, pose_b);
    let ta: Vec<Triangle> = a.triangles().collect();
    let tb: Vec<Triangle> = b.triangles().map(|t| frame.triangle(&t)).collect();
    let box_of = |t: &[Triangle]| t.iter().fold(Aabb::EMPTY, |acc, t| acc.union(&t.aabb()));
    // A different ray sequence than the tree's, so the two answers are reached independently.
    let seed = 0xC0FF_EE00_D15E_A5E5;
    if a.topology().is_closed() {
        let bounds = box_of(&ta);
        for p in representatives(b) {
            let p = frame.point(p);
            if point_inside(p, ta.len(), |i| ta[i], &bounds, seed) == Some(true) {
                return Some(Containment::BInsideA);
            }
        }
    }
    if b.topology().is_closed() {
        let bounds = box_of(&tb);
        for p in representatives(a) {
            if point_inside(p, tb.len(), |i| tb[i], &bounds, seed) == Some(true) {
                return Some(Containment::AInsideB);
            }
        }
    }
    None
}

/// The oracle's full answer: touching pairs, and (solid mode, no touching pair) containment.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OracleAnswer {
    /// Every touching pair, sorted ascending.
    pub pairs: Vec<(u32, u32)>,
    /// Solid mode only: containment when `pairs` is empty.
    pub contained: Option<Containment>,
}

impl OracleAnswer {
    /// True when the bodies interfere.
    pub fn collide(&self) -> bool {
        !self.pairs.is_empty() || self.contained.is_some()
    }
}

/// [`pairs`], plus [`containment`] when `solid` and no pair touches.
pub fn answer(a: &TriMesh, pose_a: &Pose, b: &TriMesh, pose_b: &Pose, solid: bool) -> OracleAnswer {
    let pairs = pairs(a, pose_a, b, pose_b);
    let contained = if solid && pairs.is_empty() {
        containment(a, pose_a, b, pose_b)
    } else {
        None
    };
    OracleAnswer { pairs, contained }
}

/// One vertex of each connected component, by a union-find independent of the tree's.
fn representatives(m: &TriMesh) -> Vec<DVec3> {
    let n = m.vertex_count();
    let mut label: Vec<u32> = (0..n as u32).collect();
    // Relax labels to the minimum over triangles until stable (simple and obviously right).
    loop {
        let mut changed = false;
        for t in m.indices() {
            let lo = t
                .iter()
                .map(|&v| label[v as usize])
                .min()
                .expect("3 corners");
            for &v in t {
                if label[v as usize] != lo {
                    label[v as usize] = lo;
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
    let mut used = vec![false; n];
    for t in m.indices() {
        for &v in t {
            used[v as usize] = true;
        }
    }
    let mut seen = std::collections::HashSet::new();
    (0..n)
        .filter(|&v| used[v] && seen.insert(label[v]))
        .map(|v| m.vertices()[v])
        .collect()
}
