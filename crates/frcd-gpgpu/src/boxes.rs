use crate::context::BOX_TILE;
use crate::pack::{round_down_normal, round_up_normal};
use crate::{GpuContext, GpuError};
use frcd_geom::Aabb;
use frcd_gpu::layout::{BodyBox, BoxParams};

pub(crate) const UNCERTAIN_FLAG: u32 = 0x8000_0000;
pub(crate) const MAX_RERUNS: u32 = 32;

/// The answer of [`GpuContext::overlapping_bodies`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct BodyPairs {
    /// Every pair `(i, j)`, `i < j`, of boxes that share a point (closed boxes, f64), sorted.
    pub pairs: Vec<(u32, u32)>,
    /// Pairs the f32 comparison could not decide, re-checked in f64 on the CPU.
    pub uncertain: usize,
    /// Submissions made (1 unless the output overflowed).
    pub submissions: u32,
    /// Readbacks made (1 unless the output overflowed).
    pub readbacks: u32,
}

struct BoxBuffers {
    ctx_id: u64,
    body_cap: u32,
    output_cap: u32,
    boxes: wgpu::Buffer,
    out: wgpu::Buffer,
    count: wgpu::Buffer,
    params: wgpu::Buffer,
    staging: wgpu::Buffer,
    bind: wgpu::BindGroup,
}

/// Caller-owned buffers of [`GpuContext::overlapping_bodies`] (and of the all-pairs form),
/// sized by capacity, grown as needed and kept for the next frame; tied to the first context it
/// is used with.
pub struct BoxScratch {
    pub(crate) output_cap: u32,
    bufs: Option<BoxBuffers>,
    pub(crate) sweep: Option<crate::sweep::SweepBuffers>,
}

impl Default for BoxScratch {
    fn default() -> Self {
        Self::with_capacity(1 << 12)
    }
}

impl std::fmt::Debug for BoxScratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BoxScratch")
            .field("output_capacity", &self.output_cap)
            .finish()
    }
}

impl BoxScratch {
    /// Scratch whose first output buffer holds `output` pairs (at least 1); overflow re-runs.
    pub fn with_capacity(output: u32) -> Self {
        Self {
            output_cap: output.max(1),
            bufs: None,
            sweep: None,
        }
    }

    /// Current output capacity in pairs.
    pub fn capacity(&self) -> u32 {
        self.output_cap
    }

    fn ensure(&mut self, ctx: &GpuContext, bodies: u32) -> Result<&BoxBuffers, GpuError> {
        let reuse = match &self.bufs {
            Some(b) if b.ctx_id != ctx.id => return Err(GpuError::ForeignObject("BoxScratch")),
            Some(b) => b.body_cap >= bodies && b.output_cap == self.output_cap,
            None => false,
        };
        if !reuse {
            let body_cap = bodies.next_power_of_two().max(64);
            ctx.check_storage(&[
                ("body boxes", body_cap as u64 * 64),
                ("body pairs", self.output_cap as u64 * 8),
            ])?;
            use wgpu::BufferUsages as B;
            let d = &ctx.device;
            let buf = |label: &str, size: u64, usage: B| ctx.buffer(label, size, usage);
            let osize = self.output_cap as u64 * 8;
            let boxes = buf(
                "frcd-gpgpu body boxes",
                body_cap as u64 * 64,
                B::STORAGE | B::COPY_DST,
            );
            let out = buf("frcd-gpgpu body pairs", osize, B::STORAGE | B::COPY_SRC);
            let count = buf(
                "frcd-gpgpu body pair count",
                4,
                B::STORAGE | B::COPY_SRC | B::COPY_DST,
            );
            let params = buf("frcd-gpgpu body params", 16, B::UNIFORM | B::COPY_DST);
            let staging = buf(
                "frcd-gpgpu body staging",
                8 + osize,
                B::MAP_READ | B::COPY_DST,
            );
            let bind = d.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("frcd-gpgpu boxes"),
                layout: &ctx.pipes.boxes_bgl,
                entries: &[
                    crate::context::entry(0, &boxes),
                    crate::context::entry(1, &out),
                    crate::context::entry(2, &count),
                    crate::context::entry(3, &params),
                ],
            });
            self.bufs = Some(BoxBuffers {
                ctx_id: ctx.id,
                body_cap,
                output_cap: self.output_cap,
                boxes,
                out,
                count,
                params,
                staging,
                bind,
            });
        }
        Ok(self.bufs.as_ref().expect("just set"))
    }
}

