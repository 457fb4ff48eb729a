#![doc = include_str!("../README.md")]
#![forbid(unsafe_code)]
//! ## API overview
//!
//! | function | method | arithmetic |
//! |---|---|---|
//! | [`exact`] | Guigue-Devillers structure, one float filter per pair, exact fallback | exact for every finite f64 input |
//! | [`zou`] | Zou et al. 2008, reconstructed (seed-algorithms §1) | f64 |
//! | [`moller`] | Möller 1997, division-free interval overlap | f64, absolute ε = 1e-6 |
//! | [`guigue_devillers`] | Guigue & Devillers 2003, orientation predicates | f64 |
//! | [`shen`] | Shen, Heng & Tang 2003, signed distances | f64, absolute ε = 1e-7 |
//! | [`tropp`] | Tropp, Tal & Shimshoni 2006, shared determinants | f64 |
//!
//! For many tests against the same triangles, [`PreparedTriangle`] caches what the exact
//! filter's error bound needs (normal, per-axis magnitudes), so [`exact_prepared`] pays a few
//! multiplies per pair for it; [`TriangleBatch`] and [`intersects_batch`] test one triangle
//! against the 4-8 triangles of a tree leaf with the filter vectorised over the leaf. Both give
//! exactly the answers of [`exact`].
//!
//! [`intersection_segment`] reports the contact itself (point, segment, or the overlap polygon
//! of coplanar triangles).
//!
//! ```
//! use frcd_tritri::{intersects, Method, Triangle};
//! use frcd_geom::DVec3;
//! let a = Triangle::new(DVec3::ZERO, DVec3::X, DVec3::Y);
//! // Touches a's edge x + y = 1 at one point: closed sets, so it counts.
//! let b = Triangle::new(DVec3::new(0.5, 0.5, -1.0), DVec3::new(0.5, 0.5, 1.0), DVec3::new(2.0, 2.0, 0.0));
//! assert!(intersects(Method::Exact, &a, &b));
//! ```
#![warn(missing_docs)]

mod contact;
mod exact;
mod float;
mod prepared;

pub use contact::{Contact, intersection_segment};
pub use float::{MOLLER_EPSILON, SHEN_EPSILON};
use frcd_geom::DVec3;
pub use frcd_geom::Triangle;
pub use prepared::{
    BATCH_LANES, PreparedTriangle, TriangleBatch, exact_prepared, intersects_batch,
};

/// Which triangle-triangle test to run.
///
/// Non-exhaustive: more methods may come; match with a wildcard arm (or use [`Method::ALL`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
#[non_exhaustive]
pub enum Method {
    /// Zou et al. 2008 (reconstructed, see [`zou`]).
    Zou,
    /// Möller 1997, division-free interval overlap ([`moller`]).
    Moller,
    /// Guigue & Devillers 2003, orientation predicates in floating point ([`guigue_devillers`]).
    GuigueDevillers,
    /// Shen, Heng & Tang 2003, signed distances ([`shen`]).
    Shen,
    /// Tropp, Tal & Shimshoni 2006, shared determinants ([`tropp`]).
    Tropp,
    /// Filtered exact predicates: the right answer for every finite f64 input ([`exact`]).
    #[default]
    Exact,
}

impl Method {
    /// Every method, in a fixed order.
    pub const ALL: [Method; 6] = [
        Method::Zou,
        Method::Moller,
        Method::GuigueDevillers,
        Method::Shen,
        Method::Tropp,
        Method::Exact,
    ];

    /// A short lowercase name (`"zou"`, `"moller"`, `"guigue_devillers"`, `"shen"`, `"tropp"`, `"exact"`).
    pub fn name(self) -> &'static str {
        match self {
            Method::Zou => "zou",
            Method::Moller => "moller",
            Method::GuigueDevillers => "guigue_devillers",
            Method::Shen => "shen",
            Method::Tropp => "tropp",
            Method::Exact => "exact",
        }
    }

    /// True for the exact method.
    pub fn is_exact(self) -> bool {
        self == Method::Exact
    }
}

/// Runs the chosen test on two triangles.
#[inline]
pub fn intersects(method: Method, a: &Triangle, b: &Triangle) -> bool {
    match method {
        Method::Zou => zou(a, b),
        Method::Moller => moller(a, b),
        Method::GuigueDevillers => guigue_devillers(a, b),
        Method::Shen => shen(a, b),
        Method::Tropp => tropp(a, b),
        Method::Exact => exact(a, b),
    }
}

