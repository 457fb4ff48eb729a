//! Clearance: the distance of every body pair closer than a threshold, with per-pair state
//! between frames that proves most far pairs far without a distance query.
//!
//! # The decision
//!
//! A pair that does not interfere is within its threshold `t` when the exact distance `d*` of
//! the f64 inputs (A's vertices, B's mapped into A's frame by [`RelativeFrame`]) is `<= t`.
//! [`distance_below`] gives `d`, the smallest computed triangle-pair distance, with
//! `d* - WORST·e <= d <= d* + e` (`e` = [`error_bound`]; `WORST·e` covers the ill-conditioned
//! features of the distance module's docs, which lose at most `~sqrt(ε)·L`, with a margin of
//! about 100). So `d + e <= t` proves the pair within, `d - WORST·e > t` proves it not, and in
//! the band between [`within`] decides exactly. The search is bounded by `t + WORST·e` (plus a
//! look-ahead, below): a farther pair never opens the node pairs a full search would.
//!
//! # Temporal state ([`ClearanceCache`])
//!
//! Each query leaves a certificate: the relative frame `(M₀, t₀)` it ran in and a certified
//! lower bound `L₀ <= d*₀` (`d - WORST·e`, or the search limit less `WORST·e` when nothing came
//! below it). In a later frame `(M₁, t₁)` every vertex `v` of B moves in A's frame by at most
//! `‖M₁ - M₀‖_F·r_B + |t₁ - t₀|` (`r_B` bounds `|v|`), plus the rounding of both mappings; A's
//! vertices do not move in A's frame, and every surface point is a convex combination of its
//! triangle's vertices, so `d*₁ >= L₀ - motion`. When that exceeds `t` the pair is not within
//! and no query runs: the answer is the one a fresh query gives. The bound compares the two
//! frames directly, so it does not accumulate over the skipped frames, and teleports are safe.
//!
//! A query that runs starts from the previous answer's triangle pair ([`DistanceCache`]) when
//! that pair is still closer than the search limit (the search then prunes from its first box
//! test), and otherwise from the limit. Either way its answer is the smallest computed
//! triangle-pair distance below the limit, as without the cache (on exact ties another triangle
//! pair of the same distance may be named).
//!
//! # Bodies turning about their own axis ([`SpinProfile`], [`pair_clearance_spin`])
//!
//! The motion bound sees every vertex of a spinning wheel move (25 mm a frame on the bogie
//! demo), so it never skips a wheel's pair. A body close to a solid of revolution carries a
//! [`SpinProfile`]: the boxes of its triangles' images under the meridian map `x ↦ (ρ, z)`
//! about its axis, which is 1-Lipschitz and blind to the turning angle; when the other body's
//! meridian image stays farther than the threshold from them, the pair is proved not within,
//! at whatever angle (derivation in [`SpinProfile`]'s module).
//!
//! # Before the collision query ([`pair_clearance_apart`])
//!
//! Every evaluation also knows whether it proved the exact distance above 0 (a skip of either
//! kind, or a search whose certified lower bound is positive): then no triangle pair of the
//! f64 inputs touches, which are the exact collision test's inputs, and a caller can skip the
//! collision traversal; only solid-mode containment is left ([`Apart::contained`]).

#[path = "clearance_spin.rs"]
mod spin;

use super::BodyId;
use crate::distance::{
    Distance, DistanceCache, DistanceRequest, distance_below, distance_cached, error_bound, within,
};
use crate::query::RelativeFrame;
use crate::tree::ObbTree;
use frcd_geom::{DMat3, DVec3, Pose};
use frcd_tritri::Contact;
pub use spin::SpinProfile;

/// Factor from [`Distance::error_bound`] (well-conditioned features) to a bound that holds for
/// every feature pair: `2²⁸·64ε = 2⁻¹⁹` relative to the scene magnitude, against the
/// `~sqrt(ε) = 2⁻²⁶·⁵` the distance module's docs derive for the worst case.
const WORST: f64 = (1u64 << 28) as f64;

