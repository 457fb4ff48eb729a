//! Work and time per query on the near-contact knots and the dense sphere sweep, for each leaf
//! size, uncached and cached: a quick probe beside the criterion bench (no peers, no oracle).
//!
//! ```text
//! cargo run --release -p frcd-obb --example obb_probe -- [knots|spheres] [leaf sizes...]
//! ```

use frcd_geom::shapes::{TorusKnotParams, icosphere, torus_knot};
use frcd_geom::{DQuat, DVec3, Pose, TriMesh};
use frcd_obb::{
    BuildOptions, Counters, Mode, ObbTree, PairCache, Request, collide, collide_cached,
};
use std::time::Instant;

struct Rng(u64);
impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }
    fn unit(&mut self) -> DVec3 {
        loop {
            let v = DVec3::new(
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
            );
            let l = v.length_squared();
            if l > 1e-6 && l <= 1.0 {
                return v / l.sqrt();
            }
        }
    }
}

fn knots(steps: usize) -> (TriMesh, Vec<[Pose; 2]>) {
    let params = TorusKnotParams {
        tubular_segments: 1040,
        radial_segments: 24,
        ..TorusKnotParams::default()
    };
    let mesh = torus_knot(&params).expect("valid knot");
    let lift: f64 = std::env::var("LIFT")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.36);
    let lift = 2.0 * params.tube_radius * lift;
    let mut rng = Rng(0x7075);
    let frames = (0..steps)
        .map(|k| {
            let s = k as f64;
            let wobble = DQuat::from_axis_angle(rng.unit(), 0.008 * (0.3 * s).sin())
                * DQuat::from_rotation_z(0.01 * (0.05 * s).sin());
            [
                Pose::IDENTITY,
                Pose::new(DVec3::new(0.0, 0.0, lift), wobble),
            ]
        })
        .collect();
    (mesh, frames)
}

fn spheres(steps: usize) -> (TriMesh, Vec<[Pose; 2]>) {
    let frames = (0..steps)
        .map(|k| {
            let s = k as f64 / (steps.max(2) - 1) as f64;
            [
                Pose::IDENTITY,
                Pose::new(
                    DVec3::new(-2.5 + 5.0 * s, 0.15, -0.1),
                    DQuat::from_rotation_z(0.6 * s) * DQuat::from_rotation_x(0.3 * s),
                ),
            ]
        })
        .collect();
    (icosphere(1.0, 5), frames)
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene = args.first().map(String::as_str).unwrap_or("knots");
    let leaves: Vec<u32> = args[1.min(args.len())..]
        .iter()
        .filter_map(|a| a.parse().ok())
        .collect();
    let leaves = if leaves.is_empty() { vec![1] } else { leaves };
    let (mesh, frames) = match scene {
        "spheres" => spheres(200),
        _ => knots(500),
    };
    println!(
        "scene {scene}: {} tris, {} steps",
        mesh.triangle_count(),
        frames.len()
    );
    for leaf in leaves {
        let opts = BuildOptions {
            max_leaf_triangles: leaf,
            ..BuildOptions::default()
        };
        let t0 = Instant::now();
        let tree = ObbTree::build(&mesh, &opts);
        let build = t0.elapsed().as_secs_f64() * 1e3;
        println!(
            "leaf {leaf}: build {build:.1} ms, {} nodes",
            tree.node_count()
        );
        for mode in [Mode::FirstContact, Mode::AllPairs] {
            // METHOD=tropp (or moller) compares a float triangle test with Exact in the tree.
            let method = match std::env::var("METHOD").as_deref() {
                Ok("tropp") => frcd_obb::Method::Tropp,
                Ok("moller") => frcd_obb::Method::Moller,
                _ => frcd_obb::Method::Exact,
            };
            let r = Request {
                method,
                mode,
                ..Request::default()
            };
            for cached in [false, true] {
                // Two rounds; keep the second (warm caches).
                let mut rows = Vec::new();
                for _ in 0..2 {
                    rows.clear();
                    let mut cache = PairCache::new();
                    for f in &frames {
                        let t = Instant::now();
                        let c = if cached {
                            collide_cached(&tree, &f[0], &tree, &f[1], &r, &mut cache)
                        } else {
                            collide(&tree, &f[0], &tree, &f[1], &r)
                        };
                        rows.push((t.elapsed().as_secs_f64() * 1e9, c.collide, c.counters));
                    }
                }
                let total: f64 = rows.iter().map(|r| r.0).sum();
                let mut sum = [Counters::default(), Counters::default()];
                let mut n = [0usize; 2];
                let mut ns = [0.0f64; 2];
                for (t, hit, c) in &rows {
                    let k = *hit as usize;
                    sum[k] += *c;
                    n[k] += 1;
                    ns[k] += t;
                }
                let med = |k: bool| {
                    median(
                        rows.iter()
                            .filter(|r| r.1 == k)
                            .map(|r| r.0 / 1e3)
                            .collect(),
                    )
                };
                let per = |k: usize| {
                    let c = &sum[k];
                    format!(
                        "{} steps, med {:.1} us, box/q {:.0}, tri/q {:.0}, ns/box(all work) {:.1}",
                        n[k],
                        med(k == 1),
                        c.box_tests as f64 / n[k].max(1) as f64,
                        c.tri_tests as f64 / n[k].max(1) as f64,
                        ns[k] / c.box_tests.max(1) as f64
                    )
                };
                println!(
                    "  {mode:?}{} total {:.2} ms | disjoint: {} | touching: {}",
                    if cached { " cached" } else { "" },
                    total / 1e6,
                    per(0),
                    per(1)
                );
            }
        }
    }
}