/// The prelude's `BodyBox`: outer corners (rounded outward) and inner ones (rounded inward), as
/// boxes.wgsl compares them. No corner is subnormal, so a GPU that flushes subnormal comparison
/// operands to zero compares the values stored ([`round_up_normal`]).
pub(crate) fn body_box(b: &Aabb) -> BodyBox {
    let (lo, hi) = (b.min, b.max);
    let (up, dn) = (round_up_normal, round_down_normal);
    BodyBox {
        lo_dn: [dn(lo.x), dn(lo.y), dn(lo.z), 0.0],
        hi_up: [up(hi.x), up(hi.y), up(hi.z), 0.0],
        lo_up: [up(lo.x), up(lo.y), up(lo.z), 0.0],
        hi_dn: [dn(hi.x), dn(hi.y), dn(hi.z), 0.0],
    }
}

/// Refuses a box with a NaN coordinate (both box passes; an empty or infinite box is fine).
pub(crate) fn check_boxes(boxes: &[Aabb]) -> Result<(), GpuError> {
    match boxes.iter().position(|b| b.min.is_nan() || b.max.is_nan()) {
        Some(i) => Err(GpuError::InvalidInput(format!(
            "box {i} has a NaN coordinate"
        ))),
        None => Ok(()),
    }
}

/// A box pass submitted and not read yet ([`GpuContext::submit_broad_phase`]): owned (no
/// borrow of the context or the scratch), so the caller can work while the GPU runs it, e.g.
/// the CPU finishing frame k while the GPU finds frame k+1's body pairs.
/// [`GpuContext::resolve_broad_phase`] reads it (waiting on its own submission only) and gives
/// the scratch back. Dropping it unresolved is allowed (the work is discarded).
#[must_use = "a submitted box pass is read by GpuContext::resolve_broad_phase"]
pub struct SubmittedBoxes {
    ctx_id: u64,
    scratch: BoxScratch,
    state: Submitted,
}

enum Submitted {
    /// The all-pairs pass in flight: its boxes (for the f64 re-check of uncertain pairs).
    InFlight {
        boxes: Vec<Aabb>,
        index: wgpu::SubmissionIndex,
        out_bytes: u64,
    },
    /// Answered at submission (fewer than two boxes, or the sort-and-sweep, which runs its
    /// passes at once).
    Done(BodyPairs),
}

impl std::fmt::Debug for SubmittedBoxes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SubmittedBoxes")
            .field(
                "in_flight",
                &matches!(self.state, Submitted::InFlight { .. }),
            )
            .finish()
    }
}

impl GpuContext {
    /// The all-pairs form of [`GpuContext::overlapping_bodies`] (O(n²) comparisons, tiled in
    /// workgroup memory): the same answer, kept as a reference and for small counts.
    /// One submission and one readback (plus one per output overflow). Boxes with NaN are an
    /// error; empty boxes overlap nothing.
    pub fn overlapping_bodies_all_pairs(
        &self,
        boxes: &[Aabb],
        scratch: &mut BoxScratch,
    ) -> Result<BodyPairs, GpuError> {
        let mut answer = BodyPairs::default();
        loop {
            let Some((index, out_bytes)) = self.submit_all_pairs(boxes, scratch)? else {
                return Ok(answer);
            };
            answer.submissions += 1;
            if self.read_all_pairs(boxes, scratch, index, out_bytes, &mut answer)? {
                return Ok(answer);
            }
        }
    }

    /// [`GpuContext::broad_phase`] submitted, not waited for: read it with
    /// [`GpuContext::resolve_broad_phase`] (the same answer). The all-pairs pass (up to
    /// [`crate::ALL_PAIRS_MAX_BODIES`] bodies) is queued and left running; the sort-and-sweep
    /// above that runs its passes here and the resolve only hands its answer over.
    ///
    /// ```no_run
    /// # use frcd_gpgpu::{BoxScratch, GpuContext};
    /// # use frcd_geom::{Aabb, DVec3};
    /// let ctx = GpuContext::headless()?;
    /// let boxes: Vec<Aabb> = (0..64)
    ///     .map(|i| Aabb::new(DVec3::X * i as f64, DVec3::X * i as f64 + DVec3::splat(1.5)))
    ///     .collect();
    /// let pending = ctx.submit_broad_phase(&boxes, BoxScratch::default())?;
    /// // ... CPU work while the GPU runs the pass ...
    /// let (found, _scratch) = ctx.resolve_broad_phase(pending)?;
    /// assert_eq!(found.pairs.len(), 63);
    /// # Ok::<(), frcd_gpgpu::GpuError>(())
    /// ```
    pub fn submit_broad_phase(
        &self,
        boxes: &[Aabb],
        mut scratch: BoxScratch,
    ) -> Result<SubmittedBoxes, GpuError> {
        let state = if boxes.len() > crate::ALL_PAIRS_MAX_BODIES {
            Submitted::Done(self.overlapping_bodies(boxes, &mut scratch)?)
        } else {
            match self.submit_all_pairs(boxes, &mut scratch)? {
                None => Submitted::Done(BodyPairs::default()),
                Some((index, out_bytes)) => Submitted::InFlight {
                    boxes: boxes.to_vec(),
                    index,
                    out_bytes,
                },
            }
        };
        Ok(SubmittedBoxes {
            ctx_id: self.id,
            scratch,
            state,
        })
    }

