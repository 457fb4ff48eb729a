// frcd-image: rasterization passes of the image-space detector.
//
// One pipeline per role, all sharing `vs_main`:
// - peel   (`fs_peel`): renders one mesh with depth test Less and depth write, discarding every
//   fragment not strictly behind the previous layer, so the depth buffer ends up holding the
//   next surface layer; the colour target records whether that layer's face is front facing.
// - parity (`fs_parity`, colour writes off): renders the other mesh against that depth with test
//   Less, no depth write, stencil op Invert on bit 0: afterwards bit 0 of the stencil is the
//   parity of the other mesh's faces in front of the layer, i.e. 1 iff the layer's surface
//   point is inside the other solid (Knott & Pai's CInDeR "virtual ray casting").

// Draw comes from the prelude (frcd-gpu).

@group(0) @binding(0) var<uniform> draw: Draw;
// Depth of the previous peeled layer (or of the overlap region's near face for the first layer).
@group(1) @binding(0) var prev_depth: texture_depth_2d;

struct VsOut {
    // Invariant: the peel and parity pipelines must place every vertex identically, or the
    // rasterizer's watertight edge rule would not hold between them.
    @builtin(position) @invariant pos: vec4<f32>,
};

@vertex
fn vs_main(@location(0) p: vec3<f32>) -> VsOut {
    var out: VsOut;
    out.pos = draw.clip_from_local * vec4<f32>(p, 1.0);
    return out;
}

@fragment
fn fs_peel(@builtin(position) pos: vec4<f32>, @builtin(front_facing) front: bool) -> @location(0) u32 {
    let prev = textureLoad(prev_depth, vec2<i32>(floor(pos.xy)), 0);
    // Float depth is stored exactly, so "strictly behind" never peels the same layer twice.
    if (pos.z <= prev) {
        discard;
    }
    return select(2u, 1u, front);
}

@fragment
fn fs_parity() -> @location(0) u32 {
    return 0u;
}
