//! The top of a pair traversal, breadth first, for an engine that finishes it elsewhere.

use super::{Ctx, TopVolume};
use crate::tree::ObbTree;
use crate::wide::{ALanes, separation4};
use frcd_geom::Pose;
use frcd_tritri::Method;

/// The node pairs of two trees whose boxes overlap, one level of the pair tree at a time: the
/// top of a traversal that another engine finishes (a GPU, whose first levels hold too few
/// pairs to be worth a dispatch each).
///
/// The pair tree descends both trees at once where both nodes are internal; a leaf stays as it
/// is while the other side descends, and a pair of two leaves stays in the front unchanged.
/// The boxes are tested as [`crate::collide`] tests them (the bodies' top volume, then the
/// certified separating-axis test on the tree's boxes): rounding can keep a pair of boxes that
/// are apart, never drop one that overlaps. So at every step each touching triangle pair of
/// the two meshes lies below exactly one pair of the front.
///
/// ```
/// use frcd_obb::{BuildOptions, ObbTree, PairFront};
/// use frcd_geom::{shapes, DVec3, Pose};
/// let t = ObbTree::build(&shapes::icosphere(1.0, 3), &BuildOptions::default());
/// let (p, q) = (Pose::IDENTITY, Pose::from_translation(DVec3::X * 1.5));
/// let mut front = PairFront::new(&t, &p, &t, &q);
/// assert_eq!(front.pairs(), &[(0, 0)]);
/// while front.next_tests() > 0 && front.next_tests() <= 4096 {
///     front.step();
/// }
/// assert!(front.steps() > 0 && !front.pairs().is_empty());
/// // Apart bodies have an empty front from the start.
/// let far = Pose::from_translation(DVec3::X * 5.0);
/// assert!(PairFront::new(&t, &p, &t, &far).pairs().is_empty());
/// ```
pub struct PairFront<'a> {
    ctx: Ctx<'a>,
    pairs: Vec<(u32, u32)>,
    next: Vec<(u32, u32)>,
    /// The child pairs one step tests.
    tests: Vec<(u32, u32)>,
    steps: u32,
}

impl std::fmt::Debug for PairFront<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PairFront")
            .field("pairs", &self.pairs.len())
            .field("steps", &self.steps)
            .finish()
    }
}

impl<'a> PairFront<'a> {
    /// The front at the roots: `[(0, 0)]` when the root boxes overlap (after the bodies' top
    /// volume), else empty.
    pub fn new(a: &'a ObbTree, pose_a: &Pose, b: &'a ObbTree, pose_b: &Pose) -> Self {
        let mut ctx = Ctx::new(a, pose_a, b, pose_b, Method::default());
        let mut pairs = Vec::new();
        if !ctx.top_rejects(TopVolume::Hybrid) {
            let placed = ctx.place(0);
            if ctx.separation(0, &placed).is_none() {
                pairs.push((0, 0));
            }
        }
        PairFront {
            ctx,
            pairs,
            next: Vec::new(),
            tests: Vec::new(),
            steps: 0,
        }
    }

    /// The front's node pairs `(node of A, node of B)`, in a deterministic order.
    pub fn pairs(&self) -> &[(u32, u32)] {
        &self.pairs
    }

    /// Steps taken below the roots.
    pub fn steps(&self) -> u32 {
        self.steps
    }

    /// Box tests made so far (the roots' included; the top volume's are not box tests).
    pub fn box_tests(&self) -> u64 {
        self.ctx.counters.box_tests
    }

    /// Box tests the next [`PairFront::step`] makes: four per pair of internal nodes, two per
    /// pair of a leaf and an internal node, none for a pair of leaves (0: the front is final).
    pub fn next_tests(&self) -> usize {
        let (a, b) = (&self.ctx.a.nodes, &self.ctx.b.nodes);
        self.pairs
            .iter()
            .map(|&(i, j)| {
                let k = |leaf: bool| if leaf { 1 } else { 2 };
                let (la, lb) = (a[i as usize].is_leaf(), b[j as usize].is_leaf());
                if la && lb { 0 } else { k(la) * k(lb) }
            })
            .sum()
    }

