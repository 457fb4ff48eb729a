//! A lower bound on a pair's distance that does not depend on how far one body has turned about
//! an axis of its own: the *meridian bound*.
//!
//! # The bound
//!
//! Take an axis (point `c`, unit direction `u`) fixed in body S's frame and write every point
//! `x` in cylindrical coordinates about it: `z = u·(x - c)`, `ρ = |(x - c) - z u|`, angle `θ`.
//! The meridian map `P(x) = (ρ, z)` is 1-Lipschitz: for two points at angles `θ₁`, `θ₂`,
//! `|x₁ - x₂|² = (z₁ - z₂)² + ρ₁² + ρ₂² - 2ρ₁ρ₂ cos(θ₁ - θ₂) >= (z₁ - z₂)² + (ρ₁ - ρ₂)²`.
//! So for any other surface O, `dist(O, S) >= min |P(o) - P(s)|` over `o ∈ O`, `s ∈ S`, and
//! the right side does not change when S turns about the axis (a turn changes only `θ`). This
//! holds for any mesh and any axis; it is *tight* (close to the true distance) when S is close
//! to a surface of revolution about the axis, like a wheelset spinning on its axle, which
//! sweeps no new space as it turns while every tread vertex moves tens of millimetres a frame.
//! Then a pair such as wheelset / side frame, 28-48 mm apart, is proved farther than a 5 mm
//! threshold in every frame without a distance search, where the motion bound (which sees the
//! wheel's vertices move) never could.
//!
//! # Computing it
//!
//! Per triangle of S, a box in `(ρ, z)` holding its meridian image: `z` is linear, so its range
//! is that of the vertices; `ρ` is convex (a norm of a linear function), so its maximum is at a
//! vertex, and its minimum is the distance from the axis to the triangle projected along `u`
//! (a 2D point-triangle distance). The boxes go into a small 2D box tree (built once per body:
//! [`SpinProfile`]). Per query, O's tree is descended: an internal node's box in `(ρ, z)` is
//! bounded from its OBB (`z` range `z_c ± Σ h_i |u·a_i|`, `ρ` within `ρ_c ± Σ h_i |a_i - (u·a_i) u|`),
//! a leaf's from its triangles as above, and a node or triangle whose box is farther than the
//! limit from every box of S's tree is dropped. When everything is dropped, every point pair is
//! farther apart than `limit`.
//!
//! Rounding: every quantity is a few operations on coordinates of magnitude at most `M` (the
//! sum of both bodies' radii from their origins, `|c|` and the relative translation), so each
//! computed `(ρ, z)` is within `~16 ε M` of the exact one; O's points are mapped into S's frame
//! either as [`RelativeFrame`] maps them (S is body A: the same f64 operations as the distance
//! query's inputs) or by the transposed rotation (S is body B: within `~8 ε M` of the inverse of
//! that mapping). The decision subtracts `SLACK_REL · M = 1e-9 M`, far above all of it.

use crate::query::RelativeFrame;
use crate::tree::ObbTree;
use frcd_geom::{DMat3, DVec3, Obb};
use std::collections::HashSet;

/// Relative slack of the meridian decision (see the module docs).
const SLACK_REL: f64 = 1e-9;
/// Boxes per leaf of the meridian tree.
const LEAF: usize = 4;

/// A box in meridian coordinates: `ρ ∈ [r0, r1]`, `z ∈ [z0, z1]`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct MBox {
    r0: f64,
    r1: f64,
    z0: f64,
    z1: f64,
}

impl MBox {
    const EMPTY: MBox = MBox {
        r0: f64::INFINITY,
        r1: f64::NEG_INFINITY,
        z0: f64::INFINITY,
        z1: f64::NEG_INFINITY,
    };

    fn union(self, o: MBox) -> MBox {
        MBox {
            r0: self.r0.min(o.r0),
            r1: self.r1.max(o.r1),
            z0: self.z0.min(o.z0),
            z1: self.z1.max(o.z1),
        }
    }

