//! `#[repr(C)]` Rust mirrors of the structs declared in the WGSL [`crate::PRELUDE`]: what the CPU
//! writes to and reads from the shaders' buffers, by name instead of word offsets.
//! `tests/layout.rs` checks every mirror (size, member names, offsets and sizes) against naga's
//! reflection of the prelude, so the two cannot drift apart.

use bytemuck::{Pod, Zeroable};

/// `State`: the counters of one frcd-gpgpu traversal batch (read back after the batch).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct State {
    /// Entries appended to each level's frontier, by level mod 3 (after the batch, the entry
    /// of `levels % 3` holds what the last level left: 0 when the traversal finished). The
    /// one-pass traversal: `[1]` entries left after the most levels, `[2]` non-zero when a
    /// workgroup stopped at its loop budget.
    pub counts: [u32; 3],
    /// Triangle pairs appended to the output (may exceed its capacity: overflow).
    pub out: u32,
    /// The batch's root pairs, or the largest frontier size requested where that exceeded
    /// the frontier's capacity (overflow).
    pub needed: u32,
    /// Levels that had work (the one-pass traversal: the most any of its workgroups ran).
    pub levels: u32,
    /// Frontier entries expanded (each tests up to four child pairs).
    pub pairs_tested: u32,
    /// Triangle pairs appended to the triangle list (may exceed its capacity: overflow).
    pub tris: u32,
    /// The triangle pass's indirect arguments `(x, y, z)` (the traversal raises them as it
    /// lists triangle pairs; they start at `(0, 1, 1)`).
    pub tri_args: [u32; 3],
}

/// `Level`: which counters and indirect-argument buffers one traversal level uses
/// (`L % 3`, `(L + 1) % 3`, `(L + 2) % 3`, unused).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct Level {
    /// `[L % 3, (L + 1) % 3, (L + 2) % 3, 0]`.
    pub slots: [u32; 4],
}

/// `Params`: capacities of one frcd-gpgpu batch.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct Params {
    /// Frontier capacity, output capacity, max workgroups per dimension, pairs in the batch.
    pub caps: [u32; 4],
    /// Triangle list capacity; the one-pass traversal's loop budget per invocation and loop
    /// iterations per frontier entry at most; unused.
    pub caps2: [u32; 4],
    /// The one-pass traversal: workgroups, frontier entries per workgroup (in each of its two
    /// halves), the first level's entries, most levels.
    pub one_pass: [u32; 4],
}

/// `Arena`: shape of frcd-gpgpu's mesh arena textures.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct Arena {
    /// Nodes per row, rows per layer (both powers of two), log2 of each.
    pub node_layout: [u32; 4],
    /// Triangles per row, rows per layer (both powers of two), log2 of each.
    pub tri_layout: [u32; 4],
}

/// `PairInfo`: one body pair of a frcd-gpgpu batch.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PairInfo {
    /// Row 0 of R (B local to A local), w unused.
    pub r0: [f32; 4],
    /// Row 1 of R.
    pub r1: [f32; 4],
    /// Row 2 of R.
    pub r2: [f32; 4],
    /// Translation, w unused.
    pub t: [f32; 4],
    /// A's first node, A's first triangle, B's first node, B's first triangle.
    pub base: [u32; 4],
    /// The triangle pass's exact path: (1 exact / 0 rotated, A's grid exponent, B's, unused).
    pub fix: [i32; 4],
    /// Column 0 of the fixed-point rotation `M = round(R 2^46)`: `M0 | M1 << 16` per row.
    pub m_lo0: [u32; 4],
    /// Column 1 of `M`, low limbs.
    pub m_lo1: [u32; 4],
    /// Column 2 of `M`, low limbs.
    pub m_lo2: [u32; 4],
    /// Column 0 of `M`: `M >> 32` per row.
    pub m_hi0: [i32; 4],
    /// Column 1 of `M`, high limbs.
    pub m_hi1: [i32; 4],
    /// Column 2 of `M`, high limbs.
    pub m_hi2: [i32; 4],
    /// `t` on the fine grid, `T0 | T1 << 16` per coordinate.
    pub t01: [u32; 4],
    /// `T2 | T3 << 16` per coordinate.
    pub t23: [u32; 4],
    /// `T >> 64` per coordinate.
    pub t4: [i32; 4],
}

