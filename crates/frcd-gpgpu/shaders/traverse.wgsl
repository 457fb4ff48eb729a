// frcd-gpgpu: one level of the breadth-first traversal of the pair trees of a whole batch of
// body pairs (one frame: every candidate pair in one dispatch chain).
//
// Each invocation takes one frontier entry, a pair of overlapping nodes, and runs the
// separating-axis test in f32 with a computed error bound on each of its (up to four) child
// pairs, so rounding can only keep a pair, never drop one. Overlapping child pairs with an
// internal node append one entry each, naming their children, to the next frontier (atomic
// compaction, one atomic per invocation); overlapping leaf pairs append every triangle pair of
// the two leaves to the triangle list. After the last level, `triangles` runs the triangle test (Guigue-Devillers
// orientation form) once per listed pair, one pair per invocation (the tests of a leaf pair no
// longer run as a loop in the few lanes that reached a leaf: a SIMD driver such as llvmpipe
// then kept the other lanes of the vector idle), and appends the touching pairs to the output,
// flagged "uncertain" when a sign it needs is within the bound of zero. `traverse_all` runs the
// same levels and triangle tests in one dispatch of a few workgroups (see "the one-pass
// traversal" below), for software drivers.
//
// Everything is computed in A's local frame: B's geometry is mapped by the pair's relative pose
// (R, t). Every mesh of a context lives in one pair of arena textures (nodes rgba32uint, the
// f32 words as bits; triangles rgba32float; one texel = 4 words), each tree in its own local
// frame, at the item offsets of its pair entry:
//   node i: 4 texels (64 bytes) (c.xyz, link) (a0.xyz, h0 | leaf) (a1.xyz, h1) (a2.xyz, h2):
//   link = the first child (internal; nodes are breadth first with siblings side by side, the
//   second child is link + 1) or first | (count - 1) << 24 (leaf); leaf = bit 31 of h0's word
//   (a sign bit: h0 >= 0). The axes' bound eps (see `obb_overlap`) is one per mesh, the pair's
//   sum in the pose texture.
//   triangle j (leaf order): 3 texels (o0.xyz, mesh index) (o1.xyz, k1) (o2.xyz, k2): the
//   vertices' offsets o = v - c from a reference point c = k 2^e on the mesh's power-of-two grid
//   (k an integer vector, |k_i| <= 2^13, packed into k1 and k2; e per mesh, in PairInfo.fix);
//   see `triangles` and `exact_w`.
// Node and triangle indices inside an item are relative to the mesh's base; item i lives at
// row-major slot i of (layer, row, column group); see `slot`.

const WG: u32 = 64u;

// ---- Floating-point model (WGSL, not IEEE) ----
//
// WGSL lets an implementation (1) round each f32 operation either way: the result is one of
// the two f32 neighbours of the exact value, error < 1 ulp <= 2^-23 relative; (2) contract
// a * b + c into one fused multiply-add (one rounding instead of two); (3) flush subnormal
// inputs and results to zero (absolute error < 2^-126 per operation); (4) assume finite math.
// The bounds below hold under every combination:
// - U = 2^-23 is the relative error of one operation (either rounding direction). The
//   forward bounds used are of the form "|computed - exact| <= gamma_k * (sum of |terms|)",
//   gamma_k = k U / (1 - k U); a fused multiply-add skips a rounding, and every such bound
//   stays valid with fewer roundings (it is a bound on the product of (1 + delta_i) factors).
// - TAU = 2^-126 bounds the absolute error a flush adds to one operation. Every bound adds
//   a TAU term scaled by what the flushed value is later multiplied by, written so that it
//   is never itself below the normal range (64 TAU * (1 + x)^k >= 2^-120).
// - Finite math: the CPU refuses inputs whose magnitude could overflow any quantity here
//   (coordinates, extents and translations above 2^36, see `pack::MAX_MAGNITUDE`), so no
//   NaN or infinity is ever produced and no comparison relies on their semantics.
// - Every bound is evaluated in f32 itself, from non-negative terms only (at most ~10
//   roundings, relative error < 12 U), and multiplied by 1.01, which covers that.
// - Every sign a decision uses is taken only when it exceeds its bound, so both verdicts are
//   certified: "disjoint" / "separated" (rounding can only add candidates) and "touching"
//   (`check_min_max` answers TRI_TOUCH only from certain signs). By default (`Recheck::All`)
//   the CPU still re-decides every pair the GPU reports with the exact test, so a driver that
//   breaks these rules cannot add a pair; `Recheck::Uncertain` takes the touching verdicts.
// `emulate.rs` (a test module of the crate) runs this arithmetic on the CPU with every
// rounding direction, with and without FMA and FTZ, and checks both directions: no touching
// pair is declared disjoint and no disjoint pair touching.
const U: f32 = 1.1920929e-7;
const TAU: f32 = 1.1754944e-38;
const UNCERTAIN_FLAG: u32 = 0x80000000u;
// The triangles pipeline with the exact path compiled in (true) or the rotated path only (false:
// a context with the exact path off, where the integer work would be dead weight; a software
// driver would otherwise run it under masks). The traverse pipeline does not use it.
override EXACT_PATH: bool = true;
// A measurement hook (`context::SHADER_VARIANT_ENV`): 0 in every pipeline a context makes
// unless that variable says otherwise. A contrast build branches on it (`if VARIANT == 1u
// { the change } else { the code it replaces }`) so that `cargo xtask bench gpgpu
// --checker-shader-variants 1` times both run by run in one process. No shipped code reads it.
override VARIANT: u32 = 0u;

// State, Params, Arena and PairInfo come from the prelude (frcd-gpu).

@group(0) @binding(0) var nodes: texture_2d_array<u32>;
@group(0) @binding(1) var tris: texture_2d_array<f32>;
@group(0) @binding(2) var<uniform> arena: Arena;

// `traverse`: this level's frontier (binding 0), the next level's (binding 1), both entries
// (pair, children of A, children of B, unused): each names a pair of overlapping internal
// nodes by their first children (`link`), or a node itself with ONE_NODE set (a leaf, or a
// root); the level runs one invocation per entry, which tests its child pairs. Then the triangle
// list it appends to (binding 3),
// entries (pair, triangle of A, triangle of B, unused), triangles in leaf order relative to each
// mesh's first triangle.
// `triangles` (same layout, other buffers): the triangle list (binding 0) and the output
// (binding 1), entries (pair, triangle of A, triangle of B | UNCERTAIN_FLAG, unused) as input-mesh
// indices; binding 3 is bound but not used.
@group(1) @binding(0) var<storage, read> frontier_in: array<vec4<u32>>;
@group(1) @binding(1) var<storage, read_write> frontier_out: array<vec4<u32>>;
@group(1) @binding(2) var<storage, read_write> state: State;
@group(1) @binding(3) var<storage, read_write> tri_list: array<vec4<u32>>;
@group(1) @binding(4) var<uniform> params: Params;
@group(1) @binding(5) var<storage, read> pairs: array<PairInfo>;
// `traverse` only (the triangle pass binds other buffers there and does not use them): the
// next level's indirect arguments (x, y, z, unused), which this level raises to cover what it
// appends; the arguments of the level after it, which it sets back to (1, 1, 1); and which of
// `State.counts` it reads, appends to and zeroes.
@group(1) @binding(6) var<storage, read_write> args_next: array<atomic<u32>, 4>;
@group(1) @binding(7) var<storage, read_write> args_after: array<u32, 4>;
@group(1) @binding(8) var<uniform> level: Level;
// Both passes: each pair's f32 pose and arena bases as five rgba32uint texels, pair p at texels
// 5 (p mod 256) + k of row p / 256: (R row 0, t.x) (R row 1, t.y) (R row 2, t.z) as f32 bits,
// `PairInfo.base`, then (eps_A + eps_B, fix.x, fix.y, fix.z): the meshes' axes' bound
// (`obb_overlap`) and the triangle pass's path and grid exponents (`PairInfo.fix`).
// The pose words are those of `pairs[p]` (r0-r2, t, base); read as texels because a
// software driver such as llvmpipe fetches a texel for its whole vector of invocations at once,
// where a storage-buffer load of an index that varies across lanes becomes a loop over the
// lanes with a bounds check per word (measured 2026-12-01: those loops were a fifth of the
// traversal's time there).
@group(1) @binding(9) var poses: texture_2d<u32>;