/// A body pair closer than its clearance threshold (or interfering), with where it is closest.
///
/// `Id` names the bodies: [`BodyId`] in a [`super::World`], the body index in `frcd-hybrid`,
/// `()` from [`pair_clearance`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clearance<Id = BodyId> {
    /// The body with the lower slot index.
    pub a: Id,
    /// The other body.
    pub b: Id,
    /// Smallest distance between the two surfaces; 0 when the bodies interfere (touching
    /// surfaces, or in solid mode one inside the other).
    pub distance: f64,
    /// Closest points in world coordinates (on A, on B). Interfering pairs: a point of the
    /// contact of `triangles` (twice); contained pairs: the closest surface points.
    pub points: [DVec3; 2],
    /// The triangle pair `(tri of a, tri of b)` the points lie on.
    pub triangles: (u32, u32),
    /// The bodies interfere (the `distance` is 0 by definition).
    pub interfering: bool,
}

impl<Id> Clearance<Id> {
    /// The same answer naming the bodies with other ids.
    pub fn with_ids<J>(self, a: J, b: J) -> Clearance<J> {
        Clearance {
            a,
            b,
            distance: self.distance,
            points: self.points,
            triangles: self.triangles,
            interfering: self.interfering,
        }
    }
}

/// Work of clearance evaluations (summed with `+=`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ClearanceWork {
    /// Pair evaluations (one per pair with a threshold whose boxes came within it).
    pub pairs: u64,
    /// Pairs proved farther than their threshold by the motion bound: no query.
    pub skipped: u64,
    /// Pairs proved farther than their threshold by the meridian bound of a body turning about
    /// its own axis ([`SpinProfile`], [`pair_clearance_spin`]): no query.
    pub spin_skipped: u64,
    /// Distance searches run.
    pub distance_queries: u64,
    /// Searches seeded with the previous answer's triangle pair.
    pub warm_starts: u64,
    /// Exact [`within`] decisions (a distance within its error band of the threshold).
    pub exact_decisions: u64,
    /// Node-pair lower bounds computed by the distance searches (a time-free measure of their
    /// work).
    pub box_tests: u64,
    /// Triangle pairs evaluated by the distance searches.
    pub tri_tests: u64,
}

impl std::ops::AddAssign for ClearanceWork {
    fn add_assign(&mut self, o: Self) {
        self.pairs += o.pairs;
        self.skipped += o.skipped;
        self.spin_skipped += o.spin_skipped;
        self.distance_queries += o.distance_queries;
        self.warm_starts += o.warm_starts;
        self.exact_decisions += o.exact_decisions;
        self.box_tests += o.box_tests;
        self.tri_tests += o.tri_tests;
    }
}

/// What a query proved about one frame of a pair.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Certificate {
    /// The trees it holds for (their build identities).
    trees: (u64, u64),
    /// B's frame in A's at that frame.
    m: DMat3,
    t: DVec3,
    /// A lower bound on the exact surface distance then.
    lower: f64,
}

/// Caller-owned state of one body pair between frames for [`pair_clearance_cached`]: a lower
/// bound on the pair's distance and the relative pose it holds for (see the module docs), the
/// previous answer's triangle pair, and the last relative pose (to size the look-ahead).
///
/// A cache used with other trees is safe: the certificate names its trees and is ignored for
/// others.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ClearanceCache {
    distance: DistanceCache,
    cert: Option<Certificate>,
    /// Relative frame of the last call and how far B moved (bound) since the call before.
    last: Option<(DMat3, DVec3)>,
    step: f64,
    /// The last search found the pair below its limit.
    near: bool,
}

impl ClearanceCache {
    /// An empty cache.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets everything.
    pub fn clear(&mut self) {
        *self = Self::default();
    }
}

