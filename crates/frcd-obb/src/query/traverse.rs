//! The traversal engine of the pair queries: the query context ([`Ctx`]), the wide f32
//! traversal (four-lane steps, paired as eight-lane tests in the AVX2 build), the binary f64
//! descent for magnitudes f32 cannot hold, and the leaf tests.

use super::cache::{Recording, record_pairs, record_separated};
use super::hits::Hits;
use super::{Containment, Counters, RelativeFrame, TopVolume, contained, query_slack};
use crate::isa::{self, Isa};
use crate::nodes::TNode;
use crate::sat::{self, Placed};
use crate::tree::ObbTree;
use crate::wide::{self, ALanes, BLanes, NO_QUAD, NodeMeta, Sat32, quad_ids};
use frcd_geom::{Aabb, DVec3, Pose, Triangle};
use frcd_tritri::Method;

/// Which node of a pair the traversal splits: A unless B is the bigger internal node, bigger by
/// the sum of its half extents (a rule that depends on the trees only, so the traversal tree is
/// the same every query). Against `|h|²`, the sum gave 2 % fewer box tests per disjoint query on
/// the near-contact knots and 5-15 % fewer on the CAD pairs (`FRCD_BENCH_COUNT=1`); it weighs a
/// box's smaller sides more, as PQP's size of a swept rectangle does.
#[inline(always)]
pub(super) fn split_a(na: &TNode, nb: &TNode) -> bool {
    nb.is_leaf() || (!na.is_leaf() && na.size() >= nb.size())
}

/// How a traversal step splits its (not leaf) entry: A's node or B's, and the split node's
/// quad entry ([`wide::Quads::of`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Split {
    pub a: bool,
    pub quad: u32,
}

impl Split {
    /// The split of entry `(i, j)` decided on the two nodes ([`split_a`]) and the split node's
    /// quad entry; `None` for a leaf pair.
    #[inline(always)]
    pub(super) fn on_nodes(
        a: &ObbTree,
        b: &ObbTree,
        qa: &wide::Quads,
        qb: &wide::Quads,
        i: u32,
        j: u32,
    ) -> Option<Split> {
        let (na, nb) = (&a.nodes[i as usize], &b.nodes[j as usize]);
        if na.is_leaf() && nb.is_leaf() {
            None
        } else if split_a(na, nb) {
            Some(Split {
                a: true,
                quad: qa.of[i as usize],
            })
        } else {
            Some(Split {
                a: false,
                quad: qb.of[j as usize],
            })
        }
    }

    /// The same decision on the entry's two node metas; `None` for a leaf pair.
    #[inline(always)]
    pub(super) fn on_metas(ma: NodeMeta, mb: NodeMeta) -> Option<Split> {
        if ma.is_leaf() && mb.is_leaf() {
            None
        } else if NodeMeta::split_a(ma, mb) {
            Some(Split {
                a: true,
                quad: ma.quad,
            })
        } else {
            Some(Split {
                a: false,
                quad: mb.quad,
            })
        }
    }
}

/// The overlapping lanes (margin not positive, NaN included) of the first `n` of a four-lane
/// test, in the order to push them so that the most negative margin is popped first: largest
/// margin first, ties by lane; returns them and their number. Branch-free: each lane becomes
/// one integer (the margin's total-order key above the lane's inverted index, 0 for a lane not
/// to expand), and a five-exchange sorting network puts them largest first (the branchy rank
/// count it replaces took a fifth of the dense sweep's first-contact time, perf). Out of line:
/// it runs at most [`ORDERED_STEPS`] times per descent, and inlined into the traversal loop it
/// made the loop's register allocation worse (1.6× the instructions per disjoint knots query,
/// callgrind).
#[inline(never)]
pub(super) fn deepest_last(m: &wide::F4, n: usize) -> ([usize; 4], usize) {
    let mut keys = [0u64; 4];
    let mut len = 0;
    for (k, (&margin, slot)) in m.0.iter().zip(&mut keys).enumerate() {
        let bits = margin.to_bits() as i32;
        // Total order of f32 as i32 (NaN above +inf), shifted to [1, 2^32] so that 0 stays
        // below every lane that is expanded.
        let key = (bits ^ ((((bits >> 31) as u32) >> 1) as i32)) as i64 + (1 << 31) + 1;
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        let expand = k < n && !(margin > 0.0);
        // A mask, not a branch: the compiler keeps `if` as a jump on the margin.
        *slot = ((key as u64) << 2 | (3 - k) as u64) & (expand as u64).wrapping_neg();
        len += expand as usize;
    }
    let exchange = |keys: &mut [u64; 4], p: usize, q: usize| {
        let (hi, lo) = (keys[p].max(keys[q]), keys[p].min(keys[q]));
        keys[p] = hi;
        keys[q] = lo;
    };
    exchange(&mut keys, 0, 1);
    exchange(&mut keys, 2, 3);
    exchange(&mut keys, 0, 2);
    exchange(&mut keys, 1, 3);
    exchange(&mut keys, 1, 2);
    (keys.map(|key| 3 - (key & 3) as usize), len)
}

/// A triangle in A's frame with its axis-aligned box (the leaf test's cheap rejection).
#[derive(Clone, Copy)]
pub(super) struct PlacedTriangle {
    pub(super) tri: Triangle,
    pub(super) aabb: Aabb,
}

impl PlacedTriangle {
    /// A placeholder, overwritten before use.
    const EMPTY: PlacedTriangle = PlacedTriangle {
        tri: Triangle {
            v: [DVec3::ZERO; 3],
        },
        aabb: Aabb {
            min: DVec3::ZERO,
            max: DVec3::ZERO,
        },
    };

    #[inline(always)]
    pub(super) fn new(tri: Triangle) -> Self {
        PlacedTriangle {
            aabb: tri.aabb(),
            tri,
        }
    }
}

