//! Convex hull: every input point inside or on every face (exact predicate), closed oriented
//! 2-manifold, Euler characteristic 2, on random, cospherical, gridded, repeated and
//! near-coplanar input.

use frcd_geom::hull::{Hull3, HullError, convex_hull};
use frcd_geom::predicates::{orient2d, orient3d};
use frcd_geom::{DQuat, DVec2, DVec3, Pose, TriMesh};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::collections::HashSet;

fn key(p: DVec3) -> [u64; 3] {
    p.to_array().map(|x| if x == 0.0 { 0 } else { x.to_bits() })
}

/// Checks a full-dimensional hull and returns its vertex count.
fn check_polytope(points: &[DVec3]) -> usize {
    let hull = convex_hull(points).unwrap();
    let Hull3::Polytope { vertices, faces } = &hull else {
        panic!("expected a polytope, got {:?}", hull.dimension());
    };
    let inputs: HashSet<[u64; 3]> = points.iter().map(|p| key(*p)).collect();
    assert!(
        vertices.iter().all(|v| inputs.contains(&key(*v))),
        "hull vertex not an input point"
    );
    let distinct: HashSet<[u64; 3]> = vertices.iter().map(|p| key(*p)).collect();
    assert_eq!(distinct.len(), vertices.len(), "repeated hull vertex");
    for f in faces {
        let [a, b, c] = f.map(|i| vertices[i as usize]);
        for p in points {
            assert!(orient3d(a, b, c, *p) <= 0, "point {p:?} outside face {f:?}");
        }
    }
    let mesh: TriMesh = hull.to_mesh().unwrap().unwrap();
    let t = mesh.topology();
    assert!(t.is_closed_oriented_manifold(), "{t:?}");
    assert_eq!(t.components, 1);
    assert!(mesh.report().degenerate.is_empty(), "degenerate hull face");
    assert!(mesh.report().duplicates.is_empty());
    let chi = mesh.vertex_count() as i64 - t.edges as i64 + mesh.triangle_count() as i64;
    assert_eq!(chi, 2);
    // The rounded volume is only meaningful for a hull that is not nearly flat.
    let ext = mesh.aabb().max - mesh.aabb().min;
    let scale = ext.max_element().powi(3);
    assert!(
        mesh.signed_volume() >= -1e-9 * scale,
        "{}",
        mesh.signed_volume()
    );
    assert_eq!(mesh.report().unreferenced_vertices, 0);
    vertices.len()
}

#[test]
fn random_clouds() {
    let mut rng = StdRng::seed_from_u64(1);
    for n in [4usize, 5, 10, 100, 1000] {
        for _ in 0..5 {
            let pts: Vec<DVec3> = (0..n)
                .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - 1.0)
                .collect();
            check_polytope(&pts);
        }
    }
}

#[test]
fn points_on_a_sphere_are_all_vertices() {
    let mut rng = StdRng::seed_from_u64(2);
    let pts: Vec<DVec3> = (0..1500)
        .map(|_| {
            loop {
                let p = DVec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - 1.0;
                if p.length_squared() > 0.01 && p.length_squared() <= 1.0 {
                    break p.normalize() * 3.0;
                }
            }
        })
        .collect();
    // Rounded onto the sphere: (almost) all strictly convex; at least most are vertices.
    let v = check_polytope(&pts);
    assert!(v > 1400, "{v}");
}

#[test]
fn integer_points_on_a_sphere() {
    // x² + y² + z² = 25² exactly: exactly cospherical, with many coplanar quadruples.
    let mut pts = Vec::new();
    for x in -25i32..=25 {
        for y in -25i32..=25 {
            let r = 625 - x * x - y * y;
            if r < 0 {
                continue;
            }
            let z = (r as f64).sqrt();
            if z.fract() == 0.0 {
                pts.push(DVec3::new(x as f64, y as f64, z));
                pts.push(DVec3::new(x as f64, y as f64, -z));
            }
        }
    }
    let v = check_polytope(&pts);
    let distinct: HashSet<[u64; 3]> = pts.iter().map(|p| key(*p)).collect();
    // Every point of a sphere is extreme.
    assert_eq!(v, distinct.len());
}