    /// Squared distance between the two boxes (0 when they overlap).
    #[inline]
    fn gap2(&self, o: &MBox) -> f64 {
        let dr = (o.r0 - self.r1).max(self.r0 - o.r1).max(0.0);
        let dz = (o.z0 - self.z1).max(self.z0 - o.z1).max(0.0);
        dr * dr + dz * dz
    }

    fn center(&self) -> (f64, f64) {
        (0.5 * (self.r0 + self.r1), 0.5 * (self.z0 + self.z1))
    }
}

/// A node of the meridian tree: a leaf holds `boxes[start..start + len]`, an internal node
/// (`len == 0`) its children `start` and `start + 1`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct MNode {
    bx: MBox,
    start: u32,
    len: u32,
}

/// The meridian image of a body about an axis of its own (see the module docs): what
/// [`super::pair_clearance_spin`] needs to prove the body's pairs far whatever angle the body
/// has turned to about that axis. Built once per tree; read-only afterwards (`Send + Sync`).
///
/// ```
/// use frcd_obb::{BuildOptions, ObbTree, SpinProfile};
/// use frcd_geom::{shapes, DVec3};
/// // A cylinder about z: its own axis is found; a cuboid has none worth using.
/// let cyl = ObbTree::build(&shapes::cylinder(0.5, 1.0, 48, 2).unwrap(), &BuildOptions::default());
/// let s = SpinProfile::detect(&cyl).expect("a solid of revolution");
/// assert!(s.axis().1.z.abs() > 0.999);
/// let cube = ObbTree::build(&shapes::cuboid(DVec3::splat(0.5)), &BuildOptions::default());
/// assert!(SpinProfile::detect(&cube).is_none());
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct SpinProfile {
    /// The tree it was built for.
    tree: u64,
    c: DVec3,
    u: DVec3,
    /// Orthonormal basis of the plane normal to `u`.
    e1: DVec3,
    e2: DVec3,
    boxes: Vec<MBox>,
    nodes: Vec<MNode>,
    /// `|c|` plus the body's radius from its origin (for the slack).
    magnitude: f64,
}

impl SpinProfile {
    /// The profile of `tree` about the axis through `point` along `dir` (body-local
    /// coordinates; `dir` need not be unit). `None` for a zero or non-finite axis. The bound is
    /// valid for any axis; it is useful only when the body is close to a surface of revolution
    /// about it.
    pub fn about(tree: &ObbTree, point: DVec3, dir: DVec3) -> Option<SpinProfile> {
        let u = dir.normalize_or_zero();
        if u == DVec3::ZERO || !point.is_finite() || !u.is_finite() {
            return None;
        }
        let e1 = u.any_orthonormal_vector();
        let e2 = u.cross(e1);
        let mut p = SpinProfile {
            tree: tree.uid,
            c: point,
            u,
            e1,
            e2,
            boxes: Vec::new(),
            nodes: Vec::new(),
            magnitude: point.length() + tree.radius_from_origin,
        };
        let mut boxes: Vec<MBox> = (0..tree.triangle_count() as u32)
            .map(|t| p.triangle_box(&tree.triangle(t).v))
            .collect();
        if boxes.is_empty()
            || boxes
                .iter()
                .any(|b| !(b.r1.is_finite() && b.z1.is_finite()))
        {
            return None;
        }
        // Triangles of one ring of a solid of revolution share one box up to rounding: grow
        // each box outward to a grid of `1e-9 M` (it still holds its triangle's image) and
        // keep one of each.
        let q = SLACK_REL * p.magnitude.max(f64::MIN_POSITIVE);
        for b in &mut boxes {
            *b = MBox {
                r0: ((b.r0 / q).floor() * q).max(0.0),
                r1: (b.r1 / q).ceil() * q,
                z0: (b.z0 / q).floor() * q,
                z1: (b.z1 / q).ceil() * q,
            };
        }
        boxes.sort_unstable_by(|x, y| {
            (x.z0, x.r0, x.z1, x.r1)
                .partial_cmp(&(y.z0, y.r0, y.z1, y.r1))
                .expect("finite")
        });
        boxes.dedup();
        p.nodes.push(MNode {
            bx: MBox::EMPTY,
            start: 0,
            len: 0,
        });
        build(&mut boxes, 0, &mut p.nodes, 0);
        p.boxes = boxes;
        Some(p)
    }

