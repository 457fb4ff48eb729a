//! Pair queries between two OBB trees: boolean first contact or every touching triangle pair,
//! with the hybrid top volume, optional solid-mode containment and a caller-owned coherence
//! cache.

use crate::isa;
use crate::nodes::TNode;
use crate::sat::{self, Placed, SLACK_REL};
use crate::solid::point_inside_tree;
use crate::tree::ObbTree;
use crate::wide::{self, ALanes, BLanes, NO_QUAD, Sat32, quad_ids};
use frcd_geom::{Aabb, DMat3, DVec3, Pose, Triangle};
use frcd_tritri::{Contact, Method};

/// What a pair query looks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Mode {
    /// Stop at the first touching triangle pair (boolean answer plus one witness pair).
    #[default]
    FirstContact,
    /// Every touching triangle pair.
    AllPairs,
}

/// Which bounding volumes are tested before the root OBB pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum TopVolume {
    /// Bounding spheres, then the bodies' axis-aligned boxes, then the root OBBs (cheapest first).
    #[default]
    Hybrid,
    /// The root OBB pair only.
    RootObb,
}

/// Options of a pair query.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Request {
    /// First contact or all pairs.
    pub mode: Mode,
    /// Also compute the intersection segment of every reported pair.
    pub segments: bool,
    /// Triangle-triangle test. Only [`Method::Exact`] makes the answer equal the oracle's.
    #[cfg_attr(feature = "serde", serde(with = "method_serde"))]
    pub method: Method,
    /// Treat closed meshes as solids: when no surface pair touches, report one mesh lying inside
    /// the other (a point-in-mesh parity test on exact predicates). A mesh that is not closed
    /// cannot contain anything.
    pub solid: bool,
    /// Bounding volumes tested before the root OBB pair.
    pub top_volume: TopVolume,
}

/// `Method` (frcd-tritri has no serde feature) as its `Debug` name.
#[cfg(feature = "serde")]
mod method_serde {
    use frcd_tritri::Method;
    pub fn serialize<S: serde::Serializer>(m: &Method, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&format!("{m:?}"))
    }
    pub fn deserialize<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Method, D::Error> {
        let name = <String as serde::Deserialize>::deserialize(d)?;
        Method::ALL
            .iter()
            .copied()
            .find(|m| format!("{m:?}") == name)
            .ok_or_else(|| serde::de::Error::custom(format!("unknown triangle test {name:?}")))
    }
}

/// Which body lies inside which (solid mode, no touching surface pair).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Containment {
    /// A connected component of B lies inside A.
    BInsideA,
    /// A connected component of A lies inside B.
    AInsideB,
}

/// Work counters of a query, for benchmarking.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Counters {
    /// Sphere and AABB tests of the hybrid top volume.
    pub top_tests: u64,
    /// OBB-OBB separating-axis tests: box pairs decided. The wide traversal decides up to
    /// four pairs in one four-lane test; each lane in use counts as one box test (so the count
    /// compares with the binary traversal's, and time per box test is time per pair decided).
    pub box_tests: u64,
    /// Triangle-triangle tests (after the exact per-pair box check).
    pub tri_tests: u64,
    /// B boxes mapped into A's frame (a 3x3 product each; one per lane when placed in lanes).
    pub placements: u64,
}

impl Counters {
    /// One time-free number for the work of a query, in units of about one box test: box tests
    /// and placements count one, a triangle test four (the exact test costs about four box
    /// tests). Used by the coherence cache's budget and by tests comparing cached and plain
    /// queries.
    pub fn work(&self) -> u64 {
        self.top_tests / 4 + self.box_tests + self.placements + 4 * self.tri_tests
    }
}

impl core::ops::AddAssign for Counters {
    fn add_assign(&mut self, o: Counters) {
        self.top_tests += o.top_tests;
        self.box_tests += o.box_tests;
        self.tri_tests += o.tri_tests;
        self.placements += o.placements;
    }
}

/// The answer of a pair query.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Collision {
    /// True when the bodies interfere: a surface pair touches, or (solid mode) one lies inside
    /// the other.
    pub collide: bool,
    /// [`Mode::AllPairs`]: every touching pair `(tri_a, tri_b)` (input-mesh indices), sorted
    /// ascending. Empty in [`Mode::FirstContact`], whose answer is `collide` and `witness`.
    pub pairs: Vec<(u32, u32)>,
    /// A touching pair, when there is one ([`Mode::FirstContact`]: the first one found, which
    /// may depend on the cache; [`Mode::AllPairs`]: the first of `pairs`).
    pub witness: Option<(u32, u32)>,
    /// With [`Request::segments`]: the contact (point, segment, or coplanar overlap polygon) of
    /// each pair of `pairs` (AllPairs) or of the witness (FirstContact), in A's frame, in the
    /// same order ([`frcd_tritri::intersection_segment`]; `None` only where a non-exact
    /// `method` reported a pair the exact test rejects).
    pub segments: Vec<Option<Contact>>,
    /// Solid mode: which body lies inside the other, when no surface pair touches.
    pub contained: Option<Containment>,
    /// Work done.
    pub counters: Counters,
}

/// How B's geometry is mapped into A's frame: `p_a = m * p_b + t` with
/// `m = rel.rotation_matrix()`, `t = rel.translation`, `rel = pose_b.relative_to(pose_a)`.
///
/// Every CPU path (the OBB traversal and [`crate::oracle`]) maps triangles with exactly these
/// operations, so the exact triangle test sees the same f64 coordinates in both.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RelativeFrame {
    /// Rotation from B's frame to A's (internal: read it with [`RelativeFrame::rotation`]).
    #[doc(hidden)]
    pub m: DMat3,
    /// B's origin in A's frame (internal: read it with [`RelativeFrame::translation`]).
    #[doc(hidden)]
    pub t: DVec3,
}

impl RelativeFrame {
    /// The frame mapping B-local points to A-local points.
    pub fn new(pose_a: &Pose, pose_b: &Pose) -> Self {
        let rel = pose_b.relative_to(pose_a);
        Self {
            m: rel.rotation_matrix(),
            t: rel.translation,
        }
    }

    /// Rotation from B's frame to A's.
    pub fn rotation(&self) -> DMat3 {
        self.m
    }

    /// B's origin in A's frame.
    pub fn translation(&self) -> DVec3 {
        self.t
    }

    /// Maps a B-local point into A's frame.
    #[inline(always)]
    pub fn point(&self, p: DVec3) -> DVec3 {
        self.m * p + self.t
    }

    /// Maps a B-local triangle into A's frame.
    #[inline(always)]
    pub fn triangle(&self, t: &Triangle) -> Triangle {
        Triangle::new(self.point(t.v[0]), self.point(t.v[1]), self.point(t.v[2]))
    }

    /// A box holding the images of every point of a B-local box, grown by `slack`.
    pub fn aabb(&self, b: &Aabb, slack: f64) -> Aabb {
        let c = self.point(b.center());
        let m = self.m;
        let abs = DMat3::from_cols(m.x_axis.abs(), m.y_axis.abs(), m.z_axis.abs());
        let e = abs * b.half_extents() + DVec3::splat(slack);
        Aabb::new(c - e, c + e)
    }
}

/// Separation margin of a query: see the `sat` module's error bound.
pub(crate) fn query_slack(a: &ObbTree, b: &ObbTree, frame: &RelativeFrame) -> f64 {
    // The absolute floor covers subnormal coordinates, whose rounding is absolute.
    SLACK_REL * (a.radius_from_origin + b.radius_from_origin + frame.t.length())
        + frcd_geom::ABSOLUTE_SLACK
}

/// A traversal front: the node pairs where a traversal stopped (a cut of the traversal tree:
/// every leaf pair lies below exactly one of them), with one bound per pair. Two parallel
/// arrays rather than one of entries, so that the walk's scan for expired pairs (most of a
/// coherent front's pairs are only read) compares eight bounds at a time.
#[derive(Clone, Debug, Default)]
struct Front {
    /// Node pairs (A, B).
    pairs: Vec<(u32, u32)>,
    /// For a separated pair: the pair stays separated while the cache's motion clock plus the
    /// query's slack stays below this value (clock at the test + separation margin). -∞ for
    /// the others (a leaf pair whose boxes overlapped, a pair left untested after a hit):
    /// always traversed again.
    bounds: Vec<f64>,
}

impl Front {
    fn len(&self) -> usize {
        self.pairs.len()
    }

    fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }

    fn clear(&mut self) {
        self.pairs.clear();
        self.bounds.clear();
    }

    #[inline(always)]
    fn push(&mut self, a: u32, b: u32, bound: f64) {
        self.pairs.push((a, b));
        self.bounds.push(bound);
    }

    /// The first index in `from..end` whose pair is not known separated at `limit` (the
    /// clock plus the query's slack; a NaN bound counts as expired), or `end`.
    #[inline]
    fn next_expired(&self, from: usize, end: usize, limit: f64) -> usize {
        let bounds = &self.bounds[..end];
        let mut k = from;
        // Eight at a time without a branch per pair (vectorised); the chunk that holds one is
        // searched pair by pair.
        while let Some(chunk) = bounds.get(k..k + 8) {
            if chunk.iter().fold(false, |any, &x| any | expired(limit, x)) {
                break;
            }
            k += 8;
        }
        while k < bounds.len() && !expired(limit, bounds[k]) {
            k += 1;
        }
        k
    }
}

impl Front {
    /// How many pairs in `..end` are not known separated at `limit` (as in
    /// [`Front::next_expired`]).
    fn count_expired(&self, end: usize, limit: f64) -> usize {
        self.bounds[..end]
            .iter()
            .map(|&x| expired(limit, x) as usize)
            .sum()
    }
}

/// Whether a front pair with this bound must be tested again at `limit`: it is not known
/// separated (a NaN bound, which no finite input makes, would count as expired).
#[inline(always)]
#[allow(clippy::neg_cmp_op_on_partial_ord)]
fn expired(limit: f64, bound: f64) -> bool {
    !(limit < bound)
}

/// The front a traversal records into, if any, with the cache's motion clock.
type Recording<'f> = Option<(&'f mut Front, f64)>;

/// Records a separated pair (bound: clock + `margin`) when a front is being recorded.
#[inline(always)]
fn record_separated(front: &mut Recording<'_>, a: u32, b: u32, margin: f64) {
    if let Some((f, clock)) = front {
        f.push(a, b, *clock + margin);
    }
}

/// Records pairs to be traversed again next time (overlapping leaf pairs, pairs left
/// untested after a hit) when a front is being recorded.
#[inline(always)]
fn record_pairs(front: &mut Recording<'_>, pairs: impl Iterator<Item = (u32, u32)>) {
    if let Some((f, _)) = front {
        for (a, b) in pairs {
            f.push(a, b, f64::NEG_INFINITY);
        }
    }
}

/// Which node of a pair the traversal splits: A unless B is the bigger internal node, bigger by
/// the sum of its half extents (a rule that depends on the trees only, so the traversal tree is
/// the same every query). Against `|h|²`, the sum gave 2 % fewer box tests per disjoint query on
/// the near-contact knots and 5-15 % fewer on the CAD pairs (`FRCD_BENCH_COUNT=1`); it weighs a
/// box's smaller sides more, as PQP's size of a swept rectangle does.
#[inline(always)]
fn split_a(na: &TNode, nb: &TNode) -> bool {
    nb.is_leaf() || (!na.is_leaf() && na.size() >= nb.size())
}

/// The overlapping lanes (margin not positive, NaN included) of the first `n` of a four-lane
/// test, in the order to push them so that the most negative margin is popped first: largest
/// margin first, ties by lane; returns them and their number. Branch-free: each lane becomes
/// one integer (the margin's total-order key above the lane's inverted index, 0 for a lane not
/// to expand), and a five-exchange sorting network puts them largest first (the branchy rank
/// count it replaces took a fifth of the dense sweep's first-contact time, perf). Out of line:
/// it runs at most [`ORDERED_STEPS`] times per descent, and inlined into the traversal loop it
/// made the loop's register allocation worse (1.6× the instructions per disjoint knots query,
/// callgrind).
#[inline(never)]
fn deepest_last(m: &wide::F4, n: usize) -> ([usize; 4], usize) {
    let mut keys = [0u64; 4];
    let mut len = 0;
    for (k, (&margin, slot)) in m.0.iter().zip(&mut keys).enumerate() {
        let bits = margin.to_bits() as i32;
        // Total order of f32 as i32 (NaN above +inf), shifted to [1, 2^32] so that 0 stays
        // below every lane that is expanded.
        let key = (bits ^ ((((bits >> 31) as u32) >> 1) as i32)) as i64 + (1 << 31) + 1;
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        let expand = k < n && !(margin > 0.0);
        // A mask, not a branch: the compiler keeps `if` as a jump on the margin.
        *slot = ((key as u64) << 2 | (3 - k) as u64) & (expand as u64).wrapping_neg();
        len += expand as usize;
    }
    let exchange = |keys: &mut [u64; 4], p: usize, q: usize| {
        let (hi, lo) = (keys[p].max(keys[q]), keys[p].min(keys[q]));
        keys[p] = hi;
        keys[q] = lo;
    };
    exchange(&mut keys, 0, 1);
    exchange(&mut keys, 2, 3);
    exchange(&mut keys, 0, 2);
    exchange(&mut keys, 1, 3);
    exchange(&mut keys, 1, 2);
    (keys.map(|key| 3 - (key & 3) as usize), len)
}

/// Caller-owned frame-to-frame state for [`collide_cached`] on one pair of trees.
///
/// Holds the last witness triangle pair (tested first in [`Mode::FirstContact`]) with the leaf
/// pair that held it (when that pair no longer touches and the bodies moved by at most a tenth
/// of the smaller one's bounding radius, the subtree pair four levels above those leaves is
/// searched before the whole trees) and the
/// traversal front of the last traversal: the node pairs where it stopped, each separated pair
/// with its separation margin. Between queries the cache bounds how far any point of B moved
/// in A's frame (`|Δt| + ‖ΔM‖₂ · r_v`, `r_v` the largest vertex distance from B's origin,
/// summed into a motion clock); a separated front pair
/// whose margin exceeds the motion since its test is still separated and is not tested again
/// (the argument holds for the fixed separating direction, so it is exact, not a heuristic).
/// The others are tested again and traversed below where they overlap; leaf pairs whose boxes
/// overlapped get a box test before their triangle tests.
///
/// The cache never costs much: a work budget compares each front walk with the last fresh
/// traversal ([`Counters::work`]); when the front saves less than a quarter of that work, the
/// cache drops it and traverses afresh, backing off exponentially (up to 64 queries) before trying a front again, so
/// incoherent sequences (random poses, teleports) run at the uncached speed. The answers are
/// the same as without a cache; only the work differs. A cache used with other trees resets
/// itself.
#[derive(Clone, Debug, Default)]
pub struct PairCache {
    key: (u64, u64),
    witness: Option<(u32, u32)>,
    /// The leaves (node ids of A and of B) that held `witness`.
    witness_leaves: Option<(u32, u32)>,
    front: Front,
    scratch: Front,
    /// Frame of the previous query.
    prev: Option<RelativeFrame>,
    /// Sum of the motion bounds since the cache was bound.
    clock: f64,
    /// Work of the last fresh traversal.
    fresh_work: u64,
    /// Queries left to traverse afresh before the front is tried again.
    skip: u32,
    /// Length of the next back-off.
    backoff: u32,
    /// Motion bound of the last query (how far any point of B moved in A's frame).
    delta: f64,
}

