//! Triangle counts of the procedural shapes at their default parameters.
//!
//! `cargo run -p frcd-geom --example shape_counts`

use frcd_geom::{DVec3, TriMesh, shapes};

fn main() {
    let rows: Vec<(&str, TriMesh)> = vec![
        ("cuboid", shapes::cuboid(DVec3::ONE)),
        ("icosphere(level 3)", shapes::icosphere(1.0, 3)),
        ("uv_sphere(32, 16)", shapes::uv_sphere(1.0, 32, 16).unwrap()),
        (
            "cylinder(32, 1)",
            shapes::cylinder(1.0, 1.0, 32, 1).unwrap(),
        ),
        ("torus(48, 24)", shapes::torus(1.0, 0.3, 48, 24).unwrap()),
        (
            "torus_knot",
            shapes::torus_knot(&Default::default()).unwrap(),
        ),
        ("spur_gear", shapes::spur_gear(&Default::default()).unwrap()),
        (
            "coil_spring",
            shapes::coil_spring(&Default::default()).unwrap(),
        ),
        ("wheel", shapes::wheel(&Default::default()).unwrap()),
        ("wheelset", shapes::wheelset(&Default::default()).unwrap()),
        ("rail", shapes::rail(&Default::default()).unwrap()),
    ];
    println!(
        "{:<20} {:>9} {:>9} {:>12}",
        "shape", "triangles", "vertices", "volume m3"
    );
    for (name, m) in rows {
        println!(
            "{name:<20} {:>9} {:>9} {:>12.6}",
            m.triangle_count(),
            m.vertex_count(),
            m.signed_volume()
        );
    }
}
