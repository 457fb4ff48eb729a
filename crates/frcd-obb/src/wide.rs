//! The wide box test of the traversal: one 15-axis separating-axis test run on four box pairs
//! at once, in four f32 lanes (a plain `[f32; 4]` type the compiler vectorises: SSE on the
//! x86-64 baseline, AVX in the traversal's AVX2 build chosen at run time (`isa.rs`), NEON on
//! aarch64; no fused multiply-add, so every operation is one IEEE rounding whichever build
//! runs). The AVX2 build also runs two such tests as one eight-lane test ([`avx`], intrinsics:
//! the module's only unsafe code), with the same operations in the same order per lane.
//!
//! The traversal (`query/traverse.rs`) tests one node of one tree against the (up to four)
//! nodes two levels below a node of the other tree: A's grandchildren against one placed box of B, or
//! B's grandchildren, placed in A's frame in lanes, against one box of A. Each lane computes
//! exactly the scalar operations below, in the same order; a lane's answer does not depend on
//! the other lanes.
//!
//! # The f32 test and its error bound
//!
//! B's box is placed with the query's rotation rounded to f32 (`M32`), `R`, `t` and the radii
//! are formed in f32, and the centre offset `d = (M c_B + t) − c_A` is formed in f64 and rounded
//! once, so that every error scales with the pair's own sizes, not with the coordinates. With
//! `ε = 2⁻²⁴`, `D = ‖d‖₁`, `ΣH = ΣH_A + ΣH_B` (`u_i` the f32 axes of A, `v_j` those of B, both
//! orthonormal up to `η < 2⁻²²` (`nodes.rs`), so `|u_i|, |v_j| ≤ 1 + η`; one rounding per
//! operation):
//!
//! - `M32`: `|M32_kl − M_kl| ≤ ε |M_kl|`;
//! - placed axes `P_j[k] = (M32_k0 v_j0 + M32_k1 v_j1) + M32_k2 v_j2`:
//!   `|P32 − P| ≤ (ε + γ₃(1 + ε)) Σ_l |M_kl| |v_jl| ≤ 4.02 ε` per entry (`γₙ = nε/(1 − nε)`);
//! - `R_ij = (u_i0 P_j0 + u_i1 P_j1) + u_i2 P_j2`: `|R32 − R| ≤ 4.02 ε ‖u_i‖₁ +
//!   γ₃ ‖u_i‖ ‖P_j‖ ≤ 10.2 ε`, so `|R32| + `[`EPS_R32`]` ≥ |R| + `[`EPS_R`](crate::sat::EPS_R)
//!   and every radius the f32 test computes is at least `(1 − γ₆)` times the f64 test's radius
//!   (which is at most `1.03 ΣH`);
//! - `d`: `|d32_k − d_k| ≤ 1.01 ε |d_k|` (plus f64 rounding of order `2⁻⁵⁰ M`, `M` the query's
//!   magnitude); `t_i = u_i · d`: error `≤ 4.3 ε D`; B's face projections `P_j · d`:
//!   `≤ 8.3 ε D`; the cross projections `t_{i2} R_{i1 j} − t_{i1} R_{i2 j}`:
//!   `≤ 2·4.3·1.02 ε D + 2·1.01·10.2 ε D + 4.2 ε D ≤ 34 ε D`;
//! - the slack sum `S = (s + (C_H + EPS_R32)(ΣH_A + ΣH_B)) + C_D D` (it also carries the
//!   [`EPS_R32`] of every `|R_ij|`, see [`separation4`]), each radius sum and each
//!   `|projection| − radius` round by `γ₅` relative, far inside the factor 1.25 below.
//!
//! The test asks for a separation larger than `S` with `s = 2·slack` (the f64 query slack
//! rounded up to f32, at least `2⁻¹⁰⁰`), [`C_H`]` = 2⁻¹⁶ ≥ 1.25·SIGMA + 7 ε` and
//! [`C_D`]` = 2⁻¹⁸ = 64 ε`: when it finds one, the exact real margin of that axis exceeds
//! `1.25 ×` the f64 test's slack plus its sigma terms, so the f64 test of `sat.rs` (whose own
//! rounding is far below a quarter of its slack) separates the pair too, on the same axis. The
//! f32 test therefore never culls a pair the f64 test keeps (tested below on random, touching,
//! near-parallel, tiny and huge boxes, and at the f32 test's own threshold), and its margin on
//! an axis never exceeds the f64 margin on that axis, so it bounds the gap as the f64 one does
//! (scaled by [`MARGIN_SCALE`]).
//!
//! It runs only when the query's magnitude lies in `[2⁻⁶⁰, 2¹⁰⁰]` ([`Sat32::new`]): no f32
//! overflow, and underflow stays below the floor of `s`; outside that range queries use the f64
//! test. A NaN margin never separates (comparisons with NaN are false).

// Index loops mirror the formulas (axis i, coordinate x, lane k) and keep the operation order
// the error bound counts.
#![allow(clippy::needless_range_loop)]

use crate::nodes::{MARGIN_SCALE, TNode};
use frcd_geom::{DMat3, DVec3};

/// `unroll3!(i => body)`: `body` for `i` = 0, 1 and 2, written out. The hot loops over axes
/// are unrolled in the source: left as loops of three, LLVM's loop vectoriser turns them, for
/// AVX-512 targets (`-C target-cpu=znver4`, `native` on Zen 4/5 or recent Xeons), into masked
/// gathers and scatters across the loop instead of keeping the four lanes together, and
/// traversals ran 2× slower (measured: 97-105 against 47-49 µs per disjoint knots query).
macro_rules! unroll3 {
    ($i:ident => $body:block) => {{
        {
            let $i: usize = 0;
            $body
        }
        {
            let $i: usize = 1;
            $body
        }
        {
            let $i: usize = 2;
            $body
        }
    }};
}

/// Added to every `|R_ij|` by the f32 test (covers its rounding of `R` and the f64 test's
/// [`crate::sat::EPS_R`]).
pub(crate) const EPS_R32: f32 = 1.0 / (1u32 << 20) as f32;
/// Slack per unit of `ΣH_A + ΣH_B` in the f32 test.
pub(crate) const C_H: f32 = 1.0 / (1u32 << 16) as f32;
/// Slack per unit of `‖d‖₁` in the f32 test.
pub(crate) const C_D: f32 = 1.0 / (1u32 << 18) as f32;

/// Four f32 lanes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(16))]
pub(crate) struct F4(pub [f32; 4]);

impl F4 {
    #[inline(always)]
    fn map2(self, o: F4, f: impl Fn(f32, f32) -> f32) -> F4 {
        F4([
            f(self.0[0], o.0[0]),
            f(self.0[1], o.0[1]),
            f(self.0[2], o.0[2]),
            f(self.0[3], o.0[3]),
        ])
    }
    #[inline(always)]
    pub fn splat(x: f32) -> F4 {
        F4([x; 4])
    }
    #[inline(always)]
    fn add(self, o: F4) -> F4 {
        self.map2(o, |a, b| a + b)
    }
    #[inline(always)]
    fn sub(self, o: F4) -> F4 {
        self.map2(o, |a, b| a - b)
    }
    #[inline(always)]
    fn mul(self, o: F4) -> F4 {
        self.map2(o, |a, b| a * b)
    }
    #[inline(always)]
    fn abs(self) -> F4 {
        F4([
            self.0[0].abs(),
            self.0[1].abs(),
            self.0[2].abs(),
            self.0[3].abs(),
        ])
    }
    /// Lane-wise maximum that ignores a NaN in `o` (keeps `self`).
    #[inline(always)]
    fn max(self, o: F4) -> F4 {
        self.map2(o, |a, b| if b > a { b } else { a })
    }
    /// Bit `k` set where lane `k` is `> 0`.
    #[cfg(test)]
    pub fn positive(self) -> u32 {
        (0..4).fold(0, |m, k| m | ((self.0[k] > 0.0) as u32) << k)
    }
    /// Bit `k` set where lane `k` is `> o`'s lane `k`.
    #[inline(always)]
    fn above(self, o: F4) -> u32 {
        (0..4).fold(0, |m, k| m | ((self.0[k] > o.0[k]) as u32) << k)
    }
}

