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

use crate::nodes::{MARGIN_SCALE, SIGMA, TNode};
use frcd_geom::{DMat3, DVec3};

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
    let ax = [f(a.u[0]), f(a.u[1]), f(a.u[2])];
    let bx = [b.axes.x_axis, b.axes.y_axis, b.axes.z_axis];
    let d = b.center - f(a.c);
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
pub(crate) mod tests {
    use super::*;
    use crate::nodes::compact_box;
    use frcd_geom::{DQuat, Obb, Pose};

    /// A traversal node holding `obb` (shared with the wide test's tests).
    pub(crate) fn node(obb: &Obb) -> TNode {
        let (c, h, u) = compact_box(obb);
        TNode { c, h, u, link: 0 }
    }

    /// An axis-aligned unit-half-extent node at `center`.
    pub(crate) fn unit_box(center: DVec3) -> TNode {
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
}
