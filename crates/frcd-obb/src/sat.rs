//! The 15-axis separating-axis test between two OBBs, in the frame of the first, made
//! conservative: rounding can only keep a pair of boxes, never separate a touching one.
//!
//! Error bound. Every quantity the test computes (the relative rotation `R`, the offset `T`,
//! the projected radii) carries rounding of a few ulp of the query's magnitude
//! `M = |A's mesh| + |B's mesh| + |relative translation|`; the boxes themselves hold their
//! triangles only up to a few ulp of slack, and the relative rotation matrix is orthonormal only
//! up to a few ulp. The rounded images of B's vertices (the ones the exact triangle test sees)
//! therefore lie within `~50 ε M` of the exactly rotated boxes. A separation is accepted only
//! when it exceeds `slack = 1e-13 · M ≈ 450 ε M`, and `|R|` gets the customary `+ EPS_R`
//! guard against near-parallel edges.
//!
//! The boxes are the tree's f32 traversal nodes ([`TNode`]), widened exactly to f64 before any
//! arithmetic; their axes are orthonormal only to f32 precision, which the test covers with a
//! further `SIGMA · (ΣH_A + ΣH_B)` of slack (derived in `nodes.rs`).
//!
//! # The f32 test (the one queries use)
//!
//! [`separation32`] runs the same 15 axes in four f32 lanes (`lanes.rs`): B's box placed with
//! the rotation rounded to f32, `R`, `t` and the radii in f32, the centre offset
//! `d = (M c_B + t) − c_A` formed in f64 and rounded once, so that every error scales with the
//! pair's own sizes, not with the coordinates. With `ε = 2⁻²⁴`, `D = ‖d‖₁`, `ΣH = ΣH_A + ΣH_B`
//! (`u_i` the f32 axes, `|u_i| ≤ 1 + η`; one rounding per operation, no fused multiply-add):
//!
//! - placed axes `P_j = M v_j`: `|P32 − P| ≤ (ε + γ₃) Σ_l |M_kl| |v_jl| ≤ 4.02 ε` per entry;
//! - `R_ij = u_i · P_j`: `|R32 − R| ≤ 4.02 ε ‖u_i‖₁ + γ₃ ‖u_i‖ ‖P_j‖ ≤ 10.2 ε`, so
//!   `|R32| + `[`EPS_R32`]` ≥ |R| + `[`EPS_R`] and every computed radius is at least
//!   `(1 − γ₆)` times the f64 test's radius, which is at most `1.03 ΣH`;
//! - `d`: `|d32_k − d_k| ≤ 1.01 ε |d_k|` (plus f64 rounding of order `2⁻⁵⁰ M`);
//!   `t_i = u_i · d`: error `≤ 4.3 ε D`; B's face projections `P_j · d`: `≤ 8.3 ε D`; the
//!   cross projections `t_{i2} R_{i1 j} − t_{i1} R_{i2 j}`: `≤ 2·4.3·1.02 ε D +
//!   2·1.01·10.2 ε D + 4.2 ε D ≤ 34 ε D`.
//!
//! The test asks for a separation larger than `2·slack + `[`C_H`]`·ΣH + `[`C_D`]`·D`
//! (`C_H = 2⁻¹⁶ ≥ 1.25·SIGMA + 7 ε`, `C_D = 2⁻¹⁸ = 64 ε`, the f64 slack rounded up to f32 with a
//! floor of `2⁻¹⁰⁰` for underflow): when it finds one, the exact real margin of that axis
//! exceeds `1.25 ×` the f64 test's slack plus sigma terms, so the f64 test (whose own rounding is
//! far below a quarter of its slack) separates the pair too. The f32 test never culls a pair the
//! f64 test keeps (tested on random and near-degenerate boxes below). It runs only when the
//! query's magnitude `M` lies in `[2⁻⁶⁰, 2¹⁰⁰]` ([`Sat32::new`]): no f32 overflow, and underflow
//! stays below the floor; outside that range queries use the f64 test. NaN anywhere keeps the
//! pair.

use crate::lanes::{F4, sel, transpose3};
use crate::nodes::{MARGIN_SCALE, SIGMA, TNode};
use frcd_geom::{DMat3, DVec3};