/// Four f64 lanes (the centres).
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
pub(crate) struct D4(pub [f64; 4]);

impl D4 {
    /// `self − o`, rounded to f32.
    #[inline(always)]
    fn sub32(self, o: D4) -> F4 {
        F4([
            (self.0[0] - o.0[0]) as f32,
            (self.0[1] - o.0[1]) as f32,
            (self.0[2] - o.0[2]) as f32,
            (self.0[3] - o.0[3]) as f32,
        ])
    }
}

/// The (2 to 4) nodes two levels below an internal node, stored in lanes (structure of
/// arrays) so that a traversal step loads them without gathering four scattered nodes: the
/// derived layer of [`crate::ObbTree`], kept for the internal nodes at even depth (the ones a
/// traversal from the roots expands; others are gathered). Unused lanes repeat lane 0.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct Quad {
    /// `u[i][x]`: coordinate `x` of axis `i`.
    pub u: [[F4; 3]; 3],
    pub h: [F4; 3],
    pub c: [F4; 3],
    /// The binary node ids of the lanes.
    pub ids: [u32; 4],
}

const _: () = assert!(std::mem::size_of::<Quad>() == 256);

impl Quad {
    /// Nodes `ids` (1 to 4) in lanes; unused lanes repeat lane 0.
    #[inline(always)]
    pub fn gather(nodes: &[TNode], ids: &[u32; 4], len: usize) -> Quad {
        let mut q = Quad::default();
        for k in 0..4 {
            let id = ids[if k < len { k } else { 0 }];
            let src = &nodes[id as usize];
            for i in 0..3 {
                for x in 0..3 {
                    q.u[i][x].0[k] = src.u[i][x];
                }
                q.h[i].0[k] = src.h[i];
                q.c[i].0[k] = src.c[i];
            }
            q.ids[k] = id;
        }
        q
    }
}

/// No quad for this node (leaves, odd depth).
pub(crate) const NO_QUAD: u32 = u32::MAX;

/// The nodes two levels below internal node `n` (a child that is a leaf stands for itself):
/// 2 to 4 ids, left to right, and their number.
#[inline(always)]
pub(crate) fn quad_ids(nodes: &[TNode], n: u32) -> ([u32; 4], usize) {
    let mut ids = [0u32; 4];
    let mut len = 0;
    for c in [n + 1, nodes[n as usize].right()] {
        let cn = &nodes[c as usize];
        if cn.is_leaf() {
            ids[len] = c;
            len += 1;
        } else {
            ids[len] = c + 1;
            ids[len + 1] = cn.right();
            len += 2;
        }
    }
    (ids, len)
}

/// What the wide traversal's step decides on, per node, in 8 bytes beside the 64-byte
/// [`TNode`]: whether it is a leaf, its split size and its quad. The paired loop pops an entry
/// and decides "leaf pair?" and "split A or B?" on the two metas, so an A split reads neither
/// node (its lanes come from the quad) and a B split only A's: two trees of the dense sweep
/// hold 2.6 MB of nodes, more than a core's L2, and 0.3 MB of metas.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(8))]
pub(crate) struct NodeMeta {
    /// The node's quad index times four plus the lane count minus one, or [`NO_QUAD`].
    pub quad: u32,
    /// [`TNode::size`] for an internal node, −∞ for a leaf, so that [`NodeMeta::split_a`] is
    /// one comparison.
    pub size: f32,
}

impl NodeMeta {
    /// The meta of `node` with quad entry `quad`.
    pub fn of(node: &TNode, quad: u32) -> Self {
        let size = if node.is_leaf() {
            f32::NEG_INFINITY
        } else {
            node.size()
        };
        NodeMeta { quad, size }
    }

    /// A leaf.
    #[inline(always)]
    pub fn is_leaf(self) -> bool {
        self.size == f32::NEG_INFINITY
    }

    /// The traversal's split rule (`split_a` in `query/traverse.rs`) on metas: split A when
    /// `B leaf || (A internal && |A| ≥ |B|)`, which with a leaf's size −∞ is the one
    /// comparison `|A| ≥ |B|`. The same decision as on the nodes wherever sizes are not NaN
    /// (a built tree's half extents are finite; tested for every node pair).
    #[inline(always)]
    pub fn split_a(a: NodeMeta, b: NodeMeta) -> bool {
        a.size >= b.size
    }
}

/// The quad layer of a tree: one [`Quad`] per internal node at even depth, and per node its
/// quad's index times four plus the lane count minus one (or [`NO_QUAD`]) in `of`, and its
/// [`NodeMeta`] (the same quad entry, leaf flag, split size) in `metas`.
///
/// Both per-node arrays, because each kind of descent reads one. Descents from the roots (every
/// plain query, and the cache's fresh traversals) pop long runs of entries and decide them on
/// the metas (1-6 % less time, `docs/performance/cpu-core.md`, fifteenth and sixteenth
/// sittings). A cached query's descents from its front entries are short and scattered: they
/// test the start pair on its two nodes, so deciding on the nodes costs no new cache line
/// there, where the two meta lines cost 7-12 % on a host with a small L2 (fifteenth sitting);
/// they read `of` for the split node, as before the metas.
#[derive(Clone, Debug, Default)]
pub(crate) struct Quads {
    pub quads: Vec<Quad>,
    pub of: Vec<u32>,
    pub metas: Vec<NodeMeta>,
}

impl Quads {
    /// Heap bytes.
    pub fn memory_bytes(&self) -> usize {
        self.quads.capacity() * std::mem::size_of::<Quad>()
            + self.of.capacity() * std::mem::size_of::<u32>()
            + self.metas.capacity() * std::mem::size_of::<NodeMeta>()
    }

    /// The layer of `nodes` without quads: every step gathers its four lanes from the nodes.
    pub fn without_quads(nodes: &[TNode]) -> Quads {
        Quads {
            quads: Vec::new(),
            of: vec![NO_QUAD; nodes.len()],
            metas: nodes.iter().map(|n| NodeMeta::of(n, NO_QUAD)).collect(),
        }
    }
}

/// Builds the quad layer of a tree's nodes.
pub(crate) fn build_quads(nodes: &[TNode]) -> Quads {
    let mut depth = vec![0u32; nodes.len()];
    let mut of = vec![NO_QUAD; nodes.len()];
    let mut quads = Vec::new();
    for (n, node) in nodes.iter().enumerate() {
        if node.is_leaf() {
            continue;
        }
        // Children follow their parent in depth-first order: one forward pass sets depths.
        depth[n + 1] = depth[n] + 1;
        depth[node.right() as usize] = depth[n] + 1;
        if depth[n] & 1 != 0 {
            continue;
        }
        let (ids, len) = quad_ids(nodes, n as u32);
        of[n] = (quads.len() as u32) << 2 | (len as u32 - 1);
        quads.push(Quad::gather(nodes, &ids, len));
    }
    // The pushes may have doubled the capacity: keep only what is used.
    quads.shrink_to_fit();
    let metas = nodes
        .iter()
        .zip(&of)
        .map(|(n, &q)| NodeMeta::of(n, q))
        .collect();
    Quads { quads, of, metas }
}

