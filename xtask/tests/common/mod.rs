//! Helpers shared by xtask's test binaries.
#![allow(dead_code)] // each test binary uses a subset

use std::path::{Path, PathBuf};

/// A folder removed with everything in it when the guard drops: at the end of the test, pass,
/// fail or skip.
pub struct TempDir(pub PathBuf);

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