#[test]
fn grids_and_repeated_cube_corners() {
    let mut pts = Vec::new();
    for i in 0..6 {
        for j in 0..6 {
            for k in 0..6 {
                pts.push(DVec3::new(i as f64, j as f64, k as f64) * 0.1);
            }
        }
    }
    check_polytope(&pts);
    // Corners of a cube, each repeated, with -0.0 and 0.0 mixed.
    let mut corners = Vec::new();
    for rep in 0..5 {
        for c in 0..8 {
            let z = if rep % 2 == 0 { 0.0 } else { -0.0 };
            corners.push(DVec3::new(
                if c & 1 == 0 { z } else { 1.0 },
                if c & 2 == 0 { z } else { 1.0 },
                if c & 4 == 0 { z } else { 1.0 },
            ));
        }
    }
    assert_eq!(check_polytope(&corners), 8);
    let Hull3::Polytope { faces, .. } = convex_hull(&corners).unwrap() else {
        unreachable!()
    };
    assert_eq!(faces.len(), 12);
    // Rotated and offset far away: still 8 vertices (exact predicates on rounded corners; the
    // rounded points need not stay coplanar, so only check the invariants).
    let pose = Pose::new(
        DVec3::new(1e8, -3e7, 12.5),
        DQuat::from_euler(glam::EulerRot::XYZ, 0.3, 0.2, 0.1),
    );
    let moved: Vec<DVec3> = corners.iter().map(|p| pose.transform_point(*p)).collect();
    assert_eq!(check_polytope(&moved), 8);
}

#[test]
fn near_coplanar_and_tiny() {
    let mut rng = StdRng::seed_from_u64(3);
    // A plane rotated off the axes, points jittered by 1e-12 off it; rounding makes the set
    // only nearly coplanar, which the exact predicates decide.
    let q = DQuat::from_euler(glam::EulerRot::XYZ, 0.7, -0.4, 1.3);
    for jitter in [0.0, 1e-15, 1e-12] {
        let pts: Vec<DVec3> = (0..400)
            .map(|_| {
                let p = DVec3::new(
                    rng.random::<f64>() * 2.0 - 1.0,
                    rng.random::<f64>() * 2.0 - 1.0,
                    0.0,
                );
                q * (p + DVec3::Z * jitter * (rng.random::<f64>() - 0.5))
                    + DVec3::new(1e3, 0.0, 0.0)
            })
            .collect();
        match convex_hull(&pts).unwrap() {
            Hull3::Polytope { .. } => {
                check_polytope(&pts);
            }
            Hull3::Polygon { .. } => {}
            other => panic!("{:?}", other.dimension()),
        }
    }
    // Tiny and subnormal coordinates.
    let tiny: Vec<DVec3> = (0..200)
        .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()) * 1e-310)
        .collect();
    check_polytope(&tiny);
}

#[test]
fn flat_inputs() {
    // Coplanar grid in a tilted plane with integer coordinates: exactly coplanar.
    let mut pts = Vec::new();
    for i in 0..7 {
        for j in 0..5 {
            let (a, b) = (i as f64, j as f64);
            pts.push(DVec3::new(a, b, a + 2.0 * b)); // plane z = x + 2y
        }
    }
    pts.push(pts[3]);
    let Hull3::Polygon { vertices, normal } = convex_hull(&pts).unwrap() else {
        panic!()
    };
    assert_eq!(vertices.len(), 4);
    // Every point inside or on every edge, in the projection along the normal's largest axis.
    let k = (0..3)
        .max_by(|&a, &b| normal[a].abs().total_cmp(&normal[b].abs()))
        .unwrap();
    let proj = |p: DVec3| match k {
        0 => DVec2::new(p.y, p.z),
        1 => DVec2::new(p.z, p.x),
        _ => DVec2::new(p.x, p.y),
    };
    assert!(normal[k] > 0.0);
    for i in 0..vertices.len() {
        let (a, b) = (proj(vertices[i]), proj(vertices[(i + 1) % vertices.len()]));
        for p in &pts {
            assert!(orient2d(a, b, proj(*p)) >= 0);
        }
        // No collinear consecutive vertices.
        let c = proj(vertices[(i + 2) % vertices.len()]);
        assert!(orient2d(a, b, c) > 0);
    }
    assert_eq!(
        convex_hull(&[DVec3::ONE; 3]).unwrap(),
        Hull3::Point(DVec3::ONE)
    );
    let seg: Vec<DVec3> = (0..5)
        .map(|i| DVec3::new(3.0 - i as f64, 0.0, 1.0))
        .collect();
    assert_eq!(convex_hull(&seg).unwrap(), Hull3::Segment(seg[4], seg[0]));
    assert_eq!(convex_hull(&[]).unwrap(), Hull3::Empty);
    assert!(matches!(
        convex_hull(&[DVec3::ZERO, DVec3::new(0.0, f64::INFINITY, 0.0)]),
        Err(HullError::NonFinitePoint { index: 1, .. })
    ));
}