// The pair this invocation works on.
var<private> pose: PairInfo;
// Its meshes' bound on their axes' distance to an orthonormal frame, eps_A + eps_B (see
// `obb_overlap`).
var<private> pose_eps: f32;

const LEAF_FLAG: u32 = 0x80000000u;
// Bit 31 of a frontier entry's node word: the word is that node itself, not its first child.
const ONE_NODE: u32 = 0x80000000u;

struct Node {
    c: vec3<f32>,
    a0: vec3<f32>,
    a1: vec3<f32>,
    a2: vec3<f32>,
    h: vec3<f32>,
    leaf: bool,
    // Internal: the first child (the second is the next node). Leaf: first triangle and count.
    first_child: u32,
    first: u32,
    count: u32,
}

// Texel coordinates (column of the item's first texel, row, layer) of item i. Items per row
// (lay.x) and rows per layer (lay.y) are powers of two with logarithms lay.z and lay.w: shifts
// and masks, no integer division (a software driver runs vector divisions lane by lane).
fn slot(lay: vec4<u32>, per_item: u32, i: u32) -> vec3<u32> {
    let row_g = i >> lay.z;
    return vec3<u32>((i & (lay.x - 1u)) * per_item, row_g & (lay.y - 1u), row_g >> lay.w);
}

fn texel(t: texture_2d_array<f32>, s: vec3<u32>, k: u32) -> vec4<f32> {
    return textureLoad(t, vec2<u32>(s.x + k, s.y), s.z, 0);
}

fn node_texel(s: vec3<u32>, k: u32) -> vec4<u32> {
    return textureLoad(nodes, vec2<u32>(s.x + k, s.y), s.z, 0);
}

// A bit cast is exact; a subnormal word a driver flushes when it computes with it is inside
// the TAU terms of `obb_overlap`'s bound.
fn load_node(i: u32) -> Node {
    let s = slot(arena.node_layout, 4u, i);
    let t0 = node_texel(s, 0u);
    let t1 = node_texel(s, 1u);
    let t2 = node_texel(s, 2u);
    let t3 = node_texel(s, 3u);
    var n: Node;
    n.c = bitcast<vec3<f32>>(t0.xyz);
    n.a0 = bitcast<vec3<f32>>(t1.xyz);
    n.a1 = bitcast<vec3<f32>>(t2.xyz);
    n.a2 = bitcast<vec3<f32>>(t3.xyz);
    n.h = bitcast<vec3<f32>>(vec3<u32>(t1.w & ~LEAF_FLAG, t2.w, t3.w));
    n.leaf = (t1.w & LEAF_FLAG) != 0u;
    n.first_child = t0.w;
    n.first = t0.w & 0xffffffu;
    n.count = select(0u, (t0.w >> 24u) + 1u, n.leaf);
    return n;
}

// Fills `pose`'s f32 pose and bases for pair p from `poses` (the triangle pass reads `fix` from
// the fifth texel and the exact path's limbs from `pairs`; the axes' bound is
// `load_pose_eps`'s). A bit cast is exact;
// a subnormal word a driver flushes when it computes with it is inside the TAU terms of every
// bound.
fn load_pose(p: u32) {
    let col = (p & 255u) * 5u;
    let row = p >> 8u;
    let w0 = textureLoad(poses, vec2<u32>(col, row), 0);
    let w1 = textureLoad(poses, vec2<u32>(col + 1u, row), 0);
    let w2 = textureLoad(poses, vec2<u32>(col + 2u, row), 0);
    pose.r0 = vec4<f32>(bitcast<vec3<f32>>(w0.xyz), 0.0);
    pose.r1 = vec4<f32>(bitcast<vec3<f32>>(w1.xyz), 0.0);
    pose.r2 = vec4<f32>(bitcast<vec3<f32>>(w2.xyz), 0.0);
    pose.t = vec4<f32>(bitcast<f32>(w0.w), bitcast<f32>(w1.w), bitcast<f32>(w2.w), 0.0);
    pose.base = textureLoad(poses, vec2<u32>(col + 3u, row), 0);
}

// `pose_eps` for pair p (its fifth pose texel; only the box test needs it).
fn load_pose_eps(p: u32) {
    pose_eps = bitcast<f32>(textureLoad(poses, vec2<u32>((p & 255u) * 5u + 4u, p >> 8u), 0).x);
}

fn rot(v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(pose.r0.xyz, v), dot(pose.r1.xyz, v), dot(pose.r2.xyz, v));
}

fn l1(v: vec3<f32>) -> f32 {
    return abs(v.x) + abs(v.y) + abs(v.z);
}

fn maxabs(v: vec3<f32>) -> f32 {
    return max(abs(v.x), max(abs(v.y), abs(v.z)));
}

// Conservative OBB overlap (Gottschalk's form of the 15-axis test): false only when some axis
// separates the boxes with margin. C = (a_i . b_j) holds B's axes in A's frame and T = (a_i . tt)
// the centre offset, both computed once; every axis then costs a few products of C, |C| and T
// entries instead of a general projection.
//
// Error bound (valid for any rounding direction, FMA contraction and flush-to-zero; U, TAU as
// above). The boxes are the f32 parallelepipeds {c + sum s_i h_i a_i}; their axes are only
// near-orthonormal: the CPU computes an eps_A >= max_i |a_i - q_i|_2 for an orthonormal
// Q_A (3 max|A^T A - I|, via the polar factor; see `pack::ObbF32::axes_deviation`; one bound per
// mesh, the largest of its nodes', as err only grows with it; the pair's eps_A + eps_B comes
// rounded up from the CPU in `pose_eps`). Box A lies in
// the orthonormal box (c, Q_A, h_i + eps_A sum h), likewise B, and the exact Gottschalk test of
// those boxes (exact pose R64, t64) is what the computed test must imply. With
// eps = eps_A + eps_B + U (U also covers R64's f64 non-orthogonality), per entry:
// - |C_ij - C'_ij| <= e_C = 10U + 1.01 eps: rot() with R rounded (3.6U per coordinate of b_j),
//   the dot with a_i (3.1U + 6.3U for b_j's error), and the axes' distance to Q (eps).
// - |T_i - T'_i| <= e_T = 9U (|c_B|_1 + |t|_1) + 7U |tt|_1 + 1.01 eps |tt|_1: the centre (rot()
//   + t, R and t rounded: 5U per coordinate of |c_B|_1 + |t|_1; the subtraction U |tt|), the
//   dot with a_i or b_j (3.1U |tt|_1, plus 3.6U |tt|_1 for b_j's error), the axes' eps.
// - an edge axis's offset T_m C_kj - T_k C_mj (|C'| <= 1, |T| <= 1.01 |tt|_1) is off by
//   <= 2 e_T + 2.02 e_C |tt|_1 + 4.1U |tt|_1 (its own two roundings).
// - a radius (h'_k |C'| summed, h' the inflated extents) exceeds the computed one by
//   <= (e_C + 2.1 eps_A) sum h_A + (e_C + 2.1 eps_B) sum h_B; its computation (gamma_3 on
//   <= 1.01 sum h) and the comparison's two additions: 6U (sum h_A + sum h_B).
// Summed with margin: err = 20U (|c_B|_1 + |t|_1) + (48U + 5 eps) |tt|_1
//   + (20U + 4 eps) (sum h_A + sum h_B) + 128 TAU (1 + sum h + |tt|_1) (flush-to-zero: each of
// the ~20 operations behind an entry may lose TAU, later scaled by at most h, |tt| or 1), all
// terms >= 0, times 1.01 for the ~15 roundings of err itself. The same err serves all 15 axes.
// B's node as both of A's children see it: its axes and centre mapped into A's frame by the
// pair's pose (rot(b) + t), and the error bound's |c_B|_1 + |t|_1. A frontier entry tests each
// of B's (up to) two children against each of A's, so this is done once per B child, not once
// per child pair; the operations and their order are those of the test itself.
struct MappedB {
    b0: vec3<f32>,
    b1: vec3<f32>,
    b2: vec3<f32>,
    // rot(c_B) + t
    c: vec3<f32>,
    h: vec3<f32>,
    // l1(c_B) + l1(t)
    lc: f32,
}

