// frcd-image: per-pixel resolve of one peeled layer.
//
// For every pixel holding a fragment of the peeled mesh X (depth < 1), bit 0 of the stencil says
// whether that surface point is inside the other solid Y. If so the pixel interferes, and the
// point's depth is added to the pixel's inside-both length with the sign of the crossing: an
// entering face (the ray enters X there) starts an interval of X ∩ Y, a leaving face ends one.
// Summed over every layer of both meshes this is the exact length of the ray inside X ∩ Y.

// ResolveParams comes from the prelude (frcd-gpu).

@group(0) @binding(0) var<uniform> params: ResolveParams;
@group(0) @binding(1) var layer_depth: texture_depth_2d;
@group(0) @binding(2) var layer_stencil: texture_2d<u32>;
@group(0) @binding(3) var layer_facing: texture_2d<u32>;
@group(0) @binding(4) var<storage, read_write> lengths: array<f32>;
@group(0) @binding(5) var<storage, read_write> mask: array<u32>;
// [0]: pixels holding a fragment of this layer (0 ends the peeling), [1]: of those, inside Y.
@group(0) @binding(6) var<storage, read_write> counters: array<atomic<u32>, 2>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= params.width || gid.y >= params.height) {
        return;
    }
    let px = vec2<i32>(gid.xy);
    let d = textureLoad(layer_depth, px, 0);
    if (d >= 1.0) {
        return;
    }
    atomicAdd(&counters[0], 1u);
    if ((textureLoad(layer_stencil, px, 0).r & 1u) == 0u) {
        return;
    }
    atomicAdd(&counters[1], 1u);
    let i = gid.y * params.width + gid.x;
    mask[i] = 1u;
    let z = (d - params.depth_ref) * params.depth_scale;
    let entering = textureLoad(layer_facing, px, 0).r == params.entering_code;
    lengths[i] = lengths[i] + select(z, -z, entering);
}
