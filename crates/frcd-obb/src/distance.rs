//! Distance and tolerance queries between two posed OBB trees (PQP's `PQP_Distance` and
//! `PQP_Tolerance`).
//!
//! - [`distance`]: the smallest Euclidean distance between the two surfaces (0 when they touch
//!   or cross), the closest points (world coordinates) and the triangle pair they lie on;
//! - [`within`]: is that distance at most a tolerance? Decided **exactly** for the f64 inputs.
//!
//! ```
//! use frcd_obb::{BuildOptions, ObbTree, distance::{distance, within, DistanceRequest}};
//! use frcd_geom::{shapes, DVec3, Pose};
//! let mesh = shapes::cuboid(DVec3::splat(0.5));
//! let tree = ObbTree::build(&mesh, &BuildOptions::default());
//! let (pa, pb) = (Pose::IDENTITY, Pose::from_translation(DVec3::new(1.25, 0.0, 0.0)));
//! let d = distance(&tree, &pa, &tree, &pb, &DistanceRequest::default());
//! assert!((d.distance - 0.25).abs() <= d.error_bound);
//! assert!((d.points[0].x - 0.5).abs() < 1e-12 && (d.points[1].x - 0.75).abs() < 1e-12);
//! assert!(within(&tree, &pa, &tree, &pb, 0.25)); // exactly at the tolerance: within
//! assert!(!within(&tree, &pa, &tree, &pb, 0.2499999999999999));
//! ```
//!
//! # Frame and inputs
//!
//! As in [`crate::collide`], B's triangles are mapped once into A's frame with the f64 operations
//! of [`RelativeFrame`], so world offsets cost no precision. "The f64 inputs" below are A's local
//! vertices and B's vertices so mapped; [`within`] is exact for those, and the oracle
//! ([`crate::oracle::distance`]) maps B the same way.
//!
//! # Error bound of [`distance`]
//!
//! Let `M = |c_A| + |h_A| + |c_B| + |h_B| + |t|` (root box centres and half extents, relative
//! translation): every coordinate the query touches has magnitude at most `M`, and
//! `ε = 2⁻⁵³`. The returned `d` satisfies `|d - d*| <= error_bound = 64 ε M` (rel = abs = 0), where
//! `d*` is the exact distance of the f64 inputs, for pairs whose closest features are
//! well-conditioned (see below). Derivation:
//! 1. *Candidates are real point pairs.* Each leaf candidate is a pair of points built as
//!    `p + s (q - p)` with `s` clamped to `[0, 1]` (edges), or the foot `p - n h / |n|²` of a vertex
//!    inside a face: three roundings of quantities of size `<= 2M` each, so each point lies
//!    within `~6 ε M` of an exact point of its triangle, and the length adds `ε d`. Hence
//!    `d >= d* - 13 ε M - ε d`.
//! 2. *The true pair is not pruned.* A node pair is skipped only when a certified lower bound
//!    on its boxes' distance is at least the best value: the boxes' separating-axis gaps minus a
//!    slack of `1e-13 M ≈ 450 ε M`, which exceeds the rounding of the relative rotation, the
//!    boxes' own containment slack and the projections. So the pair holding the true closest
//!    points is evaluated, or the best value is already below it.
//! 3. *The true pair's candidate is accurate.* For the closest features, the clamped
//!    parameters differ from the exact ones by rounding of their numerators and denominators;
//!    the distance is stationary at the exact parameters, so the value moves by `~16 ε M` for
//!    well-conditioned features. Ill-conditioned features widen this: a vertex over the interior
//!    of a sliver face (area `A` much less than `L²` for edge length `L`) by a factor `L²/(2A)`
//!    (the face normal's direction is computed from rounded edges), and two edges crossing at a
//!    small angle `φ` by `1/φ` (the common perpendicular's feet); near-parallel edges are also
//!    caught by the endpoint candidates, so the loss is at most `~sqrt(ε) L` in the worst case.
//!    CAD meshes rarely put the closest pair there, and [`within`] is exact in every case.
//!
//! With `rel_err`, `abs_err > 0` a node pair is also skipped when its lower bound `lb` gives
//! `lb (1 + rel_err) >= best` or `lb + abs_err >= best` (PQP's rule), so
//! `d* - error_bound <= d <= d* (1 + rel_err) + abs_err + error_bound`.

#[path = "distance_exact.rs"]
mod exact;
#[path = "distance_tri.rs"]
mod tri;

use crate::query::RelativeFrame;
use crate::tree::ObbTree;
use exact::{Stage, triangles_within};
use frcd_geom::{DMat3, DVec3, Obb, Pose};
use tri::triangle_distance;

