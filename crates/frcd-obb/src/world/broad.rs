//! The broad phase: sweep and prune over the bodies' world boxes, along the axis their centres
//! spread most, on a contiguous copy of the boxes.

use super::Slot;
use frcd_geom::Aabb;

/// A body's box as the sweep reads it: its extent along the sweep axis, then the other two
/// axes' bounds, and its slot.
#[derive(Clone, Copy, Debug)]
struct Swept {
    lo: f64,
    hi: f64,
    /// `[min, max]` of the next axis, then of the one after it.
    rest: [f64; 4],
    slot: u32,
}

impl Swept {
    fn new(b: &Aabb, slot: u32, axis: usize) -> Self {
        let (a1, a2) = ((axis + 1) % 3, (axis + 2) % 3);
        Self {
            lo: b.min[axis],
            hi: b.max[axis],
            rest: [b.min[a1], b.max[a1], b.min[a2], b.max[a2]],
            slot,
        }
    }

    /// The sort order: by the lower bound along the axis, ties by slot (so the order depends on
    /// the boxes only).
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.lo
            .total_cmp(&other.lo)
            .then(self.slot.cmp(&other.slot))
    }
}

/// The bodies' boxes sorted along the sweep axis, maintained incrementally.
///
/// Why a copy: the sweep compares each box with every box that shares its range along the
/// axis, and reading those through the world's slots (a `Body` each, a few hundred bytes
/// apart) cost a cache miss per comparison. 65,536 unit boxes in a cube took 225 ms per step
/// that way; see `benches/benches/world.rs` (`world/broad`) for the figures now.
#[derive(Debug, Default)]
pub(super) struct BroadPhase {
    /// Sorted at the end of [`BroadPhase::sort`] (live slots only).
    swept: Vec<Swept>,
    /// Slots added or teleported since the last sort, merged in by the next one.
    pending: Vec<u32>,
    /// The sweep axis (0 = x, 1 = y, 2 = z).
    axis: usize,
    /// Scratch: membership of `pending`, by slot.
    mark: Vec<bool>,
    /// Scratch: the boxes of the last order's live slots, then of the pending ones.
    boxes: Vec<(Aabb, u32)>,
}

/// A new axis is taken only when the centres spread this many times more along it (by
/// variance) than along the current one: a scene near the tie does not re-sort every step.
const AXIS_SWITCH: f64 = 2.0;

impl BroadPhase {
    /// A new body in slot `i`.
    pub(super) fn insert(&mut self, i: u32) {
        self.pending.push(i);
    }

    /// A teleported body: taken out of the order and merged back at the next sort (O(1) now).
    pub(super) fn reinsert(&mut self, i: u32) {
        self.pending.push(i);
    }

    /// The body in slot `i` was removed: the next sort drops it (it re-reads every slot).
    pub(super) fn remove(&mut self, _i: u32) {}