    /// Reads a box pass [`GpuContext::submit_broad_phase`] queued (waiting on its submission
    /// only: the device's other work, the caller's included, is not waited for) and gives the
    /// scratch back; an output overflow re-runs the pass here. A pass submitted on another
    /// context is [`GpuError::ForeignObject`].
    pub fn resolve_broad_phase(
        &self,
        submitted: SubmittedBoxes,
    ) -> Result<(BodyPairs, BoxScratch), GpuError> {
        if submitted.ctx_id != self.id {
            return Err(GpuError::ForeignObject("SubmittedBoxes"));
        }
        let SubmittedBoxes {
            mut scratch, state, ..
        } = submitted;
        let (boxes, index, out_bytes) = match state {
            Submitted::Done(answer) => return Ok((answer, scratch)),
            Submitted::InFlight {
                boxes,
                index,
                out_bytes,
            } => (boxes, index, out_bytes),
        };
        let mut answer = BodyPairs {
            submissions: 1,
            ..BodyPairs::default()
        };
        if !self.read_all_pairs(&boxes, &mut scratch, index, out_bytes, &mut answer)? {
            let again = self.overlapping_bodies_all_pairs(&boxes, &mut scratch)?;
            answer = BodyPairs {
                submissions: answer.submissions + again.submissions,
                readbacks: answer.readbacks + again.readbacks,
                ..again
            };
        }
        Ok((answer, scratch))
    }

    /// Checks the boxes and queues one all-pairs pass; its submission and the bytes of output
    /// to read back, or `None` for fewer than two boxes (no pair, nothing queued).
    fn submit_all_pairs(
        &self,
        boxes: &[Aabb],
        scratch: &mut BoxScratch,
    ) -> Result<Option<(wgpu::SubmissionIndex, u64)>, GpuError> {
        check_boxes(boxes)?;
        let n = boxes.len();
        if n < 2 {
            return Ok(None);
        }
        let groups = (n as u64).div_ceil(BOX_TILE as u64);
        let max_groups = self.limits.max_compute_workgroups_per_dimension as u64;
        if groups > max_groups || n as u64 >= UNCERTAIN_FLAG as u64 {
            return Err(GpuError::CapacityExceeded {
                what: "bodies (workgroups per dimension)",
                needed: n as u64,
                limit: max_groups * BOX_TILE as u64,
            });
        }
        let words: Vec<BodyBox> = boxes.iter().map(body_box).collect();
        let bufs = scratch.ensure(self, n as u32)?;
        self.queue
            .write_buffer(&bufs.boxes, 0, bytemuck::cast_slice(&words));
        self.queue.write_buffer(
            &bufs.params,
            0,
            bytemuck::bytes_of(&BoxParams {
                n: [n as u32, bufs.output_cap, 0, 0],
            }),
        );
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frcd-gpgpu boxes"),
            });
        enc.clear_buffer(&bufs.count, 0, None);
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("frcd-gpgpu boxes"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipes.boxes);
            pass.set_bind_group(0, &bufs.bind, &[]);
            pass.dispatch_workgroups(groups as u32, groups as u32, 1);
        }
        let out_bytes = bufs.output_cap as u64 * 8;
        enc.copy_buffer_to_buffer(&bufs.count, 0, &bufs.staging, 0, 4);
        enc.copy_buffer_to_buffer(&bufs.out, 0, &bufs.staging, 8, out_bytes);
        Ok(Some((self.submit(enc.finish()), out_bytes)))
    }

    /// Reads an all-pairs pass into `answer` (one readback); false when its output overflowed
    /// (the scratch then grows to the count found: submit again).
    fn read_all_pairs(
        &self,
        boxes: &[Aabb],
        scratch: &mut BoxScratch,
        index: wgpu::SubmissionIndex,
        out_bytes: u64,
        answer: &mut BodyPairs,
    ) -> Result<bool, GpuError> {
        let bufs = scratch.bufs.as_ref().expect("submitted");
        let output_cap = bufs.output_cap;
        let bytes = self.read_back(&bufs.staging, 8 + out_bytes, index)?;
        answer.readbacks += 1;
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        let count = words[0];
        if count > output_cap {
            scratch.output_cap = count.max(output_cap.saturating_mul(2));
            if answer.submissions > MAX_RERUNS {
                return Err(GpuError::Internal("box pass keeps overflowing".into()));
            }
            return Ok(false);
        }
        decode(boxes, &words[2..2 + 2 * count as usize], answer)?;
        Ok(true)
    }
}

