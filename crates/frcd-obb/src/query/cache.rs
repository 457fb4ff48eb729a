//! The coherence cache of the pair queries ([`PairCache`]): the front a traversal recorded,
//! its walk under a work budget, the bounds on how far B moved since, and the old witness's
//! neighbourhood.

use super::RelativeFrame;
use super::hits::{Hits, Restart};
use super::traverse::{Ctx, PooledStack};
use crate::isa::Isa;
use crate::nodes::TNode;
use crate::tree::ObbTree;
use crate::wide::{self, ALanes};
use frcd_geom::DMat3;

/// A traversal front: the node pairs where a traversal stopped (a cut of the traversal tree:
/// every leaf pair lies below exactly one of them), with one bound per pair. Two parallel
/// arrays rather than one of entries, so that the walk's scan for expired pairs (most of a
/// coherent front's pairs are only read) compares eight bounds at a time.
#[derive(Clone, Debug, Default)]
pub(super) struct Front {
    /// Node pairs (A, B).
    pub(super) pairs: Vec<(u32, u32)>,
    /// For a separated pair: the pair stays separated while the cache's motion clock plus the
    /// query's slack stays below this value (clock at the test + separation margin). -∞ for
    /// the others (a leaf pair whose boxes overlapped, a pair left untested after a hit):
    /// always traversed again.
    pub(super) bounds: Vec<f64>,
}

impl Front {
    pub(super) fn len(&self) -> usize {
        self.pairs.len()
    }