/// The f32 test of one query (module docs).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sat32 {
    /// `M` rounded to f32: `ms[k][l] = M_kl`.
    ms: [[f32; 3]; 3],
    m: DMat3,
    t: DVec3,
    /// `2 · slack`, rounded up, at least `2⁻¹⁰⁰`.
    s: f32,
}

impl Sat32 {
    /// The f32 test of a query with rotation `m`, translation `t`, f64 slack `slack` and
    /// magnitude `mag` (`|A's mesh| + |B's mesh| + |t|`), or `None` when `mag` lies outside
    /// `[2⁻⁶⁰, 2¹⁰⁰]` or anything is not finite.
    // Always inlined, built in place in the query's context (see `Ctx::new`).
    #[inline(always)]
    pub fn new(m: DMat3, t: DVec3, slack: f64, mag: f64) -> Option<Self> {
        let range = 2f64.powi(-60)..=2f64.powi(100);
        if !range.contains(&mag) || !slack.is_finite() || !m.is_finite() || !t.is_finite() {
            return None;
        }
        let s2 = (2.0 * slack).max(2f64.powi(-100));
        let mut s = s2 as f32;
        if (s as f64) < s2 {
            s = s.next_up();
        }
        let e = |k: usize, l: usize| m.col(l)[k] as f32;
        Some(Sat32 {
            ms: [0, 1, 2].map(|k| [e(k, 0), e(k, 1), e(k, 2)]),
            m,
            t,
            s,
        })
    }

    /// Places one node of B in A's frame.
    #[inline(always)]
    pub fn place(&self, node: &TNode) -> Placed32 {
        let v = &node.u;
        let ms = &self.ms;
        // p[j][k] = (M_k0 v_j0 + M_k1 v_j1) + M_k2 v_j2, as the lanes compute it. (Loops, not
        // `array::map`, which the compiler leaves out of line here.)
        let mut p = [[0.0f32; 3]; 3];
        for j in 0..3 {
            for k in 0..3 {
                p[j][k] = ms[k][0] * v[j][0] + ms[k][1] * v[j][1] + ms[k][2] * v[j][2];
            }
        }
        Placed32 {
            p,
            h: node.h,
            c: self.m * node.center() + self.t,
        }
    }

    /// B's nodes `ids` (1 to 4) placed in A's frame, one per lane (unused lanes repeat lane 0).
    #[inline(always)]
    pub fn place_lanes(&self, nodes: &[TNode], ids: &[u32; 4], n: usize) -> BLanes {
        let mut out = BLanes::default();
        // Gather: v[j][l] lane k = axis j, coordinate l of node k.
        let mut v = [[F4::default(); 3]; 3];
        for k in 0..4 {
            let node = &nodes[ids[if k < n { k } else { 0 }] as usize];
            unroll3!(j => {
                unroll3!(l => {
                    v[j][l].0[k] = node.u[j][l];
                });
                out.h[j].0[k] = node.h[j];
            });
            let c = self.m * node.center() + self.t;
            unroll3!(x => {
                out.c[x].0[k] = c[x];
            });
        }
        let ms = &self.ms;
        unroll3!(j => {
            unroll3!(kk => {
                out.p[j][kk] = F4::splat(ms[kk][0])
                    .mul(v[j][0])
                    .add(F4::splat(ms[kk][1]).mul(v[j][1]))
                    .add(F4::splat(ms[kk][2]).mul(v[j][2]));
            });
        });
        out
    }

    /// The nodes of a quad of B placed in A's frame, one per lane (the same operations as
    /// [`Sat32::place_lanes`]).
    #[inline(always)]
    pub fn place_quad(&self, q: &Quad) -> BLanes {
        let mut out = BLanes::default();
        let ms = &self.ms;
        unroll3!(j => {
            unroll3!(kk => {
                out.p[j][kk] = F4::splat(ms[kk][0])
                    .mul(q.u[j][0])
                    .add(F4::splat(ms[kk][1]).mul(q.u[j][1]))
                    .add(F4::splat(ms[kk][2]).mul(q.u[j][2]));
            });
        });
        out.h = q.h;
        // Centres in f64: M c + t, row by row as glam's `DMat3 * DVec3` (the same f64 value as
        // `place`, whose rounding the query slack covers either way).
        let m = &self.m;
        let mut c = [[0.0f64; 4]; 3];
        for x in 0..3 {
            for k in 0..4 {
                c[x][k] = q.c[x].0[k] as f64;
            }
        }
        unroll3!(r => {
            let (m0, m1, m2) = (m.x_axis[r], m.y_axis[r], m.z_axis[r]);
            let mut v = [0.0f64; 4];
            for k in 0..4 {
                v[k] = m0 * c[0][k] + m1 * c[1][k] + m2 * c[2][k] + self.t[r];
            }
            out.c[r] = D4(v);
        });
        out
    }

    /// The base slack `s` (`2 · slack` rounded up).
    #[inline(always)]
    pub fn s(&self) -> f32 {
        self.s
    }
}

/// A box of B placed in A's frame for the f32 test.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Placed32 {
    /// `p[j]` = B's axis `j` in A's frame.
    pub p: [[f32; 3]; 3],
    /// Half extents.
    pub h: [f32; 3],
    /// Centre in A's frame, in f64.
    pub c: DVec3,
}

impl Placed32 {
    /// This box in every lane.
    #[inline(always)]
    pub fn splat(&self) -> BLanes {
        let mut out = BLanes::default();
        for j in 0..3 {
            for k in 0..3 {
                out.p[j][k] = F4::splat(self.p[j][k]);
            }
            out.h[j] = F4::splat(self.h[j]);
        }
        out.c = [D4([self.c.x; 4]), D4([self.c.y; 4]), D4([self.c.z; 4])];
        out
    }
}

/// Up to four boxes of B placed in A's frame, one per lane.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct BLanes {
    /// `p[j][k]`: coordinate `k` of B's axis `j` in A's frame.
    pub p: [[F4; 3]; 3],
    pub h: [F4; 3],
    pub c: [D4; 3],
}

impl BLanes {
    /// Lane `k` in every lane (the same values as `self.lane(k).splat()`).
    #[inline(always)]
    pub fn broadcast(&self, k: usize) -> BLanes {
        let mut out = BLanes::default();
        unroll3!(j => {
            unroll3!(x => {
                out.p[j][x] = F4::splat(self.p[j][x].0[k]);
            });
            out.h[j] = F4::splat(self.h[j].0[k]);
            out.c[j] = D4([self.c[j].0[k]; 4]);
        });
        out
    }

    /// Lane `k` as one placed box.
    #[cfg(test)]
    pub fn lane(&self, k: usize) -> Placed32 {
        let mut p = [[0.0f32; 3]; 3];
        for j in 0..3 {
            for x in 0..3 {
                p[j][x] = self.p[j][x].0[k];
            }
        }
        Placed32 {
            p,
            h: [self.h[0].0[k], self.h[1].0[k], self.h[2].0[k]],
            c: DVec3::new(self.c[0].0[k], self.c[1].0[k], self.c[2].0[k]),
        }
    }
}

