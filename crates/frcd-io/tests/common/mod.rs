//! Helpers shared by frcd-io's test binaries.
#![allow(dead_code)] // each test binary uses a subset

use std::path::{Path, PathBuf};

/// A fresh, empty folder in the system temp folder, `frcd-io-<prefix>-<process>-<name>`
/// (unique to this process and test), removed with everything in it when the guard drops: at
/// the end of the test, pass or fail.
pub struct TempDir(PathBuf);

impl TempDir {
    pub fn new(prefix: &str, name: &str) -> TempDir {
        let dir = TempDir(
            std::env::temp_dir().join(format!("frcd-io-{prefix}-{}-{name}", std::process::id())),
        );
        // A folder of the same name left by a killed run is cleared first.
        let _ = std::fs::remove_dir_all(&dir.0);
        std::fs::create_dir_all(&dir.0).unwrap();
        dir
    }
}

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
