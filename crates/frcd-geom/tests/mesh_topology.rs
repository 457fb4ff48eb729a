//! TriMesh validation, reports, welding and topology.

use frcd_geom::{DVec3, MeshError, Pose, TriMesh, shapes};

fn cube_soup(offset: DVec3) -> Vec<[DVec3; 3]> {
    shapes::cuboid(DVec3::ONE)
        .triangles()
        .map(|t| t.v.map(|p| p + offset))
        .collect()
}

#[test]
fn empty_meshes_are_refused() {
    assert_eq!(
        TriMesh::new(vec![], vec![[0, 1, 2]]).unwrap_err(),
        MeshError::Empty {
            vertices: 0,
            triangles: 1
        }
    );
    assert_eq!(
        TriMesh::new(vec![DVec3::ZERO; 3], vec![]).unwrap_err(),
        MeshError::Empty {
            vertices: 3,
            triangles: 0
        }
    );
    assert!(matches!(
        TriMesh::from_triangle_soup(&[]),
        Err(MeshError::Empty { .. })
    ));
}

#[test]
fn non_finite_vertices_are_named() {
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut v = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z];
        v[2].z = bad;
        let e = TriMesh::new(v, vec![[0, 1, 3]]).unwrap_err();
        assert!(
            matches!(e, MeshError::NonFiniteVertex { vertex: 2, .. }),
            "{e:?}"
        );
        assert!(e.to_string().contains("vertex 2"), "{e}");
    }
    // In a soup, the position in the soup: triangle 1, corner 2 -> 5.
    let mut soup = cube_soup(DVec3::ZERO);
    soup[1][2].x = f64::NAN;
    assert!(matches!(
        TriMesh::from_triangle_soup(&soup),
        Err(MeshError::NonFiniteVertex { vertex: 5, .. })
    ));
    // A non-finite pose is refused by try_transformed.
    let m = shapes::cuboid(DVec3::ONE);
    let bad = Pose {
        translation: DVec3::new(f64::NAN, 0.0, 0.0),
        ..Pose::IDENTITY
    };
    assert!(matches!(
        m.try_transformed(&bad),
        Err(MeshError::NonFiniteVertex { vertex: 0, .. })
    ));
}

#[test]
fn out_of_range_indices_name_triangle_and_corner() {
    let v = vec![DVec3::ZERO, DVec3::X, DVec3::Y];
    let e = TriMesh::new(v, vec![[0, 1, 2], [2, 7, 0]]).unwrap_err();
    assert_eq!(
        e,
        MeshError::IndexOutOfRange {
            triangle: 1,
            corner: 1,
            index: 7,
            vertex_count: 3
        }
    );
    let msg = e.to_string();
    assert!(
        msg.contains("triangle 1") && msg.contains("corner 1") && msg.contains("7"),
        "{msg}"
    );
    assert!(matches!(
        TriMesh::new(vec![DVec3::ZERO; 3], vec![[0, 1, u32::MAX]]),
        Err(MeshError::IndexOutOfRange {
            triangle: 0,
            corner: 2,
            index: u32::MAX,
            ..
        })
    ));
}

#[test]
fn degenerate_duplicate_and_unreferenced_are_reported() {
    let v = vec![
        DVec3::ZERO,
        DVec3::X,
        DVec3::Y,
        DVec3::new(2.0, 0.0, 0.0), // collinear with 0 and 1
        DVec3::Z,                  // unreferenced
        DVec3::new(1e-300, 0.0, 0.0),
        DVec3::new(0.0, 1e-300, 0.0),
    ];
    let tris = vec![
        [0, 1, 2],
        [0, 1, 3], // collinear: zero area
        [2, 1, 0], // same vertices as 0, reversed
        [1, 1, 2], // repeated index
        [1, 2, 0], // same as 0, rotated
        [0, 5, 6], // tiny but not degenerate (exact predicate)
    ];
    let m = TriMesh::new(v, tris).unwrap();
    let r = m.report();
    assert_eq!(r.degenerate, vec![1, 3]);
    assert_eq!(r.duplicates, vec![(0, 2), (0, 4)]);
    assert_eq!(r.unreferenced_vertices, 1);
    assert!(!r.is_clean());
    assert!(shapes::cuboid(DVec3::ONE).report().is_clean());
    assert_eq!(m.topology().index_degenerate, 1);
}

