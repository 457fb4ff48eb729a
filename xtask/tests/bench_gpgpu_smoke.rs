//! `cargo xtask bench gpgpu` end to end at its smallest sizes: the pair queries (one query per
//! body pair and one batch per step, each checked equal to the CPU inside the bench), a frame
//! and the box pass run, and the table carries every column. Without a GPU adapter: SKIP,
//! unless `FRCD_REQUIRE_GPU=1`.

use std::process::Command;

mod common;
use common::TempDir;

#[test]
fn bench_gpgpu_runs_and_writes_every_column() {
    let out = TempDir(
        std::env::temp_dir().join(format!("frcd-bench-gpgpu-smoke-{}", std::process::id())),
    );
    let run = Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args([
            "bench", "gpgpu", "--levels", "1,2", "--pairs", "2", "--runs", "1",
        ])
        .args(["--frame-parts", "2", "--bodies", "2,40", "--out"])
        .arg(&*out)
        .output()
        .expect("xtask runs");
    let text =
        String::from_utf8_lossy(&run.stdout).to_string() + &String::from_utf8_lossy(&run.stderr);
    if !run.status.success() && text.contains("needs a GPU adapter") {
        assert!(
            std::env::var("FRCD_REQUIRE_GPU").as_deref() != Ok("1"),
            "FRCD_REQUIRE_GPU=1 but no adapter: {text}"
        );
        println!("SKIP bench gpgpu smoke: no GPU adapter");
        return;
    }
    assert!(run.status.success(), "bench gpgpu failed: {text}");
    let md = std::fs::read_to_string(out.join("gpgpu.md")).expect("table written");
    for column in [
        "GPU ms (transfers incl.)",
        "GPU batch ms",
        "batch / CPU 1",
        "upload ms / mesh",
    ] {
        assert!(md.contains(column), "missing column {column}:\n{md}");
    }
    // Two pair rows (levels 1 and 2), twelve cells each.
    let rows: Vec<&str> = md
        .lines()
        .filter(|l| l.starts_with("| 1 | 80 |") || l.starts_with("| 2 | 320 |"))
        .collect();
    assert_eq!(rows.len(), 2, "{md}");
    for r in rows {
        assert_eq!(r.matches('|').count(), 13, "{r}");
    }
}