fn map_b(nb: Node) -> MappedB {
    var m: MappedB;
    m.b0 = rot(nb.a0);
    m.b1 = rot(nb.a1);
    m.b2 = rot(nb.a2);
    m.c = rot(nb.c) + pose.t.xyz;
    m.h = nb.h;
    m.lc = l1(nb.c) + l1(pose.t.xyz);
    return m;
}

fn obb_overlap(na: Node, mb: MappedB, eps_ab: f32) -> bool {
    let b0 = mb.b0;
    let b1 = mb.b1;
    let b2 = mb.b2;
    let tt = mb.c - na.c;
    // Rows: A's axes; columns: B's axes.
    let c0 = vec3<f32>(dot(na.a0, b0), dot(na.a0, b1), dot(na.a0, b2));
    let c1 = vec3<f32>(dot(na.a1, b0), dot(na.a1, b1), dot(na.a1, b2));
    let c2 = vec3<f32>(dot(na.a2, b0), dot(na.a2, b1), dot(na.a2, b2));
    let t = vec3<f32>(dot(na.a0, tt), dot(na.a1, tt), dot(na.a2, tt));
    let ha = na.h;
    let hb = mb.h;
    let sha = ha.x + ha.y + ha.z;
    let shb = hb.x + hb.y + hb.z;
    let ltt = l1(tt);
    let eps = eps_ab + U;
    let err = (20.0 * U * mb.lc + (48.0 * U + 5.0 * eps) * ltt
        + (20.0 * U + 4.0 * eps) * (sha + shb)
        + 128.0 * TAU * (1.0 + sha + shb + ltt)) * 1.01;
    let a0 = abs(c0);
    let a1 = abs(c1);
    let a2 = abs(c2);
    // A's face axes: radius of A is h_i, of B sum_j hb_j |C_ij|.
    if abs(t.x) > ha.x + dot(hb, a0) + err { return false; }
    if abs(t.y) > ha.y + dot(hb, a1) + err { return false; }
    if abs(t.z) > ha.z + dot(hb, a2) + err { return false; }
    // B's face axes: offset tt . b_j, radius of A sum_i h_i |C_ij|, of B hb_j.
    if abs(dot(tt, b0)) > dot(ha, vec3<f32>(a0.x, a1.x, a2.x)) + hb.x + err { return false; }
    if abs(dot(tt, b1)) > dot(ha, vec3<f32>(a0.y, a1.y, a2.y)) + hb.y + err { return false; }
    if abs(dot(tt, b2)) > dot(ha, vec3<f32>(a0.z, a1.z, a2.z)) + hb.z + err { return false; }
    // Edge axes a_i x b_j, (i, k, m) cyclic: offset T_m C_kj - T_k C_mj, radius of A
    // h_k |C_mj| + h_m |C_kj|, of B (j, p, q cyclic) hb_p |C_iq| + hb_q |C_ip|.
    if abs(t.z * c1.x - t.y * c2.x) > ha.y * a2.x + ha.z * a1.x + hb.y * a0.z + hb.z * a0.y + err { return false; }
    if abs(t.z * c1.y - t.y * c2.y) > ha.y * a2.y + ha.z * a1.y + hb.x * a0.z + hb.z * a0.x + err { return false; }
    if abs(t.z * c1.z - t.y * c2.z) > ha.y * a2.z + ha.z * a1.z + hb.x * a0.y + hb.y * a0.x + err { return false; }
    if abs(t.x * c2.x - t.z * c0.x) > ha.x * a2.x + ha.z * a0.x + hb.y * a1.z + hb.z * a1.y + err { return false; }
    if abs(t.x * c2.y - t.z * c0.y) > ha.x * a2.y + ha.z * a0.y + hb.x * a1.z + hb.z * a1.x + err { return false; }
    if abs(t.x * c2.z - t.z * c0.z) > ha.x * a2.z + ha.z * a0.z + hb.x * a1.y + hb.y * a1.x + err { return false; }
    if abs(t.y * c0.x - t.x * c1.x) > ha.x * a1.x + ha.y * a0.x + hb.y * a2.z + hb.z * a2.y + err { return false; }
    if abs(t.y * c0.y - t.x * c1.y) > ha.x * a1.y + ha.y * a0.y + hb.x * a2.z + hb.z * a2.x + err { return false; }
    if abs(t.y * c0.z - t.x * c1.z) > ha.x * a1.z + ha.y * a0.z + hb.x * a2.y + hb.y * a2.x + err { return false; }
    return true;
}

// ---- triangle-triangle test ----

const TRI_DISJOINT: u32 = 0u;
const TRI_TOUCH: u32 = 1u;
const TRI_UNCERTAIN: u32 = 2u;

// Sign of v when |v| > e for certain; 0 means "not certain" (NaN included).
fn sgn(v: f32, e: f32) -> i32 {
    return select(select(0, -1, v < -e), 1, v > e);
}

// Side of w against the plane of (x, y, z), as Guigue-Devillers compute it:
// dot(w - z, (x - z) x (y - z)) = det(y - x, z - x, w - x) (positive: w above the
// counter-clockwise triangle).
fn orient(x: vec3<f32>, y: vec3<f32>, z: vec3<f32>, w: vec3<f32>) -> f32 {
    return dot(w - z, cross(x - z, y - z));
}

// Guigue-Devillers CHECK_MIN_MAX in the canonical configuration: p1 alone on the positive side
// of plane 2 and p2 alone on the positive side of plane 1; the triangles meet iff both values
// are <= 0.
fn check_min_max(p1: vec3<f32>, q1: vec3<f32>, r1: vec3<f32>,
                 p2: vec3<f32>, q2: vec3<f32>, r2: vec3<f32>, e: f32) -> u32 {
    let v1 = sgn(dot(q2 - q1, cross(p2 - q1, p1 - q1)), e);
    let v2 = sgn(dot(r2 - p1, cross(p2 - p1, r1 - p1)), e);
    let touch = select(TRI_UNCERTAIN, TRI_TOUCH, v1 < 0 && v2 < 0);
    return select(touch, TRI_DISJOINT, v1 > 0 || v2 > 0);
}

// A triangle rotated so that its lone vertex against the other triangle's plane comes first
// (the vertex whose sign differs from the other two; signs nonzero, not all equal), and whether
// that vertex lies on the negative side.
struct LoneFirst {
    p: vec3<f32>,
    q: vec3<f32>,
    r: vec3<f32>,
    negative: bool,
}

// Guigue-Devillers' permutation steps as selects, not branches: llvmpipe runs every branch of
// an `if` under a mask, so the branching form (six rotations of triangle 1, each calling six
// of triangle 2) paid 36 CHECK_MIN_MAXes per triangle pair where one is needed. The points
// passed on are the same as the branching form's, so the arithmetic, and its bound, are too.
fn lone_first(p: vec3<f32>, q: vec3<f32>, r: vec3<f32>, sp: i32, sq: i32, sr: i32) -> LoneFirst {
    let r_lone = sq == sp;
    let q_lone = !r_lone && sr == sp;
    let s = select(select(sp, sq, q_lone), sr, r_lone);
    return LoneFirst(select(select(p, q, q_lone), r, r_lone),
                     select(select(q, r, q_lone), p, r_lone),
                     select(select(r, p, q_lone), q, r_lone),
                     s < 0);
}

