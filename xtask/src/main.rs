//! `cargo xtask <task>`: the project's verification, stress and benchmark drivers.
//!
//! - `verify`: every backend against the exact oracle on generated and stored scenes;
//! - `stress`: near-degenerate triangle families, wrong answers per method and family;
//! - `gen-bogie`: regenerates the bogie demo scene in testdata/bogie;
//! - `bench`: run time against error tables and SVG plots.

use anyhow::Result;
use clap::{Args, Parser, Subcommand};

mod bench_gpgpu;
mod bench_hybrid;
mod bench_image;
mod bench_tritri;
mod fuzz;
mod gen_bogie;
mod stress;
mod stress_distance;
mod verify;
mod verify_distance;
mod verify_gpgpu;
mod verify_hybrid;
mod verify_image;

/// The project's verification, stress and benchmark drivers.
#[derive(Parser)]
#[command(name = "cargo xtask", bin_name = "cargo xtask")]
struct Cli {
    #[command(subcommand)]
    task: Task,
}

#[derive(Subcommand)]
enum Task {
    /// Near-degenerate triangle families: wrong answers per method and family.
    Stress(Rest),
    /// Every backend against the exact oracle on generated and stored scenes.
    Verify(Rest),
    /// Run time against error tables and SVG plots, by suite.
    Bench {
        #[command(subcommand)]
        suite: Suite,
    },
    /// Regenerates the bogie demo scene in testdata/bogie.
    GenBogie(Rest),
    /// Coverage-guided fuzzing of every target in fuzz/ (nightly + cargo-fuzz).
    Fuzz(Rest),
}

#[derive(Subcommand)]
enum Suite {
    /// Every triangle-triangle method side by side at intersection ratios 0-100 %.
    Tritri(Rest),
    /// The image-space detector: run time against resolution against error.
    Image(Rest),
    /// The GPGPU pipeline against the CPU OBB traversal by scene size.
    Gpgpu(Rest),
    /// Run time against error of every backend and mode of the hybrid scheduler.
    Hybrid(Rest),
}

/// A command's own options, passed on to its `run` (each command's file parses and documents
/// them; `--help` after the command name prints its usage).
#[derive(Args)]
#[command(disable_help_flag = true)]
struct Rest {
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    args: Vec<String>,
}

fn main() -> Result<()> {
    match Cli::parse().task {
        Task::Stress(r) => stress::run(&r.args),
        Task::Verify(r) => verify::run(&r.args),
        Task::GenBogie(r) => gen_bogie::run(&r.args),
        Task::Fuzz(r) => fuzz::run(&r.args),
        Task::Bench { suite } => match suite {
            Suite::Tritri(r) => bench_tritri::run(&r.args),
            Suite::Image(r) => bench_image::run(&r.args),
            Suite::Gpgpu(r) => bench_gpgpu::run(&r.args),
            Suite::Hybrid(r) => bench_hybrid::run(&r.args),
        },
    }
}
