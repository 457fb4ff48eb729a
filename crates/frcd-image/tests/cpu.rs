//! CPU-only tests: input rules, the no-adapter error, the view.

use frcd_geom::{Aabb, DQuat, DVec3, Pose, TriMesh, shapes};
use frcd_image::{ImageError, View, ViewAxis, check_solid};

#[test]
fn open_non_manifold_and_misoriented_meshes_are_refused() {
    let cube = shapes::cuboid(DVec3::ONE);
    assert!(check_solid("cube", &cube).is_ok());
    let open = TriMesh::new(cube.vertices().to_vec(), cube.indices()[1..].to_vec()).unwrap();
    match check_solid("open", &open) {
        Err(ImageError::NotSolid { name, topology }) => {
            assert_eq!(name, "open");
            assert_eq!(topology.boundary_edges, 3);
        }
        other => panic!("{other:?}"),
    }
    let mut flipped = cube.indices().to_vec();
    flipped[0].swap(1, 2);
    let flipped = TriMesh::new(cube.vertices().to_vec(), flipped).unwrap();
    match check_solid("flipped", &flipped) {
        Err(ImageError::NotSolid { topology, .. }) => assert!(topology.orientation_conflicts > 0),
        other => panic!("{other:?}"),
    }
    // Two cubes sharing one edge's vertices: non-manifold.
    let mut v = cube.vertices().to_vec();
    let mut idx = cube.indices().to_vec();
    let off = v.len() as u32;
    v.extend(
        cube.vertices()
            .iter()
            .map(|p| *p + DVec3::new(2.0, 2.0, 0.0)),
    );
    idx.extend(cube.indices().iter().map(|t| t.map(|i| i + off)));
    // Weld the +x+y edge of the first with the -x-y edge of the second.
    let welded = TriMesh::new(v, idx).unwrap().welded(0.0);
    match check_solid("pair", &welded) {
        Err(ImageError::NotSolid { topology, .. }) => assert!(!topology.is_manifold()),
        other => panic!("{other:?}"),
    }
}

#[test]
fn no_backend_means_no_adapter_error() {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = wgpu::Backends::empty();
    match frcd_image::ImageContext::headless_with(desc) {
        Err(ImageError::NoAdapter(msg)) => println!("no adapter: {msg}"),
        other => panic!("expected NoAdapter, got {other:?}"),
    }
}

#[test]
fn view_looks_along_the_thinnest_overlap_and_maps_pixels() {
    let a = Aabb::new(DVec3::splat(-1.0), DVec3::splat(1.0));
    let b_local = Aabb::new(DVec3::splat(-1.0), DVec3::splat(1.0));
    let rel = Pose::from_translation(DVec3::new(0.5, 0.2, 1.9));
    let (region, b_box) = View::overlap(&a, &b_local, &rel).unwrap();
    let view = View::new(region, &a, &b_box, ViewAxis::Auto, 100);
    assert_eq!(view.axis, 2);
    // Lateral extents 1.5 (x) and 1.8 (y): pixel = 1.8 / 100, 84 × 100 pixels.
    assert!((view.pixel_size - 0.018).abs() < 1e-15);
    assert_eq!((view.width, view.height), (84, 100));
    // Depth range starts in front of both boxes.
    assert!(view.near < -1.0 && view.far > 1.0);
    // Pixel (0, 0) is top-left: smallest u, largest v.
    let (u, v) = view.pixel_center(0, 0);
    assert!(u < region.min.x + view.pixel_size && v > region.max.y - view.pixel_size);
    // The matrix maps the region's corners inside the clip volume.
    let m = view.clip_from_local(&Pose::IDENTITY, DVec3::ZERO);
    for p in [region.min, region.max] {
        let c: Vec<f64> = (0..3)
            .map(|i| (0..3).map(|j| m[j][i] as f64 * p[j]).sum::<f64>() + m[3][i] as f64)
            .collect();
        assert!(c[0].abs() <= 1.0 + 1e-6 && c[1].abs() <= 1.0 + 1e-6);
        assert!(c[2] > 0.0 && c[2] < 1.0);
    }
    // Disjoint boxes: no region.
    assert!(View::overlap(&a, &b_local, &Pose::from_translation(DVec3::X * 2.5)).is_none());
    // Rotated B: its mapped box is the box of the rotated corners.
    let rot = Pose::new(
        DVec3::ZERO,
        DQuat::from_rotation_z(std::f64::consts::FRAC_PI_4),
    );
    let (_, bb) = View::overlap(&a, &b_local, &rot).unwrap();
    assert!((bb.max.x - 2f64.sqrt()).abs() < 1e-12);
}