    pub(super) fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }

    pub(super) fn clear(&mut self) {
        self.pairs.clear();
        self.bounds.clear();
    }

    #[inline(always)]
    pub(super) fn push(&mut self, a: u32, b: u32, bound: f64) {
        self.pairs.push((a, b));
        self.bounds.push(bound);
    }

    /// The first index in `from..end` whose pair is not known separated at `limit` (the
    /// clock plus the query's slack; a NaN bound counts as expired), or `end`.
    #[inline]
    pub(super) fn next_expired(&self, from: usize, end: usize, limit: f64) -> usize {
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
    pub(super) fn count_expired(&self, end: usize, limit: f64) -> usize {
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
pub(super) fn expired(limit: f64, bound: f64) -> bool {
    !(limit < bound)
}

/// The front a traversal records into, if any, with the cache's motion clock.
pub(super) type Recording<'f> = Option<(&'f mut Front, f64)>;

/// Records a separated pair (bound: clock + `margin`) when a front is being recorded.
#[inline(always)]
pub(super) fn record_separated(front: &mut Recording<'_>, a: u32, b: u32, margin: f64) {
    if let Some((f, clock)) = front {
        f.push(a, b, *clock + margin);
    }
}

/// Records pairs to be traversed again next time (overlapping leaf pairs, pairs left
/// untested after a hit) when a front is being recorded.
#[inline(always)]
pub(super) fn record_pairs(front: &mut Recording<'_>, pairs: impl Iterator<Item = (u32, u32)>) {
    if let Some((f, _)) = front {
        for (a, b) in pairs {
            f.push(a, b, f64::NEG_INFINITY);
        }
    }
}

/// Caller-owned frame-to-frame state for [`collide_cached`](crate::collide_cached) on one pair of trees.
///
/// Holds the last witness triangle pair (tested first in [`Mode::FirstContact`](crate::Mode::FirstContact)) with the leaf
/// pair that held it (when that pair no longer touches and the bodies moved by at most a tenth
/// of the smaller one's bounding radius, the subtree pair four levels above those leaves is
/// searched before the whole trees) and the
/// traversal front of the last traversal: the node pairs where it stopped, each separated pair
/// with its separation margin. Between queries the cache bounds how far any point of B moved
/// in A's frame (`|Δt| + ‖ΔM‖₂ · r_v`, `r_v` the largest vertex distance from B's origin,
/// summed into a motion clock; a shift of more than a tenth of the smaller body's bounding
/// radius drops the front instead, unbounded); a separated front pair
/// whose margin exceeds the motion since its test is still separated and is not tested again
/// (the argument holds for the fixed separating direction, so it is exact, not a heuristic).
/// The others are tested again and traversed below where they overlap; leaf pairs whose boxes
/// overlapped get a box test before their triangle tests.
///
/// The cache never costs much: a work budget compares each front walk with the last fresh
/// traversal ([`Counters::work`](crate::Counters::work)); when the front saves less than a quarter of that work, the
/// cache drops it and traverses afresh, backing off exponentially (up to 64 queries) before trying a front again, so
/// incoherent sequences (random poses, teleports) run at the uncached speed. The answers are
/// the same as without a cache; only the work differs. A cache used with other trees resets
/// itself.
#[derive(Clone, Debug, Default)]
pub struct PairCache {
    pub(super) key: (u64, u64),
    pub(super) witness: Option<(u32, u32)>,
    /// The leaves (node ids of A and of B) that held `witness`.
    pub(super) witness_leaves: Option<(u32, u32)>,
    pub(super) front: Front,
    pub(super) scratch: Front,
    /// Frame of the previous query.
    pub(super) prev: Option<RelativeFrame>,
    /// Sum of the motion bounds since the cache was bound.
    pub(super) clock: f64,
    /// Work of the last fresh traversal.
    pub(super) fresh_work: u64,
    /// Queries left to traverse afresh before the front is tried again.
    pub(super) skip: u32,
    /// Length of the next back-off.
    pub(super) backoff: u32,
    /// Motion bound of the last query (how far any point of B moved in A's frame).
    pub(super) delta: f64,
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

    /// Binds the cache to trees `a` and `b`: one used with other trees resets itself.
    pub(super) fn bind_trees(&mut self, a: &ObbTree, b: &ObbTree) {
        let key = (a.uid, b.uid);
        if key != self.key {
            self.clear();
            self.key = key;
        }
    }

    /// Binds the cache to the query's trees and frame: bounds how far B moved since the last
    /// bound frame (`delta`, added to the clock), or drops the front after a shift past
    /// coherence.
    pub(super) fn bind(&mut self, a: &ObbTree, b: &ObbTree, frame: &RelativeFrame) {
        self.bind_trees(a, b);
        if let Some(p) = self.prev {
            let shift = (frame.t - p.t).length() * (1.0 + 1e-15);
            if shift > coherence_limit(a, b) {
                // Incoherent whatever the turn: the front goes (so the clock need not count
                // this motion) and the turn's bound is not computed: on random poses (the CAD
                // pairs) it was most of a cached query's bookkeeping over a plain query's
                // (`docs/performance/cpu-core.md`, seventeenth sitting).
                self.delta = f64::INFINITY;
                self.front.clear();
            } else {
                // A bound on |frame(v) - prev(v)| for every vertex v of B (hence every point
                // of B's triangles, convex combinations of them), rounded up.
                let delta = shift + rotation_change_bound(&p.m, &frame.m) * b.vertex_radius;
                self.delta = delta;
                self.clock += delta * (1.0 + 1e-9);
                if !self.clock.is_finite() {
                    self.front.clear();
                    self.clock = 0.0;
                }
            }
        }
        self.prev = Some(*frame);
    }

    /// True when B moved by at most [`coherence_limit`] since the last bound frame (in A's
    /// frame): only then can a front or the old witness's neighbourhood pay.
    pub(super) fn coherent(&self, a: &ObbTree, b: &ObbTree) -> bool {
        self.delta <= coherence_limit(a, b)
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
pub(super) fn scaled_spectral_bound(d: DMat3) -> f64 {
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

/// The front walk or a fresh traversal of a cached query ([`collide_cached`](crate::collide_cached), after its cheap
/// rejections), under the cache's work budget and back-off: fills `hits`, records the next
/// front where the next query will try it.
pub(super) fn walk_or_traverse(
    ctx: &mut Ctx<'_>,
    cache: &mut PairCache,
    coherent: bool,
    was_touching: bool,
    hits: &mut impl Restart,
) {
    let mut use_front = coherent && !cache.front.is_empty() && cache.skip == 0;
    if use_front {
        let walked = cache.front.len();
        let before = ctx.counters.work();
        // The walk may spend at most 40 % of a fresh traversal: a stale front is abandoned
        // early.
        let budget = 2 * cache.fresh_work / 5;
        let (done, charged) = walk_front(
            ctx,
            &mut cache.front,
            &mut cache.scratch,
            cache.clock,
            budget,
            hits,
        );
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
            hits.clear();
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
        ctx.descend(
            0,
            0,
            &mut stack,
            record.then_some((&mut front, cache.clock)),
            hits,
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

/// The motion, as a fraction of the smaller body's bounding radius, up to which a cached query
/// counts as coherent ([`PairCache::coherent`]): after larger motion (random poses, teleports)
/// every margin has expired, so the cache neither walks nor records a front.
pub(super) const COHERENT_MOTION: f64 = 0.1;

/// The largest motion of B in A's frame that counts as coherent for trees `a` and `b`:
/// [`COHERENT_MOTION`] of the smaller body's bounding radius.
pub(super) fn coherence_limit(a: &ObbTree, b: &ObbTree) -> f64 {
    COHERENT_MOTION * a.sphere.radius.min(b.sphere.radius)
}

/// How many levels above the old witness's leaves a coherent cached first-contact query
/// searches before the whole trees (the subtrees hold up to `2^4` leaves each). The dense
/// sweep's cached first contact, 2 / 3 / 4 / 5 / 7 levels against none (alternated twice):
/// touching steps' median 2.0 / 1.5-1.6 / 1.3-1.4 / 1.4-1.5 / 1.9 µs against 2.1-2.2, the
/// sequence 0.36 / 0.34-0.35 / 0.32-0.33 / 0.33 / 0.37 ms against 0.38-0.39; near-contact
/// knots 16.7 → 16.1-16.3 ms at 4; the random-pose CAD pairs (not coherent: no search)
/// unchanged.
pub(super) const NEIGHBOURHOOD_LEVELS: usize = 4;

/// The node `levels` (at most 7) levels above node `leaf` on its path from the root (the root
/// when the path is shorter, or when `leaf` is no node of `nodes`). In the depth-first layout the
/// left child of `n` is `n + 1` and the right one `right(n)`, so each subtree is one range of
/// ids and the path follows from comparisons.
pub(super) fn ancestor(nodes: &[TNode], leaf: u32, levels: usize) -> u32 {
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

/// Work charged on top of a front walk's counters per four-lane re-test of expired entries
/// (and, on the f64 traversal, per descent, each of which re-tests one entry): the walk's
/// gathers and scattered loads cost more per test than a fresh wide traversal's steps, so its
/// counters alone undercount its time next to a fresh traversal. Three: set when each expired
/// entry started its own descent (with two, fronts on the near-contact knots saved about 4 %
/// of the work and cost 10 % more time; with four, the touching all-pairs front of
/// `coherent_front_does_less_work` at leaf 1, which saves 3× the work, was dropped), and
/// measured again with batched re-tests (charging descents from overlapping entries as well
/// changed the near-contact knots by under 2 %).
pub(super) const WALK_STEP_WORK: u64 = 3;

/// Walks the front (see [`collide_cached`](crate::collide_cached)) in place: returns whether it finished within
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
pub(super) fn walk_front(
    ctx: &mut Ctx<'_>,
    front: &mut Front,
    scratch: &mut Front,
    clock: f64,
    budget: u64,
    hit: &mut impl Hits,
) -> (bool, u64) {
    #[cfg(target_arch = "x86_64")]
    match ctx.isa {
        // SAFETY: `isa` names only a build whose features the running CPU reports
        // (`Ctx::new`, `isa::best`).
        #[allow(unsafe_code)]
        Isa::Avx512 => {
            return unsafe { walk_front_avx512(ctx, front, scratch, clock, budget, hit) };
        }
        #[allow(unsafe_code)]
        Isa::Avx2 => return unsafe { walk_front_avx2(ctx, front, scratch, clock, budget, hit) },
        Isa::Baseline => {}
    }
    walk_front_body(ctx, front, scratch, clock, budget, hit)
}

/// [`walk_front`] compiled with AVX2 (`isa.rs`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(super) fn walk_front_avx2(
    ctx: &mut Ctx<'_>,
    front: &mut Front,
    scratch: &mut Front,
    clock: f64,
    budget: u64,
    hit: &mut impl Hits,
) -> (bool, u64) {
    walk_front_body(ctx, front, scratch, clock, budget, hit)
}

/// [`walk_front`] compiled with AVX-512 F and VL (`isa.rs`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512vl")]
pub(super) fn walk_front_avx512(
    ctx: &mut Ctx<'_>,
    front: &mut Front,
    scratch: &mut Front,
    clock: f64,
    budget: u64,
    hit: &mut impl Hits,
) -> (bool, u64) {
    walk_front_body(ctx, front, scratch, clock, budget, hit)
}

/// The body of [`walk_front`], inlined into each of its instruction-set builds.
#[inline(always)]
pub(super) fn walk_front_body(
    ctx: &mut Ctx<'_>,
    front: &mut Front,
    scratch: &mut Front,
    clock: f64,
    budget: u64,
    hit: &mut impl Hits,
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
