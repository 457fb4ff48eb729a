//! The GPU broad phase in O(n log n + pairs): sort-based sweep and prune (`shaders/sweep.wgsl`).

use crate::boxes::{
    BodyPairs, BoxScratch, MAX_RERUNS, UNCERTAIN_FLAG, body_box, check_boxes, decode,
};
use crate::{GpuContext, GpuError};
use frcd_geom::Aabb;
use frcd_gpu::layout::{BodyBox, BoxParams, SortStage};

/// Bodies up to which [`GpuContext::broad_phase`] takes the all-pairs pass: its one dispatch
/// beats the sweep's sort passes there. Measured on `cargo xtask bench gpgpu --boxes-only`:
/// lavapipe (2 cores, 2026-12-01) all-pairs / sweep 0.43 at 64 bodies, 0.88 at 256 and 1.9 at
/// 512; an NVIDIA H200 (2026-11-28) 0.85 at 256 and 0.69 at 4,096.
pub const ALL_PAIRS_MAX_BODIES: usize = 256;

/// Workgroup size of every sweep pass (must match `WG` in sweep.wgsl).
const WG: u32 = 64;
/// Keys sorted per workgroup in workgroup memory (must match `BLOCK` in sweep.wgsl).
const BLOCK: u32 = 128;

/// Which sweep pipeline (index into `Pipelines::sweep`).
#[derive(Clone, Copy)]
enum Pass {
    Keys = 0,
    Local = 1,
    Global = 2,
    Gather = 3,
    Sweep = 4,
}

/// Buffers of the sweep, sized by capacity: the body-sized ones (boxes, keys, sorted boxes,
/// sort stages) and the output-sized ones (pairs, staging) grow independently, so an output
/// overflow re-runs only the sweep pass over the already sorted boxes.
pub(crate) struct SweepBuffers {
    ctx_id: u64,
    /// Padded body capacity (a power of two, at least `BLOCK`).
    body_cap: u32,
    output_cap: u32,
    /// Byte stride of one sort stage (the device's uniform offset alignment).
    stride: u64,
    boxes: wgpu::Buffer,
    keys: wgpu::Buffer,
    sorted: wgpu::Buffer,
    stages: wgpu::Buffer,
    params: wgpu::Buffer,
    count: wgpu::Buffer,
    out: wgpu::Buffer,
    staging: wgpu::Buffer,
    bind: wgpu::BindGroup,
}

/// The sort network's steps for `padded` keys, as `(pass, k, j)`: one presort of every block,
/// then per `k > BLOCK` the global steps `j >= BLOCK` and one local finish.
fn sort_steps(padded: u32) -> Vec<(Pass, u32, u32)> {
    let mut steps = vec![(Pass::Local, 0, 0)];
    let mut k = BLOCK * 2;
    while k <= padded {
        let mut j = k / 2;
        while j >= BLOCK {
            steps.push((Pass::Global, k, j));
            j /= 2;
        }
        steps.push((Pass::Local, k, 0));
        k *= 2;
    }
    steps
}

/// Most sort stages for `padded` keys (stage buffer size).
fn stage_count(padded: u32) -> usize {
    sort_steps(padded).len()
}

impl SweepBuffers {
    fn new(ctx: &GpuContext, body_cap: u32, output_cap: u32) -> Result<Self, GpuError> {
        let stride = (ctx.limits.min_uniform_buffer_offset_alignment as u64).max(16);
        let osize = output_cap as u64 * 8;
        ctx.check_storage(&[
            ("body boxes", body_cap as u64 * 64),
            ("sweep keys", body_cap as u64 * 8),
            ("body pairs", osize),
        ])?;
        if stage_count(body_cap) as u64 * stride > ctx.limits.max_buffer_size {
            return Err(GpuError::CapacityExceeded {
                what: "sweep sort stages",
                needed: stage_count(body_cap) as u64 * stride,
                limit: ctx.limits.max_buffer_size,
            });
        }
        use wgpu::BufferUsages as B;
        let buf = |label: &str, size: u64, usage: B| ctx.buffer(label, size, usage);
        let boxes = buf(
            "frcd-gpgpu sweep boxes",
            body_cap as u64 * 64,
            B::STORAGE | B::COPY_DST,
        );
        let keys = buf("frcd-gpgpu sweep keys", body_cap as u64 * 8, B::STORAGE);
        let sorted = buf("frcd-gpgpu sweep sorted", body_cap as u64 * 64, B::STORAGE);
        let stages = buf(
            "frcd-gpgpu sweep stages",
            stage_count(body_cap) as u64 * stride,
            B::UNIFORM | B::COPY_DST,
        );
        let params = buf("frcd-gpgpu sweep params", 16, B::UNIFORM | B::COPY_DST);
        // The pair count and the "another round" flag (sweep.wgsl).
        let count = buf(
            "frcd-gpgpu sweep pair count",
            8,
            B::STORAGE | B::COPY_SRC | B::COPY_DST,
        );
        let (out, staging) = output_buffers(ctx, output_cap);
        let bind = bind_group(
            ctx,
            [&boxes, &out, &count, &params, &keys, &sorted],
            &stages,
        );
        Ok(Self {
            ctx_id: ctx.id,
            body_cap,
            output_cap,
            stride,
            boxes,
            keys,
            sorted,
            stages,
            params,
            count,
            out,
            staging,
            bind,
        })
    }