/// Up to four boxes of A, one per lane.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ALanes {
    /// `u[i][x]`: coordinate `x` of A's axis `i`.
    pub u: [[F4; 3]; 3],
    pub h: [F4; 3],
    pub c: [D4; 3],
}

impl ALanes {
    /// A's nodes `ids` (1 to 4), one per lane (unused lanes repeat lane 0).
    #[inline(always)]
    pub fn gather(nodes: &[TNode], ids: &[u32; 4], n: usize) -> ALanes {
        let mut out = ALanes::default();
        for k in 0..4 {
            let node = &nodes[ids[if k < n { k } else { 0 }] as usize];
            unroll3!(i => {
                unroll3!(x => {
                    out.u[i][x].0[k] = node.u[i][x];
                });
                out.h[i].0[k] = node.h[i];
                out.c[i].0[k] = node.c[i] as f64;
            });
        }
        out
    }

    /// The nodes of a quad, one per lane.
    #[inline(always)]
    pub fn from_quad(q: &Quad) -> ALanes {
        let mut out = ALanes {
            u: q.u,
            h: q.h,
            ..ALanes::default()
        };
        for x in 0..3 {
            let c = &q.c[x].0;
            out.c[x] = D4([c[0] as f64, c[1] as f64, c[2] as f64, c[3] as f64]);
        }
        out
    }

    /// One node in every lane.
    #[inline(always)]
    pub fn splat(node: &TNode) -> ALanes {
        let mut out = ALanes::default();
        for i in 0..3 {
            for x in 0..3 {
                out.u[i][x] = F4::splat(node.u[i][x]);
            }
            out.h[i] = F4::splat(node.h[i]);
            out.c[i] = D4([node.c[i] as f64; 4]);
        }
        out
    }
}

/// The f32 15-axis test on four box pairs: lane `k` holds the largest margin (a lower bound on
/// the boxes' gap along a direction of length at most one, before [`MARGIN_SCALE`]) over the
/// axes tested, positive exactly when some axis separates the pair by more than the error
/// bound (module docs). The B faces and the nine edge-pair axes are skipped once the axes
/// before them separate every lane of `active` (a bit mask).
///
/// Two sums are taken out of the fifteen radii (fewer instructions per lane, the same bound):
/// the slack `S` is subtracted once from the largest `|projection| − radius` (the sign of a
/// rounded difference is the sign of the exact one, so `max − S > 0` exactly when some axis's
/// rounded `|projection| − radius` exceeds `S`), and [`EPS_R32`] is not added to each `|R_ij|`
/// but counted in `S` as `EPS_R32 · (ΣH_A + ΣH_B)`, which bounds its share in every radius
/// (`EPS_R32 · ΣH_B` on A's faces, `· ΣH_A` on B's, `· (h_A,i1 + h_A,i2 + h_B,j1 + h_B,j2)` on
/// an edge pair).
#[inline(always)]
pub(crate) fn separation4(a: &ALanes, b: &BLanes, s: f32, active: u32) -> F4 {
    let d = [
        b.c[0].sub32(a.c[0]),
        b.c[1].sub32(a.c[1]),
        b.c[2].sub32(a.c[2]),
    ];
    let sa = a.h[0].add(a.h[1]).add(a.h[2]);
    let sb = b.h[0].add(b.h[1]).add(b.h[2]);
    let sd = d[0].abs().add(d[1].abs()).add(d[2].abs());
    let sv = F4::splat(s)
        .add(F4::splat(C_H + EPS_R32).mul(sa.add(sb)))
        .add(F4::splat(C_D).mul(sd));
    let (u, p) = (&a.u, &b.p);
    // t_i = u_i · d; R_ij = u_i · P_j. (Loops, not `array::map`, which the compiler leaves
    // out of line here.)
    let mut t = [F4::default(); 3];
    let mut r = [[F4::default(); 3]; 3];
    let mut ar = [[F4::default(); 3]; 3];
    unroll3!(i => {
        t[i] = u[i][0]
            .mul(d[0])
            .add(u[i][1].mul(d[1]))
            .add(u[i][2].mul(d[2]));
        unroll3!(j => {
            r[i][j] = u[i][0]
                .mul(p[j][0])
                .add(u[i][1].mul(p[j][1]))
                .add(u[i][2].mul(p[j][2]));
            ar[i][j] = r[i][j].abs();
        });
    });
    let (ha, hb) = (&a.h, &b.h);
    let mut best = F4::splat(f32::NEG_INFINITY);
    // A's faces.
    for i in 0..3 {
        let rad = ha[i]
            .add(hb[0].mul(ar[i][0]))
            .add(hb[1].mul(ar[i][1]))
            .add(hb[2].mul(ar[i][2]));
        best = best.max(t[i].abs().sub(rad));
    }
    if best.above(sv) & active == active {
        return best.sub(sv);
    }
    // B's faces: P_j · d.
    for j in 0..3 {
        let proj = p[j][0]
            .mul(d[0])
            .add(p[j][1].mul(d[1]))
            .add(p[j][2].mul(d[2]));
        let rad = hb[j]
            .add(ha[0].mul(ar[0][j]))
            .add(ha[1].mul(ar[1][j]))
            .add(ha[2].mul(ar[2][j]));
        best = best.max(proj.abs().sub(rad));
    }
    if best.above(sv) & active == active {
        return best.sub(sv);
    }
    // Edge pairs u_i × P_j; (i1, i2) = (i + 1, i + 2) mod 3, likewise (j1, j2).
    for i in 0..3 {
        let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
        for j in 0..3 {
            let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
            let proj = t[i2].mul(r[i1][j]).sub(t[i1].mul(r[i2][j]));
            let rad = ha[i1]
                .mul(ar[i2][j])
                .add(ha[i2].mul(ar[i1][j]))
                .add(hb[j1].mul(ar[i][j2]))
                .add(hb[j2].mul(ar[i][j1]));
            best = best.max(proj.abs().sub(rad));
        }
    }
    best.sub(sv)
}

/// Two four-lane steps in one eight-lane test, in AVX2 registers (the traversal's AVX2 build,
/// `query/traverse.rs`). Each step's lanes are built as one [`avx::Half`] straight from where
/// they lie (a quad of A, a broadcast lane of a placed B block, a node of A broadcast, a placed quad of B),
/// and the test runs the operations of [`separation4`] in the same order on eight lanes, so each
/// lane is separated exactly when [`separation4`] separates it.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
pub(crate) mod avx {
    use super::{BLanes, C_D, C_H, EPS_R32, F4, Quad};
    use crate::nodes::TNode;
    use std::arch::x86_64::*;

    /// The lanes of one step: A's axes and half extents, B's placed axes and half extents, and
    /// the centre offsets (B's minus A's, formed in f64 and rounded once, as [`super::D4`]'s
    /// `sub32`).
    #[derive(Clone, Copy)]
    pub(crate) struct Half {
        u: [[__m128; 3]; 3],
        ha: [__m128; 3],
        p: [[__m128; 3]; 3],
        hb: [__m128; 3],
        d: [__m128; 3],
    }

    impl Half {
        /// Every value zero, to be filled lane value by lane value.
        #[inline(always)]
        fn zero() -> Half {
            // SAFETY: SSE, part of every x86-64 target.
            let z = unsafe { _mm_setzero_ps() };
            Half {
                u: [[z; 3]; 3],
                ha: [z; 3],
                p: [[z; 3]; 3],
                hb: [z; 3],
                d: [z; 3],
            }
        }
    }