#[test]
fn exact_welding() {
    let m = TriMesh::from_triangle_soup(&cube_soup(DVec3::ZERO)).unwrap();
    assert_eq!(m.vertex_count(), 8);
    assert!(m.topology().is_closed_oriented_manifold());
    // -0.0 and 0.0 are one point.
    let a = [DVec3::new(-0.0, 0.0, 0.0), DVec3::X, DVec3::Y];
    let b = [DVec3::new(0.0, -0.0, 0.0), DVec3::Y, DVec3::Z];
    assert_eq!(
        TriMesh::from_triangle_soup(&[a, b]).unwrap().vertex_count(),
        4
    );
    // welded(0) on an unwelded mesh, plus dropping unreferenced vertices.
    let raw: Vec<DVec3> = cube_soup(DVec3::ZERO)
        .into_iter()
        .flatten()
        .chain([DVec3::splat(9.0)])
        .collect();
    let idx: Vec<[u32; 3]> = (0..12u32).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect();
    let m = TriMesh::new(raw, idx).unwrap();
    assert!(!m.topology().is_closed());
    assert_eq!(m.report().unreferenced_vertices, 1);
    let w = m.welded(0.0);
    assert_eq!(w.vertex_count(), 8);
    assert!(w.topology().is_closed_oriented_manifold());
    assert!(w.report().is_clean());
    assert!((w.signed_volume() - 8.0).abs() < 1e-12);
}

#[test]
fn tolerance_welding() {
    // Each soup corner nudged by up to 1e-7: exact welding leaves it open, tolerance closes it.
    let mut soup = cube_soup(DVec3::ZERO);
    for (t, tri) in soup.iter_mut().enumerate() {
        for (k, p) in tri.iter_mut().enumerate() {
            *p += DVec3::new(1.0, -1.0, 0.5) * 1e-7 * ((3 * t + k) % 5) as f64 / 5.0;
        }
    }
    let m = TriMesh::from_triangle_soup(&soup).unwrap();
    assert!(!m.topology().is_closed());
    let w = m.welded(1e-6);
    assert_eq!(w.vertex_count(), 8);
    assert!(w.topology().is_closed_oriented_manifold());
    // Too small a tolerance merges nothing new (and a tolerance so small that coordinates over
    // it overflow i64 grid keys must not panic).
    assert_eq!(m.welded(1e-12).vertex_count(), m.vertex_count());
    assert_eq!(m.welded(1e-300).vertex_count(), m.vertex_count());
    assert_eq!(
        m.welded(f64::MIN_POSITIVE / 4.0).vertex_count(),
        m.vertex_count()
    );
    // Far from the origin (1e12 m offset, 1 mm tolerance): still found.
    let far = TriMesh::from_triangle_soup(&cube_soup(DVec3::new(1e12, -3e11, 7e10))).unwrap();
    let nudged: Vec<[DVec3; 3]> = far
        .triangles()
        .enumerate()
        .map(|(t, tri)| {
            tri.v.map(|p| {
                if t % 2 == 0 {
                    p + DVec3::new(2e-4, 0.0, 0.0)
                } else {
                    p
                }
            })
        })
        .collect();
    let nm = TriMesh::from_triangle_soup(&nudged).unwrap();
    assert!(nm.vertex_count() > 8);
    assert_eq!(nm.welded(1e-3).vertex_count(), 8);
}

#[test]
fn tolerance_welding_is_transitive_and_inclusive() {
    let v = vec![
        DVec3::ZERO,
        DVec3::new(0.75, 0.0, 0.0),
        DVec3::new(1.5, 0.0, 0.0), // 1.5 from the first, but chained through the second
        DVec3::new(0.0, 5.0, 0.0),
        DVec3::new(0.0, 6.0, 0.0), // exactly 1.0 away: merged (distance <= tolerance)
        DVec3::new(0.0, 9.0, 0.0),
    ];
    let m = TriMesh::new(v, vec![[0, 1, 3], [2, 4, 5]]).unwrap();
    let w = m.welded(1.0);
    assert_eq!(w.vertex_count(), 3);
    assert_eq!(w.vertices()[0], DVec3::ZERO); // the lowest index's position
    let w = m.welded(0.7);
    assert_eq!(w.vertex_count(), 6);
    // Infinite tolerance: everything is one vertex, every triangle degenerate (reported).
    let w = m.welded(f64::INFINITY);
    assert_eq!(w.vertex_count(), 1);
    assert_eq!(w.report().degenerate.len(), 2);
}