impl PairCache {
    /// An empty cache.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets everything (e.g. after a teleport).
    pub fn clear(&mut self) {
        *self = Self::default();
    }

    /// Number of node pairs in the stored traversal front.
    pub fn front_len(&self) -> usize {
        self.front.len()
    }

    fn bind(&mut self, a: &ObbTree, b: &ObbTree, frame: &RelativeFrame) {
        let key = (a.uid, b.uid);
        if key != self.key {
            self.clear();
            self.key = key;
        }
        if let Some(p) = self.prev {
            // A bound on |frame(v) - prev(v)| for every vertex v of B (hence every point of
            // B's triangles, convex combinations of them), rounded up.
            let delta = (frame.t - p.t).length() * (1.0 + 1e-15)
                + rotation_change_bound(&p.m, &frame.m) * b.vertex_radius;
            self.delta = delta;
            self.clock += delta * (1.0 + 1e-9);
            if !self.clock.is_finite() {
                self.front.clear();
                self.clock = 0.0;
            }
        }
        self.prev = Some(*frame);
    }
}

/// An upper bound on `‖M1 − M0‖₂` for two near-rotation matrices (the relative frames of two
/// queries): about `2 sin(θ/2)` for a turn by `θ` between them, the exact value for exact
/// rotations, where [`spectral_norm_bound`] gives `√(4/3)` times that.
///
/// With `η_k ≥ ‖M_kᵀM_k − I‖₂` (their Frobenius norms, computed and rounded up) and the exact
/// product `P = M1 M0ᵀ`: `M1 − M0 = (P − I) M0 + M1 (I − M0ᵀM0)`, so
/// `‖M1 − M0‖ ≤ ‖P − I‖·√(1 + η0) + √(1 + η1)·η0`. `PᵀP − I = M0 (M1ᵀM1 − I) M0ᵀ +
/// (M0M0ᵀ − I)`, so `‖PᵀP − I‖ ≤ η_P = η0 + (1 + η0) η1`; then the orthogonal factor `Q` of
/// `P`'s polar decomposition is within `η_P` of `P`, and `‖P − I‖ ≤ ‖Q − I‖ + η_P`. When
/// `tr Q > 1`, `Q` is a rotation (a reflection has trace at most 1), by an angle `φ` with
/// `‖Q − I‖₂ = 2 sin(φ/2) = √(3 − tr Q)`, and `tr Q ≥ tr P − 3η_P`. `tr P = Σ M1_ij M0_ij`
/// is computed within `30ε`. Otherwise (a turn beyond 90° between two queries, or matrices far
/// from rotations) it falls back to [`spectral_norm_bound`], and it never returns more.
pub(crate) fn rotation_change_bound(m0: &DMat3, m1: &DMat3) -> f64 {
    let defect = |m: &DMat3| {
        let g = m.transpose() * *m - DMat3::IDENTITY;
        let f = (g.x_axis.length_squared() + g.y_axis.length_squared() + g.z_axis.length_squared())
            .sqrt();
        // Each entry of MᵀM is within 3ε·(1 + η) of the exact one; 64ε covers them all.
        f * (1.0 + 1e-12) + 64.0 * f64::EPSILON
    };
    let (e0, e1) = (defect(m0), defect(m1));
    let ep = e0 + (1.0 + e0) * e1;
    let tr = m1.x_axis.dot(m0.x_axis) + m1.y_axis.dot(m0.y_axis) + m1.z_axis.dot(m0.z_axis);
    let tr_q = tr - 3.0 * ep - 30.0 * f64::EPSILON;
    if !(ep < 1e-6 && tr_q > 1.0) {
        return spectral_norm_bound(*m1 - *m0);
    }
    let q_minus_i = (3.0 - tr_q).max(0.0).sqrt();
    let bound = (q_minus_i + ep) * (1.0 + e0).sqrt() + (1.0 + e1).sqrt() * e0;
    // Both are bounds: the general one is the tighter for turns under about 10⁻⁶ rad, where
    // the rounding floor `√(3η_P)` of this one dominates.
    (bound * (1.0 + 1e-12)).min(spectral_norm_bound(*m1 - *m0))
}

/// An upper bound on the spectral norm `‖D‖₂` (the largest factor by which `D` stretches a
/// vector), about `√(4/3)·2 sin(θ/2)` for the difference of two rotations by `θ` against the
/// Frobenius norm's `√2·2 sin(θ/2)`.
///
/// `‖D‖₂² = λ_max(G)` for `G = DᵀD`. The computed `G` is exactly symmetric (entry `ij` and `ji`
/// are the same products summed in the same order) and differs from the exact one by at most
/// `3ε·tr G` per entry, so by Weyl's inequality its largest eigenvalue is within `27ε·tr G` of
/// the exact one. The eigenvalues `λ_k` of a symmetric 3×3 matrix with mean `μ = tr G / 3` and
/// variance `σ² = ‖G‖_F² / 3 − μ²` satisfy `λ_max ≤ μ + √2·σ` (Laguerre-Samuelson). The
/// variance is formed by a subtraction: its rounding, at most `8ε (‖G‖_F²/3 + μ²)`, is added
/// before the square root; the result is rounded up by a relative `10⁻¹²`.
pub(crate) fn spectral_norm_bound(d: DMat3) -> f64 {
    // Scaled exactly by powers of two so the largest entry is in [1, 2) (nothing under- or
    // overflows in G or its squares), the bound scaled back, plus the smallest normal number
    // against rounding in the subnormal range.
    let pow2 = |e: i32| f64::from_bits(((e + 1023) as u64) << 52);
    let cols = [d.x_axis.abs(), d.y_axis.abs(), d.z_axis.abs()];
    let m = cols[0].max(cols[1]).max(cols[2]).max_element();
    if m == 0.0 {
        return 0.0;
    }
    if !m.is_finite() {
        return f64::INFINITY;
    }
    let (d, pre) = if m < pow2(-900) {
        (d * pow2(600), pow2(-600))
    } else {
        (d, 1.0)
    };
    let e = ((d
        .x_axis
        .abs()
        .max(d.y_axis.abs())
        .max(d.z_axis.abs())
        .max_element()
        .to_bits()
        >> 52) as i32)
        - 1023;
    let b = scaled_spectral_bound(d * pow2(-e));
    b * pow2(e) * pre + f64::MIN_POSITIVE
}

/// [`spectral_norm_bound`] for a matrix whose largest entry is in `[1, 2)`.
fn scaled_spectral_bound(d: DMat3) -> f64 {
    let g = d.transpose() * d;
    let cols = [g.x_axis, g.y_axis, g.z_axis];
    let tr = g.x_axis.x + g.y_axis.y + g.z_axis.z;
    let f2: f64 = cols.iter().map(|c| c.length_squared()).sum();
    let mean = tr / 3.0;
    let spread = f2 / 3.0 - mean * mean;
    let var = spread.max(0.0) + 8.0 * f64::EPSILON * (f2 / 3.0 + mean * mean);
    let lambda = mean + (2.0 * var).sqrt() + 27.0 * f64::EPSILON * tr;
    lambda.sqrt() * (1.0 + 1e-12)
}

/// A triangle in A's frame with its axis-aligned box (the leaf test's cheap rejection).
#[derive(Clone, Copy)]
struct PlacedTriangle {
    tri: Triangle,
    aabb: Aabb,
}

impl PlacedTriangle {
    /// A placeholder, overwritten before use.
    const EMPTY: PlacedTriangle = PlacedTriangle {
        tri: Triangle {
            v: [DVec3::ZERO; 3],
        },
        aabb: Aabb {
            min: DVec3::ZERO,
            max: DVec3::ZERO,
        },
    };

    #[inline(always)]
    fn new(tri: Triangle) -> Self {
        PlacedTriangle {
            aabb: tri.aabb(),
            tri,
        }
    }
}

/// One step of the wide traversal: a stack entry, which node it splits and the children it
/// tests.
#[derive(Clone, Copy)]
struct StepMeta {
    entry: (u32, u32, u32),
    /// A's node splits (its children against B's placed box), else B's.
    split_a: bool,
    ids: [u32; 4],
    n: usize,
    /// B splits: the block of the stack's placed lanes that holds B's children.
    block: u32,
}

impl StepMeta {
    /// Pushes the lanes that `m` does not separate (margin not positive), last lane first so
    /// that the leftmost is expanded first, and records the separated ones in `front` when one
    /// is being recorded. Without a front, branch-free: every lane written, the overlapping
    /// ones kept.
    #[inline(always)]
    fn push<const RECORD: bool>(&self, stack: &mut Stack, front: &mut Recording<'_>, m: wide::F4) {
        let (i, j, p) = self.entry;
        if RECORD {
            for k in (0..self.n).rev() {
                let (a, b, q) = if self.split_a {
                    (self.ids[k], j, p)
                } else {
                    (i, self.ids[k], self.block << 2 | k as u32)
                };
                if m.0[k] > 0.0 {
                    record_separated(front, a, b, wide::margin64(m.0[k]));
                } else {
                    stack.pairs.push((a, b, q));
                }
            }
            return;
        }
        let top = stack.pairs.len();
        stack.pairs.resize(top + 4, (0, 0, 0));
        let mut len = top;
        if self.split_a {
            for k in (0..self.n).rev() {
                stack.pairs[len] = (self.ids[k], j, p);
                len += 1 - (m.0[k] > 0.0) as usize;
            }
        } else {
            let block = self.block << 2;
            for k in (0..self.n).rev() {
                stack.pairs[len] = (i, self.ids[k], block | k as u32);
                len += 1 - (m.0[k] > 0.0) as usize;
            }
        }
        stack.pairs.truncate(len);
    }
}

/// A step with its lanes for the four-lane test ([`Ctx::step_lanes`]).
struct Step {
    meta: StepMeta,
    a: ALanes,
    /// B's placed box in every lane (A splits; B splits keep theirs in `meta.block`).
    b: BLanes,
}

impl Step {
    /// The B lanes of the test.
    #[inline(always)]
    fn b<'s>(&'s self, stack: &'s Stack) -> &'s BLanes {
        if self.meta.split_a {
            &self.b
        } else {
            &stack.placed32[self.meta.block as usize]
        }
    }
}

/// The traversal stack: node pairs, each naming its B box (placed in A's frame) in `placed`
/// (f64 boxes for the f64 traversal) or in `placed32` (the wide f32 traversal: the lanes one
/// step placed, kept whole, named `4 · block + lane`).
#[derive(Default)]
struct Stack {
    pairs: Vec<(u32, u32, u32)>,
    placed: Vec<Placed>,
    placed32: Vec<BLanes>,
    /// B leaves already placed in A's frame by the query that holds the stack.
    leaves: PlacedLeaves,
    /// A leaves already fetched and boxed by that query.
    a_leaves: PlacedLeaves,
}

impl Stack {
    fn new() -> Self {
        Stack {
            pairs: Vec::with_capacity(64),
            placed: Vec::with_capacity(64),
            placed32: Vec::with_capacity(64),
            leaves: PlacedLeaves::default(),
            a_leaves: PlacedLeaves::default(),
        }
    }
}

/// One tree's leaves of one or two triangles, fetched and boxed by one query (B's placed in
/// A's frame first), direct-mapped by node index ([`PLACED_LEAF_SLOTS`] slots): a leaf met
/// again is read back instead of fetched and placed again. Depth-first, the A leaves below one
/// node meet the same B leaves one after another, and the other way round: on the dense
/// sweep's all pairs 558 of 828 leaf pairs per query found their B leaf here (67 %), on the
/// near-contact knots 110 of 174. The B slots cut the dense sweep's all-pairs instructions by
/// 2.2 %, the A slots by 1.3 % more.
///
/// A slot's tag is `generation << 32 | node`; the generation changes with every query
/// ([`PlacedLeaves::next_query`]), so no query reads another's triangles (another frame,
/// perhaps another tree).
#[derive(Default)]
struct PlacedLeaves {
    /// Empty until a query first meets a leaf pair (then [`PLACED_LEAF_SLOTS`] entries).
    tags: Vec<u64>,
    tris: Vec<[PlacedTriangle; 2]>,
    generation: u32,
}

/// Slots of [`PlacedLeaves`]: 256 (62 KB); 4,096 found 4 more leaves per dense query.
const PLACED_LEAF_SLOTS: usize = 256;

impl PlacedLeaves {
    /// Forgets every placement (a new query: a new frame).
    fn next_query(&mut self) {
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            // Tags of the generation 2^32 queries ago could match again: clear them.
            self.tags.fill(0);
            self.generation = 1;
        }
    }

    /// Leaf `node`'s slot and whether it holds the node's placed triangles; on a miss the
    /// slot is claimed for the node (the caller fills it).
    #[inline(always)]
    fn slot(&mut self, node: u32) -> (&mut [PlacedTriangle; 2], bool) {
        if self.tags.is_empty() {
            self.tags = vec![0; PLACED_LEAF_SLOTS];
            self.tris = vec![[PlacedTriangle::EMPTY; 2]; PLACED_LEAF_SLOTS];
        }
        let k = node as usize % PLACED_LEAF_SLOTS;
        let tag = (u64::from(self.generation) << 32) | u64::from(node);
        let found = self.tags[k] == tag;
        self.tags[k] = tag;
        (&mut self.tris[k], found)
    }
}

thread_local! {
    /// This thread's traversal stack between queries: its buffers (about 27 KB to start with,
    /// then as deep as the deepest traversal, plus 124 KB of placed-leaf slots once a query
    /// meets a leaf pair) are reused instead of allocated and freed by every query that passes
    /// the top volume.
    static STACK: std::cell::Cell<Stack> = std::cell::Cell::new(Stack::default());
}

/// The thread's [`Stack`], lent to one query and given back (emptied) when dropped, on every
/// return path. A query started inside another's callback finds the slot empty and gets a
/// fresh stack.
struct PooledStack(Stack);

impl PooledStack {
    fn take() -> Self {
        let stack = STACK.try_with(|c| c.take()).unwrap_or_default();
        let mut stack = if stack.pairs.capacity() == 0 {
            Stack::new()
        } else {
            stack
        };
        stack.leaves.next_query();
        stack.a_leaves.next_query();
        PooledStack(stack)
    }
}

impl std::ops::Deref for PooledStack {
    type Target = Stack;
    fn deref(&self) -> &Stack {
        &self.0
    }
}

impl std::ops::DerefMut for PooledStack {
    fn deref_mut(&mut self) -> &mut Stack {
        &mut self.0
    }
}

impl Drop for PooledStack {
    fn drop(&mut self) {
        let mut stack = std::mem::take(&mut self.0);
        stack.pairs.clear();
        stack.placed.clear();
        stack.placed32.clear();
        // Fails only while the thread's locals are being destroyed: then the stack is freed.
        let _ = STACK.try_with(|c| c.set(stack));
    }
}

/// Which traversal a query runs (crate-internal switch, for tests comparing the two).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Traversal {
    /// The wide f32 traversal when the query's magnitudes fit f32 (`wide.rs`), else the f64 one.
    Wide,
    /// The wide traversal compiled for the baseline instruction set even where the CPU has
    /// AVX2 (tests comparing the two builds of the hot loop, `isa.rs`).
    #[cfg_attr(not(test), allow(dead_code))]
    WideBaseline,
    /// The binary f64 traversal (one box pair per test, `sat.rs`).
    #[cfg_attr(not(test), allow(dead_code))]
    Binary,
}

