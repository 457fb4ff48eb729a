//! STL reader (ASCII and binary): any bytes give a mesh or a typed error, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(mesh) = frcd_io::parse_stl(data, "fuzz.stl".as_ref()) {
        // A loaded mesh is valid: every index in range, every coordinate finite.
        assert!(mesh.triangle_count() > 0);
        assert!(mesh.vertices().iter().all(|v| v.is_finite()));
        let n = mesh.vertex_count() as u32;
        assert!(mesh.indices().iter().flatten().all(|&i| i < n));
    }
});
