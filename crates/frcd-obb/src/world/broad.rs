//! The broad phase: candidate pairs of grown boxes kept from step to step, found afresh by sweep
//! and prune (or a uniform grid) when many bodies move far.

use super::boxtree::{BoxTree, holds, within};
use frcd_geom::{Aabb, DVec3};

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

/// The broad phase of a [`World`](crate::World): candidate pairs kept from step to step over
/// grown ("fat") boxes.
///
/// Each body's box is kept grown by `slack` times its largest side, and the pairs of fat boxes
/// within the margin are the candidates. A step filters the candidates with the bodies' own
/// boxes (the exact test, so the answer is every pair within the margin, and only those: a fat
/// box holds its body's box, and the test is monotone in the boxes). Only a body that leaves
/// its fat box (or is added or removed) changes the candidates: it is re-inserted in a dynamic
/// [`BoxTree`] and queried against it. When more than an eighth of the bodies leave in one
/// step (incoherent motion, a new margin, the first step), every fat box is re-grown and the
/// candidates are found afresh by a sweep along the centres' widest axis, or by a uniform grid
/// where that sweep would be long ([`box_pairs`]).
///
/// Why: re-finding every pair each step (the sweep or grid alone) was 1.05-2.3× slower than
/// parry3d-f64's incremental BVH at 4,096-262,144 bodies; see `benches/benches/world.rs`
/// (`world/broad`) and `testdata/bench/world-broad.md` for the figures now.
#[derive(Debug, Default)]
pub(super) struct BroadPhase {
    /// By slot: the body's box (valid where `live`).
    tight: Vec<Aabb>,
    /// By slot: a body is there.
    live: Vec<bool>,
    /// Live slots.
    count: usize,
    /// By slot: the grown box the candidates were found with (valid where `indexed`).
    fat: Vec<Aabb>,
    /// By slot: the slot's fat box is among the candidates' (and in the tree, once built).
    indexed: Vec<bool>,
    /// Slots set or removed since the last update, each once (`touched_mark`).
    touched: Vec<u32>,
    touched_mark: Vec<bool>,
    /// Every pair of indexed slots whose fat boxes are within `margin`, `(lo, hi)`, sorted.
    candidates: Vec<(u32, u32)>,
    /// The margin the candidates hold for (its bits); `None` before the first update.
    margin: Option<u64>,
    /// The candidates were found with the bodies' own boxes, not the grown ones (a rebuild in
    /// incoherent motion): they are this step's answer, and any later move makes them stale.
    tight_candidates: bool,
    /// The last update rebuilt because too many bodies left their grown boxes.
    incoherent: bool,
    /// Relative growth of the fat boxes.
    slack: f64,
    /// The index of the fat boxes, built at the first step that needs it after a rebuild.
    tree: BoxTree,
    tree_built: bool,
    /// Scratch.
    changed: Vec<bool>,
    escaped: Vec<u32>,
    gone: Vec<u32>,
    stacks: Vec<Vec<u32>>,
    query_boxes: Vec<Aabb>,
    found: Vec<(u32, u32)>,
    /// A rebuild's boxes and its pair finder's buffers, kept from rebuild to rebuild.
    rebuild_items: Vec<(Aabb, u32)>,
    pair_scratch: PairScratch,
    /// The buffer the next merge of new candidates writes into.
    merge_spare: Vec<(u32, u32)>,
    /// Work counters since the world was made.
    pub(super) stats: BroadStats,
}

/// What the broad phase of a [`World`](crate::World) did since the world was made
/// ([`World::broad_stats`](crate::World::broad_stats)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BroadStats {
    /// Updates that found every candidate pair afresh (the first, a new margin, or more than
    /// an eighth of the bodies out of their grown boxes).
    pub rebuilds: u64,
    /// Of the `rebuilds`, those that found the step's pairs with the bodies' own boxes (the
    /// second step in a row in which more than an eighth of the bodies left their grown boxes;
    /// such candidates serve that step only).
    pub tight_rebuilds: u64,
    /// Bodies re-inserted one by one (out of their grown box, added, or removed).
    pub reinserted: u64,
    /// Builds of the dynamic tree those are re-inserted in.
    pub tree_builds: u64,
}

