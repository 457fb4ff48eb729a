//! Prepared triangles: the exact test with its float filter's error bound cached per triangle,
//! one pair at a time ([`exact_prepared`]) or one triangle against a struct-of-arrays batch of
//! up to four ([`TriangleBatch`], [`intersects_batch`]).
//!
//! # The cached bound (why the answer stays exact)
//!
//! The decisions are those of [`crate::exact`]: signs of `orient3d` of input vertices, each
//! trusted only when its f64 value exceeds an error bound, recomputed exactly otherwise. What
//! changes is how the plane-side values and their bound are formed. A [`PreparedTriangle`]
//! `(p, q, r)` stores
//!
//! - `n = fl((q−p) × (r−p))`, its normal as [`crate::exact`] rounds it, and `d = fl(n·p)`;
//! - `M = max |coordinate|` over its nine coordinates;
//! - `C = max(fl(10ε·fl(P̂_x + P̂_y + P̂_z)), 2⁻¹⁰⁰⁰)` with
//!   `P̂_i = fl(|f1_j|·|f2_k| + |f1_k|·|f2_j|)`, `f1 = fl(q−p)`, `f2 = fl(r−p)`, `(i, j, k)`
//!   cyclic, `ε = 2⁻⁵³`.
//!
//! **Plane sides.** For a vertex `x` of the other triangle the filter value is
//! `ŝ = fl(fl(n·x) − d)`, an approximation of `s = N·(x−p)` with `N` the exact normal and the
//! sign of `s` that of `orient3d(p, q, r, x)`. With exact differences, `P_i = |f1_j f2_k| +
//! |f1_k f2_j|`, `γ_k = kε/(1−kε)` and `S = M + M'` (this triangle's and the other's):
//!
//! 1. each normal component is `fl(fl(a·b) − fl(c·d))` of rounded differences, so
//!    `|n_i − N_i| ≤ γ4·P_i`;
//! 2. the two three-term dot products carry `γ3` each and the subtraction `ε`, and
//!    `|x_i − p_i|`, `|x_i| + |p_i|` are at most `S`, so
//!    `|ŝ − s| ≤ S·Σ_i (γ4·P_i + (γ3 + ε(1+γ3))·|n_i|) ≤ 4.0001ε·S·Σ_i (P_i + |n_i|)`;
//! 3. `|n_i| ≤ P̂_i(1+ε)/(1−ε)` and `P_i ≤ P̂_i/(1−ε)⁴`, so `|ŝ − s| ≤ 8.0002ε·S·Σ_i P̂_i`.
//!
//! The bound used, `fl(fl(M + M')·C)` (one add and one multiply per plane and pair), is at
//! least `10ε(1−ε)⁵·S·Σ P̂_i > 8.0002ε·S·Σ P̂_i ≥ |ŝ − s|`: a sign with `|ŝ| > bound` is the
//! exact sign. (The values differ from [`crate::exact`]'s `fl(x−p)·n`; only certified signs
//! are used, so the answers are the same.)
//!
//! **Final orientations.** The two Guigue-Devillers orientations mix vertices of both
//! triangles and are computed as in [`crate::exact`]. Every difference of two of the six
//! vertices is at most `2U` per coordinate, `U = max(M, M')`, so Shewchuk's stage-A permanent
//! is at most `48·U³` and the error below `8.0001ε·48·U³ < 400ε·U³` (computed, the bound still
//! exceeds `399.9ε·U³`). That bound is only formed when a pair gets that far.
//!
//! **Range.** Both bounds assume every coordinate magnitude is at most `2³⁰⁰`: then nothing
//! overflows, and everything underflow can add (a few `2⁻¹⁰⁷⁵` per product, times a
//! coordinate of at most `2³⁰¹`) stays below `2⁻⁷⁶⁰`, which the floor `2⁻⁷⁰⁰` on every bound
//! covers. A triangle with a larger or a non-finite coordinate stores `M = C = +∞`: every bound
//! of its pairs is `+∞` (never NaN: `C ≥ 2⁻¹⁰⁰⁰ > 0` and `M` is never NaN), no value passes it,
//! and each sign comes from the exact predicates. Each certified decision is a comparison
//! `value − bound > 0` or `value > bound`, false for NaN values.
//!
//! The bound is not translation invariant (it grows with `|coordinates|`, where
//! [`crate::exact`]'s grows with the pair's extent): that only sends more pairs to the exact
//! fallback far from the origin, and costs no correctness. Test meshes in the frame of one of
//! them (as frcd-obb does) and the coordinates stay small.
use crate::exact::{certainty, exact_slow, fmax, fmin, gd_final, is_positive, separation};
use frcd_geom::predicates::EPS;
use frcd_geom::{DVec3, Triangle};

