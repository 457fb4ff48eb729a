//! A dynamic tree of axis-aligned boxes, one leaf per body slot: the broad phase's index for
//! the few bodies that leave their grown ("fat") boxes in a step.
//!
//! Built top-down by median splits along the centres' widest axis (O(n log n)); a leaf is
//! inserted next to the node whose box grows least in surface area (the descent of Box2D's
//! dynamic tree, without its rotations) and removed by splicing its sibling into its parent's
//! place. The owner rebuilds the tree once it has been edited about as many times as it has
//! leaves, so its quality cannot drift far from a fresh build's.

use frcd_geom::Aabb;

const NONE: u32 = u32::MAX;

/// Queries [`BoxTree::query_many`] runs side by side.
const LANES: usize = 8;

/// Ancestors a leaf moved in place may grow (see [`BoxTree::move_in_place`]).
pub(super) const MAX_GROWN_LEVELS: usize = 3;

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    parent: u32,
    /// A leaf's slot, or an internal node's first child.
    left: u32,
    /// An internal node's second child; `NONE` marks a leaf.
    right: u32,
}

/// The tree. Slots index [`BoxTree::leaf_of`]; nodes are recycled through a free list, so the
/// memory stays at most twice the number of leaves (plus the largest count ever held).
#[derive(Debug, Default)]
pub(super) struct BoxTree {
    nodes: Vec<Node>,
    free: Vec<u32>,
    root: Option<u32>,
    /// By slot: its leaf node, `NONE` if the slot is not in the tree.
    leaf_of: Vec<u32>,
    /// Leaves inserted or removed since the last build.
    pub(super) edits: usize,
    /// Leaves in the tree.
    pub(super) leaves: usize,
}

/// Half the surface area (the insertion cost's measure); NaN for non-finite boxes, which then
/// loses every comparison and is still placed somewhere.
fn area(b: &Aabb) -> f64 {
    let d = b.max - b.min;
    d.x * d.y + d.y * d.z + d.z * d.x
}

/// Whether `outer` holds `b` (false for NaN bounds).
pub(super) fn holds(outer: &Aabb, b: &Aabb) -> bool {
    outer.min.cmple(b.min).all() && b.max.cmple(outer.max).all()
}

/// The broad phase's test: the boxes are within `margin` of each other on every axis, written
/// as [`super::broad`] writes it so that every path agrees to the last bit.
#[inline]
pub(super) fn within(a: &Aabb, b: &Aabb, margin: f64) -> bool {
    !(b.min.x - a.max.x > margin
        || a.min.x - b.max.x > margin
        || b.min.y - a.max.y > margin
        || a.min.y - b.max.y > margin
        || b.min.z - a.max.z > margin
        || a.min.z - b.max.z > margin)
}

impl BoxTree {
    /// Drops every leaf and builds the tree over `items` (`(box, slot)`; reordered).
    pub(super) fn build(&mut self, items: &mut [(Aabb, u32)], slots: usize) {
        self.nodes.clear();
        self.free.clear();
        self.leaf_of.clear();
        self.leaf_of.resize(slots, NONE);
        self.edits = 0;
        self.leaves = items.len();
        self.nodes.reserve(2 * items.len());
        self.root = if items.is_empty() {
            None
        } else {
            Some(self.build_range(items, NONE))
        };
    }

    fn build_range(&mut self, items: &mut [(Aabb, u32)], parent: u32) -> u32 {
        if let [(b, slot)] = items {
            let at = self.nodes.len() as u32;
            self.nodes.push(Node {
                bounds: *b,
                parent,
                left: *slot,
                right: NONE,
            });
            self.leaf_of[*slot as usize] = at;
            return at;
        }
        let (mut lo, mut hi) = (items[0].0.center(), items[0].0.center());
        for (b, _) in items.iter() {
            lo = lo.min(b.center());
            hi = hi.max(b.center());
        }
        let d = hi - lo;
        let axis = if d.x >= d.y && d.x >= d.z {
            0
        } else if d.y >= d.z {
            1
        } else {
            2
        };
        let mid = items.len() / 2;
        items.select_nth_unstable_by(mid, |a, b| {
            (a.0.min[axis] + a.0.max[axis]).total_cmp(&(b.0.min[axis] + b.0.max[axis]))
        });
        let at = self.nodes.len() as u32;
        self.nodes.push(Node {
            bounds: Aabb::EMPTY,
            parent,
            left: NONE,
            right: NONE,
        });
        let (first, second) = items.split_at_mut(mid);
        let left = self.build_range(first, at);
        let right = self.build_range(second, at);
        let bounds = self.nodes[left as usize]
            .bounds
            .union(&self.nodes[right as usize].bounds);
        self.nodes[at as usize] = Node {
            bounds,
            parent,
            left,
            right,
        };
        at
    }

