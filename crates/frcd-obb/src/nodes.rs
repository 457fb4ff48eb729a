//! Compact traversal nodes: the f64 boxes of the build, stored as 64-byte f32 boxes that still
//! hold every point of the node's geometry (outward-rounded), plus the one link a traversal
//! needs.
//!
//! # Containment (the derivation behind [`compact_box`])
//!
//! The build gives a box `B64 = { c + A s : |s_k| ≤ h_k }` (the columns `a_k` of `A` orthonormal
//! to f64 precision) holding the node's triangles. Rounding to f32 gives `c32`, `U = A + E` with
//! `|E_ij| ≤ 2⁻²⁴ |A_ij|`, so `‖E‖₂ ≤ ‖E‖_F ≤ 2⁻²⁴ ‖A‖_F ≤ √3 · 2⁻²⁴`. A point `p = c + A s` of
//! `B64` is `p = c32 + U s'` with `s' = U⁻¹ (δc + A s)`, `δc = c − c32`, so
//! `s' − s = U⁻¹ (δc − E s)` and
//!
//! `|s'_k − s_k| ≤ ‖U⁻¹‖₂ (|δc| + ‖E‖₂ ‖s‖₂) ≤ (|δc| + √3 · 2⁻²⁴ ‖h‖₂) / (1 − √3 · 2⁻²⁴ − 2⁻⁵⁰)`.
//!
//! The f32 half extents are `h_k` plus that bound (denominator taken as `1 − 2⁻²¹`, both norms
//! taken as the larger 1-norms, which need no square root), computed in f64 with a relative
//! `2⁻⁴⁰` margin for its own rounding, then rounded up to f32. So the
//! parallelepiped `P = { c32 + U s' : |s'_k| ≤ H_k }` holds `B64`, hence the geometry.
//!
//! # The separating-axis test on f32 nodes
//!
//! `U` is not exactly orthonormal: its Gram matrix deviates from `I` by at most
//! `η ≤ 2·2⁻²⁴ + O(2⁻⁴⁸) < 2⁻²²` per entry (checked for every node at build, [`ETA`]; a node
//! whose axes fail is re-orthonormalised in f64 first). The 15-axis test (`sat.rs`) uses the
//! orthonormal-frame formulas: A's radius along its own axis `u_i` is taken as `H_i`, the
//! projections onto `b_j` and onto `u_i × b_j` are formed from `t_i = u_i·d`, `r_ij = u_i·b_j`.
//! Against the exact projections of the two parallelepipeds onto the directions those formulas
//! actually use (`u_i`; `UᵀU b_j`; `(u_{i1} × u_{i2}) × b_j`), each radius is off by at most
//! `6η (ΣH_A + ΣH_B)` (face axes `2η ΣH`, B's faces `8η ΣH_B + 4η ΣH_A`, cross axes
//! `3η ΣH_A + 6η ΣH_B`, including the near-parallel case where the cross direction vanishes and
//! the missing `H_i |n·u_i| ≤ 3η H_i` term does not). The test adds [`SIGMA`]`· (ΣH_A + ΣH_B)`
//! with `SIGMA = 2⁻¹⁷ ≥ 32η` to its slack, which covers all of them with a factor ≥ 2 to spare;
//! the f64 arithmetic of the test itself stays covered by the query slack of `sat.rs`, as with
//! f64 nodes. A separation margin is measured along a direction of length at most
//! `(1 + 3η)(1 + η)`, so it is scaled by `1 − 2⁻²⁰` before the coherence cache uses it as a
//! bound on the gap. Net effect: no box pair the exact f64 test would keep is ever culled, and
//! the boxes are larger than the f64 ones by about `4·10⁻⁶` of their size.

use frcd_geom::{DMat3, DVec3, Obb};

/// Bound on `|UᵀU − I|` (entrywise) accepted for a node's f32 axes.
pub(crate) const ETA: f64 = 1.0 / (1u64 << 22) as f64;
/// Relative slack of the SAT on f32 nodes: `SIGMA · (ΣH_A + ΣH_B)` (see the module docs).
pub(crate) const SIGMA: f64 = 1.0 / (1u64 << 17) as f64;
/// Factor applied to a separation margin before it bounds a gap (see the module docs).
pub(crate) const MARGIN_SCALE: f64 = 1.0 - 1.0 / (1u64 << 20) as f64;
/// The link of a leaf: this bit, plus the leaf's first entry in the tree's leaf order.
pub(crate) const LEAF: u32 = 1 << 31;

