//! The cherry-pick proof: what an engine compiles when it takes frcd-tritri contains neither
//! wgpu nor serde (`cargo tree` of this crate's normal and build dependencies).

use std::collections::BTreeSet;
use std::process::Command;

fn dependency_closure() -> BTreeSet<String> {
    let out = Command::new(env!("CARGO"))
        .args(["tree", "--locked", "-p", env!("CARGO_PKG_NAME")])
        .args(["-e", "normal,build", "--prefix", "none", "--format", "{p}"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("cargo runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "cargo tree failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Lines look like "glam v0.30.10" or "frcd-geom v0.1.0 (/path)": keep the name.
    stdout
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .map(str::to_owned)
        .collect()
}

#[test]
fn cargo_tree_has_neither_wgpu_nor_serde() {
    let names = dependency_closure();
    // The tree is real: the crate it cherry-picks and the geometry underneath are in it.
    for needed in ["frcd-tritri", "frcd-geom", "glam"] {
        assert!(names.contains(needed), "{needed} missing from {names:?}");
    }
    let banned: Vec<&String> = names
        .iter()
        .filter(|n| n.starts_with("wgpu") || n.starts_with("naga") || n.starts_with("serde"))
        .collect();
    assert!(
        banned.is_empty(),
        "an engine taking frcd-tritri compiles {banned:?}"
    );
    // The narrow phase alone brings no thread pool either.
    assert!(!names.contains("rayon"), "{names:?}");
    assert!(!names.contains("frcd-obb"), "{names:?}");
}