    /// Replaces the output buffers (the body buffers and their contents are kept).
    fn set_output(&mut self, ctx: &GpuContext, output_cap: u32) -> Result<(), GpuError> {
        ctx.check_storage(&[("body pairs", output_cap as u64 * 8)])?;
        (self.out, self.staging) = output_buffers(ctx, output_cap);
        self.output_cap = output_cap;
        let b = [
            &self.boxes,
            &self.out,
            &self.count,
            &self.params,
            &self.keys,
            &self.sorted,
        ];
        self.bind = bind_group(ctx, b, &self.stages);
        Ok(())
    }
}

/// The pair output and its staging copy for `cap` pairs.
fn output_buffers(ctx: &GpuContext, cap: u32) -> (wgpu::Buffer, wgpu::Buffer) {
    use wgpu::BufferUsages as B;
    let osize = cap as u64 * 8;
    let out = ctx.buffer("frcd-gpgpu sweep pairs", osize, B::STORAGE | B::COPY_SRC);
    let staging = ctx.buffer(
        "frcd-gpgpu sweep staging",
        8 + osize,
        B::MAP_READ | B::COPY_DST,
    );
    (out, staging)
}

/// The sweep's bind group: bindings 0-5 as listed, 6 the sort stage (dynamic offset).
fn bind_group(ctx: &GpuContext, b: [&wgpu::Buffer; 6], stages: &wgpu::Buffer) -> wgpu::BindGroup {
    let e = crate::context::entry;
    ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("frcd-gpgpu sweep"),
        layout: &ctx.pipes.sweep_bgl,
        entries: &[
            e(0, b[0]),
            e(1, b[1]),
            e(2, b[2]),
            e(3, b[3]),
            e(4, b[4]),
            e(5, b[5]),
            wgpu::BindGroupEntry {
                binding: 6,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: stages,
                    offset: 0,
                    size: std::num::NonZeroU64::new(16),
                }),
            },
        ],
    })
}

impl BoxScratch {
    /// Sweep buffers for `bodies` bodies and the scratch's output capacity (re-made when either
    /// grew; kept otherwise).
    fn ensure_sweep(&mut self, ctx: &GpuContext, bodies: u32) -> Result<&SweepBuffers, GpuError> {
        match &mut self.sweep {
            Some(b) if b.ctx_id != ctx.id => return Err(GpuError::ForeignObject("BoxScratch")),
            Some(b) if b.body_cap >= bodies => {
                if b.output_cap != self.output_cap {
                    b.set_output(ctx, self.output_cap)?;
                }
            }
            _ => {
                let body_cap = bodies.next_power_of_two().max(BLOCK);
                self.sweep = Some(SweepBuffers::new(ctx, body_cap, self.output_cap)?);
            }
        }
        Ok(self.sweep.as_ref().expect("just set"))
    }
}

/// The axis along which the box centres spread most (finite, non-empty boxes only): sorting on
/// it keeps the scans short (a scene strung along y is swept along y).
fn sweep_axis(boxes: &[Aabb]) -> usize {
    let var = frcd_geom::centre_variance(boxes);
    (1..3).fold(0, |best, a| if var[a] > var[best] { a } else { best })
}

/// `b` with its `axis` component swapped into x (overlap does not depend on the axis order).
fn permuted(mut b: BodyBox, axis: usize) -> BodyBox {
    if axis != 0 {
        for v in [&mut b.lo_dn, &mut b.hi_up, &mut b.lo_up, &mut b.hi_dn] {
            v.swap(0, axis);
        }
    }
    b
}