    /// Re-reads every box and sorts them along the sweep axis: removed and pending slots are
    /// taken out (O(n)), the axis is re-chosen (the centres' largest variance, with
    /// hysteresis), the rest is insertion-sorted (near linear under coherent motion; a full
    /// sort when it would take more than `resort_factor · n` swaps or the axis changed), and the
    /// pending slots are sorted and merged in (O(n + k log k)).
    pub(super) fn sort(&mut self, slots: &[Slot], resort_factor: usize) {
        let aabb = |i: u32| slots[i as usize].body.as_ref().map(|b| b.aabb);
        self.mark.clear();
        self.mark.resize(slots.len(), false);
        let mut pending = std::mem::take(&mut self.pending);
        pending.sort_unstable();
        pending.dedup();
        for &i in &pending {
            self.mark[i as usize] = true;
        }
        // One pass over the slots in the last order (the only scattered reads of a step).
        self.boxes.clear();
        for s in &self.swept {
            if self.mark[s.slot as usize] {
                continue;
            }
            if let Some(b) = aabb(s.slot) {
                self.boxes.push((b, s.slot));
            }
        }
        let kept = self.boxes.len();
        for &i in &pending {
            if let Some(b) = aabb(i) {
                self.boxes.push((b, i));
            }
        }
        let old_axis = self.axis;
        self.axis = sweep_axis(&self.boxes, self.axis);
        let axis = self.axis;
        self.swept.clear();
        self.swept.extend(
            self.boxes[..kept]
                .iter()
                .map(|(b, i)| Swept::new(b, *i, axis)),
        );
        let limit = resort_factor.saturating_mul(self.swept.len().max(1));
        if axis != old_axis || !insertion_sort(&mut self.swept, limit) {
            self.swept.sort_unstable_by(Swept::cmp);
        }
        if kept < self.boxes.len() {
            let mut p: Vec<Swept> = self.boxes[kept..]
                .iter()
                .map(|(b, i)| Swept::new(b, *i, axis))
                .collect();
            p.sort_unstable_by(Swept::cmp);
            let old = std::mem::take(&mut self.swept);
            let mut merged = Vec::with_capacity(old.len() + p.len());
            let (mut x, mut y) = (0, 0);
            while x < old.len() && y < p.len() {
                if old[x].cmp(&p[y]).is_le() {
                    merged.push(old[x]);
                    x += 1;
                } else {
                    merged.push(p[y]);
                    y += 1;
                }
            }
            merged.extend_from_slice(&old[x..]);
            merged.extend_from_slice(&p[y..]);
            self.swept = merged;
        }
        pending.clear();
        self.pending = pending;
    }

    /// Pushes `(lo, hi)` slot pairs whose boxes, each grown by `half_margin`, overlap, as of the
    /// last [`BroadPhase::sort`].
    pub(super) fn sweep(&self, half_margin: f64, out: &mut Vec<(u32, u32)>) {
        let margin = 2.0 * half_margin;
        let s = &self.swept;
        for (p, bi) in s.iter().enumerate() {
            for bj in &s[p + 1..] {
                if bj.lo - bi.hi > margin {
                    break;
                }
                if bi.rest[0] - bj.rest[1] > margin
                    || bj.rest[0] - bi.rest[1] > margin
                    || bi.rest[2] - bj.rest[3] > margin
                    || bj.rest[2] - bi.rest[3] > margin
                {
                    continue;
                }
                out.push((bi.slot.min(bj.slot), bi.slot.max(bj.slot)));
            }
        }
    }
}

/// Insertion sort by [`Swept::cmp`]; false (order unspecified) once it exceeds `limit` swaps.
fn insertion_sort(v: &mut [Swept], limit: usize) -> bool {
    let mut swaps = 0usize;
    for i in 1..v.len() {
        let mut j = i;
        while j > 0 && v[j - 1].cmp(&v[j]).is_gt() {
            v.swap(j - 1, j);
            j -= 1;
            swaps += 1;
            if swaps > limit {
                return false;
            }
        }
    }
    true
}

/// The axis along which the box centres spread most (by variance), keeping `current` unless
/// another spreads [`AXIS_SWITCH`] times more. Non-finite boxes are skipped.
fn sweep_axis(boxes: &[(Aabb, u32)], current: usize) -> usize {
    let mut n = 0.0f64;
    let mut sum = [0.0f64; 3];
    let mut sq = [0.0f64; 3];
    // About the first centre, so that a scene far from the origin does not cancel.
    let origin = boxes
        .iter()
        .map(|(b, _)| (b.min + b.max) * 0.5)
        .find(|c| c.is_finite())
        .unwrap_or_default();
    for (b, _) in boxes {
        let c = (b.min + b.max) * 0.5 - origin;
        if !c.is_finite() {
            continue;
        }
        n += 1.0;
        for (a, v) in c.to_array().into_iter().enumerate() {
            sum[a] += v;
            sq[a] += v * v;
        }
    }
    if n < 2.0 {
        return current;
    }
    let var = |a: usize| (sq[a] / n - (sum[a] / n).powi(2)).max(0.0);
    let best = (0..3)
        .max_by(|&a, &b| var(a).total_cmp(&var(b)))
        .unwrap_or(current);
    if var(best) > AXIS_SWITCH * var(current) {
        best
    } else {
        current
    }
}