/// One step of the wide traversal: a stack entry, which node it splits and the children it
/// tests.
#[derive(Clone, Copy)]
pub(super) struct StepMeta {
    pub(super) entry: (u32, u32, u32),
    /// A's node splits (its children against B's placed box), else B's.
    pub(super) split_a: bool,
    pub(super) ids: [u32; 4],
    pub(super) n: usize,
    /// B splits: the block of the stack's placed lanes that holds B's children.
    pub(super) block: u32,
}

impl StepMeta {
    /// Pushes the lanes that `m` does not separate (margin not positive), last lane first so
    /// that the leftmost is expanded first, and records the separated ones in `front` when one
    /// is being recorded. Without a front, branch-free: every lane written, the overlapping
    /// ones kept.
    #[inline(always)]
    pub(super) fn push<const RECORD: bool>(
        &self,
        stack: &mut Stack,
        front: &mut Recording<'_>,
        m: wide::F4,
    ) {
        let (i, j, p) = self.entry;
        if RECORD {
            for k in (0..self.n).rev() {
                let (a, b, q) = if self.split_a {
                    (self.ids[k], j, p)
                } else {
                    (i, self.ids[k], self.block << 2 | k as u32)
                };
                if m.0[k] > 0.0 {
                    record_separated(front, a, b, wide::margin64(m.0[k]));
                } else {
                    stack.pairs.push((a, b, q));
                }
            }
            return;
        }
        let top = stack.pairs.len();
        stack.pairs.resize(top + 4, (0, 0, 0));
        let mut len = top;
        if self.split_a {
            for k in (0..self.n).rev() {
                stack.pairs[len] = (self.ids[k], j, p);
                len += 1 - (m.0[k] > 0.0) as usize;
            }
        } else {
            let block = self.block << 2;
            for k in (0..self.n).rev() {
                stack.pairs[len] = (i, self.ids[k], block | k as u32);
                len += 1 - (m.0[k] > 0.0) as usize;
            }
        }
        stack.pairs.truncate(len);
    }
}

/// A step with its lanes for the four-lane test ([`Ctx::step_lanes`]).
pub(super) struct Step {
    pub(super) meta: StepMeta,
    pub(super) a: ALanes,
    /// B's placed box in every lane (A splits; B splits keep theirs in `meta.block`).
    pub(super) b: BLanes,
}

impl Step {
    /// The B lanes of the test.
    #[inline(always)]
    pub(super) fn b<'s>(&'s self, stack: &'s Stack) -> &'s BLanes {
        if self.meta.split_a {
            &self.b
        } else {
            &stack.placed32[self.meta.block as usize]
        }
    }
}

/// The traversal stack: node pairs, each naming its B box (placed in A's frame) in `placed`
/// (f64 boxes for the f64 traversal) or in `placed32` (the wide f32 traversal: the lanes one
/// step placed, kept whole, named `4 · block + lane`).
#[derive(Default)]
pub(super) struct Stack {
    pub(super) pairs: Vec<(u32, u32, u32)>,
    pub(super) placed: Vec<Placed>,
    pub(super) placed32: Vec<BLanes>,
    /// B leaves already placed in A's frame by the query that holds the stack.
    pub(super) leaves: PlacedLeaves,
    /// A leaves already fetched and boxed by that query.
    pub(super) a_leaves: PlacedLeaves,
}

impl Stack {
    pub(super) fn new() -> Self {
        Stack {
            pairs: Vec::with_capacity(64),
            placed: Vec::with_capacity(64),
            placed32: Vec::with_capacity(64),
            leaves: PlacedLeaves::default(),
            a_leaves: PlacedLeaves::default(),
        }
    }
}

/// One tree's leaves of one or two triangles, fetched and boxed by one query (B's placed in
/// A's frame first), direct-mapped by node index ([`PLACED_LEAF_SLOTS`] slots): a leaf met
/// again is read back instead of fetched and placed again. Depth-first, the A leaves below one
/// node meet the same B leaves one after another, and the other way round: on the dense
/// sweep's all pairs 558 of 828 leaf pairs per query found their B leaf here (67 %), on the
/// near-contact knots 110 of 174. The B slots cut the dense sweep's all-pairs instructions by
/// 2.2 %, the A slots by 1.3 % more.
///
/// A slot's tag is `generation << 32 | node`; the generation changes with every query
/// ([`PlacedLeaves::next_query`]), so no query reads another's triangles (another frame,
/// perhaps another tree).
#[derive(Default)]
pub(super) struct PlacedLeaves {
    /// Empty until a query first meets a leaf pair (then [`PLACED_LEAF_SLOTS`] entries).
    pub(super) tags: Vec<u64>,
    pub(super) tris: Vec<[PlacedTriangle; 2]>,
    pub(super) generation: u32,
}

/// Slots of [`PlacedLeaves`]: 256 (62 KB); 4,096 found 4 more leaves per dense query.
pub(super) const PLACED_LEAF_SLOTS: usize = 256;

impl PlacedLeaves {
    /// Forgets every placement (a new query: a new frame).
    pub(super) fn next_query(&mut self) {
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            // Tags of the generation 2^32 queries ago could match again: clear them.
            self.tags.fill(0);
            self.generation = 1;
        }
    }

    /// Leaf `node`'s slot and whether it holds the node's placed triangles; on a miss the
    /// slot is claimed for the node (the caller fills it).
    #[inline(always)]
    pub(super) fn slot(&mut self, node: u32) -> (&mut [PlacedTriangle; 2], bool) {
        if self.tags.is_empty() {
            self.tags = vec![0; PLACED_LEAF_SLOTS];
            self.tris = vec![[PlacedTriangle::EMPTY; 2]; PLACED_LEAF_SLOTS];
        }
        let k = node as usize % PLACED_LEAF_SLOTS;
        let tag = (u64::from(self.generation) << 32) | u64::from(node);
        let found = self.tags[k] == tag;
        self.tags[k] = tag;
        (&mut self.tris[k], found)
    }
}

thread_local! {
    /// This thread's traversal stack between queries: its buffers (about 27 KB to start with,
    /// then as deep as the deepest traversal, plus 124 KB of placed-leaf slots once a query
    /// meets a leaf pair) are reused instead of allocated and freed by every query that passes
    /// the top volume.
    pub(super) static STACK: std::cell::Cell<Stack> = std::cell::Cell::new(Stack::default());
}

