// frcd-gpu: the WGSL prelude every frcd shader is compiled with (prepended to each file).
// One declaration of each struct the shaders and the CPU share; the Rust mirrors are in
// frcd-gpu's `layout` module and a test checks them against naga's reflection of this file.

// ---- frcd-gpgpu: pair traversal (traverse.wgsl) ----

// Counters of one batch's traversal. The traversal runs one dispatch per level and no control
// pass between levels, so each level's frontier size has its own counter, by level mod 3: level
// L reads counts[L % 3], appends to counts[(L + 1) % 3] and zeroes counts[(L + 2) % 3] (the
// size its predecessor read), see `Level`.
struct State {
    // Entries appended to each level's frontier, by level mod 3 (may exceed the capacity:
    // overflow). The one-pass traversal: [1] entries left after the most levels (an error),
    // [2] non-zero when a workgroup stopped at its loop budget.
    counts: array<atomic<u32>, 3>,
    // Triangle pairs appended to the output (may exceed the capacity: overflow).
    out: atomic<u32>,
    // The batch's root pairs, or the largest frontier size requested if that exceeds the
    // frontier's capacity (overflow: the CPU re-runs with a frontier this large).
    needed: atomic<u32>,
    // Levels that had work (the one-pass traversal: the most of any workgroup), and frontier
    // entries expanded in total.
    levels: atomic<u32>,
    pairs_tested: atomic<u32>,
    // Triangle pairs appended to the triangle list (may exceed the capacity: overflow).
    tris: atomic<u32>,
    // The triangle pass's indirect arguments (x, y, z), raised by the traversal's
    // reservations to cover the list (the CPU starts them at (0, 1, 1)).
    tri_args: array<atomic<u32>, 3>,
}

// Which of `State.counts` (and of the three indirect-argument buffers) one traversal level
// uses: (L % 3: its frontier's size, (L + 1) % 3: the next frontier's, (L + 2) % 3: the one it
// zeroes, unused). One uniform buffer per value of L % 3.
struct Level {
    slots: vec4<u32>,
}

struct Params {
    // frontier capacity, output capacity, max workgroups per dimension, pairs in the batch
    caps: vec4<u32>,
    // triangle list capacity; the one-pass traversal's loop budget per invocation and loop
    // iterations per frontier entry at most; unused
    caps2: vec4<u32>,
    // The one-pass traversal (`traverse_all`): workgroups, frontier entries per workgroup
    // (each of its two halves), the batch's first-level entries, most levels.
    one_pass: vec4<u32>,
}

// Shape of the mesh arena textures.
struct Arena {
    // items per texture row, rows per layer (both powers of two), log2 of each
    node_layout: vec4<u32>,
    tri_layout: vec4<u32>,
}

// One body pair of a batch: the relative pose (rows of R: B local -> A local, and t; w
// unused) and the item bases of the two meshes in the arena.
struct PairInfo {
    r0: vec4<f32>,
    r1: vec4<f32>,
    r2: vec4<f32>,
    t: vec4<f32>,
    // A's first node, A's first triangle, B's first node, B's first triangle
    base: vec4<u32>,
    // The triangle pass's exact path (traverse.wgsl, `exact_w`; frcd-gpgpu's `pack::ExactPose`):
    // (path: 1 exact, 0 rotated; A's grid exponent; B's grid exponent; unused).
    fix: vec4<i32>,
    // R in fixed point M = round(R 2^46), column j, one row per component: M0 | M1 << 16 (its
    // low 16-bit limbs) and M >> 32 (signed).
    m_lo0: vec4<u32>,
    m_lo1: vec4<u32>,
    m_lo2: vec4<u32>,
    m_hi0: vec4<i32>,
    m_hi1: vec4<i32>,
    m_hi2: vec4<i32>,
    // t on the fine grid 2^(e_B - 46), T = round(t / 2^(e_B - 46)), per coordinate: T0 | T1 << 16,
    // T2 | T3 << 16 (16-bit limbs) and T >> 64 (signed).
    t01: vec4<u32>,
    t23: vec4<u32>,
    t4: vec4<i32>,
}

// ---- frcd-gpgpu: many-body box pass (boxes.wgsl) ----

// A box as four f32 corners rounded from f64: outer (lo down, hi up), inner (lo up, hi down).
struct BodyBox {
    lo_dn: vec4<f32>,
    hi_up: vec4<f32>,
    lo_up: vec4<f32>,
    hi_dn: vec4<f32>,
}

struct BoxParams {
    // body count, output capacity, then per pass: unused (boxes.wgsl) or the padded count
    // (sweep.wgsl), unused
    n: vec4<u32>,
}

// One step of sweep.wgsl's bitonic sort: k, j, unused, unused (k = 0: a block's whole presort).
struct SortStage {
    kj: vec4<u32>,
}

// ---- frcd-image (raster.wgsl, resolve.wgsl) ----

struct Draw {
    // Maps a vertex (f32, relative to its mesh's centre) to clip space; composed in f64 on the
    // CPU relative to the overlap region's centre so the f32 entries stay small.
    clip_from_local: mat4x4<f32>,
}

struct ResolveParams {
    width: u32,
    height: u32,
    // Facing code written by fs_peel for faces where the view ray enters the solid.
    entering_code: u32,
    _pad0: u32,
    // Depth of the overlap region's near face; lengths are measured from it to keep f32 small.
    depth_ref: f32,
    // World length of the whole depth range [0, 1].
    depth_scale: f32,
    _pad1: f32,
    _pad2: f32,
}

