//! OBJ reader (one mesh and per-object): any bytes give meshes or a typed error.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("fuzz.obj");
    let one = frcd_io::parse_obj(data, path);
    let per_object = frcd_io::parse_obj_objects(data, path);
    if let Ok(mesh) = &one {
        assert!(mesh.vertices().iter().all(|v| v.is_finite()));
        let n = mesh.vertex_count() as u32;
        assert!(mesh.indices().iter().flatten().all(|&i| i < n));
    }
    // Both readers see the same faces: when the per-object reader succeeds, so does the
    // merged one, with as many triangles in total.
    if let Ok(objects) = &per_object {
        let total: usize = objects.iter().map(|o| o.mesh.triangle_count()).sum();
        let merged = one
            .as_ref()
            .expect("per-object read succeeded, merged read failed");
        assert_eq!(merged.triangle_count(), total);
    }
});