    /// Looks for an axis about which `tree`'s mesh is a solid of revolution (rings of at least
    /// 6 vertices sharing a radius and height), among its root box's axes and the coordinate
    /// axes through the mean of its vertices; `None` when no candidate fits. A heuristic: it
    /// only chooses which axis to use (see [`SpinProfile::about`]).
    pub fn detect(tree: &ObbTree) -> Option<SpinProfile> {
        let v = tree.mesh.vertices();
        if v.len() < 24 {
            return None;
        }
        let c = v.iter().copied().sum::<DVec3>() / v.len() as f64;
        let obb = tree.node_obb(tree.root_node());
        let scale = tree.radius_from_origin.max(1e-300);
        let q = 1e-4 * scale;
        let mut best: Option<(usize, DVec3)> = None;
        for u in [
            obb.axes.x_axis,
            obb.axes.y_axis,
            obb.axes.z_axis,
            DVec3::X,
            DVec3::Y,
            DVec3::Z,
        ] {
            let u = u.normalize_or_zero();
            if u == DVec3::ZERO {
                continue;
            }
            let rings: HashSet<(i64, i64)> = v
                .iter()
                .map(|x| {
                    let d = *x - c;
                    let z = d.dot(u);
                    let r = (d - z * u).length();
                    ((r / q).round() as i64, (z / q).round() as i64)
                })
                .collect();
            if best.is_none_or(|(n, _)| rings.len() < n) {
                best = Some((rings.len(), u));
            }
        }
        let (n, u) = best?;
        (n * 6 <= v.len())
            .then(|| Self::about(tree, c, u))
            .flatten()
    }

    /// The axis `(point, unit direction)` in the body's local frame.
    pub fn axis(&self) -> (DVec3, DVec3) {
        (self.c, self.u)
    }

    /// Distinct triangle boxes kept (a measure of how close to a solid of revolution the body
    /// is: a revolved profile keeps about one per profile edge).
    pub fn box_count(&self) -> usize {
        self.boxes.len()
    }

    /// The meridian box of a triangle given in this body's frame.
    fn triangle_box(&self, v: &[DVec3; 3]) -> MBox {
        let d = [v[0] - self.c, v[1] - self.c, v[2] - self.c];
        let z = [d[0].dot(self.u), d[1].dot(self.u), d[2].dot(self.u)];
        let p = [
            (d[0].dot(self.e1), d[0].dot(self.e2)),
            (d[1].dot(self.e1), d[1].dot(self.e2)),
            (d[2].dot(self.e1), d[2].dot(self.e2)),
        ];
        let r = |(x, y): (f64, f64)| x.hypot(y);
        MBox {
            r0: origin_to_triangle_2d(&p),
            r1: r(p[0]).max(r(p[1])).max(r(p[2])),
            z0: z[0].min(z[1]).min(z[2]),
            z1: z[0].max(z[1]).max(z[2]),
        }
    }

    /// The meridian box of a box with centre `c` and axes scaled by its half extents (`h`
    /// columns), in this body's frame.
    fn obb_box(&self, center: DVec3, h: [DVec3; 3]) -> MBox {
        let d = center - self.c;
        let zc = d.dot(self.u);
        let rc = (d.dot(self.e1)).hypot(d.dot(self.e2));
        let (mut ez, mut er) = (0.0, 0.0);
        for a in h {
            ez += a.dot(self.u).abs();
            er += (a.dot(self.e1)).hypot(a.dot(self.e2));
        }
        MBox {
            r0: (rc - er).max(0.0),
            r1: rc + er,
            z0: zc - ez,
            z1: zc + ez,
        }
    }