thread_local! {
    /// The traversal of this thread's queries (tests switch it; queries read it once).
    static TRAVERSAL: std::cell::Cell<Traversal> = const { std::cell::Cell::new(Traversal::Wide) };
}

/// Runs `f` with this thread's queries using traversal `t` (tests).
#[cfg(test)]
pub(crate) fn with_traversal<R>(t: Traversal, f: impl FnOnce() -> R) -> R {
    let old = TRAVERSAL.with(|c| c.replace(t));
    let r = f();
    TRAVERSAL.with(|c| c.set(old));
    r
}

struct Ctx<'a> {
    a: &'a ObbTree,
    b: &'a ObbTree,
    frame: RelativeFrame,
    slack: f64,
    method: Method,
    counters: Counters,
    /// The f32 box test of the wide traversal, `None` where the query's magnitudes do not fit
    /// f32 (then the binary f64 traversal runs).
    sat32: Option<Sat32>,
    /// Run the wide traversal's AVX2 build (`isa.rs`): the CPU has AVX2 and no test asked for
    /// the baseline build (always false, and unread, off x86-64).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    avx2: bool,
    /// How many steps at the top of each wide descent expand their overlapping lanes deepest
    /// first ([`ORDERED_STEPS`] in first contact, 0 in all pairs, where order is moot).
    ordered_steps: u32,
    /// The leaf pair (nodes of A and of B) the traversal tested last: where first contact
    /// stopped, once it has.
    last_leaves: (u32, u32),
}

/// First contact: the first steps of a wide descent (those near the roots, where the choice
/// of subtree matters most) expand their overlapping lanes in order of depth of overlap, the
/// most negative margin first; later steps take the leftmost lane first (branch-free). Box
/// tests per touching first-contact query (time-free counts, `FRCD_BENCH_COUNT=1`), lane 0
/// first everywhere → deepest first in the first 16 steps: dense sweep 196 → 136, knots near
/// contact 1,309 → 1,197, wagon + bogie 690 → 541, bogie pair 708 → 547, fandisk 315 → 288;
/// deepest first at every step gives about the same counts (118 / 1,241 / 504 / 575 / 264) but
/// pays the sort at every step of the disjoint queries too, which cost more than it saved.
const ORDERED_STEPS: u32 = 16;

/// [`ORDERED_STEPS`], or in tests the value [`with_ordered_steps`] set for this thread.
#[inline]
fn ordered_steps() -> u32 {
    #[cfg(test)]
    if let Some(n) = ORDERED_OVERRIDE.with(|c| c.get()) {
        return n;
    }
    ORDERED_STEPS
}

#[cfg(test)]
thread_local! {
    static ORDERED_OVERRIDE: std::cell::Cell<Option<u32>> = const { std::cell::Cell::new(None) };
}

/// Runs `f` with first contact ordering `n` steps per descent on this thread (tests).
#[cfg(test)]
fn with_ordered_steps<R>(n: u32, f: impl FnOnce() -> R) -> R {
    ORDERED_OVERRIDE.with(|c| c.set(Some(n)));
    let r = f();
    ORDERED_OVERRIDE.with(|c| c.set(None));
    r
}

impl<'a> Ctx<'a> {
    fn new(a: &'a ObbTree, pose_a: &Pose, b: &'a ObbTree, pose_b: &Pose, method: Method) -> Self {
        let frame = RelativeFrame::new(pose_a, pose_b);
        let slack = query_slack(a, b, &frame);
        let traversal = TRAVERSAL.with(|c| c.get());
        let sat32 = match traversal {
            Traversal::Wide | Traversal::WideBaseline => {
                let mag = a.radius_from_origin + b.radius_from_origin + frame.t.length();
                Sat32::new(frame.m, frame.t, slack, mag)
            }
            Traversal::Binary => None,
        };
        let avx2 = traversal == Traversal::Wide && isa::has_avx2();
        Ctx {
            a,
            b,
            slack,
            frame,
            method,
            counters: Counters::default(),
            sat32,
            avx2,
            ordered_steps: 0,
            last_leaves: (0, 0),
        }
    }

    /// Hybrid top volume: sphere, then AABB. True when the bodies are certainly apart. Only
    /// finite figures reject: near the top of the f64 range a distance, a box centre or a
    /// transformed corner can overflow (and `0 · ∞` gives NaN), and such a figure proves
    /// nothing (found by the `mesh_tree` fuzz target: two point triangles at `z ≈ −1.8·10³⁰⁸`
    /// were rejected as apart from themselves).
    fn top_rejects(&mut self, top: TopVolume) -> bool {
        if top == TopVolume::RootObb {
            return false;
        }
        self.counters.top_tests += 1;
        let sa = self.a.sphere;
        let sb = self.b.sphere;
        let d = self.frame.point(sb.center).distance(sa.center);
        let reach = sa.radius + sb.radius + self.slack;
        if d.is_finite() && reach.is_finite() && d > reach {
            return true;
        }
        self.counters.top_tests += 1;
        let bb = self.frame.aabb(&self.b.aabb, self.slack);
        let ba = self.a.aabb.inflated(self.slack);
        let finite = |b: &Aabb| b.min.is_finite() && b.max.is_finite();
        finite(&bb) && finite(&ba) && !bb.intersects(&ba)
    }

    #[inline(always)]
    fn place(&mut self, j: u32) -> Placed {
        self.counters.placements += 1;
        Placed::new(&self.b.nodes[j as usize], &self.frame.m, self.frame.t)
    }

    /// The separating axis and margin of node `i` of A against a placed box of B, if any.
    #[inline(always)]
    fn separation(&mut self, i: u32, pb: &Placed) -> Option<(u8, f64)> {
        self.counters.box_tests += 1;
        sat::separation(&self.a.nodes[i as usize], pb, self.slack)
    }

    /// The two children of a node pair in the traversal tree (descend into the bigger box; a
    /// rule that depends on the trees only, so the traversal tree is the same every query).
    #[inline(always)]
    fn children(&self, i: u32, j: u32) -> [(u32, u32); 2] {
        let na = &self.a.nodes[i as usize];
        let nb = &self.b.nodes[j as usize];
        if split_a(na, nb) {
            [(i + 1, j), (na.right(), j)]
        } else {
            [(i, j + 1), (i, nb.right())]
        }
    }

    #[inline(always)]
    fn both_leaves(&self, i: u32, j: u32) -> bool {
        self.a.nodes[i as usize].is_leaf() && self.b.nodes[j as usize].is_leaf()
    }

    /// Exact per-pair box check, then the triangle test.
    #[inline]
    fn tri_pair(&mut self, ta: u32, tb: u32) -> bool {
        let t1 = PlacedTriangle::new(self.a.triangle(ta));
        let t2 = PlacedTriangle::new(self.frame.triangle(&self.b.triangle(tb)));
        self.placed_tri_pair(&t1, &t2)
    }

    /// [`Ctx::tri_pair`] on triangles already fetched, placed in A's frame and boxed.
    #[inline(always)]
    fn placed_tri_pair(&mut self, t1: &PlacedTriangle, t2: &PlacedTriangle) -> bool {
        if !t1.aabb.intersects(&t2.aabb) {
            return false;
        }
        self.counters.tri_tests += 1;
        frcd_tritri::intersects(self.method, &t1.tri, &t2.tri)
    }

    /// Tests the triangles of a leaf pair; calls `hit` on each touching pair, stops when it
    /// returns `true`. Each triangle is fetched from its mesh, placed and boxed once per query
    /// where its leaf holds one or two triangles (kept in `leaves` for B, `a_leaves` for A,
    /// see [`PlacedLeaves`]), else once per leaf pair; never once per triangle pair. The same
    /// operations on the same values either way, so the same answers.
    #[inline]
    fn leaf_pair(
        &mut self,
        (leaves, a_leaves): (&mut PlacedLeaves, &mut PlacedLeaves),
        i: u32,
        j: u32,
        hit: &mut impl FnMut(u32, u32) -> bool,
    ) -> bool {
        self.last_leaves = (i, j);
        let tas = self.a.node_triangles(i);
        let tbs = self.b.node_triangles(j);
        // Leaves of one or two triangles (the default leaf holds two) go through `leaves`;
        // larger ones get one instance per size up to four, so the placed triangles live in
        // an array of exactly that size.
        if tbs.len() <= 2 {
            let (placed, found) = leaves.slot(j);
            if !found {
                for (p, &tb) in placed.iter_mut().zip(tbs) {
                    *p = PlacedTriangle::new(self.frame.triangle(&self.b.triangle(tb)));
                }
            }
            let placed = &placed[..tbs.len()];
            let a = self.a;
            if tas.len() <= 2 {
                // A's triangles, fetched and boxed once per query too.
                let (fetched, found) = a_leaves.slot(i);
                if !found {
                    for (p, &ta) in fetched.iter_mut().zip(tas) {
                        *p = PlacedTriangle::new(a.triangle(ta));
                    }
                }
                for (t1, &ta) in fetched.iter().zip(tas) {
                    if self.triangle_row(ta, t1, placed, tbs, hit) {
                        return true;
                    }
                }
                false
            } else {
                self.fetched_rows(tas, placed, tbs, hit)
            }
        } else if let Ok(tbs) = <&[u32; 3]>::try_from(tbs) {
            self.placed_leaf_pair(tas, tbs, hit)
        } else if let Ok(tbs) = <&[u32; 4]>::try_from(tbs) {
            self.placed_leaf_pair(tas, tbs, hit)
        } else {
            // Larger leaves (a build option): triangle by triangle.
            for &ta in tas {
                for &tb in tbs {
                    if self.tri_pair(ta, tb) && hit(ta, tb) {
                        return true;
                    }
                }
            }
            false
        }
    }

    /// A's triangles `tas`, each fetched and boxed here, against B's placed triangles of one
    /// leaf ([`Ctx::triangle_row`] each); true when `hit` stops the traversal.
    #[inline(always)]
    fn fetched_rows(
        &mut self,
        tas: &[u32],
        placed: &[PlacedTriangle],
        tbs: &[u32],
        hit: &mut impl FnMut(u32, u32) -> bool,
    ) -> bool {
        let a = self.a;
        for &ta in tas {
            let t1 = PlacedTriangle::new(a.triangle(ta));
            if self.triangle_row(ta, &t1, placed, tbs, hit) {
                return true;
            }
        }
        false
    }

    /// A's triangle `ta` (boxed, `t1`) against B's placed triangles of one leaf; calls `hit`
    /// on each touching pair, true when it stops the traversal.
    #[inline(always)]
    fn triangle_row(
        &mut self,
        ta: u32,
        t1: &PlacedTriangle,
        placed: &[PlacedTriangle],
        tbs: &[u32],
        hit: &mut impl FnMut(u32, u32) -> bool,
    ) -> bool {
        for (t2, &tb) in placed.iter().zip(tbs) {
            if self.placed_tri_pair(t1, t2) && hit(ta, tb) {
                return true;
            }
        }
        false
    }

    /// [`Ctx::leaf_pair`] with B's `N` triangles placed first.
    #[inline]
    fn placed_leaf_pair<const N: usize>(
        &mut self,
        tas: &[u32],
        tbs: &[u32; N],
        hit: &mut impl FnMut(u32, u32) -> bool,
    ) -> bool {
        let b = self.b;
        // A plain loop over a filled array: `array::from_fn` kept its closure out of line
        // (a call and a copy of the result per triangle).
        let mut placed = [PlacedTriangle::EMPTY; N];
        for (p, &tb) in placed.iter_mut().zip(tbs) {
            *p = PlacedTriangle::new(self.frame.triangle(&b.triangle(tb)));
        }
        self.fetched_rows(tas, &placed, tbs, hit)
    }

    /// Depth-first traversal below (and including) node pair `(i, j)`. Appends the pairs where
    /// it stopped to `front` (when given; separated pairs with bound `clock + margin`); calls
    /// `hit` on touching triangle pairs and stops everything when `hit` returns `true` (then
    /// returns `true`, and the pairs it did not reach go to `front` as untested, so the front
    /// stays a cut).
    fn descend(
        &mut self,
        i: u32,
        j: u32,
        stack: &mut Stack,
        front: Recording<'_>,
        hit: &mut impl FnMut(u32, u32) -> bool,
    ) -> bool {
        match self.sat32 {
            Some(sat) => self.descend_wide(&sat, i, j, None, stack, front, hit),
            None => self.descend64(i, j, stack, front, hit),
        }
    }

    /// [`Ctx::descend`] on the binary f64 traversal: one box pair per test (`sat.rs`).
    fn descend64(
        &mut self,
        i: u32,
        j: u32,
        stack: &mut Stack,
        mut front: Recording<'_>,
        hit: &mut impl FnMut(u32, u32) -> bool,
    ) -> bool {
        let base = stack.pairs.len();
        let pbase = stack.placed.len();
        // B's boxes mapped into A's frame live in `stack.placed`; stack entries name them by
        // index (12-byte entries instead of copying a 128-byte box on every push and pop), and
        // splitting A reuses them. Indices never decrease up the stack, so when an entry is
        // popped every box above its own belongs to finished subtrees and is dropped.
        let pj = self.place(j);
        stack.placed.push(pj);
        stack.pairs.push((i, j, pbase as u32));
        while stack.pairs.len() > base {
            let (i, j, p) = stack.pairs.pop().expect("non-empty");
            stack.placed.truncate(p as usize + 1);
            if let Some((_, margin)) = self.separation(i, &stack.placed[p as usize]) {
                record_separated(&mut front, i, j, margin);
                continue;
            }
            if self.both_leaves(i, j) {
                record_pairs(&mut front, std::iter::once((i, j)));
                if self.leaf_pair((&mut stack.leaves, &mut stack.a_leaves), i, j, hit) {
                    let rest = stack.pairs[base..].iter().map(|&(a, b, _)| (a, b));
                    record_pairs(&mut front, rest);
                    stack.pairs.truncate(base);
                    stack.placed.truncate(pbase);
                    return true;
                }
                continue;
            }
            let [l, r] = self.children(i, j);
            if l.1 == j {
                stack.pairs.push((r.0, r.1, p));
                stack.pairs.push((l.0, l.1, p));
            } else {
                let q = stack.placed.len() as u32;
                let pr = self.place(r.1);
                let pl = self.place(l.1);
                stack.placed.push(pr);
                stack.placed.push(pl);
                stack.pairs.push((r.0, r.1, q));
                stack.pairs.push((l.0, l.1, q + 1));
            }
        }
        stack.placed.truncate(pbase);
        false
    }