/// Largest coordinate magnitude the cached filter handles (`2³⁰⁰`).
const FILTER_MAX: f64 = f64::from_bits((1023 + 300) << 52);
/// Floor of every bound (`2⁻⁷⁰⁰`): covers underflow (module docs).
const FLOOR: f64 = f64::from_bits((1023 - 700) << 52);
/// `C = PLANE_FACTOR · Σ P̂_i`.
const PLANE_FACTOR: f64 = 10.0 * EPS;
/// Smallest `C` (`2⁻¹⁰⁰⁰`): keeps `C > 0` so that `(+∞)·C` is never NaN.
const MIN_C: f64 = f64::from_bits((1023 - 1000) << 52);
/// Final orientations: `ORIENT_FACTOR · U³`.
const ORIENT_FACTOR: f64 = 400.0 * EPS;

/// Raises a bound to [`FLOOR`]; a NaN bound stays NaN (and is then never passed).
#[inline(always)]
fn floored(b: f64) -> f64 {
    if b < FLOOR { FLOOR } else { b }
}

/// A triangle with what the exact test's float filter needs cached: its normal, per-axis
/// coordinate magnitudes and error-bound coefficients (module docs of `prepared.rs` derive the
/// bound). Build it once per triangle (at tree build for a mesh's own triangles, once per query
/// for triangles mapped into another mesh's frame) and test it against many.
///
/// ```
/// use frcd_geom::DVec3;
/// use frcd_tritri::{PreparedTriangle, Triangle, exact, exact_prepared};
/// let a = Triangle::new(DVec3::ZERO, DVec3::X, DVec3::Y);
/// let b = Triangle::new(DVec3::new(0.2, 0.2, -1.0), DVec3::new(0.2, 0.2, 1.0), DVec3::new(2.0, 2.0, 0.0));
/// let (pa, pb) = (PreparedTriangle::new(&a), PreparedTriangle::new(&b));
/// assert!(exact_prepared(&pa, &pb));
/// assert_eq!(exact_prepared(&pa, &pb), exact(&a, &b));
/// assert_eq!(pa.triangle(), a);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreparedTriangle {
    v: [DVec3; 3],
    n: DVec3,
    d: f64,
    m: f64,
    c: f64,
}

impl PreparedTriangle {
    /// Prepares a triangle (about a cross product and a dozen multiplies). Any finite input is
    /// accepted, zero-area triangles included; a triangle with a coordinate above `2³⁰⁰` in
    /// magnitude or a non-finite one is kept and always takes the exact fallback.
    #[inline]
    pub fn new(t: &Triangle) -> Self {
        Self::from_vertices(t.v)
    }

    /// [`PreparedTriangle::new`] from the three vertices.
    #[inline]
    pub fn from_vertices(v: [DVec3; 3]) -> Self {
        let [p, q, r] = v;
        let f1 = q - p;
        let f2 = r - p;
        let n = f1.cross(f2);
        let d = n.dot(p);
        let (a1, a2) = (f1.abs(), f2.abs());
        let pp =
            (a1.y * a2.z + a1.z * a2.y) + (a1.z * a2.x + a1.x * a2.z) + (a1.x * a2.y + a1.y * a2.x);
        // One `maxsd` each (glam's `max` adds NaN handling; NaN is caught below).
        let mx = |a: DVec3, b: DVec3| DVec3::new(fmax(a.x, b.x), fmax(a.y, b.y), fmax(a.z, b.z));
        let am = mx(mx(p.abs(), q.abs()), r.abs());
        let m = fmax(fmax(am.x, am.y), am.z);
        // `<=` is false for NaN and infinities; a NaN coordinate makes `d` NaN (it reaches `n`
        // through the differences, then `d`), which `is_finite` rejects.
        let in_range = (m <= FILTER_MAX) & d.is_finite();
        if in_range {
            Self {
                v,
                n,
                d,
                m,
                c: fmax(pp * PLANE_FACTOR, MIN_C),
            }
        } else {
            Self {
                v,
                n,
                d,
                m: f64::INFINITY,
                c: f64::INFINITY,
            }
        }
    }

    /// The triangle as given.
    #[inline]
    pub fn triangle(&self) -> Triangle {
        Triangle { v: self.v }
    }