#[test]
fn topology_of_open_meshes() {
    let tri = TriMesh::new(vec![DVec3::ZERO, DVec3::X, DVec3::Y], vec![[0, 1, 2]]).unwrap();
    let t = tri.topology();
    assert_eq!((t.edges, t.boundary_edges, t.components), (3, 3, 1));
    assert!(!t.is_closed() && t.is_manifold() && t.is_oriented());
    // A cube with one triangle removed: a disk with a 3-edge boundary.
    let c = shapes::cuboid(DVec3::ONE);
    let open = TriMesh::new(c.vertices().to_vec(), c.indices()[1..].to_vec()).unwrap();
    let t = open.topology();
    assert_eq!(t.boundary_edges, 3);
    assert!(!t.is_closed() && t.is_manifold() && t.is_oriented());
    assert!(!t.is_closed_oriented_manifold());
}

#[test]
fn non_manifold_edge() {
    // Three triangles on one edge (0, 1).
    let v = vec![
        DVec3::ZERO,
        DVec3::X,
        DVec3::Y,
        DVec3::Z,
        DVec3::new(0.0, -1.0, 0.0),
    ];
    let m = TriMesh::new(v, vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]]).unwrap();
    let t = m.topology();
    assert_eq!(t.non_manifold_edges, 1);
    assert!(!t.is_manifold() && !t.is_closed());
    assert!(t.non_manifold_vertices >= 2); // both ends of the edge
    assert!(t.orientation_conflicts >= 1); // (0,1) occurs twice in the same direction
}

#[test]
fn non_manifold_vertex_two_cones_touching_at_the_tip() {
    // Two closed tetrahedra ("cones") sharing only their apex.
    let apex = DVec3::ZERO;
    let mut v = vec![apex];
    let base = |z: f64| {
        [
            DVec3::new(1.0, 0.0, z),
            DVec3::new(-0.5, 0.8, z),
            DVec3::new(-0.5, -0.8, z),
        ]
    };
    v.extend(base(1.0)); // 1, 2, 3 above
    v.extend(base(-1.0)); // 4, 5, 6 below
    let up = [[0, 2, 1], [0, 3, 2], [0, 1, 3], [1, 2, 3]];
    let down = [[0, 4, 5], [0, 5, 6], [0, 6, 4], [4, 6, 5]];
    let m = TriMesh::new(v, up.iter().chain(down.iter()).copied().collect()).unwrap();
    let t = m.topology();
    assert!(t.is_closed() && t.is_oriented());
    assert_eq!(t.non_manifold_edges, 0);
    assert_eq!(t.non_manifold_vertices, 1);
    assert!(!t.is_manifold() && !t.is_closed_oriented_manifold());
    assert_eq!(t.components, 1); // connected through the shared vertex
    assert!(m.signed_volume() > 0.0);
}

#[test]
fn inconsistent_orientation_and_components() {
    let c = shapes::cuboid(DVec3::ONE);
    let mut idx = c.indices().to_vec();
    idx[5].swap(1, 2);
    let m = TriMesh::new(c.vertices().to_vec(), idx).unwrap();
    let t = m.topology();
    assert!(t.is_closed() && t.is_manifold() && !t.is_oriented());
    assert_eq!(t.orientation_conflicts, 3); // each of the flipped triangle's edges
    // Everything flipped: consistent, but inside out.
    let flipped: Vec<[u32; 3]> = c.indices().iter().map(|&[a, b, c]| [a, c, b]).collect();
    let inv = TriMesh::new(c.vertices().to_vec(), flipped).unwrap();
    assert!(inv.topology().is_closed_oriented_manifold());
    assert!((inv.signed_volume() + 8.0).abs() < 1e-12);
    // Two disjoint cubes: two components.
    let two = shapes::merge(&[
        c.clone(),
        c.transformed(&Pose::from_translation(DVec3::splat(5.0))),
    ])
    .unwrap();
    assert_eq!(two.topology().components, 2);
    assert!(two.topology().is_closed_oriented_manifold());
    assert!((two.signed_volume() - 16.0).abs() < 1e-9);
}