    /// [`Ctx::descend`] on the wide f32 traversal (`wide.rs`). Stack entries are node pairs
    /// whose boxes overlap (tested); expanding one tests the smaller node against the (2 to 4)
    /// nodes two levels below the bigger one in one four-lane test (a child that is a leaf
    /// stands for itself; the bigger box is split as in the binary traversal, leaves never),
    /// so a stack step decides up to four box pairs with one branch. Each lane counts as one
    /// box test, each B box placed in A's frame as one placement. Front entries are binary
    /// node pairs, as in the binary traversal, so a front is a cut of either traversal tree.
    ///
    /// `overlapping_start`: B's start node already placed in A's frame (in every lane) and
    /// found overlapping A's (the front walk tests expired pairs four at a time), so neither
    /// is done again.
    #[allow(clippy::too_many_arguments)]
    fn descend_wide(
        &mut self,
        sat: &Sat32,
        i: u32,
        j: u32,
        overlapping_start: Option<BLanes>,
        stack: &mut Stack,
        front: Recording<'_>,
        hit: &mut impl FnMut(u32, u32) -> bool,
    ) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is true only where the running CPU reports AVX2 (`Ctx::new`,
            // `isa::has_avx2`), the one feature `descend_wide_avx2` is compiled with.
            #[allow(unsafe_code)]
            return unsafe {
                self.descend_wide_avx2(sat, i, j, overlapping_start, stack, front, hit)
            };
        }
        self.descend_wide_body::<false>(sat, i, j, overlapping_start, stack, front, hit)
    }

    /// [`Ctx::descend_wide`] compiled with AVX2 (`isa.rs`): the same operations, encoded with
    /// AVX's three-operand instructions and 256-bit f64 lanes.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(clippy::too_many_arguments)]
    fn descend_wide_avx2(
        &mut self,
        sat: &Sat32,
        i: u32,
        j: u32,
        overlapping_start: Option<BLanes>,
        stack: &mut Stack,
        front: Recording<'_>,
        hit: &mut impl FnMut(u32, u32) -> bool,
    ) -> bool {
        self.descend_wide_body::<true>(sat, i, j, overlapping_start, stack, front, hit)
    }

    /// The body of [`Ctx::descend_wide`], inlined into each of its instruction-set builds
    /// (`AVX`: the AVX2 build, which runs paired steps as eight-lane tests).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn descend_wide_body<const AVX: bool>(
        &mut self,
        sat: &Sat32,
        i: u32,
        j: u32,
        overlapping_start: Option<BLanes>,
        stack: &mut Stack,
        mut front: Recording<'_>,
        hit: &mut impl FnMut(u32, u32) -> bool,
    ) -> bool {
        let base = stack.pairs.len();
        let pbase = stack.placed32.len();
        let (a, b) = (self.a, self.b);
        let start = match overlapping_start {
            Some(lanes) => lanes,
            None => {
                // The start pair, in one lane.
                self.counters.placements += 1;
                self.counters.box_tests += 1;
                let pj = sat.place(&b.nodes[j as usize]).splat();
                let m = wide::separation4(&ALanes::splat(&a.nodes[i as usize]), &pj, sat.s(), 1);
                if m.0[0] > 0.0 {
                    record_separated(&mut front, i, j, wide::margin64(m.0[0]));
                    return false;
                }
                pj
            }
        };
        // A B box is named `4 · block + lane`, a block being the lanes one step placed, stored
        // whole (one store per step instead of taking each surviving lane apart). As in
        // `descend64`, blocks never decrease up the stack, so when an entry is popped every
        // block above its own is finished with.
        stack.placed32.push(start);
        stack.pairs.push((i, j, (pbase as u32) << 2));
        if self.ordered_steps > 0 && front.is_none() {
            if let Some(stop) = self.ordered_loop(sat, base, pbase, stack, hit, self.ordered_steps)
            {
                return stop;
            }
        }
        // One instance per case, so that the plain loop carries no front checks.
        if front.is_none() {
            self.paired_steps::<AVX, false>(sat, base, pbase, stack, &mut front, hit)
        } else {
            self.paired_steps::<AVX, true>(sat, base, pbase, stack, &mut front, hit)
        }
    }

    /// A's nodes two levels below internal node `i`, in lanes (from its quad, or gathered):
    /// their ids and number, counted as box tests.
    #[inline(always)]
    fn a_children(&mut self, i: u32) -> ([u32; 4], usize, ALanes) {
        let a = self.a;
        let qa_all = a.quads();
        let qa = qa_all.of[i as usize];
        let (ids, n, lanes) = if qa != NO_QUAD {
            let q = &qa_all.quads[(qa >> 2) as usize];
            (q.ids, (qa & 3) as usize + 1, ALanes::from_quad(q))
        } else {
            let (ids, n) = quad_ids(&a.nodes, i);
            (ids, n, ALanes::gather(&a.nodes, &ids, n))
        };
        self.counters.box_tests += n as u64;
        (ids, n, lanes)
    }

    /// B's nodes two levels below internal node `j`, placed in A's frame in lanes (from its
    /// quad, or gathered): their ids and number, counted as box tests and placements.
    #[inline(always)]
    fn b_children(&mut self, sat: &Sat32, j: u32) -> ([u32; 4], usize, BLanes) {
        let b = self.b;
        let qb_all = b.quads();
        let qb = qb_all.of[j as usize];
        let (ids, n, lanes) = if qb != NO_QUAD {
            let q = &qb_all.quads[(qb >> 2) as usize];
            (q.ids, (qb & 3) as usize + 1, sat.place_quad(q))
        } else {
            let (ids, n) = quad_ids(&b.nodes, j);
            (ids, n, sat.place_lanes(&b.nodes, &ids, n))
        };
        self.counters.box_tests += n as u64;
        self.counters.placements += n as u64;
        (ids, n, lanes)
    }

    /// The lanes of one traversal step on the stack entry `(i, j, p)` (not a leaf pair): the
    /// split node's children two levels down against the other node, counted as box tests
    /// (and placements, where B's children are placed).
    #[inline(always)]
    fn step_lanes(&mut self, sat: &Sat32, stack: &mut Stack, (i, j, p): (u32, u32, u32)) -> Step {
        let (a, b) = (self.a, self.b);
        let na = &a.nodes[i as usize];
        let nb = &b.nodes[j as usize];
        if split_a(na, nb) {
            let (ids, n, lanes) = self.a_children(i);
            let pb = stack.placed32[(p >> 2) as usize].broadcast((p & 3) as usize);
            Step {
                meta: StepMeta {
                    entry: (i, j, p),
                    split_a: true,
                    ids,
                    n,
                    block: 0,
                },
                a: lanes,
                b: pb,
            }
        } else {
            let (ids, n, lanes) = self.b_children(sat, j);
            // Stored at once as a new block (a copy of the lanes kept in the step went
            // through memcpy twice). The caller pushes B splits' entries after A splits'.
            let block = stack.placed32.len() as u32;
            stack.placed32.push(lanes);
            Step {
                meta: StepMeta {
                    entry: (i, j, p),
                    split_a: false,
                    ids,
                    n,
                    block,
                },
                a: ALanes::splat(na),
                b: BLanes::default(),
            }
        }
    }

    /// The main loop of [`Ctx::descend_wide_body`]: each step pops two entries (the second
    /// unless it is a leaf pair) and tests both steps' lanes at once, in the AVX2 build as one
    /// eight-lane test ([`wide::avx::separation8`]: twice the lanes for about 1.2× the
    /// instructions of one four-lane test), in the baseline build as two four-lane tests. The
    /// same pairs are tested and kept as one entry at a time would, in another order on the
    /// stack; both builds take the same order, so their answers, counters and (with `RECORD`,
    /// a front being recorded, each separated lane with its margin) fronts are the same bit for
    /// bit. Disjoint near-contact knots: 545 → 486 thousand instructions per query, 18 % less
    /// time (`docs/performance/cpu-core.md`, eighth sitting). True when `hit` stopped the
    /// traversal.
    #[inline(always)]
    fn paired_steps<const AVX: bool, const RECORD: bool>(
        &mut self,
        sat: &Sat32,
        base: usize,
        pbase: usize,
        stack: &mut Stack,
        front: &mut Recording<'_>,
        hit: &mut impl FnMut(u32, u32) -> bool,
    ) -> bool {
        let (a, b) = (self.a, self.b);
        let s = sat.s();
        while stack.pairs.len() > base {
            let (i, j, p) = stack.pairs.pop().expect("non-empty");
            stack.placed32.truncate((p >> 2) as usize + 1);
            if a.nodes[i as usize].is_leaf() && b.nodes[j as usize].is_leaf() {
                if RECORD {
                    record_pairs(front, std::iter::once((i, j)));
                }
                if self.leaf_pair((&mut stack.leaves, &mut stack.a_leaves), i, j, hit) {
                    if RECORD {
                        let rest = stack.pairs[base..].iter().map(|&(a, b, _)| (a, b));
                        record_pairs(front, rest);
                    }
                    stack.pairs.truncate(base);
                    stack.placed32.truncate(pbase);
                    return true;
                }
                continue;
            }
            // The entry below, unless it is a leaf pair. Its block is at most the first's, so
            // the truncation above kept it.
            let second = match stack.pairs.last() {
                Some(&(i2, j2, p2)) if stack.pairs.len() > base => {
                    let leaves = a.nodes[i2 as usize].is_leaf() && b.nodes[j2 as usize].is_leaf();
                    (!leaves).then_some((i2, j2, p2))
                }
                _ => None,
            };
            let Some(entry2) = second else {
                let first = self.step_lanes(sat, stack, (i, j, p));
                let m = wide::separation4(&first.a, first.b(stack), s, (1 << first.meta.n) - 1);
                first.meta.push::<RECORD>(stack, front, m);
                continue;
            };
            stack.pairs.pop();
            let (first, m1, second, m2) =
                self.paired_test::<AVX, RECORD>(sat, stack, (i, j, p), entry2);
            // Blocks must not decrease up the stack: the A splits' entries (which name blocks
            // already there) go first, the second's below the first's, then the B splits'
            // (new blocks, the first's before the second's).
            for (step, m) in [(&second, m2), (&first, m1)] {
                if step.split_a {
                    step.push::<RECORD>(stack, front, m);
                }
            }
            for (step, m) in [(&first, m1), (&second, m2)] {
                if !step.split_a {
                    step.push::<RECORD>(stack, front, m);
                }
            }
        }
        stack.placed32.truncate(pbase);
        false
    }

    /// Both steps of a pair built and tested: in the AVX2 build as one eight-lane test
    /// ([`wide::avx`]), in the baseline build as two four-lane tests (the same lanes
    /// separated either way). The first entry's B block, if any, is stored before the second's.
    #[inline(always)]
    fn paired_test<const AVX: bool, const MARGINS: bool>(
        &mut self,
        sat: &Sat32,
        stack: &mut Stack,
        entry1: (u32, u32, u32),
        entry2: (u32, u32, u32),
    ) -> (StepMeta, wide::F4, StepMeta, wide::F4) {
        let s = sat.s();
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: `AVX` is true only in the traversal's AVX2 build, entered only where the
            // CPU reports AVX2 (`Ctx::new`, `isa::has_avx2`).
            #[allow(unsafe_code)]
            unsafe {
                let (first, h1) = self.step_half(sat, stack, entry1);
                let (second, h2) = self.step_half(sat, stack, entry2);
                let active = ((1 << first.n) - 1) | (((1 << second.n) - 1) << 4);
                let (m1, m2) = wide::avx::separation8::<MARGINS>(&h1, &h2, s, active);
                return (first, m1, second, m2);
            }
        }
        let first = self.step_lanes(sat, stack, entry1);
        let second = self.step_lanes(sat, stack, entry2);
        let m1 = wide::separation4(&first.a, first.b(stack), s, (1 << first.meta.n) - 1);
        let m2 = wide::separation4(&second.a, second.b(stack), s, (1 << second.meta.n) - 1);
        (first.meta, m1, second.meta, m2)
    }

    /// [`Ctx::step_lanes`] for the eight-lane test: the step's lanes as one half, built from
    /// where they lie.
    ///
    /// # Safety
    ///
    /// The CPU must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn step_half(
        &mut self,
        sat: &Sat32,
        stack: &mut Stack,
        (i, j, p): (u32, u32, u32),
    ) -> (StepMeta, wide::avx::Half) {
        let (a, b) = (self.a, self.b);
        let na = &a.nodes[i as usize];
        let nb = &b.nodes[j as usize];
        if split_a(na, nb) {
            let qa_all = a.quads();
            let qa = qa_all.of[i as usize];
            let placed = &stack.placed32[(p >> 2) as usize];
            let k = (p & 3) as usize;
            // SAFETY (both calls): the caller guarantees AVX2.
            let (ids, n, half) = if qa != NO_QUAD {
                let q = &qa_all.quads[(qa >> 2) as usize];
                (q.ids, (qa & 3) as usize + 1, unsafe {
                    wide::avx::a_split(q, placed, k)
                })
            } else {
                let (ids, n) = quad_ids(&a.nodes, i);
                let q = wide::Quad::gather(&a.nodes, &ids, n);
                (ids, n, unsafe { wide::avx::a_split(&q, placed, k) })
            };
            self.counters.box_tests += n as u64;
            let meta = StepMeta {
                entry: (i, j, p),
                split_a: true,
                ids,
                n,
                block: 0,
            };
            (meta, half)
        } else {
            let (ids, n, lanes) = self.b_children(sat, j);
            // SAFETY: the caller guarantees AVX2.
            let half = unsafe { wide::avx::b_split(na, &lanes) };
            let block = stack.placed32.len() as u32;
            stack.placed32.push(lanes);
            let meta = StepMeta {
                entry: (i, j, p),
                split_a: false,
                ids,
                n,
                block,
            };
            (meta, half)
        }
    }

    /// First contact's first steps over the stack above `base` (no front recorded): each step
    /// pushes its overlapping lanes deepest last ([`ORDERED_STEPS`]), for at most `ordered`
    /// steps. `Some(true)` when `hit` stopped the traversal, `Some(false)` when the stack is
    /// done, `None` after `ordered` steps, with the stack as it is for [`Ctx::paired_steps`].
    /// A loop of its own, so that the paired loop, where the time goes, carries no step count.
    #[inline(always)]
    fn ordered_loop(
        &mut self,
        sat: &Sat32,
        base: usize,
        pbase: usize,
        stack: &mut Stack,
        hit: &mut impl FnMut(u32, u32) -> bool,
        mut ordered: u32,
    ) -> Option<bool> {
        let (a, b) = (self.a, self.b);
        let s = sat.s();
        while stack.pairs.len() > base {
            if ordered == 0 {
                return None;
            }
            let (i, j, p) = stack.pairs.pop().expect("non-empty");
            stack.placed32.truncate((p >> 2) as usize + 1);
            let na = &a.nodes[i as usize];
            let nb = &b.nodes[j as usize];
            if na.is_leaf() && nb.is_leaf() {
                if self.leaf_pair((&mut stack.leaves, &mut stack.a_leaves), i, j, hit) {
                    stack.pairs.truncate(base);
                    stack.placed32.truncate(pbase);
                    return Some(true);
                }
                continue;
            }
            ordered -= 1;
            if split_a(na, nb) {
                let (ids, n, lanes) = self.a_children(i);
                let pb = stack.placed32[(p >> 2) as usize].broadcast((p & 3) as usize);
                let m = wide::separation4(&lanes, &pb, s, (1 << n) - 1);
                let (order, len) = deepest_last(&m, n);
                for &k in &order[..len] {
                    stack.pairs.push((ids[k], j, p));
                }
            } else {
                let (ids, n, lanes) = self.b_children(sat, j);
                let m = wide::separation4(&ALanes::splat(na), &lanes, s, (1 << n) - 1);
                let block = (stack.placed32.len() as u32) << 2;
                stack.placed32.push(lanes);
                let (order, len) = deepest_last(&m, n);
                for &k in &order[..len] {
                    stack.pairs.push((i, ids[k], block | k as u32));
                }
            }
        }
        stack.placed32.truncate(pbase);
        Some(false)
    }

    fn containment(&self, solid: bool) -> Option<Containment> {
        if !solid {
            return None;
        }
        contained(self.a, self.b, &self.frame, 0x5EED)
    }
}

