//! `cargo xtask bench tritri [--pairs N] [--reps R] [--out DIR]`: every triangle-triangle method
//! side by side at intersection ratios 0-100 %, in one process with all methods interleaved.
//!
//! Each repetition times every method once on every ratio's pair set (the order rotates between
//! repetitions); one repetition of a method is the best of `BURST` short samples (~1 ms
//! each: on a shared, oversubscribed machine a sample that was preempted is discarded), and the
//! reported value is the median over repetitions of ns per test.
//! Kernels: the five float methods, `exact` on raw triangles, `exact_prepared` on triangles
//! prepared beforehand (as a tree caches them), `exact_prep_b` (one side prepared inside the
//! loop); then one triangle against leaves of 4 (`TriangleBatch`) against one-pair loops.
//! Prints the tables and writes `DIR/tritri.md` (the tables) and `DIR/tritri.svg` (ns/test vs
//! ratio). Fails if an exact kernel's hit count differs from the exact labels.
use anyhow::{Context, Result, bail};
use frcd_benches::tritri_pairs::{RATIOS, pairs_at_ratio, unit_cube_triangle};
use frcd_tritri::{PreparedTriangle, Triangle, TriangleBatch, exact_prepared};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use std::fmt::Write as _;
use std::hint::black_box;
use std::path::PathBuf;
use std::time::Instant;

/// Samples per repetition (the best one counts).
const BURST: usize = 5;

/// Options of `cargo xtask bench tritri`.
#[derive(clap::Args, Debug)]
pub struct Opts {
    /// Triangle pairs per intersection ratio.
    #[arg(long, value_name = "N", default_value_t = 5000, value_parser = crate::positive::<usize>)]
    pub pairs: usize,
    /// Repetitions (the median is reported).
    #[arg(long, value_name = "R", default_value_t = 15, value_parser = crate::positive::<usize>)]
    pub reps: usize,
    /// Folder for tritri.md and tritri.svg.
    #[arg(long, value_name = "DIR", default_value = "testdata/bench")]
    pub out: PathBuf,
}

/// One timed pass over `items`, each worth `per` tests: (ns per test, hits per pass).
/// Monomorphised per kernel so each loop inlines its test.
#[inline(never)]
fn pass<T, F: Fn(&T) -> u32>(f: F, items: &[T], per: usize) -> (f64, usize) {
    // Enough passes over the set for ~1 ms per sample.
    let mut loops = 1usize;
    loop {
        let t0 = Instant::now();
        let mut hits = 0usize;
        for _ in 0..loops {
            for it in black_box(items) {
                hits += f(it) as usize;
            }
        }
        let dt = t0.elapsed().as_nanos() as u64;
        if dt >= 1_000_000 || loops >= 1 << 20 {
            return (
                dt as f64 / (loops * items.len() * per) as f64,
                black_box(hits) / loops,
            );
        }
        loops *= 2;
    }
}

/// The pair-test kernels compared, in table order: the five float methods and three forms of
/// the exact test.
const KERNELS: [&str; 8] = [
    "zou",
    "moller",
    "guigue_devillers",
    "shen",
    "tropp",
    "exact",
    "exact_prepared",
    "exact_prep_b",
];
/// Number of float kernels (the first ones).
const FLOATS: usize = 5;

/// One ratio's workload: the raw pairs and the same pairs prepared beforehand (as a tree caches
/// its own triangles).
struct Set {
    raw: Vec<(Triangle, Triangle)>,
    prepared: Vec<(PreparedTriangle, PreparedTriangle)>,
}

fn run_kernel(k: usize, set: &Set) -> (f64, usize) {
    let raw = &set.raw;
    let b = |x: bool| x as u32;
    match k {
        0 => pass(|(a, c)| b(frcd_tritri::zou(a, c)), raw, 1),
        1 => pass(|(a, c)| b(frcd_tritri::moller(a, c)), raw, 1),
        2 => pass(|(a, c)| b(frcd_tritri::guigue_devillers(a, c)), raw, 1),
        3 => pass(|(a, c)| b(frcd_tritri::shen(a, c)), raw, 1),
        4 => pass(|(a, c)| b(frcd_tritri::tropp(a, c)), raw, 1),
        5 => pass(|(a, c)| b(frcd_tritri::exact(a, c)), raw, 1),
        6 => pass(|(a, c)| b(exact_prepared(a, c)), &set.prepared, 1),
        // A prepared (cached), B prepared inside the timed loop: the cost when each mapped
        // triangle of the other mesh meets only one cached triangle.
        _ => pass(
            |(a, c): &(PreparedTriangle, Triangle)| b(exact_prepared(a, &PreparedTriangle::new(c))),
            &set.prepared
                .iter()
                .zip(raw)
                .map(|(p, r)| (p.0, r.1))
                .collect::<Vec<_>>(),
            1,
        ),
    }
}

