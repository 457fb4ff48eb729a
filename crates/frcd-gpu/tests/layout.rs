//! CPU only: the prelude validates with naga, and every `#[repr(C)]` mirror in
//! `frcd_gpu::layout` matches naga's reflection of its WGSL struct (size, member names, offsets,
//! member sizes); every struct of the prelude has a mirror.

fn module() -> naga::Module {
    let src = frcd_gpu::PRELUDE;
    let module = naga::front::wgsl::parse_str(src)
        .unwrap_or_else(|e| panic!("prelude: {}", e.emit_to_string(src)));
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::default(),
    )
    .validate(&module)
    .unwrap_or_else(|e| panic!("prelude: {}", e.emit_to_string(src)));
    module
}

#[test]
fn mirrors_match_naga_reflection() {
    let module = module();
    let mut structs = std::collections::BTreeMap::new();
    for (_, ty) in module.types.iter() {
        if let naga::TypeInner::Struct { members, span } = &ty.inner {
            structs.insert(
                ty.name.clone().unwrap_or_default(),
                (members.clone(), *span),
            );
        }
    }
    let mirrors = frcd_gpu::layout::mirrors();
    assert_eq!(
        mirrors
            .iter()
            .map(|m| m.0.to_string())
            .collect::<std::collections::BTreeSet<_>>(),
        structs.keys().cloned().collect(),
        "every prelude struct has exactly one mirror"
    );
    let mut layouter = naga::proc::Layouter::default();
    layouter.update(module.to_ctx()).expect("layout");
    for (name, size, fields) in mirrors {
        let (members, span) = &structs[name];
        assert_eq!(*span as usize, size, "{name}: size");
        assert_eq!(members.len(), fields.len(), "{name}: member count");
        for (m, (fname, off, fsize)) in members.iter().zip(&fields) {
            assert_eq!(m.name.as_deref(), Some(*fname), "{name}: member order");
            assert_eq!(m.offset as usize, *off, "{name}.{fname}: offset");
            assert_eq!(layouter[m.ty].size as usize, *fsize, "{name}.{fname}: size");
        }
    }
}

#[test]
fn a_drifted_mirror_would_be_caught() {
    // The comparison above can fail: a struct with one member moved has other offsets.
    let src = "struct State { next: atomic<u32>, cur: u32 }";
    let module = naga::front::wgsl::parse_str(src).unwrap();
    let members = module
        .types
        .iter()
        .find_map(|(_, ty)| match &ty.inner {
            naga::TypeInner::Struct { members, .. } => Some(members.clone()),
            _ => None,
        })
        .expect("a struct");
    let (_, _, fields) = &frcd_gpu::layout::mirrors()[0];
    assert_ne!(members[0].name.as_deref(), Some(fields[0].0));
}