/// Decodes the GPU's `(i, j | flag)` entries into `answer.pairs` (sorted): flagged pairs are
/// re-checked in f64.
pub(crate) fn decode(
    boxes: &[Aabb],
    entries: &[u32],
    answer: &mut BodyPairs,
) -> Result<(), GpuError> {
    let n = boxes.len();
    let mut pairs = Vec::with_capacity(entries.len() / 2);
    for e in entries.chunks_exact(2) {
        let (i, tag) = (e[0], e[1]);
        let j = tag & !UNCERTAIN_FLAG;
        if i as usize >= n || j as usize >= n || i >= j {
            return Err(GpuError::Internal(format!("body pair ({i}, {j}) invalid")));
        }
        if tag & UNCERTAIN_FLAG != 0 {
            answer.uncertain += 1;
            if !boxes[i as usize].intersects(&boxes[j as usize]) {
                continue;
            }
        }
        pairs.push((i, j));
    }
    pairs.sort_unstable();
    if pairs.windows(2).any(|w| w[0] == w[1]) {
        return Err(GpuError::Internal("a body pair was reported twice".into()));
    }
    answer.pairs = pairs;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use frcd_geom::DVec3;

    /// The shader's `meet` on one axis as a GPU that flushes subnormal comparison operands to
    /// zero evaluates it (`ftz`), or as stored.
    fn meet(alo: f32, ahi: f32, blo: f32, bhi: f32, ftz: bool) -> bool {
        let f = |x: f32| if ftz && x.is_subnormal() { 0.0 } else { x };
        f(alo) <= f(bhi) && f(blo) <= f(ahi)
    }

    /// Intervals at and around f32's underflow and overflow thresholds: the outer test never
    /// drops an overlapping pair and the inner ("surely overlapping") test never accepts a
    /// separated one, with and without flush-to-zero. Before the packer kept subnormals out,
    /// planes at z = 1e-300 and 2e-300 were "surely overlapping" on an H200.
    #[test]
    fn bounds_hold_under_flush_to_zero() {
        let mut v = vec![0.0, 1.0, 1e39, f64::INFINITY];
        for m in [1e-300, 2e-300, 1e-45, 1e-41, 3e-39, 1.1754942e-38] {
            v.push(m);
        }
        v.push(f32::MIN_POSITIVE as f64);
        v.push(f32::MIN_POSITIVE as f64 * (1.0 + 1e-12));
        let v: Vec<f64> = v.iter().flat_map(|&x| [x, -x]).collect();
        let boxes: Vec<Aabb> = v
            .iter()
            .flat_map(|&lo| v.iter().map(move |&hi| (lo, hi)))
            .filter(|(lo, hi)| lo <= hi)
            .map(|(lo, hi)| Aabb::new(DVec3::new(lo, 0.0, 0.0), DVec3::new(hi, 1.0, 1.0)))
            .collect();
        let packed: Vec<BodyBox> = boxes.iter().map(body_box).collect();
        for p in &packed {
            for x in p
                .lo_dn
                .iter()
                .chain(&p.hi_up)
                .chain(&p.lo_up)
                .chain(&p.hi_dn)
            {
                assert!(!x.is_subnormal(), "subnormal bound {x:e}");
            }
        }
        let mut checked = 0;
        for (a, pa) in boxes.iter().zip(&packed) {
            for (b, pb) in boxes.iter().zip(&packed) {
                let exact = a.intersects(b);
                for ftz in [false, true] {
                    let outer = meet(pa.lo_dn[0], pa.hi_up[0], pb.lo_dn[0], pb.hi_up[0], ftz);
                    let inner = meet(pa.lo_up[0], pa.hi_dn[0], pb.lo_up[0], pb.hi_dn[0], ftz);
                    assert!(outer || !exact, "{a:?} {b:?} (ftz {ftz}): overlap dropped");
                    assert!(
                        !inner || exact,
                        "{a:?} {b:?} (ftz {ftz}): false sure overlap"
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 10_000, "{checked}");
    }
}