// Decides whether triangle (p1, q1, r1) meets triangle (p2, q2, r2), both in A's frame (possibly
// shifted by a common reference point: signs of orientations do not change), given a bound
// `delta` on every coordinate's distance from the f64 points the exact test sees (A's vertices
// and B's mapped by the f64 pose, shifted alike). Every sign is taken only when the computed
// value exceeds a forward error bound covering `delta` and the arithmetic; a sign that is not
// certain (touching, coplanar, degenerate, or simply too close) makes the answer TRI_UNCERTAIN
// and the CPU decides that pair exactly.
fn tri_tri_core(p1: vec3<f32>, q1: vec3<f32>, r1: vec3<f32>,
                p2: vec3<f32>, q2: vec3<f32>, r2: vec3<f32>, delta: f32) -> u32 {
    // Box side of the six points bounds every coordinate difference (hi - lo rounds by U).
    let lo = min(min(min(p1, q1), min(r1, p2)), min(q2, r2));
    let hi = max(max(max(p1, q1), max(r1, p2)), max(q2, r2));
    let ext = hi - lo;
    let d = (max(ext.x, max(ext.y, ext.z)) + 2.0 * delta) * (1.0 + 4.0 * U);
    // |computed det - exact det| for dot(w - z, cross(x - z, y - z)) with |differences| <= d:
    // rounding: differences (U each, 3 factors), cross (gamma_2), dot (gamma_3): gamma_8 times
    // the permanent (<= 6 d^3): 48 U d^3 (+ margin); input perturbation of each point by
    // delta (differences by 2 delta): first, second and third order terms; flush to zero:
    // ~20 operations, each loss scaled by at most 2 d^2 (a difference), d (a cross term) or
    // 1: <= 64 TAU (1 + d)^2. Evaluated in f32 with margin 1.01 (all terms >= 0).
    let dd = 1.0 + d;
    let e = (50.0 * U * d * d * d + 32.0 * delta * d * d + 64.0 * delta * delta * d
        + 42.0 * delta * delta * delta + 64.0 * TAU * dd * dd) * 1.01;

    let sp1 = sgn(orient(p2, q2, r2, p1), e);
    let sq1 = sgn(orient(p2, q2, r2, q1), e);
    let sr1 = sgn(orient(p2, q2, r2, r1), e);
    let sp2 = sgn(orient(p1, q1, r1, p2), e);
    let sq2 = sgn(orient(p1, q1, r1, q2), e);
    let sr2 = sgn(orient(p1, q1, r1, r2), e);
    let disjoint = (sp1 != 0 && sp1 == sq1 && sp1 == sr1) || (sp2 != 0 && sp2 == sq2 && sp2 == sr2);
    let unsure = sp1 == 0 || sq1 == 0 || sr1 == 0 || sp2 == 0 || sq2 == 0 || sr2 == 0;
    // Generic case: both triangles strictly straddle the other's plane. Rotate triangle 1 so
    // that its lone vertex comes first; if it lies on the negative side, flip plane 2 by
    // swapping q2 and r2. Then the same for triangle 2, flipping plane 1 (q1 and r1).
    let t1 = lone_first(p1, q1, r1, sp1, sq1, sr1);
    let t2 = lone_first(p2, select(q2, r2, t1.negative), select(r2, q2, t1.negative),
                        sp2, select(sq2, sr2, t1.negative), select(sr2, sq2, t1.negative));
    let generic = check_min_max(t1.p, select(t1.q, t1.r, t2.negative),
                                select(t1.r, t1.q, t2.negative), t2.p, t2.q, t2.r, e);
    return select(select(generic, TRI_UNCERTAIN, unsure), TRI_DISJOINT, disjoint);
}

// ---- the exact path: W = R c_B + t - c_A in integer arithmetic ----
//
// The CPU gives R in fixed point, M = round(R 2^46) (|M / 2^46 - R| <= 2^-47 per entry), and t on
// the fine grid f = 2^(e_B - 46), T = round(t / f) (|T f - t| <= f / 2), both as 16-bit limbs
// (PairInfo.m_*, t01, t23, t4; `pack::ExactPose`). With c_A = k_A 2^(e_A), c_B = k_B 2^(e_B),
//   W_int / f = M k_B + T - k_A 2^(e_A - e_B + 46)
// is an integer, computed here exactly: WGSL's i32 and u32 arithmetic is exact (wrapping) under
// every float rule, and every partial below stays inside i32. Products are 16 x 14 bits (M's
// 16-bit limbs times k_B, |k_B| <= 2^13: below 2^29), summed per limb of M (three products:
// below 2^30.6) onto T's 16-bit limbs (five limbs, weights 2^0 .. 2^64), A's term subtracted as
// two 16-bit pieces, then carries are propagated (arithmetic shifts). A negative value is negated limb by limb. The magnitude (below 2^79:
// |T| < 2^78, |k_A 2^sa| <= 2^76, |M k_B| < 2^62) is converted to f32 once: its top 32 bits (the
// bits below are dropped: relative error < 2^-31) converted by f32() (one rounding, either
// direction: U), scaled by a power of two (exact: the result is 0 or >= f >= 2^-96, as the CPU keeps
// e_A, e_B >= -50, and below 2^79 f <= 2^56). So
//   |W_f32 - W_int| <= (U + 2^-31)(1 + U) |W_int| <= 1.02 U |W_f32|.
const M16: vec3<i32> = vec3<i32>(0xffff, 0xffff, 0xffff);
const S16: vec3<u32> = vec3<u32>(16u, 16u, 16u);
const ZERO3: vec3<i32> = vec3<i32>(0, 0, 0);

// 2^e for e in [-126, 127], built from its bits (ldexp is a long sequence on some drivers);
// products with it are exact wherever the results below use them (normal or zero). Out of
// that range (only on the path a `select` discards) the bits are some other float.
fn pow2(e: vec3<i32>) -> vec3<f32> {
    return bitcast<vec3<f32>>(vec3<u32>(e + vec3<i32>(127)) << vec3<u32>(23u));
}

// A five-limb integer per coordinate, limb i of weight 2^(16 i).
struct Limbs {
    l0: vec3<i32>,
    l1: vec3<i32>,
    l2: vec3<i32>,
    l3: vec3<i32>,
    l4: vec3<i32>,
}

// Propagates carries: limbs 0-3 end in [0, 2^16), limb 4 keeps the sign.
fn carry(x: Limbs) -> Limbs {
    var o = x;
    var c = o.l0 >> S16;
    o.l0 = o.l0 & M16;
    o.l1 = o.l1 + c;
    c = o.l1 >> S16;
    o.l1 = o.l1 & M16;
    o.l2 = o.l2 + c;
    c = o.l2 >> S16;
    o.l2 = o.l2 & M16;
    o.l3 = o.l3 + c;
    c = o.l3 >> S16;
    o.l3 = o.l3 & M16;
    o.l4 = o.l4 + c;
    return o;
}

// A triangle's grid coordinates (`pack::pack_k`: 16 bits each, biased by 2^15).
fn unpack_k(w1: f32, w2: f32) -> vec3<i32> {
    let a = u32(w1);
    let b = u32(w2);
    return vec3<i32>(vec3<u32>(a & 0xffffu, (a >> 16u) | ((b & 0xffu) << 8u), b >> 8u))
        - vec3<i32>(32768);
}