/// `BodyBox`: one body's world box for the box pass, outer and inner f32 corners.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct BodyBox {
    /// Lower corner rounded down.
    pub lo_dn: [f32; 4],
    /// Upper corner rounded up.
    pub hi_up: [f32; 4],
    /// Lower corner rounded up.
    pub lo_up: [f32; 4],
    /// Upper corner rounded down.
    pub hi_dn: [f32; 4],
}

/// `BoxParams`: body count and output capacity of the box pass.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct BoxParams {
    /// Body count, output capacity, padded count (the sweep; unused by the all-pairs pass),
    /// unused.
    pub n: [u32; 4],
}

/// `SortStage`: one step `(k, j)` of the box sweep's bitonic sort (`k = 0`: a block's whole
/// presort); bound with a dynamic offset, one per dispatch.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct SortStage {
    /// `k`, `j`, unused, unused.
    pub kj: [u32; 4],
}

/// `Draw`: frcd-image's clip-from-local matrix (column-major).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Draw {
    /// Column-major 4×4 matrix.
    pub clip_from_local: [[f32; 4]; 4],
}

/// `ResolveParams`: frcd-image's per-layer resolve parameters.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ResolveParams {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Facing code of faces where the view ray enters the solid.
    pub entering_code: u32,
    /// Padding.
    pub _pad0: u32,
    /// Depth of the overlap region's near face.
    pub depth_ref: f32,
    /// World length of the depth range.
    pub depth_scale: f32,
    /// Padding.
    pub _pad1: f32,
    /// Padding.
    pub _pad2: f32,
}

/// One mirror as `(WGSL name, size, [(member, offset, size)])`.
#[doc(hidden)]
pub type MirrorLayout = (&'static str, usize, Vec<(&'static str, usize, usize)>);

/// Every mirror's layout, for the reflection test.
#[doc(hidden)]
pub fn mirrors() -> Vec<MirrorLayout> {
    use std::mem::{offset_of, size_of};
    macro_rules! m {
        ($t:ident { $($f:ident : $ft:ty),* }) => {
            (stringify!($t), size_of::<$t>(), vec![$((stringify!($f), offset_of!($t, $f), size_of::<$ft>())),*])
        };
    }
    vec![
        m!(State {
            counts: [u32; 3],
            out: u32,
            needed: u32,
            levels: u32,
            pairs_tested: u32,
            tris: u32,
            tri_args: [u32; 3]
        }),
        m!(Level { slots: [u32; 4] }),
        m!(Params {
            caps: [u32; 4],
            caps2: [u32; 4],
            one_pass: [u32; 4]
        }),
        m!(Arena {
            node_layout: [u32; 4],
            tri_layout: [u32; 4]
        }),
        m!(PairInfo {
            r0: [f32; 4],
            r1: [f32; 4],
            r2: [f32; 4],
            t: [f32; 4],
            base: [u32; 4],
            fix: [i32; 4],
            m_lo0: [u32; 4],
            m_lo1: [u32; 4],
            m_lo2: [u32; 4],
            m_hi0: [i32; 4],
            m_hi1: [i32; 4],
            m_hi2: [i32; 4],
            t01: [u32; 4],
            t23: [u32; 4],
            t4: [i32; 4]
        }),
        m!(BodyBox {
            lo_dn: [f32; 4],
            hi_up: [f32; 4],
            lo_up: [f32; 4],
            hi_dn: [f32; 4]
        }),
        m!(BoxParams { n: [u32; 4] }),
        m!(SortStage { kj: [u32; 4] }),
        m!(Draw {
            clip_from_local: [[f32; 4]; 4]
        }),
        m!(ResolveParams {
            width: u32,
            height: u32,
            entering_code: u32,
            _pad0: u32,
            depth_ref: f32,
            depth_scale: f32,
            _pad1: f32,
            _pad2: f32
        }),
    ]
}
