//! Point-in-mesh parity on exact orientation predicates, for solid-mode queries.

use crate::nodes::TNode;
use crate::query::RelativeFrame;
use crate::tree::ObbTree;
use frcd_geom::predicates::{collinear3, orient3d};
use frcd_geom::{Aabb, DVec3, Triangle};

/// Most ray directions tried before giving up on a point whose every ray hits an edge, a vertex
/// or runs in a face's plane (measure-zero events: in practice the first ray succeeds).
const MAX_RAYS: u32 = 64;

/// Outcome of one ray against one triangle.
enum Hit {
    Miss,
    Cross,
    Degenerate,
}

#[inline]
fn ray_hit(p: DVec3, q: DVec3, t: &Triangle) -> Hit {
    let [a, b, c] = t.v;
    let sp = orient3d(a, b, c, p);
    let sq = orient3d(a, b, c, q);
    if sp == sq && sp != 0 {
        return Hit::Miss;
    }
    if sp == 0 && sq == 0 {
        // The segment lies in the triangle's plane, or the triangle has no area. A zero-area
        // triangle is a segment or a point, which a generic ray misses.
        if collinear3(a, b, c) {
            return Hit::Miss;
        }
        return Hit::Degenerate;
    }
    let e1 = orient3d(p, q, a, b);
    let e2 = orient3d(p, q, b, c);
    let e3 = orient3d(p, q, c, a);
    let pos = e1 > 0 || e2 > 0 || e3 > 0;
    let neg = e1 < 0 || e2 < 0 || e3 < 0;
    if pos && neg {
        return Hit::Miss;
    }
    if e1 == 0 || e2 == 0 || e3 == 0 || sp == 0 || sq == 0 {
        return Hit::Degenerate;
    }
    Hit::Cross
}

