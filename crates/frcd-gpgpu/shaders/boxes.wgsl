// frcd-gpgpu: all-pairs overlap of many bodies' world boxes (the rough colliding set).
//
// Each box arrives as four f32 corners rounded from f64: (lo rounded down, hi rounded up) contain
// the f64 box, (lo rounded up, hi rounded down) are contained in it. Comparing the outer corners
// can only add pairs; comparing the inner ones can only drop pairs. A pair whose outer boxes meet
// is appended, flagged "uncertain" unless the inner boxes meet too; the CPU re-checks flagged
// pairs in f64, so the final set equals the f64 all-pairs answer. No corner is subnormal (the
// packer moves such values outward or inward to zero or the smallest normal), because a GPU may
// flush subnormal comparison operands to zero: on an H200, planes at z = 1e-300 and 2e-300 were
// "surely" overlapping before.
//
// Workgroup (x, y) compares the 64 boxes i of tile x with the 64 boxes j of tile y (j > i), the
// j tile staged in workgroup memory: one invocation per i, 64 comparisons each.

const UNCERTAIN_FLAG: u32 = 0x80000000u;

// BodyBox and BoxParams come from the prelude (frcd-gpu).

@group(0) @binding(0) var<storage, read> boxes: array<BodyBox>;
@group(0) @binding(1) var<storage, read_write> out_pairs: array<vec2<u32>>;
@group(0) @binding(2) var<storage, read_write> count: atomic<u32>;
@group(0) @binding(3) var<uniform> params: BoxParams;

const TILE: u32 = 64u;

var<workgroup> tile: array<BodyBox, 64>;

fn meet(alo: vec3<f32>, ahi: vec3<f32>, blo: vec3<f32>, bhi: vec3<f32>) -> bool {
    return all(alo <= bhi) && all(blo <= ahi);
}

@compute @workgroup_size(64)
fn overlap(@builtin(workgroup_id) wid: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let n = params.n.x;
    let i0 = wid.x * TILE;
    let j0 = wid.y * TILE;
    // Whole-workgroup exits only (uniform), before the barrier: no j > i in this tile pair.
    if i0 >= n || j0 >= n || j0 + TILE <= i0 + 1u {
        return;
    }
    let jl = j0 + lid;
    if jl < n {
        tile[lid] = boxes[jl];
    }
    workgroupBarrier();
    let i = i0 + lid;
    if i >= n {
        return;
    }
    let a = boxes[i];
    let j_end = min(j0 + TILE, n);
    for (var j = max(j0, i + 1u); j < j_end; j++) {
        let b = tile[j - j0];
        if !meet(a.lo_dn.xyz, a.hi_up.xyz, b.lo_dn.xyz, b.hi_up.xyz) {
            continue;
        }
        let sure = meet(a.lo_up.xyz, a.hi_dn.xyz, b.lo_up.xyz, b.hi_dn.xyz);
        let slot = atomicAdd(&count, 1u);
        if slot < params.n.y {
            var tag = j;
            if !sure {
                tag = j | UNCERTAIN_FLAG;
            }
            out_pairs[slot] = vec2<u32>(i, tag);
        }
    }
}
