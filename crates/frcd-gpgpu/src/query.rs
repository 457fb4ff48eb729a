use crate::{GpuContext, GpuError, GpuMesh};
use frcd_geom::Pose;
use frcd_obb::RelativeFrame;
use frcd_tritri::Method;

/// Bit 31 of an output entry's second word: the GPU could not decide the pair.
const UNCERTAIN_FLAG: u32 = 0x8000_0000;
/// Bytes of the `State` struct shared with the shaders.
const STATE_BYTES: u64 = 32;
/// Re-runs allowed after overflows before giving up (each at least doubles a buffer).
const MAX_RERUNS: u32 = 32;

/// The answer of [`GpuContext::collide`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct GpuCollision {
    /// Every touching triangle pair `(tri_a, tri_b)` (input-mesh indices), sorted ascending:
    /// equal to the exact oracle's answer (surface mode).
    pub pairs: Vec<(u32, u32)>,
    /// Pairs the GPU decided on its own (all of them touching).
    pub gpu_decided: usize,
    /// Pairs the GPU flagged uncertain, re-decided on the CPU with the exact test.
    pub uncertain: usize,
    /// Node pairs the GPU tested (separating-axis tests).
    pub node_pairs_tested: u64,
    /// Traversal levels that had work.
    pub levels: u32,
    /// Command-buffer submissions this query made (1 unless a buffer overflowed).
    pub submissions: u32,
    /// Readbacks this query made (1 unless a buffer overflowed).
    pub readbacks: u32,
    /// Re-runs after an overflow.
    pub reruns: u32,
}

impl GpuCollision {
    /// True when some triangle pair touches.
    pub fn collide(&self) -> bool {
        !self.pairs.is_empty()
    }
}

struct Buffers {
    ctx_id: u64,
    frontier_cap: u32,
    output_cap: u32,
    // `frontier` and `params` are reached through the bind groups; kept here to own them.
    #[allow(dead_code)]
    frontier: [wgpu::Buffer; 2],
    state: wgpu::Buffer,
    args: wgpu::Buffer,
    out: wgpu::Buffer,
    #[allow(dead_code)]
    params: wgpu::Buffer,
    pose: wgpu::Buffer,
    staging: wgpu::Buffer,
    trav_bg: [wgpu::BindGroup; 2],
    ctrl_bg: wgpu::BindGroup,
    /// Bind group of the last mesh pair, keyed by mesh ids.
    mesh_bg: Option<((u64, u64), wgpu::BindGroup)>,
}

/// Caller-owned GPU buffers of pair queries (frontiers, output, staging), grown on overflow and
/// kept for the next query. One per thread issuing queries; tied to the first context it is
/// used with.
pub struct QueryScratch {
    frontier_cap: u32,
    output_cap: u32,
    bufs: Option<Buffers>,
}

impl Default for QueryScratch {
    fn default() -> Self {
        Self::with_capacity(1 << 14, 1 << 12)
    }
}

impl std::fmt::Debug for QueryScratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("QueryScratch")
            .field("frontier_capacity", &self.frontier_cap)
            .field("output_capacity", &self.output_cap)
            .finish()
    }
}

impl QueryScratch {
    /// Scratch whose first buffers hold `frontier` node pairs per level and `output` triangle
    /// pairs (at least 1 each). Too small is only slower: overflow re-runs the query.
    pub fn with_capacity(frontier: u32, output: u32) -> Self {
        Self {
            frontier_cap: frontier.max(1),
            output_cap: output.max(1),
            bufs: None,
        }
    }

    /// Current capacities `(frontier pairs per level, output pairs)`.
    pub fn capacity(&self) -> (u32, u32) {
        (self.frontier_cap, self.output_cap)
    }