/// One traversal node: an f32 box in the mesh's local frame that holds every triangle below
/// it, and a link (internal node: index of the right child, the left one being the next node;
/// leaf: [`LEAF`] | first entry in the leaf order, its length kept in the tree's end bits).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct TNode {
    /// Centre.
    pub c: [f32; 3],
    /// Half extents along `u[0..3]`, outward-rounded.
    pub h: [f32; 3],
    /// The box axes (`u[k]` is axis `k`), orthonormal up to [`ETA`].
    pub u: [[f32; 3]; 3],
    /// See the type docs.
    pub link: u32,
}

const _: () = assert!(std::mem::size_of::<TNode>() == 64);

impl TNode {
    /// True for a leaf.
    #[inline(always)]
    pub fn is_leaf(&self) -> bool {
        self.link & LEAF != 0
    }
    /// Index of the right child (internal nodes).
    #[inline(always)]
    pub fn right(&self) -> u32 {
        self.link
    }
    /// First entry in the leaf order (leaves).
    #[inline(always)]
    pub fn first(&self) -> u32 {
        self.link & !LEAF
    }
    /// The centre in f64.
    #[inline(always)]
    pub fn center(&self) -> DVec3 {
        v64(self.c)
    }
    /// The half extents in f64.
    #[inline(always)]
    pub fn half(&self) -> DVec3 {
        v64(self.h)
    }
    /// The axes as the columns of an f64 matrix (exact widening).
    #[inline(always)]
    pub fn axes(&self) -> DMat3 {
        DMat3::from_cols(v64(self.u[0]), v64(self.u[1]), v64(self.u[2]))
    }
    /// `h₀ + h₁ + h₂`, the size used to choose which box to split.
    #[inline(always)]
    pub fn size(&self) -> f32 {
        self.h[0] + self.h[1] + self.h[2]
    }

    /// An f64 box with orthonormal axes (to f64 precision) holding this node's f32 box, hence
    /// the node's geometry: the f32 axes orthonormalised, the half extents the exact
    /// projection radii of the f32 parallelepiped onto them, rounded up.
    pub fn obb(&self) -> Obb {
        let u = [v64(self.u[0]), v64(self.u[1]), v64(self.u[2])];
        let q = orthonormal(u).unwrap_or(DMat3::IDENTITY);
        Obb {
            center: self.center(),
            axes: q,
            half_extents: hull_half(&q, &u, self.half()),
        }
    }
}

#[inline(always)]
fn v64(a: [f32; 3]) -> DVec3 {
    DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64)
}

/// The smallest f32 at or above `x` (`x ≥ 0`; `+∞` and NaN are kept). Without a branch: the
/// rounding goes down about half the time, a branch on it mispredicted as often (three per
/// node of the build); for a non-negative `f` below `+∞` the next f32 up is the next bit
/// pattern (`f32::MAX` goes to `+∞`).
#[inline(always)]
fn up(x: f64) -> f32 {
    let f = x as f32;
    f32::from_bits(f.to_bits() + ((f as f64) < x) as u32)
}

/// Largest `|G_ij − δ_ij|` of the Gram matrix of three axes.
pub(crate) fn gram_deviation(u: &[DVec3; 3]) -> f64 {
    let mut worst: f64 = 0.0;
    // The upper triangle: `u[j]·u[i]` rounds exactly as `u[i]·u[j]` (the same products).
    for i in 0..3 {
        for j in i..3 {
            let g = u[i].dot(u[j]) - if i == j { 1.0 } else { 0.0 };
            worst = worst.max(g.abs());
        }
    }
    // The three-term sums round by a few f64 ulp.
    worst + 1e-15
}

/// Gram-Schmidt in f64 (columns of the result), `None` for degenerate or non-finite axes.
fn orthonormal(a: [DVec3; 3]) -> Option<DMat3> {
    let q0 = a[0].try_normalize()?;
    let q1 = (a[1] - q0 * q0.dot(a[1])).try_normalize()?;
    let q2 = q0.cross(q1).try_normalize()?;
    Some(DMat3::from_cols(q0, q1, q2))
}

/// Half extents along the columns of `q` of the parallelepiped `{ Σ s_j a_j : |s_j| ≤ h_j }`
/// (its exact projection radii), rounded up.
fn hull_half(q: &DMat3, a: &[DVec3; 3], h: DVec3) -> DVec3 {
    let qs = [q.x_axis, q.y_axis, q.z_axis];
    let r = |k: usize| {
        (h.x * qs[k].dot(a[0]).abs() + h.y * qs[k].dot(a[1]).abs() + h.z * qs[k].dot(a[2]).abs())
            * (1.0 + 1e-12)
    };
    DVec3::new(r(0), r(1), r(2))
}

