//! `cargo xtask bench tritri [--pairs N] [--reps R] [--out DIR]`: every triangle-triangle method
//! side by side at intersection ratios 0-100 %, in one process with all methods interleaved.
//!
//! Each repetition times every method once on every ratio's pair set (the order rotates between
//! repetitions); one repetition of a method is the best of `BURST` short samples (~1 ms
//! each: on a shared, oversubscribed machine a sample that was preempted is discarded), and the
//! reported value is the median over repetitions of ns per test.
//! Prints the table and writes `DIR/tritri.md` (the table) and `DIR/tritri.svg` (ns/test vs ratio).
use anyhow::{Context, Result, bail};
use frcd_benches::tritri_pairs::{RATIOS, pairs_at_ratio};
use frcd_tritri::{Method, Triangle};
use std::fmt::Write as _;
use std::hint::black_box;
use std::path::PathBuf;
use std::time::Instant;

/// Samples per repetition (the best one counts).
const BURST: usize = 5;

struct Opts {
    pairs: usize,
    reps: usize,
    out: PathBuf,
}

fn parse(args: &[String]) -> Result<Opts> {
    let mut o = Opts {
        pairs: 5000,
        reps: 15,
        out: PathBuf::from("testdata/bench"),
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut val = |name: &str| {
            it.next()
                .with_context(|| format!("{name} needs a value"))
                .cloned()
        };
        match a.as_str() {
            "--pairs" => o.pairs = val("--pairs")?.parse().context("--pairs: a count")?,
            "--reps" => o.reps = val("--reps")?.parse().context("--reps: a count")?,
            "--out" => o.out = PathBuf::from(val("--out")?),
            "-h" | "--help" => {
                println!("usage: cargo xtask bench tritri [--pairs N] [--reps R] [--out DIR]");
                std::process::exit(0);
            }
            other => bail!("bench tritri: unknown argument '{other}'"),
        }
    }
    if o.pairs == 0 || o.reps == 0 {
        bail!("bench tritri: --pairs and --reps must be positive");
    }
    Ok(o)
}

/// One timed pass: ns per test. Monomorphised per method so each loop inlines its test.
#[inline(never)]
fn pass<F: Fn(&Triangle, &Triangle) -> bool>(f: F, pairs: &[(Triangle, Triangle)]) -> (f64, usize) {
    // Enough passes over the set for ~1 ms per sample.
    let mut loops = 1usize;
    loop {
        let t0 = Instant::now();
        let mut hits = 0usize;
        for _ in 0..loops {
            for (a, b) in black_box(pairs) {
                hits += f(a, b) as usize;
            }
        }
        let dt = t0.elapsed().as_nanos() as u64;
        if dt >= 1_000_000 || loops >= 1 << 20 {
            return (
                dt as f64 / (loops * pairs.len()) as f64,
                black_box(hits) / loops,
            );
        }
        loops *= 2;
    }
}