/// Solid-mode containment with everything in A's frame (B's points and triangles mapped by
/// `frame`), for when no surface pair touches. `seed` picks the ray directions.
pub(crate) fn contained(
    a: &ObbTree,
    b: &ObbTree,
    frame: &RelativeFrame,
    seed: u64,
) -> Option<Containment> {
    if a.closed {
        for &p in &b.component_points {
            let p = frame.point(p);
            if point_inside_tree(p, a, None, seed) == Some(true) {
                return Some(Containment::BInsideA);
            }
        }
    }
    if b.closed {
        let slack = query_slack(a, b, frame);
        for &p in &a.component_points {
            if point_inside_tree(p, b, Some((frame, slack)), seed) == Some(true) {
                return Some(Containment::AInsideB);
            }
        }
    }
    None
}

/// Solid-mode containment alone, for two closed meshes whose surfaces are known not to touch
/// (e.g. a GPU traversal found no touching triangle pair): the [`Collision::contained`] that
/// [`collide`] reports in solid mode when no pair touches, without the traversal that proves
/// it. Meaningless when the surfaces touch.
///
/// ```
/// use frcd_obb::{collide, containment, BuildOptions, Containment, ObbTree, Request};
/// use frcd_geom::{shapes, DVec3, Pose};
/// let big = ObbTree::build(&shapes::icosphere(1.0, 2), &BuildOptions::default());
/// let small = ObbTree::build(&shapes::icosphere(0.2, 1), &BuildOptions::default());
/// let (inside, apart) = (Pose::IDENTITY, Pose::from_translation(DVec3::X * 3.0));
/// let c = containment(&big, &Pose::IDENTITY, &small, &inside);
/// assert_eq!(c, Some(Containment::BInsideA));
/// let solid = Request { solid: true, ..Request::default() };
/// assert_eq!(c, collide(&big, &Pose::IDENTITY, &small, &inside, &solid).contained);
/// assert_eq!(containment(&big, &Pose::IDENTITY, &small, &apart), None);
/// ```
pub fn containment(a: &ObbTree, pose_a: &Pose, b: &ObbTree, pose_b: &Pose) -> Option<Containment> {
    let mut ctx = Ctx::new(a, pose_a, b, pose_b, Request::default().method);
    // Apart top volumes: neither can hold the other (as in `collide`).
    if ctx.top_rejects(TopVolume::Hybrid) {
        return None;
    }
    ctx.containment(true)
}

/// Sorts triangle pairs ascending (by A's triangle, then B's), on one `u64` key per pair.
/// Long lists (a dense overlap's hundreds of pairs) take a least-significant-digit radix sort
/// over the key bytes some pair uses (stable passes of 256 buckets): on the dense sweep's all
/// pairs (about 590 pairs) it saved 36 thousand of the query's 2.6 million instructions
/// against the comparison sort, which short lists keep.
fn sort_pairs(pairs: &mut [(u32, u32)]) {
    let key = |&(a, b): &(u32, u32)| (u64::from(a) << 32) | u64::from(b);
    if pairs.len() < RADIX_MIN_PAIRS {
        pairs.sort_unstable_by_key(key);
        return;
    }
    let mut keys: Vec<u64> = pairs.iter().map(key).collect();
    let mut spare = vec![0u64; keys.len()];
    // Bytes where no key has a set bit are zero everywhere: nothing to sort there.
    let used = keys.iter().fold(0u64, |m, &k| m | k);
    for shift in (0..64).step_by(8) {
        if (used >> shift) & 0xff == 0 {
            continue;
        }
        let mut start = [0usize; 256];
        for &k in &keys {
            start[((k >> shift) & 0xff) as usize] += 1;
        }
        let mut sum = 0;
        for s in start.iter_mut() {
            (*s, sum) = (sum, sum + *s);
        }
        for &k in &keys {
            let d = ((k >> shift) & 0xff) as usize;
            spare[start[d]] = k;
            start[d] += 1;
        }
        std::mem::swap(&mut keys, &mut spare);
    }
    for (p, k) in pairs.iter_mut().zip(keys) {
        *p = ((k >> 32) as u32, k as u32);
    }
}

/// From this many pairs on, [`sort_pairs`] takes the radix sort (below, its fixed cost of
/// 256 buckets per pass outweighs the comparisons it saves).
const RADIX_MIN_PAIRS: usize = 128;

fn finish(ctx: &Ctx<'_>, request: &Request, mut c: Collision) -> Collision {
    if request.mode == Mode::AllPairs {
        sort_pairs(&mut c.pairs);
        c.witness = c.pairs.first().copied();
    }
    c.collide = c.witness.is_some();
    if !c.collide {
        c.contained = ctx.containment(request.solid);
        c.collide = c.contained.is_some();
    }
    if request.segments {
        let list: Vec<(u32, u32)> = match request.mode {
            Mode::AllPairs => c.pairs.clone(),
            Mode::FirstContact => c.witness.into_iter().collect(),
        };
        c.segments = list
            .iter()
            .map(|&(ta, tb)| {
                frcd_tritri::intersection_segment(
                    &ctx.a.triangle(ta),
                    &ctx.frame.triangle(&ctx.b.triangle(tb)),
                )
            })
            .collect();
    }
    c.counters = ctx.counters;
    c
}

/// Collides two trees placed at `pose_a` and `pose_b`.
///
/// B is tested in A's frame (one relative pose per query, [`RelativeFrame`]); the hybrid top
/// volume runs first, then a depth-first traversal with the conservative 15-axis test, then the
/// triangle test of `request.method` on leaf pairs. The traversal is wide: each step tests one
/// node against the up to four nodes two levels below the other in one four-lane f32 test whose
/// error bound keeps every box pair the exact f64 test would keep (the f64 test alone where the
/// query's magnitudes do not fit f32), so the answer is the same as with one f64 test per pair.
///
/// ```
/// use frcd_obb::{collide, BuildOptions, Mode, ObbTree, Request};
/// use frcd_geom::{shapes, DVec3, Pose};
/// let tree = ObbTree::build(&shapes::icosphere(1.0, 3), &BuildOptions::default());
/// let near = Pose::from_translation(DVec3::new(1.5, 0.0, 0.0));
/// let far = Pose::from_translation(DVec3::new(2.5, 0.0, 0.0));
/// let all = Request { mode: Mode::AllPairs, ..Request::default() };
/// let hit = collide(&tree, &Pose::IDENTITY, &tree, &near, &all);
/// assert!(hit.collide && !hit.pairs.is_empty());
/// assert!(!collide(&tree, &Pose::IDENTITY, &tree, &far, &Request::default()).collide);
/// ```
pub fn collide(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    request: &Request,
) -> Collision {
    let mut ctx = Ctx::new(a, pose_a, b, pose_b, request.method);
    let mut c = Collision::default();
    if ctx.top_rejects(request.top_volume) {
        // Disjoint bounding volumes: neither contact nor containment.
        c.counters = ctx.counters;
        return c;
    }
    let mut stack = PooledStack::take();
    match request.mode {
        Mode::FirstContact => {
            ctx.ordered_steps = ordered_steps();
            let mut w = None;
            ctx.descend(0, 0, &mut stack, None, &mut |x, y| {
                w = Some((x, y));
                true
            });
            c.witness = w;
        }
        Mode::AllPairs => {
            let pairs = &mut c.pairs;
            ctx.descend(0, 0, &mut stack, None, &mut |x, y| {
                pairs.push((x, y));
                false
            });
        }
    }
    finish(&ctx, request, c)
}

/// [`collide`] with frame-to-frame coherence: the same answer (`collide`, `pairs`, `contained`;
/// in FirstContact mode the witness may be a different touching pair), less work when poses
/// change little between calls, and about the same work when they do not (see [`PairCache`]).
/// `cache` belongs to this pair of trees (it resets itself when given other trees).
pub fn collide_cached(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    request: &Request,
    cache: &mut PairCache,
) -> Collision {
    let mut ctx = Ctx::new(a, pose_a, b, pose_b, request.method);
    cache.bind(a, b, &ctx.frame);
    let mut c = Collision::default();
    // Cheap rejections first: the top volume, then (first contact) the old witness pair and
    // its neighbourhood.
    if ctx.top_rejects(request.top_volume) {
        cache.witness = None;
        cache.witness_leaves = None;
        c.counters = ctx.counters;
        return c;
    }
    let first = request.mode == Mode::FirstContact;
    if first {
        ctx.ordered_steps = ordered_steps();
    }
    // First contact keeps a witness exactly when the last query touched. Touching steps are
    // the witness's job: a front recorded there holds the whole cut below the first hit and
    // costs more to record and walk than a fresh wide traversal that stops at the first hit.
    let was_touching = first && cache.witness.is_some();
    if first {
        if let Some((x, y)) = cache.witness {
            if ctx.tri_pair(x, y) {
                c.witness = Some((x, y));
                return finish(&ctx, request, c);
            }
        }
    }
    let mut found = None;
    // A front only pays when the bodies moved by a small part of their size since the last
    // query: after larger motion (random poses, teleports) every margin has expired, so the
    // cache neither walks nor records a front.
    let coherent = cache.delta <= 0.1 * a.sphere.radius.min(b.sphere.radius);
    let mut searched_all = false;
    if first && coherent {
        if let Some((la, lb)) = cache.witness_leaves {
            // Where the bodies touched a moment ago they most likely touch now: the subtrees a
            // few levels above the old witness's leaves first, the whole trees only if they
            // hold no touching pair (their pairs are then tested again: a capped loss). In
            // trees shallower than that the neighbourhood is the whole trees.
            let na = ancestor(&a.nodes, la, NEIGHBOURHOOD_LEVELS);
            let nb = ancestor(&b.nodes, lb, NEIGHBOURHOOD_LEVELS);
            let mut stack = PooledStack::take();
            let mut hit = hit_fn(true, &mut found, &mut c.pairs);
            ctx.descend(na, nb, &mut stack, None, &mut hit);
            searched_all = (na, nb) == (0, 0);
        }
    }
    if found.is_none() && !searched_all {
        walk_or_traverse(
            &mut ctx,
            cache,
            first,
            coherent,
            was_touching,
            &mut found,
            &mut c.pairs,
        );
    }
    if first {
        c.witness = found;
        cache.witness = found;
        cache.witness_leaves = found.map(|_| ctx.last_leaves);
    }
    finish(&ctx, request, c)
}

/// The front walk or a fresh traversal of a cached query ([`collide_cached`], after its cheap
/// rejections), under the cache's work budget and back-off: fills `found` (first contact) or
/// `pairs` (all pairs), records the next front where the next query will try it.
fn walk_or_traverse(
    ctx: &mut Ctx<'_>,
    cache: &mut PairCache,
    first: bool,
    coherent: bool,
    was_touching: bool,
    found: &mut Option<(u32, u32)>,
    pairs: &mut Vec<(u32, u32)>,
) {
    let mut use_front = coherent && !cache.front.is_empty() && cache.skip == 0;
    if use_front {
        let walked = cache.front.len();
        let before = ctx.counters.work();
        // The walk may spend at most 40 % of a fresh traversal: a stale front is abandoned
        // early.
        let budget = 2 * cache.fresh_work / 5;
        let mut hit = hit_fn(first, found, pairs);
        let (done, charged) = walk_front(
            ctx,
            &mut cache.front,
            &mut cache.scratch,
            cache.clock,
            budget,
            &mut hit,
        );
        drop(hit);
        let work = ctx.counters.work() - before + walked as u64 / 8 + charged;
        if !done || 5 * work > 3 * cache.fresh_work {
            // The front saved less than 40 % of a fresh traversal's work: drop it and back off
            // (a walk's work unit costs more time than a fresh wide traversal's, whose paired
            // steps test two entries at once, so a smaller saving did not pay in time:
            // measured on the near-contact knots).
            cache.front.clear();
            cache.backoff = (cache.backoff * 2).clamp(1, 64);
            cache.skip = cache.backoff;
        } else {
            cache.backoff = 0;
        }
        if !done {
            // Abandoned half way: start again from the root (the pairs found so far would be
            // found again).
            pairs.clear();
            *found = None;
            use_front = false;
        }
    }
    if !use_front {
        cache.skip = cache.skip.saturating_sub(1);
        // Record a front only when the next query will try it.
        let record = coherent && cache.skip == 0 && !was_touching;
        let mut front = std::mem::take(&mut cache.front);
        front.clear();
        let before = ctx.counters.work();
        let mut stack = PooledStack::take();
        let mut hit = hit_fn(first, found, pairs);
        ctx.descend(
            0,
            0,
            &mut stack,
            record.then_some((&mut front, cache.clock)),
            &mut hit,
        );
        // A running mean: a first-contact traversal's work varies with where the hit is.
        let work = ctx.counters.work() - before;
        cache.fresh_work = if cache.fresh_work == 0 {
            work
        } else {
            (3 * cache.fresh_work + work) / 4
        };
        cache.front = front;
    }
}

/// How many levels above the old witness's leaves a coherent cached first-contact query
/// searches before the whole trees (the subtrees hold up to `2^4` leaves each). The dense
/// sweep's cached first contact, 2 / 3 / 4 / 5 / 7 levels against none (alternated twice):
/// touching steps' median 2.0 / 1.5-1.6 / 1.3-1.4 / 1.4-1.5 / 1.9 µs against 2.1-2.2, the
/// sequence 0.36 / 0.34-0.35 / 0.32-0.33 / 0.33 / 0.37 ms against 0.38-0.39; near-contact
/// knots 16.7 → 16.1-16.3 ms at 4; the random-pose CAD pairs (not coherent: no search)
/// unchanged.
const NEIGHBOURHOOD_LEVELS: usize = 4;

/// The node `levels` (at most 7) levels above node `leaf` on its path from the root (the root
/// when the path is shorter, or when `leaf` is no node of `nodes`). In the depth-first layout the
/// left child of `n` is `n + 1` and the right one `right(n)`, so each subtree is one range of
/// ids and the path follows from comparisons.
fn ancestor(nodes: &[TNode], leaf: u32, levels: usize) -> u32 {
    const RING: usize = 8;
    let levels = levels.min(RING - 1);
    let mut path = [0u32; RING];
    let (mut n, mut depth) = (0u32, 0usize);
    while n != leaf {
        let Some(node) = nodes.get(n as usize) else {
            return 0;
        };
        if node.is_leaf() {
            return 0;
        }
        n = if leaf < node.right() {
            n + 1
        } else {
            node.right()
        };
        depth += 1;
        path[depth % RING] = n;
    }
    if depth < levels {
        0
    } else {
        path[(depth - levels) % RING]
    }
}

/// The hit callback of a cached query: first contact stores the pair and stops, all pairs
/// collects them.
fn hit_fn<'a>(
    first: bool,
    found: &'a mut Option<(u32, u32)>,
    pairs: &'a mut Vec<(u32, u32)>,
) -> impl FnMut(u32, u32) -> bool + 'a {
    move |x, y| {
        if first {
            *found = Some((x, y));
            true
        } else {
            pairs.push((x, y));
            false
        }
    }
}