#[test]
fn deterministic() {
    let mut rng = StdRng::seed_from_u64(4);
    let pts: Vec<DVec3> = (0..300)
        .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()))
        .collect();
    assert_eq!(convex_hull(&pts).unwrap(), convex_hull(&pts).unwrap());
}

/// Brute-force oracle for points in general position (no four exactly coplanar): the hull's
/// faces are exactly the triples with every other point strictly below them.
#[test]
fn matches_brute_force_on_small_sets() {
    let mut rng = StdRng::seed_from_u64(5);
    let mut checked = 0;
    for round in 0..60 {
        let n = 4 + round % 20;
        let pts: Vec<DVec3> = (0..n)
            .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()))
            .collect();
        let mut general = true;
        let mut brute: HashSet<[u64; 9]> = HashSet::new();
        let canon = |t: [DVec3; 3]| {
            // Rotate so the lexicographically smallest key comes first (keeps orientation).
            let keys = t.map(key);
            let m = (0..3).min_by_key(|&i| keys[i]).unwrap();
            let r = [keys[m], keys[(m + 1) % 3], keys[(m + 2) % 3]];
            [
                r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2],
            ]
        };
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    if i == j || j == k || i == k {
                        continue;
                    }
                    let signs: Vec<i8> = (0..n)
                        .filter(|&l| l != i && l != j && l != k)
                        .map(|l| orient3d(pts[i], pts[j], pts[k], pts[l]))
                        .collect();
                    if signs.contains(&0) {
                        general = false;
                    }
                    if signs.iter().all(|&s| s < 0) {
                        brute.insert(canon([pts[i], pts[j], pts[k]]));
                    }
                }
            }
        }
        if !general {
            continue;
        }
        let Hull3::Polytope { vertices, faces } = convex_hull(&pts).unwrap() else {
            panic!()
        };
        let ours: HashSet<[u64; 9]> = faces
            .iter()
            .map(|f| canon(f.map(|i| vertices[i as usize])))
            .collect();
        assert_eq!(ours.len(), faces.len());
        assert_eq!(ours, brute, "n = {n}");
        checked += 1;
    }
    assert!(checked > 50);
}

mod degenerate_props {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        /// Small integer coordinates: duplicates, collinear and coplanar subsets everywhere.
        #[test]
        fn integer_lattice_sets(raw in prop::collection::vec((0i32..4, 0i32..4, 0i32..3), 1..40),
                                flat in 0usize..4) {
            let pts: Vec<DVec3> = raw
                .iter()
                .map(|&(x, y, z)| match flat {
                    // Force lower-dimensional sets some of the time.
                    0 => DVec3::new(x as f64, y as f64, 0.0),
                    1 => DVec3::new(x as f64, 2.0 * x as f64, -(x as f64)),
                    _ => DVec3::new(x as f64, y as f64, z as f64),
                })
                .collect();
            match convex_hull(&pts).unwrap() {
                Hull3::Polytope { .. } => {
                    check_polytope(&pts);
                }
                Hull3::Polygon { vertices, normal } => {
                    // All points coplanar with the polygon, inside or on every edge.
                    let (a, b, c) = (vertices[0], vertices[1], vertices[2]);
                    let k = (0..3).max_by(|&i, &j| normal[i].abs().total_cmp(&normal[j].abs())).unwrap();
                    let proj = |p: DVec3| match k {
                        0 => DVec2::new(p.y, p.z),
                        1 => DVec2::new(p.z, p.x),
                        _ => DVec2::new(p.x, p.y),
                    };
                    for p in &pts {
                        prop_assert_eq!(orient3d(a, b, c, *p), 0);
                        for i in 0..vertices.len() {
                            let (u, w) = (vertices[i], vertices[(i + 1) % vertices.len()]);
                            // Counter-clockwise around `normal`: in a projection the sign
                            // follows the normal's component there.
                            let o = orient2d(proj(u), proj(w), proj(*p)) as f64 * normal[k].signum();
                            prop_assert!(o >= 0.0);
                        }
                    }
                }
                Hull3::Segment(a, b) => {
                    prop_assert!(a != b);
                    for p in &pts {
                        prop_assert!(frcd_geom::predicates::collinear3(a, b, *p));
                        // Between the ends.
                        prop_assert!((*p - a).dot(b - a) >= 0.0 && (*p - b).dot(a - b) >= 0.0);
                    }
                }
                Hull3::Point(p) => prop_assert!(pts.iter().all(|q| *q == p)),
                Hull3::Empty => prop_assert!(pts.is_empty()),
            }
        }
    }
}