/// The thread's [`Stack`], lent to one query and given back (emptied) when dropped, on every
/// return path. A query started inside another's callback finds the slot empty and gets a
/// fresh stack.
pub(super) struct PooledStack(Stack);

impl PooledStack {
    pub(super) fn take() -> Self {
        let stack = STACK.try_with(|c| c.take()).unwrap_or_default();
        let mut stack = if stack.pairs.capacity() == 0 {
            Stack::new()
        } else {
            stack
        };
        stack.leaves.next_query();
        stack.a_leaves.next_query();
        PooledStack(stack)
    }
}

impl std::ops::Deref for PooledStack {
    type Target = Stack;
    fn deref(&self) -> &Stack {
        &self.0
    }
}

impl std::ops::DerefMut for PooledStack {
    fn deref_mut(&mut self) -> &mut Stack {
        &mut self.0
    }
}

impl Drop for PooledStack {
    fn drop(&mut self) {
        let mut stack = std::mem::take(&mut self.0);
        stack.pairs.clear();
        stack.placed.clear();
        stack.placed32.clear();
        // Fails only while the thread's locals are being destroyed: then the stack is freed.
        let _ = STACK.try_with(|c| c.set(stack));
    }
}

/// Which traversal a query runs (crate-internal switch, for tests comparing the two).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Traversal {
    /// The wide f32 traversal when the query's magnitudes fit f32 (`wide.rs`), else the f64 one;
    /// the process's build of its hot loop ([`isa::best`]).
    Wide,
    /// The wide traversal's AVX2 build even where the process runs the AVX-512 one (tests
    /// comparing the builds, `isa.rs`).
    #[cfg_attr(not(test), allow(dead_code))]
    WideAvx2,
    /// The wide traversal compiled for the baseline instruction set even where the CPU has
    /// AVX2 (tests comparing the two builds of the hot loop, `isa.rs`).
    #[cfg_attr(not(test), allow(dead_code))]
    WideBaseline,
    /// The binary f64 traversal (one box pair per test, `sat.rs`).
    #[cfg_attr(not(test), allow(dead_code))]
    Binary,
}

thread_local! {
    /// The traversal of this thread's queries (tests switch it; queries read it once).
    static TRAVERSAL: std::cell::Cell<Traversal> = const { std::cell::Cell::new(Traversal::Wide) };
}

/// Runs `f` with this thread's queries using traversal `t` (tests).
#[cfg(test)]
pub(crate) fn with_traversal<R>(t: Traversal, f: impl FnOnce() -> R) -> R {
    let old = TRAVERSAL.with(|c| c.replace(t));
    let r = f();
    TRAVERSAL.with(|c| c.set(old));
    r
}

pub(super) struct Ctx<'a> {
    pub(super) a: &'a ObbTree,
    pub(super) b: &'a ObbTree,
    pub(super) frame: RelativeFrame,
    pub(super) slack: f64,
    pub(super) method: Method,
    pub(super) counters: Counters,
    /// The f32 box test of the wide traversal, `None` where the query's magnitudes do not fit
    /// f32 (then the binary f64 traversal runs).
    pub(super) sat32: Option<Sat32>,
    /// The build of the wide traversal's hot loop this query runs (`isa.rs`): one the CPU has
    /// (always the baseline, and unread, off x86-64).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub(super) isa: Isa,
    /// How many steps at the top of each wide descent expand their overlapping lanes deepest
    /// first ([`ORDERED_STEPS`] in first contact, 0 in all pairs, where order is moot).
    pub(super) ordered_steps: u32,
    /// The leaf pair (nodes of A and of B) the traversal tested last: where first contact
    /// stopped, once it has.
    pub(super) last_leaves: (u32, u32),
}

/// First contact: the first steps of a wide descent (those near the roots, where the choice
/// of subtree matters most) expand their overlapping lanes in order of depth of overlap, the
/// most negative margin first; later steps take the leftmost lane first (branch-free). Box
/// tests per touching first-contact query (time-free counts, `FRCD_BENCH_COUNT=1`), lane 0
/// first everywhere → deepest first in the first 16 steps: dense sweep 196 → 136, knots near
/// contact 1,309 → 1,197, wagon + bogie 690 → 541, bogie pair 708 → 547, fandisk 315 → 288;
/// deepest first at every step gives about the same counts (118 / 1,241 / 504 / 575 / 264) but
/// pays the sort at every step of the disjoint queries too, which cost more than it saved.
pub(super) const ORDERED_STEPS: u32 = 16;

/// [`ORDERED_STEPS`], or in tests the value `with_ordered_steps` set for this thread.
#[inline]
pub(super) fn ordered_steps() -> u32 {
    #[cfg(test)]
    if let Some(n) = ORDERED_OVERRIDE.with(|c| c.get()) {
        return n;
    }
    ORDERED_STEPS
}

#[cfg(test)]
thread_local! {
    static ORDERED_OVERRIDE: std::cell::Cell<Option<u32>> = const { std::cell::Cell::new(None) };
}

/// Runs `f` with first contact ordering `n` steps per descent on this thread (tests).
#[cfg(test)]
pub(super) fn with_ordered_steps<R>(n: u32, f: impl FnOnce() -> R) -> R {
    ORDERED_OVERRIDE.with(|c| c.set(Some(n)));
    let r = f();
    ORDERED_OVERRIDE.with(|c| c.set(None));
    r
}

