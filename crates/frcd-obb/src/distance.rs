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
//! well-conditioned (see below), plus `2⁻⁴⁹⁶` for underflow (squared lengths of tiny and
//! subnormal gaps). Derivation:
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
#[path = "distance_rss.rs"]
pub(crate) mod rss;

use crate::query::RelativeFrame;
use crate::tree::ObbTree;
use exact::{Stage, triangles_within};
use frcd_geom::{DMat3, DVec3, Obb, Pose};
use std::collections::BinaryHeap;
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
    /// Bound on the floating-point error of `distance` (see the module docs): `64 ε M + 2⁻⁴⁹⁶`.
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
    run_distance(a, pose_a, b, pose_b, r, None, f64::INFINITY)
        .expect("an unbounded search always finds a pair")
}

/// Caller-owned warm start for [`distance_cached`]: the triangle pair of the previous answer.
///
/// The next query first evaluates that pair, so the search starts with a good upper bound and
/// prunes from the first box test. The pair only seeds the upper bound, so the guarantee is the
/// same as without a cache (on exact ties another pair of the same distance may be named); a
/// cache used with other trees is still safe (an out-of-range pair is ignored), just not useful.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DistanceCache {
    pair: Option<(u32, u32)>,
}

impl DistanceCache {
    /// An empty cache.
    pub fn new() -> Self {
        Self::default()
    }
    /// Forgets the stored pair.
    pub fn clear(&mut self) {
        self.pair = None;
    }
    /// The stored triangle pair, if any.
    pub fn pair(&self) -> Option<(u32, u32)> {
        self.pair
    }
}

/// [`distance`] starting from the triangle pair in `cache` (PQP's temporal coherence), and
/// storing this answer's pair there. Same guarantee as [`distance`].
pub fn distance_cached(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    r: &DistanceRequest,
    cache: &mut DistanceCache,
) -> Distance {
    let d = run_distance(a, pose_a, b, pose_b, r, cache.pair, f64::INFINITY)
        .expect("an unbounded search always finds a pair");
    cache.pair = d.distance.is_finite().then_some(d.triangles);
    d
}

/// [`distance`] when the surfaces may come within `limit` of each other; `None` when they are
/// farther apart than that. The search starts with `limit` as its upper bound, so node pairs
/// whose certified lower bound already exceeds it are never opened: a pair farther than `limit`
/// costs about what a [`within`] query costs instead of a full distance search (clearance
/// checks ask exactly this).
///
/// Guarantee: every triangle pair whose computed distance is below `limit` is considered, so
/// `Some(d)` is what [`distance`] returns (same bound), and `None` means the computed distance
/// of every triangle pair is at least `limit` (with `rel_err` / `abs_err`, at least `limit`
/// less those tolerances). Give `limit` a margin above a decision threshold
/// (e.g. `threshold + k * error_bound`) when the decision must account for rounding.
///
/// ```
/// use frcd_obb::distance::{distance_below, DistanceRequest};
/// use frcd_obb::{BuildOptions, ObbTree};
/// use frcd_geom::{shapes, DVec3, Pose};
/// let t = ObbTree::build(&shapes::icosphere(1.0, 2), &BuildOptions::default());
/// let far = Pose::from_translation(DVec3::new(5.0, 0.0, 0.0));
/// let r = DistanceRequest::default();
/// assert!(distance_below(&t, &Pose::IDENTITY, &t, &far, &r, 1.0).is_none());
/// let d = distance_below(&t, &Pose::IDENTITY, &t, &far, &r, 4.0).unwrap();
/// assert!((d.distance - 3.0).abs() < 1e-2); // icosphere vertices lie on the unit sphere
/// ```
pub fn distance_below(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    r: &DistanceRequest,
    limit: f64,
) -> Option<Distance> {
    if limit.is_nan() {
        return None;
    }
    run_distance(a, pose_a, b, pose_b, r, None, limit)
}