/// Options of [`distance`]. `Default`: exact (zero relative and absolute error).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct DistanceRequest {
    /// Allowed relative error: the answer may exceed the true distance by this fraction (plus
    /// `abs_err`). Values `<= 0` (and NaN) mean none.
    pub rel_err: f64,
    /// Allowed absolute error (scene units). Values `<= 0` (and NaN) mean none.
    pub abs_err: f64,
}

/// Work counters of a distance or tolerance query.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DistanceCounters {
    /// Box-pair lower bounds computed.
    pub box_tests: u64,
    /// Triangle pairs evaluated.
    pub tri_tests: u64,
    /// Triangle pairs that needed exact (big-integer) arithmetic ([`within`] only).
    pub exact_fallbacks: u64,
}

/// The answer of [`distance`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Distance {
    /// Smallest distance between the two surfaces (0 when they touch or cross).
    pub distance: f64,
    /// The triangle pair `(tri_a, tri_b)` (input-mesh indices) the closest points lie on.
    pub triangles: (u32, u32),
    /// The closest points in world coordinates: on A, on B (equal up to rounding when the
    /// surfaces touch or cross).
    pub points: [DVec3; 2],
    /// Bound on the floating-point error of `distance` (see the module docs): `64 ε M`.
    pub error_bound: f64,
    /// Work done.
    pub counters: DistanceCounters,
}

/// Distance between two posed trees, with closest points and their triangle pair.
///
/// `r` allows a relative and absolute error, which lets the search stop earlier (see the
/// module docs for the guarantee). Non-finite poses give a NaN distance.
pub fn distance(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    r: &DistanceRequest,
) -> Distance {
    let mut q = Query::new(a, pose_a, b, pose_b);
    let rel = if r.rel_err > 0.0 { r.rel_err } else { 0.0 };
    let abs = if r.abs_err > 0.0 { r.abs_err } else { 0.0 };
    let mut best = Best {
        d: f64::INFINITY,
        pair: (0, 0),
        pa: DVec3::NAN,
        pb: DVec3::NAN,
    };
    q.search(&mut best, rel, abs);
    if !best.d.is_finite() {
        // Non-finite input: report NaN rather than an arbitrary pair.
        best.d = f64::NAN;
    }
    Distance {
        distance: best.d,
        triangles: best.pair,
        points: [
            pose_a.transform_point(best.pa),
            pose_a.transform_point(best.pb),
        ],
        error_bound: q.error_bound(),
        counters: q.counters,
    }
}

/// True when the two surfaces come within `tolerance` of each other (touching counts, so touching
/// meshes are within every tolerance `>= 0`). Decided exactly for the f64 inputs (A's vertices
/// and B's vertices mapped into A's frame): a float filter with a certified error bound, and
/// big-integer arithmetic when the filter cannot decide. A negative or NaN tolerance gives
/// `false`; `+∞` gives `true`.
///
/// ```
/// use frcd_obb::{BuildOptions, ObbTree, distance::within};
/// use frcd_geom::{shapes, DVec3, Pose};
/// let t = ObbTree::build(&shapes::icosphere(1.0, 2), &BuildOptions::default());
/// let far = Pose::from_translation(DVec3::new(3.0, 0.0, 0.0));
/// assert!(within(&t, &Pose::IDENTITY, &t, &far, 1.0 + 1e-9));
/// assert!(!within(&t, &Pose::IDENTITY, &t, &far, 0.9));
/// ```
pub fn within(a: &ObbTree, pose_a: &Pose, b: &ObbTree, pose_b: &Pose, tolerance: f64) -> bool {
    within_counted(a, pose_a, b, pose_b, tolerance).0
}

/// [`within`] with its work counters.
pub fn within_counted(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    tolerance: f64,
) -> (bool, DistanceCounters) {
    if tolerance.is_nan() || tolerance < 0.0 {
        return (false, DistanceCounters::default());
    }
    if tolerance == f64::INFINITY {
        return (true, DistanceCounters::default());
    }
    let mut q = Query::new(a, pose_a, b, pose_b);
    let r = q.within(tolerance);
    (r, q.counters)
}

/// The best pair found so far (A's frame).
struct Best {
    d: f64,
    pair: (u32, u32),
    pa: DVec3,
    pb: DVec3,
}

/// A box of B mapped into A's frame.
#[derive(Clone, Copy)]
struct Placed {
    axes: DMat3,
    center: DVec3,
    half: DVec3,
}

struct Query<'a> {
    a: &'a ObbTree,
    b: &'a ObbTree,
    frame: RelativeFrame,
    /// Certified slack subtracted from every box lower bound.
    slack: f64,
    magnitude: f64,
    counters: DistanceCounters,
}

/// Relative slack of the box lower bounds (see the module docs, step 2).
const SLACK_REL: f64 = 1e-13;
/// Bound factor of the returned distance: `64 ε`.
const BOUND_REL: f64 = 64.0 * f64::EPSILON * 0.5;