/// More than `1 / REBUILD_FRACTION` of the bodies changed in one step: find every pair afresh.
/// Chosen by measurement (`examples/broad_probe.rs`, 262,144 drifting boxes at four speeds):
/// 1/8 was as fast as 1/4 and 1/2 or faster by mean time per step at every speed (a rebuild
/// also re-centres every grown box, so fewer bodies leave them in the next steps).
const REBUILD_FRACTION: usize = 8;

/// The most a re-grown fat box is stretched ahead along its body's motion, per axis, in
/// growths (`slack` times the box's largest side); see [`BroadPhase::fatten_moving`].
const LEAD_CAP: f64 = 4.0;

impl BroadPhase {
    /// A broad phase whose fat boxes are grown by `slack` times their largest side (negative or
    /// NaN: 0, tight boxes).
    pub(super) fn new(slack: f64) -> Self {
        Self {
            slack: if slack > 0.0 { slack } else { 0.0 },
            ..Self::default()
        }
    }

    fn touch(&mut self, i: u32) {
        let i = i as usize;
        if self.touched_mark.len() <= i {
            let n = (i + 1).max(2 * self.touched_mark.len());
            self.touched_mark.resize(n, false);
            self.tight.resize(n, Aabb::EMPTY);
            self.live.resize(n, false);
            self.fat.resize(n, Aabb::EMPTY);
            self.indexed.resize(n, false);
            self.changed.resize(n, false);
        }
        if !self.touched_mark[i] {
            self.touched_mark[i] = true;
            self.touched.push(i as u32);
        }
    }

    /// Slot `i` holds a body with box `b` (added or moved).
    pub(super) fn set(&mut self, i: u32, b: Aabb) {
        self.touch(i);
        let i = i as usize;
        if !self.live[i] {
            self.live[i] = true;
            self.count += 1;
        }
        self.tight[i] = b;
    }

    /// Slot `i`'s box, as last set (valid while the slot holds a body).
    #[inline]
    pub(super) fn tight_box(&self, i: u32) -> &Aabb {
        &self.tight[i as usize]
    }

    /// Slot `i`'s body is gone.
    pub(super) fn remove(&mut self, i: u32) {
        self.touch(i);
        let i = i as usize;
        if self.live[i] {
            self.live[i] = false;
            self.count -= 1;
        }
    }

    /// The fat box of `b`.
    fn fatten(&self, b: &Aabb) -> Aabb {
        let side = (b.max - b.min).max_element();
        let d = self.slack * side;
        // Inverted or non-finite boxes get no growth (and fail `holds`, so they are re-inserted
        // whenever they move).
        b.inflated(if d.is_finite() && d > 0.0 { d } else { 0.0 })
    }

    /// The fat box of `b`, for a body that left its fat box `old`: grown as [`Self::fatten`],
    /// then stretched ahead along its motion since `old` was made (the shift of the centre,
    /// at most [`LEAD_CAP`] growths per axis), as Box2D stretches its fat boxes by the
    /// displacement. A body moving steadily then stays inside about three times as many steps
    /// (the stretch settles at about two growths: `old`'s own stretch shifts its centre by
    /// half of it), so it leaves, is re-inserted and searched for a third as often; a body
    /// that wanders or jumps gets at most the cap. Only the candidates grow: the answer is
    /// still tested with the bodies' own boxes.
    fn fatten_moving(&self, b: &Aabb, old: &Aabb) -> Aabb {
        let mut f = self.fatten(b);
        let grow = self.slack * (b.max - b.min).max_element();
        if !(grow.is_finite() && grow > 0.0) {
            return f;
        }
        let cap = LEAD_CAP * grow;
        let shift = b.center() - old.center();
        for a in 0..3 {
            // Adding a positive amount to `max` (or a negative one to `min`) only grows the
            // box, so it still holds `b`; a NaN shift stretches nothing.
            let x = shift[a];
            if x > 0.0 {
                f.max[a] += x.min(cap);
            } else if x < 0.0 {
                f.min[a] += x.max(-cap);
            }
        }
        f
    }