/// Work charged on top of a front walk's counters per four-lane re-test of expired entries
/// (and, on the f64 traversal, per descent, each of which re-tests one entry): the walk's
/// gathers and scattered loads cost more per test than a fresh wide traversal's steps, so its
/// counters alone undercount its time next to a fresh traversal. Three: set when each expired
/// entry started its own descent (with two, fronts on the near-contact knots saved about 4 %
/// of the work and cost 10 % more time; with four, the touching all-pairs front of
/// `coherent_front_does_less_work` at leaf 1, which saves 3× the work, was dropped), and
/// measured again with batched re-tests (charging descents from overlapping entries as well
/// changed the near-contact knots by under 2 %).
const WALK_STEP_WORK: u64 = 3;

/// Walks the front (see [`collide_cached`]) in place: returns whether it finished within
/// `budget`, and the work to charge on top of its counters ([`WALK_STEP_WORK`] per re-test
/// step). Separated pairs whose margin still exceeds the motion since their test are kept
/// untested. The others (expired) are re-tested four at a time in lanes: a pair separated
/// again only gets its new bound, one that overlaps is traversed from where it is. Every leaf
/// pair is covered exactly once whatever the front holds, so the answer never depends on the
/// cache; an abandoned walk's results are incomplete (the caller starts again from the root).
/// A walk whose expired entries alone would cost more than `budget` is abandoned before it
/// starts.
///
/// A separated entry whose bound still holds is only read, never moved, so a query on a
/// coherent front costs one comparison per valid entry (eight at a time). An entry that is
/// traversed again is replaced by the first entry its descent records, the others appended
/// after the walked part (`scratch` holds them meanwhile); appended entries are fresh and not
/// walked again in this query. On a hit (first contact) the descent's untested pairs are
/// recorded the same way and every entry not reached stays as it is, so the front remains a
/// cut.
fn walk_front(
    ctx: &mut Ctx<'_>,
    front: &mut Front,
    scratch: &mut Front,
    clock: f64,
    budget: u64,
    hit: &mut impl FnMut(u32, u32) -> bool,
) -> (bool, u64) {
    #[cfg(target_arch = "x86_64")]
    if ctx.avx2 {
        // SAFETY: `avx2` is true only where the running CPU reports AVX2 (`Ctx::new`,
        // `isa::has_avx2`), the one feature `walk_front_avx2` is compiled with.
        #[allow(unsafe_code)]
        return unsafe { walk_front_avx2(ctx, front, scratch, clock, budget, hit) };
    }
    walk_front_body(ctx, front, scratch, clock, budget, hit)
}

/// [`walk_front`] compiled with AVX2 (`isa.rs`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn walk_front_avx2(
    ctx: &mut Ctx<'_>,
    front: &mut Front,
    scratch: &mut Front,
    clock: f64,
    budget: u64,
    hit: &mut impl FnMut(u32, u32) -> bool,
) -> (bool, u64) {
    walk_front_body(ctx, front, scratch, clock, budget, hit)
}