impl<'a> Ctx<'a> {
    // Always inlined: out of line, the context (and its `Option<Sat32>`) came back through a
    // call to `memcpy`, 13 % of a query the top volume rejects (perf, dense sweep).
    #[inline(always)]
    pub(super) fn new(
        a: &'a ObbTree,
        pose_a: &Pose,
        b: &'a ObbTree,
        pose_b: &Pose,
        method: Method,
    ) -> Self {
        let frame = RelativeFrame::new(pose_a, pose_b);
        let slack = query_slack(a, b, &frame);
        let traversal = TRAVERSAL.with(|c| c.get());
        let sat32 = match traversal {
            Traversal::Wide | Traversal::WideAvx2 | Traversal::WideBaseline => {
                let mag = a.radius_from_origin + b.radius_from_origin + frame.t.length();
                Sat32::new(frame.m, frame.t, slack, mag)
            }
            Traversal::Binary => None,
        };
        let isa = match (traversal, isa::best()) {
            (Traversal::Wide, best) => best,
            (Traversal::WideAvx2, Isa::Avx512) => Isa::Avx2,
            (Traversal::WideAvx2, best) => best,
            (Traversal::WideBaseline | Traversal::Binary, _) => Isa::Baseline,
        };
        Ctx {
            a,
            b,
            slack,
            frame,
            method,
            counters: Counters::default(),
            sat32,
            isa,
            ordered_steps: 0,
            last_leaves: (0, 0),
        }
    }

    /// Hybrid top volume: sphere, then AABB. True when the bodies are certainly apart. Only
    /// finite figures reject: near the top of the f64 range a distance, a box centre or a
    /// transformed corner can overflow (and `0 · ∞` gives NaN), and such a figure proves
    /// nothing (found by the `mesh_tree` fuzz target: two point triangles at `z ≈ −1.8·10³⁰⁸`
    /// were rejected as apart from themselves).
    pub(super) fn top_rejects(&mut self, top: TopVolume) -> bool {
        if top == TopVolume::RootObb {
            return false;
        }
        self.counters.top_tests += 1;
        let sa = self.a.sphere;
        let sb = self.b.sphere;
        let d = self.frame.point(sb.center).distance(sa.center);
        let reach = sa.radius + sb.radius + self.slack;
        if d.is_finite() && reach.is_finite() && d > reach {
            return true;
        }
        self.counters.top_tests += 1;
        let bb = self.frame.aabb(&self.b.aabb, self.slack);
        let ba = self.a.aabb.inflated(self.slack);
        let finite = |b: &Aabb| b.min.is_finite() && b.max.is_finite();
        finite(&bb) && finite(&ba) && !bb.intersects(&ba)
    }

    #[inline(always)]
    pub(super) fn place(&mut self, j: u32) -> Placed {
        self.counters.placements += 1;
        Placed::new(&self.b.nodes[j as usize], &self.frame.m, self.frame.t)
    }

    /// The separating axis and margin of node `i` of A against a placed box of B, if any.
    #[inline(always)]
    pub(super) fn separation(&mut self, i: u32, pb: &Placed) -> Option<(u8, f64)> {
        self.counters.box_tests += 1;
        sat::separation(&self.a.nodes[i as usize], pb, self.slack)
    }

    /// The two children of a node pair in the traversal tree (descend into the bigger box; a
    /// rule that depends on the trees only, so the traversal tree is the same every query).
    #[inline(always)]
    pub(super) fn children(&self, i: u32, j: u32) -> [(u32, u32); 2] {
        let na = &self.a.nodes[i as usize];
        let nb = &self.b.nodes[j as usize];
        if split_a(na, nb) {
            [(i + 1, j), (na.right(), j)]
        } else {
            [(i, j + 1), (i, nb.right())]
        }
    }

    #[inline(always)]
    pub(super) fn both_leaves(&self, i: u32, j: u32) -> bool {
        self.a.nodes[i as usize].is_leaf() && self.b.nodes[j as usize].is_leaf()
    }

    /// Exact per-pair box check, then the triangle test.
    #[inline]
    pub(super) fn tri_pair(&mut self, ta: u32, tb: u32) -> bool {
        let t1 = PlacedTriangle::new(self.a.triangle(ta));
        let t2 = PlacedTriangle::new(self.frame.triangle(&self.b.triangle(tb)));
        self.placed_tri_pair(&t1, &t2)
    }

    /// [`Ctx::tri_pair`] on triangles already fetched, placed in A's frame and boxed.
    #[inline(always)]
    pub(super) fn placed_tri_pair(&mut self, t1: &PlacedTriangle, t2: &PlacedTriangle) -> bool {
        if !t1.aabb.intersects(&t2.aabb) {
            return false;
        }
        self.counters.tri_tests += 1;
        frcd_tritri::intersects(self.method, &t1.tri, &t2.tri)
    }

    /// Tests the triangles of a leaf pair; calls `hit` on each touching pair, stops when it
    /// returns `true`. Each triangle is fetched from its mesh, placed and boxed once per query
    /// where its leaf holds one or two triangles (kept in `leaves` for B, `a_leaves` for A,
    /// see [`PlacedLeaves`]), else once per leaf pair; never once per triangle pair. The same
    /// operations on the same values either way, so the same answers.
    #[inline]
    pub(super) fn leaf_pair(
        &mut self,
        (leaves, a_leaves): (&mut PlacedLeaves, &mut PlacedLeaves),
        i: u32,
        j: u32,
        hit: &mut impl Hits,
    ) -> bool {
        self.last_leaves = (i, j);
        let tas = self.a.node_triangles(i);
        let tbs = self.b.node_triangles(j);
        // Leaves of one or two triangles (the default leaf holds two) go through `leaves`;
        // larger ones get one instance per size up to four, so the placed triangles live in
        // an array of exactly that size.
        if tbs.len() <= 2 {
            let (placed, found) = leaves.slot(j);
            if !found {
                for (p, &tb) in placed.iter_mut().zip(tbs) {
                    *p = PlacedTriangle::new(self.frame.triangle(&self.b.triangle(tb)));
                }
            }
            let placed = &placed[..tbs.len()];
            let a = self.a;
            if tas.len() <= 2 {
                // A's triangles, fetched and boxed once per query too.
                let (fetched, found) = a_leaves.slot(i);
                if !found {
                    for (p, &ta) in fetched.iter_mut().zip(tas) {
                        *p = PlacedTriangle::new(a.triangle(ta));
                    }
                }
                for (t1, &ta) in fetched.iter().zip(tas) {
                    if self.triangle_row(ta, t1, placed, tbs, hit) {
                        return true;
                    }
                }
                false
            } else {
                self.fetched_rows(tas, placed, tbs, hit)
            }
        } else if let Ok(tbs) = <&[u32; 3]>::try_from(tbs) {
            self.placed_leaf_pair(tas, tbs, hit)
        } else if let Ok(tbs) = <&[u32; 4]>::try_from(tbs) {
            self.placed_leaf_pair(tas, tbs, hit)
        } else {
            // Larger leaves (a build option): triangle by triangle.
            for &ta in tas {
                for &tb in tbs {
                    if self.tri_pair(ta, tb) && hit.hit(ta, tb) {
                        return true;
                    }
                }
            }
            false
        }
    }

