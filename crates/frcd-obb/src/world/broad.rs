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
    /// last [`BroadPhase::sort`]. Sweeps the sorted array, unless a sample says the sweep would
    /// compare each box with more than [`GRID_FROM`] others (bodies filling a volume: a box
    /// shares its range along any one axis with about n^(2/3) others); then a uniform grid.
    pub(super) fn sweep(&self, half_margin: f64, out: &mut Vec<(u32, u32)>) {
        let margin = 2.0 * half_margin;
        let s = &self.swept;
        if s.len() >= GRID_MIN_BODIES
            && sampled_sweep_length(s, margin) > GRID_FROM
            && grid_pairs(s, margin, out)
        {
            return;
        }
        for (p, bi) in s.iter().enumerate() {
            for bj in &s[p + 1..] {
                if bj.lo - bi.hi > margin {
                    break;
                }
                if apart_across(bi, bj, margin) {
                    continue;
                }
                out.push((bi.slot.min(bj.slot), bi.slot.max(bj.slot)));
            }
        }
    }
}

/// Boxes the sweep may compare each box with, on average, before the grid takes over.
const GRID_FROM: f64 = 24.0;
/// Below this many bodies the sweep is always cheap enough.
const GRID_MIN_BODIES: usize = 1024;
/// Boxes sampled to estimate the sweep's length.
const SAMPLES: usize = 64;

/// Whether `a` and `b` are more than `margin` apart along one of the two axes across the sweep.
fn apart_across(a: &Swept, b: &Swept, margin: f64) -> bool {
    a.rest[0] - b.rest[1] > margin
        || b.rest[0] - a.rest[1] > margin
        || a.rest[2] - b.rest[3] > margin
        || b.rest[2] - a.rest[3] > margin
}

/// The mean number of boxes the sweep compares a box with, over evenly spaced samples (a binary
/// search each: the sweep of box `p` stops at the first box starting more than `margin` past
/// its end).
fn sampled_sweep_length(s: &[Swept], margin: f64) -> f64 {
    let step = (s.len() / SAMPLES).max(1);
    let mut total = 0usize;
    let mut n = 0usize;
    for p in (0..s.len()).step_by(step) {
        let bi = &s[p];
        let end = p + 1 + s[p + 1..].partition_point(|bj| bj.lo - bi.hi <= margin);
        total += end - p - 1;
        n += 1;
    }
    total as f64 / n.max(1) as f64
}

/// Whether two boxes are within `margin` of each other on every axis: the sweep's test,
/// written the same way so that both paths give the same pairs to the last bit.
fn within(a: &Swept, b: &Swept, margin: f64) -> bool {
    !(b.lo - a.hi > margin || a.lo - b.hi > margin || apart_across(a, b, margin))
}

