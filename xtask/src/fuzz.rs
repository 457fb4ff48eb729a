//! `cargo xtask fuzz [--seconds N] [TARGET...]`: runs every cargo-fuzz target in `fuzz/` (or
//! the named ones) for N seconds each (default 60) and prints executions, coverage and
//! crashes per target. Needs the nightly toolchain and cargo-fuzz
//! (`rustup toolchain install nightly && cargo install cargo-fuzz`).
//!
//! New inputs go to `fuzz/corpus/<target>` (not committed); the committed seeds in
//! `fuzz/seeds/<target>` are read too. A crash leaves its input in `fuzz/artifacts/<target>/`
//! and makes the task fail.

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The targets, in the order they run (cheap parsers first).
pub const TARGETS: [&str; 7] = [
    "stl",
    "obj",
    "scene",
    "trajectory",
    "mesh_tree",
    "collide_oracle",
    "world_broad",
];

/// Figures libFuzzer prints at the end of a run (`-print_final_stats=1`).
#[derive(Debug, Default)]
struct Stats {
    execs: u64,
    cov: u64,
    corpus: u64,
    crashed: bool,
}

fn parse_stats(log: &str) -> Stats {
    let mut s = Stats::default();
    for line in log.lines() {
        let num = |l: &str| {
            l.rsplit(':')
                .next()
                .and_then(|v| v.trim().parse::<u64>().ok())
        };
        if line.starts_with("stat::number_of_executed_units") {
            s.execs = num(line).unwrap_or(0);
        }
        // "#1234  DONE   cov: 567 ft: ... corp: 89/..."
        if let Some(i) = line.find("cov: ")
            && let Some(v) = line[i + 5..].split_whitespace().next()
        {
            s.cov = v.parse().unwrap_or(s.cov);
        }
        if let Some(i) = line.find("corp: ")
            && let Some(v) = line[i + 6..].split('/').next()
        {
            s.corpus = v.trim().parse().unwrap_or(s.corpus);
        }
        if line.contains("ERROR: libFuzzer") || line.contains("panicked at") {
            s.crashed = true;
        }
    }
    s
}

/// Options of `cargo xtask fuzz`.
#[derive(clap::Args, Debug)]
pub struct Opts {
    /// Seconds per target.
    #[arg(long, value_name = "N", default_value_t = 60, value_parser = crate::positive::<u64>)]
    pub seconds: u64,
    /// Targets to run (all when none is named).
    #[arg(value_name = "TARGET", value_parser = clap::builder::PossibleValuesParser::new(TARGETS))]
    pub targets: Vec<String>,
}

/// Runs the task.
pub fn run(o: Opts) -> Result<()> {
    let Opts {
        seconds,
        mut targets,
    } = o;
    if targets.is_empty() {
        targets = TARGETS.iter().map(|s| s.to_string()).collect();
    }
    let fuzz_dir: PathBuf = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz");
    let probe = Command::new("cargo")
        .args(["+nightly", "fuzz", "--version"])
        .output();
    if !probe.is_ok_and(|o| o.status.success()) {
        bail!(
            "cargo-fuzz on the nightly toolchain is needed: `rustup toolchain install nightly && cargo install cargo-fuzz`"
        );
    }
    println!("building the fuzz targets (release, sanitizer: address)...");
    let status = Command::new("cargo")
        .args(["+nightly", "fuzz", "build", "-O"])
        .current_dir(&fuzz_dir)
        .status()
        .context("cargo fuzz build")?;
    if !status.success() {
        bail!("cargo fuzz build failed");
    }
    let mut rows = Vec::new();
    let mut failed = Vec::new();
    for t in &targets {
        let corpus = fuzz_dir.join("corpus").join(t);
        let artifacts = fuzz_dir.join("artifacts").join(t);
        std::fs::create_dir_all(&corpus)?;
        std::fs::create_dir_all(&artifacts)?;
        println!("fuzzing {t} for {seconds} s...");
        let out = Command::new("cargo")
            .args(["+nightly", "fuzz", "run", "-O", t])
            .arg(&corpus)
            .arg(fuzz_dir.join("seeds").join(t))
            .arg("--")
            .arg(format!("-max_total_time={seconds}"))
            .arg("-print_final_stats=1")
            .arg("-max_len=4096")
            .arg("-rss_limit_mb=2048")
            .arg("-timeout=20")
            .arg(format!("-artifact_prefix={}/", artifacts.display()))
            .current_dir(&fuzz_dir)
            .output()
            .with_context(|| format!("cargo fuzz run {t}"))?;
        let log = String::from_utf8_lossy(&out.stderr).into_owned()
            + &String::from_utf8_lossy(&out.stdout);
        let mut stats = parse_stats(&log);
        stats.crashed |= !out.status.success();
        if stats.crashed {
            let tail: Vec<&str> = log.lines().rev().take(40).collect();
            eprintln!(
                "{t}: CRASH (input in {}):\n{}",
                artifacts.display(),
                tail.into_iter().rev().collect::<Vec<_>>().join("\n")
            );
            failed.push(t.clone());
        }
        rows.push((t.clone(), stats));
    }
    println!(
        "\n| target | seconds | executions | coverage (edges) | corpus | crashes |\n|---|---:|---:|---:|---:|---:|"
    );
    for (t, s) in &rows {
        println!(
            "| {t} | {seconds} | {} | {} | {} | {} |",
            s.execs,
            s.cov,
            s.corpus,
            u8::from(s.crashed)
        );
    }
    if !failed.is_empty() {
        bail!("crashes in: {}", failed.join(", "));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn final_stats_are_read() {
        let log = "#512\tDONE   cov: 321 ft: 900 corp: 45/2Kb lim: 100 exec/s: 50 rss: 40Mb\nstat::number_of_executed_units: 512\nstat::peak_rss_mb: 40\n";
        let s = super::parse_stats(log);
        assert_eq!((s.execs, s.cov, s.corpus, s.crashed), (512, 321, 45, false));
        assert!(super::parse_stats("==1== ERROR: libFuzzer: deadly signal").crashed);
    }
}
