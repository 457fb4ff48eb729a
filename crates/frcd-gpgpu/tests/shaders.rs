//! CPU-only: every WGSL file in crates/frcd-gpgpu/shaders parses and validates with naga, and the crate
//! embeds each of them.

use std::path::PathBuf;

fn validate(name: &str, src: &str) {
    // Every file is compiled with frcd-gpu's prelude in front (the shared structs).
    let src = &frcd_gpu::with_prelude(src);
    let module = naga::front::wgsl::parse_str(src)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::default(),
    )
    .validate(&module)
    .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
}

#[test]
fn every_wgsl_file_validates_with_naga() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("shaders");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("crates/frcd-gpgpu/shaders exists")
        .map(|e| e.expect("readable entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "wgsl"))
        .collect();
    files.sort();
    assert!(files.len() >= 3, "{files:?}");
    for path in &files {
        let src = std::fs::read_to_string(path).expect("readable shader");
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        validate(&name, &src);
        // The crate compiles in exactly this text.
        let embedded = frcd_gpgpu::shaders::ALL
            .iter()
            .find(|(n, _)| *n == name)
            .unwrap_or_else(|| panic!("{name} is not embedded in frcd_gpgpu::shaders::ALL"));
        assert_eq!(embedded.1, src, "{name}");
    }
}

#[test]
fn a_broken_shader_is_rejected() {
    // The check above can fail: a type error must be caught by the validator.
    let src = "@compute @workgroup_size(1) fn main() { let x: u32 = 1.5; }";
    let parsed = naga::front::wgsl::parse_str(src);
    assert!(parsed.is_err());
}
