//! Pair queries between two OBB trees: boolean first contact or every touching triangle pair,
//! with the hybrid top volume, optional solid-mode containment and a caller-owned coherence
//! cache.
//!
//! The module's parts: this file holds the requests, answers and entry points
//! ([`collide`], [`collide_cached`], [`containment`]); `traverse` the traversal engine (the
//! query context, the wide f32 steps and the binary f64 descent, the leaf tests); `cache` the
//! coherence cache ([`PairCache`]: the recorded front, its walk, the motion bounds and the
//! witness neighbourhood).

mod cache;
mod front;
mod hits;
#[cfg(test)]
mod tests;
mod traverse;

pub use cache::PairCache;
use cache::{NEIGHBOURHOOD_LEVELS, ancestor, walk_or_traverse};
pub use front::PairFront;
use hits::{AllHits, FirstHit};
use traverse::{Ctx, PooledStack, ordered_steps};

use crate::sat::SLACK_REL;
use crate::solid::point_inside_tree;
use crate::tree::ObbTree;
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

/// Solid-mode containment with everything in A's frame (B's points and triangles mapped by
/// `frame`), for when no surface pair touches. `seed` picks the ray directions.
pub(crate) fn contained(
    a: &ObbTree,
    b: &ObbTree,
    frame: &RelativeFrame,
    seed: u64,
) -> Option<Containment> {
    // The surfaces do not touch, so each component of one mesh lies wholly inside the other's
    // solid or wholly outside: one of its extreme vertices outside a box holding the other mesh
    // (the box the parity test itself starts with) settles it without a ray.
    if a.closed {
        for (&p, ext) in b.component_points.iter().zip(&b.component_extremes) {
            if ext.iter().any(|&v| !a.aabb.contains_point(frame.point(v))) {
                continue;
            }
            let p = frame.point(p);
            if point_inside_tree(p, a, None, seed) == Some(true) {
                return Some(Containment::BInsideA);
            }
        }
    }
    if b.closed {
        let slack = query_slack(a, b, frame);
        // B's box in A's frame, as the parity test bounds it (none where it overflows).
        let bounds = frame.aabb(&b.aabb, slack);
        let finite = bounds.min.is_finite() && bounds.max.is_finite();
        for (&p, ext) in a.component_points.iter().zip(&a.component_extremes) {
            if finite && ext.iter().any(|&v| !bounds.contains_point(v)) {
                continue;
            }
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
/// over the key bytes that differ between pairs (`radix.rs`, passes of 256 buckets): on the
/// dense sweep's all pairs (about 590 pairs) it saved 36 thousand of the query's 2.6 million
/// instructions against the comparison sort, which short lists keep.
fn sort_pairs(pairs: &mut [(u32, u32)]) {
    let key = |&(a, b): &(u32, u32)| (u64::from(a) << 32) | u64::from(b);
    if pairs.len() < RADIX_MIN_PAIRS {
        pairs.sort_unstable_by_key(key);
        return;
    }
    let mut keys: Vec<u64> = pairs.iter().map(key).collect();
    crate::radix::sort_by_u64_key(&mut keys, &mut Vec::new(), &mut [0; 256], |&k| k);
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
            ctx.descend(0, 0, &mut stack, None, &mut FirstHit(&mut w));
            c.witness = w;
        }
        Mode::AllPairs => {
            ctx.descend(0, 0, &mut stack, None, &mut AllHits(&mut c.pairs));
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
    cache.bind_trees(a, b);
    let mut c = Collision::default();
    // Cheap rejections first: the top volume, then (first contact) the old witness pair and
    // its neighbourhood.
    if ctx.top_rejects(request.top_volume) {
        // The motion is not bounded for a rejected query: the next one bounds it from the
        // last frame that was (a front's margins hold against the pose at their test,
        // whatever path led to the current one).
        cache.witness = None;
        cache.witness_leaves = None;
        c.counters = ctx.counters;
        return c;
    }
    cache.bind(a, b, &ctx.frame);
    let first = request.mode == Mode::FirstContact;
    if first {
        ctx.ordered_steps = ordered_steps();
    }
    // First contact keeps a witness exactly when the last query touched. Touching steps are
    // the witness's job: a front recorded there holds the whole cut below the first hit and
    // costs more to record and walk than a fresh wide traversal that stops at the first hit.
    let was_touching = first && cache.witness.is_some();
    if first
        && let Some((x, y)) = cache.witness
        && ctx.tri_pair(x, y)
    {
        c.witness = Some((x, y));
        return finish(&ctx, request, c);
    }
    let mut found = None;
    // A front only pays when the bodies moved by a small part of their size since the last
    // query: after larger motion (random poses, teleports) every margin has expired, so the
    // cache neither walks nor records a front.
    let coherent = cache.coherent(a, b);
    let mut searched_all = false;
    if first
        && coherent
        && let Some((la, lb)) = cache.witness_leaves
    {
        // Where the bodies touched a moment ago they most likely touch now: the subtrees a
        // few levels above the old witness's leaves first, the whole trees only if they
        // hold no touching pair (their pairs are then tested again: a capped loss). In
        // trees shallower than that the neighbourhood is the whole trees.
        let na = ancestor(&a.nodes, la, NEIGHBOURHOOD_LEVELS);
        let nb = ancestor(&b.nodes, lb, NEIGHBOURHOOD_LEVELS);
        let mut stack = PooledStack::take();
        ctx.descend(na, nb, &mut stack, None, &mut FirstHit(&mut found));
        searched_all = (na, nb) == (0, 0);
    }
    if found.is_none() && !searched_all {
        if first {
            walk_or_traverse(
                &mut ctx,
                cache,
                coherent,
                was_touching,
                &mut FirstHit(&mut found),
            );
        } else {
            walk_or_traverse(
                &mut ctx,
                cache,
                coherent,
                was_touching,
                &mut AllHits(&mut c.pairs),
            );
        }
    }
    if first {
        c.witness = found;
        cache.witness = found;
        cache.witness_leaves = found.map(|_| ctx.last_leaves);
    }
    finish(&ctx, request, c)
}