    #[inline(always)]
    fn m128(x: F4) -> __m128 {
        // SAFETY: `F4` is four f32 in a `repr(C)` array, the layout of `__m128`.
        unsafe { std::mem::transmute::<F4, __m128>(x) }
    }

    /// A split: A's lanes from quad `q` (or the same layout gathered), against lane `k` of B's
    /// placed block in every lane.
    ///
    /// # Safety
    ///
    /// The CPU must have AVX2 (as for every function here; inlined into the traversal's AVX2
    /// build, their intrinsics are single instructions: a `#[target_feature]` function would
    /// not be inlined there).
    #[inline(always)]
    pub(crate) unsafe fn a_split(q: &Quad, b: &BLanes, k: usize) -> Half {
        // SAFETY: the caller guarantees AVX2; `k < 4` indexes the lanes.
        unsafe {
            let bc = |x: &F4| _mm_broadcast_ss(&x.0[k]);
            let mut h = Half::zero();
            unroll3!(i => {
                unroll3!(x => {
                    h.u[i][x] = m128(q.u[i][x]);
                    h.p[i][x] = bc(&b.p[i][x]);
                });
                h.ha[i] = m128(q.h[i]);
                h.hb[i] = bc(&b.h[i]);
                let cb = _mm256_broadcast_sd(&b.c[i].0[k]);
                h.d[i] = _mm256_cvtpd_ps(_mm256_sub_pd(cb, _mm256_cvtps_pd(m128(q.c[i]))));
            });
            h
        }
    }

    /// A B split: node `na` of A in every lane, against B's children placed in `b`.
    ///
    /// # Safety
    ///
    /// The CPU must have AVX2.
    #[inline(always)]
    pub(crate) unsafe fn b_split(na: &TNode, b: &BLanes) -> Half {
        // SAFETY: the caller guarantees AVX2.
        unsafe {
            let mut h = Half::zero();
            unroll3!(i => {
                unroll3!(x => {
                    h.u[i][x] = _mm_broadcast_ss(&na.u[i][x]);
                    h.p[i][x] = m128(b.p[i][x]);
                });
                h.ha[i] = _mm_broadcast_ss(&na.h[i]);
                h.hb[i] = m128(b.h[i]);
                let cb = std::mem::transmute::<super::D4, __m256d>(b.c[i]);
                let ca = _mm256_set1_pd(na.c[i] as f64);
                h.d[i] = _mm256_cvtpd_ps(_mm256_sub_pd(cb, ca));
            });
            h
        }
    }

    /// The eight-lane test: `h1` in lanes 0-3, `h2` in lanes 4-7, `active` a mask over the
    /// eight; the margins of each half. The test runs on until both halves are done, so each
    /// lane is separated exactly when [`super::separation4`] separates it; with `MARGINS` (a
    /// front is being recorded) each half's margins are also bit for bit `separation4`'s,
    /// taken where it would have stopped (after A's faces, after B's faces, or at the end),
    /// else a half that stopped early may get larger margins (more axes), which is as sound.
    ///
    /// # Safety
    ///
    /// The CPU must have AVX2.
    #[inline(always)]
    pub(crate) unsafe fn separation8<const MARGINS: bool>(
        h1: &Half,
        h2: &Half,
        s: f32,
        active: u32,
    ) -> (F4, F4) {
        // SAFETY: the caller guarantees AVX2.
        unsafe {
            let j = |lo: __m128, hi: __m128| _mm256_set_m128(hi, lo);
            let add = |x, y| _mm256_add_ps(x, y);
            let sub = |x, y| _mm256_sub_ps(x, y);
            let mul = |x, y| _mm256_mul_ps(x, y);
            let sign = _mm256_set1_ps(-0.0);
            let abs = |x| _mm256_andnot_ps(sign, x);
            // `vmaxps new, best` keeps `best` where `new` is NaN, as `F4::max` does.
            let max = |best, new| _mm256_max_ps(new, best);
            let above = |x, y| _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(x, y)) as u32;
            let zero = _mm256_setzero_ps();
            let (mut d, mut ha, mut hb) = ([zero; 3], [zero; 3], [zero; 3]);
            unroll3!(i => {
                d[i] = j(h1.d[i], h2.d[i]);
                ha[i] = j(h1.ha[i], h2.ha[i]);
                hb[i] = j(h1.hb[i], h2.hb[i]);
            });
            let sa = add(add(ha[0], ha[1]), ha[2]);
            let sb = add(add(hb[0], hb[1]), hb[2]);
            let sd = add(add(abs(d[0]), abs(d[1])), abs(d[2]));
            let sv = add(
                add(
                    _mm256_set1_ps(s),
                    mul(_mm256_set1_ps(C_H + EPS_R32), add(sa, sb)),
                ),
                mul(_mm256_set1_ps(C_D), sd),
            );
            let mut p = [[zero; 3]; 3];
            unroll3!(k => {
                unroll3!(x => {
                    p[k][x] = j(h1.p[k][x], h2.p[k][x]);
                });
            });
            let (mut t, mut r, mut ar) = ([zero; 3], [[zero; 3]; 3], [[zero; 3]; 3]);
            unroll3!(i => {
                let u0 = j(h1.u[i][0], h2.u[i][0]);
                let u1 = j(h1.u[i][1], h2.u[i][1]);
                let u2 = j(h1.u[i][2], h2.u[i][2]);
                t[i] = add(add(mul(u0, d[0]), mul(u1, d[1])), mul(u2, d[2]));
                unroll3!(k => {
                    r[i][k] = add(add(mul(u0, p[k][0]), mul(u1, p[k][1])), mul(u2, p[k][2]));
                    ar[i][k] = abs(r[i][k]);
                });
            });
            let halves = |m: __m256| {
                let f4 = |x: __m128| std::mem::transmute::<__m128, F4>(x);
                (
                    f4(_mm256_castps256_ps128(m)),
                    f4(_mm256_extractf128_ps::<1>(m)),
                )
            };
            let mut best = _mm256_set1_ps(f32::NEG_INFINITY);
            unroll3!(i => {
                let rad = add(
                    add(add(ha[i], mul(hb[0], ar[i][0])), mul(hb[1], ar[i][1])),
                    mul(hb[2], ar[i][2]),
                );
                best = max(best, sub(abs(t[i]), rad));
            });
            // Each half's exits, as `separation4` takes them on its own four lanes (only
            // needed for the margins: the test stops once both halves are done).
            let (lo, hi) = (active & 0x0f, active & 0xf0);
            let sep = above(best, sv);
            if sep & active == active {
                return halves(sub(best, sv));
            }
            let (lo_a, hi_a) = (sep & lo == lo, sep & hi == hi);
            let after_a = sub(best, sv);
            unroll3!(k => {
                let proj = add(add(mul(p[k][0], d[0]), mul(p[k][1], d[1])), mul(p[k][2], d[2]));
                let rad = add(
                    add(add(hb[k], mul(ha[0], ar[0][k])), mul(ha[1], ar[1][k])),
                    mul(ha[2], ar[2][k]),
                );
                best = max(best, sub(abs(proj), rad));
            });
            let sep = above(best, sv);
            if !MARGINS && sep & active == active {
                return halves(sub(best, sv));
            }
            let (lo_b, hi_b) = (lo_a || sep & lo == lo, hi_a || sep & hi == hi);
            let after_b = sub(best, sv);
            // Where a half stopped early, its margins from then (this half's lanes only).
            let stopped = |m: __m256| {
                let (a_lo, a_hi) = halves(after_a);
                let (b_lo, b_hi) = halves(after_b);
                let (m_lo, m_hi) = halves(m);
                let pick = |a: bool, b: bool, xa, xb, xm| {
                    if a {
                        xa
                    } else if b {
                        xb
                    } else {
                        xm
                    }
                };
                (
                    pick(lo_a, lo_b, a_lo, b_lo, m_lo),
                    pick(hi_a, hi_b, a_hi, b_hi, m_hi),
                )
            };
            if MARGINS && lo_b && hi_b {
                return stopped(after_b);
            }
            unroll3!(i => {
                let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
                unroll3!(k => {
                    let (k1, k2) = ((k + 1) % 3, (k + 2) % 3);
                    let proj = sub(mul(t[i2], r[i1][k]), mul(t[i1], r[i2][k]));
                    let rad = add(
                        add(
                            add(mul(ha[i1], ar[i2][k]), mul(ha[i2], ar[i1][k])),
                            mul(hb[k1], ar[i][k2]),
                        ),
                        mul(hb[k2], ar[i][k1]),
                    );
                    best = max(best, sub(abs(proj), rad));
                });
            });
            if MARGINS {
                stopped(sub(best, sv))
            } else {
                halves(sub(best, sv))
            }
        }
    }
}

