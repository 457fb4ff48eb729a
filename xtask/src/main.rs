//! `cargo xtask <task>`: the project's verification, stress and benchmark drivers.
//!
//! - `verify`: every backend against the exact oracle on generated and stored scenes;
//! - `stress`: near-degenerate triangle families, wrong answers per method and family;
//! - `bench`: run time against error tables and SVG plots.

use anyhow::{Result, bail};

mod stress;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (task, rest) = match args.split_first() {
        Some((t, r)) => (t.as_str(), r),
        None => ("help", &[][..]),
    };
    match task {
        "stress" => stress::run(rest),
        "help" | "--help" | "-h" => {
            println!("usage: cargo xtask <stress|verify|bench> [args]");
            Ok(())
        }
        other => bail!("unknown task '{other}' (try: stress, verify, bench)"),
    }
}