/// The overlapping pairs through a uniform grid. Each box covers the cells of
/// `[lower, upper + margin]` on every axis (the upper bound rounded outward, so a box covers
/// every point `x` with `x - upper <= margin` as [`within`] computes it); the entries are sorted
/// by cell, and a pair that passes [`within`] is reported in the one cell holding the largest of
/// its lower corners (both boxes cover that point, so the pair is found there and only there).
/// Cells are twice the median box's largest covered side; a box covering more than
/// [`GRID_SPAN`] cells along an axis is tested against every other box instead. False (nothing
/// pushed) where no grid can be laid out or it would not pay (non-finite boxes, more than 2^21
/// cells along an axis, more than [`GRID_ENTRIES`] entries per box, many long boxes): the
/// caller sweeps.
fn grid_pairs(s: &[Swept], margin: f64, out: &mut Vec<(u32, u32)>) -> bool {
    let up = |x: f64| {
        let g = x + margin;
        g + (g.abs() + margin) * (4.0 * f64::EPSILON)
    };
    let cover = |b: &Swept| -> ([f64; 3], [f64; 3]) {
        (
            [b.lo, b.rest[0], b.rest[2]],
            [up(b.hi), up(b.rest[1]), up(b.rest[3])],
        )
    };
    let mut sides: Vec<f64> = s
        .iter()
        .map(|b| {
            let (lo, hi) = cover(b);
            (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max)
        })
        .collect();
    let mid = sides.len() / 2;
    let (_, median, _) = sides.select_nth_unstable_by(mid, f64::total_cmp);
    let h = 2.0 * *median;
    let mut origin = [f64::INFINITY; 3];
    let mut top = [f64::NEG_INFINITY; 3];
    for b in s {
        let (lo, hi) = cover(b);
        for k in 0..3 {
            origin[k] = origin[k].min(lo[k]);
            top[k] = top[k].max(hi[k]);
        }
    }
    let cells = |k: usize| ((top[k] - origin[k]) / h).floor();
    // NaN fails every comparison: a non-finite box or size refuses the grid.
    let fits = |k: usize| cells(k) < (1u64 << 21) as f64;
    if !(h.is_finite() && h > 0.0 && (0..3).all(fits)) {
        return false;
    }
    // Monotone in x, so a box's cell range holds the cell of every point it covers.
    let cell = |x: f64, k: usize| ((x - origin[k]) / h).floor() as u64;
    let key = |c: [u64; 3]| (c[0] << 42) | (c[1] << 21) | c[2];
    // First the sizes: a grid that would need more than `GRID_ENTRIES` entries per box, or
    // more boxes in the all-pairs list than `s.len() / 64` (at least 64), is refused, so the
    // memory stays linear and the long boxes' pass stays small; the sweep runs instead.
    let ranges = |b: &Swept| {
        let (lo, hi) = cover(b);
        (
            [cell(lo[0], 0), cell(lo[1], 1), cell(lo[2], 2)],
            [cell(hi[0], 0), cell(hi[1], 1), cell(hi[2], 2)],
        )
    };
    // Long boxes, and inverted ones (`min > max`, which `overlapping_boxes` may be given and
    // `within` still pairs), go to the all-pairs list.
    let listed =
        |c0: [u64; 3], c1: [u64; 3]| (0..3).any(|k| c1[k] < c0[k] || c1[k] - c0[k] >= GRID_SPAN);
    let mut big: Vec<u32> = Vec::new();
    let mut total = 0u64;
    for (i, b) in s.iter().enumerate() {
        let (c0, c1) = ranges(b);
        if listed(c0, c1) {
            big.push(i as u32);
        } else {
            total += (0..3).map(|k| c1[k] - c0[k] + 1).product::<u64>();
        }
    }
    if total > GRID_ENTRIES * s.len() as u64 || big.len() > (s.len() / 64).max(64) {
        return false;
    }
    let mut entries: Vec<(u64, u32)> = Vec::with_capacity(total as usize);
    for (i, b) in s.iter().enumerate() {
        let (c0, c1) = ranges(b);
        if listed(c0, c1) {
            continue;
        }
        for x in c0[0]..=c1[0] {
            for y in c0[1]..=c1[1] {
                for z in c0[2]..=c1[2] {
                    entries.push((key([x, y, z]), i as u32));
                }
            }
        }
    }
    entries.sort_unstable();
    let mut start = 0;
    while start < entries.len() {
        let k = entries[start].0;
        let end = start + entries[start..].partition_point(|e| e.0 == k);
        let run = &entries[start..end];
        for (x, &(_, i)) in run.iter().enumerate() {
            let bi = &s[i as usize];
            for &(_, j) in &run[x + 1..] {
                let bj = &s[j as usize];
                if !within(bi, bj, margin) {
                    continue;
                }
                let corner = [
                    cell(bi.lo.max(bj.lo), 0),
                    cell(bi.rest[0].max(bj.rest[0]), 1),
                    cell(bi.rest[2].max(bj.rest[2]), 2),
                ];
                if key(corner) == k {
                    out.push((bi.slot.min(bj.slot), bi.slot.max(bj.slot)));
                }
            }
        }
        start = end;
    }
    // Boxes too large for the grid: against every other box (a pair of two of them once).
    for (x, &b) in big.iter().enumerate() {
        let bi = &s[b as usize];
        for (j, bj) in s.iter().enumerate() {
            let other_big = big.binary_search(&(j as u32));
            if j == b as usize || other_big.is_ok_and(|y| y < x) {
                continue;
            }
            if within(bi, bj, margin) {
                out.push((bi.slot.min(bj.slot), bi.slot.max(bj.slot)));
            }
        }
    }
    true
}

/// Cells a box may cover along one axis before it leaves the grid for the all-pairs list.
const GRID_SPAN: u64 = 4;
/// Grid entries per box above which the grid is refused (memory stays linear in the boxes).
const GRID_ENTRIES: u64 = 16;

/// Every pair of boxes within `margin` of each other on every axis (`a.min - b.max <= margin`
/// and `b.min - a.max <= margin`, computed as written), as index pairs `(i, j)`, `i < j`,
/// sorted: the [`World`](crate::World)'s broad phase on plain boxes, for a caller that keeps
/// its own bodies. The boxes are sorted along the axis their centres spread most and swept,
/// or laid on a uniform grid where the sweep would be long (1,024 boxes or more filling a
/// volume). Non-finite boxes give unspecified pairs (never a panic).
///
/// ```
/// use frcd_geom::{Aabb, DVec3};
/// let unit = |x: f64, y: f64| Aabb::new(DVec3::new(x, y, 0.0), DVec3::new(x + 1.0, y + 1.0, 1.0));
/// let boxes = [unit(0.0, 0.0), unit(5.0, 0.0), unit(0.5, 0.5), unit(1.2, 0.0)];
/// assert_eq!(frcd_obb::overlapping_boxes(&boxes, 0.0), vec![(0, 2), (2, 3)]);
/// assert_eq!(frcd_obb::overlapping_boxes(&boxes, 0.25), vec![(0, 2), (0, 3), (2, 3)]);
/// ```
pub fn overlapping_boxes(boxes: &[Aabb], margin: f64) -> Vec<(u32, u32)> {
    let tagged: Vec<(Aabb, u32)> = boxes
        .iter()
        .enumerate()
        .map(|(i, b)| (*b, i as u32))
        .collect();
    let axis = sweep_axis(&tagged, 0);
    let mut swept: Vec<Swept> = tagged
        .iter()
        .map(|(b, i)| Swept::new(b, *i, axis))
        .collect();
    swept.sort_unstable_by(Swept::cmp);
    let phase = BroadPhase {
        swept,
        axis,
        ..BroadPhase::default()
    };
    let mut out = Vec::new();
    phase.sweep(margin.max(0.0) * 0.5, &mut out);
    out.sort_unstable();
    out
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
    let var = frcd_geom::centre_variance(boxes.iter().map(|(b, _)| b));
    let best = (1..3).fold(0, |best, a| if var[a] > var[best] { a } else { best });
    if var[best] > AXIS_SWITCH * var[current] {
        best
    } else {
        current
    }
}