fn run_method(m: Method, pairs: &[(Triangle, Triangle)]) -> (f64, usize) {
    match m {
        Method::Zou => pass(frcd_tritri::zou, pairs),
        Method::Moller => pass(frcd_tritri::moller, pairs),
        Method::GuigueDevillers => pass(frcd_tritri::guigue_devillers, pairs),
        Method::Shen => pass(frcd_tritri::shen, pairs),
        Method::Tropp => pass(frcd_tritri::tropp, pairs),
        Method::Exact => pass(frcd_tritri::exact, pairs),
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
pub fn run(args: &[String]) -> Result<()> {
    let o = parse(args)?;
    let methods = Method::ALL;
    // table[ratio][method] = median ns/test
    let mut table = vec![[0.0f64; 6]; RATIOS.len()];
    let mut wrong = vec![[0usize; 6]; RATIOS.len()];
    let sets: Vec<Vec<(Triangle, Triangle)>> = RATIOS
        .iter()
        .map(|&r| pairs_at_ratio(o.pairs, r, 42))
        .collect();
    let expect: Vec<usize> = sets
        .iter()
        .map(|p| p.iter().filter(|(a, b)| frcd_tritri::exact(a, b)).count())
        .collect();
    // samples[ratio][method]
    let mut samples: Vec<Vec<Vec<f64>>> = vec![vec![Vec::new(); 6]; RATIOS.len()];
    for pairs in &sets {
        for &m in &methods {
            run_method(m, pairs); // warm-up
        }
    }
    // Repetitions outermost: every (ratio, method) cell is sampled across the whole run, so a
    // slow phase of a shared machine hits all cells alike.
    for rep in 0..o.reps {
        for (ri, pairs) in sets.iter().enumerate() {
            for k in 0..methods.len() {
                let mi = (k + rep + ri) % methods.len();
                let mut best = f64::INFINITY;
                for _ in 0..BURST {
                    let (ns, hits) = run_method(methods[mi], pairs);
                    best = best.min(ns);
                    wrong[ri][mi] = wrong[ri][mi].max(hits.abs_diff(expect[ri]));
                }
                samples[ri][mi].push(best);
            }
        }
    }
    for ri in 0..RATIOS.len() {
        for mi in 0..6 {
            table[ri][mi] = median(&mut samples[ri][mi]);
        }
    }

    let mut md = String::new();
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let load = load.split_whitespace().next().unwrap_or("?");
    writeln!(
        md,
        "Triangle-triangle tests, ns per test (median of {} repetitions interleaved over all ratios and methods, each the best of 5 samples of ~1 ms; {} pairs per ratio, vertices uniform in the unit cube; {} cores, load average {} at the end of the run).\n",
        o.reps, o.pairs, cores, load
    )?;
    write!(md, "| intersecting |")?;
    for m in methods {
        write!(md, " {} |", m.name())?;
    }
    writeln!(
        md,
        " fastest float | exact / fastest float | zou / best other float |"
    )?;
    writeln!(md, "|---|{}---|---|---|", "---|".repeat(methods.len()))?;
    for (ri, &ratio) in RATIOS.iter().enumerate() {
        let row = &table[ri];
        let (fi, fastest) = (0..5)
            .map(|i| (i, row[i]))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .expect("five float methods");
        let best_other = (1..5).map(|i| row[i]).fold(f64::INFINITY, f64::min);
        write!(md, "| {ratio} % |")?;
        for v in row {
            write!(md, " {v:.1} |")?;
        }
        writeln!(
            md,
            " {} | {:.2} | {:.2} |",
            methods[fi].name(),
            row[5] / fastest,
            row[0] / best_other
        )?;
    }
    let mut miscount: Vec<String> = Vec::new();
    for (ri, r) in RATIOS.iter().enumerate() {
        for (mi, m) in methods.iter().enumerate() {
            if wrong[ri][mi] > 0 {
                miscount.push(format!(
                    "{} at {r} %: hit count off by {}",
                    m.name(),
                    wrong[ri][mi]
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
    Ok(())
}

fn plot(path: &std::path::Path, table: &[[f64; 6]]) -> Result<()> {
    use plotters::prelude::*;
    let ymax = table.iter().flatten().fold(0.0f64, |a, &b| a.max(b)) * 1.15;
    let root = SVGBackend::new(path, (800, 500)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "triangle-triangle tests: ns per test vs intersection ratio",
            ("sans-serif", 20),
        )
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d(0f64..100f64, 0f64..ymax)?;
    chart
        .configure_mesh()
        .x_desc("intersecting pairs (%)")
        .y_desc("ns / test")
        .draw()?;
    let colors = [RED, BLUE, GREEN, MAGENTA, CYAN, BLACK];
    for (mi, m) in Method::ALL.iter().enumerate() {
        let pts: Vec<(f64, f64)> = RATIOS
            .iter()
            .enumerate()
            .map(|(ri, &r)| (r as f64, table[ri][mi]))
            .collect();
        let c = colors[mi];
        chart
            .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))?
            .label(m.name())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}