fn obb_magnitude(o: &Obb) -> f64 {
    o.center.length() + o.half_extents.length()
}

impl<'a> Query<'a> {
    fn new(a: &'a ObbTree, pose_a: &Pose, b: &'a ObbTree, pose_b: &Pose) -> Self {
        let frame = RelativeFrame::new(pose_a, pose_b);
        let magnitude = obb_magnitude(&a.node_obb(a.root_node()))
            + obb_magnitude(&b.node_obb(b.root_node()))
            + frame.t.length();
        Query {
            a,
            b,
            frame,
            slack: SLACK_REL * magnitude,
            magnitude,
            counters: DistanceCounters::default(),
        }
    }

    fn error_bound(&self) -> f64 {
        BOUND_REL * self.magnitude
    }

    #[inline]
    fn place(&self, nb: u32) -> Placed {
        let o = self.b.node_obb(nb);
        Placed {
            axes: self.frame.m * o.axes,
            center: self.frame.m * o.center + self.frame.t,
            half: o.half_extents,
        }
    }

    /// A certified lower bound on the distance between A's node box and B's placed box (0 when
    /// they may overlap).
    #[inline]
    fn lower_bound(&mut self, na: u32, pb: &Placed) -> f64 {
        self.counters.box_tests += 1;
        box_lower_bound(&self.a.node_obb(na), pb, self.slack)
    }

    fn b_triangle(&self, t: u32) -> [DVec3; 3] {
        self.frame.triangle(&self.b.triangle(t)).v
    }

    /// Depth-first, nearer child pair first (PQP's order), pruning with the lower bounds.
    fn search(&mut self, best: &mut Best, rel: f64, abs: f64) {
        let prune = |lb: f64, best: f64| lb * (1.0 + rel) >= best || lb + abs >= best;
        let (ra, rb) = (self.a.root_node(), self.b.root_node());
        let pr = self.place(rb);
        let lb = self.lower_bound(ra, &pr);
        let mut stack: Vec<(u32, u32, f64)> = Vec::with_capacity(64);
        stack.push((ra, rb, lb));
        let mut kids_a: Vec<u32> = Vec::with_capacity(2);
        let mut kids_b: Vec<u32> = Vec::with_capacity(2);
        while let Some((na, nb, lb)) = stack.pop() {
            if prune(lb, best.d) {
                continue;
            }
            kids_a.clear();
            kids_a.extend(self.a.node_children(na));
            kids_b.clear();
            kids_b.extend(self.b.node_children(nb));
            if kids_a.is_empty() && kids_b.is_empty() {
                self.leaf_pair(na, nb, best);
                if best.d == 0.0 {
                    return;
                }
                continue;
            }
            // Split the larger node (or the one that is not a leaf).
            let split_a = if kids_a.is_empty() {
                false
            } else if kids_b.is_empty() {
                true
            } else {
                let sa = self.a.node_obb(na).half_extents.length_squared();
                let sb = self.b.node_obb(nb).half_extents.length_squared();
                sa >= sb
            };
            let mut children: [(u32, u32, f64); 4] = [(0, 0, 0.0); 4];
            let mut n = 0;
            if split_a {
                let pb = self.place(nb);
                for &ca in &kids_a {
                    let lb = self.lower_bound(ca, &pb);
                    children[n] = (ca, nb, lb);
                    n += 1;
                }
            } else {
                for &cb in &kids_b {
                    let pb = self.place(cb);
                    let lb = self.lower_bound(na, &pb);
                    children[n] = (na, cb, lb);
                    n += 1;
                }
            }
            let children = &mut children[..n];
            // Push the farther first so the nearer is popped next.
            children.sort_unstable_by(|x, y| y.2.total_cmp(&x.2));
            for &c in children.iter() {
                if !prune(c.2, best.d) {
                    stack.push(c);
                }
            }
        }
    }

    fn leaf_pair(&mut self, na: u32, nb: u32, best: &mut Best) {
        for &tb in self.b.node_triangles(nb) {
            let vb = self.b_triangle(tb);
            for &ta in self.a.node_triangles(na) {
                self.counters.tri_tests += 1;
                let va = self.a.triangle(ta).v;
                let (d, pa, pb) = triangle_distance(&va, &vb);
                if d < best.d {
                    *best = Best {
                        d,
                        pair: (ta, tb),
                        pa,
                        pb,
                    };
                    if d == 0.0 {
                        return;
                    }
                }
            }
        }
    }