/// The f32 box (centre, half extents, axes) of an f64 build box, holding it (module docs).
pub(crate) fn compact_box(obb: &Obb) -> ([f32; 3], [f32; 3], [[f32; 3]; 3]) {
    let f = |v: DVec3| [v.x as f32, v.y as f32, v.z as f32];
    let mut a = [obb.axes.x_axis, obb.axes.y_axis, obb.axes.z_axis];
    let mut h = obb.half_extents.max(DVec3::ZERO);
    let mut u = a.map(f);
    if gram_deviation(&u.map(v64)) > ETA {
        // Axes not orthonormal to f32 precision: orthonormalise in f64 (the identity when
        // degenerate) and take the box that holds the original parallelepiped.
        let q = orthonormal(a).unwrap_or(DMat3::IDENTITY);
        h = hull_half(&q, &a, h);
        a = [q.x_axis, q.y_axis, q.z_axis];
        u = a.map(f);
    }
    debug_assert!(gram_deviation(&u.map(v64)) <= ETA || !h.is_finite());
    let c = f(obb.center);
    // `‖δc‖₂` and `‖h‖₂` bounded by their 1-norms (`h ≥ 0`): a bound a little looser (the
    // boxes grow by about 10⁻⁷ of their size, as before) for no square root or division on
    // the latency chain of every node of the build.
    let dc = (obb.center - v64(c)).abs().element_sum();
    const SQRT3_EPS32: f64 = 1.732_050_808 / (1u64 << 24) as f64;
    // `1 / (1 − 2⁻²¹)`, rounded (half an ulp, inside the `2⁻⁴⁰` margin of `grow`).
    const INV_DENOM: f64 = 1.0 / (1.0 - 1.0 / (1u64 << 21) as f64);
    let e = (dc + SQRT3_EPS32 * h.element_sum()) * INV_DENOM;
    let grow = |x: f64| up((x + e) * (1.0 + 1.0 / (1u64 << 40) as f64));
    (c, [grow(h.x), grow(h.y), grow(h.z)], u)
}

/// Converts the build's f64 nodes into traversal nodes and the leaf-end bits (bit `k` set when
/// leaf-order entry `k` is the last of its leaf). The build writes this layout directly
/// (`build::build_compact`); this is the reference its test compares with.
#[cfg(test)]
pub(crate) fn compact(nodes: &[crate::tree::Node], order_len: usize) -> (Vec<TNode>, Vec<u64>) {
    let mut ends = vec![0u64; order_len.div_ceil(64).max(1)];
    let out = nodes
        .iter()
        .map(|n| {
            let (c, h, u) = compact_box(&n.obb);
            let link = if n.is_leaf() {
                let last = (n.first + n.count - 1) as usize;
                ends[last / 64] |= 1 << (last % 64);
                LEAF | n.first
            } else {
                n.right
            };
            TNode { c, h, u, link }
        })
        .collect();
    (out, ends)
}

