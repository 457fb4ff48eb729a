//! The broad phase: sweep and prune along x over the bodies' world boxes.

use super::Slot;

/// Slot indices sorted by their box's `min.x`, maintained incrementally.
#[derive(Debug, Default)]
pub(super) struct BroadPhase {
    /// Sorted at the end of [`BroadPhase::sort`]; may hold removed or pending slots before it.
    order: Vec<u32>,
    /// Slots added or teleported since the last sort, merged in by the next one.
    pending: Vec<u32>,
    /// A body was removed since the last sort.
    removed: bool,
    /// Scratch: membership of `pending`, by slot.
    mark: Vec<bool>,
}

fn key(slots: &[Slot], i: u32) -> f64 {
    slots[i as usize]
        .body
        .as_ref()
        .map_or(f64::INFINITY, |b| b.aabb.min.x)
}

impl BroadPhase {
    /// A new body in slot `i`.
    pub(super) fn insert(&mut self, i: u32) {
        self.pending.push(i);
    }

    /// A teleported body: taken out of the order and merged back at the next sort (O(1) now).
    pub(super) fn reinsert(&mut self, i: u32) {
        self.pending.push(i);
    }

    /// The body in slot `i` was removed.
    pub(super) fn remove(&mut self, _i: u32) {
        self.removed = true;
    }

    /// Sorts the order by `min.x`: removed and pending slots are taken out (O(n)), the rest is
    /// insertion-sorted (near linear under coherent motion; a full sort when it would take more
    /// than `resort_factor · n` swaps), and the pending slots are sorted and merged in
    /// (O(n + k log k)). Ties are broken by slot index, so the order depends on the boxes only.
    pub(super) fn sort(&mut self, slots: &[Slot], resort_factor: usize) {
        if self.removed || !self.pending.is_empty() {
            self.mark.clear();
            self.mark.resize(slots.len(), false);
            for &i in &self.pending {
                self.mark[i as usize] = true;
            }
            let mark = &self.mark;
            self.order
                .retain(|&i| slots[i as usize].body.is_some() && !mark[i as usize]);
            self.removed = false;
        }
        let less = |x: u32, y: u32| key(slots, x).total_cmp(&key(slots, y)).then(x.cmp(&y));
        let limit = resort_factor.saturating_mul(self.order.len().max(1));
        let mut swaps = 0usize;
        let o = &mut self.order;
        let mut ok = true;
        'outer: for i in 1..o.len() {
            let mut j = i;
            while j > 0 && less(o[j - 1], o[j]).is_gt() {
                o.swap(j - 1, j);
                j -= 1;
                swaps += 1;
                if swaps > limit {
                    ok = false;
                    break 'outer;
                }
            }
        }
        if !ok {
            o.sort_unstable_by(|&x, &y| less(x, y));
        }
        if !self.pending.is_empty() {
            let mut p = std::mem::take(&mut self.pending);
            p.sort_unstable();
            p.dedup();
            p.retain(|&i| slots[i as usize].body.is_some());
            p.sort_unstable_by(|&x, &y| less(x, y));
            let old = std::mem::take(&mut self.order);
            let mut merged = Vec::with_capacity(old.len() + p.len());
            let (mut x, mut y) = (0, 0);
            while x < old.len() && y < p.len() {
                if less(old[x], p[y]).is_le() {
                    merged.push(old[x]);
                    x += 1;
                } else {
                    merged.push(p[y]);
                    y += 1;
                }
            }
            merged.extend_from_slice(&old[x..]);
            merged.extend_from_slice(&p[y..]);
            self.order = merged;
            p.clear();
            self.pending = p;
        }
    }

    /// Pushes `(lo, hi)` slot pairs whose boxes, each grown by `half_margin`, overlap (after a
    /// [`BroadPhase::sort`]).
    pub(super) fn sweep(&self, slots: &[Slot], half_margin: f64, out: &mut Vec<(u32, u32)>) {
        let margin = 2.0 * half_margin;
        let bx = |i: u32| {
            &slots[i as usize]
                .body
                .as_ref()
                .expect("live after sort")
                .aabb
        };
        for (p, &i) in self.order.iter().enumerate() {
            let bi = bx(i);
            for &j in &self.order[p + 1..] {
                let bj = bx(j);
                if bj.min.x - bi.max.x > margin {
                    break;
                }
                if bi.min.y - bj.max.y > margin
                    || bj.min.y - bi.max.y > margin
                    || bi.min.z - bj.max.z > margin
                    || bj.min.z - bi.max.z > margin
                {
                    continue;
                }
                out.push((i.min(j), i.max(j)));
            }
        }
    }
}