/// A bound on how far any point of B's surface, mapped into A's frame, moves between frame
/// `(m0, t0)` and `f`: `‖Δm‖_F·r + |Δt|` (`‖·‖_F` bounds the spectral norm), grown by `1e-12`
/// relative for the rounding of this sum, and by the rounding of both mappings (per coordinate
/// `γ₃(|row|·|v| + |t|)`, `≤ 3·2⁻⁵²(r + |t|)` as a vector norm; 8 used).
fn motion_bound(m0: &DMat3, t0: DVec3, f: &RelativeFrame, radius: f64) -> f64 {
    let dm = f.m - *m0;
    let fro =
        (dm.x_axis.length_squared() + dm.y_axis.length_squared() + dm.z_axis.length_squared())
            .sqrt();
    let exact = fro * radius + (f.t - t0).length();
    let rounding = 8.0 * f64::EPSILON * (2.0 * radius + t0.length() + f.t.length());
    exact * (1.0 + 1e-12) + rounding
}

/// The clearance of one body pair for a `threshold`, given what the collision query found:
/// `None` when the pair does not interfere and its surfaces are farther apart than the threshold
/// (decided exactly); otherwise the distance (0 when `interfering`), closest points and triangle
/// pair. `witness` is a touching triangle pair of an interfering pair, when there is one (its
/// contact point is reported without a distance query).
///
/// This is [`pair_clearance_cached`] with a fresh cache: the same answers, without the
/// temporal state.
pub fn pair_clearance(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    threshold: f64,
    witness: Option<(u32, u32)>,
    interfering: bool,
) -> Option<Clearance<()>> {
    let mut cache = ClearanceCache::new();
    pair_clearance_cached(
        a,
        pose_a,
        b,
        pose_b,
        threshold,
        witness,
        interfering,
        &mut cache,
    )
    .0
}

/// [`pair_clearance`] with per-pair state between frames (see the module docs): a pair whose
/// certified lower bound from an earlier query, less the motion bound of the two bodies since,
/// stays above the threshold is answered `None` without a query; a query that runs starts from
/// the previous answer's triangle pair. The answers are those of [`pair_clearance`]: the same
/// pairs, the same distances (on exact ties another triangle pair of the same distance may be
/// named). Also returns the work done.
///
/// ```
/// use frcd_obb::{BuildOptions, ClearanceCache, ObbTree, pair_clearance, pair_clearance_cached};
/// use frcd_geom::{shapes, DVec3, Pose};
/// let t = ObbTree::build(&shapes::cuboid(DVec3::splat(0.5)), &BuildOptions::default());
/// let mut cache = ClearanceCache::new();
/// for k in 0..6 {
///     // B approaches A from 30 mm to 20 mm; the threshold is 5 mm.
///     let pb = Pose::from_translation(DVec3::new(1.03 - 0.002 * k as f64, 0.0, 0.0));
///     let (c, work) = pair_clearance_cached(&t, &Pose::IDENTITY, &t, &pb, 0.005, None, false, &mut cache);
///     assert_eq!(c, pair_clearance(&t, &Pose::IDENTITY, &t, &pb, 0.005, None, false));
///     assert!(c.is_none());
///     if k > 1 {
///         // The second query looked ahead by 8 frames of the motion it saw: no query since.
///         assert_eq!((work.skipped, work.distance_queries), (1, 0));
///     }
/// }
/// ```
#[allow(clippy::too_many_arguments)]
pub fn pair_clearance_cached(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    threshold: f64,
    witness: Option<(u32, u32)>,
    interfering: bool,
    cache: &mut ClearanceCache,
) -> (Option<Clearance<()>>, ClearanceWork) {
    pair_clearance_spin(
        a,
        pose_a,
        b,
        pose_b,
        threshold,
        witness,
        interfering,
        [None, None],
        cache,
    )
}