/// A fixed pseudo-random direction sequence (SplitMix64), mostly along one axis so the ray's
/// box stays narrow; the axis cycles with `k`.
fn direction(seed: u64, k: u32) -> DVec3 {
    let mut s = seed ^ (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    let mut next = || {
        s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = s;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let (u, v) = (0.2 * next(), 0.2 * next());
    let sign = if k & 4 == 0 { 1.0 } else { -1.0 };
    match k % 3 {
        0 => DVec3::new(sign, u, v),
        1 => DVec3::new(u, sign, v),
        _ => DVec3::new(u, v, sign),
    }
}

/// The far end `q` of a parity segment from `p` (inside `bounds`) along `dir` (major axis ±1,
/// minor components within ±0.1): a finite point outside `bounds`, at any finite magnitude.
///
/// The segment need not be exactly `p + s·dir`: parity counts crossings of any segment from `p`
/// to a point outside the closed mesh, and a closed mesh lies inside `bounds`. So `q` leaves the
/// box through the face the major axis points at, by as much again as `p` is from that face,
/// computed so nothing overflows (the old `2·|max - min|` reach overflowed from extents of about
/// 1e154 and made every point "outside"). `None` when no finite point lies beyond that face
/// (the box reaches ±f64::MAX there): the caller tries another direction.
fn ray_end(p: DVec3, dir: DVec3, bounds: &Aabb) -> Option<DVec3> {
    let axis = if dir.x.abs() == 1.0 {
        0
    } else if dir.y.abs() == 1.0 {
        1
    } else {
        2
    };
    let sign = dir[axis];
    let face = if sign > 0.0 {
        bounds.max[axis]
    } else {
        bounds.min[axis]
    };
    // Half-distances never overflow; `p` and the face have the same sign relation as `sign`.
    let half = (face * 0.5 - p[axis] * 0.5).abs();
    let mut end = face + sign * (half.max(f64::MIN_POSITIVE) * 2.0).max(face.abs() * 1e-3);
    if !end.is_finite() {
        end = sign * f64::MAX;
    }
    if (sign > 0.0 && end <= face) || (sign < 0.0 && end >= face) {
        return None;
    }
    // The travel along the major axis, halved so it stays finite; the minor components follow
    // it and are clamped to the finite range (the segment stays generic, which is all parity
    // needs).
    let travel_half = (end * 0.5 - p[axis] * 0.5).abs();
    let mut q = p;
    q[axis] = end;
    for m in 0..3 {
        if m != axis {
            let v = p[m] + (2.0 * dir[m]) * travel_half;
            q[m] = v.clamp(-f64::MAX, f64::MAX);
        }
    }
    Some(q)
}

/// Parity of the number of triangles a ray from `p` crosses: `Some(true)` when `p` is inside the
/// closed mesh whose `n` triangles `tri(i)` returns, `None` when every tried ray was degenerate.
/// `bounds` must hold every triangle. `p` must not lie on the surface (callers test this first:
/// the surface pair test would have reported it).
pub(crate) fn point_inside(
    p: DVec3,
    n: usize,
    tri: impl Fn(usize) -> Triangle,
    bounds: &Aabb,
    seed: u64,
) -> Option<bool> {
    parity(p, bounds, seed, |q, seg| {
        let mut crossings = Crossings::default();
        for i in 0..n {
            if !crossings.add(p, q, seg, &tri(i)) {
                return None;
            }
        }
        Some(crossings.0)
    })
}

/// The ray loop of the parity tests: for each direction in turn, the segment from `p` to a
/// point beyond `bounds`, until `count(q, segment box)` gives a crossing count (`None`: a
/// degenerate hit, try the next direction).
fn parity(
    p: DVec3,
    bounds: &Aabb,
    seed: u64,
    mut count: impl FnMut(DVec3, &Aabb) -> Option<u32>,
) -> Option<bool> {
    if !bounds.contains_point(p) {
        return Some(false);
    }
    for k in 0..MAX_RAYS {
        let Some(q) = ray_end(p, direction(seed, k), bounds) else {
            continue;
        };
        let seg = Aabb::new(p.min(q), p.max(q));
        if let Some(crossings) = count(q, &seg) {
            return Some(crossings % 2 == 1);
        }
    }
    None
}

/// A running crossing count of one parity segment.
#[derive(Default)]
struct Crossings(u32);

impl Crossings {
    /// Counts `t` (skipped when its box misses the segment's box `seg`); `false` on a
    /// degenerate hit (the segment must be abandoned).
    #[inline]
    fn add(&mut self, p: DVec3, q: DVec3, seg: &Aabb, t: &Triangle) -> bool {
        if !seg.intersects(&t.aabb()) {
            return true;
        }
        match ray_hit(p, q, t) {
            Hit::Miss => true,
            Hit::Cross => {
                self.0 += 1;
                true
            }
            Hit::Degenerate => false,
        }
    }
}

/// [`point_inside`] against a closed tree's mesh, visiting only the leaves whose box meets the
/// ray's box: O(log n + leaves along the ray) instead of every triangle.
///
/// With `map = Some((frame, slack))` the mesh is B's of a query, its triangles mapped into A's
/// frame by `frame` (exactly as [`RelativeFrame::triangle`] maps them for every other CPU test)
/// and `slack` the query's (`query_slack`), which covers the rounding of mapping a box.
///
/// Same answer as [`point_inside`] over all the (mapped) triangles: a node is skipped only when
/// its box, which holds every triangle below it, misses the segment's box, and such triangles
/// are skipped by [`point_inside`]'s own per-triangle box filter too. (With a frame the ray's far
/// end is placed beyond the mapped tree box instead of beyond the mapped triangles' box: a
/// different segment to a point outside the mesh, hence the same parity.)
pub(crate) fn point_inside_tree(
    p: DVec3,
    tree: &ObbTree,
    map: Option<(&RelativeFrame, f64)>,
    seed: u64,
) -> Option<bool> {
    let bounds = match map {
        None => tree.aabb,
        Some((frame, slack)) => {
            let b = frame.aabb(&tree.aabb, slack);
            if b.min.is_finite() && b.max.is_finite() {
                b
            } else {
                // The slack overflows for extents near 1e154 and beyond (it is built from
                // lengths): the box of the mapped triangles themselves, one pass over them.
                tree.triangles()
                    .fold(Aabb::EMPTY, |acc, t| acc.union(&frame.triangle(&t).aabb()))
            }
        }
    };
    let node_box = |n: &TNode| {
        let local = local_box(n);
        match map {
            None => local,
            Some((frame, slack)) => frame.aabb(&local, slack),
        }
    };
    let triangle = |i: u32| {
        let t = tree.triangle(i);
        match map {
            None => t,
            Some((frame, _)) => frame.triangle(&t),
        }
    };
    let mut stack: Vec<u32> = Vec::with_capacity(64);
    parity(p, &bounds, seed, |q, seg| {
        let mut crossings = Crossings::default();
        stack.clear();
        stack.push(0);
        while let Some(i) = stack.pop() {
            let n = &tree.nodes[i as usize];
            let b = node_box(n);
            // A box that is not finite (coordinates beyond f32) culls nothing.
            if b.min.is_finite() && b.max.is_finite() && !seg.intersects(&b) {
                continue;
            }
            if !n.is_leaf() {
                stack.push(n.right());
                stack.push(i + 1);
                continue;
            }
            for &ti in tree.node_triangles(i) {
                if !crossings.add(p, q, seg, &triangle(ti)) {
                    return None;
                }
            }
        }
        Some(crossings.0)
    })
}

/// The axis-aligned box of a traversal node's f32 box `{c + U s : |s_k| ≤ h_k}` in the mesh's
/// frame, rounded outward: `c ± Σ_k |u_k| h_k`, where each product of two f32 values is exact in
/// f64 and the two sums and `c ± r` round by at most `2⁻⁵¹ (|c| + r)` in all, covered by the
/// `2⁻⁵⁰` pad (plus the smallest normal for subnormal coordinates).
fn local_box(n: &TNode) -> Aabb {
    let c = n.center();
    let h = n.half();
    let u = n.axes();
    let r = u.x_axis.abs() * h.x + u.y_axis.abs() * h.y + u.z_axis.abs() * h.z;
    let pad = (r + c.abs()) * (1.0 / (1u64 << 50) as f64) + DVec3::splat(f64::MIN_POSITIVE);
    let e = r + pad;
    Aabb::new(c - e, c + e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use frcd_geom::shapes;

    #[test]
    fn parity_inside_and_outside_an_icosphere_and_a_cube() {
        let s = shapes::icosphere(1.0, 3);
        let tris: Vec<Triangle> = s.triangles().collect();
        let b = s.aabb();
        for (p, inside) in [
            (DVec3::ZERO, true),
            (DVec3::new(0.9, 0.0, 0.0), true),
            (DVec3::new(0.5, 0.5, 0.5), true),
            (DVec3::new(1.01, 0.0, 0.0), false),
            (DVec3::new(0.7, 0.7, 0.7), false),
        ] {
            assert_eq!(
                point_inside(p, tris.len(), |i| tris[i], &b, 1),
                Some(inside),
                "{p}"
            );
        }
        // A cube: rays along axes through the centre hit edges and face diagonals; the
        // perturbed directions must still count right.
        let c = shapes::cuboid(DVec3::ONE);
        let tris: Vec<Triangle> = c.triangles().collect();
        for seed in 0..20 {
            assert_eq!(
                point_inside(DVec3::ZERO, 12, |i| tris[i], &c.aabb(), seed),
                Some(true)
            );
            assert_eq!(
                point_inside(DVec3::new(0.0, 0.0, 0.99), 12, |i| tris[i], &c.aabb(), seed),
                Some(true)
            );
        }
    }
}

/// The tree-accelerated parity against the plain loop over every triangle.
#[cfg(test)]
mod tree_tests {
    use super::*;
    use crate::BuildOptions;
    use frcd_geom::{DQuat, Pose, TriMesh, shapes};
    use rand::{Rng, SeedableRng};

    fn meshes() -> Vec<TriMesh> {
        let knot = shapes::torus_knot(&shapes::TorusKnotParams::default()).unwrap();
        let gear = shapes::spur_gear(&shapes::SpurGearParams::default()).unwrap();
        vec![
            shapes::icosphere(1.0, 3),
            shapes::cuboid(DVec3::new(1.0, 0.2, 0.5)),
            knot,
            gear,
        ]
    }

    /// Points all over the mesh's box and just off its vertices (both sides of the surface).
    fn points(mesh: &TriMesh, rng: &mut rand::rngs::StdRng, n: usize) -> Vec<DVec3> {
        let b = mesh.aabb();
        let size = (b.max - b.min).length();
        let verts = mesh.vertices();
        (0..n)
            .map(|k| {
                let r = DVec3::new(rng.random(), rng.random(), rng.random());
                if k % 2 == 0 {
                    b.min + (b.max - b.min) * (r * 1.2 - 0.1)
                } else {
                    let v = verts[rng.random_range(0..verts.len())];
                    v + (r * 2.0 - 1.0) * (size * 1e-3)
                }
            })
            .collect()
    }

    #[test]
    fn tree_parity_equals_the_plain_loop() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        for (m, mesh) in meshes().iter().enumerate() {
            for leaf in [1, 4] {
                let opts = BuildOptions {
                    max_leaf_triangles: leaf,
                    ..BuildOptions::default()
                };
                let tree = ObbTree::build(mesh, &opts);
                assert!(tree.closed, "mesh {m}");
                let tris: Vec<Triangle> = mesh.triangles().collect();
                let (mut inside, mut outside) = (0, 0);
                // Unmapped: the tree's own frame.
                for p in points(mesh, &mut rng, 400) {
                    let want = point_inside(p, tris.len(), |i| tris[i], &tree.aabb, 3);
                    assert_eq!(point_inside_tree(p, &tree, None, 3), want, "mesh {m} {p}");
                    inside += (want == Some(true)) as u32;
                    outside += (want == Some(false)) as u32;
                }
                // Mapped: the tree as B of a query, its triangles in A's frame.
                for k in 0..8 {
                    let pose_a = Pose::new(
                        DVec3::new(rng.random(), rng.random(), rng.random()) * 3.0,
                        DQuat::from_rotation_x(k as f64) * DQuat::from_rotation_z(1.1),
                    );
                    let pose_b = Pose::new(
                        DVec3::new(rng.random(), rng.random(), rng.random()) * 3.0,
                        DQuat::from_rotation_y(0.7 * k as f64),
                    );
                    let frame = RelativeFrame::new(&pose_a, &pose_b);
                    let slack = crate::query::query_slack(&tree, &tree, &frame);
                    let mapped: Vec<Triangle> = tris.iter().map(|t| frame.triangle(t)).collect();
                    let bounds = mapped
                        .iter()
                        .fold(Aabb::EMPTY, |acc, t| acc.union(&t.aabb()));
                    for p in points(mesh, &mut rng, 60) {
                        let p = frame.point(p);
                        let want = point_inside(p, mapped.len(), |i| mapped[i], &bounds, 5);
                        let got = point_inside_tree(p, &tree, Some((&frame, slack)), 5);
                        assert_eq!(got, want, "mesh {m} pose {k} {p}");
                        inside += (want == Some(true)) as u32;
                    }
                }
                assert!(
                    inside > 50 && outside > 50,
                    "{m}: {inside} in, {outside} out"
                );
            }
        }
    }

    /// Boxes beyond f32's range (not finite as f32 nodes) cull nothing, and subnormal-scale
    /// boxes still hold their triangles: the answers stay those of the plain loop.
    #[test]
    fn tree_parity_at_extreme_magnitudes() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(12);
        for scale in [1e-42, 1e-30, 1e30, 1e45, 1e300] {
            let mesh = shapes::icosphere(scale, 2);
            let tree = ObbTree::build(&mesh, &BuildOptions::default());
            let tris: Vec<Triangle> = mesh.triangles().collect();
            let mut inside = 0;
            for p in points(&mesh, &mut rng, 200) {
                let want = point_inside(p, tris.len(), |i| tris[i], &tree.aabb, 9);
                assert_eq!(point_inside_tree(p, &tree, None, 9), want, "{scale:e} {p}");
                inside += (want == Some(true)) as u32;
            }
            assert!(inside > 20, "{scale:e}: {inside}");
        }
    }
}

#[cfg(test)]
mod magnitude_tests {
    use super::*;
    use frcd_geom::shapes;

    /// Regression (issue 11): extents of 1e154 and more overflowed the ray reach to infinity,
    /// and every point was reported outside.
    #[test]
    fn parity_is_right_at_any_finite_magnitude() {
        for s in [1.0, 1e154, 1e200, 1e300, 8.9e307] {
            let c = shapes::cuboid(DVec3::splat(s));
            let tris: Vec<Triangle> = c.triangles().collect();
            let b = c.aabb();
            for seed in 0..8 {
                for (p, inside) in [
                    (DVec3::ZERO, true),
                    (DVec3::new(0.5 * s, -0.25 * s, 0.75 * s), true),
                    (DVec3::new(-0.999 * s, 0.999 * s, -0.999 * s), true),
                    (DVec3::new(1.5 * s, 0.0, 0.0), false),
                    (DVec3::new(0.0, 0.0, -1.001 * s), false),
                ] {
                    assert_eq!(
                        point_inside(p, tris.len(), |i| tris[i], &b, seed),
                        Some(inside),
                        "extent {s:e}, point {p}, seed {seed}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_box_reaching_the_largest_finite_value_still_gets_an_answer() {
        // The +x face is at f64::MAX: rays that point that way have no finite end beyond it and
        // are skipped; the others decide.
        let m = f64::MAX;
        let c = shapes::cuboid(DVec3::splat(m / 2.0)).transformed(
            &frcd_geom::Pose::from_translation(DVec3::new(m / 2.0, 0.0, 0.0)),
        );
        let tris: Vec<Triangle> = c.triangles().collect();
        let b = c.aabb();
        assert_eq!(b.max.x, m);
        for seed in 0..4 {
            let p = DVec3::new(m / 2.0, m / 4.0, 0.0);
            assert_eq!(
                point_inside(p, tris.len(), |i| tris[i], &b, seed),
                Some(true)
            );
        }
    }

    #[test]
    fn ray_ends_are_finite_and_outside_the_box() {
        let b = Aabb::new(DVec3::splat(-1e300), DVec3::splat(1e300));
        for k in 0..MAX_RAYS {
            let d = direction(7, k);
            let q = ray_end(DVec3::new(1e300, -1e300, 0.0), d, &b).expect("room beyond the box");
            assert!(q.is_finite(), "{q}");
            assert!(!b.contains_point(q), "{q} inside");
        }
    }
}