    fn alloc(&mut self, node: Node) -> u32 {
        match self.free.pop() {
            Some(i) => {
                self.nodes[i as usize] = node;
                i
            }
            None => {
                self.nodes.push(node);
                (self.nodes.len() - 1) as u32
            }
        }
    }

    /// Adds a leaf for `slot` (which must not have one).
    pub(super) fn insert(&mut self, slot: u32, b: Aabb) {
        if self.leaf_of.len() <= slot as usize {
            self.leaf_of.resize(slot as usize + 1, NONE);
        }
        debug_assert_eq!(self.leaf_of[slot as usize], NONE);
        self.edits += 1;
        self.leaves += 1;
        let leaf = self.alloc(Node {
            bounds: b,
            parent: NONE,
            left: slot,
            right: NONE,
        });
        self.leaf_of[slot as usize] = leaf;
        let Some(root) = self.root else {
            self.root = Some(leaf);
            return;
        };
        // Descend to the sibling whose pairing costs least: a new parent's area, plus the
        // growth of every ancestor on the way (Box2D's rule).
        let mut at = root;
        while self.nodes[at as usize].right != NONE {
            let n = self.nodes[at as usize];
            let combined = area(&n.bounds.union(&b));
            let here = 2.0 * combined;
            let inherited = 2.0 * (combined - area(&n.bounds));
            let cost = |c: u32| {
                let cb = &self.nodes[c as usize];
                let grown = area(&cb.bounds.union(&b));
                if cb.right == NONE {
                    grown + inherited
                } else {
                    grown - area(&cb.bounds) + inherited
                }
            };
            let (cl, cr) = (cost(n.left), cost(n.right));
            if here < cl && here < cr {
                break;
            }
            at = if cl <= cr { n.left } else { n.right };
        }
        let sibling = at;
        let old_parent = self.nodes[sibling as usize].parent;
        let bounds = self.nodes[sibling as usize].bounds.union(&b);
        let parent = self.alloc(Node {
            bounds,
            parent: old_parent,
            left: sibling,
            right: leaf,
        });
        self.nodes[sibling as usize].parent = parent;
        self.nodes[leaf as usize].parent = parent;
        if old_parent == NONE {
            self.root = Some(parent);
        } else {
            self.replace_child(old_parent, sibling, parent);
            self.refit_from(old_parent);
        }
    }

    /// Moves `slot`'s leaf (which must exist) to `b` in place when one of its nearest
    /// [`MAX_GROWN_LEVELS`] ancestors already holds `b`: the ancestors below that one grow to
    /// hold it (they never shrink until the next build). False, and nothing changed, when the
    /// move is larger: the caller removes and re-inserts the leaf.
    pub(super) fn move_in_place(&mut self, slot: u32, b: Aabb) -> bool {
        let leaf = self.leaf_of[slot as usize];
        let mut at = self.nodes[leaf as usize].parent;
        let mut levels = 0;
        while at != NONE && !holds(&self.nodes[at as usize].bounds, &b) {
            levels += 1;
            if levels > MAX_GROWN_LEVELS {
                return false;
            }
            at = self.nodes[at as usize].parent;
        }
        if at == NONE && levels > 0 {
            // Only the root would hold it after growing: re-insert instead.
            return false;
        }
        self.edits += 1;
        self.nodes[leaf as usize].bounds = b;
        let mut up = self.nodes[leaf as usize].parent;
        while up != at {
            let n = &mut self.nodes[up as usize];
            n.bounds = n.bounds.union(&b);
            up = n.parent;
        }
        true
    }

