//! Where the coherence cache gains and loses, step by step: `collide_cached` against `collide`
//! over whole sequences, each step's time grouped by what the cache did.
//!
//! ```text
//! cargo bench -p frcd-benches --bench cache_steps
//! FRCD_CACHE_STEPS_ONLY=knots_near FRCD_CACHE_STEPS_ROUNDS=30 cargo bench -p frcd-benches --bench cache_steps
//! ```
//!
//! Each round runs the sequence plain, then cached with a fresh [`PairCache`] (the order reversed
//! every other round, so neither always runs on caches the other warmed), and keeps every step's
//! time; a step's figure is its median over the rounds. Running one query after the other on the
//! same step instead would time the second on nodes the first brought into the cache.
//!
//! Steps are grouped by whether they touch, whether the step before touched, and whether the
//! cache held a front before the query and after it ([`PairCache::front_len`]): a step with no
//! front before or after did a plain query's work (its ratio should be 1), one with a front
//! after but none before recorded one, one with a front before walked it (and kept it, or
//! dropped it). The table prints each group's steps, summed medians and cached / plain in time
//! and in time-free work ([`frcd_obb::Counters::work`]: a group whose time ratio exceeds its
//! work ratio spends more per unit of work), then the sequence's. Answers are compared with
//! the plain query's on every step and round (a difference stops the run).
//!
//! Scenes: `dense` (the icospheres' sweep), `knots_near` (near contact, half the steps
//! disjoint), `knots_slow` (slow coherent rotation) and the CAD pairs of `../shared/meshes` at
//! random poses (SKIP when absent), both modes.

#[path = "common/cad.rs"]
mod cad;

use frcd_benches::scenes::{self, Scene};
use frcd_obb::{BuildOptions, Mode, ObbTree, PairCache, Request, collide, collide_cached};
use std::collections::BTreeMap;
use std::time::Instant;

/// What the cache did on one step (the table's row key).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct StepKind {
    touching: bool,
    after_touching: bool,
    front_before: bool,
    front_after: bool,
}

impl StepKind {
    fn label(self) -> String {
        let what = match (self.front_before, self.front_after) {
            (false, false) => "no front (a plain query's work)",
            (false, true) => "recorded a front",
            (true, true) => "walked its front, kept one",
            (true, false) => "walked its front, dropped it",
        };
        format!(
            "{} after {}: {what}",
            if self.touching {
                "touching"
            } else {
                "disjoint"
            },
            if self.after_touching {
                "touching"
            } else {
                "disjoint"
            },
        )
    }
}

fn median(xs: &mut [f64]) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

/// Times `scene` plain and cached in `mode` over `rounds` rounds and prints the table.
fn run(scene: &Scene, mode: Mode, rounds: usize) {
    let request = Request {
        mode,
        ..Request::default()
    };
    let opts = BuildOptions::default();
    let (ta, tb) = (
        ObbTree::build(&scene.bodies[0].mesh, &opts),
        ObbTree::build(&scene.bodies[1].mesh, &opts),
    );
    let n = scene.frames.len();
    // times[variant][step] over the rounds; variant 0 plain, 1 cached.
    let mut times = vec![vec![Vec::with_capacity(rounds); n]; 2];
    // Time-free work per step ([`frcd_obb::Counters::work`]): the same every round.
    let mut work = vec![vec![0u64; n]; 2];
    let mut plain_answers = vec![None; n];
    let mut kinds = vec![None; n];
    for round in 0..rounds {
        for k in 0..2 {
            let cached = (k + round) % 2 == 1;
            let mut cache = PairCache::new();
            let mut last_touching = false;
            for (s, poses) in scene.frames.iter().enumerate() {
                let before = cache.front_len();
                let t = Instant::now();
                let c = if cached {
                    collide_cached(&ta, &poses[0], &tb, &poses[1], &request, &mut cache)
                } else {
                    collide(&ta, &poses[0], &tb, &poses[1], &request)
                };
                times[cached as usize][s].push(t.elapsed().as_secs_f64() * 1e6);
                work[cached as usize][s] = c.counters.work();
                let answer = (c.collide, c.pairs);
                if cached {
                    kinds[s] = Some(StepKind {
                        touching: answer.0,
                        after_touching: last_touching,
                        front_before: before > 0,
                        front_after: cache.front_len() > 0,
                    });
                } else {
                    plain_answers[s] = Some(answer.clone());
                }
                if let Some(plain) = &plain_answers[s] {
                    assert_eq!(
                        plain, &answer,
                        "{}: cached and plain answers differ at step {s}",
                        scene.name
                    );
                }
                last_touching = answer.0;
            }
        }
    }
    // Per group: steps, plain and cached µs, plain and cached work.
    let mut groups: BTreeMap<StepKind, (usize, f64, f64, u64, u64)> = BTreeMap::new();
    for s in 0..n {
        let kind = kinds[s].expect("every step ran cached");
        let g = groups.entry(kind).or_default();
        g.0 += 1;
        g.1 += median(&mut times[0][s]);
        g.2 += median(&mut times[1][s]);
        g.3 += work[0][s];
        g.4 += work[1][s];
    }
    let total = groups.values().fold((0.0, 0.0, 0, 0), |t, g| {
        (t.0 + g.1, t.1 + g.2, t.2 + g.3, t.3 + g.4)
    });
    // A ratio of two sums, "-" when nothing was spent.
    let ratio = |c: f64, p: f64| {
        if p > 0.0 {
            format!("{:.3}", c / p)
        } else {
            "-".to_string()
        }
    };
    println!(
        "\n{} {}, {rounds} rounds (summed per-step medians):",
        scene.name,
        match mode {
            Mode::FirstContact => "first contact",
            Mode::AllPairs => "all pairs",
        }
    );
    println!(
        "| steps | what the cache did | plain µs | cached µs | time, cached / plain | work, cached / plain |"
    );
    println!("|---:|---|---:|---:|---:|---:|");
    for (kind, &(count, p, c, wp, wc)) in &groups {
        println!(
            "| {count} | {} | {p:.0} | {c:.0} | {} | {} |",
            kind.label(),
            ratio(c, p),
            ratio(wc as f64, wp as f64)
        );
    }
    println!(
        "| {n} | whole sequence | {:.0} | {:.0} | **{}** | {} |",
        total.0,
        total.1,
        ratio(total.1, total.0),
        ratio(total.3 as f64, total.2 as f64)
    );
}

fn main() {
    // `cargo bench` passes `--bench`; this harness takes no arguments.
    let rounds = std::env::var("FRCD_CACHE_STEPS_ROUNDS")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
        .filter(|&r| r > 0)
        .unwrap_or(15);
    let only = std::env::var("FRCD_CACHE_STEPS_ONLY").unwrap_or_default();
    let wanted = |name: &str| only.is_empty() || only.split(',').any(|o| name.contains(o));
    // Scenes are made only when wanted (the knots take a second to build).
    let make = |name: &str| -> Vec<Scene> {
        match name {
            "dense" => vec![scenes::icospheres_sweep(5, 200)],
            "knots_near" => vec![scenes::knots_near_contact(500)],
            "knots_slow" => vec![scenes::knots_slow_rotation(200)],
            _ => cad::cad_scenes(),
        }
    };
    for name in ["dense", "knots_near", "knots_slow", "cad"] {
        if !wanted(name) {
            continue;
        }
        let made = make(name);
        if made.is_empty() {
            println!("SKIP {name}: no meshes (../shared/meshes absent)");
        }
        for scene in made {
            for mode in [Mode::FirstContact, Mode::AllPairs] {
                run(&scene, mode, rounds);
            }
        }
    }
}
