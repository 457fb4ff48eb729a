//! The wide traversal's builds against each other in one process (`frcd_obb::set_wide_traversal_isa`):
//! the trees are built once, and each round times every obb-bench scene class's whole sequence
//! under build A and under build B, in an order reversed every round, so that a noisy host
//! shifts both alike. Prints per class and mode the medians of both and the median and
//! quartiles of the per-round ratio B / A. Every answer and work counter is asserted equal
//! between the builds (they run the same IEEE operations).
//!
//! ```text
//! cargo bench -p frcd-benches --bench isa_builds                       # avx512 / avx2, 15 rounds
//! FRCD_ISA_PAIR=avx2,baseline FRCD_ISA_ROUNDS=30 FRCD_ISA_ONLY=knots cargo bench -p frcd-benches --bench isa_builds
//! ```
//!
//! A build the CPU lacks falls back to the CPU's default (`set_wide_traversal_isa`'s rule);
//! the bench says so and stops when both sides would run the same build.

#[path = "common/cad.rs"]
mod cad;

use frcd_benches::scenes::{self, Scene};
use frcd_obb::{
    BuildOptions, Counters, Mode, ObbTree, PairCache, Request, collide, collide_cached,
    set_wide_traversal_isa,
};
use std::hint::black_box;
use std::sync::Arc;
use std::time::Instant;

/// One whole sequence under the process's current build: its time (ms) and every step's
/// answer and work, to compare the builds.
fn run(
    s: &Scene,
    t: &[Arc<ObbTree>; 2],
    r: &Request,
    cached: bool,
) -> (f64, Vec<(bool, usize, Counters)>) {
    let mut cache = PairCache::new();
    let mut out = Vec::with_capacity(s.frames.len());
    let start = Instant::now();
    for f in &s.frames {
        let c = if cached {
            collide_cached(&t[0], &f[0], &t[1], &f[1], r, &mut cache)
        } else {
            collide(&t[0], &f[0], &t[1], &f[1], r)
        };
        out.push((c.collide, c.pairs.len(), c.counters));
        black_box(&c);
    }
    (start.elapsed().as_secs_f64() * 1e3, out)
}

fn quantile(v: &[f64], q: f64) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

fn main() {
    let env = |k: &str| std::env::var(k).unwrap_or_default();
    let rounds: usize = env("FRCD_ISA_ROUNDS").parse().unwrap_or(15).max(1);
    let pair = env("FRCD_ISA_PAIR");
    let (want_a, want_b) = pair.split_once(',').unwrap_or(("avx2", "avx512"));
    let (a, b) = (
        set_wide_traversal_isa(want_a),
        set_wide_traversal_isa(want_b),
    );
    println!("[isa_builds] A = {a} (asked {want_a}), B = {want_b} -> {b}; {rounds} rounds");
    if a == b {
        println!("[isa_builds] both sides run {a} on this CPU: nothing to compare");
        return;
    }
    let only = env("FRCD_ISA_ONLY");
    let mut list = vec![
        {
            let mut s = scenes::icospheres_sweep(5, 200);
            s.name = format!("dense_{}", s.name);
            s
        },
        scenes::knots_near_contact(500),
        scenes::knots_slow_rotation(200),
    ];
    list.extend(cad::cad_scenes());
    for scene in list {
        if !only.is_empty() && !only.split(',').any(|o| scene.name.contains(o)) {
            continue;
        }
        let opts = BuildOptions::default();
        let tree = |i: usize| Arc::new(ObbTree::build_shared(scene.bodies[i].mesh.clone(), &opts));
        let trees = [tree(0), tree(1)];
        for (label, mode, cached) in [
            ("first", Mode::FirstContact, false),
            ("all", Mode::AllPairs, false),
            ("cached first", Mode::FirstContact, true),
            ("cached all", Mode::AllPairs, true),
        ] {
            let r = Request {
                mode,
                ..Request::default()
            };
            let (mut ta, mut tb, mut ratio) = (Vec::new(), Vec::new(), Vec::new());
            // Round 0 warms both builds (the quad layers, the caches) and is not counted.
            for k in 0..=rounds {
                let order = if k % 2 == 0 { [a, b] } else { [b, a] };
                let mut times = [0.0; 2];
                let mut answers = Vec::new();
                for isa in order {
                    set_wide_traversal_isa(isa);
                    let (ms, ans) = run(&scene, &trees, &r, cached);
                    times[(isa == b) as usize] = ms;
                    answers.push(ans);
                }
                assert_eq!(
                    answers[0], answers[1],
                    "{} {label}: the builds differ",
                    scene.name
                );
                if k > 0 {
                    ta.push(times[0]);
                    tb.push(times[1]);
                    ratio.push(times[1] / times[0]);
                }
            }
            println!(
                "[isa_builds] {:<20} {:<12} {a} {:8.3} ms  {b} {:8.3} ms  {b}/{a} median {:.3} (quartiles {:.3}-{:.3})",
                scene.name,
                label,
                quantile(&ta, 0.5),
                quantile(&tb, 0.5),
                quantile(&ratio, 0.5),
                quantile(&ratio, 0.25),
                quantile(&ratio, 0.75),
            );
        }
    }
    set_wide_traversal_isa("");
}
