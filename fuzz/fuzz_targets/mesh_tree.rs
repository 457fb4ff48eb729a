//! `TriMesh::new` on raw vertices and indices (NaN, infinities, huge and subnormal coordinates,
//! out-of-range indices), then `ObbTree::build` on every mesh it accepts; the tree's
//! self-collision must equal the exact oracle's pairs.
#![no_main]
use frcd_geom::{DVec3, Pose, TriMesh};
use frcd_obb::{BuildOptions, FitMethod, Mode, ObbTree, Request, collide, oracle};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    let (head, rest) = data.split_at(2);
    let nv = (head[0] % 12) as usize;
    let leaf = 1 + (head[1] % 4) as u32;
    let fit = [
        FitMethod::VertexCovariance,
        FitMethod::AreaWeighted,
        FitMethod::HullSurface,
    ][(head[1] / 4 % 3) as usize];
    let mut words = rest
        .chunks_exact(8)
        .map(|c| u64::from_le_bytes(c.try_into().unwrap()));
    let mut vertices = Vec::with_capacity(nv);
    for _ in 0..nv {
        let mut c = [0.0; 3];
        for x in &mut c {
            *x = f64::from_bits(words.next().unwrap_or(0));
        }
        vertices.push(DVec3::from_array(c));
    }
    let mut indices = Vec::new();
    while let Some(w) = words.next() {
        // Mostly in range, sometimes not.
        let m = nv as u32 + 1;
        let idx = |s: u32| ((w >> s) as u32 & 0xFF) % m.max(1);
        indices.push([idx(0), idx(8), idx(16)]);
        if indices.len() >= 24 {
            break;
        }
    }
    let Ok(mesh) = TriMesh::new(vertices, indices) else {
        return;
    };
    let _ = mesh.topology();
    let options = BuildOptions {
        fit,
        max_leaf_triangles: leaf,
    };
    let tree = ObbTree::build(&mesh, &options);
    let request = Request {
        mode: Mode::AllPairs,
        ..Request::default()
    };
    let got = collide(&tree, &Pose::IDENTITY, &tree, &Pose::IDENTITY, &request);
    let want = oracle::pairs(&mesh, &Pose::IDENTITY, &mesh, &Pose::IDENTITY);
    assert_eq!(got.pairs, want, "self-collision differs from the oracle");
});
