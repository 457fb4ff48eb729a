//! Meshes at subnormal scale: rounding there is absolute, not relative, so the trees' slack has
//! an absolute floor. Found by the `mesh_tree` fuzz target (fuzz/regressions/mesh_tree).

use frcd_geom::{DVec3, Pose, TriMesh};
use frcd_obb::{BuildOptions, Mode, ObbTree, Request, collide, oracle};

fn scaled(mesh: &TriMesh, s: f64, offset: DVec3) -> TriMesh {
    let v: Vec<DVec3> = mesh.vertices().iter().map(|&p| p * s + offset).collect();
    TriMesh::new(v, mesh.indices().to_vec()).expect("valid mesh")
}

#[test]
fn subnormal_meshes_equal_the_oracle() {
    let base = frcd_geom::shapes::icosphere(1.0, 1);
    let request = Request {
        mode: Mode::AllPairs,
        ..Request::default()
    };
    // 2^-1040 .. 2^-1070: coordinates deep in the subnormal range (few significant bits).
    for e in [1040, 1055, 1065, 1070] {
        let s = 2f64.powi(-e);
        for leaf in [1, 4] {
            let options = BuildOptions {
                max_leaf_triangles: leaf,
                ..BuildOptions::default()
            };
            let a = scaled(&base, s, DVec3::ZERO);
            let b = scaled(&base, s, DVec3::new(1.5 * s, 0.25 * s, 0.0));
            let (ta, tb) = (ObbTree::build(&a, &options), ObbTree::build(&b, &options));
            for (m, tm, n, tn) in [(&a, &ta, &a, &ta), (&a, &ta, &b, &tb)] {
                let got = collide(tm, &Pose::IDENTITY, tn, &Pose::IDENTITY, &request);
                let want = oracle::pairs(m, &Pose::IDENTITY, n, &Pose::IDENTITY);
                assert_eq!(got.pairs, want, "scale 2^-{e}, leaf {leaf}");
            }
        }
    }
}

/// The fuzz reproducer `fuzz/regressions/mesh_tree/subnormal_points`, decoded as the
/// `mesh_tree` target decodes its input: the tree's self-collision must equal the oracle's.
#[test]
fn fuzz_reproducer_subnormal_points() {
    const DATA: &[u8] = &[
        254, 0, 1, 0, 16, 104, 0, 0, 0, 0, 4, 0, 0, 0, 3, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 7,
        0, 0, 0, 0, 0, 0, 0, 0, 0, 254, 0, 0, 0, 0, 0, 213, 254, 255, 9, 0, 0, 0, 0, 0, 0, 64, 0,
        0, 249, 247, 0, 0, 0, 0, 0, 5, 126, 0, 0, 0, 64, 0, 0, 0, 64, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
        204, 204, 204, 3, 0, 204, 4, 204, 204,
    ];
    let (head, rest) = DATA.split_at(2);
    let nv = (head[0] % 12) as usize;
    let leaf = 1 + (head[1] % 4) as u32;
    let fit = [
        frcd_obb::FitMethod::VertexCovariance,
        frcd_obb::FitMethod::AreaWeighted,
        frcd_obb::FitMethod::HullSurface,
    ][(head[1] / 4 % 3) as usize];
    let mut words = rest
        .chunks_exact(8)
        .map(|c| u64::from_le_bytes(c.try_into().unwrap()));
    let mut vertices = Vec::new();
    for _ in 0..nv {
        let mut c = [0.0; 3];
        for x in &mut c {
            *x = f64::from_bits(words.next().unwrap_or(0));
        }
        vertices.push(DVec3::from_array(c));
    }
    let mut indices = Vec::new();
    for w in words {
        let m = nv as u32 + 1;
        let idx = |s: u32| ((w >> s) as u32 & 0xFF) % m.max(1);
        indices.push([idx(0), idx(8), idx(16)]);
        if indices.len() >= 24 {
            break;
        }
    }
    let mesh = TriMesh::new(vertices, indices).expect("the reproducer is a valid mesh");
    let tree = ObbTree::build(
        &mesh,
        &BuildOptions {
            fit,
            max_leaf_triangles: leaf,
            ..BuildOptions::default()
        },
    );
    let request = Request {
        mode: Mode::AllPairs,
        ..Request::default()
    };
    let got = collide(&tree, &Pose::IDENTITY, &tree, &Pose::IDENTITY, &request);
    let want = oracle::pairs(&mesh, &Pose::IDENTITY, &mesh, &Pose::IDENTITY);
    assert!(!want.is_empty());
    assert_eq!(got.pairs, want);
}