// W / f = M k_B + T - k_A 2^sa as f32 times f = 2^ef (xyz, one rounding) and 1 in w (0: out of
// range, which the CPU's ranges rule out), for body pair pi (its limbs are read here).
// sa in [0, 62], ef >= -96 (`pack::ExactPose`).
fn exact_w(pi: u32, ka: vec3<i32>, kb: vec3<i32>, sa: i32, ef: i32) -> vec4<f32> {
    var x: Limbs;
    let t01 = pairs[pi].t01.xyz;
    let t23 = pairs[pi].t23.xyz;
    x.l0 = vec3<i32>(t01 & vec3<u32>(0xffffu));
    x.l1 = vec3<i32>(t01 >> S16);
    x.l2 = vec3<i32>(t23 & vec3<u32>(0xffffu));
    x.l3 = vec3<i32>(t23 >> S16);
    x.l4 = pairs[pi].t4.xyz;
    // M k_B per limb of M (|k_B| <= 2^13: each product below 2^29, each sum of three below
    // 2^30.6), added to T's limbs unsplit; the carries below spread them.
    let m0 = pairs[pi].m_lo0.xyz;
    let m1 = pairs[pi].m_lo1.xyz;
    let m2 = pairs[pi].m_lo2.xyz;
    let lo16 = vec3<u32>(0xffffu);
    x.l0 = x.l0 + vec3<i32>(m0 & lo16) * kb.x + vec3<i32>(m1 & lo16) * kb.y
        + vec3<i32>(m2 & lo16) * kb.z;
    x.l1 = x.l1 + vec3<i32>(m0 >> S16) * kb.x + vec3<i32>(m1 >> S16) * kb.y
        + vec3<i32>(m2 >> S16) * kb.z;
    x.l2 = x.l2 + pairs[pi].m_hi0.xyz * kb.x + pairs[pi].m_hi1.xyz * kb.y
        + pairs[pi].m_hi2.xyz * kb.z;
    // - k_A 2^sa, sa = 16 q + r in [0, 62]: k_A 2^r (|.| < 2^30) split at limb q.
    let q = sa >> 4u;
    let ks = ka * (1 << u32(sa & 15));
    let kl = ks & M16;
    let kh = ks >> S16;
    x.l0 = x.l0 - select(ZERO3, kl, vec3<bool>(q == 0));
    x.l1 = x.l1 - select(ZERO3, kl, vec3<bool>(q == 1)) - select(ZERO3, kh, vec3<bool>(q == 0));
    x.l2 = x.l2 - select(ZERO3, kl, vec3<bool>(q == 2)) - select(ZERO3, kh, vec3<bool>(q == 1));
    x.l3 = x.l3 - select(ZERO3, kl, vec3<bool>(q == 3)) - select(ZERO3, kh, vec3<bool>(q == 2));
    x.l4 = x.l4 - select(ZERO3, kh, vec3<bool>(q == 3));
    x = carry(x);
    // Magnitude: negate the negative ones.
    let neg = x.l4 < ZERO3;
    let sg = select(vec3<i32>(1), vec3<i32>(-1), neg);
    x.l0 = x.l0 * sg;
    x.l1 = x.l1 * sg;
    x.l2 = x.l2 * sg;
    x.l3 = x.l3 * sg;
    x.l4 = x.l4 * sg;
    x = carry(x);
    // |V| < 2^79: limb 4 below 2^15 (else, impossible by the CPU's ranges, report uncertain).
    let ok = all(x.l4 < vec3<i32>(32768));
    // A 64-bit window (hi, lo) holding the leading bits with hi < 2^31 (so the shifts below stay
    // within 1..31): limbs 3-0, or 4-1 when |V| >= 2^63 (then limb 0 is dropped: relative error
    // < 2^-47, inside the 2^-31 below).
    let big = (x.l4 != ZERO3) | (x.l3 >= vec3<i32>(32768));
    let hi = vec3<u32>(select((x.l3 << S16) | x.l2, (x.l4 << S16) | x.l3, big));
    let lo = vec3<u32>(select((x.l1 << S16) | x.l0, (x.l2 << S16) | x.l1, big));
    let e0 = select(vec3<i32>(ef), vec3<i32>(ef + 16), big);
    // Top 32 bits: hi = 0: lo itself; else shifted so hi's leading bit is bit 31.
    let n1 = select(firstLeadingBit(hi) + vec3<u32>(1u), vec3<u32>(0u), hi == vec3<u32>(0u));
    let top = (hi << ((vec3<u32>(32u) - n1) & vec3<u32>(31u))) | (lo >> n1);
    let m = vec3<f32>(top) * pow2(vec3<i32>(n1) + e0);
    return vec4<f32>(select(m, -m, neg), select(0.0, 1.0, ok));
}

// ---- the triangle pass's two paths ----
//
// The rotated path: triangle A (p1, q1, r1) and B (pb, qb, rb) rebuilt from their offsets and
// reference points (p = o + c in f32; c = k 2^e is exact), B mapped by the f32 pose
// (rot(pb) + t). Per-coordinate distance from the f64 points the exact test sees: A: offset
// stored rounded to nearest (f64 subtraction, then f32: U/2 (1 + 2^-28) |o|), the sum o + c
// (U |p|), or flushed (TAU each): U (|p_A| + 0.5 |o_A|) + 2 TAU. B: that storage error
// (0.5 U |o_B| + U |pb| per coordinate), carried through a row of R (|R_i|_1 <= 3 in this bound):
// 1.5 U |o_B| + 3 U |pb|; R and t rounded (U/2 |pb|_1, U/2 |t|); rot() + t (gamma_4 (|pb|_1 +
// |t|), |pb|_1 <= 3 |pb|_inf): <= U (16.5 |pb| + 1.5 |o_B| + 4.5 |t|), plus flushes (the offset,
// the sum, the rotation: <= 14 TAU through R). The (1 + U) factors of these first-order terms
// are inside the final 1.01.
//
// The exact path: A's offsets o_A; B's points pb rotated by the f32 R, plus W; all relative to
// c_A. Mode 1: pb = o_B (B's offsets), W = R c_B + t - c_A. Mode 2 (B small next to A, see
// `pack::ExactPose`): pb = o_B + c_B rebuilt in f32, W = t - c_A (c_B's term is then k_B = 0).
// Per-coordinate distance from the f64 points the exact test sees (shifted by c_A):
// A: o_A's storage (f64 subtraction, then f32: U/2 (1 + 2^-28) |o_A|) or a flush (TAU).
// B: the exact point is R (b - c_B) + W_exact (mode 2: R b + W_exact), W_exact = R c_B + t - c_A
//   (f64 R, t), and the exact test maps b in f64 (gamma_4 (|b|_1 + |t|) <= 2^-51 (|c_B|_1 +
//   3.01 |pb| + |t|)).
//   - |W_int - W_exact| <= 2^-47 |c_B|_1 + f / 2 (M's and T's rounding; mode 2: f / 2): with
//     the f64 mapping's terms, <= (|k_B|_1 + 0.5) f + 2^-46 |t| (mode 1: |c_B|_1 2^-46 =
//     |k_B|_1 f; mode 2: k_B = 0 here).
//   - |W_f32 - W_int| <= 1.02 U |W| (above).
//   - pb: mode 1: o_B's storage, 0.5 U |o_B| per coordinate; mode 2: that plus the sum
//     o_B + c_B (U |pb|).
//   - rot(pb): pb's error through a row of R (|R_i|_1 <= 3 here: mode 1 1.5 U |pb|, mode 2
//     1.5 U |o_B| + 3 U |pb|), R rounded (U/2 |pb|_1 = 1.5 U |pb|), the dot (gamma_3 |pb|_1:
//     9.01 U |pb|); + W: one rounding (U (3.01 |pb| + |W|)). Mode 1: <= 15.1 U |pb| + 2.03 U
//     |W|; mode 2: <= 16.6 U |pb| + 1.5 U |o_B| + 2.03 U |W| (2^-51 3.01 |pb| is inside the
//     margins to 16 and 17).
//   - flushes: o_B, the sum with c_B, the products and sums of rot(), the sum with W: <= 12 TAU.
// delta = max(0.5 U |o_A|, U (cp |pb| + co |o_B| + 3 |W|) + (|k_B|_1 + 0.5) f + 2^-46 |t|)
//   + 16 TAU, times 1.01 (the (1 + U) factors above and the ~14 roundings of delta itself),
//   (cp, co) = (16, 0) in mode 1, (17, 2) in mode 2. |o|, |W| and f are leaf-sized, not
//   mesh-sized (mode 2: |pb| is B's size, small next to A's), and the terms in |c_B| and |t|
//   are ~2^-23 U of the mesh.
//
// Both paths run as one sequence of operations with the path's operands chosen by `select`
// (a software driver such as llvmpipe runs both sides of a branch that varies across lanes
// under masks: two branches made this pass about 2x slower there), in the order of the
// formulas above: A = o_A (exact) or o_A + c_A (rotated); B's points pb = o_B (mode 1) or
// o_B + c_B (mode 2, rotated), mapped by rot(pb) + W (exact) or + t (rotated); one delta,
//   max(U (ca |p_A| + 0.5 |o_A|), U (cp |pb| + co |o_B| + cw |W or t|) + far) + 16 TAU,
// (ca, cp, co, cw) = (0, 16, 0, 3) mode 1, (0, 17, 2, 3) mode 2, (1, 17, 2, 5) rotated, far 0
// on the rotated path; times 1.01.
fn tri_pair(pi: u32, a0: vec4<f32>, a1: vec4<f32>, a2: vec4<f32>,
            b0: vec4<f32>, b1: vec4<f32>, b2: vec4<f32>) -> u32 {
    let ka = unpack_k(a1.w, a2.w);
    let kb = unpack_k(b1.w, b2.w);
    let rotated = !EXACT_PATH || pose.fix.x == 0;
    let mode2 = pose.fix.x == 2;
    // Mode 1: fine grid 2^(e_B - 46); mode 2: 2^(e_A - 46) and k_B's term 0.
    let sa = select(pose.fix.y - pose.fix.z + 46, 46, mode2);
    let ef = select(pose.fix.z - 46, pose.fix.y - 46, mode2);
    let kbx = select(kb, ZERO3, mode2);
    var w = vec4<f32>(0.0);
    if EXACT_PATH {
        w = exact_w(pi, ka, kbx, sa, ef);
    }
    // c = k 2^e, exact (|k| <= 2^13, e >= -50, or k = 0).
    let ca = vec3<f32>(ka) * pow2(vec3<i32>(pose.fix.y)).x;
    let cb = vec3<f32>(kb) * pow2(vec3<i32>(pose.fix.z)).x;
    let add_cb = rotated || mode2;
    let p1 = select(a0.xyz, a0.xyz + ca, rotated);
    let q1 = select(a1.xyz, a1.xyz + ca, rotated);
    let r1 = select(a2.xyz, a2.xyz + ca, rotated);
    let pb = select(b0.xyz, b0.xyz + cb, add_cb);
    let qb = select(b1.xyz, b1.xyz + cb, add_cb);
    let rb = select(b2.xyz, b2.xyz + cb, add_cb);
    let shift = select(w.xyz, pose.t.xyz, rotated);
    let p2 = rot(pb) + shift;
    let q2 = rot(qb) + shift;
    let r2 = rot(rb) + shift;
    let oa_mag = max(maxabs(a0.xyz), max(maxabs(a1.xyz), maxabs(a2.xyz)));
    let ob_mag = max(maxabs(b0.xyz), max(maxabs(b1.xyz), maxabs(b2.xyz)));
    let pa_mag = max(maxabs(p1), max(maxabs(q1), maxabs(r1)));
    let pb_mag = max(maxabs(pb), max(maxabs(qb), maxabs(rb)));
    let c_a = select(0.0, 1.0, rotated);
    let cp = select(16.0, 17.0, add_cb);
    let co = select(0.0, 2.0, add_cb);
    let cw = select(3.0, 5.0, rotated);
    let far = select((l1(vec3<f32>(kbx)) + 0.5) * pow2(vec3<i32>(ef)).x + 1.4210855e-14 * maxabs(pose.t.xyz),
                     0.0, rotated);
    let delta = (max(U * (c_a * pa_mag + 0.5 * oa_mag),
                     U * (cp * pb_mag + co * ob_mag + cw * maxabs(shift)) + far)
        + 16.0 * TAU) * 1.01;
    let r = tri_tri_core(p1, q1, r1, p2, q2, r2, delta);
    // W out of range (ruled out by the CPU's ranges): uncertain.
    return select(r, TRI_UNCERTAIN, !rotated && w.w == 0.0);
}