    /// True when some box of this profile comes within `limit` of `b` (`limit2 = limit²`).
    fn any_within(&self, b: &MBox, limit2: f64, stack: &mut Vec<u32>) -> bool {
        stack.clear();
        stack.push(0);
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if node.bx.gap2(b) > limit2 {
                continue;
            }
            if node.len == 0 {
                stack.push(node.start);
                stack.push(node.start + 1);
                continue;
            }
            let s = node.start as usize;
            if self.boxes[s..s + node.len as usize]
                .iter()
                .any(|x| x.gap2(b) <= limit2)
            {
                return true;
            }
        }
        false
    }

    /// True when every point of `other`'s surface, placed by `place` (a point of `other`'s frame
    /// to this body's) and `rot` (its rotation), is proved farther than `limit` from every
    /// point of this body's surface, at any angle this body has turned to about its axis.
    /// `extra_magnitude` is `other`'s radius from its origin plus the relative translation's
    /// length (for the slack). Also returns the nodes visited.
    pub(crate) fn proves_far(
        &self,
        other: &ObbTree,
        place: impl Fn(DVec3) -> DVec3,
        rot: DMat3,
        limit: f64,
        extra_magnitude: f64,
    ) -> (bool, u64) {
        let slack = SLACK_REL * (self.magnitude + extra_magnitude);
        let reach = limit + slack;
        if !(reach.is_finite() && reach >= 0.0) {
            return (false, 0);
        }
        let limit2 = reach * reach * (1.0 + 1e-12);
        let mut todo = vec![other.root_node()];
        let mut stack = Vec::with_capacity(64);
        let mut visits = 0u64;
        while let Some(n) = todo.pop() {
            visits += 1;
            let tris = other.node_triangles(n);
            if tris.is_empty() {
                let o: Obb = other.node_obb(n);
                let h = [
                    rot * (o.axes.x_axis * o.half_extents.x),
                    rot * (o.axes.y_axis * o.half_extents.y),
                    rot * (o.axes.z_axis * o.half_extents.z),
                ];
                let b = self.obb_box(place(o.center), h);
                if !b.r1.is_finite() || !b.z1.is_finite() {
                    return (false, visits);
                }
                if self.any_within(&b, limit2, &mut stack) {
                    todo.extend(other.node_children(n));
                }
                continue;
            }
            for &t in tris {
                let v = other.triangle(t).v;
                let b = self.triangle_box(&[place(v[0]), place(v[1]), place(v[2])]);
                if !b.r1.is_finite() || !b.z1.is_finite() || self.any_within(&b, limit2, &mut stack)
                {
                    return (false, visits);
                }
            }
        }
        (true, visits)
    }

    /// True when some vertex of `other`, placed in this body's frame by `place`, lies outside
    /// the convex region `ρ <= ρ_max`, `z_min <= z <= z_max` (over this body's surface) by more
    /// than the slack: that vertex is then outside this body's solid. `extra_magnitude` as in
    /// [`SpinProfile::proves_far`].
    pub(crate) fn any_outside(
        &self,
        other: &ObbTree,
        place: impl Fn(DVec3) -> DVec3,
        extra_magnitude: f64,
    ) -> bool {
        let slack = SLACK_REL * (self.magnitude + extra_magnitude);
        let r = &self.nodes[0].bx;
        let (rmax, z0, z1) = (r.r1 + slack, r.z0 - slack, r.z1 + slack);
        // Vertices of triangles (a vertex no triangle uses is no point of the surface).
        other.mesh.indices().iter().any(|t| {
            let v = other.mesh.vertices()[t[0] as usize];
            let d = place(v) - self.c;
            let z = d.dot(self.u);
            z < z0 || z > z1 || d.dot(self.e1).hypot(d.dot(self.e2)) > rmax
        })
    }

    /// True when this profile was built for `tree` (or a clone of it).
    pub(crate) fn is_for(&self, tree: &ObbTree) -> bool {
        self.tree == tree.uid
    }
}

