//! `cargo xtask <task>`: the project's verification, stress and benchmark drivers.
//!
//! - `verify`: every backend against the exact oracle on generated and stored scenes;
//! - `stress`: near-degenerate triangle families, wrong answers per method and family;
//! - `gen-bogie`: regenerates the bogie demo scene in testdata/bogie;
//! - `bench <suite>`: run time against error tables and SVG plots (one plotting module,
//!   [`plot`]);
//! - `fuzz`: coverage-guided fuzzing (nightly + cargo-fuzz).
//!
//! Every command and option is a clap derive: `cargo xtask <task> --help` lists them with
//! their defaults. Each command's options struct lives beside its `run` in the command's file.

use anyhow::Result;
use clap::{Parser, Subcommand};

mod bench_gpgpu;
mod bench_hybrid;
mod bench_image;
mod bench_tritri;
mod fuzz;
mod gen_bogie;
mod plot;
mod stress;
mod stress_distance;
mod verify;
mod verify_distance;
mod verify_gpgpu;
mod verify_hybrid;
mod verify_image;

/// The project's verification, stress and benchmark drivers.
#[derive(Parser, Debug)]
#[command(name = "cargo xtask", bin_name = "cargo xtask")]
struct Cli {
    #[command(subcommand)]
    task: Task,
}

#[derive(Subcommand, Debug)]
enum Task {
    /// Near-degenerate triangle families: wrong answers per method and family.
    Stress(stress::Opts),
    /// Every backend against the exact oracle on generated and stored scenes.
    Verify(verify::Opts),
    /// Run time against error tables and SVG plots, by suite.
    Bench {
        #[command(subcommand)]
        suite: Suite,
    },
    /// Regenerates the bogie demo scene in testdata/bogie.
    GenBogie(gen_bogie::Opts),
    /// Coverage-guided fuzzing of every target in fuzz/ (nightly + cargo-fuzz).
    Fuzz(fuzz::Opts),
}

#[derive(Subcommand, Debug)]
enum Suite {
    /// Every triangle-triangle method side by side at intersection ratios 0-100 %.
    Tritri(bench_tritri::Opts),
    /// The image-space detector: run time against resolution against error.
    Image(bench_image::Opts),
    /// The GPGPU pipeline against the CPU OBB traversal by scene size.
    // Boxed: its options are most of the enum's size.
    Gpgpu(Box<bench_gpgpu::Opts>),
    /// Run time against error of every backend and mode of the hybrid scheduler.
    Hybrid(bench_hybrid::Opts),
}

/// `rel` inside this workspace (the default of the output and input paths, wherever the task
/// runs from).
pub fn workspace_path(rel: &str) -> std::path::PathBuf {
    let xtask = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    xtask.parent().unwrap_or(xtask).join(rel)
}

/// A count that must be at least 1 (clap value parser: `value_parser = crate::positive::<usize>`).
pub fn positive<T>(s: &str) -> Result<T, String>
where
    T: std::str::FromStr + Default + PartialEq,
    T::Err: std::fmt::Display,
{
    match s.parse::<T>() {
        Ok(n) if n == T::default() => Err("must be at least 1".into()),
        Ok(n) => Ok(n),
        Err(e) => Err(e.to_string()),
    }
}