/// [`pair_clearance_cached`] that also uses the meridian bound of A's and B's [`SpinProfile`]
/// (`spins[0]` for A, `spins[1]` for B; a profile built for another tree is ignored): a pair
/// that the motion bound cannot skip is proved farther than its threshold without a distance
/// query when its meridian images are that far apart, whatever angle the body with the
/// profile has turned to (see [`SpinProfile`]). The answers are those of [`pair_clearance`].
///
/// ```
/// use frcd_obb::{BuildOptions, ClearanceCache, ObbTree, SpinProfile, pair_clearance, pair_clearance_spin};
/// use frcd_geom::{shapes, DQuat, DVec3, Pose};
/// let opts = BuildOptions { max_leaf_triangles: 1, ..BuildOptions::default() };
/// let wheel = ObbTree::build(&shapes::cylinder(0.46, 0.07, 64, 1).unwrap(), &opts);
/// let block = ObbTree::build(&shapes::cuboid(DVec3::new(0.05, 0.05, 0.05)), &opts);
/// let spin = SpinProfile::detect(&wheel).unwrap();
/// let mut cache = ClearanceCache::new();
/// let pb = Pose::from_translation(DVec3::new(0.53, 0.0, 0.0)); // 20 mm off the wheel
/// for k in 0..10 {
///     // The wheel turns 0.054 rad a frame: its rim moves 25 mm, more than the gap.
///     let pa = Pose::new(DVec3::ZERO, DQuat::from_rotation_z(0.054 * k as f64));
///     let (c, work) = pair_clearance_spin(&wheel, &pa, &block, &pb, 0.005, None, false, [Some(&spin), None], &mut cache);
///     assert_eq!(c, pair_clearance(&wheel, &pa, &block, &pb, 0.005, None, false));
///     assert_eq!((work.spin_skipped, work.distance_queries), (1, 0));
/// }
/// ```
#[allow(clippy::too_many_arguments)]
pub fn pair_clearance_spin(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    threshold: f64,
    witness: Option<(u32, u32)>,
    interfering: bool,
    spins: [Option<&SpinProfile>; 2],
    cache: &mut ClearanceCache,
) -> (Option<Clearance<()>>, ClearanceWork) {
    let mut work = ClearanceWork {
        pairs: 1,
        ..ClearanceWork::default()
    };
    let frame = RelativeFrame::new(pose_a, pose_b);
    let radius = b.radius_from_origin * (1.0 + 1e-12);
    // How far B moved since the last call: sizes the look-ahead below.
    update_step(cache, &frame, radius);
    if interfering {
        cache.cert = None;
        cache.near = true;
        if let Some((x, y)) = witness {
            let ta = a.triangle(x);
            let tb = frame.triangle(&b.triangle(y));
            let p = match frcd_tritri::intersection_segment(&ta, &tb) {
                Some(Contact::Point(p)) => p,
                Some(Contact::Segment(p, q)) => 0.5 * (p + q),
                Some(Contact::Polygon(v)) if !v.is_empty() => v[0],
                // A non-exact method's witness: the closest points of the pair instead.
                _ => crate::oracle::closest_points_triangles(&ta, &tb).1,
            };
            let w = pose_a.transform_point(p);
            return (
                Some(Clearance {
                    a: (),
                    b: (),
                    distance: 0.0,
                    points: [w, w],
                    triangles: (x, y),
                    interfering: true,
                }),
                work,
            );
        }
        // Contained: 0, with the closest surface points however far apart they are.
        work.distance_queries += 1;
        let d = distance_cached(
            a,
            pose_a,
            b,
            pose_b,
            &DistanceRequest::default(),
            &mut cache.distance,
        );
        return (
            Some(Clearance {
                a: (),
                b: (),
                distance: 0.0,
                points: d.points,
                triangles: d.triangles,
                interfering: true,
            }),
            work,
        );
    }
    let (answer, _) = evaluate(
        a, pose_a, b, pose_b, &frame, radius, threshold, spins, cache, &mut work,
    );
    (answer, work)
}

