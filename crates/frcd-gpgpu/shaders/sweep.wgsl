// frcd-gpgpu: sort-based sweep and prune over many bodies' world boxes (the rough colliding set
// in O(n log n + pairs)).
//
// Boxes arrive as in boxes.wgsl (outer and inner f32 corners rounded from f64), with the CPU's
// chosen sweep axis permuted into x. The passes, all in one compute pass:
//
//   keys:        key[p] = (x of outer lo as an order-preserving u32, body index p); padding
//                entries (p >= n, up to a power of two) are (0xffffffff, 0xffffffff).
//   sort_local:  bitonic sort network steps with j < BLOCK done in workgroup memory, one block
//                of BLOCK keys per workgroup (stage.k = 0: every step of k = 2..BLOCK; otherwise
//                the steps j = BLOCK/2 .. 1 of stage k).
//   sort_global: one step (k, j), j >= BLOCK, over the whole array.
//   gather:      sorted[p] = boxes[key[p].y], so the sweep reads boxes in sorted order.
//   sweep:       sorted box p scans q = p+1, p+2, .. while outer lo.x of q <= outer hi.x of p,
//                testing the outer boxes on all three axes; each pair is found once, by the
//                earlier box in sorted order. Output and the "uncertain" flag as in boxes.wgsl.
//                A round scans at most SWEEP_STEP candidates per box (see there): round r
//                (params.n.w) scans q from p + 1 + r SWEEP_STEP on, and a scan cut off by the
//                window sets count[1], so that the host runs round r + 1.
//
// Keys compare (key, index) lexicographically, so the order depends on the boxes only. The key
// order agrees with f32 order (-0 and +0 are equal floats with adjacent keys), so once the scan
// meets a q whose lo.x exceeds p's hi.x, every later q does too: no pair is missed. The f32
// comparisons are exact (no arithmetic), so WGSL's rounding latitude does not apply; but an
// implementation may flush subnormal operands to zero even in a comparison (NVIDIA's Vulkan
// driver does), so the packer (boxes.rs, body_box) stores no subnormal corner.

const UNCERTAIN_FLAG: u32 = 0x80000000u;
const PAD_KEY: u32 = 0xffffffffu;
// Workgroup size; BLOCK keys per workgroup in sort_local (must match sweep.rs).
const WG: u32 = 64u;
const BLOCK: u32 = 128u;
// Candidates one invocation scans per round. llvmpipe (Mesa's gallivm, the software driver)
// ends every loop of a shader invocation once all its loops together have run 65,535
// iterations (LP_MAX_TGSI_LOOP_ITERATIONS), silently: one box whose x range reached past
// 65,536 others lost its pairs there (measured 2026-12-02). A round stays far below that; a
// longer scan continues in the next round.
const SWEEP_STEP: u32 = 16384u;

// BodyBox, BoxParams and SortStage come from the prelude (frcd-gpu).
// params.n: body count, output capacity, padded count (power of two, >= BLOCK), sweep round.

@group(0) @binding(0) var<storage, read> boxes: array<BodyBox>;
@group(0) @binding(1) var<storage, read_write> out_pairs: array<vec2<u32>>;
// [0]: pairs found (past the output's capacity only counted); [1]: nonzero when a scan of
// this round was cut off by its window (another round is needed).
@group(0) @binding(2) var<storage, read_write> count: array<atomic<u32>, 2>;
@group(0) @binding(3) var<uniform> params: BoxParams;
@group(0) @binding(4) var<storage, read_write> keys: array<vec2<u32>>;
@group(0) @binding(5) var<storage, read_write> sorted: array<BodyBox>;
@group(0) @binding(6) var<uniform> stage: SortStage;

var<workgroup> block: array<vec2<u32>, 128>;

// Order-preserving map of a non-NaN f32 to u32.
fn order_key(x: f32) -> u32 {
    let b = bitcast<u32>(x);
    if (b & 0x80000000u) != 0u {
        return ~b;
    }
    return b | 0x80000000u;
}

