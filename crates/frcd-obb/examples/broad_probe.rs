//! The World's broad phase under drift, for profiling (`perf record`) without criterion:
//! `n` unit boxes in a cube (about 4 neighbours each), each drifting at its own speed (uniform
//! in 0 to `speed` per step; a negative speed places every body anew in the cube each step),
//! median time per step of `overlapping_pairs` (and of the `set_poses` before it) and the
//! bodies re-inserted per step.
//!
//! ```text
//! cargo run --release -p frcd-obb --example broad_probe -- [n] [speed] [steps]
//! ```

use frcd_geom::{DVec3, Pose, shapes};
use frcd_obb::{BuildOptions, ObbTree, World, WorldOptions};
use std::sync::Arc;
use std::time::Instant;

fn main() {
    let arg = |k: usize, d: f64| {
        std::env::args()
            .nth(k)
            .and_then(|s| s.parse().ok())
            .unwrap_or(d)
    };
    let (n, speed, steps) = (
        arg(1, 262_144.0) as usize,
        arg(2, 0.02),
        arg(3, 24.0) as usize,
    );
    let cube = Arc::new(ObbTree::build(
        &shapes::cuboid(DVec3::splat(0.5)),
        &BuildOptions::default(),
    ));
    let side = (n as f64 * (4.0 / 3.0 * std::f64::consts::PI * 8.0) / 4.0).cbrt();
    let mut s = 12345u64;
    let mut rnd = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let centres: Vec<DVec3> = (0..n)
        .map(|_| DVec3::new(rnd() * side, rnd() * side, rnd() * side))
        .collect();
    let vel: Vec<DVec3> = (0..n)
        .map(|_| {
            let d = DVec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5);
            d.normalize_or(DVec3::X) * rnd() * speed
        })
        .collect();
    let mut w = World::new(WorldOptions::default());
    let ids: Vec<_> = centres
        .iter()
        .map(|&c| {
            w.add_body(cube.clone(), Pose::from_translation(c), false)
                .expect("valid pose")
        })
        .collect();
    let (mut times, mut set_times) = (Vec::new(), Vec::new());
    let start = w.broad_stats();
    for k in 0..steps {
        let up: Vec<_> = ids
            .iter()
            .enumerate()
            .map(|(i, &id)| {
                // A negative speed: every body placed anew in the cube each step (shuffle).
                let at = if speed < 0.0 {
                    DVec3::new(rnd() * side, rnd() * side, rnd() * side)
                } else {
                    centres[i] + vel[i] * k as f64
                };
                (id, Pose::from_translation(at))
            })
            .collect();
        let t = Instant::now();
        w.set_poses(&up).expect("valid poses");
        let set = t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        std::hint::black_box(w.overlapping_pairs(0.0));
        if k > 1 {
            times.push(t.elapsed().as_secs_f64() * 1e3);
            set_times.push(set);
        }
    }
    let end = w.broad_stats();
    let mean = times.iter().sum::<f64>() / times.len() as f64;
    times.sort_by(f64::total_cmp);
    set_times.sort_by(f64::total_cmp);
    println!(
        "{n} bodies, speed {speed}: median {:.2} ms, mean {mean:.2} ms per step (set_poses median {:.3} ms), {:.0} re-inserted and {:.2} rebuilds per step",
        times[times.len() / 2],
        set_times[set_times.len() / 2],
        (end.reinserted - start.reinserted) as f64 / steps as f64,
        (end.rebuilds - start.rebuilds) as f64 / steps as f64,
    );
}
