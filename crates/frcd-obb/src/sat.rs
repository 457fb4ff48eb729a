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

use frcd_geom::{DMat3, DVec3, Obb};

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
}

impl Placed {
    #[inline(always)]
    pub fn new(obb: &Obb, m: &DMat3, t: DVec3) -> Self {
        Placed {
            axes: *m * obb.axes,
            center: *m * obb.center + t,
            half: obb.half_extents,
        }
    }
}

struct Setup {
    r: [[f64; 3]; 3],
    ar: [[f64; 3]; 3],
    t: [f64; 3],
    a: [f64; 3],
    b: [f64; 3],
}

#[inline(always)]
fn setup(a: &Obb, b: &Placed) -> Setup {
    let at = a.axes.transpose();
    let rm = at * b.axes; // column j = A^T B_j, so R[i][j] = rm.col(j)[i]
    let tv = at * (b.center - a.center);
    let c = [rm.x_axis, rm.y_axis, rm.z_axis];
    let mut r = [[0.0; 3]; 3];
    let mut ar = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = c[j][i];
            ar[i][j] = c[j][i].abs() + EPS_R;
        }
    }
    Setup {
        r,
        ar,
        t: tv.to_array(),
        a: a.half_extents.to_array(),
        b: b.half.to_array(),
    }
}

#[inline(always)]
fn axis(s: &Setup, k: u8, slack: f64) -> bool {
    let (r, ar, t, a, b) = (&s.r, &s.ar, &s.t, &s.a, &s.b);
    match k {
        0..=2 => {
            let i = k as usize;
            t[i].abs() > a[i] + b[0] * ar[i][0] + b[1] * ar[i][1] + b[2] * ar[i][2] + slack
        }
        3..=5 => {
            let j = (k - 3) as usize;
            (t[0] * r[0][j] + t[1] * r[1][j] + t[2] * r[2][j]).abs()
                > a[0] * ar[0][j] + a[1] * ar[1][j] + a[2] * ar[2][j] + b[j] + slack
        }
        _ => {
            let i = ((k - 6) / 3) as usize;
            let j = ((k - 6) % 3) as usize;
            let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
            let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
            (t[i2] * r[i1][j] - t[i1] * r[i2][j]).abs()
                > a[i1] * ar[i2][j]
                    + a[i2] * ar[i1][j]
                    + b[j1] * ar[i][j2]
                    + b[j2] * ar[i][j1]
                    + slack
        }
    }
}

/// True when some axis separates the boxes by more than the error bound.
#[inline]
pub(crate) fn disjoint(a: &Obb, b: &Placed, slack: f64) -> bool {
    let s = setup(a, b);
    (0..15u8).any(|k| axis(&s, k, slack))
}

/// Like [`disjoint`], trying `first` before the others; returns the separating axis (0..15).
pub(crate) fn separating_axis(a: &Obb, b: &Placed, slack: f64, first: Option<u8>) -> Option<u8> {
    let s = setup(a, b);
    if let Some(f) = first.filter(|f| *f < 15) {
        if axis(&s, f, slack) {
            return Some(f);
        }
    }
    (0..15u8).find(|&k| Some(k) != first && axis(&s, k, slack))
}

#[cfg(test)]
mod tests {
    use super::*;
    use frcd_geom::{DQuat, Pose};

    fn unit_box(center: DVec3) -> Obb {
        Obb {
            center,
            axes: DMat3::IDENTITY,
            half_extents: DVec3::ONE,
        }
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
            &Placed::new(&b, &m, DVec3::new(1e-6, 0.0, 0.0)),
            slack
        ));
        assert_eq!(
            separating_axis(
                &a,
                &Placed::new(&b, &m, DVec3::new(1e-6, 0.0, 0.0)),
                slack,
                None
            ),
            Some(0)
        );
    }

    #[test]
    fn edge_edge_separation_needs_a_cross_axis() {
        // Two unit cubes, B rotated 45° about z and about x, placed so only a cross axis
        // separates them.
        let a = unit_box(DVec3::ZERO);
        let q = DQuat::from_rotation_x(std::f64::consts::FRAC_PI_4)
            * DQuat::from_rotation_z(std::f64::consts::FRAC_PI_4);
        let pose = Pose::new(DVec3::ZERO, q);
        let b = Obb {
            center: DVec3::ZERO,
            axes: DMat3::IDENTITY,
            half_extents: DVec3::ONE,
        };
        let m = pose.rotation_matrix();
        // Scan along a diagonal direction: separated far away, touching near.
        let dir = DVec3::new(1.0, 1.0, 1.0).normalize();
        let far = Placed::new(&b, &m, dir * 10.0);
        let near = Placed::new(&b, &m, dir * 1.0);
        assert!(disjoint(&a, &far, 1e-12));
        assert!(!disjoint(&a, &near, 1e-12));
    }
}