/// Leaf workload: one triangle against `LEAF` others, `LEAF·ratio` of which it meets.
const LEAF: usize = 4;

struct Leaves {
    /// (the triangle, its leaf) raw, for the one-pair loops.
    raw: Vec<(Triangle, [Triangle; LEAF])>,
    /// The same prepared, and the leaf packed as a batch.
    batched: Vec<(PreparedTriangle, [PreparedTriangle; LEAF], TriangleBatch)>,
}

fn leaves_at_ratio(n: usize, percent: u32, seed: u64) -> Leaves {
    let mut rng = StdRng::seed_from_u64(seed ^ (percent as u64).wrapping_mul(0x51_7cc1_b727_220a));
    let want_hit = (LEAF * percent as usize + 50) / 100;
    let mut raw = Vec::with_capacity(n);
    while raw.len() < n {
        let t = unit_cube_triangle(&mut rng);
        let (mut hit, mut miss) = (Vec::new(), Vec::new());
        let mut tries = 0;
        while (hit.len() < want_hit || miss.len() < LEAF - want_hit) && tries < 10_000 {
            tries += 1;
            let c = unit_cube_triangle(&mut rng);
            if frcd_tritri::exact(&t, &c) {
                if hit.len() < want_hit {
                    hit.push(c);
                }
            } else if miss.len() < LEAF - want_hit {
                miss.push(c);
            }
        }
        if hit.len() < want_hit || miss.len() < LEAF - want_hit {
            continue; // a triangle too small to be hit often enough: draw another
        }
        hit.append(&mut miss);
        hit.shuffle(&mut rng);
        raw.push((t, std::array::from_fn(|i| hit[i])));
    }
    let batched = raw
        .iter()
        .map(|(t, l)| {
            let pl = l.map(|x| PreparedTriangle::new(&x));
            let batch = TriangleBatch::from_prepared(&pl).expect("a leaf of 1 to 4");
            (PreparedTriangle::new(t), pl, batch)
        })
        .collect();
    Leaves { raw, batched }
}

/// Leaf kernels: the batch, the prepared one-pair loop, the raw exact loop, the fastest float
/// loop (Tropp).
const LEAF_KERNELS: [&str; 4] = ["batch", "prepared loop", "exact loop", "tropp loop"];