/// What [`pair_clearance_apart`] proved: the surfaces do not touch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Apart {
    /// The answer [`pair_clearance_spin`] gives for a pair that does not interfere (`None`:
    /// farther than the threshold). Meaningless when `contained` is set: the pair then
    /// interferes, and its clearance is that of an interfering pair.
    pub clearance: Option<Clearance<()>>,
    /// Solid-mode containment (when asked for): what [`crate::collide`] reports for these
    /// poses when no surface pair touches.
    pub contained: Option<crate::Containment>,
}

/// [`pair_clearance_spin`] before the collision query, for a pair that may not interfere:
/// `Some` when this evaluation proves the two surfaces apart (a certified lower bound above 0
/// on the exact distance of the f64 inputs, which are the exact collision test's: then no
/// triangle pair touches, and of the collision query only solid-mode containment is left,
/// answered here when `solid`), with the answer [`pair_clearance_spin`] gives for a pair that
/// does not interfere. `None` when it cannot prove that: run the collision query, then
/// [`pair_clearance_spin`] with its answer; this call's work then counts no pair evaluation
/// (the second call does), its searches still count.
///
/// ```
/// use frcd_obb::{BuildOptions, ClearanceCache, ObbTree, collide, pair_clearance, pair_clearance_apart, Request};
/// use frcd_geom::{shapes, DVec3, Pose};
/// let t = ObbTree::build(&shapes::cuboid(DVec3::splat(0.5)), &BuildOptions::default());
/// let pb = Pose::from_translation(DVec3::new(1.003, 0.0, 0.0)); // 3 mm apart
/// let (apart, _) = pair_clearance_apart(&t, &Pose::IDENTITY, &t, &pb, 0.005, true, [None, None], &mut ClearanceCache::new());
/// let apart = apart.unwrap();
/// assert_eq!(apart.clearance, pair_clearance(&t, &Pose::IDENTITY, &t, &pb, 0.005, None, false));
/// assert_eq!(apart.contained, None);
/// assert!(!collide(&t, &Pose::IDENTITY, &t, &pb, &Request::default()).collide);
/// let touching = Pose::from_translation(DVec3::new(1.0, 0.0, 0.0));
/// let (apart, work) = pair_clearance_apart(&t, &Pose::IDENTITY, &t, &touching, 0.005, true, [None, None], &mut ClearanceCache::new());
/// assert_eq!((apart, work.pairs), (None, 0));
/// ```
#[allow(clippy::too_many_arguments)]
pub fn pair_clearance_apart(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    threshold: f64,
    solid: bool,
    spins: [Option<&SpinProfile>; 2],
    cache: &mut ClearanceCache,
) -> (Option<Apart>, ClearanceWork) {
    let mut work = ClearanceWork::default();
    let frame = RelativeFrame::new(pose_a, pose_b);
    let radius = b.radius_from_origin * (1.0 + 1e-12);
    // Leave `cache.step` and `cache.last` to `pair_clearance_spin` when this cannot decide: a
    // second update in one frame would shrink the look-ahead to nothing.
    let last = cache.last;
    let step = cache.step;
    update_step(cache, &frame, radius);
    let (answer, apart) = evaluate(
        a, pose_a, b, pose_b, &frame, radius, threshold, spins, cache, &mut work,
    );
    if !apart {
        cache.last = last;
        cache.step = step;
        return (None, work);
    }
    work.pairs = 1;
    let contained = if solid {
        containment_apart(a, b, &frame, spins)
    } else {
        None
    };
    (
        Some(Apart {
            clearance: answer,
            contained,
        }),
        work,
    )
}