/// The 2D box tree over `boxes[..]` (reordered in place), rooted at `nodes[at]`.
fn build(boxes: &mut [MBox], offset: usize, nodes: &mut Vec<MNode>, at: usize) {
    let bx = boxes.iter().fold(MBox::EMPTY, |a, b| a.union(*b));
    if boxes.len() <= LEAF {
        nodes[at] = MNode {
            bx,
            start: offset as u32,
            len: boxes.len() as u32,
        };
        return;
    }
    let along_r = bx.r1 - bx.r0 >= bx.z1 - bx.z0;
    let key = |b: &MBox| {
        let (r, z) = b.center();
        if along_r { r } else { z }
    };
    let mid = boxes.len() / 2;
    boxes.select_nth_unstable_by(mid, |x, y| key(x).total_cmp(&key(y)));
    let kids = nodes.len();
    nodes[at] = MNode {
        bx,
        start: kids as u32,
        len: 0,
    };
    nodes.push(MNode {
        bx: MBox::EMPTY,
        start: 0,
        len: 0,
    });
    nodes.push(MNode {
        bx: MBox::EMPTY,
        start: 0,
        len: 0,
    });
    let (lo, hi) = boxes.split_at_mut(mid);
    build(lo, offset, nodes, kids);
    build(hi, offset + mid, nodes, kids + 1);
}

