//! Build time and tree shape for the two `obb/build` bench meshes (icosphere 20k, knot 50k): a
//! quick probe beside the criterion bench, for profiling (`perf record`) without criterion.
//!
//! ```text
//! cargo run --release -p frcd-obb --example build_probe -- [reps]
//! ```

use frcd_geom::TriMesh;
use frcd_geom::shapes::{TorusKnotParams, icosphere, torus_knot};
use frcd_obb::{BuildOptions, ObbTree};
use std::time::Instant;

fn main() {
    if std::env::var("EIGEN").is_ok() {
        eigen_timing();
        return;
    }
    let reps: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(20);
    let knot = torus_knot(&TorusKnotParams {
        tubular_segments: 1040,
        radial_segments: 24,
        ..TorusKnotParams::default()
    })
    .expect("valid knot");
    let meshes: [(&str, TriMesh); 2] = [("icosphere_20k", icosphere(1.0, 5)), ("knot_50k", knot)];
    for (name, mesh) in &meshes {
        let _ = mesh.topology();
        let opts = BuildOptions::default();
        let mut times = Vec::new();
        let mut tree = ObbTree::build(mesh, &opts);
        let cpu0 = cpu_seconds();
        for _ in 0..reps {
            let t0 = Instant::now();
            tree = ObbTree::build(mesh, &opts);
            times.push(t0.elapsed().as_secs_f64() * 1e3);
        }
        let cpu = (cpu_seconds() - cpu0) / reps as f64 * 1e3;
        times.sort_by(f64::total_cmp);
        // Shape: total volume and surface of the boxes (a tree-quality proxy), depth.
        let (mut vol, mut area) = (0.0, 0.0);
        for n in tree.nodes() {
            let e = n.obb.half_extents;
            vol += 8.0 * e.x * e.y * e.z;
            area += 8.0 * (e.x * e.y + e.y * e.z + e.z * e.x);
        }
        println!(
            "{name}: {} tris, build min {:.2} ms, median {:.2} ms, cpu {cpu:.2} ms; {} nodes, depth {}, sum vol {:.6e}, sum area {:.6e}",
            mesh.triangle_count(),
            times[0],
            times[times.len() / 2],
            tree.nodes().len(),
            tree.depth(),
            vol,
            area
        );
    }
}

#[allow(dead_code)]
fn eigen_timing() {
    use frcd_geom::{DMat3, DVec3};
    let mut s = 1u64;
    let mut r = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let ms: Vec<DMat3> = (0..100_000)
        .map(|_| {
            let a = DMat3::from_cols(
                DVec3::new(r(), r(), r()),
                DVec3::new(r(), r(), r()),
                DVec3::new(r(), r(), r()),
            );
            a * a.transpose()
        })
        .collect();
    let t0 = Instant::now();
    let mut acc = 0.0;
    for m in &ms {
        acc += frcd_geom::eigen::symmetric_eigen(*m).unwrap().1.x_axis.x;
    }
    let t1 = Instant::now();
    for m in &ms {
        acc += frcd_geom::eigen::symmetric_eigen_jacobi(*m).1.x_axis.x;
    }
    let t2 = Instant::now();
    println!(
        "eigen closed {:.1} ns, jacobi {:.1} ns ({acc})",
        (t1 - t0).as_secs_f64() * 1e4,
        (t2 - t1).as_secs_f64() * 1e4
    );
}

/// This process's user + system CPU time (Linux `/proc`; 0 elsewhere): on a loaded machine a
/// steadier measure than wall time.
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the command name (which is in parentheses): utime and stime are 14 and 15.
    let rest = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}