/// Number of entries of the leaf starting at leaf-order entry `first`.
#[inline(always)]
pub(crate) fn leaf_len(ends: &[u64], first: u32) -> u32 {
    let mut k = first as usize;
    loop {
        let w = ends[k / 64] >> (k % 64);
        if w != 0 {
            return (k + w.trailing_zeros() as usize + 1) as u32 - first;
        }
        k = (k | 63) + 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use frcd_geom::{DQuat, Pose};

    /// Corners of a parallelepiped given as (centre, axes columns, half extents).
    fn corners(c: DVec3, a: [DVec3; 3], h: DVec3) -> Vec<DVec3> {
        let mut out = Vec::new();
        for s in 0..8 {
            let sg = |b: usize| if s >> b & 1 == 1 { 1.0 } else { -1.0 };
            out.push(c + a[0] * (sg(0) * h.x) + a[1] * (sg(1) * h.y) + a[2] * (sg(2) * h.z));
        }
        out
    }

    /// Solves for the f32 box coordinates of `p` in f64 and checks them against the extents.
    fn inside_f32(n: &TNode, p: DVec3) -> bool {
        let s = n.axes().inverse() * (p - n.center());
        (0..3).all(|k| s[k].abs() <= n.h[k] as f64)
    }

    #[test]
    fn up_rounds_to_the_smallest_f32_at_or_above() {
        // The reference: round to nearest, then step up where that went below.
        let reference = |x: f64| {
            let f = x as f32;
            if (f as f64) < x { f.next_up() } else { f }
        };
        let max = f32::MAX as f64;
        let mut cases = vec![
            0.0,
            f64::MIN_POSITIVE,
            1e-46,
            f32::from_bits(1) as f64,
            f32::MIN_POSITIVE as f64 * 0.75,
            1.0,
            1.0 + 1e-12,
            1.0 - 1e-12,
            3.0e38,
            max,
            max * (1.0 + 1e-12),
            max * 2.0,
            f64::MAX,
            f64::INFINITY,
        ];
        let mut r = 0x9E37_79B9_7F4A_7C15u64;
        for _ in 0..20_000 {
            r ^= r << 13;
            r ^= r >> 7;
            r ^= r << 17;
            // Positive f64 of every exponent an f32 can hold or overflow to.
            cases.push(f64::from_bits((r >> 2) & 0x47ff_ffff_ffff_ffff));
        }
        for x in cases {
            let got = up(x);
            assert_eq!(got.to_bits(), reference(x).to_bits(), "{x:e}");
            assert!(got as f64 >= x, "{x:e}");
        }
        assert!(up(f64::NAN).is_nan());
    }

    #[test]
    fn compact_boxes_hold_the_f64_box_far_from_the_origin() {
        let mut worst_growth: f64 = 0.0;
        for k in 0..200 {
            let q = DQuat::from_axis_angle(
                DVec3::new(0.3 + k as f64, -1.1, 2.0 - 0.01 * k as f64).normalize(),
                0.1 * k as f64,
            );
            let pose = Pose::new(DVec3::new(3.0e3, -1.7e3 * k as f64, 512.3), q);
            let obb = Obb {
                center: pose.translation,
                axes: pose.rotation_matrix(),
                half_extents: DVec3::new(1e-3 * (k + 1) as f64, 0.5, 0.0),
            };
            let (c, h, u) = compact_box(&obb);
            let n = TNode { c, h, u, link: 0 };
            let a = [obb.axes.x_axis, obb.axes.y_axis, obb.axes.z_axis];
            for p in corners(obb.center, a, obb.half_extents) {
                assert!(inside_f32(&n, p), "box {k}: corner {p:?} outside");
            }
            // The f64 view holds the f32 box.
            let view = n.obb();
            for p in corners(n.center(), [0, 1, 2].map(|i| v64(n.u[i])), n.half()) {
                let s = view.axes.transpose() * (p - view.center);
                // The corner and its projection round by a few ulp of the coordinates.
                let tol = 8.0 * f64::EPSILON * (p.length() + view.center.length());
                for i in 0..3 {
                    assert!(s[i].abs() <= view.half_extents[i] + tol, "{k} {i}");
                }
            }
            worst_growth = worst_growth.max(n.h[1] as f64 - 0.5);
        }
        // Tight: growth of a few f32 ulp of the coordinates.
        assert!(worst_growth < 1e-3, "{worst_growth}");
    }

    #[test]
    fn non_orthonormal_axes_are_repaired_and_still_contain() {
        let a = DMat3::from_cols(
            DVec3::new(1.0, 0.01, 0.0),
            DVec3::new(0.0, 1.0, 0.02),
            DVec3::new(0.0, 0.0, 1.0),
        );
        let obb = Obb {
            center: DVec3::new(1.0, 2.0, 3.0),
            axes: a,
            half_extents: DVec3::new(1.0, 2.0, 3.0),
        };
        let (c, h, u) = compact_box(&obb);
        let n = TNode { c, h, u, link: 0 };
        assert!(gram_deviation(&u.map(v64)) <= ETA);
        for p in corners(obb.center, [a.x_axis, a.y_axis, a.z_axis], obb.half_extents) {
            assert!(inside_f32(&n, p));
        }
    }

    #[test]
    fn leaf_lengths_read_back_across_words() {
        let mut ends = vec![0u64; 3];
        // Leaves [0..1), [1..70), [70..130), [130..192).
        for last in [0usize, 69, 129, 191] {
            ends[last / 64] |= 1 << (last % 64);
        }
        assert_eq!(leaf_len(&ends, 0), 1);
        assert_eq!(leaf_len(&ends, 1), 69);
        assert_eq!(leaf_len(&ends, 70), 60);
        assert_eq!(leaf_len(&ends, 130), 62);
    }
}