/// A lane's margin as the f64 bound the coherence cache stores (`nodes.rs`).
#[inline(always)]
pub(crate) fn margin64(m: f32) -> f64 {
    m as f64 * MARGIN_SCALE
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sat::tests::{node, unit_box};
    use crate::sat::{Placed, SLACK_REL, separation};
    use frcd_geom::{DQuat, Obb};

    /// All 15 margins of the f64 test (no early exit), before [`MARGIN_SCALE`].
    fn margins64(a: &TNode, b: &Placed, slack: f64) -> [f64; 15] {
        use crate::nodes::SIGMA;
        use crate::sat::EPS_R;
        let ax = a.axes();
        let ax = [ax.x_axis, ax.y_axis, ax.z_axis];
        let bx = [b.axes.x_axis, b.axes.y_axis, b.axes.z_axis];
        let d = b.center - a.center();
        let ah = a.half().to_array();
        let slack = slack + b.sigma + SIGMA * (ah[0] + ah[1] + ah[2]);
        let bh = b.half.to_array();
        let mut r = [[0.0; 3]; 3];
        let mut ar = [[0.0; 3]; 3];
        let mut t = [0.0; 3];
        let mut out = [0.0; 15];
        for i in 0..3 {
            t[i] = ax[i].x * d.x + ax[i].y * d.y + ax[i].z * d.z;
            for j in 0..3 {
                r[i][j] = ax[i].x * bx[j].x + ax[i].y * bx[j].y + ax[i].z * bx[j].z;
                ar[i][j] = r[i][j].abs() + EPS_R;
            }
            out[i] = t[i].abs()
                - (ah[i] + bh[0] * ar[i][0] + bh[1] * ar[i][1] + bh[2] * ar[i][2] + slack);
        }
        for j in 0..3 {
            out[3 + j] = (t[0] * r[0][j] + t[1] * r[1][j] + t[2] * r[2][j]).abs()
                - (ah[0] * ar[0][j] + ah[1] * ar[1][j] + ah[2] * ar[2][j] + bh[j] + slack);
        }
        for i in 0..3 {
            let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
            for j in 0..3 {
                let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
                out[6 + 3 * i + j] = (t[i2] * r[i1][j] - t[i1] * r[i2][j]).abs()
                    - (ah[i1] * ar[i2][j]
                        + ah[i2] * ar[i1][j]
                        + bh[j1] * ar[i][j2]
                        + bh[j2] * ar[i][j1]
                        + slack);
            }
        }
        out
    }

    /// The test generator: the dev-dependency's seeded `StdRng` and the draws these tests use.
    struct Rng(rand::rngs::StdRng);
    impl Rng {
        fn new(seed: u64) -> Self {
            use rand::SeedableRng;
            Rng(rand::rngs::StdRng::seed_from_u64(seed))
        }
        fn next(&mut self) -> u64 {
            rand::RngCore::next_u64(&mut self.0)
        }
        fn f(&mut self) -> f64 {
            (self.next() >> 11) as f64 / (1u64 << 53) as f64
        }
        fn sym(&mut self) -> f64 {
            2.0 * self.f() - 1.0
        }
        fn v(&mut self) -> DVec3 {
            DVec3::new(self.sym(), self.sym(), self.sym())
        }
        fn rot(&mut self) -> DQuat {
            let q = DQuat::from_xyzw(self.sym(), self.sym(), self.sym(), self.sym());
            if q.length() < 1e-3 {
                DQuat::IDENTITY
            } else {
                q.normalize()
            }
        }
    }

    /// One box pair and pose: A's node, B's node (local), the frame.
    #[derive(Clone, Copy)]
    struct Case {
        a: TNode,
        b: TNode,
        m: DMat3,
        t: DVec3,
    }

    impl Case {
        fn mag(&self) -> f64 {
            let r = |n: &TNode| n.center().length() + n.half().length();
            r(&self.a) + r(&self.b) + self.t.length()
        }
        fn slack(&self) -> f64 {
            SLACK_REL * self.mag() + frcd_geom::ABSOLUTE_SLACK
        }
    }

    /// Runs four cases through the lanes in both arrangements (A in lanes against a splatted
    /// B, B placed in lanes against a splatted A) where the cases share a frame, and each case
    /// alone in lane 0; checks each lane against the f64 test: the f32 test never separates
    /// what f64 keeps, and its margin never exceeds the f64 margin of the best f32 axis.
    /// Returns (f64 separates, f32 separates) per case.
    fn check4(cases: &[Case; 4], what: &str) -> [(bool, bool); 4] {
        let mut out = [(false, false); 4];
        for (k, c) in cases.iter().enumerate() {
            let slack = c.slack();
            let p64 = Placed::new(&c.b, &c.m, c.t);
            let s64 = separation(&c.a, &p64, slack);
            let all64 = margins64(&c.a, &p64, slack);
            let max64 = all64.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let Some(sat) = Sat32::new(c.m, c.t, slack, c.mag()) else {
                out[k] = (s64.is_some(), false);
                continue;
            };
            // Lane 0 alone, and the case in every lane position with the others as fillers.
            let mut seen = Vec::new();
            let nodes_a: Vec<TNode> = cases.iter().map(|x| x.a).collect();
            let nodes_b: Vec<TNode> = cases.iter().map(|x| x.b).collect();
            let ids = [
                k as u32,
                ((k + 1) % 4) as u32,
                ((k + 2) % 4) as u32,
                ((k + 3) % 4) as u32,
            ];
            // A in lanes (lane 0 is this case) against this case's B.
            let al = ALanes::gather(&nodes_a, &ids, 4);
            let m1 = separation4(&al, &sat.place(&c.b).splat(), sat.s(), 1);
            seen.push(m1.0[0]);
            // B placed in lanes against this case's A (same frame for every lane).
            let bl = sat.place_lanes(&nodes_b, &ids, 4);
            let m2 = separation4(&ALanes::splat(&c.a), &bl, sat.s(), 0xF);
            seen.push(m2.0[0]);
            // A single lane (fillers repeat it).
            let al1 = ALanes::gather(&nodes_a, &ids, 1);
            let m3 = separation4(&al1, &sat.place_lanes(&nodes_b, &ids, 1), sat.s(), 0xF);
            seen.push(m3.0[0]);
            for &m in &seen {
                if m > 0.0 {
                    assert!(
                        s64.is_some(),
                        "{what}: f32 separates (margin {m:e}), f64 keeps: {:?} {:?} m {:?} t {:?}",
                        c.a,
                        c.b,
                        c.m,
                        c.t
                    );
                    assert!(
                        m as f64 <= max64 * (1.0 + 1e-9) + 1e-300,
                        "{what}: {m:e} > {max64:e}"
                    );
                }
            }
            // The arrangements agree (each lane computes the same operations), at least on
            // the sign.
            assert!(
                seen.iter().all(|&m| (m > 0.0) == (seen[0] > 0.0)),
                "{what}: {seen:?}"
            );
            // The eight-lane test (AVX2 build), an A split in one half and a B split in the
            // other: recording a front, each half's margins are the four-lane test's bits; in
            // plain queries (it runs on until both halves are done) the same verdicts.
            #[cfg(target_arch = "x86_64")]
            if crate::isa::has_avx2() {
                let splat_b = sat.place(&c.b).splat();
                let quad = Quad::gather(&nodes_a, &ids, 4);
                let four = [
                    separation4(&al, &splat_b, sat.s(), 1).0[0],
                    separation4(&ALanes::splat(&c.a), &bl, sat.s(), 1).0[0],
                ];
                // SAFETY: the CPU has AVX2 (`isa::has_avx2`).
                #[allow(unsafe_code)]
                let (recorded, plain) = unsafe { eight_lane(&quad, &splat_b, &c.a, &bl, sat.s()) };
                assert_eq!(recorded.map(f32::to_bits), four.map(f32::to_bits), "{what}");
                assert_eq!(plain.map(|m| m > 0.0), four.map(|m| m > 0.0), "{what}");
            }
            out[k] = (s64.is_some(), seen[0] > 0.0);
        }
        out
    }

    /// Lane 0 of quad `q` against lane 0 of `b` (an A split) in the low half, node `a`
    /// against lane 0 of `bl` (a B split) in the high half, through the eight-lane test:
    /// lane 0 of each half, recording margins, then as plain queries run it.
    ///
    /// # Safety
    ///
    /// The CPU must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[allow(unsafe_code)]
    #[target_feature(enable = "avx2")]
    unsafe fn eight_lane(
        q: &Quad,
        b: &BLanes,
        a: &TNode,
        bl: &BLanes,
        s: f32,
    ) -> ([f32; 2], [f32; 2]) {
        // SAFETY: the caller guarantees AVX2.
        unsafe {
            let (h1, h2) = (avx::a_split(q, b, 0), avx::b_split(a, bl));
            let (r1, r2) = avx::separation8::<true>(&h1, &h2, s, 0x11);
            let (p1, p2) = avx::separation8::<false>(&h1, &h2, s, 0x11);
            ([r1.0[0], r2.0[0]], [p1.0[0], p2.0[0]])
        }
    }

    fn random_node(rng: &mut Rng, centre: DVec3, size: f64) -> TNode {
        let h = DVec3::new(rng.f(), rng.f(), rng.f()) * size;
        // Some flat and some needle boxes.
        let h = match rng.next() % 8 {
            0 => DVec3::new(h.x, h.y, 0.0),
            1 => DVec3::new(h.x, 0.0, 0.0),
            _ => h,
        };
        node(&Obb {
            center: centre,
            axes: DMat3::from_quat(rng.rot()),
            half_extents: h,
        })
    }

    /// B placed so that its support along one of A's axes (or a cross axis) is `gap` away from
    /// A's, measured exactly in f64 on the f32 boxes.
    fn touching(rng: &mut Rng, offset: f64, size: f64, gap: f64) -> Case {
        let ca = rng.v() * size + DVec3::splat(offset);
        let a = random_node(rng, ca, size);
        let cb = rng.v() * size - DVec3::splat(offset);
        let b = random_node(rng, cb, size);
        let m = if rng.next().is_multiple_of(3) {
            // Nearly parallel to A's axes.
            let eps = 1e-7 * rng.sym();
            a.axes() * DMat3::from_quat(DQuat::from_rotation_z(eps)) * b.axes().transpose()
        } else {
            DMat3::from_quat(rng.rot())
        };
        let pa = a.axes();
        let pb = m * b.axes();
        let k = (rng.next() % 15) as usize;
        let n = if k < 3 {
            pa.col(k)
        } else if k < 6 {
            pb.col(k - 3)
        } else {
            let c = pa.col((k - 6) / 3).cross(pb.col((k - 6) % 3));
            if c.length() < 1e-3 {
                pa.col(0)
            } else {
                c.normalize()
            }
        };
        let support = |ax: &DMat3, h: DVec3| {
            h.x * n.dot(ax.col(0)).abs()
                + h.y * n.dot(ax.col(1)).abs()
                + h.z * n.dot(ax.col(2)).abs()
        };
        let dist = support(&pa, a.half()) + support(&pb, b.half()) + gap;
        let want = a.center() + n * dist;
        let t = want - m * b.center();
        Case { a, b, m, t }
    }

    /// Four cases sharing the frame of the first (the lanes of one query share it).
    fn share_frame(mut c: [Case; 4]) -> [Case; 4] {
        for k in 1..4 {
            c[k].m = c[0].m;
            c[k].t = c[0].t;
        }
        c
    }

    #[test]
    fn lanes_never_separate_what_f64_keeps_random() {
        let mut rng = Rng::new(7);
        let (mut total64, mut only64, mut both) = (0u32, 0u32, 0u32);
        for k in 0..40_000 {
            let size = [1.0, 1e-3, 50.0][k % 3];
            let offset = [0.0, 10.0, 1e4][(k / 3) % 3];
            let m = DMat3::from_quat(rng.rot());
            let t = DVec3::splat(offset) + rng.v() * 3.0 * size;
            let cases = [0; 4].map(|_| {
                let ca = rng.v() * size + DVec3::splat(offset);
                let a = random_node(&mut rng, ca, size);
                let cb = rng.v() * size;
                let b = random_node(&mut rng, cb, size);
                Case { a, b, m, t }
            });
            for (s64, s32) in check4(&cases, "random") {
                total64 += s64 as u32;
                both += (s64 && s32) as u32;
                only64 += (s64 && !s32) as u32;
            }
        }
        // Sound (checked above) and nearly as sharp as the f64 test.
        assert!(total64 > 40_000, "{total64}");
        assert!(
            only64 * 200 < total64,
            "f32 keeps {only64} of {total64} ({both})"
        );
    }

    #[test]
    fn lanes_never_separate_what_f64_keeps_near_degenerate() {
        let mut rng = Rng::new(11);
        let (mut sep, mut near) = ([0u32; 2], [0u32; 2]);
        for k in 0..20_000 {
            let size: f64 = [1.0, 1e-6, 1e3, 1e-15, 1e12][k % 5];
            let offset = [0.0, 1.0, 1e6, -3e3][(k / 5) % 4] * size.max(1.0);
            let rel = [
                0.0, 1e-15, -1e-15, 1e-12, -1e-12, 1e-9, 1e-6, -1e-6, 1e-4, 1e-2,
            ][(k / 20) % 10];
            let c = [0; 4].map(|_| touching(&mut rng, offset, size, rel * size));
            // Each case with its own frame in lane 0 (the other lanes are fillers).
            for x in 0..4 {
                let r = check4(
                    &[c[x], c[(x + 1) % 4], c[(x + 2) % 4], c[(x + 3) % 4]],
                    "near-degenerate",
                );
                sep[0] += r[0].0 as u32;
                sep[1] += r[0].1 as u32;
            }
            check4(&share_frame(c), "near-degenerate, shared frame");
            // Gaps just around the f32 test's own threshold (its slack plus the f32 terms).
            let c2 = touching(&mut Rng::new(k as u64), offset, size, 0.0);
            let sh = c2.a.half().element_sum() + c2.b.half().element_sum();
            let d1 = (c2.m * c2.b.center() + c2.t - c2.a.center())
                .abs()
                .element_sum();
            let thr = 2.0 * c2.slack() + (C_H + EPS_R32) as f64 * sh + C_D as f64 * d1;
            let cases = [-0.3, -0.01, 0.0, 0.01].map(|rel| {
                touching(
                    &mut Rng::new(k as u64),
                    offset,
                    size,
                    thr * (1.0 + rel + 0.3 * (k % 4) as f64),
                )
            });
            for (s64, s32) in check4(&cases, "at the f32 threshold") {
                near[0] += s64 as u32;
                near[1] += s32 as u32;
            }
        }
        assert!(sep[1] > 0 && sep[0] >= sep[1], "{sep:?}");
        assert!(near[1] > 0 && near[0] > near[1], "{near:?}");
    }

    #[test]
    fn f32_test_refuses_magnitudes_f32_cannot_hold() {
        let m = DMat3::IDENTITY;
        assert!(Sat32::new(m, DVec3::ZERO, 1e-13, 1.0).is_some());
        assert!(Sat32::new(m, DVec3::ZERO, 1e-13, 1e31).is_none());
        assert!(Sat32::new(m, DVec3::ZERO, 1e-40, 1e-25).is_none());
        assert!(Sat32::new(m, DVec3::splat(f64::NAN), 1e-13, 1.0).is_none());
        assert!(Sat32::new(m, DVec3::ZERO, f64::INFINITY, 1.0).is_none());
        // Huge boxes at the top of the range: the test keeps what it cannot decide, never
        // separates on overflow.
        let big = Case {
            a: unit_box(DVec3::ZERO),
            b: node(&Obb {
                center: DVec3::ZERO,
                axes: DMat3::IDENTITY,
                half_extents: DVec3::splat(1e29),
            }),
            m,
            t: DVec3::new(1e29, 0.0, 0.0),
        };
        assert_eq!(check4(&[big; 4], "huge")[0], (false, false));
    }

    /// The quad layer holds exactly the nodes two levels below every internal node at even
    /// depth, and its lanes give the gathered lanes' answers bit for bit.
    #[test]
    fn quads_equal_the_gathered_nodes() {
        let mesh = frcd_geom::shapes::icosphere(1.0, 3);
        for leaf in [1, 2, 3] {
            let opts = crate::BuildOptions {
                max_leaf_triangles: leaf,
                ..Default::default()
            };
            let tree = crate::ObbTree::build(&mesh, &opts);
            let nodes = &tree.nodes;
            let sat = Sat32::new(
                DMat3::from_quat(DQuat::from_rotation_x(0.4)),
                DVec3::new(0.3, -0.2, 0.1),
                1e-13,
                3.0,
            )
            .unwrap();
            let (mut with, mut depth) = (0, vec![0u32; nodes.len()]);
            for n in 0..nodes.len() {
                let q = tree.quads().of[n];
                assert_eq!(tree.quads().metas[n], NodeMeta::of(&nodes[n], q));
                if nodes[n].is_leaf() {
                    assert_eq!(q, NO_QUAD);
                    continue;
                }
                depth[n + 1] = depth[n] + 1;
                depth[nodes[n].right() as usize] = depth[n] + 1;
                assert_eq!(q == NO_QUAD, depth[n] % 2 == 1, "node {n}");
                if q == NO_QUAD {
                    continue;
                }
                with += 1;
                let quad = &tree.quads().quads[(q >> 2) as usize];
                let (ids, len) = quad_ids(nodes, n as u32);
                assert_eq!((q & 3) as usize + 1, len);
                assert_eq!(quad.ids[..len], ids[..len]);
                let g = ALanes::gather(nodes, &ids, len);
                let f = ALanes::from_quad(quad);
                let b = sat.place(&nodes[0]).splat();
                let mask = (1 << len) - 1;
                let (x, y) = (
                    separation4(&g, &b, sat.s(), mask),
                    separation4(&f, &b, sat.s(), mask),
                );
                assert_eq!(x.0[..len], y.0[..len]);
                let a = ALanes::splat(&nodes[n]);
                let (pl, pq) = (sat.place_lanes(nodes, &ids, len), sat.place_quad(quad));
                let (x, y) = (
                    separation4(&a, &pl, sat.s(), mask),
                    separation4(&a, &pq, sat.s(), mask),
                );
                assert_eq!(x.0[..len], y.0[..len]);
                for k in 0..len {
                    assert_eq!(pl.lane(k).c, pq.lane(k).c);
                    // A lane broadcast from a block is that lane in every lane.
                    let (one, all) = (pq.lane(k), pq.broadcast(k));
                    for m in 0..4 {
                        let got = all.lane(m);
                        assert_eq!((got.p, got.h, got.c), (one.p, one.h, one.c));
                    }
                }
            }
            assert!(with > 10, "{with}");
        }
    }

    #[test]
    fn hand_made_cases() {
        let sat = |t: DVec3| Sat32::new(DMat3::IDENTITY, t, 4.0 * SLACK_REL, 4.0).unwrap();
        let a = unit_box(DVec3::ZERO);
        let b = unit_box(DVec3::new(2.0, 0.0, 0.0));
        let one = |s: &Sat32, a: &TNode, b: &TNode| {
            separation4(&ALanes::splat(a), &s.place(b).splat(), s.s(), 1).0[0]
        };
        // Face-touching: kept; a 1e-3 gap: separated with a margin below the gap.
        let s = sat(DVec3::ZERO);
        assert!(one(&s, &a, &b) <= 0.0);
        let s = sat(DVec3::new(1e-3, 0.0, 0.0));
        let m = one(&s, &a, &b);
        assert!(m > 0.0 && m < 1e-3, "{m}");
        // Only an edge-edge axis separates these.
        let q = DQuat::from_rotation_x(std::f64::consts::FRAC_PI_4)
            * DQuat::from_rotation_z(std::f64::consts::FRAC_PI_4);
        let m = DMat3::from_quat(q);
        let dir = DVec3::new(1.0, 1.0, 1.0).normalize();
        let b = unit_box(DVec3::ZERO);
        for (dist, apart) in [(10.0, true), (1.0, false)] {
            let s = Sat32::new(m, dir * dist, 1e-12, 20.0).unwrap();
            assert_eq!(one(&s, &a, &b) > 0.0, apart, "{dist}");
            let f64_says = separation(&a, &Placed::new(&b, &m, dir * dist), 1e-12);
            assert_eq!(f64_says.is_some(), apart);
        }
        // Lanes mix: four A boxes along x against one B, only the far ones separated.
        let nodes: Vec<TNode> = (0..4)
            .map(|k| unit_box(DVec3::new(3.0 * k as f64, 0.0, 0.0)))
            .collect();
        let s = sat(DVec3::ZERO);
        let r = separation4(
            &ALanes::gather(&nodes, &[0, 1, 2, 3], 4),
            &s.place(&unit_box(DVec3::new(1.5, 0.0, 0.0))).splat(),
            s.s(),
            0xF,
        );
        assert_eq!(r.positive(), 0b1100, "{r:?}");
    }
}