    /// The three vertices as given.
    #[inline]
    pub fn vertices(&self) -> &[DVec3; 3] {
        &self.v
    }

    /// The unnormalised normal `(q − p) × (r − p)` as rounded in f64.
    #[inline]
    pub fn normal(&self) -> DVec3 {
        self.n
    }

    /// The exact test against another prepared triangle; the same as [`exact_prepared`].
    #[inline]
    pub fn intersects(&self, other: &PreparedTriangle) -> bool {
        exact_prepared(self, other)
    }
}

impl From<&Triangle> for PreparedTriangle {
    #[inline]
    fn from(t: &Triangle) -> Self {
        Self::new(t)
    }
}

impl From<Triangle> for PreparedTriangle {
    #[inline]
    fn from(t: Triangle) -> Self {
        Self::new(&t)
    }
}

/// Bound for the final orientations (any `orient3d` of the pair's six vertices).
#[inline(always)]
fn orient_bound(ma: f64, mb: f64) -> f64 {
    let u = fmax(ma, mb);
    floored(ORIENT_FACTOR * u * u * u)
}

/// The exact test on prepared triangles: the same answer as [`crate::exact`] on the triangles
/// they were made from, for every input, with the filter's bound two multiplies per pair.
///
/// Both plane tests are evaluated before the one branch that rejects (a mispredicted early
/// exit costs more than the second plane test).
///
/// See [`PreparedTriangle`] for an example.
#[inline]
pub fn exact_prepared(a: &PreparedTriangle, b: &PreparedTriangle) -> bool {
    let sab = a.m + b.m;
    let bb = floored(sab * b.c);
    let ba = floored(sab * a.c);
    // A's vertices against plane(B), B's against plane(A).
    let s = a.v.map(|x| b.n.dot(x) - b.d);
    let t = b.v.map(|x| a.n.dot(x) - a.d);
    let sep = fmax(
        separation(s[0], s[1], s[2], bb),
        separation(t[0], t[1], t[2], ba),
    );
    if sep > 0.0 {
        return false; // one triangle certainly on one side of the other's plane
    }
    let cert = fmin(
        certainty(s[0], s[1], s[2], bb),
        certainty(t[0], t[1], t[2], ba),
    );
    let bound = orient_bound(a.m, b.m);
    if !is_positive(cert) {
        return exact_slow(&a.v, &b.v, bound);
    }
    gd_final(&a.v, &b.v, s, t, bound)
}

// ---------------------------------------------------------------------------------------------
// Batches.

/// Lanes per [`TriangleBatch`].
pub const BATCH_LANES: usize = 4;
const L: usize = BATCH_LANES;
type Lanes = [f64; L];

/// Up to [`BATCH_LANES`] (4) prepared triangles in struct-of-arrays layout, for
/// [`intersects_batch`]: one triangle against all of them with the float filter evaluated over
/// the lanes in plain arrays the compiler vectorises, and the exact fallback per lane.
///
/// Meant to be built once per tree leaf (a leaf of 8 triangles is two batches; see
/// [`TriangleBatch::pack`]). Unused lanes are zero and never reported. 488 bytes.
///
/// ```
/// use frcd_geom::DVec3;
/// use frcd_tritri::{PreparedTriangle, Triangle, TriangleBatch, exact};
/// let leaf: Vec<Triangle> = (0..4)
///     .map(|i| {
///         let z = i as f64 * 0.5;
///         Triangle::new(DVec3::new(0.0, 0.0, z), DVec3::new(1.0, 0.0, z), DVec3::new(0.0, 1.0, z))
///     })
///     .collect();
/// let batch = TriangleBatch::from_triangles(&leaf).expect("1 to 4 triangles");
/// let t = Triangle::new(DVec3::new(0.2, 0.2, -0.1), DVec3::new(0.2, 0.2, 0.7), DVec3::new(0.3, 0.1, 0.3));
/// let mask = batch.intersect_mask(&PreparedTriangle::new(&t));
/// for (i, tri) in leaf.iter().enumerate() {
///     assert_eq!(mask >> i & 1 == 1, exact(&t, tri));
/// }
/// assert_eq!(mask, 0b0011); // the planes z = 0 and z = 0.5
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct TriangleBatch {
    /// `v[vertex][axis][lane]`.
    v: [[Lanes; 3]; 3],
    /// `n[axis][lane]`.
    n: [Lanes; 3],
    d: Lanes,
    m: Lanes,
    c: Lanes,
    len: usize,
}

