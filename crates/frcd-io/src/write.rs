//! Mesh writers.

use crate::{Error, Result};
use frcd_geom::TriMesh;
use std::fmt::Write as _;
use std::path::Path;

/// Writes a binary STL file atomically (see [`crate::write_atomic`]) (f32 coordinates: values are rounded to the nearest f32; vertices
/// that share an f64 position share the f32 one, so welding on load restores the topology).
pub fn write_stl_binary(path: impl AsRef<Path>, mesh: &TriMesh) -> Result<()> {
    let path = path.as_ref();
    let v = |p: frcd_geom::DVec3| stl_io::Vertex::new([p.x as f32, p.y as f32, p.z as f32]);
    let triangles: Vec<stl_io::Triangle> = mesh
        .triangles()
        .map(|t| {
            let n = t.normal().normalize_or_zero();
            stl_io::Triangle {
                normal: stl_io::Normal::new([n.x as f32, n.y as f32, n.z as f32]),
                vertices: t.v.map(v),
            }
        })
        .collect();
    let mut bytes = Vec::with_capacity(84 + 50 * triangles.len());
    stl_io::write_stl(&mut bytes, triangles.iter()).map_err(|e| Error::io(path, e))?;
    crate::write_atomic(path, &bytes)
}

/// Writes a Wavefront OBJ file atomically with one object named `name`. Coordinates are written in Rust's
/// shortest form that reads back to the same f64, so the file round-trips exactly.
pub fn write_obj(path: impl AsRef<Path>, mesh: &TriMesh, name: &str) -> Result<()> {
    let path = path.as_ref();
    let mut s = String::with_capacity(40 * (mesh.vertex_count() + mesh.triangle_count()));
    let _ = writeln!(
        s,
        "# frcd mesh: {} vertices, {} triangles\no {name}",
        mesh.vertex_count(),
        mesh.triangle_count()
    );
    for p in mesh.vertices() {
        let _ = writeln!(s, "v {} {} {}", p.x, p.y, p.z);
    }
    for [a, b, c] in mesh.indices() {
        let _ = writeln!(s, "f {} {} {}", a + 1, b + 1, c + 1);
    }
    crate::write_atomic(path, s.as_bytes())
}
