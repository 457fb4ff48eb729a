//! The top of every pair tree of a batch on the CPU ("host front"), the rest on the GPU.
//!
//! The GPU traverses a batch one level of the pair trees per dispatch. Near the roots a level
//! holds a few hundred node pairs, too few to fill a GPU, and still costs a whole dispatch: on
//! lavapipe (Mesa 22.3, two worker threads, a 2-vCPU VM) each of a 64-part frame's first
//! twelve levels took 120-220 µs of GPU time whatever its size (2026-12-02). So the CPU
//! descends the top of every pair tree of the batch breadth first with frcd-obb's certified box
//! test ([`frcd_obb::PairFront`]) while a level costs at most a budget of box tests in all, and
//! the GPU starts from the pairs it reached: the same answers (the GPU's levels below and the
//! triangle pass do the rest; a box test on either side can keep a pair, never drop one),
//! fewer dispatches.

use crate::query::{BodyPair, ONE_NODE};
use frcd_obb::{ObbTree, PairFront};
use std::sync::Arc;

/// What the CPU needs of an uploaded tree to descend its top: the tree itself and where each
/// node sits in the packed (breadth-first, siblings side by side) order.
pub(crate) struct HostTree {
    pub(crate) tree: ObbTree,
    /// Per tree node: its slot in the packed order (its left child's slot is its first child
    /// there, the right child's the next one).
    slot: Vec<u32>,
    /// Per tree node: the height of its subtree (a leaf: 1).
    height: Vec<u32>,
}

impl HostTree {
    /// `tree` with its packed order (`bfs[slot]` = tree node, `first_child[slot]` its first
    /// child's slot or 0 for a leaf: `pack::sibling_order`'s output; children come after their
    /// parent there).
    pub(crate) fn new(tree: &ObbTree, bfs: &[usize], first_child: &[u32]) -> Arc<Self> {
        let n = bfs.len();
        let mut slot = vec![0u32; n];
        for (s, &i) in bfs.iter().enumerate() {
            slot[i] = s as u32;
        }
        // Heights by slot, children first (the root is slot 0, so no child's slot is 0).
        let mut by_slot = vec![1u32; n];
        for s in (0..n).rev() {
            let c = first_child[s] as usize;
            if c != 0 {
                by_slot[s] = 1 + by_slot[c].max(by_slot[c + 1]);
            }
        }
        let height = (0..n).map(|i| by_slot[slot[i] as usize]).collect();
        Arc::new(HostTree {
            tree: tree.clone(),
            slot,
            height,
        })
    }

    /// The frontier word of node `i` in a traversal entry: its first child's slot (an internal
    /// node: the entry tests its children), or its own slot with [`ONE_NODE`] (a leaf).
    fn entry_word(&self, i: u32) -> u32 {
        if self.height[i as usize] == 1 {
            self.slot[i as usize] | ONE_NODE
        } else {
            self.slot[i as usize + 1]
        }
    }
}

/// A batch's first traversal level, as the CPU's descent left it.
#[derive(Debug, Default)]
pub(crate) struct HostFront {
    /// Entries `(pair, word of A, word of B, 0)` of the first GPU level (`traverse.wgsl`).
    pub(crate) entries: Vec<[u32; 4]>,
    /// GPU levels the entries need: the deepest remaining descent below any of them.
    pub(crate) levels: u32,
    /// Box tests the CPU made.
    pub(crate) tests: u64,
    /// Levels the CPU descended below the roots.
    pub(crate) steps: u32,
}

/// The first GPU level of `pairs`: with `budget == 0` the roots themselves (the GPU tests
/// them: as many levels as the deepest tree); otherwise the CPU descends every pair tree one
/// level at a time while the level's box tests, over the whole batch, stay within `budget`,
/// and each pair of the front becomes one entry (a pair of leaves itself, any other pair its
/// children). On one thread: split over rayon's two threads on the 2-vCPU host it was no
/// faster (the 64-part checker frame's front took 0.42-1.19 ms against 0.52-0.99 ms on one,
/// 2026-12-02), the pool's threads competing with the software driver's.
pub(crate) fn host_front(pairs: &[BodyPair<'_>], budget: u32) -> HostFront {
    // A pair starts at its roots without a budget, or with a mesh uploaded without its CPU
    // copy (the front was off then).
    let mut fronts: Vec<Option<PairFront<'_>>> = pairs
        .iter()
        .map(|&(a, pa, b, pb)| match (&a.host, &b.host, budget) {
            (_, _, 0) | (None, _, _) | (_, None, _) => None,
            (Some(ha), Some(hb), _) => Some(PairFront::new(&ha.tree, pa, &hb.tree, pb)),
        })
        .collect();
    let mut front = HostFront::default();
    loop {
        let next: Vec<usize> = fronts
            .iter()
            .map(|f| f.as_ref().map_or(0, PairFront::next_tests))
            .collect();
        let total: usize = next.iter().sum();
        if total == 0 || total > budget as usize {
            break;
        }
        for (f, &n) in fronts.iter_mut().zip(&next) {
            if let (Some(f), true) = (f, n > 0) {
                f.step();
            }
        }
        front.steps += 1;
    }
    for (k, (f, &(a, _, b, _))) in fronts.iter().zip(pairs).enumerate() {
        let (Some(f), Some(ha), Some(hb)) = (f, &a.host, &b.host) else {
            front.entries.push([k as u32, ONE_NODE, ONE_NODE, 0]);
            front.levels = front.levels.max(a.depth.max(b.depth));
            continue;
        };
        front.tests += f.box_tests();
        for &(i, j) in f.pairs() {
            front
                .entries
                .push([k as u32, ha.entry_word(i), hb.entry_word(j), 0]);
            let (da, db) = (ha.height[i as usize], hb.height[j as usize]);
            // A pair of leaves is tested again (one level); any other pair's entry tests its
            // children, and its pair tree is as deep as the deeper of its two subtrees.
            let need = if da == 1 && db == 1 {
                1
            } else {
                da.max(db) - 1
            };
            front.levels = front.levels.max(need);
        }
    }
    front
}