    /// A's triangles `tas`, each fetched and boxed here, against B's placed triangles of one
    /// leaf ([`Ctx::triangle_row`] each); true when `hit` stops the traversal.
    #[inline(always)]
    pub(super) fn fetched_rows(
        &mut self,
        tas: &[u32],
        placed: &[PlacedTriangle],
        tbs: &[u32],
        hit: &mut impl Hits,
    ) -> bool {
        let a = self.a;
        for &ta in tas {
            let t1 = PlacedTriangle::new(a.triangle(ta));
            if self.triangle_row(ta, &t1, placed, tbs, hit) {
                return true;
            }
        }
        false
    }

    /// A's triangle `ta` (boxed, `t1`) against B's placed triangles of one leaf; calls `hit`
    /// on each touching pair, true when it stops the traversal.
    #[inline(always)]
    pub(super) fn triangle_row(
        &mut self,
        ta: u32,
        t1: &PlacedTriangle,
        placed: &[PlacedTriangle],
        tbs: &[u32],
        hit: &mut impl Hits,
    ) -> bool {
        for (t2, &tb) in placed.iter().zip(tbs) {
            if self.placed_tri_pair(t1, t2) && hit.hit(ta, tb) {
                return true;
            }
        }
        false
    }

    /// [`Ctx::leaf_pair`] with B's `N` triangles placed first.
    #[inline]
    pub(super) fn placed_leaf_pair<const N: usize>(
        &mut self,
        tas: &[u32],
        tbs: &[u32; N],
        hit: &mut impl Hits,
    ) -> bool {
        let b = self.b;
        // A plain loop over a filled array: `array::from_fn` kept its closure out of line
        // (a call and a copy of the result per triangle).
        let mut placed = [PlacedTriangle::EMPTY; N];
        for (p, &tb) in placed.iter_mut().zip(tbs) {
            *p = PlacedTriangle::new(self.frame.triangle(&b.triangle(tb)));
        }
        self.fetched_rows(tas, &placed, tbs, hit)
    }

    /// Depth-first traversal below (and including) node pair `(i, j)`. Appends the pairs where
    /// it stopped to `front` (when given; separated pairs with bound `clock + margin`); calls
    /// `hit` on touching triangle pairs and stops everything when `hit` returns `true` (then
    /// returns `true`, and the pairs it did not reach go to `front` as untested, so the front
    /// stays a cut).
    pub(super) fn descend(
        &mut self,
        i: u32,
        j: u32,
        stack: &mut Stack,
        front: Recording<'_>,
        hit: &mut impl Hits,
    ) -> bool {
        match self.sat32 {
            Some(sat) => self.descend_wide(&sat, i, j, None, stack, front, hit),
            None => self.descend64(i, j, stack, front, hit),
        }
    }

    /// [`Ctx::descend`] on the binary f64 traversal: one box pair per test (`sat.rs`).
    pub(super) fn descend64(
        &mut self,
        i: u32,
        j: u32,
        stack: &mut Stack,
        mut front: Recording<'_>,
        hit: &mut impl Hits,
    ) -> bool {
        let base = stack.pairs.len();
        let pbase = stack.placed.len();
        // B's boxes mapped into A's frame live in `stack.placed`; stack entries name them by
        // index (12-byte entries instead of copying a 128-byte box on every push and pop), and
        // splitting A reuses them. Indices never decrease up the stack, so when an entry is
        // popped every box above its own belongs to finished subtrees and is dropped.
        let pj = self.place(j);
        stack.placed.push(pj);
        stack.pairs.push((i, j, pbase as u32));
        while stack.pairs.len() > base {
            let (i, j, p) = stack.pairs.pop().expect("non-empty");
            stack.placed.truncate(p as usize + 1);
            if let Some((_, margin)) = self.separation(i, &stack.placed[p as usize]) {
                record_separated(&mut front, i, j, margin);
                continue;
            }
            if self.both_leaves(i, j) {
                record_pairs(&mut front, std::iter::once((i, j)));
                if self.leaf_pair((&mut stack.leaves, &mut stack.a_leaves), i, j, hit) {
                    let rest = stack.pairs[base..].iter().map(|&(a, b, _)| (a, b));
                    record_pairs(&mut front, rest);
                    stack.pairs.truncate(base);
                    stack.placed.truncate(pbase);
                    return true;
                }
                continue;
            }
            let [l, r] = self.children(i, j);
            if l.1 == j {
                stack.pairs.push((r.0, r.1, p));
                stack.pairs.push((l.0, l.1, p));
            } else {
                let q = stack.placed.len() as u32;
                let pr = self.place(r.1);
                let pl = self.place(l.1);
                stack.placed.push(pr);
                stack.placed.push(pl);
                stack.pairs.push((r.0, r.1, q));
                stack.pairs.push((l.0, l.1, q + 1));
            }
        }
        stack.placed.truncate(pbase);
        false
    }