/// Added to every `|R_ij|` by the f32 test (covers its rounding of `R` and [`EPS_R`]).
pub(crate) const EPS_R32: f32 = 1.0 / (1u32 << 20) as f32;
/// Slack per unit of `ΣH_A + ΣH_B` in the f32 test.
pub(crate) const C_H: f32 = 1.0 / (1u32 << 16) as f32;
/// Slack per unit of `‖d‖₁` in the f32 test.
pub(crate) const C_D: f32 = 1.0 / (1u32 << 18) as f32;

/// A box test: how B's boxes are placed in A's frame and how a placed box is tested against one
/// of A's nodes. The traversal is generic over it ([`Sat32`] normally, [`Sat64`] for
/// magnitudes f32 cannot hold).
pub(crate) trait BoxTest {
    /// A box of B placed in A's frame.
    type Placed: Copy;
    /// Places node `node` of B in A's frame.
    fn place(&self, node: &TNode) -> Self::Placed;
    /// The separating axis and margin (a lower bound on the boxes' gap along a direction of
    /// length at most one), or `None` when no axis separates them by more than the error bound.
    fn separation(&self, a: &TNode, b: &Self::Placed) -> Option<(u8, f64)>;
}

/// The f64 test of a query.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sat64 {
    pub m: DMat3,
    pub t: DVec3,
    pub slack: f64,
}

impl BoxTest for Sat64 {
    type Placed = Placed;
    #[inline(always)]
    fn place(&self, node: &TNode) -> Placed {
        Placed::new(node, &self.m, self.t)
    }
    #[inline(always)]
    fn separation(&self, a: &TNode, b: &Placed) -> Option<(u8, f64)> {
        separation(a, b, self.slack)
    }
}

/// The f32 four-lane test of a query (module docs).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sat32 {
    /// `M` rounded to f32, each entry in all four lanes: `ms[k][l] = M_kl`.
    ms: [[F4; 3]; 3],
    m: DMat3,
    t: DVec3,
    /// `2 · slack`, rounded up, at least `2⁻¹⁰⁰`.
    s: f32,
}

impl Sat32 {
    /// The f32 test of a query with rotation `m`, translation `t`, f64 slack `slack` and
    /// magnitude `mag` (`|A's mesh| + |B's mesh| + |t|`), or `None` when `mag` lies outside
    /// `[2⁻⁶⁰, 2¹⁰⁰]` or anything is not finite.
    pub fn new(m: DMat3, t: DVec3, slack: f64, mag: f64) -> Option<Self> {
        let range = 2f64.powi(-60)..=2f64.powi(100);
        if !range.contains(&mag) || !slack.is_finite() || !m.is_finite() || !t.is_finite() {
            return None;
        }
        let s2 = (2.0 * slack).max(2f64.powi(-100));
        let mut s = s2 as f32;
        if (s as f64) < s2 {
            s = s.next_up();
        }
        let e = |k: usize, l: usize| F4::splat(m.col(l)[k] as f32);
        Some(Sat32 {
            ms: [0, 1, 2].map(|k| [e(k, 0), e(k, 1), e(k, 2)]),
            m,
            t,
            s,
        })
    }
}

/// A box of B placed in A's frame for the f32 test.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Placed32 {
    /// Row `k`: lanes `j` hold `P_j[k]` (`P_j` = B's axis `j` in A's frame), lane 3 zero.
    p: [F4; 3],
    /// Half extents, lane 3 zero.
    h: F4,
    /// Centre in A's frame, in f64.
    c: DVec3,
    /// `C_H · ΣH_B`.
    sh: f32,
}

impl BoxTest for Sat32 {
    type Placed = Placed32;
    #[inline(always)]
    fn place(&self, node: &TNode) -> Placed32 {
        let w = [
            F4::load(&node.w[0]),
            F4::load(&node.w[1]),
            F4::load(&node.w[2]),
        ];
        let row = |k: usize| {
            let ms = &self.ms[k];
            ms[0]
                .mul(w[0])
                .add(ms[1].mul(w[1]))
                .add(ms[2].mul(w[2]))
                .zero3()
        };
        let h = node.h;
        Placed32 {
            p: [row(0), row(1), row(2)],
            h: F4::new(h[0], h[1], h[2], 0.0),
            c: self.m * node.center() + self.t,
            sh: C_H * (h[0] + h[1] + h[2]),
        }
    }
    #[inline(always)]
    fn separation(&self, a: &TNode, b: &Placed32) -> Option<(u8, f64)> {
        separation32(a, b, self.s).map(|(k, m)| (k, m as f64 * MARGIN_SCALE))
    }
}