impl Default for TriangleBatch {
    fn default() -> Self {
        Self::new()
    }
}

// Elementwise lane operations: plain loops over fixed arrays, which the compiler turns into
// packed SSE2/AVX instructions (checked in the release assembly for baseline x86-64: the
// stage is `mulpd`/`addpd`/`subpd`/`minpd`/`maxpd` on pairs of lanes).
#[inline(always)]
fn lmap(f: impl Fn(usize) -> f64) -> Lanes {
    std::array::from_fn(f)
}

impl TriangleBatch {
    /// An empty batch.
    pub const fn new() -> Self {
        Self {
            v: [[[0.0; L]; 3]; 3],
            n: [[0.0; L]; 3],
            d: [0.0; L],
            m: [0.0; L],
            c: [0.0; L],
            len: 0,
        }
    }

    /// Appends a triangle; returns its lane, or `None` (and changes nothing) when the batch
    /// already holds [`BATCH_LANES`].
    pub fn push(&mut self, t: &PreparedTriangle) -> Option<usize> {
        let k = self.len;
        if k == L {
            return None;
        }
        for j in 0..3 {
            for i in 0..3 {
                self.v[j][i][k] = t.v[j][i];
            }
        }
        for i in 0..3 {
            self.n[i][k] = t.n[i];
        }
        self.d[k] = t.d;
        self.m[k] = t.m;
        self.c[k] = t.c;
        self.len += 1;
        Some(k)
    }

    /// A batch of 1 to [`BATCH_LANES`] prepared triangles, in order; `None` for 0 or more.
    pub fn from_prepared(tris: &[PreparedTriangle]) -> Option<Self> {
        if tris.is_empty() || tris.len() > L {
            return None;
        }
        let mut b = Self::new();
        for t in tris {
            b.push(t);
        }
        Some(b)
    }

    /// A batch of 1 to [`BATCH_LANES`] triangles (prepared here), in order; `None` for 0 or more.
    pub fn from_triangles(tris: &[Triangle]) -> Option<Self> {
        if tris.is_empty() || tris.len() > L {
            return None;
        }
        let mut b = Self::new();
        for t in tris {
            b.push(&PreparedTriangle::new(t));
        }
        Some(b)
    }

    /// Any number of prepared triangles as consecutive batches: triangle `i` is lane `i % 4` of
    /// batch `i / 4`, which is the index [`intersects_batch`] reports.
    pub fn pack(tris: &[PreparedTriangle]) -> Vec<Self> {
        tris.chunks(L)
            .map(|c| Self::from_prepared(c).expect("chunks of 1 to 4"))
            .collect()
    }

    /// Number of triangles held (0 to [`BATCH_LANES`]).
    #[inline]
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when no triangle is held.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The prepared triangle in lane `k`, or `None` past [`TriangleBatch::len`].
    pub fn get(&self, k: usize) -> Option<PreparedTriangle> {
        (k < self.len).then(|| PreparedTriangle {
            v: self.vertices(k),
            n: DVec3::new(self.n[0][k], self.n[1][k], self.n[2][k]),
            d: self.d[k],
            m: self.m[k],
            c: self.c[k],
        })
    }

    #[inline(always)]
    fn vertices(&self, k: usize) -> [DVec3; 3] {
        let vtx = |j: usize| DVec3::new(self.v[j][0][k], self.v[j][1][k], self.v[j][2][k]);
        [vtx(0), vtx(1), vtx(2)]
    }

    /// The exact test of `t` against every triangle of the batch: bit `k` of the result is
    /// set iff `t` meets lane `k` (the answer of [`exact_prepared`] / [`crate::exact`]).
    #[inline]
    pub fn intersect_mask(&self, t: &PreparedTriangle) -> u32 {
        let f = self.filter(t);
        let mut hits = 0u32;
        let mut live = f.live;
        while live != 0 {
            let k = live.trailing_zeros() as usize;
            live &= live - 1;
            if self.decide(t, k, &f) {
                hits |= 1 << k;
            }
        }
        hits
    }