    /// Pushes the `(lo, hi)` slot pairs whose boxes are within `margin` (`>= 0`) of each
    /// other on every axis, sorted.
    pub(super) fn pairs(&mut self, margin: f64, out: &mut Vec<(u32, u32)>) {
        self.update(margin + 0.0);
        let t = &self.tight;
        let c = &self.candidates;
        if self.tight_candidates {
            // Found with these very boxes by the same comparisons as `within`.
            out.extend_from_slice(c);
            return;
        }
        out.reserve(c.len() / 2);
        for (k, &(a, b)) in c.iter().enumerate() {
            // The second box of each pair is a random read: ask for it a few pairs ahead.
            if let Some(&(_, ahead)) = c.get(k + PREFETCH_AHEAD) {
                prefetch(&t[ahead as usize]);
            }
            if within(&t[a as usize], &t[b as usize], margin) {
                out.push((a, b));
            }
        }
    }

    /// Brings the candidates up to date with the touched slots.
    fn update(&mut self, margin: f64) {
        if self.margin != Some(margin.to_bits()) {
            self.incoherent = false;
            return self.rebuild(margin, false);
        }
        self.escaped.clear();
        self.gone.clear();
        let moved = !self.touched.is_empty();
        for &s in &self.touched {
            let i = s as usize;
            self.touched_mark[i] = false;
            if !self.live[i] {
                if self.indexed[i] {
                    self.gone.push(s);
                }
            } else if !self.indexed[i] || !holds(&self.fat[i], &self.tight[i]) {
                self.escaped.push(s);
            }
        }
        self.touched.clear();
        let k = self.escaped.len() + self.gone.len();
        if k > self.count / REBUILD_FRACTION {
            // Incoherent motion. A second such step in a row finds the pairs with the bodies'
            // own boxes: fewer pairs to find and none to filter, where grown-box candidates
            // would be thrown away at the next step if the motion goes on (a single jump of
            // every body still gets grown boxes, kept for the calm steps after it).
            let tight = self.incoherent;
            self.incoherent = true;
            return self.rebuild(margin, tight);
        }
        self.incoherent = false;
        if self.tight_candidates {
            // The motion calmed down: grown-box candidates again, found afresh (stale the
            // moment anything moved).
            if moved {
                self.rebuild(margin, false);
            }
            return;
        }
        if k == 0 {
            return;
        }
        for &s in self.escaped.iter().chain(&self.gone) {
            self.changed[s as usize] = true;
        }
        let rebuild_tree = !self.tree_built || self.tree.edits > self.tree.leaves.max(1024);
        if rebuild_tree {
            // The unchanged indexed slots (the changed ones are inserted below).
            let mut items: Vec<(Aabb, u32)> = (0..self.indexed.len())
                .filter(|&i| self.indexed[i] && !self.changed[i])
                .map(|i| (self.fat[i], i as u32))
                .collect();
            self.tree.build(&mut items, self.indexed.len());
            self.tree_built = true;
            self.stats.tree_builds += 1;
        } else {
            for &s in &self.gone {
                self.tree.remove(s);
            }
        }
        for &s in &self.gone {
            self.indexed[s as usize] = false;
        }
        // In space-filling-curve order, so that consecutive insertions and queries walk the
        // same upper nodes while they are in the cache.
        sort_along_curve(&mut self.escaped, &self.tight);
        for k in 0..self.escaped.len() {
            let s = self.escaped[k];
            let i = s as usize;
            let fat = if self.indexed[i] {
                self.fatten_moving(&self.tight[i], &self.fat[i])
            } else {
                self.fatten(&self.tight[i])
            };
            self.fat[i] = fat;
            // A leaf already in the tree whose new box its near ancestors (almost) hold moves
            // in place; any other is (re-)inserted.
            let in_tree = self.indexed[i] && !rebuild_tree;
            if !(in_tree && self.tree.move_in_place(s, fat)) {
                if in_tree {
                    self.tree.remove(s);
                }
                self.tree.insert(s, fat);
            }
            self.indexed[i] = true;
        }
        self.stats.reinserted += k as u64;
        let changed = &self.changed;
        self.candidates
            .retain(|&(a, b)| !changed[a as usize] && !changed[b as usize]);
        self.found.clear();
        self.query_boxes.clear();
        self.query_boxes
            .extend(self.escaped.iter().map(|&e| self.fat[e as usize]));
        let (found, escaped) = (&mut self.found, &self.escaped);
        self.tree
            .query_many(&self.query_boxes, margin, &mut self.stacks, |q, o| {
                let e = escaped[q];
                // A pair of two re-inserted slots is taken from the lower one's query.
                if o != e && (!changed[o as usize] || e < o) {
                    found.push((e.min(o), e.max(o)));
                }
            });
        for &s in self.escaped.iter().chain(&self.gone) {
            self.changed[s as usize] = false;
        }
        if !self.found.is_empty() {
            self.found.sort_unstable();
            // Merged into the last merge's buffer (kept, like every buffer of a step), which
            // then holds the old list for the next merge.
            merge_sorted(&self.candidates, &self.found, &mut self.merge_spare);
            std::mem::swap(&mut self.candidates, &mut self.merge_spare);
        }
    }