impl GpuContext {
    /// The GPU broad phase with the form that is faster for the count: the all-pairs pass
    /// ([`GpuContext::overlapping_bodies_all_pairs`]) up to [`ALL_PAIRS_MAX_BODIES`] bodies,
    /// the sort-and-sweep ([`GpuContext::overlapping_bodies`]) above. The same answer either
    /// way; one submission and one readback.
    ///
    /// ```no_run
    /// # use frcd_gpgpu::{BoxScratch, GpuContext};
    /// # use frcd_geom::{Aabb, DVec3};
    /// let ctx = GpuContext::headless()?;
    /// let boxes: Vec<Aabb> = (0..64)
    ///     .map(|i| Aabb::new(DVec3::X * i as f64, DVec3::X * i as f64 + DVec3::splat(1.5)))
    ///     .collect();
    /// let found = ctx.broad_phase(&boxes, &mut BoxScratch::default())?;
    /// assert_eq!(found.pairs.len(), 63);
    /// # Ok::<(), frcd_gpgpu::GpuError>(())
    /// ```
    pub fn broad_phase(
        &self,
        boxes: &[Aabb],
        scratch: &mut BoxScratch,
    ) -> Result<BodyPairs, GpuError> {
        if boxes.len() <= ALL_PAIRS_MAX_BODIES {
            self.overlapping_bodies_all_pairs(boxes, scratch)
        } else {
            self.overlapping_bodies(boxes, scratch)
        }
    }