/// Distance from the origin to a 2D triangle (0 when the triangle holds it).
fn origin_to_triangle_2d(p: &[(f64, f64); 3]) -> f64 {
    let cross = |a: (f64, f64), b: (f64, f64)| a.0 * b.1 - a.1 * b.0;
    let s = [cross(p[0], p[1]), cross(p[1], p[2]), cross(p[2], p[0])];
    if (s[0] >= 0.0 && s[1] >= 0.0 && s[2] >= 0.0) || (s[0] <= 0.0 && s[1] <= 0.0 && s[2] <= 0.0) {
        // Inside or on the boundary (or degenerate and through the origin): 0 is a lower bound.
        return 0.0;
    }
    let seg = |a: (f64, f64), b: (f64, f64)| {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let len2 = dx * dx + dy * dy;
        let t = if len2 > 0.0 {
            (-(a.0 * dx + a.1 * dy) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (a.0 + t * dx).hypot(a.1 + t * dy)
    };
    seg(p[0], p[1]).min(seg(p[1], p[2])).min(seg(p[2], p[0]))
}

/// `proves_far` for a pair: `spin` belongs to A (`on_a`) or B; the other body's points are
/// mapped into the spinning body's frame.
pub(crate) fn pair_proved_far(
    spin: &SpinProfile,
    on_a: bool,
    a: &ObbTree,
    b: &ObbTree,
    frame: &RelativeFrame,
    limit: f64,
) -> (bool, u64) {
    let tl = frame.t.length();
    if on_a {
        let (m, t) = (frame.m, frame.t);
        spin.proves_far(b, |x| m * x + t, m, limit, b.radius_from_origin + tl)
    } else {
        let mt = frame.m.transpose();
        let t = frame.t;
        spin.proves_far(a, |x| mt * (x - t), mt, limit, a.radius_from_origin + tl)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tree::BuildOptions;
    use frcd_geom::{DQuat, Pose, shapes};
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    fn tree(m: &frcd_geom::TriMesh) -> ObbTree {
        ObbTree::build(
            m,
            &BuildOptions {
                max_leaf_triangles: 1,
                ..BuildOptions::default()
            },
        )
    }

    /// Random spins of a solid of revolution (turned about its axis by any angle, the axis
    /// itself tilted and moved a little) against random bodies around it: whenever the
    /// meridian bound proves the pair farther than a limit, the oracle's distance is larger,
    /// with the profiled body as A and as B; and the bound is tight (within the polygon's
    /// sagitta and the other body's triangle size) so that it proves most far pairs far.
    #[test]
    fn meridian_bound_is_below_the_oracle_at_every_spin() {
        let wheel_mesh = shapes::cylinder(0.3, 0.1, 24, 2).unwrap();
        let wheel = tree(&wheel_mesh);
        let spin = SpinProfile::detect(&wheel).expect("a cylinder is a solid of revolution");
        assert!(spin.axis().1.z.abs() > 1.0 - 1e-12, "{:?}", spin.axis());
        assert!(spin.axis().0.length() < 1e-12);
        let others = [
            shapes::icosphere(0.04, 1),
            shapes::cuboid(DVec3::new(0.05, 0.02, 0.08)),
        ];
        let others: Vec<(frcd_geom::TriMesh, ObbTree)> = others
            .into_iter()
            .map(|m| {
                let t = tree(&m);
                (m, t)
            })
            .collect();
        let mut rng = StdRng::seed_from_u64(12);
        let (mut proved, mut far_cases, mut checks) = (0, 0, 0);
        for case in 0..240 {
            let (om, ot) = &others[case % others.len()];
            // The wheel: any spin about z, a small wobble, a small offset.
            let wobble = DQuat::from_rotation_x(rng.random_range(-0.01..0.01));
            let pose_w = Pose::new(
                DVec3::new(
                    rng.random_range(-0.01..0.01),
                    rng.random_range(-0.01..0.01),
                    0.0,
                ),
                wobble * DQuat::from_rotation_z(rng.random_range(0.0..std::f64::consts::TAU)),
            );
            // The other body: near the rim, the faces or the axis.
            let ang = rng.random_range(0.0..std::f64::consts::TAU);
            let r = rng.random_range(0.0..0.5);
            let pose_o = Pose::new(
                DVec3::new(r * ang.cos(), r * ang.sin(), rng.random_range(-0.3..0.3)),
                DQuat::from_rotation_x(rng.random_range(0.0..3.0))
                    * DQuat::from_rotation_y(rng.random_range(0.0..3.0))
                    * DQuat::from_rotation_z(rng.random_range(0.0..3.0)),
            );
            let d = crate::oracle::distance(&wheel_mesh, &pose_w, om, &pose_o).distance;
            for on_a in [true, false] {
                let (a, pa, b, pb) = if on_a {
                    (&wheel, &pose_w, ot, &pose_o)
                } else {
                    (ot, &pose_o, &wheel, &pose_w)
                };
                let frame = RelativeFrame::new(pa, pb);
                for limit in [0.0, 0.5 * d, 0.9 * d, d - 1e-9, d, 1.01 * d + 1e-9] {
                    checks += 1;
                    let (far, _) = pair_proved_far(&spin, on_a, a, b, &frame, limit);
                    assert!(
                        !far || d > limit,
                        "case {case} on_a {on_a}: proved farther than {limit}, oracle {d}"
                    );
                }
                // Tightness: the wheel's sagitta (0.3 (1 - cos(π/24)) = 2.6 mm), the wobble's
                // tilt and the other body's triangles (a few cm) are all it loses.
                if d > 0.08 {
                    far_cases += 1;
                    proved += pair_proved_far(&spin, on_a, a, b, &frame, d - 0.06).0 as u32;
                }
            }
        }
        assert!(checks > 2000);
        assert!(far_cases > 100, "{far_cases}");
        assert!(proved * 10 >= far_cases * 9, "{proved} of {far_cases}");
    }

    /// The wheelset of the bogie demo: found to be a solid of revolution about its axle (y),
    /// keeping about one box per profile edge.
    #[test]
    fn wheelset_axis_is_found() {
        let m = shapes::wheelset(&shapes::WheelsetParams::default()).unwrap();
        let t = tree(&m);
        let s = SpinProfile::detect(&t).unwrap();
        assert!(s.axis().1.y.abs() > 1.0 - 1e-9, "{:?}", s.axis());
        assert!(s.box_count() * 16 < t.triangle_count(), "{}", s.box_count());
        // Not one for a body that is no solid of revolution, nor for bad axes.
        let frame = tree(&shapes::cuboid(DVec3::new(1.0, 0.2, 0.1)));
        assert!(SpinProfile::detect(&frame).is_none());
        assert!(SpinProfile::about(&t, DVec3::ZERO, DVec3::ZERO).is_none());
        assert!(SpinProfile::about(&t, DVec3::NAN, DVec3::Y).is_none());
    }
}