/// `crate::query::contained` (what [`crate::collide`] reports when no surface pair touches)
/// for surfaces known not to touch, with a shortcut for a body that has a [`SpinProfile`]:
/// its solid lies in the convex region `ρ <= ρ_max`, `z_min <= z <= z_max` about its axis (the
/// region holds its surface, so its hull, so the solid). A connected surface that does not
/// touch the other body's surface lies wholly inside or wholly outside it, so when the other
/// body's surface is one connected component and one of its vertices lies outside that region,
/// its component point is outside the solid: the parity test would say so, and is skipped.
/// Likewise, as in `contained`, a component with one of its six axis-extreme vertices outside
/// the box holding the other mesh needs no ray. Otherwise the same parity tests, in the same
/// order, with the same rays.
fn containment_apart(
    a: &ObbTree,
    b: &ObbTree,
    frame: &RelativeFrame,
    spins: [Option<&SpinProfile>; 2],
) -> Option<crate::Containment> {
    let spin_a = spins[0].filter(|s| s.is_for(a));
    let spin_b = spins[1].filter(|s| s.is_for(b));
    if a.closed {
        let outside = spin_a.is_some_and(|s| {
            b.component_points.len() == 1
                && s.any_outside(
                    b,
                    |x| frame.point(x),
                    b.radius_from_origin + frame.t.length(),
                )
        });
        if !outside {
            for (&p, ext) in b.component_points.iter().zip(&b.component_extremes) {
                if ext.iter().any(|&v| !a.aabb.contains_point(frame.point(v))) {
                    continue;
                }
                let p = frame.point(p);
                if crate::solid::point_inside_tree(p, a, None, CONTAINMENT_SEED) == Some(true) {
                    return Some(crate::Containment::BInsideA);
                }
            }
        }
    }
    if b.closed {
        let slack = crate::query::query_slack(a, b, frame);
        let rough = frame.aabb(&b.aabb, slack);
        if !a.component_points.iter().any(|p| rough.contains_point(*p)) {
            return None;
        }
        let mt = frame.m.transpose();
        let outside = spin_b.is_some_and(|s| {
            a.component_points.len() == 1
                && s.any_outside(
                    a,
                    |x| mt * (x - frame.t),
                    a.radius_from_origin + frame.t.length(),
                )
        });
        if outside {
            return None;
        }
        let finite = rough.min.is_finite() && rough.max.is_finite();
        for (&p, ext) in a.component_points.iter().zip(&a.component_extremes) {
            if finite && ext.iter().any(|&v| !rough.contains_point(v)) {
                continue;
            }
            if crate::solid::point_inside_tree(p, b, Some((frame, slack)), CONTAINMENT_SEED)
                == Some(true)
            {
                return Some(crate::Containment::AInsideB);
            }
        }
    }
    None
}

/// The ray seed [`crate::collide`] uses for its containment test.
const CONTAINMENT_SEED: u64 = 0x5EED;

/// Records the frame of this call and how far B moved since the last (sizes the look-ahead).
fn update_step(cache: &mut ClearanceCache, frame: &RelativeFrame, radius: f64) {
    cache.step = match &cache.last {
        Some((m, t)) => motion_bound(m, *t, frame, radius),
        None => f64::INFINITY,
    };
    cache.last = Some((frame.m, frame.t));
}