/// The exact test: correct for every pair of triangles with finite f64 coordinates.
///
/// Covers coplanar overlap / touching / disjoint pairs, vertex on face or edge, edge-edge
/// crossings, shared vertices and edges, one-ulp near misses, needles, tiny and subnormal
/// coordinates, large offsets, and zero-area triangles (treated as the segment or point their
/// vertices span).
///
/// Structure (Guigue & Devillers): signs of the vertices of each triangle against the other's
/// plane, a permutation that isolates the lone vertex of each, then two orientation tests of
/// four input vertices. Every sign is an `orient3d` of input vertices computed in f64 and
/// trusted when it exceeds one error bound computed once per pair from the pair's bounding box
/// (`48ε·Δ³`); a sign inside the bound is recomputed exactly
/// ([`frcd_geom::predicates::orient3d_exact`]). Coplanar pairs and zero-area triangles are
/// decided by exact 2D/3D primitives after classifying each triangle exactly as a triangle,
/// segment or point. Non-finite input gives an unspecified answer (meshes reject it at load).
#[inline]
pub fn exact(a: &Triangle, b: &Triangle) -> bool {
    exact::exact(&a.v, &b.v)
}

/// Zou et al. 2008, "a fast triangle-triangle intersection test", as reconstructed in
/// seed-algorithms.md §1 (the paper is not available; the structure below is INFERRED from the
/// abstract's named ingredients).
///
/// 1. plane of B: `s0 = nB·(a0−b0)`, `s1 = s0 + nB·e1`, `s2 = s0 + nB·e2` (linear dependence of
///    A's edges, `e3` never formed); reject if all strictly one side;
/// 2. plane of A: the same with `t_j`, reusing `e1, e2` for `nA`;
/// 3. drop the largest component `k` of `nB`; the affine coordinates `(α, β)` of any point in
///    B's frame are 2×2 determinants over `nB_k` (linearity: computed for `a0` and the two
///    edges once); the two points where A's edges cross plane(B) are homogeneous combinations
///    `(s_l α_m − s_m α_l, s_l β_m − s_m β_l, nB_k (s_l − s_m))`, never built in 3D;
/// 4. the segment between them against the canonical triangle `α, β ≥ 0, α + β ≤ 1` with a
///    four-axis separating test (three half-planes, then one 2D cross product for the corners).
///
/// No divisions. Degenerate input: one or two `s_i = 0` give the touching vertex / in-plane edge
/// as segment endpoints; all `s_i = 0` (coplanar) goes to a float 2D edge/containment test
/// projected along A's largest normal component. A zero-area B makes every `s_i` zero and falls
/// into that coplanar branch; a zero-area A projects to a degenerate 2D shape. Both answers are
/// then unreliable (zero-area triangles are meant to be rejected at mesh load).
#[inline]
pub fn zou(a: &Triangle, b: &Triangle) -> bool {
    float::zou(&a.v, &b.v)
}

/// Möller 1997, "A Fast Triangle-Triangle Intersection Test" (JGT 2(2)), division-free version
/// (`NoDivTriTriIsect` of opttritri.c): plane-side distances of each triangle against the
/// other's plane, then both triangles' intervals on the line `L = nA × nB` projected on its
/// largest axis, scaled to a common denominator and compared.
///
/// As in the reference code, plane distances with `|d| <` [`MOLLER_EPSILON`] (1e-6, absolute, in
/// units of length³) are snapped to zero: scale dependent. Tiny triangles look coplanar (the
/// float 2D coplanar test then decides) and large ones never snap. Zero-area triangles go to the
/// coplanar branch with an unreliable answer.
#[inline]
pub fn moller(a: &Triangle, b: &Triangle) -> bool {
    float::moller(&a.v, &b.v)
}

/// Guigue & Devillers 2003, "Fast and Robust Triangle-Triangle Overlap Test Using Orientation
/// Predicates" (JGT 8(1)), with every orientation evaluated in plain f64 (one normal per
/// triangle reused for its three plane-side signs, as in the authors' code).
///
/// Degenerate input: exactly coplanar pairs (all three signs exactly 0) use the float 2D test;
/// near-coplanar pairs get whatever signs rounding produces. A zero-area triangle has a zero
/// normal, so the pair is treated as coplanar: unreliable.
#[inline]
pub fn guigue_devillers(a: &Triangle, b: &Triangle) -> bool {
    float::guigue_devillers(&a.v, &b.v)
}

/// Shen, Heng & Tang 2003, "A Fast Triangle-Triangle Overlap Test Using Signed Distances"
/// (JGT 8(1)): signed vertex-plane distances snapped to zero below [`SHEN_EPSILON`] (1e-7,
/// absolute, as in the paper), the lone vertex of each triangle isolated by permutation, then two
/// signed distances between the lines of the edges leaving the lone vertices,
/// `(p2 − p1)·((q1 − p1) × (q2 − p2))`. Reconstructed from the paper's description.
///
/// Degenerate input: snapped-to-coplanar and zero-area pairs use the float 2D test: unreliable
/// for zero-area triangles and scale dependent (tiny triangles look coplanar).
#[inline]
pub fn shen(a: &Triangle, b: &Triangle) -> bool {
    float::shen(&a.v, &b.v)
}