    /// Lane `k`, which the vectorised stage did not separate: the rest of [`exact_prepared`]
    /// for that pair (the lane's vertices against `t`'s plane, then the final orientations).
    #[inline]
    fn decide(&self, t: &PreparedTriangle, k: usize, f: &Filtered) -> bool {
        let v = self.vertices(k);
        let ba = floored((t.m + self.m[k]) * t.c);
        let tt = v.map(|x| t.n.dot(x) - t.d);
        if separation(tt[0], tt[1], tt[2], ba) > 0.0 {
            return false;
        }
        let s = [f.s[0][k], f.s[1][k], f.s[2][k]];
        let cert = fmin(
            certainty(s[0], s[1], s[2], f.bb[k]),
            certainty(tt[0], tt[1], tt[2], ba),
        );
        let bound = orient_bound(t.m, self.m[k]);
        if !is_positive(cert) {
            return exact_slow(&t.v, &v, bound);
        }
        gd_final(&t.v, &v, s, tt, bound)
    }

    /// The vectorised stage: `t`'s vertices against every lane's plane, branch-free and
    /// elementwise over the lanes (packed instructions; `t`'s coordinates broadcast). A lane
    /// is live unless `t` is certainly on one side of its plane. `t` plays A of
    /// [`exact_prepared`], each lane B, with the same values and bounds.
    #[inline]
    fn filter(&self, t: &PreparedTriangle) -> Filtered {
        let bb = lmap(|k| floored((t.m + self.m[k]) * self.c[k]));
        let s: [Lanes; 3] = std::array::from_fn(|j| {
            let x = t.v[j];
            lmap(|k| self.n[0][k] * x.x + self.n[1][k] * x.y + self.n[2][k] * x.z - self.d[k])
        });
        let sep = lmap(|k| separation(s[0][k], s[1][k], s[2][k], bb[k]));
        let mut live = 0u32;
        for (k, &x) in sep.iter().enumerate() {
            live |= (!is_positive(x) as u32) << k;
        }
        Filtered {
            live: live & ((1u32 << self.len) - 1),
            s,
            bb,
        }
    }
}

/// What the vectorised stage found: the lanes not certainly separated (`live`), `t`'s
/// plane-side values against each lane's plane, and their bounds.
struct Filtered {
    live: u32,
    s: [Lanes; 3],
    bb: Lanes,
}

/// The exact test of one triangle against the triangles of consecutive batches (for example a
/// tree leaf packed by [`TriangleBatch::pack`]): calls `out(i)` for every triangle `i`
/// (`4 × batch + lane`) that `t` meets, in increasing order, and stops as soon as `out` returns
/// `false`. Returns `false` when stopped that way, `true` when every triangle was tested.
///
/// Each answer is that of [`exact_prepared`] (and [`crate::exact`]) on the same pair: exact
/// for the f64 coordinates given. For the pairs of two meshes, map one mesh's triangles into
/// the other's frame, prepare them, and keep the other's leaves packed.
///
/// ```
/// use frcd_geom::DVec3;
/// use frcd_tritri::{PreparedTriangle, Triangle, TriangleBatch, intersects_batch};
/// // A leaf of 6 triangles (two batches), in the leaf mesh's own frame.
/// let leaf: Vec<PreparedTriangle> = (0..6)
///     .map(|i| {
///         let x = i as f64;
///         PreparedTriangle::new(&Triangle::new(
///             DVec3::new(x, 0.0, 0.0),
///             DVec3::new(x + 0.5, 0.0, 0.0),
///             DVec3::new(x, 0.5, 0.0),
///         ))
///     })
///     .collect();
/// let batches = TriangleBatch::pack(&leaf);
/// assert_eq!(batches.len(), 2);
/// // The other mesh's triangle, already mapped into this frame: crosses z = 0 along x = 4.1.
/// let t = PreparedTriangle::new(&Triangle::new(
///     DVec3::new(4.1, 0.1, -1.0),
///     DVec3::new(4.1, 0.1, 1.0),
///     DVec3::new(4.1, -3.0, 0.0),
/// ));
/// let mut hits = Vec::new();
/// let finished = intersects_batch(&t, &batches, &mut |i| {
///     hits.push(i);
///     true // keep going (return false to stop at the first contact)
/// });
/// assert!(finished);
/// assert_eq!(hits, vec![4]);
/// ```
pub fn intersects_batch(
    t: &PreparedTriangle,
    batches: &[TriangleBatch],
    out: &mut impl FnMut(usize) -> bool,
) -> bool {
    for (bi, b) in batches.iter().enumerate() {
        let f = b.filter(t);
        let mut live = f.live;
        while live != 0 {
            let k = live.trailing_zeros() as usize;
            live &= live - 1;
            if b.decide(t, k, &f) && !out(bi * L + k) {
                return false;
            }
        }
    }
    true
}