    /// Removes `slot`'s leaf, if it has one.
    pub(super) fn remove(&mut self, slot: u32) {
        let Some(&leaf) = self.leaf_of.get(slot as usize) else {
            return;
        };
        if leaf == NONE {
            return;
        }
        self.leaf_of[slot as usize] = NONE;
        self.edits += 1;
        self.leaves -= 1;
        self.free.push(leaf);
        let parent = self.nodes[leaf as usize].parent;
        if parent == NONE {
            self.root = None;
            return;
        }
        let p = self.nodes[parent as usize];
        let sibling = if p.left == leaf { p.right } else { p.left };
        self.free.push(parent);
        self.nodes[sibling as usize].parent = p.parent;
        if p.parent == NONE {
            self.root = Some(sibling);
        } else {
            self.replace_child(p.parent, parent, sibling);
            self.refit_from(p.parent);
        }
    }

    fn replace_child(&mut self, parent: u32, old: u32, new: u32) {
        let p = &mut self.nodes[parent as usize];
        if p.left == old {
            p.left = new;
        } else {
            p.right = new;
        }
    }

    /// Recomputes the boxes from `at` up to the root.
    fn refit_from(&mut self, mut at: u32) {
        while at != NONE {
            let n = self.nodes[at as usize];
            self.nodes[at as usize].bounds = self.nodes[n.left as usize]
                .bounds
                .union(&self.nodes[n.right as usize].bounds);
            at = n.parent;
        }
    }

    /// Calls `found` with the slot of every leaf whose box is [`within`] `margin` of `b`
    /// (`stack` is scratch): one query at a time, the reference for [`BoxTree::query_many`].
    #[cfg(test)]
    pub(super) fn query(
        &self,
        b: &Aabb,
        margin: f64,
        stack: &mut Vec<u32>,
        mut found: impl FnMut(u32),
    ) {
        let Some(root) = self.root else {
            return;
        };
        stack.clear();
        stack.push(root);
        while let Some(at) = stack.pop() {
            let n = &self.nodes[at as usize];
            // A parent's box holds its leaves' boxes, and the test is monotone in the boxes
            // (rounding is monotone), so culling a node never loses a leaf that passes.
            if !within(&n.bounds, b, margin) {
                continue;
            }
            if n.right == NONE {
                found(n.left);
            } else {
                stack.push(n.right);
                stack.push(n.left);
            }
        }
    }

    /// `BoxTree::query` (the tests' reference) for many boxes at once: `found(i, slot)` for
    /// every leaf within `margin` of `boxes[i]`. [`LANES`] queries advance side by side, one
    /// node each in turn, and every node pushed is prefetched: a lone query waits on one cache
    /// miss per level (about 18 levels at 262,144 leaves), these overlap theirs. `stacks` is
    /// scratch.
    pub(super) fn query_many(
        &self,
        boxes: &[Aabb],
        margin: f64,
        stacks: &mut Vec<Vec<u32>>,
        mut found: impl FnMut(usize, u32),
    ) {
        let Some(root) = self.root else {
            return;
        };
        stacks.resize_with(LANES, Vec::new);
        let mut owner = [usize::MAX; LANES];
        let mut next = 0;
        let mut busy = 0;
        loop {
            for (lane, stack) in stacks.iter_mut().enumerate() {
                if stack.is_empty() {
                    if owner[lane] != usize::MAX {
                        owner[lane] = usize::MAX;
                        busy -= 1;
                    }
                    if next == boxes.len() {
                        continue;
                    }
                    owner[lane] = next;
                    next += 1;
                    busy += 1;
                    stack.push(root);
                }
                let q = owner[lane];
                let at = stack.pop().expect("a busy lane has a node");
                let n = &self.nodes[at as usize];
                // As in `query`: culling by a parent's box never loses a leaf that passes.
                if !within(&n.bounds, &boxes[q], margin) {
                    continue;
                }
                if n.right == NONE {
                    found(q, n.left);
                } else {
                    super::broad::prefetch(&self.nodes[n.right as usize]);
                    super::broad::prefetch(&self.nodes[n.left as usize]);
                    stack.push(n.right);
                    stack.push(n.left);
                }
            }
            if busy == 0 && next == boxes.len() {
                return;
            }
        }
    }