    /// [`Ctx::descend`] on the wide f32 traversal (`wide.rs`). Stack entries are node pairs
    /// whose boxes overlap (tested); expanding one tests the smaller node against the (2 to 4)
    /// nodes two levels below the bigger one in one four-lane test (a child that is a leaf
    /// stands for itself; the bigger box is split as in the binary traversal, leaves never),
    /// so a stack step decides up to four box pairs with one branch. Each lane counts as one
    /// box test, each B box placed in A's frame as one placement. Front entries are binary
    /// node pairs, as in the binary traversal, so a front is a cut of either traversal tree.
    ///
    /// `overlapping_start`: B's start node already placed in A's frame (in every lane) and
    /// found overlapping A's (the front walk tests expired pairs four at a time), so neither
    /// is done again.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn descend_wide(
        &mut self,
        sat: &Sat32,
        i: u32,
        j: u32,
        overlapping_start: Option<BLanes>,
        stack: &mut Stack,
        front: Recording<'_>,
        hit: &mut impl Hits,
    ) -> bool {
        #[cfg(target_arch = "x86_64")]
        match self.isa {
            // SAFETY: `isa` names only a build whose features the running CPU reports
            // (`Ctx::new`, `isa::best`): AVX2, or AVX2 with AVX-512 F and VL.
            #[allow(unsafe_code)]
            Isa::Avx512 => {
                return unsafe {
                    self.descend_wide_avx512(sat, i, j, overlapping_start, stack, front, hit)
                };
            }
            #[allow(unsafe_code)]
            Isa::Avx2 => {
                return unsafe {
                    self.descend_wide_avx2(sat, i, j, overlapping_start, stack, front, hit)
                };
            }
            Isa::Baseline => {}
        }
        self.descend_wide_body::<false>(sat, i, j, overlapping_start, stack, front, hit)
    }

    /// [`Ctx::descend_wide`] compiled with AVX2 (`isa.rs`): the same operations, encoded with
    /// AVX's three-operand instructions and 256-bit f64 lanes.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn descend_wide_avx2(
        &mut self,
        sat: &Sat32,
        i: u32,
        j: u32,
        overlapping_start: Option<BLanes>,
        stack: &mut Stack,
        front: Recording<'_>,
        hit: &mut impl Hits,
    ) -> bool {
        self.descend_wide_body::<true>(sat, i, j, overlapping_start, stack, front, hit)
    }

    /// [`Ctx::descend_wide`] compiled with AVX-512 F and VL (`isa.rs`): the AVX2 build's code,
    /// EVEX-encoded with 32 vector registers, so the eight-lane test keeps its values in
    /// registers.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,avx512f,avx512vl")]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn descend_wide_avx512(
        &mut self,
        sat: &Sat32,
        i: u32,
        j: u32,
        overlapping_start: Option<BLanes>,
        stack: &mut Stack,
        front: Recording<'_>,
        hit: &mut impl Hits,
    ) -> bool {
        self.descend_wide_body::<true>(sat, i, j, overlapping_start, stack, front, hit)
    }

    /// The body of [`Ctx::descend_wide`], inlined into each of its instruction-set builds
    /// (`AVX`: the AVX2 and AVX-512 builds, which run paired steps as eight-lane tests).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn descend_wide_body<const AVX: bool>(
        &mut self,
        sat: &Sat32,
        i: u32,
        j: u32,
        overlapping_start: Option<BLanes>,
        stack: &mut Stack,
        mut front: Recording<'_>,
        hit: &mut impl Hits,
    ) -> bool {
        let base = stack.pairs.len();
        let pbase = stack.placed32.len();
        let (a, b) = (self.a, self.b);
        let start = match overlapping_start {
            Some(lanes) => lanes,
            None => {
                // The start pair, in one lane.
                self.counters.placements += 1;
                self.counters.box_tests += 1;
                let pj = sat.place(&b.nodes[j as usize]).splat();
                let m = wide::separation4(&ALanes::splat(&a.nodes[i as usize]), &pj, sat.s(), 1);
                if m.0[0] > 0.0 {
                    record_separated(&mut front, i, j, wide::margin64(m.0[0]));
                    return false;
                }
                pj
            }
        };
        // A B box is named `4 · block + lane`, a block being the lanes one step placed, stored
        // whole (one store per step instead of taking each surviving lane apart). As in
        // `descend64`, blocks never decrease up the stack, so when an entry is popped every
        // block above its own is finished with.
        stack.placed32.push(start);
        stack.pairs.push((i, j, (pbase as u32) << 2));
        if self.ordered_steps > 0
            && front.is_none()
            && let Some(stop) = self.ordered_loop(sat, base, pbase, stack, hit, self.ordered_steps)
        {
            return stop;
        }
        // One instance per case, so that the plain loop carries no front checks.
        if front.is_none() {
            self.paired_steps::<AVX, false>(sat, base, pbase, stack, &mut front, hit, false)
        } else {
            // A descent from the roots is long (the cache's fresh traversal): on the metas. One
            // from a front entry is short and starts on two nodes just tested: on the nodes.
            let on_nodes = (i, j) != (0, 0);
            self.paired_steps::<AVX, true>(sat, base, pbase, stack, &mut front, hit, on_nodes)
        }
    }

    /// A's nodes two levels below internal node `i` (quad entry `qa`, [`wide::Quads::of`]), in
    /// lanes (from its quad, or gathered): their ids and number, counted as box tests.
    #[inline(always)]
    pub(super) fn a_children(&mut self, i: u32, qa: u32) -> ([u32; 4], usize, ALanes) {
        let a = self.a;
        let qa_all = a.quads();
        let (ids, n, lanes) = if qa != NO_QUAD {
            let q = &qa_all.quads[(qa >> 2) as usize];
            (q.ids, (qa & 3) as usize + 1, ALanes::from_quad(q))
        } else {
            let (ids, n) = quad_ids(&a.nodes, i);
            (ids, n, ALanes::gather(&a.nodes, &ids, n))
        };
        self.counters.box_tests += n as u64;
        (ids, n, lanes)
    }

    /// B's nodes two levels below internal node `j` (quad entry `qb`), placed in A's frame in
    /// lanes (from its quad, or gathered): their ids and number, counted as box tests and
    /// placements.
    #[inline(always)]
    pub(super) fn b_children(&mut self, sat: &Sat32, j: u32, qb: u32) -> ([u32; 4], usize, BLanes) {
        let b = self.b;
        let qb_all = b.quads();
        let (ids, n, lanes) = if qb != NO_QUAD {
            let q = &qb_all.quads[(qb >> 2) as usize];
            (q.ids, (qb & 3) as usize + 1, sat.place_quad(q))
        } else {
            let (ids, n) = quad_ids(&b.nodes, j);
            (ids, n, sat.place_lanes(&b.nodes, &ids, n))
        };
        self.counters.box_tests += n as u64;
        self.counters.placements += n as u64;
        (ids, n, lanes)
    }

    /// The lanes of one traversal step on the stack entry `(i, j, p)` (not a leaf pair; split
    /// as `split` says): the split node's children two levels down against the other node,
    /// counted as box tests (and placements, where B's children are placed).
    #[inline(always)]
    pub(super) fn step_lanes(
        &mut self,
        sat: &Sat32,
        stack: &mut Stack,
        (i, j, p): (u32, u32, u32),
        split: Split,
    ) -> Step {
        if split.a {
            let (ids, n, lanes) = self.a_children(i, split.quad);
            let pb = stack.placed32[(p >> 2) as usize].broadcast((p & 3) as usize);
            Step {
                meta: StepMeta {
                    entry: (i, j, p),
                    split_a: true,
                    ids,
                    n,
                    block: 0,
                },
                a: lanes,
                b: pb,
            }
        } else {
            let (ids, n, lanes) = self.b_children(sat, j, split.quad);
            // Stored at once as a new block (a copy of the lanes kept in the step went
            // through memcpy twice). The caller pushes B splits' entries after A splits'.
            let block = stack.placed32.len() as u32;
            stack.placed32.push(lanes);
            Step {
                meta: StepMeta {
                    entry: (i, j, p),
                    split_a: false,
                    ids,
                    n,
                    block,
                },
                a: ALanes::splat(&self.a.nodes[i as usize]),
                b: BLanes::default(),
            }
        }
    }

    /// The main loop of [`Ctx::descend_wide_body`]: each step pops two entries (the second
    /// unless it is a leaf pair) and tests both steps' lanes at once, in the AVX2 build as one
    /// eight-lane test ([`wide::avx::separation8`]: twice the lanes for about 1.2× the
    /// instructions of one four-lane test), in the baseline build as two four-lane tests. The
    /// same pairs are tested and kept as one entry at a time would, in another order on the
    /// stack; both builds take the same order, so their answers, counters and (with `RECORD`,
    /// a front being recorded, each separated lane with its margin) fronts are the same bit for
    /// bit. Disjoint near-contact knots: 545 → 486 thousand instructions per query, 18 % less
    /// time (`docs/performance/cpu-core.md`, eighth sitting). Each popped entry is decided
    /// (leaf pair, or which node to split) on the nodes where `RECORD && on_nodes` (the
    /// cache's descents from its front entries), else on the node metas ([`wide::Quads`] says
    /// why). True when `hit` stopped the traversal.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn paired_steps<const AVX: bool, const RECORD: bool>(
        &mut self,
        sat: &Sat32,
        base: usize,
        pbase: usize,
        stack: &mut Stack,
        front: &mut Recording<'_>,
        hit: &mut impl Hits,
        on_nodes: bool,
    ) -> bool {
        let (a, b) = (self.a, self.b);
        let (qa, qb) = (a.quads(), b.quads());
        // A recorded descent from a front entry decides on the nodes, every other descent on
        // the metas (`wide::Quads`); the same decisions either way.
        let decide = |i: u32, j: u32| {
            if RECORD && on_nodes {
                Split::on_nodes(a, b, qa, qb, i, j)
            } else {
                Split::on_metas(qa.metas[i as usize], qb.metas[j as usize])
            }
        };
        let s = sat.s();
        while stack.pairs.len() > base {
            let (i, j, p) = stack.pairs.pop().expect("non-empty");
            stack.placed32.truncate((p >> 2) as usize + 1);
            let Some(split) = decide(i, j) else {
                if RECORD {
                    record_pairs(front, std::iter::once((i, j)));
                }
                if self.leaf_pair((&mut stack.leaves, &mut stack.a_leaves), i, j, hit) {
                    if RECORD {
                        let rest = stack.pairs[base..].iter().map(|&(a, b, _)| (a, b));
                        record_pairs(front, rest);
                    }
                    stack.pairs.truncate(base);
                    stack.placed32.truncate(pbase);
                    return true;
                }
                continue;
            };
            // The entry below, unless it is a leaf pair. Its block is at most the first's, so
            // the truncation above kept it.
            let second = match stack.pairs.last() {
                Some(&(i2, j2, p2)) if stack.pairs.len() > base => {
                    decide(i2, j2).map(|split2| ((i2, j2, p2), split2))
                }
                _ => None,
            };
            let Some(entry2) = second else {
                let first = self.step_lanes(sat, stack, (i, j, p), split);
                let m = wide::separation4(&first.a, first.b(stack), s, (1 << first.meta.n) - 1);
                first.meta.push::<RECORD>(stack, front, m);
                continue;
            };
            stack.pairs.pop();
            let (first, m1, second, m2) =
                self.paired_test::<AVX, RECORD>(sat, stack, ((i, j, p), split), entry2);
            // Blocks must not decrease up the stack: the A splits' entries (which name blocks
            // already there) go first, the second's below the first's, then the B splits'
            // (new blocks, the first's before the second's).
            for (step, m) in [(&second, m2), (&first, m1)] {
                if step.split_a {
                    step.push::<RECORD>(stack, front, m);
                }
            }
            for (step, m) in [(&first, m1), (&second, m2)] {
                if !step.split_a {
                    step.push::<RECORD>(stack, front, m);
                }
            }
        }
        stack.placed32.truncate(pbase);
        false
    }

    /// Both steps of a pair built and tested: in the AVX2 build as one eight-lane test
    /// ([`wide::avx`]), in the baseline build as two four-lane tests (the same lanes
    /// separated either way). The first entry's B block, if any, is stored before the second's.
    #[inline(always)]
    pub(super) fn paired_test<const AVX: bool, const MARGINS: bool>(
        &mut self,
        sat: &Sat32,
        stack: &mut Stack,
        entry1: ((u32, u32, u32), Split),
        entry2: ((u32, u32, u32), Split),
    ) -> (StepMeta, wide::F4, StepMeta, wide::F4) {
        let s = sat.s();
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: `AVX` is true only in the traversal's AVX2 and AVX-512 builds, entered
            // only where the CPU reports their features (`Ctx::new`, `isa::best`).
            #[allow(unsafe_code)]
            unsafe {
                let (first, h1) = self.step_half(sat, stack, entry1.0, entry1.1);
                let (second, h2) = self.step_half(sat, stack, entry2.0, entry2.1);
                let active = ((1 << first.n) - 1) | (((1 << second.n) - 1) << 4);
                let (m1, m2) = wide::avx::separation8::<MARGINS>(&h1, &h2, s, active);
                return (first, m1, second, m2);
            }
        }
        let first = self.step_lanes(sat, stack, entry1.0, entry1.1);
        let second = self.step_lanes(sat, stack, entry2.0, entry2.1);
        let m1 = wide::separation4(&first.a, first.b(stack), s, (1 << first.meta.n) - 1);
        let m2 = wide::separation4(&second.a, second.b(stack), s, (1 << second.meta.n) - 1);
        (first.meta, m1, second.meta, m2)
    }

    /// [`Ctx::step_lanes`] for the eight-lane test: the step's lanes as one half, built from
    /// where they lie.
    ///
    /// # Safety
    ///
    /// The CPU must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    #[allow(unsafe_code)]
    pub(super) unsafe fn step_half(
        &mut self,
        sat: &Sat32,
        stack: &mut Stack,
        (i, j, p): (u32, u32, u32),
        split: Split,
    ) -> (StepMeta, wide::avx::Half) {
        let a = self.a;
        if split.a {
            let qa_all = a.quads();
            let qa = split.quad;
            let placed = &stack.placed32[(p >> 2) as usize];
            let k = (p & 3) as usize;
            // SAFETY (both calls): the caller guarantees AVX2.
            let (ids, n, half) = if qa != NO_QUAD {
                let q = &qa_all.quads[(qa >> 2) as usize];
                (q.ids, (qa & 3) as usize + 1, unsafe {
                    wide::avx::a_split(q, placed, k)
                })
            } else {
                let (ids, n) = quad_ids(&a.nodes, i);
                let q = wide::Quad::gather(&a.nodes, &ids, n);
                (ids, n, unsafe { wide::avx::a_split(&q, placed, k) })
            };
            self.counters.box_tests += n as u64;
            let meta = StepMeta {
                entry: (i, j, p),
                split_a: true,
                ids,
                n,
                block: 0,
            };
            (meta, half)
        } else {
            let (ids, n, lanes) = self.b_children(sat, j, split.quad);
            // SAFETY: the caller guarantees AVX2.
            let half = unsafe { wide::avx::b_split(&a.nodes[i as usize], &lanes) };
            let block = stack.placed32.len() as u32;
            stack.placed32.push(lanes);
            let meta = StepMeta {
                entry: (i, j, p),
                split_a: false,
                ids,
                n,
                block,
            };
            (meta, half)
        }
    }

    /// First contact's first steps over the stack above `base` (no front recorded): each step
    /// pushes its overlapping lanes deepest last ([`ORDERED_STEPS`]), for at most `ordered`
    /// steps. `Some(true)` when `hit` stopped the traversal, `Some(false)` when the stack is
    /// done, `None` after `ordered` steps, with the stack as it is for [`Ctx::paired_steps`].
    /// A loop of its own, so that the paired loop, where the time goes, carries no step count.
    #[inline(always)]
    pub(super) fn ordered_loop(
        &mut self,
        sat: &Sat32,
        base: usize,
        pbase: usize,
        stack: &mut Stack,
        hit: &mut impl Hits,
        mut ordered: u32,
    ) -> Option<bool> {
        let (ma_all, mb_all) = (&self.a.quads().metas, &self.b.quads().metas);
        let s = sat.s();
        while stack.pairs.len() > base {
            if ordered == 0 {
                return None;
            }
            let (i, j, p) = stack.pairs.pop().expect("non-empty");
            stack.placed32.truncate((p >> 2) as usize + 1);
            let (ma, mb) = (ma_all[i as usize], mb_all[j as usize]);
            if ma.is_leaf() && mb.is_leaf() {
                if self.leaf_pair((&mut stack.leaves, &mut stack.a_leaves), i, j, hit) {
                    stack.pairs.truncate(base);
                    stack.placed32.truncate(pbase);
                    return Some(true);
                }
                continue;
            }
            ordered -= 1;
            if NodeMeta::split_a(ma, mb) {
                let (ids, n, lanes) = self.a_children(i, ma.quad);
                let pb = stack.placed32[(p >> 2) as usize].broadcast((p & 3) as usize);
                let m = wide::separation4(&lanes, &pb, s, (1 << n) - 1);
                let (order, len) = deepest_last(&m, n);
                for &k in &order[..len] {
                    stack.pairs.push((ids[k], j, p));
                }
            } else {
                let (ids, n, lanes) = self.b_children(sat, j, mb.quad);
                let na = &self.a.nodes[i as usize];
                let m = wide::separation4(&ALanes::splat(na), &lanes, s, (1 << n) - 1);
                let block = (stack.placed32.len() as u32) << 2;
                stack.placed32.push(lanes);
                let (order, len) = deepest_last(&m, n);
                for &k in &order[..len] {
                    stack.pairs.push((i, ids[k], block | k as u32));
                }
            }
        }
        stack.placed32.truncate(pbase);
        Some(false)
    }

    pub(super) fn containment(&self, solid: bool) -> Option<Containment> {
        if !solid {
            return None;
        }
        contained(self.a, self.b, &self.frame, 0x5EED)
    }
}