/// The body of [`walk_front`], inlined into each of its instruction-set builds.
#[inline(always)]
fn walk_front_body(
    ctx: &mut Ctx<'_>,
    front: &mut Front,
    scratch: &mut Front,
    clock: f64,
    budget: u64,
    hit: &mut impl FnMut(u32, u32) -> bool,
) -> (bool, u64) {
    let start = ctx.counters.work();
    let mut charged = 0u64;
    let mut stack = PooledStack::take();
    let limit = clock + ctx.slack;
    let walked = front.len();
    // Each expired entry costs at least its lane (a box test and a placement) and a quarter
    // of its step's charge: when that alone exceeds the budget, the walk would be abandoned
    // half way, after spending it (a quarter of the near-contact knots' walks were; first
    // contact there went from 1.06× to 0.98-1.00× of the plain time).
    let expired = front.count_expired(walked, limit) as u64;
    if expired * (8 + WALK_STEP_WORK) / 4 > budget {
        return (false, 0);
    }
    // One pass in either mode, in front order: a touching first-contact query is mostly
    // decided by the witness before the walk, and a disjoint one re-tests every expired entry
    // anyway (two passes, overlapping leaf pairs first, cost more than they found early).
    let mut k = 0;
    loop {
        // The next (up to) four expired entries.
        let mut batch = [0usize; 4];
        let mut n = 0;
        while n < 4 {
            k = front.next_expired(k, walked, limit);
            if k >= walked {
                break;
            }
            batch[n] = k;
            n += 1;
            k += 1;
        }
        if n == 0 {
            return (true, charged);
        }
        if ctx.counters.work() - start + charged > budget {
            return (false, charged);
        }
        // Most expired entries are separated again: one four-lane test re-tests them all and
        // only refreshes their bounds in place. (Pairs beyond f32 take the f64 way, one at a
        // time from their own descent.)
        let (overlapping, placed) = match ctx.sat32 {
            Some(sat) => {
                charged += WALK_STEP_WORK;
                let (mut ia, mut ib) = ([0u32; 4], [0u32; 4]);
                for (l, &e) in batch[..n].iter().enumerate() {
                    (ia[l], ib[l]) = front.pairs[e];
                }
                ctx.counters.box_tests += n as u64;
                ctx.counters.placements += n as u64;
                let placed = sat.place_lanes(&ctx.b.nodes, &ib, n);
                let m = wide::separation4(
                    &ALanes::gather(&ctx.a.nodes, &ia, n),
                    &placed,
                    sat.s(),
                    (1 << n) - 1,
                );
                let mut overlapping = 0u32;
                for (l, &e) in batch[..n].iter().enumerate() {
                    if m.0[l] > 0.0 {
                        front.bounds[e] = clock + wide::margin64(m.0[l]);
                    } else {
                        overlapping |= 1 << l;
                    }
                }
                (overlapping, Some((sat, placed)))
            }
            None => ((1 << n) - 1, None),
        };
        // The overlapping ones are traversed from where they are (their test is not
        // repeated); each such descent's counters count its work.
        for (l, &e) in batch[..n].iter().enumerate() {
            if overlapping & (1 << l) == 0 {
                continue;
            }
            scratch.clear();
            let (a, b) = front.pairs[e];
            let rec = Some((&mut *scratch, clock));
            let stop = match &placed {
                Some((sat, lanes)) => {
                    let start = Some(lanes.broadcast(l));
                    ctx.descend_wide(sat, a, b, start, &mut stack, rec, hit)
                }
                None => {
                    charged += WALK_STEP_WORK;
                    ctx.descend64(a, b, &mut stack, rec, hit)
                }
            };
            // A descent records at least its start pair's outcome (separated, a leaf pair, or
            // untested after a hit), so the slot is always refilled.
            debug_assert!(!scratch.is_empty());
            if !scratch.is_empty() {
                front.pairs[e] = scratch.pairs[0];
                front.bounds[e] = scratch.bounds[0];
                front.pairs.extend_from_slice(&scratch.pairs[1..]);
                front.bounds.extend_from_slice(&scratch.bounds[1..]);
            }
            if stop {
                return (true, charged);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tree::BuildOptions;
    use frcd_geom::{DQuat, shapes};

    /// The wide f32 traversal and the binary f64 one give the oracle's pairs and the same
    /// first-contact answer, with the cache or without, near contact and at huge offsets
    /// (where the wide traversal hands over to the f64 one); the counters count lanes.
    #[test]
    fn wide_and_binary_traversals_agree_with_the_oracle() {
        let ma = shapes::icosphere(1.0, 3);
        let mb = shapes::subdivide(&shapes::cuboid(DVec3::new(0.9, 0.3, 0.6)));
        for leaf in [1, 2, 4, 5] {
            let opts = BuildOptions {
                max_leaf_triangles: leaf,
                ..BuildOptions::default()
            };
            let ta = ObbTree::build(&ma, &opts);
            let tb = ObbTree::build(&mb, &opts);
            let all = Request {
                mode: Mode::AllPairs,
                ..Request::default()
            };
            let first = Request::default();
            let mut caches = [PairCache::new(), PairCache::new()];
            let (mut touching, mut wide_boxes, mut binary_boxes) = (0, 0, 0);
            for k in 0..120 {
                let offset = if k % 40 == 39 { 1e31 } else { 1.0 };
                let base = DVec3::new(0.3 * k as f64, -2.0, 7.0) * offset;
                let pa = Pose::new(base, DQuat::from_rotation_y(0.05 * k as f64));
                let s = 0.6 + 0.012 * k as f64 % 1.0;
                let dir = DVec3::new(1.0, 0.2 * (k % 5) as f64, 0.1).normalize();
                let pb = Pose::new(
                    base + dir * s * 1.4,
                    DQuat::from_axis_angle(DVec3::new(0.3, 1.0, -0.2).normalize(), 0.07 * k as f64),
                );
                let truth = crate::oracle::pairs(&ma, &pa, &mb, &pb);
                touching += !truth.is_empty() as u32;
                for (n, t) in [Traversal::Wide, Traversal::Binary].into_iter().enumerate() {
                    with_traversal(t, || {
                        let c = collide(&ta, &pa, &tb, &pb, &all);
                        assert_eq!(c.pairs, truth, "leaf {leaf} step {k} {t:?}");
                        let cc = collide_cached(&ta, &pa, &tb, &pb, &all, &mut caches[n]);
                        assert_eq!(cc.pairs, truth, "leaf {leaf} step {k} {t:?} cached");
                        let f = collide(&ta, &pa, &tb, &pb, &first);
                        assert_eq!(f.collide, !truth.is_empty(), "leaf {leaf} step {k} {t:?}");
                        if let Some(w) = f.witness {
                            assert!(truth.binary_search(&w).is_ok());
                        }
                        if offset == 1.0 {
                            match t {
                                Traversal::Binary => binary_boxes += c.counters.box_tests,
                                _ => wide_boxes += c.counters.box_tests,
                            }
                        }
                    });
                }
            }
            assert!(touching > 20 && touching < 110, "{touching}");
            // Both traversals test box pairs (a lane counts one), within a factor of two.
            assert!(wide_boxes > 0 && binary_boxes > 0);
            assert!(wide_boxes < 2 * binary_boxes && binary_boxes < 2 * wide_boxes);
        }
    }
}

/// The AVX2 build of the wide traversal against its baseline build (`isa.rs`).
#[cfg(test)]
mod isa_tests {
    use super::*;
    use crate::tree::BuildOptions;
    use frcd_geom::{DQuat, shapes};

    /// Both builds run the same IEEE operations, so on a coherent sequence (fronts recorded,
    /// walked and refreshed) and on incoherent jumps they give the same pairs, witnesses,
    /// counters, and front margins bit for bit; and both give the oracle's pairs.
    #[test]
    fn avx2_and_baseline_builds_agree_bit_for_bit() {
        if !isa::has_avx2() {
            eprintln!("note: this CPU has no AVX2; both runs use the baseline build");
        }
        let ma = shapes::torus(1.0, 0.35, 40, 16).expect("valid torus");
        let mb = shapes::icosphere(0.5, 3);
        let opts = BuildOptions::default();
        let (ta, tb) = (ObbTree::build(&ma, &opts), ObbTree::build(&mb, &opts));
        let mut caches = [
            [PairCache::new(), PairCache::new()],
            [PairCache::new(), PairCache::new()],
        ];
        let (mut touching, mut fronts) = (0, 0);
        for k in 0..160 {
            // Slow coherent motion through the ring, with a jump every 20th step.
            let s = if k % 20 == 19 {
                3.7 * k as f64
            } else {
                0.02 * k as f64
            };
            let pa = Pose::new(DVec3::ZERO, DQuat::from_rotation_z(0.3 * s));
            let pb = Pose::new(
                DVec3::new(1.0 - 1.1 * s.sin(), 0.1 * s.cos(), 0.1 * (2.0 * s).sin()),
                DQuat::from_axis_angle(DVec3::new(0.2, 1.0, 0.4).normalize(), s),
            );
            let truth = crate::oracle::pairs(&ma, &pa, &mb, &pb);
            touching += !truth.is_empty() as u32;
            for (m, mode) in [Mode::FirstContact, Mode::AllPairs].into_iter().enumerate() {
                let req = Request {
                    mode,
                    ..Request::default()
                };
                let run = |t: Traversal, cache: &mut PairCache| {
                    with_traversal(t, || {
                        let plain = collide(&ta, &pa, &tb, &pb, &req);
                        let cached = collide_cached(&ta, &pa, &tb, &pb, &req, cache);
                        (plain, cached)
                    })
                };
                let [c0, c1] = &mut caches[m];
                let (p0, q0) = run(Traversal::Wide, c0);
                let (p1, q1) = run(Traversal::WideBaseline, c1);
                for (x, y, what) in [(&p0, &p1, "plain"), (&q0, &q1, "cached")] {
                    assert_eq!(x.collide, y.collide, "step {k} {mode:?} {what}");
                    assert_eq!(x.pairs, y.pairs, "step {k} {mode:?} {what}");
                    assert_eq!(x.witness, y.witness, "step {k} {mode:?} {what}");
                    assert_eq!(x.counters, y.counters, "step {k} {mode:?} {what}");
                    assert_eq!(x.collide, !truth.is_empty(), "step {k} {mode:?} {what}");
                }
                if mode == Mode::AllPairs {
                    assert_eq!(p0.pairs, truth, "step {k}");
                }
                assert_eq!(c0.front.pairs, c1.front.pairs, "step {k} {mode:?}");
                let bits = |f: &Front| f.bounds.iter().map(|b| b.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&c0.front), bits(&c1.front), "step {k} {mode:?}");
                fronts += !c0.front.is_empty() as u32;
            }
        }
        // The sequence exercises both answers and recorded fronts.
        assert!(touching > 20 && touching < 150, "{touching}");
        assert!(fronts > 40, "{fronts}");
    }
}

/// The coherence cache's front walk: its scan, its batched re-tests on both traversals, and
/// the walk it refuses to start.
#[cfg(test)]
mod walk_tests {
    use super::*;
    use crate::tree::{BuildOptions, SplitMethod};
    use frcd_geom::{DQuat, shapes};
    use rand::{Rng, SeedableRng};

    /// `deepest_last` returns exactly the overlapping lanes (margin not positive, NaN
    /// included) among the first `n`, largest margin first, ties by lane: a reference sort on
    /// random and hand-picked margins.
    #[test]
    fn deepest_last_orders_the_overlapping_lanes() {
        const PICKS: [f32; 9] = [
            -2.0,
            -1.0,
            -0.0,
            0.0,
            0.5,
            -1.0,
            f32::NAN,
            -f32::INFINITY,
            3.0,
        ];
        let mut rng = rand::rngs::StdRng::seed_from_u64(31);
        let mut pick = || PICKS[rng.random_range(0..PICKS.len())];
        for _ in 0..2000 {
            let m = wide::F4([pick(), pick(), pick(), pick()]);
            for n in 1..=4 {
                let mut want: Vec<usize> = (0..n)
                    .filter(|&k| m.0[k].is_nan() || m.0[k] <= 0.0)
                    .collect();
                // Largest first by total order (NaN above +inf, -0 below +0), ties by lane.
                want.sort_by(|&p, &q| m.0[q].total_cmp(&m.0[p]).then(p.cmp(&q)));
                let (order, len) = deepest_last(&m, n);
                assert_eq!(&order[..len], &want[..], "{:?} n {n}", m.0);
            }
        }
    }

    /// First contact's deepest-first steps find a touching pair with fewer box tests than
    /// lane order on overlapping meshes, with the same answers (checked against the oracle).
    #[test]
    fn ordered_first_contact_finds_contact_with_less_work() {
        let ma = shapes::icosphere(1.0, 4);
        let mb = shapes::icosphere(0.7, 4);
        let ta = ObbTree::build(&ma, &BuildOptions::default());
        let tb = ObbTree::build(&mb, &BuildOptions::default());
        let first = Request::default();
        let (mut ordered, mut plain, mut touching) = (0u64, 0u64, 0);
        for k in 0..60 {
            let pa = Pose::new(DVec3::ZERO, DQuat::from_rotation_z(0.1 * k as f64));
            let dir = DVec3::new((0.37 * k as f64).cos(), (0.37 * k as f64).sin(), 0.3).normalize();
            let pb = Pose::new(
                dir * (0.4 + 0.02 * (k % 20) as f64),
                DQuat::from_rotation_x(0.13 * k as f64),
            );
            let truth = crate::oracle::pairs(&ma, &pa, &mb, &pb);
            if truth.is_empty() {
                continue;
            }
            touching += 1;
            for (n, work) in [(ORDERED_STEPS, &mut ordered), (0, &mut plain)] {
                let f = with_ordered_steps(n, || collide(&ta, &pa, &tb, &pb, &first));
                assert!(f.collide, "step {k}");
                let w = f.witness.expect("a witness");
                assert!(truth.binary_search(&w).is_ok(), "step {k}: {w:?}");
                *work += f.counters.box_tests;
            }
        }
        assert!(touching > 40, "{touching}");
        assert!(
            ordered < plain,
            "ordered {ordered} against lane order {plain}"
        );
    }

    /// The eight-at-a-time scan finds the same expired pairs as a pair-by-pair one, at every
    /// chunk boundary, with -∞ (always expired) and NaN bounds among them.
    #[test]
    fn front_scan_finds_every_expired_pair() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        for len in [0usize, 1, 7, 8, 9, 16, 17, 40, 203] {
            for density in [0.0, 0.02, 0.3, 1.0] {
                let mut f = Front::default();
                for k in 0..len {
                    let bound = if rng.random_bool(density) {
                        match k % 3 {
                            0 => f64::NEG_INFINITY,
                            1 => f64::NAN,
                            _ => rng.random_range(0.0..1.0),
                        }
                    } else {
                        rng.random_range(1.0..2.0)
                    };
                    f.push(k as u32, 0, bound);
                }
                let limit = 1.0;
                // Expired unless the bound is known greater than the limit.
                let naive: Vec<usize> = (0..len)
                    .filter(|&k| {
                        f.bounds[k].partial_cmp(&limit) != Some(std::cmp::Ordering::Greater)
                    })
                    .collect();
                for end in [len, len / 2] {
                    let mut found = Vec::new();
                    let mut k = 0;
                    loop {
                        k = f.next_expired(k, end, limit);
                        if k >= end {
                            break;
                        }
                        found.push(k);
                        k += 1;
                    }
                    let want: Vec<usize> = naive.iter().copied().filter(|&k| k < end).collect();
                    assert_eq!(found, want, "len {len} density {density} end {end}");
                    assert_eq!(f.count_expired(end, limit), want.len());
                }
            }
        }
    }

    /// Slow coherent motion near contact, where fronts are walked every query: the cached
    /// answers equal the oracle's on the wide traversal (four-lane re-tests) and on the binary
    /// one (one descent per expired pair), in both modes, on the trees of both split rules, and
    /// the wide walk saves work (all pairs on the surface-cost trees: costs at most 1.1x).
    #[test]
    fn batched_walks_agree_with_the_oracle_on_both_traversals() {
        let ma = shapes::torus(1.0, 0.3, 32, 12).unwrap();
        let mb = shapes::icosphere(0.4, 2);
        for split in [SplitMethod::SurfaceCost, SplitMethod::MajorAxisMean] {
            let opts = BuildOptions {
                split,
                ..BuildOptions::default()
            };
            let (ta, tb) = (ObbTree::build(&ma, &opts), ObbTree::build(&mb, &opts));
            for t in [Traversal::Wide, Traversal::Binary] {
                for mode in [Mode::AllPairs, Mode::FirstContact] {
                    let req = Request {
                        mode,
                        ..Request::default()
                    };
                    let mut cache = PairCache::new();
                    let (mut plain, mut cached, mut touching, mut walked) = (0, 0, 0, 0);
                    with_traversal(t, || {
                        for k in 0..80 {
                            // Slowly from the middle of the hole into the tube.
                            let x = 0.26 + 0.0015 * k as f64;
                            let pb = Pose::new(
                                DVec3::new(x, 0.0, 0.02),
                                DQuat::from_rotation_z(0.004 * k as f64),
                            );
                            let pa = Pose::IDENTITY;
                            let truth = crate::oracle::pairs(&ma, &pa, &mb, &pb);
                            touching += !truth.is_empty() as u32;
                            walked += (cache.front_len() > 0) as u32;
                            let p = collide(&ta, &pa, &tb, &pb, &req);
                            let c = collide_cached(&ta, &pa, &tb, &pb, &req, &mut cache);
                            assert_eq!(c.collide, !truth.is_empty(), "{t:?} {mode:?} step {k}");
                            match mode {
                                Mode::AllPairs => assert_eq!(c.pairs, truth, "{t:?} step {k}"),
                                _ => {
                                    if let Some(w) = c.witness {
                                        assert!(truth.binary_search(&w).is_ok(), "{t:?} step {k}");
                                    }
                                }
                            }
                            if k > 0 {
                                plain += p.counters.work();
                                cached += c.counters.work();
                            }
                        }
                    });
                    assert!(touching > 10 && touching < 70, "{touching}");
                    assert!(
                        walked > 15,
                        "{split:?} {t:?} {mode:?}: a front before {walked} queries"
                    );
                    if t == Traversal::Wide {
                        // The surface-cost trees leave a fresh all-pairs traversal less to waste
                        // (plain work 122,782 against 127,462 on the mean-cut trees), and the walk
                        // then breaks even (124,116): there it must not cost, <= 1.1x.
                        let gains =
                            mode == Mode::FirstContact || split == SplitMethod::MajorAxisMean;
                        assert!(
                            if gains {
                                cached < plain
                            } else {
                                cached * 10 <= plain * 11
                            },
                            "{split:?} {mode:?}: cached work {cached}, plain {plain}"
                        );
                    }
                }
            }
        }
    }

    /// The thread's pooled stack comes back empty after queries that stop at a first contact
    /// and keeps its buffers, with and without a cache, so it neither grows query after query
    /// nor reallocates.
    #[test]
    fn pooled_stack_comes_back_empty_and_keeps_its_buffers() {
        let t = ObbTree::build(&shapes::icosphere(1.0, 3), &BuildOptions::default());
        let near = Pose::from_translation(DVec3::new(1.0, 0.0, 0.0));
        let pooled = || {
            STACK.with(|c| {
                let s = c.take();
                let r = (
                    s.pairs.len() + s.placed.len() + s.placed32.len(),
                    s.pairs.capacity(),
                );
                c.set(s);
                r
            })
        };
        let mut cache = PairCache::new();
        for k in 0..4 {
            let hit = if k % 2 == 0 {
                collide(&t, &Pose::IDENTITY, &t, &near, &Request::default())
            } else {
                collide_cached(
                    &t,
                    &Pose::IDENTITY,
                    &t,
                    &near,
                    &Request::default(),
                    &mut cache,
                )
            };
            assert!(hit.collide);
            let (len, capacity) = pooled();
            assert_eq!(len, 0, "query {k} left entries on the pooled stack");
            assert!(
                capacity >= 64,
                "query {k}: the pooled stack lost its buffers"
            );
        }
    }

    /// The radix sort of long pair lists gives the comparison sort's order, on lists with
    /// repeated A triangles, high bits set on either side, and lengths about its threshold.
    #[test]
    fn pair_sort_matches_the_comparison_sort() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        for len in [0, 1, 2, RADIX_MIN_PAIRS - 1, RADIX_MIN_PAIRS, 600, 5_000] {
            for range in [4u32, 70_000, u32::MAX] {
                let mut pairs: Vec<(u32, u32)> = (0..len)
                    .map(|_| (rng.random_range(0..=range), rng.random_range(0..=range)))
                    .collect();
                let mut expected = pairs.clone();
                expected.sort_unstable();
                sort_pairs(&mut pairs);
                assert_eq!(pairs, expected, "{len} pairs below {range}");
            }
        }
    }

    /// Placed leaves are reused within a query only: on one thread, queries at poses that
    /// alternate between nearby frames (so the same B leaves are met again in another frame),
    /// with A alternating between two trees of nearly the same shape (so the same A node
    /// indices are met again with other triangles), give the oracle's pairs every time, on
    /// both leaf sizes that go through the slots and on leaves too large for them.
    #[test]
    fn placed_leaves_never_cross_queries() {
        let ma = [shapes::icosphere(1.0, 3), shapes::icosphere(1.04, 3)];
        let mb = shapes::icosphere(0.7, 3);
        for leaf in [1, 2, 4] {
            let opts = BuildOptions {
                max_leaf_triangles: leaf,
                ..BuildOptions::default()
            };
            let ta = ma.each_ref().map(|m| ObbTree::build(m, &opts));
            let tb = ObbTree::build(&mb, &opts);
            let all = Request {
                mode: Mode::AllPairs,
                ..Request::default()
            };
            let mut caches = [PairCache::new(), PairCache::new()];
            for k in 0..12 {
                let angle = if k % 2 == 0 {
                    0.0
                } else {
                    0.3 + 0.01 * k as f64
                };
                let pb = Pose::new(
                    DVec3::new(1.2 + 0.02 * (k % 3) as f64, 0.1, 0.0),
                    DQuat::from_rotation_z(angle),
                );
                let s = (k / 2) % 2;
                let truth = crate::oracle::pairs(&ma[s], &Pose::IDENTITY, &mb, &pb);
                assert!(!truth.is_empty());
                let plain = collide(&ta[s], &Pose::IDENTITY, &tb, &pb, &all);
                assert_eq!(plain.pairs, truth, "leaf {leaf}, query {k}");
                let cache = &mut caches[s];
                let cached = collide_cached(&ta[s], &Pose::IDENTITY, &tb, &pb, &all, cache);
                assert_eq!(cached.pairs, truth, "leaf {leaf}, cached query {k}");
            }
        }
    }

    /// `ancestor` follows the parent links: checked against parents collected from the
    /// children links, for every node and every number of levels (past the root too, and past
    /// the seven it caps them at), and it answers the root for an id past the last node.
    #[test]
    fn ancestor_follows_the_parent_links() {
        let m = shapes::icosphere(1.0, 3);
        for leaf in [1, 2, 4] {
            let opts = BuildOptions {
                max_leaf_triangles: leaf,
                ..BuildOptions::default()
            };
            let t = ObbTree::build(&m, &opts);
            let nodes = &t.nodes;
            let mut parent = vec![u32::MAX; nodes.len()];
            for (n, node) in nodes.iter().enumerate() {
                if !node.is_leaf() {
                    parent[n + 1] = n as u32;
                    parent[node.right() as usize] = n as u32;
                }
            }
            for n in 0..nodes.len() {
                for levels in 0..10 {
                    let mut want = n as u32;
                    for _ in 0..levels.min(7) {
                        if want != 0 {
                            want = parent[want as usize];
                        }
                    }
                    assert_eq!(
                        ancestor(nodes, n as u32, levels),
                        want,
                        "node {n}, {levels}"
                    );
                }
            }
            assert!(nodes.len() > 200);
            assert_eq!(ancestor(nodes, nodes.len() as u32, 1), 0);
        }
    }

    /// A coherent cached first-contact query searches the old witness's neighbourhood first;
    /// when that holds no touching pair it answers from the whole trees, as plain `collide`.
    /// A has two spheres far apart and B touches only the second; the cache is primed with a
    /// witness leaf pair on the first sphere.
    #[test]
    fn witness_neighbourhood_falls_back_to_the_whole_trees() {
        let s = shapes::icosphere(1.0, 3);
        let mut vertices = s.vertices().to_vec();
        let mut indices = s.indices().to_vec();
        let off = vertices.len() as u32;
        vertices.extend(s.vertices().iter().map(|v| *v + DVec3::new(6.0, 0.0, 0.0)));
        indices.extend(s.indices().iter().map(|t| t.map(|k| k + off)));
        let ma = frcd_geom::TriMesh::new(vertices, indices).unwrap();
        let mb = shapes::icosphere(0.5, 2);
        let (ta, tb) = (
            ObbTree::build(&ma, &BuildOptions::default()),
            ObbTree::build(&mb, &BuildOptions::default()),
        );
        let pb = Pose::new(DVec3::new(6.0, 1.3, 0.0), DQuat::from_rotation_z(0.2));
        let truth = crate::oracle::pairs(&ma, &Pose::IDENTITY, &mb, &pb);
        assert!(!truth.is_empty());
        // A leaf of A on the first sphere (its triangles come first in the mesh).
        let leaf_a = (0..ta.nodes.len() as u32)
            .find(|&n| ta.nodes[n as usize].is_leaf() && ta.node_triangles(n)[0] < off / 2)
            .unwrap();
        let leaf_b = (0..tb.nodes.len() as u32)
            .find(|&n| tb.nodes[n as usize].is_leaf())
            .unwrap();
        let first = Request::default();
        let mut box_tests = [0; 2];
        for primed in [false, true] {
            let mut cache = PairCache::new();
            // The same frame as the query: no motion, so the query is coherent.
            cache.bind(&ta, &tb, &RelativeFrame::new(&Pose::IDENTITY, &pb));
            if primed {
                cache.witness_leaves = Some((leaf_a, leaf_b));
            }
            let c = collide_cached(&ta, &Pose::IDENTITY, &tb, &pb, &first, &mut cache);
            assert!(c.collide);
            let w = c.witness.unwrap();
            assert!(truth.binary_search(&w).is_ok(), "{w:?}");
            box_tests[primed as usize] = c.counters.box_tests;
            // The next query starts from the new witness's neighbourhood.
            let (la, _) = cache.witness_leaves.unwrap();
            assert!(ta.node_triangles(la).iter().all(|&t| t >= off));
        }
        // The primed query tested the neighbourhood (in vain) before the whole trees.
        assert!(box_tests[1] > box_tests[0], "{box_tests:?}");
    }

    /// In trees shallower than the neighbourhood's levels the neighbourhood is the whole trees:
    /// when the contact ends, the query answers from that one search (no second traversal).
    #[test]
    fn witness_neighbourhood_of_shallow_trees_is_searched_once() {
        // B, a smaller cube, crosses A's face by 0.01, then moves 0.02 inward (a coherent
        // move): inside A without touching it, so no top volume can reject the pair and the
        // traversal must prove it.
        let (ma, mb) = (
            shapes::cuboid(DVec3::splat(0.5)),
            shapes::cuboid(DVec3::splat(0.3)),
        );
        let ta = ObbTree::build(&ma, &BuildOptions::default());
        let tb = ObbTree::build(&mb, &BuildOptions::default());
        for t in [&ta, &tb] {
            for n in 0..t.nodes.len() as u32 {
                if t.nodes[n as usize].is_leaf() {
                    assert_eq!(ancestor(&t.nodes, n, NEIGHBOURHOOD_LEVELS), 0, "leaf {n}");
                }
            }
        }
        let first = Request::default();
        let mut cache = PairCache::new();
        let touching = Pose::from_translation(DVec3::new(0.21, 0.02, 0.01));
        let inside = Pose::from_translation(DVec3::new(0.19, 0.02, 0.01));
        let c = collide_cached(&ta, &Pose::IDENTITY, &tb, &touching, &first, &mut cache);
        assert!(c.collide && cache.witness_leaves.is_some());
        let plain = collide(&ta, &Pose::IDENTITY, &tb, &inside, &first);
        let c = collide_cached(&ta, &Pose::IDENTITY, &tb, &inside, &first, &mut cache);
        assert!(!plain.collide && !c.collide);
        assert!(plain.counters.box_tests > 1, "the traversal ran");
        assert!(cache.witness_leaves.is_none());
        // One traversal's work, not two.
        assert!(
            c.counters.box_tests <= plain.counters.box_tests,
            "{} against {}",
            c.counters.box_tests,
            plain.counters.box_tests
        );
    }

    /// On a coherent sweep through a deep overlap the old witness pair often stops touching,
    /// and its neighbourhood then finds the next contact with at most three quarters of the
    /// work of a traversal from the roots (time-free counts: box tests, placements and
    /// triangle tests), with a touching witness at every step.
    #[test]
    fn witness_neighbourhood_finds_contact_with_less_work() {
        let ma = shapes::icosphere(1.0, 4);
        let mb = shapes::icosphere(0.8, 4);
        let (ta, tb) = (
            ObbTree::build(&ma, &BuildOptions::default()),
            ObbTree::build(&mb, &BuildOptions::default()),
        );
        let first = Request::default();
        let mut cache = PairCache::new();
        let (mut plain_work, mut cached_work, mut witness_misses) = (0, 0, 0);
        for step in 0..120 {
            let x = -1.0 + step as f64 / 60.0;
            let pb = Pose::new(
                DVec3::new(x, 0.2, 0.1),
                DQuat::from_rotation_z(0.01 * step as f64),
            );
            let old = cache.witness;
            let plain = collide(&ta, &Pose::IDENTITY, &tb, &pb, &first);
            let cached = collide_cached(&ta, &Pose::IDENTITY, &tb, &pb, &first, &mut cache);
            assert!(plain.collide && cached.collide, "step {step}");
            let w = cached.witness.unwrap();
            let frame = RelativeFrame::new(&Pose::IDENTITY, &pb);
            let (tri_a, tri_b) = (ta.triangle(w.0), frame.triangle(&tb.triangle(w.1)));
            assert!(
                frcd_tritri::intersects(Method::Exact, &tri_a, &tri_b),
                "step {step}"
            );
            if step > 0 && old != cached.witness {
                // The old witness pair no longer touches: without the neighbourhood the cache
                // would traverse from the roots (plain's work and the witness test).
                plain_work += plain.counters.work();
                cached_work += cached.counters.work();
                witness_misses += 1;
            }
        }
        eprintln!("work plain {plain_work}, cached {cached_work}, witness moved {witness_misses}");
        assert!(witness_misses > 20, "{witness_misses}");
        // Measured: 14,241 against 21,871.
        assert!(
            4 * cached_work <= 3 * plain_work,
            "cached {cached_work}, plain {plain_work}"
        );
    }

    /// When the query generation wraps, the slots of the generation 2^32 queries back are
    /// cleared, so a stale tag cannot match.
    #[test]
    fn placed_leaf_generation_wraps_without_stale_hits() {
        let mut leaves = PlacedLeaves::default();
        leaves.next_query();
        assert!(!leaves.slot(5).1, "empty slots hold nothing");
        assert!(leaves.slot(5).1, "the same query finds its placement");
        leaves.next_query();
        assert!(!leaves.slot(5).1, "the next query does not");
        // The last generation before the wrap tags a slot; the wrap comes back as
        // generation 1 with every tag cleared, so the slot is empty when generation
        // u32::MAX comes round again.
        leaves.generation = u32::MAX;
        assert!(!leaves.slot(7).1);
        assert!(leaves.slot(7).1);
        leaves.next_query();
        assert_eq!(leaves.generation, 1);
        assert!(
            leaves.tags.iter().all(|&t| t == 0),
            "a wrap clears the tags"
        );
        leaves.generation = u32::MAX;
        assert!(!leaves.slot(7).1, "no stale hit after the wrap");
    }

    /// A front whose expired pairs alone would cost more than the budget is not walked at
    /// all: no work, no pair, the front left as it was.
    #[test]
    fn hopeless_walk_is_abandoned_before_any_work() {
        let ma = shapes::icosphere(1.0, 3);
        let mb = shapes::icosphere(0.5, 3);
        let opts = BuildOptions::default();
        let (ta, tb) = (ObbTree::build(&ma, &opts), ObbTree::build(&mb, &opts));
        let pb = Pose::new(DVec3::new(1.1, 1.1, 0.0), DQuat::IDENTITY);
        let mut ctx = Ctx::new(&ta, &Pose::IDENTITY, &tb, &pb, Method::Exact);
        assert!(ctx.sat32.is_some());
        let (mut front, mut scratch, mut stack) =
            (Front::default(), Front::default(), Stack::new());
        let mut none = |_: u32, _: u32| -> bool { panic!("apart: no pair") };
        ctx.descend(0, 0, &mut stack, Some((&mut front, 0.0)), &mut none);
        assert!(front.len() > 8, "{}", front.len());
        let fresh = ctx.counters.work();
        // A clock past every bound: all expired.
        let clock = front.bounds.iter().fold(0.0f64, |m, &b| m.max(b)) + 1.0;
        let before = (front.pairs.clone(), front.bounds.clone());
        ctx.counters = Counters::default();
        let budget = front.len() as u64 * 2;
        let (done, charged) =
            walk_front(&mut ctx, &mut front, &mut scratch, clock, budget, &mut none);
        assert!(!done);
        assert_eq!((charged, ctx.counters), (0, Counters::default()));
        assert_eq!((front.pairs.clone(), front.bounds.clone()), before);
        // With the budget of a fresh traversal it walks, and finds the same: apart.
        let (done, _) = walk_front(
            &mut ctx,
            &mut front,
            &mut scratch,
            clock,
            4 * fresh,
            &mut none,
        );
        assert!(done);
        assert!(ctx.counters.box_tests > 0);
    }
}