    /// Every pair of bodies whose world boxes overlap (closed boxes), on the GPU by sort-based
    /// sweep and prune in O(n log n + pairs): the boxes are rounded outward to f32 (and inward,
    /// for the "surely overlapping" test), bitonic-sorted by their minimum on the axis of
    /// largest spread, and each box scans forward while the next minimum is within its
    /// maximum. f32 rounding can only add candidates: a pair the f32 comparison cannot decide
    /// is re-checked in f64 on the CPU, so the answer equals the f64 all-pairs test
    /// ([`Aabb::intersects`], the CPU broad phase's set), sorted, `i < j`.
    ///
    /// One submission and one readback; an output overflow grows `scratch` to the count the
    /// GPU found and re-runs only the sweep pass (one more of each). A box scans at most
    /// 16,384 candidates per submission (a software driver such as llvmpipe silently ends a
    /// shader's loops after 65,535 iterations): a scene where one box's range on the sweep axis
    /// holds more takes one more submission and readback per 16,384. Boxes with NaN are an
    /// error; empty boxes overlap nothing.
    ///
    /// ```no_run
    /// # use frcd_gpgpu::{BoxScratch, GpuContext};
    /// # use frcd_geom::{Aabb, DVec3};
    /// let ctx = GpuContext::headless()?;
    /// let boxes: Vec<Aabb> = (0..1000)
    ///     .map(|i| Aabb::new(DVec3::X * i as f64, DVec3::X * i as f64 + DVec3::splat(1.5)))
    ///     .collect();
    /// let found = ctx.overlapping_bodies(&boxes, &mut BoxScratch::default())?;
    /// assert_eq!(found.pairs.len(), 999);
    /// # Ok::<(), frcd_gpgpu::GpuError>(())
    /// ```
    pub fn overlapping_bodies(
        &self,
        boxes: &[Aabb],
        scratch: &mut BoxScratch,
    ) -> Result<BodyPairs, GpuError> {
        check_boxes(boxes)?;
        let n = boxes.len();
        let mut answer = BodyPairs::default();
        if n < 2 {
            return Ok(answer);
        }
        let max_groups = self.limits.max_compute_workgroups_per_dimension as u64;
        let limit = (max_groups * WG as u64).min(UNCERTAIN_FLAG as u64);
        let padded = (n as u64).next_power_of_two().max(BLOCK as u64);
        if padded > limit {
            return Err(GpuError::CapacityExceeded {
                what: "bodies (workgroups per dimension)",
                needed: n as u64,
                limit,
            });
        }
        let axis = sweep_axis(boxes);
        let words: Vec<BodyBox> = boxes.iter().map(|b| permuted(body_box(b), axis)).collect();
        let mut sorted = false;
        // Sweep round (sweep.wgsl: a box's scan covers SWEEP_STEP candidates a round) and
        // output overflows so far.
        let mut round = 0u32;
        let mut overflows = 0;
        loop {
            let bufs = scratch.ensure_sweep(self, n as u32)?;
            let padded = bufs.body_cap;
            let steps = sort_steps(padded);
            let mut enc = self
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("frcd-gpgpu sweep"),
                });
            self.queue.write_buffer(
                &bufs.params,
                0,
                bytemuck::bytes_of(&BoxParams {
                    n: [n as u32, bufs.output_cap, padded, round],
                }),
            );
            if !sorted {
                self.queue
                    .write_buffer(&bufs.boxes, 0, bytemuck::cast_slice(&words));
                let stride = bufs.stride as usize;
                let mut table = vec![0u8; steps.len() * stride];
                for (s, &(_, k, j)) in steps.iter().enumerate() {
                    let st = SortStage { kj: [k, j, 0, 0] };
                    table[s * stride..s * stride + 16].copy_from_slice(bytemuck::bytes_of(&st));
                }
                self.queue.write_buffer(&bufs.stages, 0, &table);
            }
            if round == 0 {
                enc.clear_buffer(&bufs.count, 0, None);
            } else {
                // Later rounds append to the pairs found so far; only the flag restarts.
                enc.clear_buffer(&bufs.count, 4, Some(4));
            }
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("frcd-gpgpu sweep"),
                    timestamp_writes: None,
                });
                let mut run = |p: Pass, stage: usize, groups: u32| {
                    pass.set_pipeline(&self.pipes.sweep[p as usize]);
                    pass.set_bind_group(0, &bufs.bind, &[(stage as u64 * bufs.stride) as u32]);
                    pass.dispatch_workgroups(groups, 1, 1);
                };
                let body_groups = (n as u32).div_ceil(WG);
                if !sorted {
                    run(Pass::Keys, 0, padded / WG);
                    // Local: one workgroup per block of BLOCK keys; global: padded / 2
                    // compare-exchanges, WG per workgroup (BLOCK = 2 WG: the same count).
                    for (s, &(p, _, _)) in steps.iter().enumerate() {
                        run(p, s, padded / BLOCK);
                    }
                    run(Pass::Gather, 0, body_groups);
                }
                run(Pass::Sweep, 0, body_groups);
            }
            let out_bytes = bufs.output_cap as u64 * 8;
            enc.copy_buffer_to_buffer(&bufs.count, 0, &bufs.staging, 0, 8);
            enc.copy_buffer_to_buffer(&bufs.out, 0, &bufs.staging, 8, out_bytes);
            let index = self.submit(enc.finish());
            answer.submissions += 1;
            let bytes = self.read_back(&bufs.staging, 8 + out_bytes, index)?;
            answer.readbacks += 1;
            let entries: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
            let (count, more) = (entries[0], entries[1] != 0);
            if count > bufs.output_cap {
                overflows += 1;
                if overflows > MAX_RERUNS {
                    return Err(GpuError::Internal("box sweep keeps overflowing".into()));
                }
                // The body buffers (sorted keys and boxes) are kept: only the sweep re-runs,
                // from its first round, into an output buffer grown to the count the GPU found.
                scratch.output_cap = count.max(bufs.output_cap.saturating_mul(2));
                sorted = true;
                round = 0;
                continue;
            }
            if more {
                // A box reaches past this round's window (SWEEP_STEP candidates): the next
                // round scans on from there, adding to the pairs found.
                round += 1;
                sorted = true;
                continue;
            }
            let count = count as usize;
            decode(boxes, &entries[2..2 + 2 * count], &mut answer)?;
            return Ok(answer);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// CPU model of the sort network: sorting any input with the steps of `sort_steps` (with
    /// the local steps expanded as sweep.wgsl does) yields a sorted array.
    #[test]
    fn the_sort_network_sorts() {
        for padded in [128u32, 256, 1024, 4096] {
            let mut v: Vec<u64> = (0..padded as u64)
                .map(|i| (i * 2_654_435_761) % 1000)
                .collect();
            let cx = |v: &mut Vec<u64>, k: u32, j: u32, t: u32| {
                let i = 2 * j * (t / j) + t % j;
                let l = i + j;
                let up = (i & k) == 0;
                let (a, b) = (v[i as usize], v[l as usize]);
                if (b < a) == up {
                    v.swap(i as usize, l as usize);
                }
            };
            for (p, k, j) in sort_steps(padded) {
                match (p, k) {
                    (Pass::Local, 0) => {
                        let mut kk = 2;
                        while kk <= BLOCK {
                            let mut jj = kk / 2;
                            while jj > 0 {
                                for t in 0..padded / 2 {
                                    cx(&mut v, kk, jj, t);
                                }
                                jj /= 2;
                            }
                            kk *= 2;
                        }
                    }
                    (Pass::Local, k) => {
                        let mut jj = BLOCK / 2;
                        while jj > 0 {
                            for t in 0..padded / 2 {
                                cx(&mut v, k, jj, t);
                            }
                            jj /= 2;
                        }
                    }
                    _ => {
                        for t in 0..padded / 2 {
                            cx(&mut v, k, j, t);
                        }
                    }
                }
            }
            assert!(v.windows(2).all(|w| w[0] <= w[1]), "padded {padded}");
        }
    }

    #[test]
    fn the_axis_of_largest_spread_is_swept() {
        let line = |d: frcd_geom::DVec3| -> Vec<Aabb> {
            (0..50)
                .map(|i| Aabb::new(d * i as f64, d * i as f64 + frcd_geom::DVec3::ONE))
                .collect()
        };
        assert_eq!(sweep_axis(&line(frcd_geom::DVec3::X)), 0);
        assert_eq!(sweep_axis(&line(frcd_geom::DVec3::Y)), 1);
        assert_eq!(sweep_axis(&line(frcd_geom::DVec3::Z)), 2);
        assert_eq!(sweep_axis(&[Aabb::EMPTY, Aabb::EMPTY]), 0);
    }
}