    fn ensure(&mut self, ctx: &GpuContext) -> Result<(), GpuError> {
        if let Some(b) = &self.bufs {
            if b.ctx_id != ctx.id {
                return Err(GpuError::ForeignObject("QueryScratch"));
            }
            if b.frontier_cap == self.frontier_cap && b.output_cap == self.output_cap {
                return Ok(());
            }
        }
        // A level dispatches ceil(n / 64) workgroups as an x × y grid.
        let groups = ctx.limits.max_compute_workgroups_per_dimension as u64;
        let dispatchable = crate::context::WG as u64 * groups * groups;
        if self.frontier_cap as u64 > dispatchable {
            return Err(GpuError::CapacityExceeded {
                what: "frontier (workgroups per dimension squared)",
                needed: self.frontier_cap as u64,
                limit: dispatchable,
            });
        }
        ctx.check_storage(&[
            ("frontier", self.frontier_cap as u64 * 8),
            ("output", self.output_cap as u64 * 8),
        ])?;
        use wgpu::BufferUsages as B;
        let d = &ctx.device;
        let buf = |label: &str, size: u64, usage: B| ctx.buffer(label, size, usage);
        let fsize = self.frontier_cap as u64 * 8;
        let osize = self.output_cap as u64 * 8;
        let frontier = [
            buf("frcd-gpgpu frontier 0", fsize, B::STORAGE),
            buf("frcd-gpgpu frontier 1", fsize, B::STORAGE),
        ];
        let state = buf("frcd-gpgpu state", STATE_BYTES, B::STORAGE | B::COPY_SRC);
        let args = buf("frcd-gpgpu indirect args", 16, B::STORAGE | B::INDIRECT);
        let out = buf("frcd-gpgpu output", osize, B::STORAGE | B::COPY_SRC);
        let params = buf("frcd-gpgpu params", 16, B::UNIFORM | B::COPY_DST);
        let pose = buf("frcd-gpgpu pose", 64, B::UNIFORM | B::COPY_DST);
        let staging = buf(
            "frcd-gpgpu staging",
            STATE_BYTES + osize,
            B::MAP_READ | B::COPY_DST,
        );
        let max_groups = ctx.limits.max_compute_workgroups_per_dimension;
        ctx.queue.write_buffer(
            &params,
            0,
            bytemuck::cast_slice(&[self.frontier_cap, self.output_cap, max_groups, 0]),
        );
        let trav = |input: &wgpu::Buffer, output: &wgpu::Buffer| {
            d.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("frcd-gpgpu traversal"),
                layout: &ctx.pipes.trav_bgl,
                entries: &[
                    crate::context::entry(0, input),
                    crate::context::entry(1, output),
                    crate::context::entry(2, &state),
                    crate::context::entry(3, &out),
                    crate::context::entry(4, &params),
                ],
            })
        };
        let trav_bg = [
            trav(&frontier[0], &frontier[1]),
            trav(&frontier[1], &frontier[0]),
        ];
        let ctrl_bg = d.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("frcd-gpgpu control"),
            layout: &ctx.pipes.ctrl_bgl,
            entries: &[
                crate::context::entry(0, &state),
                crate::context::entry(1, &args),
                crate::context::entry(2, &frontier[0]),
                crate::context::entry(3, &params),
            ],
        });
        self.bufs = Some(Buffers {
            ctx_id: ctx.id,
            frontier_cap: self.frontier_cap,
            output_cap: self.output_cap,
            frontier,
            state,
            args,
            out,
            params,
            pose,
            staging,
            trav_bg,
            ctrl_bg,
            mesh_bg: None,
        });
        Ok(())
    }
}

/// The relative pose as the shader's uniform: rows of R, then t (f32, rounded to nearest; the
/// shaders' error bounds include this rounding).
fn pose_words(frame: &RelativeFrame) -> [f32; 16] {
    let m = frame.m;
    let row = |k: usize| {
        [
            m.x_axis[k] as f32,
            m.y_axis[k] as f32,
            m.z_axis[k] as f32,
            0.0,
        ]
    };
    let (r0, r1, r2) = (row(0), row(1), row(2));
    let t = frame.t;
    [
        r0[0], r0[1], r0[2], 0.0, r1[0], r1[1], r1[2], 0.0, r2[0], r2[1], r2[2], 0.0, t.x as f32,
        t.y as f32, t.z as f32, 0.0,
    ]
}