#[cfg(test)]
mod huge_tests {
    use super::*;
    use crate::tree::BuildOptions;
    use frcd_geom::{DQuat, shapes};

    /// Meshes beyond f32's range: the query runs the f64 traversal and still equals the oracle.
    #[test]
    fn magnitudes_beyond_f32_use_the_f64_traversal() {
        let ma = shapes::icosphere(1e31, 2);
        let mb = shapes::cuboid(DVec3::new(9e30, 3e30, 6e30));
        let opts = BuildOptions::default();
        let (ta, tb) = (ObbTree::build(&ma, &opts), ObbTree::build(&mb, &opts));
        let all = Request {
            mode: Mode::AllPairs,
            ..Request::default()
        };
        let mut hits = 0;
        for k in 0..20 {
            let pa = Pose::IDENTITY;
            let pb = Pose::new(
                DVec3::new(1.2e31 + 0.1e31 * k as f64, 0.0, 0.0),
                DQuat::from_rotation_z(0.3 * k as f64),
            );
            let ctx = Ctx::new(&ta, &pa, &tb, &pb, Method::Exact);
            assert!(ctx.sat32.is_none());
            let truth = crate::oracle::pairs(&ma, &pa, &mb, &pb);
            hits += !truth.is_empty() as u32;
            assert_eq!(collide(&ta, &pa, &tb, &pb, &all).pairs, truth, "{k}");
        }
        assert!(hits > 0 && hits < 20, "{hits}");
        // The same shapes at unit scale run the wide traversal.
        let small = ObbTree::build(&shapes::icosphere(1.0, 2), &opts);
        let ctx = Ctx::new(
            &small,
            &Pose::IDENTITY,
            &small,
            &Pose::IDENTITY,
            Method::Exact,
        );
        assert!(ctx.sat32.is_some());
    }
}

/// The coherence cache's motion bound: never below the true motion, tighter than Frobenius.
#[cfg(test)]
mod motion_tests {
    use super::*;
    use crate::tree::BuildOptions;
    use frcd_geom::{DQuat, shapes};
    use rand::{Rng, SeedableRng};

    fn random_rotation(rng: &mut rand::rngs::StdRng) -> DQuat {
        let mut c = || rng.random::<f64>() - 0.5;
        DQuat::from_xyzw(c(), c(), c(), c()).normalize()
    }

    /// `√(vᵀGv)` for the unit vector power iteration converges to: never above `‖D‖₂`
    /// (computed on `D` scaled by a power of two near 1, then scaled back).
    fn norm_from_below(d: DMat3) -> f64 {
        let m = d
            .x_axis
            .abs()
            .max(d.y_axis.abs())
            .max(d.z_axis.abs())
            .max_element();
        if m == 0.0 {
            return 0.0;
        }
        let k = 2f64.powi(-(m.log2().floor() as i32));
        let (d, back) = if k.is_finite() && k > 0.0 {
            (d * k, 1.0 / k)
        } else {
            (d, 1.0)
        };
        let g = d.transpose() * d;
        let mut best: f64 = 0.0;
        for start in [DVec3::X, DVec3::Y, DVec3::Z, DVec3::ONE] {
            let mut v = start;
            for _ in 0..200 {
                let w = g * v;
                if w.length_squared() == 0.0 {
                    break;
                }
                v = w.normalize();
            }
            best = best.max(v.dot(g * v));
        }
        best.sqrt() * back
    }

    #[test]
    fn spectral_bound_holds_and_beats_frobenius_on_rotations() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(21);
        let mut q = || random_rotation(&mut rng);
        let mut cases = Vec::new();
        for k in 0..2000 {
            let q0 = q();
            // Rotation differences from 1e-9 rad to a half turn.
            let angle = 10f64.powf(-9.0 + 9.5 * (k as f64 / 2000.0));
            let axis = q().xyz().normalize();
            let q1 = DQuat::from_axis_angle(axis, angle) * q0;
            cases.push((DMat3::from_quat(q1) - DMat3::from_quat(q0), true));
            // General matrices at many scales, some of rank one.
            let s = 10f64.powi((k % 40) * 10 - 200);
            let r = DMat3::from_quat(q()) * s * (k as f64 + 1.0);
            let r = if k % 3 == 0 {
                DMat3::from_cols(r.x_axis, r.x_axis * 0.5, r.x_axis * -2.0)
            } else {
                r
            };
            cases.push((r, false));
        }
        for (d, rotation) in cases {
            let bound = spectral_norm_bound(d);
            let norm = norm_from_below(d);
            assert!(norm.is_finite() && norm > 0.0, "{d:?}");
            assert!(
                bound >= norm * (1.0 - 1e-14),
                "{d:?}: {bound} against {norm}"
            );
            if rotation {
                let fro = (d.x_axis.length_squared()
                    + d.y_axis.length_squared()
                    + d.z_axis.length_squared())
                .sqrt();
                // Samuelson on the eigenvalues {0, a, a}: √(4a/3) against √(2a).
                assert!(bound < 0.83 * fro, "{bound} against Frobenius {fro}");
            }
        }
    }

    #[test]
    fn rotation_change_bound_holds_and_is_near_exact() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(23);
        let mut unit = || random_rotation(&mut rng);
        let mut exact_like = 0;
        for k in 0..4000 {
            let q0 = unit();
            let angle = 10f64.powf(-9.0 + 9.5 * ((k / 2) as f64 / 2000.0));
            let q1 = DQuat::from_axis_angle(unit().xyz().normalize(), angle) * q0;
            let (m0, m1) = if k % 2 == 0 {
                (DMat3::from_quat(q0), DMat3::from_quat(q1))
            } else {
                // Relative frames as queries compute them, from poses at large offsets.
                let a = Pose::new(DVec3::new(3.0, -1.0, 2.0), unit());
                let f0 = RelativeFrame::new(&a, &Pose::new(DVec3::X, q0));
                let f1 = RelativeFrame::new(&a, &Pose::new(DVec3::X, q1));
                (f0.m, f1.m)
            };
            let bound = rotation_change_bound(&m0, &m1);
            let norm = norm_from_below(m1 - m0);
            assert!(bound >= norm * (1.0 - 1e-14), "{k}: {bound} against {norm}");
            let exact = 2.0 * (angle / 2.0).sin();
            if angle > 1e-6 && angle < 1.5 {
                assert!(
                    bound <= exact * 1.001 + 1e-7,
                    "{k}: {bound} against {exact}"
                );
                exact_like += 1;
            }
            assert!(bound <= spectral_norm_bound(m1 - m0), "{k}");
        }
        assert!(exact_like > 1000, "{exact_like}");
        // Matrices far from rotations take the general bound, which still holds.
        let m0 = DMat3::from_cols(DVec3::new(2.0, 0.1, 0.0), DVec3::Y, DVec3::Z);
        let m1 = DMat3::IDENTITY * 0.5;
        assert!(rotation_change_bound(&m0, &m1) >= norm_from_below(m1 - m0) * (1.0 - 1e-14));
    }

    #[test]
    fn the_motion_clock_bounds_every_vertex_move() {
        let mesh = shapes::torus_knot(&shapes::TorusKnotParams::default()).unwrap();
        let mesh = mesh.transformed(&Pose::from_translation(DVec3::new(0.3, -0.2, 0.1)));
        let tree = ObbTree::build(&mesh, &BuildOptions::default());
        let verts = mesh.vertices();
        let mut rng = rand::rngs::StdRng::seed_from_u64(22);
        let mut cache = PairCache::new();
        let mut prev: Option<RelativeFrame> = None;
        for k in 0..300 {
            let small = 10f64.powf(-8.0 + 8.0 * rng.random::<f64>());
            let pose_b = Pose::new(
                DVec3::new(rng.random(), rng.random(), rng.random()) * small,
                DQuat::from_rotation_z(small * k as f64) * DQuat::from_rotation_x(0.3 * small),
            );
            let frame = RelativeFrame::new(&Pose::IDENTITY, &pose_b);
            cache.bind(&tree, &tree, &frame);
            if let Some(p) = prev {
                let moved = verts
                    .iter()
                    .map(|v| (frame.point(*v) - p.point(*v)).length())
                    .fold(0.0f64, f64::max);
                assert!(
                    cache.delta >= moved,
                    "step {k}: bound {} below {moved}",
                    cache.delta
                );
                assert!(
                    cache.delta <= 4.0 * moved + 1e-15,
                    "step {k}: bound {} far above {moved}",
                    cache.delta
                );
            }
            prev = Some(frame);
        }
        assert!(tree.vertex_radius <= tree.radius_from_origin);
        assert!(verts.iter().all(|v| v.length() <= tree.vertex_radius));
    }
}