/// The f32 15-axis test (module docs): the first separating axis (numbered as in
/// [`separation`]) and its margin, or `None`.
#[inline(always)]
pub(crate) fn separation32(a: &TNode, b: &Placed32, s: f32) -> Option<(u8, f32)> {
    let ca = a.center();
    let dd = b.c - ca;
    let d = [dd.x as f32, dd.y as f32, dd.z as f32];
    let ha = a.h;
    let s = s
        + C_H * (ha[0] + ha[1] + ha[2])
        + b.sh
        + C_D * (d[0].abs() + d[1].abs() + d[2].abs());
    let sv = F4::splat(s);
    let wa = [F4::load(&a.w[0]), F4::load(&a.w[1]), F4::load(&a.w[2])];
    let dv = d.map(F4::splat);
    // t_i = u_i · d in lane i.
    let t = wa[0].mul(dv[0]).add(wa[1].mul(dv[1])).add(wa[2].mul(dv[2]));
    // Column j of R (lane i: u_i · P_j).
    let p = &b.p;
    let col = |bc0: F4, bc1: F4, bc2: F4| wa[0].mul(bc0).add(wa[1].mul(bc1)).add(wa[2].mul(bc2));
    const S0: i32 = sel(0, 0, 0, 0);
    const S1: i32 = sel(1, 1, 1, 1);
    const S2: i32 = sel(2, 2, 2, 2);
    let c = [
        col(p[0].shuf::<S0>(), p[1].shuf::<S0>(), p[2].shuf::<S0>()),
        col(p[0].shuf::<S1>(), p[1].shuf::<S1>(), p[2].shuf::<S1>()),
        col(p[0].shuf::<S2>(), p[1].shuf::<S2>(), p[2].shuf::<S2>()),
    ];
    let e = F4::splat(EPS_R32);
    let hb = b.h;
    let hbs = [hb.shuf::<S0>(), hb.shuf::<S1>(), hb.shuf::<S2>()];
    // A's faces.
    let rad = F4::new(ha[0], ha[1], ha[2], 0.0)
        .add(hbs[0].mul(c[0].abs().add(e)))
        .add(hbs[1].mul(c[1].abs().add(e)))
        .add(hbs[2].mul(c[2].abs().add(e)))
        .add(sv);
    let m = t.abs().sub(rad);
    let bits = m.positive() & 7;
    if bits != 0 {
        let k = bits.trailing_zeros();
        return Some((k as u8, m.lane(k)));
    }
    // Rows of R (lane j: R_ij).
    let r = transpose3(c);
    let ar = [r[0].abs().add(e), r[1].abs().add(e), r[2].abs().add(e)];
    let has = ha.map(F4::splat);
    // B's faces: P_j · d in lane j.
    let proj = p[0].mul(dv[0]).add(p[1].mul(dv[1])).add(p[2].mul(dv[2]));
    let rad = hb
        .add(has[0].mul(ar[0]))
        .add(has[1].mul(ar[1]))
        .add(has[2].mul(ar[2]))
        .add(sv);
    let m = proj.abs().sub(rad);
    let bits = m.positive() & 7;
    if bits != 0 {
        let k = bits.trailing_zeros();
        return Some((3 + k as u8, m.lane(k)));
    }
    // Edge pairs u_i × P_j, lane j; (i1, i2) = (i + 1, i + 2) mod 3.
    const ROT1: i32 = sel(1, 2, 0, 3);
    const ROT2: i32 = sel(2, 0, 1, 3);
    let hb1 = hb.shuf::<ROT1>();
    let hb2 = hb.shuf::<ROT2>();
    let ts = [t.shuf::<S0>(), t.shuf::<S1>(), t.shuf::<S2>()];
    let cross = |i: usize, i1: usize, i2: usize| {
        let proj = ts[i2].mul(r[i1]).sub(ts[i1].mul(r[i2]));
        let rad = has[i1]
            .mul(ar[i2])
            .add(has[i2].mul(ar[i1]))
            .add(hb1.mul(ar[i].shuf::<ROT2>()))
            .add(hb2.mul(ar[i].shuf::<ROT1>()))
            .add(sv);
        proj.abs().sub(rad)
    };
    let ms = [cross(0, 1, 2), cross(1, 2, 0), cross(2, 0, 1)];
    for (i, m) in ms.iter().enumerate() {
        let bits = m.positive() & 7;
        if bits != 0 {
            let k = bits.trailing_zeros();
            return Some((6 + 3 * i as u8 + k as u8, m.lane(k)));
        }
    }
    None
}

