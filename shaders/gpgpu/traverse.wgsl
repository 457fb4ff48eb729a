// frcd-gpgpu: one level of the breadth-first traversal of the pair tree of two OBB trees.
//
// Each invocation takes one (node of A, node of B) pair from the current frontier and runs the
// separating-axis test in f32 with a computed error bound, so rounding can only keep a pair, never
// drop one. Overlapping internal pairs append their child pairs to the next frontier (atomic
// compaction); overlapping leaf pairs run the triangle test (Guigue-Devillers orientation form) and
// append the triangle pair, flagged "uncertain" when a sign it needs is within the bound of zero.
//
// Everything is computed in A's local frame: B's geometry is mapped by the relative pose (R, t).
// Textures hold each tree in its own local frame (rgba32float, one texel = 4 floats):
//   node i: 5 texels  (c.xyz, 0) (a0.xyz, h0) (a1.xyz, h1) (a2.xyz, h2) (right, first, count, 0)
//   triangle j (leaf order): 3 texels (v0.xyz, mesh index) (v1.xyz, 0) (v2.xyz, 0)
// Item i lives at row-major slot i of (layer, row, column group); see `texel_of`.

const WG: u32 = 64u;
// Unit roundoff of f32 (round to nearest): 2^-24.
const U: f32 = 5.9604645e-8;
const UNCERTAIN_FLAG: u32 = 0x80000000u;

struct MeshInfo {
    // items per texture row, rows per layer, node count, triangle count
    node_layout: vec4<u32>,
    tri_layout: vec4<u32>,
}

struct Pose {
    // Rows of the rotation R (B local -> A local), w unused.
    r0: vec4<f32>,
    r1: vec4<f32>,
    r2: vec4<f32>,
    // Translation t, w unused.
    t: vec4<f32>,
}

struct Params {
    // frontier capacity, output capacity, max workgroups per dimension, unused
    caps: vec4<u32>,
}