fn main() -> Result<()> {
    match Cli::parse().task {
        Task::Stress(o) => stress::run(o),
        Task::Verify(o) => verify::run(o),
        Task::GenBogie(o) => gen_bogie::run(o),
        Task::Fuzz(o) => fuzz::run(o),
        Task::Bench { suite } => match suite {
            Suite::Tritri(o) => bench_tritri::run(o),
            Suite::Image(o) => bench_image::run(o),
            Suite::Gpgpu(o) => bench_gpgpu::run(*o),
            Suite::Hybrid(o) => bench_hybrid::run(o),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;
    use std::path::PathBuf;

    fn parse(line: &str) -> Task {
        let argv = std::iter::once("cargo xtask").chain(line.split_whitespace());
        match Cli::try_parse_from(argv) {
            Ok(cli) => cli.task,
            Err(e) => panic!("`cargo xtask {line}` does not parse: {e}"),
        }
    }

    fn refused(line: &str) -> String {
        let argv = std::iter::once("cargo xtask").chain(line.split_whitespace());
        match Cli::try_parse_from(argv) {
            Ok(cli) => panic!("`cargo xtask {line}` parsed as {cli:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn the_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn stress_defaults_and_flags() {
        let Task::Stress(o) = parse("stress") else {
            panic!()
        };
        assert_eq!((o.pairs, o.seed, o.show), (400, 2024, 3));
        let Task::Stress(o) = parse("stress --pairs 50 --seed 7 --show 1") else {
            panic!()
        };
        assert_eq!((o.pairs, o.seed, o.show), (50, 7, 1));
        assert!(refused("stress --pairs 0").contains("at least 1"));
        assert!(refused("stress --bogus").contains("--bogus"));
    }

    #[test]
    fn verify_defaults_and_flags() {
        let Task::Verify(o) = parse("verify") else {
            panic!()
        };
        assert!(o.scene.is_none() && o.backend.is_none() && !o.no_stored && !o.quick);
        let Task::Verify(o) = parse("verify --scene bogie --backend gpgpu --no-stored --quick")
        else {
            panic!()
        };
        assert_eq!(o.scene.as_deref(), Some("bogie"));
        assert_eq!(o.backend.as_deref(), Some("gpgpu"));
        assert!(o.no_stored && o.quick);
        assert!(refused("verify --scene").contains("--scene"));
    }

    #[test]
    fn bench_tritri_as_the_readme_runs_it() {
        let Task::Bench {
            suite: Suite::Tritri(o),
        } = parse("bench tritri --pairs 5000 --reps 15")
        else {
            panic!()
        };
        assert_eq!((o.pairs, o.reps), (5000, 15));
        assert_eq!(o.out, PathBuf::from("testdata/bench"));
        let Task::Bench {
            suite: Suite::Tritri(o),
        } = parse("bench tritri --out /tmp/x")
        else {
            panic!()
        };
        assert_eq!(
            (o.pairs, o.reps, o.out),
            (5000, 15, PathBuf::from("/tmp/x"))
        );
        assert!(refused("bench tritri --reps 0").contains("at least 1"));
    }

    #[test]
    fn bench_image_lists() {
        let Task::Bench {
            suite: Suite::Image(o),
        } = parse("bench image")
        else {
            panic!()
        };
        assert_eq!(o.resolutions, [64, 128, 256, 512, 1024, 2048]);
        assert_eq!(o.runs, 5);
        assert!(o.out.ends_with("testdata/bench"));
        let Task::Bench {
            suite: Suite::Image(o),
        } = parse("bench image --resolutions 64,256 --runs 2 --out /tmp/i")
        else {
            panic!()
        };
        assert_eq!(o.resolutions, [64, 256]);
        assert_eq!((o.runs, o.out), (2, PathBuf::from("/tmp/i")));
    }

    #[test]
    fn bench_gpgpu_lists_and_counts() {
        let Task::Bench {
            suite: Suite::Gpgpu(o),
        } = parse("bench gpgpu")
        else {
            panic!()
        };
        assert_eq!(o.levels, [1, 2, 3, 4, 5]);
        assert_eq!(o.bodies, [1, 16, 256, 1024, 4096, 16384]);
        assert!(!o.boxes_only);
        assert_eq!(o.frames, [2, 8, 64]);
        assert_eq!((o.pairs, o.runs), (8, 5));
        assert!(o.out.ends_with("testdata/bench"));
        let Task::Bench {
            suite: Suite::Gpgpu(o),
        } = parse("bench gpgpu --frame-parts 64 --levels 2,3 --bodies 100,400 --pairs 2 --runs 1")
        else {
            panic!()
        };
        assert_eq!(o.frames, [64]);
        assert_eq!(o.levels, [2, 3]);
        assert_eq!(o.bodies, [100, 400]);
        assert_eq!((o.pairs, o.runs), (2, 1));
        let Task::Bench {
            suite: Suite::Gpgpu(o),
        } = parse("bench gpgpu --boxes-only --bodies 16384")
        else {
            panic!()
        };
        assert!(o.boxes_only);
        assert_eq!(o.bodies, [16384]);
        assert!(o.checker.is_empty());
        let Task::Bench {
            suite: Suite::Gpgpu(o),
        } = parse("bench gpgpu --checker-parts 16,64")
        else {
            panic!()
        };
        assert_eq!(o.checker, [16, 64]);
        assert_eq!(o.gpu_warmup_ms, None);
        let Task::Bench {
            suite: Suite::Gpgpu(o),
        } = parse("bench gpgpu --gpu-warmup-ms 0")
        else {
            panic!()
        };
        assert_eq!(o.gpu_warmup_ms, Some(0));
        assert!(refused("bench gpgpu --pairs 0").contains("at least 1"));
    }

    #[test]
    fn bench_hybrid_as_the_readme_runs_it() {
        let Task::Bench {
            suite: Suite::Hybrid(o),
        } = parse("bench hybrid --frames 600")
        else {
            panic!()
        };
        assert_eq!((o.frames, o.oracle_every), (600, 100));
        assert!(o.bogie.ends_with("testdata/bogie/scene.json"));
        assert!(o.cost.is_none());
        let Task::Bench {
            suite: Suite::Hybrid(o),
        } = parse("bench hybrid --cost c.json --bogie b.json --out o --oracle-every 0")
        else {
            panic!()
        };
        assert_eq!(o.cost, Some(PathBuf::from("c.json")));
        assert_eq!(o.bogie, PathBuf::from("b.json"));
        assert_eq!(o.out, PathBuf::from("o"));
        // 0 meant "every frame" before clap too: clamped to 1 by the task.
        assert_eq!(o.oracle_every, 0);
    }

    #[test]
    fn gen_bogie_and_fuzz() {
        let Task::GenBogie(o) = parse("gen-bogie") else {
            panic!()
        };
        assert!(o.out.ends_with("testdata/bogie"));
        let Task::GenBogie(o) = parse("gen-bogie --out /tmp/b") else {
            panic!()
        };
        assert_eq!(o.out, PathBuf::from("/tmp/b"));
        let Task::Fuzz(o) = parse("fuzz --seconds 60") else {
            panic!()
        };
        assert_eq!(o.seconds, 60);
        assert!(o.targets.is_empty());
        let Task::Fuzz(o) = parse("fuzz stl collide_oracle --seconds 5") else {
            panic!()
        };
        assert_eq!(o.targets, ["stl", "collide_oracle"]);
        assert_eq!(o.seconds, 5);
        assert!(refused("fuzz nonesuch").contains("nonesuch"));
        assert!(refused("fuzz --seconds 0").contains("at least 1"));
    }

    /// Every `cargo xtask ...` invocation written in the READMEs, docs, bench tables and CI
    /// script still parses (placeholders such as `N`, `[--out DIR]` or `a|b` are skipped).
    #[test]
    fn documented_invocations_parse() {
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
        let mut files = vec![
            root.join("README.md"),
            root.join(".ci/run"),
            root.join("API.md"),
        ];
        for dir in [
            "docs",
            "docs/performance",
            "testdata/bench",
            "fuzz",
            "crates/frcd-obb",
            "crates/frcd-gpgpu",
        ] {
            files.extend(
                std::fs::read_dir(root.join(dir))
                    .into_iter()
                    .flatten()
                    .map(|e| e.unwrap().path())
                    .filter(|p| p.extension().is_some_and(|x| x == "md")),
            );
        }
        for dir in std::fs::read_dir(root.join("crates")).unwrap() {
            files.push(dir.unwrap().path().join("README.md"));
        }
        let mut checked = 0;
        for f in files.iter().filter(|f| f.is_file()) {
            let text = std::fs::read_to_string(f).unwrap();
            for (i, _) in text.match_indices("cargo xtask ") {
                let rest = &text[i + "cargo xtask ".len()..];
                let end = rest
                    .find(['`', '#', ')', ';', '"', '\n'])
                    .unwrap_or(rest.len());
                let line = rest[..end].trim();
                let placeholder = |t: &str| {
                    t.contains(['[', '<', '|', '{'])
                        || t.chars()
                            .all(|c| c.is_ascii_uppercase() || c == ',' || c == '.')
                };
                if line.is_empty() || line.split_whitespace().any(placeholder) {
                    continue;
                }
                let argv = std::iter::once("cargo xtask").chain(line.split_whitespace());
                if let Err(e) = Cli::try_parse_from(argv) {
                    panic!(
                        "{}: `cargo xtask {line}` no longer parses: {e}",
                        f.display()
                    );
                }
                checked += 1;
            }
        }
        // README, CI and bench tables name at least stress, verify and every bench suite.
        assert!(checked >= 10, "only {checked} documented invocations found");
    }

    /// Every command has its own `--help` listing its options.
    #[test]
    fn every_command_has_help() {
        for (line, wants) in [
            (
                "stress --help",
                vec!["--pairs", "--seed", "--show", "[default: 400]"],
            ),
            (
                "verify --help",
                vec!["--scene", "--backend", "--no-stored", "--quick"],
            ),
            ("bench tritri --help", vec!["--pairs", "--reps", "--out"]),
            (
                "bench image --help",
                vec!["--resolutions", "--runs", "--out"],
            ),
            (
                "bench gpgpu --help",
                vec!["--levels", "--pairs", "--bodies", "--frame-parts", "--runs"],
            ),
            (
                "bench hybrid --help",
                vec!["--frames", "--bogie", "--cost", "--oracle-every"],
            ),
            ("gen-bogie --help", vec!["--out"]),
            ("fuzz --help", vec!["--seconds", "collide_oracle"]),
        ] {
            let argv = std::iter::once("cargo xtask").chain(line.split_whitespace());
            let err = Cli::try_parse_from(argv).expect_err("--help stops parsing");
            assert_eq!(err.kind(), clap::error::ErrorKind::DisplayHelp, "{line}");
            let text = err.to_string();
            for w in wants {
                assert!(text.contains(w), "`{line}` lacks {w}:\n{text}");
            }
        }
    }
}