// Reserves `k` entries of the triangle list (one atomic for all the leaf pairs of an entry) and
// returns the first. The counter stops near 2^31 (beyond every capacity: the CPU re-runs or
// refuses): every reservation that takes it past 2^31 brings it back there, and one level
// reserves less than 2^31 in all (checked on the CPU), so it never wraps. The reservation
// that opens a new workgroup of the triangle pass raises that pass's indirect arguments, as
// `append_args` does for the next level (both are non-decreasing in the list's size, so the
// largest raise is the final size's; no control pass runs between the last level and the
// triangle pass).
fn reserve_tris(k: u32) -> u32 {
    let base = atomicAdd(&state.tris, k);
    let end = base + k;
    if end > 0x80000000u {
        atomicMin(&state.tris, 0x80000000u);
    }
    let cap = params.caps2.x;
    let before = (min(base, cap) + WG - 1u) / WG;
    let groups = (min(end, cap) + WG - 1u) / WG;
    if groups > before {
        atomicMax(&state.tri_args[0], min(groups, params.caps.z));
        atomicMax(&state.tri_args[1], (groups + params.caps.z - 1u) / params.caps.z);
    }
    return base;
}

// Writes every triangle pair of two overlapping leaves to the triangle list from entry `w` on
// (past its capacity nothing is written; the CPU sees `state.tris` above it and re-runs with a
// larger list); returns the entry after them.
fn write_leaf_pair(p: u32, na: Node, nb: Node, w0: u32) -> u32 {
    var w = w0;
    for (var i = 0u; i < na.count; i++) {
        for (var j = 0u; j < nb.count; j++) {
            if w < params.caps2.x {
                tri_list[w] = vec4<u32>(p, na.first + i, nb.first + j, 0u);
            }
            w++;
        }
    }
    return w;
}

// The x extent of the grid of `m` invocations (`query::grid_args`, and the raises of
// `append_args` and `reserve_tris`, the same formula):
// read from the counts rather than `@builtin(num_workgroups)`, which D3D12 reports as 0 when
// wgpu's indirect-call validation is off (frcd-gpgpu's own instances turn it off).
fn grid_x(m: u32) -> u32 {
    return min((m + WG - 1u) / WG, params.caps.z);
}

// The next level's indirect arguments, raised to cover entries [base, base + k) of its
// frontier (at most the capacity), one invocation each: ceil(m / WG) workgroups as
// `query::grid_args` lays them out, x = min(groups, caps.z) and y = ceil(groups /
// caps.z), both non-decreasing in m, so the largest raise is the arguments of the final size.
// Only the append that opens a new workgroup raises them, so the atomics stay few. An append
// past the capacity also records the size asked for (`needed`).
fn append_args(base: u32, k: u32) {
    let cap = params.caps.x;
    let end = base + k;
    if end > cap {
        atomicMax(&state.needed, end);
    }
    let before = (min(base, cap) + WG - 1u) / WG;
    let groups = (min(end, cap) + WG - 1u) / WG;
    if groups > before {
        atomicMax(&args_next[0], min(groups, params.caps.z));
        atomicMax(&args_next[1], (groups + params.caps.z - 1u) / params.caps.z);
    }
}

// The triangle test of one listed pair: (pair, triangle of A, triangle of B | UNCERTAIN_FLAG,
// 1 unless certainly disjoint), as input-mesh indices.
fn test_listed(entry: vec4<u32>) -> vec4<u32> {
    load_test_pose(entry.x);
    let lay = arena.tri_layout;
    let sa = slot(lay, 3u, pose.base.y + entry.y);
    let sb = slot(lay, 3u, pose.base.w + entry.z);
    let a0 = texel(tris, sa, 0u);
    let a1 = texel(tris, sa, 1u);
    let a2 = texel(tris, sa, 2u);
    let b0 = texel(tris, sb, 0u);
    let b1 = texel(tris, sb, 1u);
    let b2 = texel(tris, sb, 2u);
    return reported(entry.x, a0, b0, tri_pair(entry.x, a0, a1, a2, b0, b1, b2));
}

// Pair p's pose for the triangle tests: the f32 pose from its texels, the path and grid
// exponents (`PairInfo.fix`) from the fifth (a texel, not the pair table: see `poses`); the
// exact path's limbs are read from the pair table by `exact_w`.
fn load_test_pose(p: u32) {
    load_pose(p);
    let w4 = textureLoad(poses, vec2<u32>((p & 255u) * 5u + 4u, p >> 8u), 0);
    pose.fix = bitcast<vec4<i32>>(vec4<u32>(w4.yzw, 0u));
}

// The output entry of pair p's triangles whose first texels are `a0` and `b0`, tested `r`:
// (pair, triangle of A, triangle of B | UNCERTAIN_FLAG, 1 unless certainly disjoint), as
// input-mesh indices.
fn reported(p: u32, a0: vec4<f32>, b0: vec4<f32>, r: u32) -> vec4<u32> {
    var tag = u32(b0.w);
    if r == TRI_UNCERTAIN {
        tag = tag | UNCERTAIN_FLAG;
    }
    return vec4<u32>(p, u32(a0.w), tag, select(0u, 1u, r != TRI_DISJOINT));
}

// One listed triangle pair per invocation: the triangle test, and the pair appended to the
// output (`frontier_out` is bound to the output buffer here) unless it is certainly disjoint.
@compute @workgroup_size(64)
fn triangles(@builtin(workgroup_id) wid: vec3<u32>,
             @builtin(local_invocation_index) lid: u32) {
    let m = min(atomicLoad(&state.tris), params.caps2.x);
    let idx = (wid.y * grid_x(m) + wid.x) * WG + lid;
    if idx >= m {
        return;
    }
    let t = test_listed(frontier_in[idx]);
    if t.w != 0u {
        let o = atomicAdd(&state.out, 1u);
        if o < params.caps.y {
            frontier_out[o] = vec4<u32>(t.xyz, 0u);
        }
    }
}