    /// Re-grows every fat box and finds every candidate afresh: pairs of the fat boxes, or with
    /// `tight` of the bodies' own boxes (this step's answer, not kept; the fat boxes are still
    /// grown, to tell at the next update how many bodies left them).
    fn rebuild(&mut self, margin: f64, tight: bool) {
        for &s in &self.touched {
            self.touched_mark[s as usize] = false;
        }
        self.touched.clear();
        // Every buffer kept from the last rebuild: an incoherent run rebuilds every step, and
        // allocating them afresh made each step fault in new pages wherever the allocator
        // gave the memory back to the system (up to 40 % of a step, `cpu-core.md`).
        let mut items = std::mem::take(&mut self.rebuild_items);
        items.clear();
        for i in 0..self.live.len() {
            self.indexed[i] = self.live[i];
            if self.live[i] {
                self.fat[i] = self.fatten(&self.tight[i]);
                items.push((if tight { self.tight[i] } else { self.fat[i] }, i as u32));
            }
        }
        box_pairs(&items, margin, &mut self.pair_scratch, &mut self.candidates);
        self.rebuild_items = items;
        self.tight_candidates = tight;
        self.stats.tight_rebuilds += u64::from(tight);
        self.margin = Some(margin.to_bits());
        self.tree_built = false;
        self.stats.rebuilds += 1;
    }
}

/// Sorts `slots` by the Morton code of their boxes' centres in the bounds of those centres
/// (non-finite centres last).
fn sort_along_curve(slots: &mut [u32], boxes: &[Aabb]) {
    let centre = |s: u32| boxes[s as usize].center();
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for &s in slots.iter() {
        let c = centre(s);
        if c.is_finite() {
            lo = lo.min(c);
            hi = hi.max(c);
        }
    }
    let scale = DVec3::splat(1023.0) / (hi - lo).max(DVec3::splat(f64::MIN_POSITIVE));
    // Ten bits per axis: a cell per about a thousandth of the spread is fine enough to order
    // queries of boxes that are small next to it.
    let spread = |x: u32| {
        let mut x = x & 0x3ff;
        x = (x | (x << 16)) & 0x0300_00ff;
        x = (x | (x << 8)) & 0x0300_f00f;
        x = (x | (x << 4)) & 0x030c_30c3;
        (x | (x << 2)) & 0x0924_9249
    };
    let key = |s: u32| {
        let c = centre(s);
        if !c.is_finite() {
            return u32::MAX;
        }
        // `as` saturates (and maps NaN to 0): never out of range.
        let q = ((c - lo) * scale).to_array().map(|v| v as u32);
        spread(q[0]) | (spread(q[1]) << 1) | (spread(q[2]) << 2)
    };
    // Each key computed once (a key per comparison re-read the boxes: 3-11 ms for 10 k slots).
    let mut keyed: Vec<(u32, u32)> = slots.iter().map(|&s| (key(s), s)).collect();
    keyed.sort_unstable();
    for (s, (_, k)) in slots.iter_mut().zip(keyed) {
        *s = k;
    }
}