/// Added to every `|R_ij|`.
pub(crate) const EPS_R: f64 = 1e-14;
/// Relative slack: a separation must exceed `SLACK_REL · M`.
pub(crate) const SLACK_REL: f64 = 1e-13;

/// A box of tree B already mapped into A's frame.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Placed {
    pub axes: DMat3,
    pub center: DVec3,
    pub half: DVec3,
    /// `SIGMA · ΣH_B`: B's share of the f32-axes slack.
    pub sigma: f64,
}

impl Placed {
    #[inline(always)]
    pub fn new(node: &TNode, m: &DMat3, t: DVec3) -> Self {
        let half = node.half();
        Placed {
            axes: *m * node.axes(),
            center: *m * node.center() + t,
            half,
            sigma: SIGMA * (half.x + half.y + half.z),
        }
    }
}

/// The separating axis (0..15: A's faces, B's faces, then edge pairs `3·i + j`) and the
/// margin by which it separates (`|projected offset| - (radii + slack)`, > 0), or `None` when
/// no axis separates the boxes by more than `slack`.
///
/// The relative rotation is computed one row at a time: a pair separated by one of A's face
/// axes, the common case deep in a traversal, costs a fraction of the full 15-axis setup.
/// For a cross axis the margin is measured along the unnormalised `a_i × b_j` (length ≤ 1), so
/// it never exceeds the true gap.
#[inline(always)]
pub(crate) fn separation(a: &TNode, b: &Placed, slack: f64) -> Option<(u8, f64)> {
    separation_raw(a, b, slack).map(|(k, m)| (k, m * MARGIN_SCALE))
}

#[inline(always)]
fn separation_raw(a: &TNode, b: &Placed, slack: f64) -> Option<(u8, f64)> {
    let f = |v: [f32; 3]| DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64);
    let ax = a.u().map(f);
    let bx = [b.axes.x_axis, b.axes.y_axis, b.axes.z_axis];
    let d = b.center - a.center();
    let ah = [a.h[0] as f64, a.h[1] as f64, a.h[2] as f64];
    let slack = slack + b.sigma + SIGMA * (ah[0] + ah[1] + ah[2]);
    let bh = b.half.to_array();
    let mut r = [[0.0f64; 3]; 3];
    let mut ar = [[0.0f64; 3]; 3];
    let mut t = [0.0f64; 3];
    for i in 0..3 {
        let ai = ax[i];
        t[i] = ai.x * d.x + ai.y * d.y + ai.z * d.z;
        for j in 0..3 {
            let bj = bx[j];
            r[i][j] = ai.x * bj.x + ai.y * bj.y + ai.z * bj.z;
            ar[i][j] = r[i][j].abs() + EPS_R;
        }
        let m =
            t[i].abs() - (ah[i] + bh[0] * ar[i][0] + bh[1] * ar[i][1] + bh[2] * ar[i][2] + slack);
        if m > 0.0 {
            return Some((i as u8, m));
        }
    }
    for j in 0..3 {
        let m = (t[0] * r[0][j] + t[1] * r[1][j] + t[2] * r[2][j]).abs()
            - (ah[0] * ar[0][j] + ah[1] * ar[1][j] + ah[2] * ar[2][j] + bh[j] + slack);
        if m > 0.0 {
            return Some((3 + j as u8, m));
        }
    }
    for i in 0..3 {
        let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
        for j in 0..3 {
            let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
            let m = (t[i2] * r[i1][j] - t[i1] * r[i2][j]).abs()
                - (ah[i1] * ar[i2][j]
                    + ah[i2] * ar[i1][j]
                    + bh[j1] * ar[i][j2]
                    + bh[j2] * ar[i][j1]
                    + slack);
            if m > 0.0 {
                return Some((6 + (3 * i + j) as u8, m));
            }
        }
    }
    None
}

