//! Helpers shared by the CLI test binaries: run the built `frcd` (killed after a time limit, so
//! a hang fails instead of sticking), format its output, and make a fresh folder per test
//! (removed when the test ends).
#![allow(dead_code)] // each test binary uses a subset

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

pub fn frcd(args: &[&str], dir: &Path) -> Output {
    run_with_timeout(args, dir, Duration::from_secs(120))
}

/// Runs frcd, killing it after `limit` (a hang is a failure, not a stuck test).
pub fn run_with_timeout(args: &[&str], dir: &Path, limit: Duration) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_frcd"))
        .args(args)
        .current_dir(dir)
        .env_remove("FRCD_COST_MODEL")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run frcd");
    let t0 = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if t0.elapsed() > limit {
            child.kill().ok();
            let o = child.wait_with_output().unwrap();
            panic!(
                "frcd {args:?} hung for {limit:?}\nstderr: {}",
                String::from_utf8_lossy(&o.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

pub fn text(o: &Output) -> String {
    format!(
        "status {:?}\nstdout:\n{}\nstderr:\n{}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

pub fn assert_clean_failure(o: &Output, needle: &str) {
    let t = text(o);
    assert!(!o.status.success(), "{t}");
    assert!(!t.contains("panicked"), "{t}");
    assert!(t.contains(needle), "expected '{needle}' in:\n{t}");
}

/// A fresh folder in the system temp folder, unique to the test binary, this process and
/// `name`, removed with everything in it when the guard drops: at the end of the test, pass or
/// fail.
pub struct TempDir(PathBuf);

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TempDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

pub fn tempdir(name: &str) -> TempDir {
    let d = TempDir(std::env::temp_dir().join(format!(
        "frcd-{}-{name}-{}",
        env!("CARGO_CRATE_NAME"),
        std::process::id()
    )));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}