    /// Depth-first, nearer child first; stops at the first triangle pair within `tol`.
    fn within(&mut self, tol: f64) -> bool {
        let (ra, rb) = (self.a.root_node(), self.b.root_node());
        let pr = self.place(rb);
        if self.lower_bound(ra, &pr) > tol {
            return false;
        }
        let mut stack: Vec<(u32, u32)> = Vec::with_capacity(64);
        stack.push((ra, rb));
        let mut kids_a: Vec<u32> = Vec::with_capacity(2);
        let mut kids_b: Vec<u32> = Vec::with_capacity(2);
        while let Some((na, nb)) = stack.pop() {
            kids_a.clear();
            kids_a.extend(self.a.node_children(na));
            kids_b.clear();
            kids_b.extend(self.b.node_children(nb));
            if kids_a.is_empty() && kids_b.is_empty() {
                for &tb in self.b.node_triangles(nb) {
                    let vb = self.b_triangle(tb);
                    for &ta in self.a.node_triangles(na) {
                        self.counters.tri_tests += 1;
                        let va = self.a.triangle(ta).v;
                        let (yes, stage) = triangles_within(&va, &vb, tol);
                        if stage == Stage::Exact {
                            self.counters.exact_fallbacks += 1;
                        }
                        if yes {
                            return true;
                        }
                    }
                }
                continue;
            }
            let split_a = if kids_a.is_empty() {
                false
            } else if kids_b.is_empty() {
                true
            } else {
                let sa = self.a.node_obb(na).half_extents.length_squared();
                let sb = self.b.node_obb(nb).half_extents.length_squared();
                sa >= sb
            };
            let mut children: [(u32, u32, f64); 4] = [(0, 0, 0.0); 4];
            let mut n = 0;
            if split_a {
                let pb = self.place(nb);
                for &ca in &kids_a {
                    children[n] = (ca, nb, self.lower_bound(ca, &pb));
                    n += 1;
                }
            } else {
                for &cb in &kids_b {
                    let pb = self.place(cb);
                    children[n] = (na, cb, self.lower_bound(na, &pb));
                    n += 1;
                }
            }
            let children = &mut children[..n];
            children.sort_unstable_by(|x, y| y.2.total_cmp(&x.2));
            for &(ca, cb, lb) in children.iter() {
                if lb <= tol {
                    stack.push((ca, cb));
                }
            }
        }
        false
    }
}

/// Lower bound on the distance between two boxes from their 15 separating axes: for a unit
/// direction `u`, the gap between the boxes' projections bounds their distance from below; the
/// largest gap over the face normals and the (normalised) edge cross products, each reduced
/// by `slack` before normalising, clamped at 0. Cross axes with `|a_i × b_j|² < 1e-6` are skipped: they are within 1e-3 rad of
/// a face axis, and their normalisation would amplify rounding.
#[inline]
fn box_lower_bound(a: &Obb, b: &Placed, slack: f64) -> f64 {
    let at = a.axes.transpose();
    let rm = at * b.axes; // column j = A^T B_j: R[i][j] = rm.col(j)[i]
    let t = at * (b.center - a.center);
    let c = [rm.x_axis, rm.y_axis, rm.z_axis];
    let r = |i: usize, j: usize| c[j][i];
    let ea = a.half_extents;
    let eb = b.half;
    let mut ar = [[0.0f64; 3]; 3];
    for (i, row) in ar.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = r(i, j).abs() + 1e-14;
        }
    }
    let mut gap = f64::NEG_INFINITY;
    // A's faces.
    for i in 0..3 {
        let g = t[i].abs() - (ea[i] + eb[0] * ar[i][0] + eb[1] * ar[i][1] + eb[2] * ar[i][2]);
        gap = gap.max(g - slack);
    }
    // B's faces.
    for j in 0..3 {
        let proj = (t[0] * r(0, j) + t[1] * r(1, j) + t[2] * r(2, j)).abs();
        let g = proj - (ea[0] * ar[0][j] + ea[1] * ar[1][j] + ea[2] * ar[2][j] + eb[j]);
        gap = gap.max(g - slack);
    }
    // Edge cross products a_i x b_j, normalised.
    for i in 0..3 {
        let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
        for j in 0..3 {
            let rij = r(i, j);
            let len2 = 1.0 - rij * rij;
            if len2 < 1e-6 {
                continue;
            }
            let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
            let proj = (t[i2] * r(i1, j) - t[i1] * r(i2, j)).abs();
            let rad =
                ea[i1] * ar[i2][j] + ea[i2] * ar[i1][j] + eb[j1] * ar[i][j2] + eb[j2] * ar[i][j1];
            // The slack covers the rounding of the unnormalised gap: subtract it first.
            let g = proj - rad - slack;
            if g > 0.0 {
                // len2 carries ~ε/1e-6 relative error: grow the divisor to stay a lower bound.
                gap = gap.max(g / (len2.sqrt() * (1.0 + 1e-9)));
            }
        }
    }
    gap.max(0.0)
}