/// Tropp, Tal & Shimshoni 2006, "A Fast Triangle to Triangle Intersection Test for Collision
/// Detection": only B's plane test, then Cramer's rule on `α1 f1 + α2 f2 − β e = a_l − b0` for
/// the two edges of A leaving its lone vertex, sharing the cofactors `(a_l−b0)×f2` and
/// `f1×(a_l−b0)` (the determinant `det[f1, f2, −e]` is the difference of two plane distances),
/// then the resulting segment in B's affine frame against the canonical triangle (the same
/// division-free 2D test as [`zou`]). Reconstructed: the paper's code is not public.
///
/// Degenerate input: all plane distances exactly zero (coplanar, or zero-area B) use the float
/// 2D test along B's normal: unreliable for zero-area triangles.
#[inline]
pub fn tropp(a: &Triangle, b: &Triangle) -> bool {
    float::tropp(&a.v, &b.v)
}

/// The Guigue-Devillers permutation: given the plane-side signs `d1` (A against plane B) and
/// `d2` (B against plane A), none all-strictly-one-side, rotate A so its first vertex is alone on
/// its side, flip B's orientation to match, do the same for B, and run `check` on the permuted
/// vertices (the two final orientation tests). `coplanar` runs when a triangle lies in the other's
/// plane.
#[inline(always)]
pub(crate) fn gd_dispatch<F, C>(
    a: [DVec3; 3],
    b: [DVec3; 3],
    d1: [f64; 3],
    d2: [f64; 3],
    check: F,
    coplanar: C,
) -> bool
where
    F: Fn(DVec3, DVec3, DVec3, DVec3, DVec3, DVec3) -> bool,
    C: FnOnce() -> bool,
{
    let [p1, q1, r1] = a;
    let [p2, q2, r2] = b;
    let [dp1, dq1, dr1] = d1;
    let [dp2, dq2, dr2] = d2;
    let c = &check;
    let r = if dp1 > 0.0 {
        if dq1 > 0.0 {
            tri3(r1, p1, q1, p2, r2, q2, dp2, dr2, dq2, c)
        } else if dr1 > 0.0 {
            tri3(q1, r1, p1, p2, r2, q2, dp2, dr2, dq2, c)
        } else {
            tri3(p1, q1, r1, p2, q2, r2, dp2, dq2, dr2, c)
        }
    } else if dp1 < 0.0 {
        if dq1 < 0.0 {
            tri3(r1, p1, q1, p2, q2, r2, dp2, dq2, dr2, c)
        } else if dr1 < 0.0 {
            tri3(q1, r1, p1, p2, q2, r2, dp2, dq2, dr2, c)
        } else {
            tri3(p1, q1, r1, p2, r2, q2, dp2, dr2, dq2, c)
        }
    } else if dq1 < 0.0 {
        if dr1 >= 0.0 {
            tri3(q1, r1, p1, p2, r2, q2, dp2, dr2, dq2, c)
        } else {
            tri3(p1, q1, r1, p2, q2, r2, dp2, dq2, dr2, c)
        }
    } else if dq1 > 0.0 {
        if dr1 > 0.0 {
            tri3(p1, q1, r1, p2, r2, q2, dp2, dr2, dq2, c)
        } else {
            tri3(q1, r1, p1, p2, q2, r2, dp2, dq2, dr2, c)
        }
    } else if dr1 > 0.0 {
        tri3(r1, p1, q1, p2, q2, r2, dp2, dq2, dr2, c)
    } else if dr1 < 0.0 {
        tri3(r1, p1, q1, p2, r2, q2, dp2, dr2, dq2, c)
    } else {
        None
    };
    match r {
        Some(v) => v,
        None => coplanar(),
    }
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn tri3<F>(
    p1: DVec3,
    q1: DVec3,
    r1: DVec3,
    p2: DVec3,
    q2: DVec3,
    r2: DVec3,
    dp2: f64,
    dq2: f64,
    dr2: f64,
    check: &F,
) -> Option<bool>
where
    F: Fn(DVec3, DVec3, DVec3, DVec3, DVec3, DVec3) -> bool,
{
    Some(if dp2 > 0.0 {
        if dq2 > 0.0 {
            check(p1, r1, q1, r2, p2, q2)
        } else if dr2 > 0.0 {
            check(p1, r1, q1, q2, r2, p2)
        } else {
            check(p1, q1, r1, p2, q2, r2)
        }
    } else if dp2 < 0.0 {
        if dq2 < 0.0 {
            check(p1, q1, r1, r2, p2, q2)
        } else if dr2 < 0.0 {
            check(p1, q1, r1, q2, r2, p2)
        } else {
            check(p1, r1, q1, p2, q2, r2)
        }
    } else if dq2 < 0.0 {
        if dr2 >= 0.0 {
            check(p1, r1, q1, q2, r2, p2)
        } else {
            check(p1, q1, r1, p2, q2, r2)
        }
    } else if dq2 > 0.0 {
        if dr2 > 0.0 {
            check(p1, r1, q1, p2, q2, r2)
        } else {
            check(p1, q1, r1, q2, r2, p2)
        }
    } else if dr2 > 0.0 {
        check(p1, q1, r1, r2, p2, q2)
    } else if dr2 < 0.0 {
        check(p1, r1, q1, r2, p2, q2)
    } else {
        return None;
    })
}
