// frcd-gpgpu: single-invocation control passes of the breadth-first traversal.
//
// `init` starts a batch: the CPU wrote the root pair of every body pair into frontier 0.
// `prepare_tris` runs after the last level: the arguments of the `triangles` pass (one
// invocation per listed triangle pair). Between levels no control pass runs: each level
// writes the next level's indirect arguments itself (`traverse`, traverse.wgsl). All run
// inside the query's one submission.

const WG: u32 = 64u;

// State and Params come from the prelude (frcd-gpu).

@group(0) @binding(0) var<storage, read_write> state: State;
@group(0) @binding(1) var<storage, read_write> args: array<u32, 3>;
@group(0) @binding(2) var<uniform> params: Params;

// Indirect arguments for `m` invocations: ceil(m / WG) workgroups as an x × y grid.
fn set_args(m: u32) {
    let groups = (m + WG - 1u) / WG;
    let x = min(groups, params.caps.z);
    var y = 0u;
    if x > 0u {
        y = (groups + x - 1u) / x;
    }
    args[0] = x;
    args[1] = y;
    args[2] = 1u;
}

// The CPU wrote the batch's root pairs (k, ONE_NODE | 0, ONE_NODE | 0) into frontier 0 (at most
// its capacity), and (1, 1, 1) into the indirect arguments of levels 1 and 2 (`traverse` raises
// them). A level runs one invocation per entry (`traverse`).
@compute @workgroup_size(1)
fn init() {
    let n = params.caps.w;
    let m = min(n, params.caps.x);
    atomicStore(&state.counts[0], m);
    atomicStore(&state.counts[1], 0u);
    atomicStore(&state.counts[2], 0u);
    atomicStore(&state.out, 0u);
    atomicStore(&state.tris, 0u);
    atomicStore(&state.needed, n);
    state.levels = 0u;
    state.pairs_tested = 0u;
    set_args(m);
}

// After the last level: one invocation per listed triangle pair (at most the list's capacity;
// on overflow the CPU re-runs the batch with a larger list).
@compute @workgroup_size(1)
fn prepare_tris() {
    set_args(min(atomicLoad(&state.tris), params.caps2.x));
}
