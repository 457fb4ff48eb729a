//! Convex hull run time against input size (expected O(n log n)).
//!
//! `cargo run -p frcd-geom --release --example hull_scaling [max_n]`

use frcd_geom::DVec3;
use frcd_geom::hull::{Hull3, convex_hull};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::time::Instant;

fn main() {
    let max_n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(1_000_000);
    let mut rng = StdRng::seed_from_u64(11);
    println!(
        "{:<8} {:>9} {:>10} {:>10} {:>14}",
        "cloud", "n", "hull verts", "ms", "ns/(n log2 n)"
    );
    for (name, on_sphere) in [("cube", false), ("sphere", true)] {
        for n in [1_000usize, 10_000, 100_000, 1_000_000] {
            if n > max_n {
                continue;
            }
            let pts: Vec<DVec3> = (0..n)
                .map(|_| {
                    let p = DVec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - 1.0;
                    if on_sphere { p.normalize() } else { p }
                })
                .collect();
            let t = Instant::now();
            let h = convex_hull(&pts).unwrap();
            let ms = t.elapsed().as_secs_f64() * 1e3;
            let Hull3::Polytope { vertices, .. } = h else {
                panic!()
            };
            let nlogn = n as f64 * (n as f64).log2();
            println!(
                "{name:<8} {n:>9} {:>10} {ms:>10.1} {:>14.1}",
                vertices.len(),
                ms * 1e6 / nlogn
            );
        }
    }
}