// One frontier entry expanded: its (up to) four child pairs, child x of A's with child y of
// B's, tested. One invocation rather than four: the pose and the entry are read once, and each
// of B's children is mapped into A's frame once for both of A's (on a SIMD software driver
// such as llvmpipe the texel fetches were about 45 % of this pass, 2026-12-02).
struct Expansion {
    a0: Node,
    a1: Node,
    b0: Node,
    b1: Node,
    // Overlapping child pairs of two leaves: list their triangle pairs (00, 10, 01, 11).
    leaf: vec4<bool>,
    // Overlapping child pairs with an internal node: one next-frontier entry each.
    down: vec4<bool>,
    // Triangle pairs the leaf pairs list, and next-frontier entries.
    k: u32,
    n: u32,
    // The next-frontier entries' node words: A's children 0 and 1, B's 0 and 1.
    ea0: u32,
    ea1: u32,
    eb0: u32,
    eb1: u32,
}

fn expand(entry: vec4<u32>) -> Expansion {
    var x: Expansion;
    let one_a = (entry.y & ONE_NODE) != 0u;
    let one_b = (entry.z & ONE_NODE) != 0u;
    // Node indices in the frontier are relative to each mesh's first node; a single node has no
    // second child: its second "child" is itself again, and its pairs are not tested.
    let ia = entry.y & ~ONE_NODE;
    let ib = entry.z & ~ONE_NODE;
    // Only the f32 pose, the bases and the axes' bound (the exact path's words are the
    // triangle pass's).
    load_pose(entry.x);
    load_pose_eps(entry.x);
    x.a0 = load_node(pose.base.x + ia);
    x.a1 = load_node(pose.base.x + ia + select(1u, 0u, one_a));
    x.b0 = load_node(pose.base.z + ib);
    x.b1 = load_node(pose.base.z + ib + select(1u, 0u, one_b));
    let mb0 = map_b(x.b0);
    let mb1 = map_b(x.b1);
    let o = vec4<bool>(
        obb_overlap(x.a0, mb0, pose_eps),
        !one_a && obb_overlap(x.a1, mb0, pose_eps),
        !one_b && obb_overlap(x.a0, mb1, pose_eps),
        !one_a && !one_b && obb_overlap(x.a1, mb1, pose_eps));
    // Overlapping pairs of two leaves list their triangle pairs; the others (at least one
    // internal node) become one entry of the next frontier, which descends both trees at once
    // where both are internal (a leaf stays as it is): the pair tree's depth is then the
    // deeper of the two trees, which bounds the number of levels recorded on the CPU.
    x.leaf = o & vec4<bool>(x.a0.leaf && x.b0.leaf, x.a1.leaf && x.b0.leaf,
                            x.a0.leaf && x.b1.leaf, x.a1.leaf && x.b1.leaf);
    x.down = o & !x.leaf;
    let sizes = vec4<u32>(x.a0.count * x.b0.count, x.a1.count * x.b0.count,
                          x.a0.count * x.b1.count, x.a1.count * x.b1.count);
    let ks = select(vec4<u32>(0u), sizes, x.leaf);
    x.k = ks.x + ks.y + ks.z + ks.w;
    let ns = select(vec4<u32>(0u), vec4<u32>(1u), x.down);
    x.n = ns.x + ns.y + ns.z + ns.w;
    // A child's entry names its children by the first one, or a leaf itself.
    x.ea0 = select(x.a0.first_child, ia | ONE_NODE, x.a0.leaf);
    x.ea1 = select(x.a1.first_child, (ia + 1u) | ONE_NODE, x.a1.leaf);
    x.eb0 = select(x.b0.first_child, ib | ONE_NODE, x.b0.leaf);
    x.eb1 = select(x.b1.first_child, (ib + 1u) | ONE_NODE, x.b1.leaf);
    return x;
}

@compute @workgroup_size(64)
fn traverse(@builtin(workgroup_id) wid: vec3<u32>,
            @builtin(local_invocation_index) lid: u32) {
    // On overflow only the first `caps.x` entries were written: those run (the answer is
    // discarded and the batch re-run with a larger frontier).
    let cur = min(atomicLoad(&state.counts[level.slots.x]), params.caps.x);
    // Every level after the first runs at least one workgroup (its arguments start at (1, 1, 1);
    // an empty first level runs none, and its level after next starts from the CPU's values),
    // whose first invocation does the level's bookkeeping: the counter and the arguments of the
    // level after the next one, which nobody reads during this level, back to their start.
    if wid.x == 0u && wid.y == 0u && lid == 0u {
        atomicStore(&state.counts[level.slots.z], 0u);
        args_after[0] = 1u;
        args_after[1] = 1u;
        args_after[2] = 1u;
        if cur > 0u {
            atomicAdd(&state.levels, 1u);
            // Entries; the CPU counts four child pairs per entry (a single node's missing
            // children included).
            atomicAdd(&state.pairs_tested, cur);
        }
    }
    let idx = (wid.y * grid_x(cur) + wid.x) * WG + lid;
    if idx >= cur {
        return;
    }
    let entry = frontier_in[idx];
    let x = expand(entry);
    if x.k > 0u {
        var w = reserve_tris(x.k);
        if x.leaf.x { w = write_leaf_pair(entry.x, x.a0, x.b0, w); }
        if x.leaf.y { w = write_leaf_pair(entry.x, x.a1, x.b0, w); }
        if x.leaf.z { w = write_leaf_pair(entry.x, x.a0, x.b1, w); }
        if x.leaf.w { w = write_leaf_pair(entry.x, x.a1, x.b1, w); }
    }
    if x.n == 0u {
        return;
    }
    var w = atomicAdd(&state.counts[level.slots.y], x.n);
    append_args(w, x.n);
    // Past capacity nothing is written; the CPU sees `needed` above the capacity and re-runs.
    let cap = params.caps.x;
    if x.down.x {
        if w < cap { frontier_out[w] = vec4<u32>(entry.x, x.ea0, x.eb0, 0u); }
        w++;
    }
    if x.down.y {
        if w < cap { frontier_out[w] = vec4<u32>(entry.x, x.ea1, x.eb0, 0u); }
        w++;
    }
    if x.down.z {
        if w < cap { frontier_out[w] = vec4<u32>(entry.x, x.ea0, x.eb1, 0u); }
        w++;
    }
    if x.down.w {
        if w < cap { frontier_out[w] = vec4<u32>(entry.x, x.ea1, x.eb1, 0u); }
    }
}

// ---- the one-pass traversal (`traverse_all`) ----
//
// The whole batch in one dispatch of `one_pass.x` workgroups, for drivers where a dispatch
// costs more than the work of a level (a software driver such as llvmpipe: 100-200 µs a level
// before it does any work, measured 2026-12-02). Workgroup g owns the first level's entries
// g, g + G, g + 2G, ... (G workgroups; the CPU's front interleaves the body pairs, so each
// gets a share of every pair), copies them to its region of `halves` and descends them level
// by level on its own, the levels separated by workgroup barriers: its frontier is that region
// (two halves of `one_pass.y` entries each, one read and one written per level), its list its
// region of `tri_list` (caps2.x / G entries), tested after its last level. No workgroup waits
// for another (WGSL gives no barrier across workgroups, and a driver need not run them at
// once). Overflow of a region records what the whole buffer would need (the region's demand
// times G) and stops the workgroup; the CPU re-runs with larger buffers, as for the level
// chain.
//
// The list holds one entry per overlapping pair of leaves, (pair, A's leaf word, B's leaf word)
// (a leaf's word is its first triangle and count, `Node.first_child`), not one per triangle
// pair as the level chain's does; `test_leaf_pair` tests the leaves' triangles against each
// other. On llvmpipe every storage access in the code is a loop over the lanes, run whether
// or not a lane takes it: listing the triangle pairs (nested loops of stores per leaf pair)
// took 15-30 % of a 64-part frame's traversal (2026-12-02), one store per leaf pair far less.
//
// llvmpipe silently ends an invocation's loops once they have run 65,535 iterations in all, so
// each workgroup counts a bound on its invocations' iterations before the copy of its first
// level, before each level (one per WG entries, plus the level's own) and before its leaf-pair
// tests (caps2.z per WG listed leaf pairs: the loop over them and the two loops over their
// triangles), and stops short of the budget caps2.y, flagging `counts[2]`: the CPU then re-runs
// the batch as the level chain. The budget (at most `ONE_PASS_LOOP_BUDGET`) also bounds what a
// workgroup lists: at most four leaf pairs per entry, WG entries per budgeted iteration, far
// below 2^31, so its list counter never wraps.
@group(1) @binding(10) var<storage, read_write> halves: array<vec4<u32>>;
@group(1) @binding(11) var<storage, read_write> out_all: array<vec4<u32>>;

