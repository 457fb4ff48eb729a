//! `cargo xtask <task>`: the project's verification, stress and benchmark drivers.
//!
//! - `verify`: every backend against the exact oracle on generated and stored scenes;
//! - `stress`: near-degenerate triangle families, wrong answers per method and family;
//! - `gen-bogie`: regenerates the bogie demo scene in testdata/bogie;
//! - `bench`: run time against error tables and SVG plots.

use anyhow::{Result, bail};

mod bench_gpgpu;
mod bench_hybrid;
mod bench_image;
mod bench_tritri;
mod fuzz;
mod gen_bogie;
mod stress;
mod verify;
mod verify_gpgpu;
mod verify_hybrid;
mod verify_image;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (task, rest) = match args.split_first() {
        Some((t, r)) => (t.as_str(), r),
        None => ("help", &[][..]),
    };
    match task {
        "stress" => stress::run(rest),
        "bench" => bench(rest),
        "verify" => verify::run(rest),
        "gen-bogie" => gen_bogie::run(rest),
        "fuzz" => fuzz::run(rest),
        "help" | "--help" | "-h" => {
            println!("usage: cargo xtask <stress|verify|bench|gen-bogie> [args]");
            Ok(())
        }
        other => bail!("unknown task '{other}' (try: stress, verify, bench, gen-bogie)"),
    }
}

/// `cargo xtask bench <suite> [args]`: the first argument selects the benchmark suite.
fn bench(args: &[String]) -> Result<()> {
    const SUITES: &str = "tritri, image, gpgpu, hybrid";
    match args.split_first() {
        Some((suite, rest)) => match suite.as_str() {
            "tritri" => bench_tritri::run(rest),
            "image" => bench_image::run(rest),
            "gpgpu" => bench_gpgpu::run(rest),
            "hybrid" => bench_hybrid::run(rest),
            other => bail!("unknown bench suite '{other}' (available: {SUITES})"),
        },
        None => bail!("usage: cargo xtask bench <suite> [args] (suites: {SUITES})"),
    }
}
