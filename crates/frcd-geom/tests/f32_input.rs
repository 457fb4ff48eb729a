//! Meshes from an engine's borrowed f32 data: exact widening, the same validation and errors as
//! the f64 constructor, and no storage beyond the mesh's own.

use frcd_geom::{DVec3, MeshError, TriMesh, Vec3, shapes};
use rand::{Rng, SeedableRng, rngs::StdRng};

fn widen(v: &[[f32; 3]]) -> Vec<DVec3> {
    v.iter()
        .map(|p| DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64))
        .collect()
}

#[test]
fn f32_mesh_equals_the_f64_mesh_of_the_widened_points() {
    let mut rng = StdRng::seed_from_u64(13);
    for _ in 0..50 {
        let n = rng.random_range(3..40usize);
        let verts: Vec<[f32; 3]> = (0..n)
            .map(|_| {
                // Large offsets and fractions that f64 would round differently from f32.
                [(); 3].map(|_| rng.random_range(-1e5f32..1e5) + rng.random::<f32>() * 0.1)
            })
            .collect();
        let tris: Vec<[u32; 3]> = (0..rng.random_range(1..60usize))
            .map(|_| [(); 3].map(|_| rng.random_range(0..n as u32)))
            .collect();
        let from_arrays = TriMesh::from_f32(&verts, &tris).unwrap();
        let as_vec3: Vec<Vec3> = verts.iter().map(|p| Vec3::from_array(*p)).collect();
        let from_vec3 = TriMesh::from_f32(&as_vec3, &tris).unwrap();
        let reference = TriMesh::new(widen(&verts), tris.clone()).unwrap();
        for m in [&from_arrays, &from_vec3] {
            assert_eq!(m.vertices(), reference.vertices());
            assert_eq!(m.indices(), reference.indices());
            assert_eq!(m.report(), reference.report());
            assert_eq!(m.topology(), reference.topology());
            assert_eq!(m.aabb(), reference.aabb());
        }
        // Widening is exact: every coordinate converts back to the same f32.
        for (p, q) in verts.iter().zip(from_arrays.vertices()) {
            assert_eq!(*p, [q.x as f32, q.y as f32, q.z as f32]);
        }
    }
}

#[test]
fn f32_errors_name_the_same_element_as_the_f64_constructor() {
    let good: Vec<[f32; 3]> = vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        for vertex in 0..4 {
            for axis in 0..3 {
                let mut v = good.clone();
                v[vertex][axis] = bad;
                let tris = [[0, 1, 2], [1, 2, 3]];
                let e32 = TriMesh::from_f32(&v, &tris).unwrap_err();
                let e64 = TriMesh::new(widen(&v), tris.to_vec()).unwrap_err();
                match (&e32, &e64) {
                    (
                        MeshError::NonFiniteVertex {
                            vertex: a,
                            value: va,
                        },
                        MeshError::NonFiniteVertex { vertex: b, .. },
                    ) => {
                        assert_eq!((*a, *b), (vertex, vertex));
                        assert!(!va[axis].is_finite());
                    }
                    other => panic!("expected NonFiniteVertex, got {other:?}"),
                }
            }
        }
    }
    let e = TriMesh::from_f32(&good, &[[0, 1, 2], [3, 4, 0]]).unwrap_err();
    assert_eq!(
        e,
        MeshError::IndexOutOfRange {
            triangle: 1,
            corner: 1,
            index: 4,
            vertex_count: 4
        }
    );
    assert_eq!(
        TriMesh::from_f32(&good, &[]).unwrap_err(),
        MeshError::Empty {
            vertices: 4,
            triangles: 0
        }
    );
    let none: [Vec3; 0] = [];
    assert_eq!(
        TriMesh::from_f32(&none, &[[0, 1, 2]]).unwrap_err(),
        MeshError::Empty {
            vertices: 0,
            triangles: 1
        }
    );
}

#[test]
fn f32_mesh_holds_only_its_own_storage() {
    // One exact-size allocation per array: memory is the element sizes, nothing kept besides.
    let ball = shapes::icosphere(1.0, 3);
    let verts: Vec<[f32; 3]> = ball
        .vertices()
        .iter()
        .map(|p| p.as_vec3().to_array())
        .collect();
    let m = TriMesh::from_f32(&verts, ball.indices()).unwrap();
    let expected = std::mem::size_of::<TriMesh>() + verts.len() * 24 + ball.triangle_count() * 12;
    assert_eq!(m.memory_bytes(), expected);
    // A closed mesh has V = T/2 + 2: about 24 bytes per triangle.
    let per_tri = m.memory_bytes() as f64 / m.triangle_count() as f64;
    assert!((24.0..25.0).contains(&per_tri), "{per_tri} B per triangle");
}