/// True when some axis separates the boxes by more than the error bound.
#[cfg(test)]
fn disjoint(a: &TNode, b: &Placed, slack: f64) -> bool {
    separation(a, b, slack).is_some()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nodes::compact_box;
    use frcd_geom::{DQuat, Obb, Pose};

    fn node(obb: &Obb) -> TNode {
        let (c, h, u) = compact_box(obb);
        TNode::new(c, h, u, 0)
    }

    fn unit_box(center: DVec3) -> TNode {
        node(&Obb {
            center,
            axes: DMat3::IDENTITY,
            half_extents: DVec3::ONE,
        })
    }

    #[test]
    fn face_touching_boxes_are_kept_and_gapped_ones_separated() {
        let a = unit_box(DVec3::ZERO);
        let b = unit_box(DVec3::new(2.0, 0.0, 0.0));
        let m = DMat3::IDENTITY;
        let slack = SLACK_REL * 4.0;
        assert!(!disjoint(&a, &Placed::new(&b, &m, DVec3::ZERO), slack));
        assert!(disjoint(
            &a,
            &Placed::new(&b, &m, DVec3::new(1e-4, 0.0, 0.0)),
            slack
        ));
        let (axis, margin) =
            separation(&a, &Placed::new(&b, &m, DVec3::new(1e-4, 0.0, 0.0)), slack).unwrap();
        assert_eq!(axis, 0);
        assert!(margin > 0.0 && margin < 1e-4, "{margin}");
    }

    #[test]
    fn edge_edge_separation_needs_a_cross_axis() {
        // Two unit cubes, B rotated 45° about z and about x, placed so only a cross axis
        // separates them.
        let a = unit_box(DVec3::ZERO);
        let q = DQuat::from_rotation_x(std::f64::consts::FRAC_PI_4)
            * DQuat::from_rotation_z(std::f64::consts::FRAC_PI_4);
        let pose = Pose::new(DVec3::ZERO, q);
        let b = unit_box(DVec3::ZERO);
        let m = pose.rotation_matrix();
        // Scan along a diagonal direction: separated far away, touching near.
        let dir = DVec3::new(1.0, 1.0, 1.0).normalize();
        let far = Placed::new(&b, &m, dir * 10.0);
        let near = Placed::new(&b, &m, dir * 1.0);
        assert!(disjoint(&a, &far, 1e-12));
        assert!(!disjoint(&a, &near, 1e-12));
    }

    /// splitmix64
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        fn f(&mut self) -> f64 {
            (self.next() >> 11) as f64 / (1u64 << 53) as f64
        }
        fn sym(&mut self) -> f64 {
            2.0 * self.f() - 1.0
        }
        fn v(&mut self) -> DVec3 {
            DVec3::new(self.sym(), self.sym(), self.sym())
        }
        fn rot(&mut self) -> DQuat {
            let q = DQuat::from_xyzw(self.sym(), self.sym(), self.sym(), self.sym());
            if q.length() < 1e-3 {
                DQuat::IDENTITY
            } else {
                q.normalize()
            }
        }
    }

    /// One box pair and pose: A's node, B's node (local), the frame, slack and magnitude as a
    /// query computes them.
    struct Case {
        a: TNode,
        b: TNode,
        m: DMat3,
        t: DVec3,
    }

    impl Case {
        fn mag(&self) -> f64 {
            let r = |n: &TNode| n.center().length() + n.half().length();
            r(&self.a) + r(&self.b) + self.t.length()
        }
        fn slack(&self) -> f64 {
            SLACK_REL * self.mag() + frcd_geom::ABSOLUTE_SLACK
        }
        /// (f64 separates, f32 separates); panics when f32 separates and f64 does not.
        fn check(&self, what: &str) -> (bool, bool) {
            let slack = self.slack();
            let p64 = Placed::new(&self.b, &self.m, self.t);
            let s64 = separation(&self.a, &p64, slack);
            let Some(sat) = Sat32::new(self.m, self.t, slack, self.mag()) else {
                return (s64.is_some(), false);
            };
            let p32 = sat.place(&self.b);
            let s32 = sat.separation(&self.a, &p32);
            if let Some((axis, margin)) = s32 {
                assert!(
                    s64.is_some(),
                    "{what}: f32 separates on axis {axis} (margin {margin:e}), f64 keeps: {:?} {:?} m {:?} t {:?}",
                    self.a,
                    self.b,
                    self.m,
                    self.t
                );
                // The f32 margin never exceeds the f64 one by more than the f64 rounding.
                let (_, m64) = s64.unwrap();
                assert!(margin <= m64 * (1.0 + 1e-9) + 1e-300 || axis != s64.unwrap().0);
            }
            (s64.is_some(), s32.is_some())
        }
    }

    fn random_node(rng: &mut Rng, centre: DVec3, size: f64) -> TNode {
        let h = DVec3::new(rng.f(), rng.f(), rng.f()) * size;
        // Some flat and some needle boxes.
        let h = match rng.next() % 8 {
            0 => DVec3::new(h.x, h.y, 0.0),
            1 => DVec3::new(h.x, 0.0, 0.0),
            _ => h,
        };
        node(&Obb {
            center: centre,
            axes: DMat3::from_quat(rng.rot()),
            half_extents: h,
        })
    }

    /// B placed so that its support along one of A's axes (or a cross axis) is `gap` away from
    /// A's, measured exactly in f64 on the f32 boxes.
    fn touching(rng: &mut Rng, offset: f64, size: f64, gap: f64) -> Case {
        let ca = rng.v() * size + DVec3::splat(offset);
        let a = random_node(rng, ca, size);
        let cb = rng.v() * size - DVec3::splat(offset);
        let b = random_node(rng, cb, size);
        let m = if rng.next() % 3 == 0 {
            // Nearly parallel to A's axes.
            let eps = 1e-7 * rng.sym();
            a.axes() * DMat3::from_quat(DQuat::from_rotation_z(eps)) * b.axes().transpose()
        } else {
            DMat3::from_quat(rng.rot())
        };
        let pa = a.axes();
        let pb = m * b.axes();
        // The direction: one of A's axes, one of B's, or a cross product.
        let k = (rng.next() % 15) as usize;
        let n = if k < 3 {
            pa.col(k)
        } else if k < 6 {
            pb.col(k - 3)
        } else {
            let c = pa.col((k - 6) / 3).cross(pb.col((k - 6) % 3));
            if c.length() < 1e-3 { pa.col(0) } else { c.normalize() }
        };
        let support = |ax: &DMat3, h: DVec3| {
            h.x * n.dot(ax.col(0)).abs() + h.y * n.dot(ax.col(1)).abs() + h.z * n.dot(ax.col(2)).abs()
        };
        let dist = support(&pa, a.half()) + support(&pb, b.half()) + gap;
        let want = a.center() + n * dist;
        let t = want - m * b.center();
        Case { a, b, m, t }
    }

    #[test]
    fn f32_test_never_separates_what_f64_keeps_random() {
        let mut rng = Rng(7);
        let (mut both, mut only64, mut total64) = (0, 0, 0);
        for k in 0..200_000 {
            let size = [1.0, 1e-3, 50.0][k % 3];
            let offset = [0.0, 10.0, 1e4][(k / 3) % 3];
            let ca = rng.v() * size + DVec3::splat(offset);
            let a = random_node(&mut rng, ca, size);
            let cb = rng.v() * size;
            let b = random_node(&mut rng, cb, size);
            let m = DMat3::from_quat(rng.rot());
            let t = DVec3::splat(offset) + rng.v() * 3.0 * size;
            let (s64, s32) = Case { a, b, m, t }.check("random");
            total64 += s64 as u32;
            both += (s64 && s32) as u32;
            only64 += (s64 && !s32) as u32;
        }
        // The f32 test is sound (checked above) and nearly as sharp as the f64 one.
        assert!(total64 > 50_000, "{total64}");
        assert!(only64 * 200 < total64, "f32 keeps {only64} of {total64} ({both})");
    }

    #[test]
    fn f32_test_never_separates_what_f64_keeps_near_degenerate() {
        let mut rng = Rng(11);
        let (mut sep, mut near) = ([0u32; 2], [0u32; 2]);
        for k in 0..100_000 {
            let size: f64 = [1.0, 1e-6, 1e3, 1e-15, 1e12][k % 5];
            let offset = [0.0, 1.0, 1e6, -3e3][(k / 5) % 4] * size.max(1.0);
            let rel = [0.0, 1e-15, -1e-15, 1e-12, -1e-12, 1e-9, 1e-6, -1e-6, 1e-4, 1e-2][(k / 20) % 10];
            let c = touching(&mut rng, offset, size, rel * size);
            let (s64, s32) = c.check("near-degenerate");
            sep[0] += s64 as u32;
            sep[1] += s32 as u32;
            // Gaps just around the f32 test's own threshold (its slack plus the f32 terms).
            let c2 = touching(&mut Rng(k as u64), offset, size, 0.0);
            let sh = c2.a.half().element_sum() + c2.b.half().element_sum();
            let d1 = (c2.m * c2.b.center() + c2.t - c2.a.center()).abs().element_sum();
            let thr = 2.0 * c2.slack() + C_H as f64 * sh + C_D as f64 * d1;
            let rel = [-0.3, -0.01, 0.0, 0.01, 0.3, 1.0][k % 6];
            // The same boxes and direction (same seed), B moved to that gap.
            let c2 = touching(&mut Rng(k as u64), offset, size, thr * (1.0 + rel));
            let (s64, s32) = c2.check("at the f32 threshold");
            near[0] += s64 as u32;
            near[1] += s32 as u32;
        }
        assert!(sep[1] > 0 && sep[0] >= sep[1], "{sep:?}");
        assert!(near[1] > 0 && near[0] > near[1], "{near:?}");
    }

    #[test]
    fn f32_test_refuses_magnitudes_f32_cannot_hold() {
        let m = DMat3::IDENTITY;
        assert!(Sat32::new(m, DVec3::ZERO, 1e-13, 1.0).is_some());
        assert!(Sat32::new(m, DVec3::ZERO, 1e-13, 1e31).is_none());
        assert!(Sat32::new(m, DVec3::ZERO, 1e-40, 1e-25).is_none());
        assert!(Sat32::new(m, DVec3::splat(f64::NAN), 1e-13, 1.0).is_none());
        assert!(Sat32::new(m, DVec3::ZERO, f64::INFINITY, 1.0).is_none());
        // Huge boxes at the top of the range: the test keeps what it cannot decide, never
        // separates on overflow.
        let big = Case {
            a: unit_box(DVec3::ZERO),
            b: node(&Obb {
                center: DVec3::ZERO,
                axes: DMat3::IDENTITY,
                half_extents: DVec3::splat(1e29),
            }),
            m,
            t: DVec3::new(1e29, 0.0, 0.0),
        };
        assert_eq!(big.check("huge"), (false, false));
    }

    #[test]
    fn f32_test_agrees_on_the_hand_made_cases() {
        let sat = |t: DVec3| Sat32::new(DMat3::IDENTITY, t, 4.0 * SLACK_REL, 4.0).unwrap();
        let a = unit_box(DVec3::ZERO);
        let b = unit_box(DVec3::new(2.0, 0.0, 0.0));
        let s = sat(DVec3::ZERO);
        assert!(s.separation(&a, &s.place(&b)).is_none());
        let s = sat(DVec3::new(1e-3, 0.0, 0.0));
        let (axis, margin) = s.separation(&a, &s.place(&b)).unwrap();
        assert_eq!(axis, 0);
        assert!(margin > 0.0 && margin < 1e-3, "{margin}");
        // Only an edge-edge axis separates these.
        let q = DQuat::from_rotation_x(std::f64::consts::FRAC_PI_4)
            * DQuat::from_rotation_z(std::f64::consts::FRAC_PI_4);
        let m = DMat3::from_quat(q);
        let dir = DVec3::new(1.0, 1.0, 1.0).normalize();
        let b = unit_box(DVec3::ZERO);
        for (dist, apart) in [(10.0, true), (1.0, false)] {
            let s = Sat32::new(m, dir * dist, 1e-12, 20.0).unwrap();
            let p = s.place(&b);
            assert_eq!(s.separation(&a, &p).is_some(), apart, "{dist}");
            let f64_says = separation(&a, &Placed::new(&b, &m, dir * dist), 1e-12);
            assert_eq!(f64_says.map(|x| x.0), s.separation(&a, &p).map(|x| x.0));
        }
    }
}