fn key_less(a: vec2<u32>, b: vec2<u32>) -> bool {
    return a.x < b.x || (a.x == b.x && a.y < b.y);
}

fn meet(alo: vec3<f32>, ahi: vec3<f32>, blo: vec3<f32>, bhi: vec3<f32>) -> bool {
    return all(alo <= bhi) && all(blo <= ahi);
}

@compute @workgroup_size(64)
fn make_keys(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = gid.x;
    if p >= params.n.z {
        return;
    }
    if p < params.n.x {
        keys[p] = vec2<u32>(order_key(boxes[p].lo_dn.x), p);
    } else {
        keys[p] = vec2<u32>(PAD_KEY, PAD_KEY);
    }
}

// Compare-exchange of local slots i < l, ascending when bit k of the global index is clear.
fn local_step(base: u32, t: u32, k: u32, j: u32) {
    let i = 2u * j * (t / j) + (t % j);
    let l = i + j;
    let up = ((base + i) & k) == 0u;
    let a = block[i];
    let b = block[l];
    if key_less(b, a) == up {
        block[i] = b;
        block[l] = a;
    }
}

@compute @workgroup_size(64)
fn sort_local(@builtin(workgroup_id) wid: vec3<u32>,
              @builtin(local_invocation_index) lid: u32) {
    let base = wid.x * BLOCK;
    block[lid] = keys[base + lid];
    block[lid + WG] = keys[base + lid + WG];
    workgroupBarrier();
    let k_stage = stage.kj.x;
    if k_stage == 0u {
        for (var k = 2u; k <= BLOCK; k = k * 2u) {
            for (var j = k / 2u; j > 0u; j = j / 2u) {
                local_step(base, lid, k, j);
                workgroupBarrier();
            }
        }
    } else {
        for (var j = BLOCK / 2u; j > 0u; j = j / 2u) {
            local_step(base, lid, k_stage, j);
            workgroupBarrier();
        }
    }
    keys[base + lid] = block[lid];
    keys[base + lid + WG] = block[lid + WG];
}

@compute @workgroup_size(64)
fn sort_global(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = gid.x;
    if t >= params.n.z / 2u {
        return;
    }
    let k = stage.kj.x;
    let j = stage.kj.y;
    let i = 2u * j * (t / j) + (t % j);
    let l = i + j;
    let up = (i & k) == 0u;
    let a = keys[i];
    let b = keys[l];
    if key_less(b, a) == up {
        keys[i] = b;
        keys[l] = a;
    }
}

@compute @workgroup_size(64)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = gid.x;
    if p < params.n.x {
        sorted[p] = boxes[keys[p].y];
    }
}

@compute @workgroup_size(64)
fn sweep(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = gid.x;
    let n = params.n.x;
    if p >= n {
        return;
    }
    // This round's window of candidates (n < 2^31 and rounds <= n / SWEEP_STEP + 1: no wrap).
    let start = p + 1u + params.n.w * SWEEP_STEP;
    if start >= n {
        return;
    }
    let end = min(n, start + SWEEP_STEP);
    let a = sorted[p];
    let ia = keys[p].y;
    let reach = a.hi_up.x;
    var q = start;
    loop {
        if q >= end {
            break;
        }
        let b = sorted[q];
        if b.lo_dn.x > reach {
            return;
        }
        if meet(a.lo_dn.xyz, a.hi_up.xyz, b.lo_dn.xyz, b.hi_up.xyz) {
            let sure = meet(a.lo_up.xyz, a.hi_dn.xyz, b.lo_up.xyz, b.hi_dn.xyz);
            let ib = keys[q].y;
            let slot = atomicAdd(&count[0], 1u);
            if slot < params.n.y {
                var tag = max(ia, ib);
                if !sure {
                    tag = tag | UNCERTAIN_FLAG;
                }
                out_pairs[slot] = vec2<u32>(min(ia, ib), tag);
            }
        }
        continuing {
            q = q + 1u;
        }
    }
    // Cut off by the window with candidates left: the next round goes on from `end`.
    if end < n {
        atomicMax(&count[1], 1u);
    }
}
