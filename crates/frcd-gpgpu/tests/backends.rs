//! No wgpu backend is forced on an engine: `cargo tree` of frcd-gpgpu's normal dependencies
//! enables the native backends by default and none with `--no-default-features` (the engine's
//! own wgpu features then decide). CPU only.

use std::collections::BTreeSet;
use std::process::Command;

/// The wgpu features enabled for frcd-gpgpu's normal dependencies.
fn wgpu_features(extra: &[&str]) -> BTreeSet<String> {
    let out = Command::new(env!("CARGO"))
        .args(["tree", "--locked", "-p", env!("CARGO_PKG_NAME")])
        .args(extra)
        .args(["-e", "features,normal", "-i", "wgpu", "--prefix", "none"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("cargo runs");
    assert!(
        out.status.success(),
        "cargo tree failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Lines look like `wgpu feature "vulkan"`.
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.strip_prefix("wgpu feature \""))
        .filter_map(|l| l.split('"').next())
        .map(str::to_owned)
        .collect()
}

#[test]
fn backends_are_passed_through_not_forced() {
    let set = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<BTreeSet<_>>();
    assert_eq!(
        wgpu_features(&[]),
        set(&["dx12", "metal", "std", "vulkan", "wgsl"])
    );
    assert_eq!(
        wgpu_features(&["--no-default-features"]),
        set(&["std", "wgsl"])
    );
    assert_eq!(
        wgpu_features(&["--no-default-features", "--features", "gles"]),
        set(&["gles", "std", "wgsl"])
    );
}