impl GpuContext {
    /// Every touching triangle pair of two uploaded meshes at two poses (surface mode), equal to
    /// [`frcd_obb::oracle::pairs`]. One submission and one readback, unless a buffer of
    /// `scratch` overflows: then the query is re-run with larger buffers (counted in the answer).
    pub fn collide(
        &self,
        a: &GpuMesh,
        pose_a: &Pose,
        b: &GpuMesh,
        pose_b: &Pose,
        scratch: &mut QueryScratch,
    ) -> Result<GpuCollision, GpuError> {
        for m in [a, b] {
            if m.ctx_id != self.id {
                return Err(GpuError::ForeignObject("GpuMesh"));
            }
        }
        for (name, p) in [("pose_a", pose_a), ("pose_b", pose_b)] {
            if !p.is_valid() {
                return Err(GpuError::InvalidInput(format!(
                    "{name} is not finite or its rotation is not a unit quaternion: {p:?}"
                )));
            }
        }
        let frame = RelativeFrame::new(pose_a, pose_b);
        let levels = a.depth.max(b.depth);
        let mut answer = GpuCollision::default();
        let words = loop {
            scratch.ensure(self)?;
            let bufs = scratch.bufs.as_mut().expect("ensured");
            let key = (a.id, b.id);
            if bufs.mesh_bg.as_ref().map(|(k, _)| *k) != Some(key) {
                let bg = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("frcd-gpgpu meshes"),
                    layout: &self.pipes.mesh_bgl,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: wgpu::BindingResource::TextureView(&a.node_view),
                        },
                        wgpu::BindGroupEntry {
                            binding: 1,
                            resource: wgpu::BindingResource::TextureView(&a.tri_view),
                        },
                        wgpu::BindGroupEntry {
                            binding: 2,
                            resource: wgpu::BindingResource::TextureView(&b.node_view),
                        },
                        wgpu::BindGroupEntry {
                            binding: 3,
                            resource: wgpu::BindingResource::TextureView(&b.tri_view),
                        },
                        wgpu::BindGroupEntry {
                            binding: 4,
                            resource: a.info.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 5,
                            resource: b.info.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 6,
                            resource: bufs.pose.as_entire_binding(),
                        },
                    ],
                });
                bufs.mesh_bg = Some((key, bg));
            }
            // The only per-query upload: the relative pose (64 bytes).
            self.queue
                .write_buffer(&bufs.pose, 0, bytemuck::cast_slice(&pose_words(&frame)));
            let mut enc = self
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("frcd-gpgpu query"),
                });
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("frcd-gpgpu traversal"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(&self.pipes.init);
                pass.set_bind_group(0, &bufs.ctrl_bg, &[]);
                pass.dispatch_workgroups(1, 1, 1);
                let mesh_bg = &bufs.mesh_bg.as_ref().expect("set above").1;
                // `init` put the root pair in frontier 0; level k reads frontier k % 2.
                for level in 0..levels as usize {
                    pass.set_pipeline(&self.pipes.traverse);
                    pass.set_bind_group(0, mesh_bg, &[]);
                    pass.set_bind_group(1, &bufs.trav_bg[level % 2], &[]);
                    pass.dispatch_workgroups_indirect(&bufs.args, 0);
                    pass.set_pipeline(&self.pipes.prepare);
                    pass.set_bind_group(0, &bufs.ctrl_bg, &[]);
                    pass.dispatch_workgroups(1, 1, 1);
                }
            }
            enc.copy_buffer_to_buffer(&bufs.state, 0, &bufs.staging, 0, STATE_BYTES);
            let out_bytes = bufs.output_cap as u64 * 8;
            enc.copy_buffer_to_buffer(&bufs.out, 0, &bufs.staging, STATE_BYTES, out_bytes);
            self.submit(enc.finish());
            answer.submissions += 1;
            let bytes = self.read_back(&bufs.staging, STATE_BYTES + out_bytes)?;
            answer.readbacks += 1;
            let words: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
            let (cur, out_count, needed) = (words[0], words[2], words[3]);
            let mut rerun = false;
            if needed > bufs.frontier_cap {
                scratch.frontier_cap = needed.max(bufs.frontier_cap.saturating_mul(2));
                rerun = true;
            }
            if out_count > bufs.output_cap {
                scratch.output_cap = out_count.max(bufs.output_cap.saturating_mul(2));
                rerun = true;
            }
            if rerun {
                log::debug!(
                    "frcd-gpgpu: overflow (frontier {needed}/{}, output {out_count}/{}), re-running",
                    bufs.frontier_cap,
                    bufs.output_cap
                );
                answer.reruns += 1;
                if answer.reruns > MAX_RERUNS {
                    return Err(GpuError::Internal(format!(
                        "still overflowing after {MAX_RERUNS} re-runs"
                    )));
                }
                continue;
            }
            if cur != 0 {
                return Err(GpuError::Internal(format!(
                    "{cur} node pairs left after {levels} levels (tree depths {} and {})",
                    a.depth, b.depth
                )));
            }
            answer.levels = words[4];
            answer.node_pairs_tested = words[5] as u64;
            break words;
        };
        let out_count = words[2] as usize;
        let entries = &words[(STATE_BYTES / 4) as usize..][..out_count * 2];
        let mut pairs = Vec::with_capacity(out_count);
        for e in entries.chunks_exact(2) {
            let (ia, tag) = (e[0], e[1]);
            let ib = tag & !UNCERTAIN_FLAG;
            let (ta, tb) = match (a.triangles.get(ia as usize), b.triangles.get(ib as usize)) {
                (Some(ta), Some(tb)) => (ta, tb),
                _ => {
                    return Err(GpuError::Internal(format!(
                        "triangle pair ({ia}, {ib}) out of range"
                    )));
                }
            };
            if tag & UNCERTAIN_FLAG == 0 {
                answer.gpu_decided += 1;
                pairs.push((ia, ib));
            } else {
                answer.uncertain += 1;
                if frcd_tritri::intersects(Method::Exact, ta, &frame.triangle(tb)) {
                    pairs.push((ia, ib));
                }
            }
        }
        pairs.sort_unstable();
        let before = pairs.len();
        pairs.dedup();
        if pairs.len() != before {
            return Err(GpuError::Internal(
                "a triangle pair was reported twice".into(),
            ));
        }
        answer.pairs = pairs;
        Ok(answer)
    }
}
