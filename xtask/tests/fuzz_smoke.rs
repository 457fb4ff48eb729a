//! Fuzz smoke test on the stable toolchain (issue 11): the coverage-guided targets in `fuzz/`
//! need nightly and cargo-fuzz, which CI cannot count on, so this test runs their bodies (the
//! same functions, `fuzz/src/lib.rs`, included below) on
//!
//! 1. every committed seed (`fuzz/seeds/<target>/`) and regression input
//!    (`fuzz/regressions/<target>/`), and
//! 2. deterministic random mutations of those inputs (bit flips, interesting bytes, byte
//!    inserts and deletes, chunk duplication, splices with another input of the same target),
//!    `FRCD_FUZZ_SMOKE_MUTATIONS` per target (default 2000).
//!
//! Each body asserts the target's own invariants (a loaded mesh is valid; a scene round-trips;
//! `collide` equals the exact oracle ...). A panic is caught, its input written to
//! `$TMPDIR/frcd-fuzz-smoke/<target>-<n>` and the test fails naming it; copy such a file into
//! `fuzz/regressions/<target>/` once fixed. The mutator is a fixed-seed xorshift, so a failure
//! reproduces exactly.

#[path = "../../fuzz/src/lib.rs"]
mod bodies;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

mod common;
use common::TempDir;

/// Inputs grow by inserts and splices; the parsers' interesting structure is near the start.
const MAX_LEN: usize = 4096;

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz")
}

/// xorshift64* (Vigna): tiny, deterministic, good enough to pick mutations.
struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform enough in `0..n` (n > 0).
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// Bytes that parsers and the binary decoders treat specially.
const INTERESTING: [u8; 16] = [
    0, 1, 0x7f, 0x80, 0xff, b'\n', b'\r', b' ', b',', b'-', b'.', b'0', b'9', b'e', b'"', b'/',
];

/// One to four mutations of `input`; `others` are the target's other inputs (for splices).
fn mutate(rng: &mut XorShift, input: &[u8], others: &[Vec<u8>]) -> Vec<u8> {
    let mut v = input.to_vec();
    for _ in 0..1 + rng.below(4) {
        match rng.below(7) {
            0 if !v.is_empty() => {
                let i = rng.below(v.len());
                v[i] ^= 1 << rng.below(8);
            }
            1 if !v.is_empty() => {
                let i = rng.below(v.len());
                v[i] = INTERESTING[rng.below(INTERESTING.len())];
            }
            2 => {
                let i = rng.below(v.len() + 1);
                v.insert(i, rng.next() as u8);
            }
            3 if !v.is_empty() => {
                let i = rng.below(v.len());
                let n = 1 + rng.below(8.min(v.len() - i));
                v.drain(i..i + n);
            }
            4 if !v.is_empty() => {
                // Duplicate a chunk in place (repeated lines, facets, records).
                let i = rng.below(v.len());
                let n = 1 + rng.below(32.min(v.len() - i));
                let chunk = v[i..i + n].to_vec();
                let at = rng.below(v.len() + 1);
                v.splice(at..at, chunk);
            }
            5 if !others.is_empty() => {
                // Splice: our head, another input's tail.
                let o = &others[rng.below(others.len())];
                let cut = rng.below(v.len() + 1);
                let from = rng.below(o.len() + 1);
                v.truncate(cut);
                v.extend_from_slice(&o[from..]);
            }
            6 if !v.is_empty() => {
                // Truncate: files cut short.
                let n = rng.below(v.len());
                v.truncate(n);
            }
            _ => v.push(rng.next() as u8),
        }
    }
    v.truncate(MAX_LEN);
    v
}