fn run_leaf_kernel(k: usize, l: &Leaves) -> (f64, usize) {
    match k {
        0 => pass(
            |(t, _, b)| b.intersect_mask(t).count_ones(),
            &l.batched,
            LEAF,
        ),
        1 => pass(
            |(t, pl, _)| pl.iter().map(|x| exact_prepared(t, x) as u32).sum(),
            &l.batched,
            LEAF,
        ),
        2 => pass(
            |(t, leaf)| leaf.iter().map(|x| frcd_tritri::exact(t, x) as u32).sum(),
            &l.raw,
            LEAF,
        ),
        _ => pass(
            |(t, leaf)| leaf.iter().map(|x| frcd_tritri::tropp(t, x) as u32).sum(),
            &l.raw,
            LEAF,
        ),
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Entry point of `cargo xtask bench tritri`.
pub fn run(o: Opts) -> Result<()> {
    let nk = KERNELS.len();
    let nl = LEAF_KERNELS.len();
    let sets: Vec<Set> = RATIOS
        .iter()
        .map(|&r| {
            let raw = pairs_at_ratio(o.pairs, r, 42);
            let prepared = raw
                .iter()
                .map(|(a, b)| (PreparedTriangle::new(a), PreparedTriangle::new(b)))
                .collect();
            Set { raw, prepared }
        })
        .collect();
    let leaves: Vec<Leaves> = RATIOS
        .iter()
        .map(|&r| leaves_at_ratio(o.pairs / LEAF, r, 43))
        .collect();
    let expect: Vec<usize> = sets
        .iter()
        .map(|s| {
            s.raw
                .iter()
                .filter(|(a, b)| frcd_tritri::exact(a, b))
                .count()
        })
        .collect();
    let leaf_expect: Vec<usize> = leaves
        .iter()
        .map(|l| {
            l.raw
                .iter()
                .map(|(t, leaf)| leaf.iter().filter(|x| frcd_tritri::exact(t, x)).count())
                .sum()
        })
        .collect();
    // samples[ratio][kernel]; wrong[ratio][kernel] = largest hit-count difference seen.
    let mut samples: Vec<Vec<Vec<f64>>> = vec![vec![Vec::new(); nk]; RATIOS.len()];
    let mut leaf_samples: Vec<Vec<Vec<f64>>> = vec![vec![Vec::new(); nl]; RATIOS.len()];
    let mut wrong = vec![vec![0usize; nk]; RATIOS.len()];
    let mut leaf_wrong = vec![vec![0usize; nl]; RATIOS.len()];
    for (s, l) in sets.iter().zip(&leaves) {
        for k in 0..nk {
            run_kernel(k, s); // warm-up
        }
        for k in 0..nl {
            run_leaf_kernel(k, l);
        }
    }
    // Repetitions outermost: every (ratio, kernel) cell is sampled across the whole run, so a
    // slow phase of a shared machine hits all cells alike.
    for rep in 0..o.reps {
        for ri in 0..RATIOS.len() {
            for j in 0..nk + nl {
                let k = (j + rep + ri) % (nk + nl);
                let mut best = f64::INFINITY;
                for _ in 0..BURST {
                    if k < nk {
                        let (ns, hits) = run_kernel(k, &sets[ri]);
                        wrong[ri][k] = wrong[ri][k].max(hits.abs_diff(expect[ri]));
                        best = best.min(ns);
                    } else {
                        let (ns, hits) = run_leaf_kernel(k - nk, &leaves[ri]);
                        let w = &mut leaf_wrong[ri][k - nk];
                        *w = (*w).max(hits.abs_diff(leaf_expect[ri]));
                        best = best.min(ns);
                    }
                }
                if k < nk {
                    samples[ri][k].push(best);
                } else {
                    leaf_samples[ri][k - nk].push(best);
                }
            }
        }
    }
    let table: Vec<Vec<f64>> = samples
        .iter_mut()
        .map(|r| r.iter_mut().map(|v| median(v)).collect())
        .collect();
    let leaf_table: Vec<Vec<f64>> = leaf_samples
        .iter_mut()
        .map(|r| r.iter_mut().map(|v| median(v)).collect())
        .collect();

    let mut md = String::new();
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let load = load.split_whitespace().next().unwrap_or("?");
    writeln!(
        md,
        "Triangle-triangle tests, ns per test (median of {} repetitions interleaved over all ratios and kernels, each the best of {BURST} samples of ~1 ms; {} pairs per ratio, vertices uniform in the unit cube; {} cores, load average {} at the end of the run). `cargo xtask bench tritri --pairs {} --reps {}`.\n",
        o.reps, o.pairs, cores, load, o.pairs, o.reps
    )?;
    writeln!(
        md,
        "`exact`: `frcd_tritri::exact` on two raw triangles (per-pair error bound). `exact_prepared`: `frcd_tritri::exact_prepared` on triangles prepared beforehand (`PreparedTriangle`, as a tree caches them; cached bound). `exact_prep_b`: one triangle prepared beforehand, the other prepared inside the timed loop.\n"
    )?;
    write!(md, "| intersecting |")?;
    for name in KERNELS {
        write!(md, " {name} |")?;
    }
    writeln!(
        md,
        " fastest float | exact / fastest | exact_prepared / fastest | exact_prep_b / fastest | zou / best other float |"
    )?;
    writeln!(md, "|---|{}---|---|---|---|---|", "---|".repeat(nk))?;
    for (ri, &ratio) in RATIOS.iter().enumerate() {
        let row = &table[ri];
        let (fi, fastest) = (0..FLOATS)
            .map(|i| (i, row[i]))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .expect("five float methods");
        let best_other = (1..FLOATS).map(|i| row[i]).fold(f64::INFINITY, f64::min);
        write!(md, "| {ratio} % |")?;
        for v in row {
            write!(md, " {v:.1} |")?;
        }
        writeln!(
            md,
            " {} | {:.2} | {:.2} | {:.2} | {:.2} |",
            KERNELS[fi],
            row[5] / fastest,
            row[6] / fastest,
            row[7] / fastest,
            row[0] / best_other
        )?;
    }
    writeln!(
        md,
        "\nOne triangle against a leaf of {LEAF} (`TriangleBatch::intersect_mask`, filter vectorised over the leaf) against one-pair loops over the same leaf, ns per triangle pair; {} leaves per ratio, the ratio exact per leaf.\n",
        o.pairs / LEAF
    )?;
    write!(md, "| intersecting |")?;
    for name in LEAF_KERNELS {
        write!(md, " {name} |")?;
    }
    writeln!(
        md,
        " batch / prepared loop | batch / exact loop | batch / tropp loop |"
    )?;
    writeln!(md, "|---|{}---|---|---|", "---|".repeat(nl))?;
    for (ri, &ratio) in RATIOS.iter().enumerate() {
        let row = &leaf_table[ri];
        write!(md, "| {ratio} % |")?;
        for v in row {
            write!(md, " {v:.1} |")?;
        }
        writeln!(
            md,
            " {:.2} | {:.2} | {:.2} |",
            row[0] / row[1],
            row[0] / row[2],
            row[0] / row[3]
        )?;
    }
    let mut miscount: Vec<String> = Vec::new();
    for (ri, r) in RATIOS.iter().enumerate() {
        for (k, name) in KERNELS.iter().enumerate() {
            if wrong[ri][k] > 0 {
                miscount.push(format!(
                    "{name} at {r} %: hit count off by {}",
                    wrong[ri][k]
                ));
            }
        }
        for (k, name) in LEAF_KERNELS.iter().enumerate() {
            if leaf_wrong[ri][k] > 0 {
                miscount.push(format!(
                    "{name} (leaves) at {r} %: hit count off by {}",
                    leaf_wrong[ri][k]
                ));
            }
        }
    }
    if !miscount.is_empty() {
        writeln!(
            md,
            "\nHit counts differing from the exact labels: {}.",
            miscount.join("; ")
        )?;
    }
    print!("{md}");

    std::fs::create_dir_all(&o.out).with_context(|| format!("creating {}", o.out.display()))?;
    let md_path = o.out.join("tritri.md");
    std::fs::write(&md_path, &md).with_context(|| format!("writing {}", md_path.display()))?;
    let svg_path = o.out.join("tritri.svg");
    plot(&svg_path, &table)?;
    println!("\nwrote {} and {}", md_path.display(), svg_path.display());
    // Every exact form must count exactly.
    for ri in 0..RATIOS.len() {
        if wrong[ri][FLOATS..].iter().any(|&w| w > 0) || leaf_wrong[ri][..3].iter().any(|&w| w > 0)
        {
            bail!("an exact kernel miscounted at {} %", RATIOS[ri]);
        }
    }
    Ok(())
}

fn plot(path: &std::path::Path, table: &[Vec<f64>]) -> Result<()> {
    use crate::plot::{self, Axis, Chart, Legend, Series};
    let ymax = table.iter().flatten().fold(0.0f64, |a, &b| a.max(b)) * 1.15;
    let colors = [
        plot::RED,
        plot::BLUE,
        plot::GREEN,
        plot::MAGENTA,
        plot::CYAN,
        plot::BLACK,
        plot::ORANGE,
        plot::GREY,
    ];
    let mut chart = Chart::new(
        "triangle-triangle tests: ns per test vs intersection ratio",
        Axis::linear("intersecting pairs (%)", 0.0..100.0),
        Axis::linear("ns / test", 0.0..ymax),
    )
    .caption_size(20)
    .legend(Legend::LowerRight);
    chart.y_label_area = 55;
    for (mi, name) in KERNELS.iter().enumerate() {
        let pts = RATIOS
            .iter()
            .zip(table)
            .map(|(&r, row)| (r as f64, row[mi]));
        chart = chart.series(Series::line(*name, colors[mi], pts.collect()));
    }
    plot::write_svg(path, (800, 500), &[chart])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plot_writes_every_series() {
        let table: Vec<Vec<f64>> = RATIOS
            .iter()
            .enumerate()
            .map(|(ri, _)| {
                (0..KERNELS.len())
                    .map(|k| 10.0 + (k * 3 + ri) as f64)
                    .collect()
            })
            .collect();
        let path = crate::plot::TempFile(
            std::env::temp_dir().join(format!("frcd-xtask-tritri-{}.svg", std::process::id())),
        );
        plot(&path, &table).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        for s in KERNELS {
            assert!(svg.contains(s), "{s} missing");
        }
    }
}
