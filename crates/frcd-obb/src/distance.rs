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
//!    on the distance of its volumes (rectangle swept spheres, built lazily per tree: see
//!    `distance_rss.rs`) is at least the best value: the volumes' separation along a direction
//!    (the best pair's, or the rectangles' approximate closest-point direction) minus a slack
//!    of `1e-13 M ≈ 450 ε M`, which exceeds the rounding of the relative rotation, the
//!    volumes' own containment margin and the projections; a leaf's triangle pair is skipped on
//!    the same rule with the triangles' own vertices. So the pair holding the true closest
//!    points is evaluated, or the best value is already below it (or step 4 ended the search).
//! 3. *The true pair's candidate is accurate.* For the closest features, the clamped
//!    parameters differ from the exact ones by rounding of their numerators and denominators;
//!    the distance is stationary at the exact parameters, so the value moves by `~16 ε M` for
//!    well-conditioned features. Ill-conditioned features widen this: a vertex over the interior
//!    of a sliver face (area `A` much less than `L²` for edge length `L`) by a factor `L²/(2A)`
//!    (the face normal's direction is computed from rounded edges), and two edges crossing at a
//!    small angle `φ` by `1/φ` (the common perpendicular's feet); near-parallel edges are also
//!    caught by the endpoint candidates, so the loss is at most `~sqrt(ε) L` in the worst case.
//!    CAD meshes rarely put the closest pair there, and [`within`] is exact in every case.
//! 4. *Early end (support certificate).* When the best pair `(pa, pb)` improves, with `n` its
//!    unit direction, `L = min_B n · y - max_A n · x` over the meshes' vertices bounds the
//!    distance from below, and `L <= n · (pb - pa) = best`. A depth-first search on the
//!    volumes decides whether any vertex of A lies above `n · pa + τ` or any of B below
//!    `n · pb - τ` (`τ = 16 ε M`), stopping at the first one; when none does, `L >= best - 2τ`
//!    less `16 ε M` of rounding (dot products, `n`'s length, B's mapping), so
//!    `d* - 13 ε M <= d <= d* + 48 ε M` whatever the conditioning, and the search stops. This
//!    ends most searches between parts apart, whose closest points usually lie on both convex
//!    hulls.
//! 5. *Early exit of the leaf test.* A triangle pair's candidate is accepted before the other
//!    candidates are computed when the slab between its two points separates the triangles
//!    (every vertex at most `4 ε M` past its plane): nothing of the pair is closer by more than
//!    `8 ε M` plus the rounding of those dot products, inside the bound above.
//!
//! With `rel_err`, `abs_err > 0` a node pair is also skipped when its lower bound `lb` gives
//! `lb (1 + rel_err) >= best` or `lb + abs_err >= best` (PQP's rule), and the certificate's
//! `τ` grows by half of `max(abs_err, rel_err · best / (1 + rel_err))`, so
//! `d* - error_bound <= d <= d* (1 + rel_err) + abs_err + error_bound`.

#[path = "distance_exact.rs"]
mod exact;
#[path = "distance_rss.rs"]
pub(crate) mod rss;
#[path = "distance_tri.rs"]
mod tri;