/// Candidate pairs between a prefetch of a box and its test.
pub(super) const PREFETCH_AHEAD: usize = 16;

/// A hint to bring `x` into the cache (nothing where the target has no such instruction).
#[inline(always)]
pub(super) fn prefetch<T>(x: &T) {
    #[cfg(target_arch = "x86_64")]
    #[allow(unsafe_code)]
    // SAFETY: a prefetch never faults and has no effect on memory; SSE is part of x86_64.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
            (x as *const T).cast(),
        );
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = x;
}

/// Two sorted lists merged into `out` (duplicates kept).
fn merge_sorted(a: &[(u32, u32)], b: &[(u32, u32)], out: &mut Vec<(u32, u32)>) {
    out.clear();
    out.reserve(a.len() + b.len());
    let (mut x, mut y) = (0, 0);
    while x < a.len() && y < b.len() {
        if a[x] <= b[y] {
            out.push(a[x]);
            x += 1;
        } else {
            out.push(b[y]);
            y += 1;
        }
    }
    out.extend_from_slice(&a[x..]);
    out.extend_from_slice(&b[y..]);
}

/// Every pair of `boxes` (`(box, id)`) within `margin` on every axis, as `(lower id, higher
/// id)`, sorted: a sweep along the centres' widest axis, or a uniform grid where a sample
/// shows the sweep would compare each box with more than [`GRID_FROM`] others (bodies filling
/// a volume: a box shares its range along any one axis with about n^(2/3) others).
fn box_pairs(
    boxes: &[(Aabb, u32)],
    margin: f64,
    scratch: &mut PairScratch,
    out: &mut Vec<(u32, u32)>,
) {
    out.clear();
    let var = frcd_geom::centre_variance(boxes.iter().map(|(b, _)| b));
    let axis = (1..3).fold(0, |best, a| if var[a] > var[best] { a } else { best });
    let s = &mut scratch.swept;
    s.clear();
    s.extend(boxes.iter().map(|(b, i)| Swept::new(b, *i, axis)));
    // Sorted for the grid too: its cells then read nearby boxes (without it the grid was
    // 4-7 % slower at 65,536 boxes).
    sort_swept(s, &mut scratch.radix);
    if !(s.len() >= GRID_MIN_BODIES
        && sampled_sweep_length(s, margin) > GRID_FROM
        && grid_pairs(s, margin, out, &mut scratch.grid))
    {
        for (p, bi) in s.iter().enumerate() {
            for bj in &s[p + 1..] {
                if bj.lo - bi.hi > margin {
                    break;
                }
                // The whole test, not only the axes across: `bj` starts at or after `bi`, but
                // an inverted `bj` (min > max) may end before `bi` starts.
                if !within_swept(bi, bj, margin) {
                    continue;
                }
                out.push((bi.slot.min(bj.slot), bi.slot.max(bj.slot)));
            }
        }
    }
    out.sort_unstable();
}

/// The buffers of [`box_pairs`], kept by the broad phase from one rebuild to the next.
#[derive(Debug, Default)]
pub(super) struct PairScratch {
    swept: Vec<Swept>,
    radix: RadixScratch,
    grid: GridScratch,
}