    /// One level down: every pair with an internal node is replaced by its child pairs whose
    /// boxes overlap; pairs of two leaves stay.
    pub fn step(&mut self) {
        let (a, b) = (self.ctx.a, self.ctx.b);
        let children = |t: &ObbTree, i: u32| -> ([u32; 2], usize) {
            let n = &t.nodes[i as usize];
            if n.is_leaf() {
                ([i, i], 1)
            } else {
                ([i + 1, n.right()], 2)
            }
        };
        self.next.clear();
        self.tests.clear();
        for &(i, j) in &self.pairs {
            let ((ca, na), (cb, nb)) = (children(a, i), children(b, j));
            if na == 1 && nb == 1 {
                self.next.push((i, j));
                continue;
            }
            for &y in &cb[..nb] {
                for &x in &ca[..na] {
                    self.tests.push((x, y));
                }
            }
        }
        match self.ctx.sat32 {
            // Four pairs at a time in f32 lanes (the wide traversal's certified test), where
            // the query's magnitudes fit f32.
            Some(sat) => {
                for chunk in self.tests.chunks(4) {
                    let n = chunk.len();
                    let (mut ia, mut ib) = ([0u32; 4], [0u32; 4]);
                    for (k, &(x, y)) in chunk.iter().enumerate() {
                        (ia[k], ib[k]) = (x, y);
                    }
                    let lanes_a = ALanes::gather(&a.nodes, &ia, n);
                    let lanes_b = sat.place_lanes(&b.nodes, &ib, n);
                    let m = separation4(&lanes_a, &lanes_b, sat.s(), (1 << n) - 1);
                    self.ctx.counters.box_tests += n as u64;
                    for (k, &pair) in chunk.iter().enumerate() {
                        // Not `m <= 0`: a NaN margin keeps the pair too.
                        #[allow(clippy::neg_cmp_op_on_partial_ord)]
                        if !(m.0[k] > 0.0) {
                            self.next.push(pair);
                        }
                    }
                }
            }
            None => {
                for &(x, y) in &self.tests {
                    let placed = self.ctx.place(y);
                    if self.ctx.separation(x, &placed).is_none() {
                        self.next.push((x, y));
                    }
                }
            }
        }
        std::mem::swap(&mut self.pairs, &mut self.next);
        self.steps += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BuildOptions, Mode, Request, collide};
    use frcd_geom::{DQuat, DVec3, shapes};

    /// Every touching triangle pair of `collide` lies below exactly one pair of the front, at
    /// every step, down to the leaves, with the f32 lanes' test and with the f64 one (queries
    /// whose magnitudes do not fit f32), which keep the same pairs or nearly.
    #[test]
    fn every_touching_pair_lies_below_exactly_one_front_pair() {
        use crate::query::traverse::{Traversal, with_traversal};
        let wide = with_traversal(Traversal::Wide, front_holds_every_touching_pair);
        let binary = with_traversal(Traversal::Binary, front_holds_every_touching_pair);
        assert!(
            wide.1 && !binary.1,
            "the f32 lanes ran in the wide traversal only"
        );
        // Both tests are conservative and nearly tight: fronts of about the same size.
        let (w, b) = (wide.0 as f64, binary.0 as f64);
        assert!(
            (w - b).abs() <= 0.1 * w.max(b),
            "{w} against {b} front pairs"
        );
    }

    /// The check of [`every_touching_pair_lies_below_exactly_one_front_pair`] under this
    /// thread's traversal: the front's pairs summed over its steps, and whether it tested in
    /// f32 lanes.
    fn front_holds_every_touching_pair() -> (usize, bool) {
        let a = ObbTree::build(&shapes::icosphere(1.0, 3), &BuildOptions::default());
        let b = ObbTree::build(
            &shapes::torus(0.8, 0.3, 24, 12).expect("valid torus"),
            &BuildOptions::default(),
        );
        let all = Request {
            mode: Mode::AllPairs,
            ..Request::default()
        };
        // The leaf (index into the tree's nodes) holding each triangle.
        let leaf_of = |t: &ObbTree| {
            let mut of = vec![0u32; t.triangle_count()];
            for i in 0..t.node_count() as u32 {
                let n = t.node(i);
                if n.is_leaf() {
                    for &tri in &t.leaf_triangles()[n.first as usize..][..n.count as usize] {
                        of[tri as usize] = i;
                    }
                }
            }
            of
        };
        let (la, lb) = (leaf_of(&a), leaf_of(&b));
        // Node i lies below node top (both trees are depth first: a subtree is a range).
        let end = |t: &ObbTree, i: u32| {
            let mut e = i;
            while !t.node(e).is_leaf() {
                e = t.node(e).right;
            }
            e
        };
        let below = |t: &ObbTree, top: u32, i: u32| top <= i && i <= end(t, top);
        let (pa, pb) = (
            Pose::IDENTITY,
            Pose::new(DVec3::new(0.7, 0.2, 0.1), DQuat::from_rotation_x(0.4)),
        );
        let want = collide(&a, &pa, &b, &pb, &all).pairs;
        assert!(!want.is_empty());
        let mut front = PairFront::new(&a, &pa, &b, &pb);
        let lanes = front.ctx.sat32.is_some();
        let mut sizes = 0;
        loop {
            sizes += front.pairs().len();
            for &(ta, tb) in &want {
                let holders = front
                    .pairs()
                    .iter()
                    .filter(|&&(i, j)| {
                        below(&a, i, la[ta as usize]) && below(&b, j, lb[tb as usize])
                    })
                    .count();
                assert_eq!(holders, 1, "pair ({ta}, {tb}) at step {}", front.steps());
            }
            if front.next_tests() == 0 {
                break;
            }
            let (tests, before) = (front.next_tests() as u64, front.box_tests());
            front.step();
            assert_eq!(front.box_tests() - before, tests);
        }
        // Down to the leaves: only leaf pairs are left.
        assert!(
            front
                .pairs()
                .iter()
                .all(|&(i, j)| a.node(i).is_leaf() && b.node(j).is_leaf())
        );
        (sizes, lanes)
    }
}