use crate::query::RelativeFrame;
use crate::tree::ObbTree;
use exact::{Stage, triangles_within};
use frcd_geom::{DVec3, Obb, Pose};
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
    if let Some((ta, tb)) = seed
        && (ta as usize) < a.triangles().len()
        && (tb as usize) < b.triangles().len()
    {
        q.counters.tri_tests += 1;
        let (d, pa, pb) = triangle_distance(&a.triangle(ta).v, &q.b_triangle(tb), q.tri_tol);
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
    q.rel = rel;
    q.abs = abs;
    if best.d > 0.0 && !(best.d.is_finite() && q.certify(&best)) {
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

struct Query<'a> {
    a: &'a ObbTree,
    b: &'a ObbTree,
    va: &'a [rss::DNode],
    vb: &'a [rss::DNode],
    frame: RelativeFrame,
    /// Certified slack subtracted from every box lower bound.
    slack: f64,
    /// One more alternating projection in the volumes' lower bound (near contact, where the
    /// bound's direction matters; at range the cheaper bound is as good).
    refine: bool,
    /// How far a vertex may lie past a triangle pair's separating slab in the leaf test's
    /// early exit (`tri::triangle_features_early`): `4 ε M`.
    tri_tol: f64,
    magnitude: f64,
    /// Unit direction between the best closest points so far (A's frame).
    dir: Option<DVec3>,
    /// `dir` mapped into B's frame, and its offset: `dir · (m x + t) = dir_b · x + dir_t`.
    dir_b: DVec3,
    dir_t: f64,
    /// Set when a support certificate proved the best pair optimal (the search stops).
    proven: bool,
    /// Certificate attempts left in this query.
    certify_left: u32,
    /// Scratch stack of the support searches.
    support_stack: Vec<u32>,
    /// The last vertices (local frames) that failed the certificate, tried first next time.
    violator_a: Option<(DVec3, u32)>,
    violator_b: Option<(DVec3, u32)>,
    /// The root volumes are apart: every triangle pair is disjoint (no exact test needed).
    far: bool,
    /// Search B's side first in the next certificate (it failed last).
    b_first: bool,
    /// The caller's error allowances (for the certificate).
    rel: f64,
    abs: f64,
    counters: DistanceCounters,
}

/// How far past the best pair's projection a vertex may lie in the support certificate, per
/// side (`16 ε`, times `M`): the answer is then within `48 ε M` above the true distance,
/// inside the documented `64 ε M` (see `Query::certify`).
const CERT_TAU: f64 = 16.0 * f64::EPSILON * 0.5;

/// Support certificates tried per query, and the nodes each support search may visit: they
/// bound what a query that cannot be certified (closest points in a concavity, or a face
/// perpendicular to the direction) pays for trying.
const CERTIFY_TRIES: u32 = 64;
const SUPPORT_BUDGET: u32 = 4096;
/// Steps towards a failing certificate's vertices per improvement (`Query::step`). Measured:
/// 8 or 12 made the wagon-bogie "far" setups 2-6x faster but the icosphere-knot ones 2x
/// slower (median over setups); 4 is the compromise.
const STEPS: u32 = 4;

/// Slab allowance of the leaf test's early exit, times `M`: `4 ε` (module docs, step 3).
const TRI_TOL: f64 = 4.0 * f64::EPSILON * 0.5;
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
            tri_tol: TRI_TOL * magnitude,
            refine: true,
            magnitude,
            dir: None,
            dir_b: DVec3::ZERO,
            dir_t: 0.0,
            proven: false,
            certify_left: CERTIFY_TRIES,
            support_stack: Vec::new(),
            violator_a: None,
            violator_b: None,
            b_first: false,
            far: false,
            rel: 0.0,
            abs: 0.0,
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

    /// A certified lower bound on the distance between A's node volume and B's placed volume
    /// (negative when they may overlap): the larger of the volumes' separations along the best
    /// pair's direction and along the rectangles' approximate closest-point direction
    /// ([`rss::lower_bound`]), less the slack.
    #[inline]
    fn lower_bound(&mut self, na: u32, pb: &rss::Placed, enough: f64) -> f64 {
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
        let r = rss::lower_bound(va, pb, self.refine, enough + self.slack);
        g.max(r - self.slack)
    }

    /// [`Self::lower_bound`] for B's node `nb`, placed only when the bound along the best
    /// pair's direction does not already reach `enough`: that bound reads B's volume in its
    /// own frame (`dir_b`, `dir_t`: the direction mapped back; their rounding, a few `ε M`, is
    /// inside the slack), so a pair it prunes costs no mapping. `placed` caches the placement
    /// for the caller's next pair with the same `nb`.
    #[inline]
    fn lower_bound_lazy(
        &mut self,
        na: u32,
        nb: u32,
        placed: &mut Option<rss::Placed>,
        enough: f64,
    ) -> f64 {
        if let Some(n) = self.dir
            && placed.is_none()
        {
            self.counters.box_tests += 1;
            let va = &self.va[na as usize].rss;
            let vb = &self.vb[nb as usize].rss;
            let (db, dt) = (self.dir_b, self.dir_t);
            let cb = db.dot(vb.c) + dt;
            let eb = vb.a * db.dot(vb.u).abs() + vb.b * db.dot(vb.v).abs();
            let g = (cb - n.dot(va.c)).abs()
                - va.a * n.dot(va.u).abs()
                - va.b * n.dot(va.v).abs()
                - eb
                - va.r
                - vb.r
                - self.slack;
            if g >= enough {
                return g;
            }
            let pb = *placed.insert(self.place(nb));
            let r = rss::lower_bound(
                &self.va[na as usize].rss,
                &pb,
                self.refine,
                enough + self.slack,
            );
            return g.max(r - self.slack);
        }
        let pb = *placed.get_or_insert_with(|| self.place(nb));
        self.lower_bound(na, &pb, enough)
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
        let lb = self.lower_bound(ra, &pr, f64::INFINITY);
        let mut heap: BinaryHeap<Entry> = BinaryHeap::with_capacity(256);
        // The pair to expand next when it is no farther than the heap's top: the nearer child
        // of the pair just expanded usually is, and skips a push and a pop.
        let mut next = Some(Entry { lb, a: ra, b: rb });
        // Dives: the nearer child pair is expanded next even when the heap holds a nearer
        // pair, down to a leaf pair, so the first triangle pair (an upper bound and a direction
        // for the certificate and the bounds along it) comes after a few dozen volume pairs
        // instead of after the whole frontier below it. The first descent always dives; when
        // the root volumes are apart, every descent does (best-first by dives: at range the
        // bounds of many pairs are nearly equal, and a dive reaches the pair the certificate
        // accepts sooner), otherwise the search is best-first after the first leaf pair.
        self.far = lb > 0.0;
        let dive_always = self.far;
        self.refine = !self.far;
        let mut dive = true;
        while let Some(Entry { lb, a: na, b: nb }) = next.take().or_else(|| heap.pop()) {
            if prune(lb, best.d) {
                // Every other entry has a larger bound.
                break;
            }
            let (leaf_a, leaf_b) = (
                self.va[na as usize].is_leaf(),
                self.vb[nb as usize].is_leaf(),
            );
            if leaf_a && leaf_b {
                dive = dive_always;
                // A positive certified bound: the triangles cannot touch, skip the exact test.
                self.leaf_pair(na, nb, best, lb > 0.0);
                if best.d == 0.0 || self.proven {
                    return;
                }
                continue;
            }
            // Split the larger node (or the one that is not a leaf).
            let split_a = !leaf_a && (leaf_b || self.size_a(na) >= self.size_b(nb));
            let mut e = [Entry {
                lb: 0.0,
                a: 0,
                b: 0,
            }; 2];
            if split_a {
                let mut pb = None;
                for (k, ca) in self.va[na as usize].kids.into_iter().enumerate() {
                    let lb = self.lower_bound_lazy(ca, nb, &mut pb, enough(best.d));
                    e[k] = Entry { lb, a: ca, b: nb };
                }
            } else {
                for (k, cb) in self.vb[nb as usize].kids.into_iter().enumerate() {
                    let lb = self.lower_bound_lazy(na, cb, &mut None, enough(best.d));
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
                if k == 0 && (dive || heap.peek().is_none_or(|t| x.lb <= t.lb)) {
                    next = Some(x);
                } else {
                    heap.push(x);
                }
            }
        }
    }

    /// Support certificate: with `n` the best pair's direction and `pa`, `pb` its points, every
    /// point of A projects on `n` at most `max_A n · x` and every point of B at least
    /// `min_B n · y`, so `L = min_B n · y - max_A n · x` bounds the distance from below (the
    /// meshes' convex hulls are that far apart along `n`), and `L <= n · (pb - pa) = best`.
    /// The certificate is a decision: no vertex of A above `n · pa + τ` and none of B below
    /// `n · pb - τ` ([`rss::support_below`], which stops at the first vertex past its limit, so
    /// a failing try is cheap, and skips whole faces that tie the limit). Then `L >= best - 2τ`
    /// less rounding, and nothing is closer than the answer by more than the allowance: this
    /// happens when the best pair lies on both hulls facing each other (the usual case for
    /// parts apart). Rounding: the dot products of vertices and of the volumes' support bounds
    /// (`|x| <= M`), the unit length of `n`, `n · (pb - pa)` against `best` and B's mapping
    /// add at most `16 ε M`; with `τ = CERT_TAU = 16 ε M` the answer is then within `48 ε M`
    /// above the true distance (inside the documented `64 ε M`). With `rel_err` / `abs_err`,
    /// `τ` grows by half of what they allow.
    fn certify(&mut self, best: &Best) -> bool {
        let Some(n) = self.dir else {
            return false;
        };
        if self.certify_left == 0 {
            return false;
        }
        self.certify_left -= 1;
        self.counters.box_tests += 1;
        let allow = self.abs.max(self.rel * best.d / (1.0 + self.rel)) * (0.5 * 0.999);
        let tau = CERT_TAU * self.magnitude + allow;
        let lim_a = n.dot(best.pa) + tau;
        // For B: -n · (m y + t) <= -(n · pb - τ), i.e. (-dir_b) · y <= dir_t - n · pb + τ.
        let lim_b = self.dir_t - n.dot(best.pb) + tau;
        let nb = -self.dir_b;
        // The vertices that failed last time first (O(1)): in a concavity they keep failing.
        if self
            .violator_a
            .is_some_and(|(p, _)| rss::past(n.dot(p), lim_a))
            || self
                .violator_b
                .is_some_and(|(p, _)| rss::past(nb.dot(p), lim_b))
        {
            return false;
        }
        let side = |on_b: bool, q: &mut Self| {
            if on_b {
                rss::support_below(
                    q.vb,
                    q.b,
                    q.b.root_node(),
                    nb,
                    lim_b,
                    SUPPORT_BUDGET,
                    &mut q.support_stack,
                    &mut q.violator_b,
                )
            } else {
                rss::support_below(
                    q.va,
                    q.a,
                    q.a.root_node(),
                    n,
                    lim_a,
                    SUPPORT_BUDGET,
                    &mut q.support_stack,
                    &mut q.violator_a,
                )
            }
        };
        // The side that failed last time first: a passing side walks its whole cap, a failing
        // one stops at its first vertex.
        let first = self.b_first;
        let proven = side(first, self) && side(!first, self);
        if !proven {
            self.b_first = self.violator_b.is_some() && (first || self.violator_a.is_none());
        }
        self.proven |= proven;
        proven
    }

    /// After a failed certificate: a vertex that failed it lies past the best pair's plane, so
    /// its triangle against the best pair's other triangle may be closer (a step towards the
    /// closest pair of the hulls, as in Frank-Wolfe). A few such steps, each certified again,
    /// often end a search at range in a handful of triangle pairs (measured: half the time of
    /// the icosphere-knot "far" setups). Only the upper bound changes (each step is an exact
    /// triangle-pair distance), so the guarantee is untouched.
    fn step(&mut self, best: &mut Best) {
        for _ in 0..STEPS {
            let mut improved = false;
            let tries = [
                self.violator_a.map(|(_, t)| (t, best.pair.1)),
                self.violator_b.map(|(_, t)| (best.pair.0, t)),
            ];
            for (ta, tb) in tries.into_iter().flatten() {
                if (ta, tb) == best.pair {
                    continue;
                }
                let va = self.a.triangle(ta).v;
                let vb = self.b_triangle(tb);
                self.counters.tri_tests += 1;
                let (d, pa, pb) = if self.far {
                    // Roots apart: the triangles are disjoint.
                    let (d2, pa, pb) = tri::triangle_features_early(&va, &vb, self.tri_tol);
                    (d2.sqrt(), pa, pb)
                } else {
                    triangle_distance(&va, &vb, self.tri_tol)
                };
                if d < best.d {
                    *best = Best {
                        d,
                        pair: (ta, tb),
                        pa,
                        pb,
                    };
                    self.set_dir(pa, pb, d);
                    if self.certify(best) {
                        return;
                    }
                    improved = true;
                    break;
                }
            }
            if !improved {
                return;
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
                // Leaf short-cut: the triangles' separation along the best direction so far
                // (a certified lower bound up to the slack) often already prunes at range.
                // It also holds for volumes that may overlap: triangles that far apart
                // along `n` are disjoint, so their exact test is skipped too.
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
                let vb = *vb.get_or_insert_with(|| self.frame.triangle(&self.b.triangle(tb)).v);
                self.counters.tri_tests += 1;
                let (d, pa, pb) = if apart {
                    let (d2, pa, pb) = tri::triangle_features_early(&va, &vb, self.tri_tol);
                    (d2.sqrt(), pa, pb)
                } else {
                    triangle_distance(&va, &vb, self.tri_tol)
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
                    if self.certify(best) {
                        return;
                    }
                    self.step(best);
                    if self.proven {
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
        let enough = tol.next_up();
        if self.lower_bound(ra, &pr, enough) > tol {
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
                    children[n] = (ca, nb, self.lower_bound(ca, &pb, enough));
                    n += 1;
                }
            } else {
                for &cb in &kids_b {
                    let pb = self.place(cb);
                    children[n] = (na, cb, self.lower_bound(na, &pb, enough));
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