/// The files of `dir`, sorted by name (empty when the folder does not exist).
fn inputs(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = entries
        .map(|e| e.expect("reading a fuzz input folder").path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    files
        .into_iter()
        .map(|p| {
            let bytes = std::fs::read(&p).expect("reading a fuzz input");
            (p.display().to_string(), bytes)
        })
        .collect()
}

/// Where a failing input is saved for the developer to pick up (kept on purpose).
fn saved_inputs_dir() -> PathBuf {
    std::env::temp_dir().join("frcd-fuzz-smoke")
}

/// Runs `body` on `data`; on a panic, saves the input in `dir` and returns a line naming it.
fn run_one(
    dir: &Path,
    target: &str,
    body: bodies::Body,
    data: &[u8],
    origin: &str,
    n: usize,
) -> Option<String> {
    if catch_unwind(AssertUnwindSafe(|| body(data))).is_ok() {
        return None;
    }
    let path = dir.join(format!("{target}-{n}"));
    let saved = std::fs::create_dir_all(dir)
        .and_then(|()| std::fs::write(&path, data))
        .map_or_else(
            |e| format!("(not saved: {e})"),
            |()| path.display().to_string(),
        );
    Some(format!(
        "{target}: input {n} ({origin}) panicked; input saved to {saved}"
    ))
}

#[test]
fn every_seed_regression_and_mutation_passes_its_target() {
    let mutations: usize = std::env::var("FRCD_FUZZ_SMOKE_MUTATIONS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2000);
    let mut failures = Vec::new();
    let mut total = 0usize;
    let saved_inputs = saved_inputs_dir();
    for (ti, (target, body)) in bodies::TARGETS.into_iter().enumerate() {
        let seeds = inputs(&fuzz_dir().join("seeds").join(target));
        assert!(!seeds.is_empty(), "fuzz/seeds/{target} has no seed");
        let regressions = inputs(&fuzz_dir().join("regressions").join(target));
        let corpus: Vec<(String, Vec<u8>)> = seeds.into_iter().chain(regressions).collect();
        let mut n = 0usize;
        for (origin, data) in &corpus {
            failures.extend(run_one(&saved_inputs, target, body, data, origin, n));
            n += 1;
        }
        let pool: Vec<Vec<u8>> = corpus.iter().map(|(_, d)| d.clone()).collect();
        let mut rng = XorShift(0x9E37_79B9_7F4A_7C15 ^ (ti as u64 + 1));
        for _ in 0..mutations {
            let k = rng.below(pool.len());
            // Stack mutations now and then: a mutant of a mutant reaches further.
            let mut data = mutate(&mut rng, &pool[k], &pool);
            if rng.below(4) == 0 {
                data = mutate(&mut rng, &data, &pool);
            }
            let origin = format!("mutation of {}", corpus[k].0);
            failures.extend(run_one(&saved_inputs, target, body, &data, &origin, n));
            n += 1;
        }
        total += n;
        println!("{target}: {n} inputs");
    }
    assert!(
        failures.is_empty(),
        "{} of {total} fuzz inputs failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// The cargo-fuzz side stays in step with the bodies: one `[[bin]]` and one one-line target
/// file per body, calling it, `cargo xtask fuzz` running it, and no seed folder for a target
/// that does not exist.
#[test]
fn fuzz_targets_call_the_shared_bodies() {
    let manifest = std::fs::read_to_string(fuzz_dir().join("Cargo.toml")).unwrap();
    let names: Vec<&str> = bodies::TARGETS.iter().map(|(n, _)| *n).collect();
    for name in &names {
        assert!(
            manifest.contains(&format!("name = \"{name}\"")),
            "fuzz/Cargo.toml has no [[bin]] {name}"
        );
        let src = std::fs::read_to_string(fuzz_dir().join(format!("fuzz_targets/{name}.rs")))
            .unwrap_or_else(|e| panic!("fuzz_targets/{name}.rs: {e}"));
        assert!(
            src.contains(&format!("frcd_fuzz::{name}(data)")),
            "fuzz_targets/{name}.rs does not call frcd_fuzz::{name}"
        );
    }
    // `cargo xtask fuzz` runs them all (its list is text in the binary, checked here).
    let task =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("src/fuzz.rs")).unwrap();
    for name in &names {
        assert!(
            task.contains(&format!("\"{name}\",")),
            "xtask fuzz does not run {name}"
        );
    }
    for folder in ["seeds", "regressions"] {
        for e in std::fs::read_dir(fuzz_dir().join(folder)).unwrap() {
            let name = e.unwrap().file_name().to_string_lossy().into_owned();
            assert!(
                names.contains(&name.as_str()),
                "fuzz/{folder}/{name}: no such target"
            );
        }
    }
}

/// A body that panics is caught, reported with its origin, and its input saved.
#[test]
fn a_panic_is_reported_and_its_input_saved() {
    fn picky(data: &[u8]) {
        assert!(!data.contains(&0xAB), "0xAB found");
    }
    // A folder of this test's own (not the shared one a developer may be collecting failing
    // inputs in), removed when the test ends, pass or fail.
    let dir =
        TempDir(std::env::temp_dir().join(format!("frcd-fuzz-smoke-{}-picky", std::process::id())));
    let _ = std::fs::remove_dir_all(&*dir);
    assert_eq!(run_one(&dir, "picky", picky, b"fine", "seed", 0), None);
    assert!(!dir.exists(), "an input that passes is not saved");
    let line = run_one(&dir, "picky", picky, &[1, 0xAB, 2], "mutation of seed", 7).unwrap();
    assert!(
        line.contains("picky: input 7 (mutation of seed) panicked"),
        "{line}"
    );
    let saved = dir.join("picky-7");
    assert!(
        line.ends_with(&format!("input saved to {}", saved.display())),
        "{line}"
    );
    assert_eq!(std::fs::read(&saved).unwrap(), [1, 0xAB, 2]);
}

/// The mutator is deterministic and exercises every kind of edit.
#[test]
fn mutator_is_deterministic_and_varied() {
    let seed = b"solid x\nfacet normal 0 0 1\nendsolid x\n".to_vec();
    let pool = vec![seed.clone(), b"v 0 0 0\n".to_vec()];
    let run = || {
        let mut rng = XorShift(7);
        (0..200)
            .map(|_| mutate(&mut rng, &seed, &pool))
            .collect::<Vec<_>>()
    };
    let a = run();
    assert_eq!(a, run());
    assert!(a.iter().any(|m| m.len() > seed.len()));
    assert!(a.iter().any(|m| m.len() < seed.len()));
    assert!(a.iter().any(|m| m.len() == seed.len() && *m != seed));
    assert!(a.iter().all(|m| m.len() <= MAX_LEN));
}