/// The buffers of [`sort_swept`].
#[derive(Debug, Default)]
struct RadixScratch {
    keys: Vec<(u64, u32)>,
    other: Vec<(u64, u32)>,
    swept: Vec<Swept>,
}

/// Below this many boxes [`sort_swept`] calls the comparison sort.
const RADIX_MIN: usize = 512;

/// `s` in the order of [`Swept::cmp`], for boxes given in increasing slot order (as every
/// caller gives them): a stable radix sort of the lower bounds' total-order keys
/// (`radix.rs`, eleven bits a pass), then one permutation of the boxes. Stable, so equal
/// lower bounds stay in slot order, as `Swept::cmp` puts them. (The comparison sort of the
/// 56-byte boxes was about 15 % of a rebuild of 4,096 boxes.)
fn sort_swept(s: &mut Vec<Swept>, r: &mut RadixScratch) {
    let n = s.len();
    debug_assert!(s.windows(2).all(|w| w[0].slot < w[1].slot));
    if n < RADIX_MIN {
        s.sort_unstable_by(Swept::cmp);
        return;
    }
    // `f64::total_cmp`'s order as unsigned integers: negative values (sign bit set) reversed
    // below the positive ones.
    let key = |x: f64| {
        let b = x.to_bits();
        if b >> 63 == 1 { !b } else { b | 1 << 63 }
    };
    let keys = &mut r.keys;
    keys.clear();
    keys.extend(s.iter().enumerate().map(|(i, b)| (key(b.lo), i as u32)));
    crate::radix::sort_by_u64_key(keys, &mut r.other, &mut [0; 2048], |e| e.0);
    r.swept.clear();
    r.swept.extend(keys.iter().map(|&(_, i)| s[i as usize]));
    std::mem::swap(s, &mut r.swept);
}