/// The evaluation of a pair that does not interfere: the answer, and whether it proved the
/// surfaces apart (a certified lower bound above 0 on the exact distance).
#[allow(clippy::too_many_arguments)]
fn evaluate(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    frame: &RelativeFrame,
    radius: f64,
    threshold: f64,
    spins: [Option<&SpinProfile>; 2],
    cache: &mut ClearanceCache,
    work: &mut ClearanceWork,
) -> (Option<Clearance<()>>, bool) {
    let frame = *frame;
    if threshold.is_nan() || threshold < 0.0 {
        return (None, false);
    }
    let trees = (a.uid, b.uid);
    if let Some(c) = cache.cert.filter(|c| c.trees == trees) {
        let motion = motion_bound(&c.m, c.t, &frame, radius);
        if c.lower > (threshold + motion) * (1.0 + 1e-15) {
            // `d* >= lower - motion > threshold >= 0`.
            work.skipped += 1;
            return (None, true);
        }
    }
    // The meridian bound: every point pair farther than the threshold at any angle the
    // profiled body has turned to about its axis.
    for (k, s) in spins.iter().enumerate() {
        let Some(s) = s.filter(|s| s.is_for(if k == 0 { a } else { b })) else {
            continue;
        };
        if spin::pair_proved_far(s, k == 0, a, b, &frame, threshold).0 {
            // Every point pair farther than `threshold >= 0`.
            work.spin_skipped += 1;
            return (None, true);
        }
    }
    let err = error_bound(a, pose_a, b, pose_b);
    let worst = WORST * err;
    let band_top = threshold + worst;
    // Look ahead: search a little past the band so that the certificate left behind covers a
    // few frames of the motion seen in the last one (0 when the motion is large against the
    // threshold: such a pair cannot be skipped for long, and the search would only grow).
    let reach = if cache.step <= threshold / 2.0 {
        (8.0 * cache.step).max(1e-9 * (threshold + worst))
    } else {
        0.0
    };
    let limit = band_top + reach;
    work.distance_queries += 1;
    let found = search(a, pose_a, b, pose_b, &frame, limit, cache, work);
    let nan = found.is_some_and(|d| d.distance.is_nan());
    let Some(d) = found.filter(|d| !d.distance.is_nan()) else {
        // Every computed distance is at least `limit`: the exact one at least `limit - worst`.
        cache.cert = Some(Certificate {
            trees,
            m: frame.m,
            t: frame.t,
            lower: lower_bound(limit, worst),
        });
        return (None, !nan && lower_bound(limit, worst) > 0.0);
    };
    let apart = lower_bound(d.distance, worst) > 0.0;
    cache.cert = Some(Certificate {
        trees,
        m: frame.m,
        t: frame.t,
        lower: lower_bound(d.distance, worst),
    });
    if d.distance >= band_top {
        return (None, apart);
    }
    let inside = d.distance + d.error_bound <= threshold
        || (d.distance - worst <= threshold && {
            work.exact_decisions += 1;
            within(a, pose_a, b, pose_b, threshold)
        });
    let answer = inside.then_some(Clearance {
        a: (),
        b: (),
        distance: d.distance,
        points: d.points,
        triangles: d.triangles,
        interfering: false,
    });
    (answer, apart)
}

/// `x - worst`, rounded down.
fn lower_bound(x: f64, worst: f64) -> f64 {
    let l = x - worst;
    l - l.abs() * 1e-15
}

/// The smallest computed triangle-pair distance below `limit` (`None`: none below it).
///
/// [`DistanceCache`] is filled only by [`distance_cached`], whose search is unbounded. So: with
/// a cached pair closer than `limit`, the seeded search (it starts below `limit`, so it opens no
/// more node pairs than the bounded one, and finds the same smallest distance); without one,
/// but when the last search found the pair below its limit, the unbounded search (best-first:
/// it expands the same node pairs as the bounded one when the answer is below `limit`), which
/// stores its pair for the next frame; otherwise the bounded [`distance_below`].
#[allow(clippy::too_many_arguments)]
fn search(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    frame: &RelativeFrame,
    limit: f64,
    cache: &mut ClearanceCache,
    work: &mut ClearanceWork,
) -> Option<Distance> {
    let r = DistanceRequest::default();
    let seeded = cache.distance.pair().is_some_and(|(x, y)| {
        (x as usize) < a.triangles().len()
            && (y as usize) < b.triangles().len()
            && crate::oracle::closest_points_triangles(
                &a.triangle(x),
                &frame.triangle(&b.triangle(y)),
            )
            .0 < limit
    });
    let d = if seeded || cache.near {
        work.warm_starts += seeded as u64;
        Some(distance_cached(
            a,
            pose_a,
            b,
            pose_b,
            &r,
            &mut cache.distance,
        ))
        .filter(|d| d.distance < limit)
    } else {
        distance_below(a, pose_a, b, pose_b, &r, limit)
    };
    cache.near = d.is_some();
    if let Some(d) = &d {
        work.box_tests += d.counters.box_tests;
        work.tri_tests += d.counters.tri_tests;
    }
    d
}
