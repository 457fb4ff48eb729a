//! CPU-only: every crates/frcd-image/shaders/*.wgsl parses and validates with naga, and the crate embeds
//! every one of them.

use std::path::PathBuf;

fn shader_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("shaders")
}

#[test]
fn every_wgsl_file_validates_with_naga() {
    let mut files: Vec<PathBuf> = std::fs::read_dir(shader_dir())
        .expect("crates/frcd-image/shaders exists")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "wgsl"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no WGSL files found");
    for path in &files {
        let file = std::fs::read_to_string(path).unwrap();
        // Compiled with frcd-gpu's prelude in front (the shared structs).
        let src = frcd_gpu::with_prelude(&file);
        let module = naga::front::wgsl::parse_str(&src)
            .unwrap_or_else(|e| panic!("{}: {}", path.display(), e.emit_to_string(&src)));
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::default(),
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("{}: {}", path.display(), e.emit_to_string(&src)));
        let name = path.file_name().unwrap().to_str().unwrap();
        let embedded = frcd_image::SHADERS
            .iter()
            .find(|(n, _)| *n == name)
            .unwrap_or_else(|| panic!("{name} is not embedded in frcd_image::SHADERS"));
        // The crate embeds the file itself; the prelude is put in front when compiling.
        assert_eq!(
            embedded.1, file,
            "{name}: embedded copy differs from the file"
        );
    }
    assert_eq!(files.len(), frcd_image::SHADERS.len());
}