/// The buffers of [`grid_pairs`].
#[derive(Debug, Default)]
struct GridScratch {
    sides: Vec<f64>,
    big: Vec<u32>,
    entries: Vec<(u64, u32)>,
    sorted: Vec<(u64, u32)>,
    next: Vec<u32>,
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
fn within_swept(a: &Swept, b: &Swept, margin: f64) -> bool {
    !(b.lo - a.hi > margin || a.lo - b.hi > margin || apart_across(a, b, margin))
}

/// The overlapping pairs through a uniform grid. Each box covers the cells of
/// `[lower, upper + margin]` on every axis (the upper bound rounded outward, so a box covers
/// every point `x` with `x - upper <= margin` as [`within_swept`] computes it); the entries are
/// sorted by cell, and a pair that passes [`within_swept`] is reported in the one cell holding the largest of
/// its lower corners (both boxes cover that point, so the pair is found there and only there).
/// Cells are twice the median box's largest covered side; a box covering more than
/// [`GRID_SPAN`] cells along an axis is tested against every other box instead. False (nothing
/// pushed) where no grid can be laid out or it would not pay (non-finite boxes, more than 2^21
/// cells along an axis, more than [`GRID_ENTRIES`] entries per box, many long boxes): the
/// caller sweeps.
fn grid_pairs(s: &[Swept], margin: f64, out: &mut Vec<(u32, u32)>, g: &mut GridScratch) -> bool {
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
    let sides = &mut g.sides;
    sides.clear();
    sides.extend(s.iter().map(|b| {
        let (lo, hi) = cover(b);
        (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max)
    }));
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
    // Monotone in x, so a box's cell range holds the cell of every point it covers. The
    // conversion truncates, which is the floor for values >= 0 and gives 0 below (saturating,
    // as the floor's conversion would, NaN included): no call to `floor` (not inlined without
    // SSE4.1, 6 % of a rebuild of 4,096 boxes).
    let cell = |x: f64, k: usize| ((x - origin[k]) / h) as u64;
    // Cells numbered densely, z fastest (below 2^63 + 3·2^42: no overflow); the same order as
    // sorting by (x, y, z).
    let span = [0, 1, 2].map(|k| cells(k) as u64 + 1);
    let key = |c: [u64; 3]| (c[0] * span[1] + c[1]) * span[2] + c[2];
    let cell_count = span[0] * span[1] * span[2];
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
    // `within_swept` still pairs), go to the all-pairs list.
    let listed =
        |c0: [u64; 3], c1: [u64; 3]| (0..3).any(|k| c1[k] < c0[k] || c1[k] - c0[k] >= GRID_SPAN);
    let big = &mut g.big;
    big.clear();
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
    let entries = &mut g.entries;
    entries.clear();
    entries.reserve(total as usize);
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
    // In cell order, ties by box: a counting sort where the cells are few next to the entries
    // (a crowded volume, the grid's use: O(n) against the sort's O(n log n)), else a sort. The
    // same order either way (the entries were pushed by increasing box index).
    let entries: &[(u64, u32)] = if cell_count <= 4 * entries.len() as u64 + 1024 {
        counting_sort_by_cell(entries, cell_count as usize, &mut g.next, &mut g.sorted);
        &g.sorted
    } else {
        entries.sort_unstable();
        entries
    };
    let mut start = 0;
    while start < entries.len() {
        let k = entries[start].0;
        // A cell holds a few boxes: a linear scan for its end (a binary search over the rest
        // of the entries was 15 % of a rebuild at 262,144 boxes).
        let mut end = start + 1;
        while end < entries.len() && entries[end].0 == k {
            end += 1;
        }
        // The boxes are read in cell order, not in their own: ask for them a few cells ahead.
        for &(_, ahead) in entries
            .get(end + PREFETCH_AHEAD..end + PREFETCH_AHEAD + 4)
            .unwrap_or(&[])
        {
            prefetch(&s[ahead as usize]);
        }
        let run = &entries[start..end];
        for (x, &(_, i)) in run.iter().enumerate() {
            let bi = &s[i as usize];
            for &(_, j) in &run[x + 1..] {
                let bj = &s[j as usize];
                if !within_swept(bi, bj, margin) {
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
            if within_swept(bi, bj, margin) {
                out.push((bi.slot.min(bj.slot), bi.slot.max(bj.slot)));
            }
        }
    }
    true
}

/// `entries` (cell below `cells`, pushed in increasing box order) stably ordered by cell: a
/// counting sort, O(`entries.len()` + `cells`), reading the entries in order.
fn counting_sort_by_cell(
    entries: &[(u64, u32)],
    cells: usize,
    next: &mut Vec<u32>,
    sorted: &mut Vec<(u64, u32)>,
) {
    next.clear();
    next.resize(cells + 1, 0);
    for e in entries {
        next[e.0 as usize + 1] += 1;
    }
    for c in 1..next.len() {
        next[c] += next[c - 1];
    }
    sorted.clear();
    sorted.resize(entries.len(), (0, 0));
    for &e in entries {
        let at = &mut next[e.0 as usize];
        sorted[*at as usize] = e;
        *at += 1;
    }
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
    let mut out = Vec::new();
    box_pairs(
        &tagged,
        margin.max(0.0),
        &mut PairScratch::default(),
        &mut out,
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The counting sort gives the order of a sort of `(cell, box)` when the entries were
    /// pushed by increasing box index, with repeated and unused cells.
    #[test]
    fn counting_sort_by_cell_equals_the_sort() {
        let mut entries = Vec::new();
        let mut x = 7u64;
        for i in 0..3000u32 {
            for _ in 0..(i % 4) {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                entries.push((x % 500, i));
            }
        }
        let mut want = entries.clone();
        want.sort_unstable();
        let (mut next, mut sorted) = (Vec::new(), Vec::new());
        counting_sort_by_cell(&entries, 500, &mut next, &mut sorted);
        assert_eq!(sorted, want);
        // Buffers reused from a larger sort give the same.
        counting_sort_by_cell(&entries[..700], 500, &mut next, &mut sorted);
        let mut part = entries[..700].to_vec();
        part.sort_unstable();
        assert_eq!(sorted, part);
        counting_sort_by_cell(&[], 3, &mut next, &mut sorted);
        assert!(sorted.is_empty());
    }

    /// The radix sort of the swept boxes gives the comparison sort's order, on a few hundred
    /// to many thousand boxes with ties, signed zeros, infinities and NaN lower bounds.
    #[test]
    fn radix_sort_of_swept_boxes_equals_the_sort() {
        let mut next = crate::test_rng::xorshift(99);
        let mut r = RadixScratch::default();
        for n in [0, 5, 511, 512, 3000, 20_000] {
            let mut s: Vec<Swept> = (0..n as u32)
                .map(|slot| {
                    let v = next();
                    let lo = match v % 16 {
                        0 => 0.0,
                        1 => -0.0,
                        2 => f64::INFINITY,
                        3 => f64::NEG_INFINITY,
                        4 => f64::NAN,
                        5 => -f64::NAN,
                        6 => 1.5,
                        _ => {
                            ((v >> 8) as f64 / (1u64 << 40) as f64 - 4000.0)
                                * [1.0, 1e-300, 1e300][v as usize % 3]
                        }
                    };
                    Swept {
                        lo,
                        hi: lo,
                        rest: [0.0; 4],
                        slot,
                    }
                })
                .collect();
            let mut want = s.clone();
            want.sort_unstable_by(Swept::cmp);
            sort_swept(&mut s, &mut r);
            let bits = |v: &[Swept]| {
                v.iter()
                    .map(|b| (b.lo.to_bits(), b.slot))
                    .collect::<Vec<_>>()
            };
            assert_eq!(bits(&s), bits(&want), "{n} boxes");
        }
    }

    fn unit_at(x: f64, y: f64) -> Aabb {
        Aabb::new(DVec3::new(x, y, 0.0), DVec3::new(x + 1.0, y + 1.0, 1.0))
    }

    /// A body moving steadily leaves its grown box about a third as often as with boxes grown
    /// the same way on every side, the stretch is capped for a jump, it stays exact (every
    /// step's pairs are those of the bodies' own boxes), and tight boxes get no stretch.
    #[test]
    fn fat_boxes_stretch_ahead_of_steady_motion() {
        // 200 still bodies in a row, one body sliding along them by 0.02 a step for 12 units.
        // Grown by 0.1 on every side, it would leave its box every 6 steps: 100 times.
        let mut b = BroadPhase::new(0.1);
        for k in 0..200u32 {
            b.set(k, unit_at(k as f64 * 1.5, 0.0));
        }
        let mut out = Vec::new();
        let mut escapes = 0;
        for step in 0..600 {
            b.set(200, unit_at(step as f64 * 0.02, 0.9));
            let before = b.stats.reinserted;
            out.clear();
            b.pairs(0.0, &mut out);
            escapes += b.stats.reinserted - before;
            let want: Vec<(u32, u32)> = (0..200)
                .filter(|&k| within(&b.tight[k as usize], &b.tight[200], 0.0))
                .map(|k| (k, 200))
                .collect();
            assert_eq!(out, want, "step {step}");
        }
        assert!(
            (20..=40).contains(&escapes),
            "{escapes} escapes in 600 steps (100 without the stretch)"
        );
        // A jump is stretched by at most the cap.
        let b = BroadPhase::new(0.1);
        let far = b.fatten_moving(&unit_at(1000.0, 0.0), &b.fatten(&unit_at(0.0, 0.0)));
        assert_eq!(far.max.x, 1001.0 + 0.1 + LEAD_CAP * 0.1);
        assert_eq!(far.min.x, 1000.0 - 0.1);
        // Tight boxes stay tight.
        let t = BroadPhase::new(0.0);
        assert_eq!(
            t.fatten_moving(&unit_at(5.0, 0.0), &unit_at(0.0, 0.0)),
            unit_at(5.0, 0.0)
        );
    }
}