// Shared with control.wgsl (same layout).
struct State {
    // Pairs in the current frontier (set by the control pass).
    cur: u32,
    // Pairs appended to the next frontier (may exceed the capacity: overflow).
    next: atomic<u32>,
    // Triangle pairs appended to the output (may exceed the capacity: overflow).
    out: atomic<u32>,
    // Largest frontier size requested so far (control pass).
    needed: u32,
    // Levels that had work, and node pairs tested in total (control pass).
    levels: u32,
    pairs_tested: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var a_nodes: texture_2d_array<f32>;
@group(0) @binding(1) var a_tris: texture_2d_array<f32>;
@group(0) @binding(2) var b_nodes: texture_2d_array<f32>;
@group(0) @binding(3) var b_tris: texture_2d_array<f32>;
@group(0) @binding(4) var<uniform> a_info: MeshInfo;
@group(0) @binding(5) var<uniform> b_info: MeshInfo;
@group(0) @binding(6) var<uniform> pose: Pose;

@group(1) @binding(0) var<storage, read> frontier_in: array<vec2<u32>>;
@group(1) @binding(1) var<storage, read_write> frontier_out: array<vec2<u32>>;
@group(1) @binding(2) var<storage, read_write> state: State;
@group(1) @binding(3) var<storage, read_write> out_pairs: array<vec2<u32>>;
@group(1) @binding(4) var<uniform> params: Params;

struct Node {
    c: vec3<f32>,
    a0: vec3<f32>,
    a1: vec3<f32>,
    a2: vec3<f32>,
    h: vec3<f32>,
    right: u32,
    first: u32,
    count: u32,
}

fn load(t: texture_2d_array<f32>, lay: vec4<u32>, per_item: u32, i: u32, k: u32) -> vec4<f32> {
    let row_g = i / lay.x;
    let col = (i % lay.x) * per_item + k;
    let layer = row_g / lay.y;
    let row = row_g % lay.y;
    return textureLoad(t, vec2<u32>(col, row), layer, 0);
}

fn load_node(t: texture_2d_array<f32>, lay: vec4<u32>, i: u32) -> Node {
    let t0 = load(t, lay, 5u, i, 0u);
    let t1 = load(t, lay, 5u, i, 1u);
    let t2 = load(t, lay, 5u, i, 2u);
    let t3 = load(t, lay, 5u, i, 3u);
    let t4 = load(t, lay, 5u, i, 4u);
    var n: Node;
    n.c = t0.xyz;
    n.a0 = t1.xyz;
    n.a1 = t2.xyz;
    n.a2 = t3.xyz;
    n.h = vec3<f32>(t1.w, t2.w, t3.w);
    n.right = u32(t4.x);
    n.first = u32(t4.y);
    n.count = u32(t4.z);
    return n;
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

// B's box mapped into A's frame.
struct BoxB {
    c: vec3<f32>,
    b0: vec3<f32>,
    b1: vec3<f32>,
    b2: vec3<f32>,
}

// True when L separates the boxes for certain. The projection of a parallelepiped
// {c + sum s_i h_i a_i, |s_i| <= 1} on any vector L is exactly [c.L - r, c.L + r] with
// r = sum h_i |a_i . L|, so no orthonormality is assumed; `s` bounds (per unit of |L|_1) the
// difference between the computed and the true centre offset and radii, and 8u (ra + rb) covers
// the rounding of the radius sums and of the comparison.
fn separated(l: vec3<f32>, tt: vec3<f32>, na: Node, bb: BoxB, hb: vec3<f32>, s: f32) -> bool {
    let d = abs(dot(tt, l));
    let ra = na.h.x * abs(dot(na.a0, l)) + na.h.y * abs(dot(na.a1, l)) + na.h.z * abs(dot(na.a2, l));
    let rb = hb.x * abs(dot(bb.b0, l)) + hb.y * abs(dot(bb.b1, l)) + hb.z * abs(dot(bb.b2, l));
    let err = (s * l1(l) + 8.0 * U * (ra + rb)) * 1.01;
    // NaN or inf anywhere makes this false: the pair is kept.
    return d > ra + rb + err;
}

// Conservative OBB overlap: false only when some of the 15 axes separates the boxes with margin.
fn obb_overlap(na: Node, nb: Node) -> bool {
    var bb: BoxB;
    bb.b0 = rot(nb.a0);
    bb.b1 = rot(nb.a1);
    bb.b2 = rot(nb.a2);
    bb.c = rot(nb.c) + pose.t.xyz;
    let tt = bb.c - na.c;
    // Centre error: R and t rounding, the 4-term sum, T's subtraction and the T.L dot product.
    // Radius error: 3-term dots against A's axes; B's rotated axes carry <= 7u |L|_1 each plus
    // their dot, all scaled by the half extents.
    let s = 6.0 * U * (l1(nb.c) + l1(pose.t.xyz)) + 5.0 * U * l1(tt)
        + 4.0 * U * (na.h.x + na.h.y + na.h.z) + 11.0 * U * (nb.h.x + nb.h.y + nb.h.z);
    let hb = nb.h;
    if separated(na.a0, tt, na, bb, hb, s) { return false; }
    if separated(na.a1, tt, na, bb, hb, s) { return false; }
    if separated(na.a2, tt, na, bb, hb, s) { return false; }
    if separated(bb.b0, tt, na, bb, hb, s) { return false; }
    if separated(bb.b1, tt, na, bb, hb, s) { return false; }
    if separated(bb.b2, tt, na, bb, hb, s) { return false; }
    if separated(cross(na.a0, bb.b0), tt, na, bb, hb, s) { return false; }
    if separated(cross(na.a0, bb.b1), tt, na, bb, hb, s) { return false; }
    if separated(cross(na.a0, bb.b2), tt, na, bb, hb, s) { return false; }
    if separated(cross(na.a1, bb.b0), tt, na, bb, hb, s) { return false; }
    if separated(cross(na.a1, bb.b1), tt, na, bb, hb, s) { return false; }
    if separated(cross(na.a1, bb.b2), tt, na, bb, hb, s) { return false; }
    if separated(cross(na.a2, bb.b0), tt, na, bb, hb, s) { return false; }
    if separated(cross(na.a2, bb.b1), tt, na, bb, hb, s) { return false; }
    if separated(cross(na.a2, bb.b2), tt, na, bb, hb, s) { return false; }
    return true;
}

// ---- triangle-triangle test ----

const TRI_DISJOINT: u32 = 0u;
const TRI_TOUCH: u32 = 1u;
const TRI_UNCERTAIN: u32 = 2u;

// Sign of v when |v| > e for certain; 0 means "not certain" (NaN included).
fn sgn(v: f32, e: f32) -> i32 {
    if v > e { return 1; }
    if v < -e { return -1; }
    return 0;
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
    if v1 > 0 || v2 > 0 { return TRI_DISJOINT; }
    if v1 < 0 && v2 < 0 { return TRI_TOUCH; }
    return TRI_UNCERTAIN;
}

// Second permutation step: make p2 the lone vertex of triangle 2 w.r.t. plane 1 (signs strict).
fn tri_tri_3d(p1: vec3<f32>, q1: vec3<f32>, r1: vec3<f32>,
              p2: vec3<f32>, q2: vec3<f32>, r2: vec3<f32>,
              sp2: i32, sq2: i32, sr2: i32, e: f32) -> u32 {
    if sp2 > 0 {
        if sq2 > 0 { return check_min_max(p1, r1, q1, r2, p2, q2, e); }
        if sr2 > 0 { return check_min_max(p1, r1, q1, q2, r2, p2, e); }
        return check_min_max(p1, q1, r1, p2, q2, r2, e);
    }
    if sq2 < 0 { return check_min_max(p1, q1, r1, r2, p2, q2, e); }
    if sr2 < 0 { return check_min_max(p1, q1, r1, q2, r2, p2, e); }
    return check_min_max(p1, r1, q1, p2, q2, r2, e);
}

// Decides whether triangle (p1, q1, r1) (A frame) meets triangle (pb, qb, rb) (B frame, mapped by
// the pose here). Every sign is taken only when the computed value exceeds a forward error bound
// that covers the f32 storage of the vertices, the pose's rounding and the arithmetic; a sign that
// is not certain (touching, coplanar, degenerate, or simply too close) makes the answer
// TRI_UNCERTAIN and the CPU decides that pair exactly.
fn tri_tri(p1: vec3<f32>, q1: vec3<f32>, r1: vec3<f32>,
           pb: vec3<f32>, qb: vec3<f32>, rb: vec3<f32>) -> u32 {
    let p2 = rot(pb) + pose.t.xyz;
    let q2 = rot(qb) + pose.t.xyz;
    let r2 = rot(rb) + pose.t.xyz;
    // Per-coordinate distance of the points used here from the f64 points the exact test sees.
    let pa_mag = max(maxabs(p1), max(maxabs(q1), maxabs(r1)));
    let pb_mag = max(maxabs(pb), max(maxabs(qb), maxabs(rb)));
    let delta = max(1.01 * U * pa_mag, U * (20.0 * pb_mag + 6.0 * maxabs(pose.t.xyz)));
    // Box side of the six points bounds every coordinate difference.
    let lo = min(min(min(p1, q1), min(r1, p2)), min(q2, r2));
    let hi = max(max(max(p1, q1), max(r1, p2)), max(q2, r2));
    let ext = hi - lo;
    let d = (max(ext.x, max(ext.y, ext.z)) + 2.0 * delta) * (1.0 + 4.0 * U);
    // |computed det - exact det|: rounding 7u * permanent (<= 6 d^3), input perturbation
    // (first, second, third order in delta), with margin for evaluating this bound in f32.
    let e = (48.0 * U * d * d * d + 32.0 * delta * d * d + 64.0 * delta * delta * d
        + 42.0 * delta * delta * delta) * 1.01;

    let sp1 = sgn(orient(p2, q2, r2, p1), e);
    let sq1 = sgn(orient(p2, q2, r2, q1), e);
    let sr1 = sgn(orient(p2, q2, r2, r1), e);
    if sp1 != 0 && sp1 == sq1 && sp1 == sr1 { return TRI_DISJOINT; }
    let sp2 = sgn(orient(p1, q1, r1, p2), e);
    let sq2 = sgn(orient(p1, q1, r1, q2), e);
    let sr2 = sgn(orient(p1, q1, r1, r2), e);
    if sp2 != 0 && sp2 == sq2 && sp2 == sr2 { return TRI_DISJOINT; }
    if sp1 == 0 || sq1 == 0 || sr1 == 0 || sp2 == 0 || sq2 == 0 || sr2 == 0 {
        return TRI_UNCERTAIN;
    }
    // Generic case: both triangles strictly straddle the other's plane. Rotate triangle 1 so
    // that its lone vertex comes first; if it lies on the negative side, flip plane 2 by
    // swapping q2 and r2.
    if sp1 > 0 {
        if sq1 > 0 { return tri_tri_3d(r1, p1, q1, p2, r2, q2, sp2, sr2, sq2, e); }
        if sr1 > 0 { return tri_tri_3d(q1, r1, p1, p2, r2, q2, sp2, sr2, sq2, e); }
        return tri_tri_3d(p1, q1, r1, p2, q2, r2, sp2, sq2, sr2, e);
    }
    if sq1 < 0 { return tri_tri_3d(r1, p1, q1, p2, q2, r2, sp2, sq2, sr2, e); }
    if sr1 < 0 { return tri_tri_3d(q1, r1, p1, p2, q2, r2, sp2, sq2, sr2, e); }
    return tri_tri_3d(p1, q1, r1, p2, r2, q2, sp2, sr2, sq2, e);
}

fn emit(ia: u32, ib: u32, uncertain: bool) {
    let slot = atomicAdd(&state.out, 1u);
    if slot < params.caps.y {
        var tag = ib;
        if uncertain {
            tag = ib | UNCERTAIN_FLAG;
        }
        out_pairs[slot] = vec2<u32>(ia, tag);
    }
}

fn leaf_pair(na: Node, nb: Node) {
    for (var i = 0u; i < na.count; i++) {
        let ja = na.first + i;
        let a0 = load(a_tris, a_info.tri_layout, 3u, ja, 0u);
        let a1 = load(a_tris, a_info.tri_layout, 3u, ja, 1u);
        let a2 = load(a_tris, a_info.tri_layout, 3u, ja, 2u);
        for (var j = 0u; j < nb.count; j++) {
            let jb = nb.first + j;
            let b0 = load(b_tris, b_info.tri_layout, 3u, jb, 0u);
            let b1 = load(b_tris, b_info.tri_layout, 3u, jb, 1u);
            let b2 = load(b_tris, b_info.tri_layout, 3u, jb, 2u);
            let r = tri_tri(a0.xyz, a1.xyz, a2.xyz, b0.xyz, b1.xyz, b2.xyz);
            if r != TRI_DISJOINT {
                emit(u32(a0.w), u32(b0.w), r == TRI_UNCERTAIN);
            }
        }
    }
}

@compute @workgroup_size(64)
fn traverse(@builtin(workgroup_id) wid: vec3<u32>,
            @builtin(num_workgroups) nwg: vec3<u32>,
            @builtin(local_invocation_index) lid: u32) {
    let idx = (wid.y * nwg.x + wid.x) * WG + lid;
    if idx >= state.cur {
        return;
    }
    let pair = frontier_in[idx];
    let na = load_node(a_nodes, a_info.node_layout, pair.x);
    let nb = load_node(b_nodes, b_info.node_layout, pair.y);
    if !obb_overlap(na, nb) {
        return;
    }
    let a_leaf = na.count > 0u;
    let b_leaf = nb.count > 0u;
    if a_leaf && b_leaf {
        leaf_pair(na, nb);
        return;
    }
    // Descend both trees at once where both are internal: the pair tree's depth is then the
    // deeper of the two trees, which bounds the number of levels recorded on the CPU.
    var ca = vec2<u32>(pair.x, pair.x);
    var nca = 1u;
    if !a_leaf {
        ca = vec2<u32>(pair.x + 1u, na.right);
        nca = 2u;
    }
    var cb = vec2<u32>(pair.y, pair.y);
    var ncb = 1u;
    if !b_leaf {
        cb = vec2<u32>(pair.y + 1u, nb.right);
        ncb = 2u;
    }
    let k = nca * ncb;
    let base = atomicAdd(&state.next, k);
    // Past capacity nothing is written; the control pass sees next > capacity and flags overflow.
    if base + k <= params.caps.x {
        var w = base;
        for (var i = 0u; i < nca; i++) {
            for (var j = 0u; j < ncb; j++) {
                frontier_out[w] = vec2<u32>(ca[i], cb[j]);
                w++;
            }
        }
    }
}