    /// Checks the links and that every node's box holds its children's (tests).
    #[cfg(test)]
    pub(super) fn check(&self) -> usize {
        let Some(root) = self.root else {
            return 0;
        };
        let mut leaves = 0;
        let mut stack = vec![root];
        while let Some(at) = stack.pop() {
            let n = self.nodes[at as usize];
            if n.right == NONE {
                assert_eq!(self.leaf_of[n.left as usize], at);
                leaves += 1;
                continue;
            }
            for c in [n.left, n.right] {
                let cn = &self.nodes[c as usize];
                assert_eq!(cn.parent, at);
                if n.bounds.min.is_finite() && n.bounds.max.is_finite() {
                    assert_eq!(n.bounds.union(&cn.bounds), n.bounds);
                }
                stack.push(c);
            }
        }
        assert_eq!(leaves, self.leaves);
        leaves
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use frcd_geom::DVec3;

    fn unit(x: f64, y: f64, z: f64) -> Aabb {
        Aabb::new(DVec3::new(x, y, z), DVec3::new(x + 1.0, y + 1.0, z + 1.0))
    }

    /// Builds, inserts, removes and queries against brute force over a few hundred boxes.
    #[test]
    fn edits_and_queries_match_brute_force() {
        let mut boxes: Vec<Option<Aabb>> = (0..300)
            .map(|i| {
                let f = i as f64;
                Some(unit((f * 7.3) % 20.0, (f * 3.1) % 17.0, (f * 1.7) % 5.0))
            })
            .collect();
        let mut t = BoxTree::default();
        let mut items: Vec<(Aabb, u32)> = boxes[..200]
            .iter()
            .enumerate()
            .map(|(i, b)| (b.unwrap(), i as u32))
            .collect();
        t.build(&mut items, 300);
        for b in &mut boxes[200..] {
            *b = None;
        }
        assert_eq!(t.check(), 200);
        for i in 200..300u32 {
            let f = i as f64;
            let b = unit((f * 5.9) % 23.0, (f * 2.3) % 11.0, (f * 0.7) % 6.0);
            t.insert(i, b);
            boxes[i as usize] = Some(b);
        }
        for i in (0..300u32).step_by(3) {
            t.remove(i);
            boxes[i as usize] = None;
        }
        t.remove(0); // twice: nothing
        assert_eq!(t.check(), 200);
        // Small moves in place (the near ancestors grow), large ones refused.
        let (mut moved, mut refused) = (0, 0);
        for i in (1..300u32).step_by(3) {
            let Some(b) = boxes[i as usize] else { continue };
            let shift = if i % 2 == 0 { 0.05 } else { 9.0 };
            let to = Aabb::new(b.min + DVec3::splat(shift), b.max + DVec3::splat(shift));
            if t.move_in_place(i, to) {
                boxes[i as usize] = Some(to);
                moved += 1;
            } else {
                refused += 1;
            }
        }
        assert!(
            moved > 10 && refused > 10,
            "{moved} moved, {refused} refused"
        );
        assert_eq!(t.check(), 200);
        let mut stack = Vec::new();
        for q in 0..40 {
            let f = q as f64;
            let qb = Aabb::new(
                DVec3::new(f % 19.0, (f * 1.3) % 15.0, 1.0),
                DVec3::new(f % 19.0 + 2.5, (f * 1.3) % 15.0 + 0.5, 2.0),
            );
            for margin in [0.0, 0.7] {
                let mut got = Vec::new();
                t.query(&qb, margin, &mut stack, |s| got.push(s));
                got.sort_unstable();
                let want: Vec<u32> = (0..300u32)
                    .filter(|&i| boxes[i as usize].is_some_and(|b| within(&b, &qb, margin)))
                    .collect();
                assert_eq!(got, want, "query {q}, margin {margin}");
            }
        }
        for i in 0..300u32 {
            t.remove(i);
        }
        assert_eq!(t.check(), 0);
        assert!(t.root.is_none());
    }

    /// A tree grown from nothing by insertions (pairings with leaves and, for a few large
    /// boxes, with whole subtrees), emptied again and re-grown, against brute force.
    #[test]
    fn a_tree_grown_by_insertions_matches_brute_force() {
        let mut t = BoxTree::default();
        let mut boxes: Vec<Option<Aabb>> = vec![None; 400];
        let mut stack = Vec::new();
        for round in 0..2 {
            for i in 0..400u32 {
                let f = (i + round * 7) as f64;
                let b = if i % 50 == 7 {
                    Aabb::new(DVec3::splat(-1.0), DVec3::new(30.0, 2.0, 3.0))
                } else {
                    unit((f * 4.1) % 29.0, (f * 2.7) % 13.0, (f * 0.9) % 7.0)
                };
                t.insert(i, b);
                boxes[i as usize] = Some(b);
                if i % 5 == 3 {
                    t.remove(i - 2);
                    boxes[i as usize - 2] = None;
                }
                if i % 97 == 0 {
                    t.check();
                }
            }
            t.check();
            for q in 0..30 {
                let f = q as f64;
                let qb = unit((f * 3.3) % 29.0, (f * 1.9) % 13.0, (f * 0.7) % 7.0);
                let mut got = Vec::new();
                t.query(&qb, 0.2, &mut stack, |s| got.push(s));
                got.sort_unstable();
                let want: Vec<u32> = (0..400u32)
                    .filter(|&i| boxes[i as usize].is_some_and(|b| within(&b, &qb, 0.2)))
                    .collect();
                assert_eq!(got, want, "round {round}, query {q}");
            }
            for i in 0..400u32 {
                t.remove(i);
                boxes[i as usize] = None;
            }
            assert_eq!(t.check(), 0);
            assert!(t.root.is_none());
        }
    }

    /// Many queries side by side find what each finds alone (more queries than lanes, some
    /// finding nothing, one tree of a single leaf).
    #[test]
    fn queries_side_by_side_equal_one_at_a_time() {
        let mut t = BoxTree::default();
        let mut items: Vec<(Aabb, u32)> = (0..500u32)
            .map(|i| {
                let f = i as f64;
                (unit((f * 6.1) % 31.0, (f * 2.9) % 17.0, (f * 1.3) % 9.0), i)
            })
            .collect();
        t.build(&mut items, 500);
        let queries: Vec<Aabb> = (0..37)
            .map(|q| {
                let f = q as f64;
                unit((f * 4.7) % 40.0, (f * 3.1) % 20.0, (f * 0.3) % 9.0)
            })
            .collect();
        let (mut stacks, mut stack) = (Vec::new(), Vec::new());
        let mut many = Vec::new();
        t.query_many(&queries, 0.1, &mut stacks, |q, s| many.push((q, s)));
        many.sort_unstable();
        let mut one = Vec::new();
        for (q, b) in queries.iter().enumerate() {
            t.query(b, 0.1, &mut stack, |s| one.push((q, s)));
        }
        one.sort_unstable();
        assert_eq!(many, one);
        assert!(one.len() > 20, "the queries find boxes: {}", one.len());
        let mut single = BoxTree::default();
        single.build(&mut [(unit(0.0, 0.0, 0.0), 3)], 4);
        let mut got = Vec::new();
        single.query_many(&queries[..2], 0.0, &mut stacks, |q, s| got.push((q, s)));
        assert_eq!(got, vec![(0, 3)]);
    }

    /// Non-finite boxes are placed and found without a panic or an endless descent.
    #[test]
    fn non_finite_boxes_do_not_panic() {
        let mut t = BoxTree::default();
        let nan = Aabb::new(DVec3::splat(f64::NAN), DVec3::splat(f64::NAN));
        let huge = Aabb::new(DVec3::splat(f64::NEG_INFINITY), DVec3::splat(f64::INFINITY));
        let mut items = vec![(unit(0.0, 0.0, 0.0), 0), (nan, 1), (huge, 2)];
        t.build(&mut items, 3);
        t.insert(3, nan);
        t.insert(4, unit(0.5, 0.0, 0.0));
        let mut got = Vec::new();
        t.query(&unit(0.2, 0.0, 0.0), 0.0, &mut Vec::new(), |s| got.push(s));
        got.sort_unstable();
        assert!(got.contains(&0) && got.contains(&4) && got.contains(&2));
        t.remove(1);
        t.remove(3);
        t.check();
    }
}