var<workgroup> wg_next: atomic<u32>;
var<workgroup> wg_tris: atomic<u32>;
var<workgroup> wg_count: u32;
var<workgroup> wg_stopped: u32;

// Lists the overlapping leaves `na` of pair p's A and `nb` of its B at entry `w` of this
// workgroup's list (`first`: the region's first entry, `cap`: its size; nothing is written past
// it, and the list's total below tells the CPU).
fn list_leaf_pair(w: u32, first: u32, cap: u32, p: u32, na: Node, nb: Node) {
    if w < cap {
        tri_list[first + w] = vec4<u32>(p, na.first_child, nb.first_child, 0u);
    }
}

// The triangle tests of one listed pair of leaves (`entry`: pair, A's leaf word, B's leaf
// word): every triangle of A's leaf against every triangle of B's, each pair appended to the
// output, as `test_listed` does for one pair, unless it is certainly disjoint.
fn test_leaf_pair(entry: vec4<u32>) {
    load_test_pose(entry.x);
    let lay = arena.tri_layout;
    let first_a = entry.y & 0xffffffu;
    let count_a = (entry.y >> 24u) + 1u;
    let first_b = entry.z & 0xffffffu;
    let count_b = (entry.z >> 24u) + 1u;
    for (var i = 0u; i < count_a; i++) {
        let sa = slot(lay, 3u, pose.base.y + first_a + i);
        let a0 = texel(tris, sa, 0u);
        let a1 = texel(tris, sa, 1u);
        let a2 = texel(tris, sa, 2u);
        for (var j = 0u; j < count_b; j++) {
            let sb = slot(lay, 3u, pose.base.w + first_b + j);
            let b0 = texel(tris, sb, 0u);
            let b1 = texel(tris, sb, 1u);
            let b2 = texel(tris, sb, 2u);
            let t = reported(entry.x, a0, b0, tri_pair(entry.x, a0, a1, a2, b0, b1, b2));
            if t.w != 0u {
                let o = atomicAdd(&state.out, 1u);
                if o < params.caps.y {
                    out_all[o] = vec4<u32>(t.xyz, 0u);
                }
            }
        }
    }
}

@compute @workgroup_size(64)
fn traverse_all(@builtin(workgroup_id) wid: vec3<u32>,
                @builtin(local_invocation_index) lid: u32) {
    let g = wid.x;
    let groups = params.one_pass.x;
    let region = params.one_pass.y;
    let roots = params.one_pass.z;
    let tri_region = params.caps2.x / groups;
    let tri_first = g * tri_region;
    if lid == 0u {
        atomicStore(&wg_next, 0u);
        atomicStore(&wg_tris, 0u);
        wg_stopped = 0u;
    }
    // The first level: entries g, g + G, ... of the CPU's (`frontier_in`).
    var cur = select(0u, (roots - g + groups - 1u) / groups, g < roots);
    var half = 0u;
    var level = 0u;
    // Loop iterations spent (a bound, the same in every invocation), and whether the budget
    // stopped the workgroup.
    let budget = params.caps2.y;
    var spent = 0u;
    var over = false;
    // The first level copied to this workgroup's first half, so that every level reads one
    // buffer (on llvmpipe a storage access is paid in full even where no lane takes it). A
    // share above the region (roots beyond what the regions hold, whose level capacity need
    // not be a multiple of G) records its demand and stops, as an overflowing level does; the
    // CPU re-runs with larger buffers.
    if cur > region {
        atomicMax(&state.needed, min(cur, 0xffffffffu / groups) * groups);
        cur = 0u;
    } else if cur > 0u {
        let rounds = (cur + WG - 1u) / WG;
        if rounds >= budget {
            over = true;
            cur = 0u;
        } else {
            spent = rounds + 1u;
            for (var j = lid; j < cur; j += WG) {
                halves[g * region + j] = frontier_in[g + j * groups];
            }
            storageBarrier();
        }
    }
    loop {
        if cur == 0u || level >= params.one_pass.w {
            break;
        }
        // This level: its own iteration of the level loop, and one per WG-wide round of its
        // entries.
        let rounds = (cur + WG - 1u) / WG;
        if rounds >= budget - min(spent, budget) {
            over = true;
            break;
        }
        spent += rounds + 1u;
        workgroupBarrier();
        let read_base = half * region * groups + g * region;
        let write_base = (1u - half) * region * groups + g * region;
        for (var j = lid; j < cur; j += WG) {
            let entry = halves[read_base + j];
            let x = expand(entry);
            // Overlapping pairs of leaves: one list entry each.
            let ls = select(vec4<u32>(0u), vec4<u32>(1u), x.leaf);
            let nl = ls.x + ls.y + ls.z + ls.w;
            if nl > 0u {
                var w = atomicAdd(&wg_tris, nl);
                if x.leaf.x {
                    list_leaf_pair(w, tri_first, tri_region, entry.x, x.a0, x.b0);
                    w++;
                }
                if x.leaf.y {
                    list_leaf_pair(w, tri_first, tri_region, entry.x, x.a1, x.b0);
                    w++;
                }
                if x.leaf.z {
                    list_leaf_pair(w, tri_first, tri_region, entry.x, x.a0, x.b1);
                    w++;
                }
                if x.leaf.w {
                    list_leaf_pair(w, tri_first, tri_region, entry.x, x.a1, x.b1);
                }
            }
            if x.n > 0u {
                var w = atomicAdd(&wg_next, x.n);
                // Past the region nothing is written; the level's total below stops the
                // workgroup and tells the CPU.
                if x.down.x {
                    if w < region { halves[write_base + w] = vec4<u32>(entry.x, x.ea0, x.eb0, 0u); }
                    w++;
                }
                if x.down.y {
                    if w < region { halves[write_base + w] = vec4<u32>(entry.x, x.ea1, x.eb0, 0u); }
                    w++;
                }
                if x.down.z {
                    if w < region { halves[write_base + w] = vec4<u32>(entry.x, x.ea0, x.eb1, 0u); }
                    w++;
                }
                if x.down.w {
                    if w < region { halves[write_base + w] = vec4<u32>(entry.x, x.ea1, x.eb1, 0u); }
                }
            }
        }
        // The level's appends are visible to the whole workgroup after this barrier.
        storageBarrier();
        workgroupBarrier();
        if lid == 0u {
            let next = atomicLoad(&wg_next);
            atomicStore(&wg_next, 0u);
            atomicAdd(&state.pairs_tested, cur);
            var stop = 0u;
            if next > region {
                // What the whole frontier must hold for this workgroup's region to fit.
                atomicMax(&state.needed, min(next, 0xffffffffu / groups) * groups);
                stop = 1u;
            }
            wg_count = select(next, 0u, stop != 0u);
            wg_stopped = stop;
        }
        cur = workgroupUniformLoad(&wg_count);
        half = 1u - half;
        level++;
    }
    // This workgroup's level count (the batch reports the most), and entries left if it ran
    // out of levels (the CPU's depth bound was wrong: an internal error).
    let stopped = workgroupUniformLoad(&wg_stopped) != 0u;
    if lid == 0u {
        atomicMax(&state.levels, level);
        if over {
            atomicMax(&state.counts[2], 1u);
        } else if !stopped && cur > 0u {
            atomicAdd(&state.counts[1], cur);
        }
        wg_count = atomicLoad(&wg_tris);
    }
    // The triangle tests of this workgroup's list; an overflowing list records the whole list's
    // demand (its own times G) and is not tested.
    let listed = workgroupUniformLoad(&wg_count);
    if lid == 0u {
        let total = select(listed, min(listed, 0xffffffffu / groups) * groups, listed > tri_region);
        atomicAdd(&state.tris, total);
    }
    if listed > tri_region || stopped || over {
        return;
    }
    // caps2.z per WG-wide round of listed leaf pairs.
    let rounds = (listed + WG - 1u) / WG;
    if rounds > (budget - min(spent, budget)) / max(params.caps2.z, 1u) {
        if lid == 0u {
            atomicMax(&state.counts[2], 1u);
        }
        return;
    }
    for (var j = lid; j < listed; j += WG) {
        test_leaf_pair(tri_list[tri_first + j]);
    }
}
