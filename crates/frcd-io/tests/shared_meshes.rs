//! Every mesh of ../shared/meshes loads with the counts and closedness its README states.
//! Prints SKIP when the folder is absent.

use frcd_io::{LoadOptions, load_mesh, load_mesh_with};
use std::path::PathBuf;

fn shared() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/meshes");
    if dir.join("README.md").exists() {
        Some(dir)
    } else {
        eprintln!("SKIP: {} not found", dir.display());
        None
    }
}

/// (file, triangles, closed, connected components), from the README's table.
///
/// "closed" here is the topology (every edge twice, consistently oriented, single fans). The
/// README also counts "no degenerate faces" in it, but intermodal_bogie_binary.stl has 4
/// triangles whose three f32 corners are exactly collinear (checked below), so that part of
/// its claim does not hold.
const TABLE: &[(&str, usize, bool, usize)] = &[
    ("railway_3dprintedtrains/bogie.stl", 5_268, true, 1),
    (
        "railway_3dprintedtrains/intermodal_bogie_binary.stl",
        59_444,
        true,
        5,
    ),
    (
        "railway_3dprintedtrains/intermodal_wagon_no_visible_container_holes_binary.stl",
        18_824,
        true,
        1,
    ),
    ("railway_3dprintedtrains/buffer_modern.stl", 1_804, true, 1),
    ("mechanical_trimesh/counter.unitsmm.STL", 83_750, true, 6),
    ("mechanical_trimesh/ADIS16480.STL", 7_436, true, 1),
    ("mechanical_trimesh/1002_tray_bottom.STL", 4_520, true, 1),
    ("mechanical_trimesh/fandisk.obj", 5_750, true, 1),
    ("mechanical_trimesh/quadknot.obj", 2_880, true, 1),
    ("mechanical_trimesh/featuretype.STL", 3_476, false, 1),
    ("classic/spot.obj", 5_856, true, 1),
];

#[test]
fn every_shared_mesh_matches_the_readme() {
    let Some(dir) = shared() else { return };
    for &(file, tris, closed, cc) in TABLE {
        let path = dir.join(file);
        if !path.exists() {
            eprintln!("SKIP: {file} absent");
            continue;
        }
        let mesh = load_mesh(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(mesh.triangle_count(), tris, "{file}");
        let topo = mesh.topology();
        assert_eq!(
            topo.is_closed_oriented_manifold(),
            closed,
            "{file}: {topo:?}"
        );
        let degenerate = mesh.report().degenerate.len();
        let expected = if file.contains("intermodal_bogie") {
            4
        } else {
            0
        };
        assert_eq!(degenerate, expected, "{file}: exactly collinear triangles");
        if closed {
            assert_eq!(topo.components, cc, "{file}");
            assert!(mesh.signed_volume() > 0.0, "{file}: normals point inward");
        }
    }
}

#[test]
fn featuretype_has_576_boundary_edges_under_exact_welding() {
    let Some(dir) = shared() else { return };
    let mesh = load_mesh(dir.join("mechanical_trimesh/featuretype.STL")).unwrap();
    assert_eq!(mesh.topology().boundary_edges, 576);
    // Tolerance welding closes more of it (trimesh's default merge closes it).
    let welded = load_mesh_with(
        dir.join("mechanical_trimesh/featuretype.STL"),
        &LoadOptions {
            weld_tolerance: 1e-5,
            ..LoadOptions::default()
        },
    )
    .unwrap();
    assert!(welded.topology().boundary_edges < 576);
}

#[test]
fn spot_is_split_at_seams_and_closes_after_position_weld() {
    let Some(dir) = shared() else { return };
    let path = dir.join("classic/spot.obj");
    // Raw tobj output, one index per (position, texcoord) pair: split at the UV seams.
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let (models, _) = tobj::load_obj(&path, &opts).unwrap();
    let m = &models[0].mesh;
    let v: Vec<frcd_geom::DVec3> = m
        .positions
        .chunks_exact(3)
        .map(|p| frcd_geom::DVec3::new(p[0], p[1], p[2]))
        .collect();
    let idx: Vec<[u32; 3]> = m
        .indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    let raw = frcd_geom::TriMesh::new(v, idx).unwrap();
    assert!(
        !raw.topology().is_closed(),
        "raw spot should be open at its seams"
    );
    let mesh = load_mesh(&path).unwrap();
    assert!(mesh.vertex_count() < raw.vertex_count());
    assert!(mesh.topology().is_closed_oriented_manifold());
}