fn run_distance(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    r: &DistanceRequest,
    seed: Option<(u32, u32)>,
    limit: f64,
) -> Option<Distance> {
    let mut q = Query::new(a, pose_a, b, pose_b);
    let rel = if r.rel_err > 0.0 { r.rel_err } else { 0.0 };
    let abs = if r.abs_err > 0.0 { r.abs_err } else { 0.0 };
    // With a finite `limit` the search starts from it as its upper bound: no pair found below it
    // leaves `pa` NaN, and the answer is `None`.
    let mut best = Best {
        d: limit,
        pair: (0, 0),
        pa: DVec3::NAN,
        pb: DVec3::NAN,
    };
    if let Some((ta, tb)) = seed {
        if (ta as usize) < a.triangles().len() && (tb as usize) < b.triangles().len() {
            q.counters.tri_tests += 1;
            let (d, pa, pb) = triangle_distance(&a.triangle(ta).v, &q.b_triangle(tb));
            if d < best.d {
                best = Best {
                    d,
                    pair: (ta, tb),
                    pa,
                    pb,
                };
                q.set_dir(pa, pb, d);
            }
        }
    }
    if best.d > 0.0 {
        q.search(&mut best, rel, abs);
    }
    if limit.is_finite() && best.pa.is_nan() {
        return None;
    }
    if !best.d.is_finite() {
        // Non-finite input: report NaN rather than an arbitrary pair.
        best.d = f64::NAN;
    }
    Some(Distance {
        distance: best.d,
        triangles: best.pair,
        points: [
            pose_a.transform_point(best.pa),
            pose_a.transform_point(best.pb),
        ],
        error_bound: q.error_bound(),
        counters: q.counters,
    })
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

/// A node pair waiting in the best-first heap (smallest bound first).
#[derive(Clone, Copy)]
struct Entry {
    lb: f64,
    a: u32,
    b: u32,
}

impl PartialEq for Entry {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == std::cmp::Ordering::Equal
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Entry {
    /// Reversed, so `BinaryHeap` (a max-heap) pops the smallest bound.
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        o.lb.total_cmp(&self.lb)
    }
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
    va: &'a [rss::DNode],
    vb: &'a [rss::DNode],
    frame: RelativeFrame,
    /// Certified slack subtracted from every box lower bound.
    slack: f64,
    magnitude: f64,
    /// Unit direction between the best closest points so far (A's frame).
    dir: Option<DVec3>,
    /// `dir` mapped into B's frame, and its offset: `dir · (m x + t) = dir_b · x + dir_t`.
    dir_b: DVec3,
    dir_t: f64,
    counters: DistanceCounters,
}

fn mode() -> u32 {
    static M: std::sync::OnceLock<u32> = std::sync::OnceLock::new();
    *M.get_or_init(|| std::env::var("FRCD_DMODE").ok().and_then(|v| v.parse().ok()).unwrap_or(0))
}

/// Relative slack of the box lower bounds (see the module docs, step 2).
const SLACK_REL: f64 = 1e-13;
/// Bound factor of the returned distance: `64 ε`.
const BOUND_REL: f64 = 64.0 * f64::EPSILON * 0.5;
/// Absolute part of the bound: squared lengths below `2⁻¹⁰⁰⁰` lose their precision to
/// underflow, and the square root turns an absolute error `c · 2⁻¹⁰⁰⁰` into at most
/// `sqrt(c) · 2⁻⁵⁰⁰`.
const UNDERFLOW_ABS: f64 = f64::from_bits((1023 - 496) << 52);

/// The `error_bound` that [`distance`] would report for this pair of trees and poses, without
/// running the query (it depends only on the scene's magnitude): for choosing the `limit` of
/// [`distance_below`] around a decision threshold.
pub fn error_bound(a: &ObbTree, pose_a: &Pose, b: &ObbTree, pose_b: &Pose) -> f64 {
    Query::new(a, pose_a, b, pose_b).error_bound()
}

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
            va: a.distance_volumes(),
            vb: b.distance_volumes(),
            frame,
            slack: SLACK_REL * magnitude,
            magnitude,
            dir: None,
            dir_b: DVec3::ZERO,
            dir_t: 0.0,
            counters: DistanceCounters::default(),
        }
    }

    fn error_bound(&self) -> f64 {
        BOUND_REL * self.magnitude + UNDERFLOW_ABS
    }

    #[inline]
    fn place(&self, nb: u32) -> rss::Placed {
        self.vb[nb as usize].rss.mapped(&self.frame.m, self.frame.t)
    }

    #[inline]
    fn place_box(&self, nb: u32) -> Placed {
        let o = self.b.node_obb(nb);
        Placed {
            axes: self.frame.m * o.axes,
            center: self.frame.m * o.center + self.frame.t,
            half: o.half_extents,
        }
    }

    /// A certified lower bound on the distance between A's node box and B's placed box
    /// (negative when they may overlap, see [`box_lower_bound`]).
    #[inline]
    fn lower_bound(&mut self, na: u32, nb: u32, pb: &rss::Placed, enough: f64) -> f64 {
        self.counters.box_tests += 1;
        let va = &self.va[na as usize].rss;
        // The best pair's direction first: at range every pair near the closest region is
        // separated along it, and it costs a few products (no dependent chain).
        let mut g = f64::NEG_INFINITY;
        if let Some(n) = self.dir {
            g = rss::gap_along(va, pb, n) - self.slack;
            if g >= enough {
                return g;
            }
        }
        let (r, _) = rss::lower_bound(va, pb);
        g = g.max(r - self.slack);
        if g >= enough || mode() & 1 == 0 {
            return g;
        }
        let pbox = self.place_box(nb);
        g.max(box_lower_bound(&self.a.node_obb(na), &pbox, self.slack, enough, self.dir))
    }

    /// Children of A's node (none for a leaf).
    #[inline(always)]
    fn kids_a(&self, n: u32) -> impl Iterator<Item = u32> {
        let d = &self.va[n as usize];
        d.kids.into_iter().take(if d.is_leaf() { 0 } else { 2 })
    }
    #[inline(always)]
    fn kids_b(&self, n: u32) -> impl Iterator<Item = u32> {
        let d = &self.vb[n as usize];
        d.kids.into_iter().take(if d.is_leaf() { 0 } else { 2 })
    }

    /// Squared size of a node's volume (which node of a pair to split).
    #[inline]
    fn size_a(&self, n: u32) -> f64 {
        let v = &self.va[n as usize].rss;
        v.a * v.a + v.b * v.b + v.r * v.r
    }
    #[inline]
    fn size_b(&self, n: u32) -> f64 {
        let v = &self.vb[n as usize].rss;
        v.a * v.a + v.b * v.b + v.r * v.r
    }

    fn b_triangle(&self, t: u32) -> [DVec3; 3] {
        self.frame.triangle(&self.b.triangle(t)).v
    }

    /// Best-first over node pairs (a min-heap on the lower bound): a pair is expanded only while
    /// its bound is below the best distance found, and the pairs most likely to hold the closest
    /// points are expanded first, so fewer pairs are expanded than in depth-first order.
    fn search(&mut self, best: &mut Best, rel: f64, abs: f64) {
        let prune = |lb: f64, best: f64| lb * (1.0 + rel) >= best || lb + abs >= best;
        // A bound at or above this prunes (used to stop the box test early).
        let enough = |best: f64| (best / (1.0 + rel)).min(best - abs);
        let (ra, rb) = (self.a.root_node(), self.b.root_node());
        let pr = self.place(rb);
        let lb = self.lower_bound(ra, rb, &pr, f64::INFINITY);
        if mode() & 4 != 0 {
            return self.search_depth_first(best, rel, abs, lb);
        }
        let mut heap: BinaryHeap<Entry> = BinaryHeap::with_capacity(256);
        // The pair to expand next when it is no farther than the heap's top: the nearer child
        // of the pair just expanded usually is, and skips a push and a pop.
        let mut next = Some(Entry { lb, a: ra, b: rb });
        loop {
            let Some(Entry { lb, a: na, b: nb }) = next.take().or_else(|| heap.pop()) else {
                break;
            };
            if prune(lb, best.d) {
                // Every other entry has a larger bound.
                break;
            }
            let (leaf_a, leaf_b) = (
                self.va[na as usize].is_leaf(),
                self.vb[nb as usize].is_leaf(),
            );
            if leaf_a && leaf_b {
                // A positive certified bound: the triangles cannot touch, skip the exact test.
                self.leaf_pair(na, nb, best, lb > 0.0);
                if best.d == 0.0 {
                    return;
                }
                continue;
            }
            // Split the larger node (or the one that is not a leaf).
            let split_a = !leaf_a && (leaf_b || self.size_a(na) >= self.size_b(nb));
            let mut e = [Entry { lb: 0.0, a: 0, b: 0 }; 2];
            if split_a {
                let pb = self.place(nb);
                for (k, ca) in self.va[na as usize].kids.into_iter().enumerate() {
                    let lb = self.lower_bound(ca, nb, &pb, enough(best.d));
                    e[k] = Entry { lb, a: ca, b: nb };
                }
            } else {
                for (k, cb) in self.vb[nb as usize].kids.into_iter().enumerate() {
                    let pb = self.place(cb);
                    let lb = self.lower_bound(na, cb, &pb, enough(best.d));
                    e[k] = Entry { lb, a: na, b: cb };
                }
            }
            if e[1].lb < e[0].lb {
                e.swap(0, 1);
            }
            for (k, x) in e.into_iter().enumerate() {
                if prune(x.lb, best.d) {
                    break; // sorted: the other is farther still
                }
                if k == 0 && heap.peek().is_none_or(|t| x.lb <= t.lb) {
                    next = Some(x);
                } else {
                    heap.push(x);
                }
            }
        }
    }

    /// Depth-first, nearer child pair first (PQP's order with a queue of size 2): no heap.
    fn search_depth_first(&mut self, best: &mut Best, rel: f64, abs: f64, root_lb: f64) {
        let prune = |lb: f64, best: f64| lb * (1.0 + rel) >= best || lb + abs >= best;
        let enough = |best: f64| (best / (1.0 + rel)).min(best - abs);
        let mut stack: Vec<Entry> = Vec::with_capacity(128);
        stack.push(Entry {
            lb: root_lb,
            a: self.a.root_node(),
            b: self.b.root_node(),
        });
        let mut kids_a: Vec<u32> = Vec::with_capacity(2);
        let mut kids_b: Vec<u32> = Vec::with_capacity(2);
        while let Some(Entry { lb, a: na, b: nb }) = stack.pop() {
            if prune(lb, best.d) {
                continue;
            }
            kids_a.clear();
            kids_a.extend(self.kids_a(na));
            kids_b.clear();
            kids_b.extend(self.kids_b(nb));
            if kids_a.is_empty() && kids_b.is_empty() {
                self.leaf_pair(na, nb, best, lb > 0.0);
                if best.d == 0.0 {
                    return;
                }
                continue;
            }
            let split_a = if kids_a.is_empty() {
                false
            } else if kids_b.is_empty() {
                true
            } else {
                self.size_a(na) >= self.size_b(nb)
            };
            let mut e = [Entry { lb: 0.0, a: 0, b: 0 }; 2];
            let mut n = 0;
            if split_a {
                let pb = self.place(nb);
                for &ca in &kids_a {
                    let lb = self.lower_bound(ca, nb, &pb, enough(best.d));
                    e[n] = Entry { lb, a: ca, b: nb };
                    n += 1;
                }
            } else {
                for &cb in &kids_b {
                    let pb = self.place(cb);
                    let lb = self.lower_bound(na, cb, &pb, enough(best.d));
                    e[n] = Entry { lb, a: na, b: cb };
                    n += 1;
                }
            }
            // Farther first onto the stack, so the nearer pair is expanded first.
            if n == 2 && e[0].lb < e[1].lb {
                e.swap(0, 1);
            }
            for x in &e[..n] {
                if !prune(x.lb, best.d) {
                    stack.push(*x);
                }
            }
        }
    }

    fn set_dir(&mut self, pa: DVec3, pb: DVec3, d: f64) {
        let n = (pb - pa) / d;
        self.dir = (d > 0.0 && n.is_finite()).then_some(n);
        if let Some(n) = self.dir {
            // n · (m x + t) = (mᵀ n) · x + n · t for B's local points x.
            self.dir_b = self.frame.m.transpose() * n;
            self.dir_t = n.dot(self.frame.t);
        }
    }

    fn leaf_pair(&mut self, na: u32, nb: u32, best: &mut Best, apart: bool) {
        for &tb in self.b.node_triangles(nb) {
            let lb_tri = self.b.triangle(tb).v;
            let mut vb: Option<[DVec3; 3]> = None;
            for &ta in self.a.node_triangles(na) {
                let va = self.a.triangle(ta).v;
                if apart {
                    // Leaf short-cut: the triangles' separation along the best direction so far
                    // (a certified lower bound up to the slack) often already prunes at range.
                    // B's triangle is projected in its own frame (`dir_b`, `dir_t`: the
                    // direction mapped back), so a pruned pair costs no mapping.
                    if let Some(n) = self.dir {
                        let (a0, a1, a2) = (n.dot(va[0]), n.dot(va[1]), n.dot(va[2]));
                        let (b0, b1, b2) = (
                            self.dir_b.dot(lb_tri[0]) + self.dir_t,
                            self.dir_b.dot(lb_tri[1]) + self.dir_t,
                            self.dir_b.dot(lb_tri[2]) + self.dir_t,
                        );
                        let (alo, ahi) = (a0.min(a1).min(a2), a0.max(a1).max(a2));
                        let (blo, bhi) = (b0.min(b1).min(b2), b0.max(b1).max(b2));
                        if (blo - ahi).max(alo - bhi) - self.slack >= best.d {
                            continue;
                        }
                    }
                }
                let vb = *vb.get_or_insert_with(|| self.frame.triangle(&self.b.triangle(tb)).v);
                self.counters.tri_tests += 1;
                let (d, pa, pb) = if apart {
                    let (d2, pa, pb) = tri::triangle_features(&va, &vb);
                    (d2.sqrt(), pa, pb)
                } else {
                    triangle_distance(&va, &vb)
                };
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
                    self.set_dir(pa, pb, d);
                }
            }
        }
    }

    /// Depth-first, nearer child first; stops at the first triangle pair within `tol`.
    fn within(&mut self, tol: f64) -> bool {
        let (ra, rb) = (self.a.root_node(), self.b.root_node());
        let pr = self.place(rb);
        let enough = tol.next_up();
        if self.lower_bound(ra, rb, &pr, enough) > tol {
            return false;
        }
        let mut stack: Vec<(u32, u32)> = Vec::with_capacity(64);
        stack.push((ra, rb));
        let mut kids_a: Vec<u32> = Vec::with_capacity(2);
        let mut kids_b: Vec<u32> = Vec::with_capacity(2);
        while let Some((na, nb)) = stack.pop() {
            kids_a.clear();
            kids_a.extend(self.kids_a(na));
            kids_b.clear();
            kids_b.extend(self.kids_b(nb));
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
                self.size_a(na) >= self.size_b(nb)
            };
            let mut children: [(u32, u32, f64); 4] = [(0, 0, 0.0); 4];
            let mut n = 0;
            if split_a {
                let pb = self.place(nb);
                for &ca in &kids_a {
                    children[n] = (ca, nb, self.lower_bound(ca, nb, &pb, enough));
                    n += 1;
                }
            } else {
                for &cb in &kids_b {
                    let pb = self.place(cb);
                    children[n] = (na, cb, self.lower_bound(na, cb, &pb, enough));
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

/// Lower bound on the distance between two boxes from 16 axes (the centre-to-centre direction
/// and the 15 separating axes): for a unit direction `u`, the gap between the boxes'
/// projections bounds their distance from below. The largest gap over these directions
/// (the edge cross products normalised), each reduced by
/// `slack` before normalising. Negative when the boxes may overlap (callers treat it as 0 for
/// pruning and use it to visit deeper overlaps first). Returns as soon as an axis reaches
/// `enough` (the caller prunes at that value anyway). Cross axes with `|a_i × b_j|² < 1e-6` are skipped:
/// they are within 1e-3 rad of a face axis, and their normalisation would amplify rounding.
#[inline]
fn box_lower_bound(a: &Obb, b: &Placed, slack: f64, enough: f64, dir: Option<DVec3>) -> f64 {
    let at = a.axes.transpose();
    let rm = at * b.axes; // column j = A^T B_j: R[i][j] = rm.col(j)[i]
    let t = at * (b.center - a.center);
    let c = [rm.x_axis, rm.y_axis, rm.z_axis];
    let mut r = [[0.0f64; 3]; 3];
    let mut ar = [[0.0f64; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = c[j][i];
            ar[i][j] = c[j][i].abs() + 1e-14;
        }
    }
    let ea = a.half_extents;
    let eb = b.half;
    // Signed: negative when every axis overlaps (then the least overlap, a depth-like value
    // that orders overlapping pairs deepest first).
    let mut gap = f64::NEG_INFINITY;
    // The centre-to-centre direction first: nearly tight for boxes far apart compared with their
    // size, where the 15 SAT axes can underestimate the distance by up to a factor sqrt(3).
    let tl = t.length();
    if tl > 0.0 {
        let u = t / tl;
        let rad_a = ea.x * u.x.abs() + ea.y * u.y.abs() + ea.z * u.z.abs();
        let mut rad_b = 0.0;
        for j in 0..3 {
            // |B_j · u|, with R's rounding (a few ε per entry) covered by 3e-14.
            rad_b += eb[j] * ((r[0][j] * u.x + r[1][j] * u.y + r[2][j] * u.z).abs() + 3e-14);
        }
        // u itself is unit only up to a few ε: its error moves the projections by ε·|t|,
        // covered by the slack like every other rounding of size ε M.
        gap = gap.max(tl - rad_a - rad_b - slack);
        if gap >= enough {
            return gap;
        }
    }
    // The direction of the best closest pair so far (A's frame, unit): node pairs around the
    // closest region are separated along it.
    if let Some(n) = dir {
        let proj = (b.center - a.center).dot(n).abs();
        let rad_a = (at * n).abs().dot(ea);
        let rad_b = (b.axes.transpose() * n).abs().dot(eb);
        gap = gap.max(proj - rad_a - rad_b - slack);
        if gap >= enough {
            return gap;
        }
    }
    // A's faces.
    for i in 0..3 {
        let g = t[i].abs() - (ea[i] + eb[0] * ar[i][0] + eb[1] * ar[i][1] + eb[2] * ar[i][2]);
        gap = gap.max(g - slack);
    }
    // B's faces.
    for j in 0..3 {
        let proj = (t[0] * r[0][j] + t[1] * r[1][j] + t[2] * r[2][j]).abs();
        let g = proj - (ea[0] * ar[0][j] + ea[1] * ar[1][j] + ea[2] * ar[2][j] + eb[j]);
        gap = gap.max(g - slack);
    }
    if gap >= enough {
        return gap;
    }
    // Edge cross products a_i x b_j, normalised (the square root only when the axis can win).
    for i in 0..3 {
        let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
        for j in 0..3 {
            let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
            let proj = (t[i2] * r[i1][j] - t[i1] * r[i2][j]).abs();
            let rad =
                ea[i1] * ar[i2][j] + ea[i2] * ar[i1][j] + eb[j1] * ar[i][j2] + eb[j2] * ar[i][j1];
            // The slack covers the rounding of the unnormalised gap: subtract it first.
            let g = proj - rad - slack;
            if g <= 0.0 {
                continue;
            }
            let rij = r[i][j];
            let len2 = 1.0 - rij * rij;
            // |L| <= 1, so g / |L| >= g: only axes with g·g > gap²·|L|² can raise a positive
            // bound.
            if len2 < 1e-6 || (gap > 0.0 && g * g <= gap * gap * len2) {
                continue;
            }
            // len2 carries ~ε/1e-6 relative error: grow the divisor to stay a lower bound.
            gap = g / (len2.sqrt() * (1.0 + 1e-9));
            if gap >= enough {
                return gap;
            }
        }
    }
    gap
}
