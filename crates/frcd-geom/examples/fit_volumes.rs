//! Mean OBB volume of each fitting rule on the procedural shapes.
//!
//! `cargo run -p frcd-geom --release --example fit_volumes`
//!
//! Two numbers per rule, relative to the vertex-covariance rule (PQP's default):
//! - *whole*: the box around the whole mesh, averaged over 16 random rotations;
//! - *tree*: the mean box volume over all nodes of a PQP-style top-down hierarchy (split at the
//!   mean of the centroids, perpendicular to the box's major axis, down to one triangle), i.e.
//!   what an OBB tree built with that rule would test against.

use frcd_geom::fit::{FitMethod, fit_obb};
use frcd_geom::{DQuat, DVec3, Pose, TriMesh, Triangle, shapes};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const METHODS: [FitMethod; 3] = [
    FitMethod::VertexCovariance,
    FitMethod::AreaWeighted,
    FitMethod::HullSurface,
];

/// Sum of node volumes and node count of a top-down hierarchy built with `method`.
fn tree_volume(tris: &mut [Triangle], method: FitMethod) -> (f64, usize) {
    let obb = fit_obb(tris, method);
    if tris.len() <= 1 {
        return (obb.volume(), 1);
    }
    let axis = obb.axes.x_axis;
    let mean = tris.iter().map(|t| t.centroid().dot(axis)).sum::<f64>() / tris.len() as f64;
    let mut k = 0;
    for i in 0..tris.len() {
        if tris[i].centroid().dot(axis) < mean {
            tris.swap(i, k);
            k += 1;
        }
    }
    if k == 0 || k == tris.len() {
        k = tris.len() / 2; // PQP halves the list when one side is empty
    }
    let (l, r) = tris.split_at_mut(k);
    let (vl, nl) = tree_volume(l, method);
    let (vr, nr) = tree_volume(r, method);
    (obb.volume() + vl + vr, 1 + nl + nr)
}

fn main() {
    let uneven = {
        // A box with one face triangle refined 4^4 times (uneven tessellation).
        let b = shapes::cuboid(DVec3::new(2.0, 1.0, 0.5));
        let mut first = TriMesh::new(b.triangle(0).v.to_vec(), vec![[0, 1, 2]]).unwrap();
        for _ in 0..4 {
            first = shapes::subdivide(&first);
        }
        let mut tris: Vec<Triangle> = first.triangles().collect();
        tris.extend((1..12).map(|i| b.triangle(i)));
        tris
    };
    let cases: Vec<(&str, Vec<Triangle>)> = vec![
        ("cuboid, one face refined", uneven),
        (
            "icosphere(1, 3)",
            shapes::icosphere(1.0, 3).triangles().collect(),
        ),
        (
            "torus_knot default",
            shapes::torus_knot(&Default::default())
                .unwrap()
                .triangles()
                .collect(),
        ),
        (
            "spur_gear default",
            shapes::spur_gear(&Default::default())
                .unwrap()
                .triangles()
                .collect(),
        ),
        (
            "coil_spring default",
            shapes::coil_spring(&Default::default())
                .unwrap()
                .triangles()
                .collect(),
        ),
        (
            "wheel default",
            shapes::wheel(&Default::default())
                .unwrap()
                .triangles()
                .collect(),
        ),
        (
            "wheelset default",
            shapes::wheelset(&Default::default())
                .unwrap()
                .triangles()
                .collect(),
        ),
        (
            "rail, R=30 m, 0.5 rad",
            shapes::rail(&shapes::RailParams {
                path: shapes::RailPath::Curve {
                    radius: 30.0,
                    angle: 0.5,
                },
                segments: 32,
            })
            .unwrap()
            .triangles()
            .collect(),
        ),
    ];
    let mut rng = StdRng::seed_from_u64(7);
    println!(
        "{:<26} {:>6} | {:>12} {:>7} {:>7} | {:>12} {:>7} {:>7}",
        "shape", "tris", "whole VC m3", "AW/VC", "HS/VC", "tree VC m3", "AW/VC", "HS/VC"
    );
    for (name, tris) in cases {
        let mut whole = [0.0; 3];
        let rotations = 16;
        for _ in 0..rotations {
            let q = DQuat::from_xyzw(
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
            )
            .normalize();
            let pose = Pose::new(DVec3::ZERO, q);
            let moved: Vec<Triangle> = tris.iter().map(|t| t.transformed(&pose)).collect();
            for (k, m) in METHODS.iter().enumerate() {
                whole[k] += fit_obb(&moved, *m).volume() / rotations as f64;
            }
        }
        let mut tree = [0.0; 3];
        for (k, m) in METHODS.iter().enumerate() {
            let mut t = tris.clone();
            let (v, n) = tree_volume(&mut t, *m);
            tree[k] = v / n as f64;
        }
        println!(
            "{:<26} {:>6} | {:>12.4e} {:>7.3} {:>7.3} | {:>12.4e} {:>7.3} {:>7.3}",
            name,
            tris.len(),
            whole[0],
            whole[1] / whole[0],
            whole[2] / whole[0],
            tree[0],
            tree[1] / tree[0],
            tree[2] / tree[0]
        );
    }
}
