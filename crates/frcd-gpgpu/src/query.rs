use crate::{GpuContext, GpuError, GpuMesh};
use frcd_geom::{DVec3, Pose, TriMesh, Triangle};
use frcd_gpu::layout::{Level, PairInfo, Params, State};
use frcd_obb::RelativeFrame;
use frcd_tritri::Method;
use std::sync::Arc;

/// Bit 31 of a frontier entry's node word: the node itself, not its first child
/// (`traverse.wgsl`).
pub(crate) const ONE_NODE: u32 = 0x8000_0000;
/// Bit 31 of an output entry's third word: the GPU could not decide the pair.
const UNCERTAIN_FLAG: u32 = 0x8000_0000;
/// Bytes of the `State` struct shared with the shaders (prelude).
const STATE_BYTES: u64 = std::mem::size_of::<State>() as u64;
/// Byte offset of `State::tri_args`, the triangle pass's indirect arguments.
const TRI_ARGS_OFFSET: u64 = std::mem::offset_of!(State, tri_args) as u64;
/// Bytes of the `Level` uniform (prelude).
const LEVEL_BYTES: u64 = std::mem::size_of::<Level>() as u64;
/// Bytes of one frontier or output entry (`vec4<u32>`).
const ENTRY_BYTES: u64 = 16;
/// Bytes of the `Params` uniform (prelude).
const PARAMS_BYTES: u64 = std::mem::size_of::<Params>() as u64;
/// Bytes of one `PairInfo` (prelude).
const PAIR_BYTES: u64 = std::mem::size_of::<PairInfo>() as u64;
/// Pairs per row of the pose texture (`traverse.wgsl`'s `poses`: five rgba32uint texels each,
/// 1,280 texels a row, within every device's 2D texture limit).
const POSE_PAIRS_PER_ROW: u32 = 256;
/// Texels per pair in the pose texture.
const POSE_TEXELS: u32 = 5;
/// Bytes of one full row of the pose texture.
const POSE_ROW_BYTES: usize = (POSE_PAIRS_PER_ROW * POSE_TEXELS * 16) as usize;
/// Re-runs allowed after overflows before giving up (each at least doubles a buffer).
const MAX_RERUNS: u32 = 32;
/// Timestamps one batch may write with pass timers on: pass start, after each level, after
/// the triangle pass. A deeper batch (levels + 2 above this) is not timed.
const MAX_TIMERS: u32 = 64;
/// Bytes of the timestamps in the staging buffer (between the state and the output).
const TIMER_BYTES: u64 = MAX_TIMERS as u64 * 8;

/// The answer for one body pair ([`GpuContext::collide`], or one entry of
/// [`GpuBatch::results`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct GpuCollision {
    /// Every touching triangle pair `(tri_a, tri_b)` (input-mesh indices), sorted ascending:
    /// equal to the exact oracle's answer (surface mode).
    pub pairs: Vec<(u32, u32)>,
    /// Pairs the GPU decided as touching and the CPU's exact re-check confirmed (with
    /// [`crate::Recheck::Uncertain`]: taken without a re-check).
    pub gpu_decided: usize,
    /// Pairs the GPU decided as touching that the CPU's exact re-check found disjoint (dropped
    /// from [`GpuCollision::pairs`]; 0 unless a driver breaks the certified bounds).
    pub gpu_refuted: usize,
    /// Pairs the GPU flagged uncertain, decided on the CPU with the exact test.
    pub uncertain: usize,
    /// The triangle pass took the exact reference-point path for this body pair (the offset
    /// `R c_B + t - c_A` of the triangles' reference points in integer arithmetic, see
    /// [`GpuContext::set_exact_offsets`]); false: the rotated path (the option is off, or the
    /// pair's integer ranges cannot hold: A's mesh below the grid's range, A's grid more than
    /// 2^46 below B's, or a translation too large).
    pub exact_offsets: bool,
    /// Node pairs the GPU's traversal took up, for the whole batch: four per frontier entry,
    /// the child pairs of a pair of overlapping nodes (a leaf has no second child: those
    /// pairs are not tested, and are counted).
    pub node_pairs_tested: u64,
    /// Traversal levels that had work, for the whole batch.
    pub levels: u32,
    /// Command-buffer submissions the batch made (1 unless a buffer overflowed; 0 when the
    /// commands were recorded into the caller's encoder and did not overflow).
    pub submissions: u32,
    /// Readbacks the batch made (1 unless a buffer overflowed).
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

/// The answer of [`GpuContext::collide_batch`]: one [`GpuCollision`] per body pair, in input
/// order, plus the batch's counters. Equality compares the answers and counters, not
/// [`GpuBatch::timings`] (two runs of one batch are equal).
#[derive(Clone, Debug, Default)]
pub struct GpuBatch {
    /// One answer per body pair, in input order.
    pub results: Vec<GpuCollision>,
    /// Node pairs the GPU's traversal took up (see [`GpuCollision::node_pairs_tested`]).
    pub node_pairs_tested: u64,
    /// Traversal levels that had work.
    pub levels: u32,
    /// Levels of the pair trees the CPU descended before the GPU's first
    /// ([`GpuContext::set_host_front`]; 0 when off).
    pub host_levels: u32,
    /// Submissions made by frcd-gpgpu for this batch (1; 0 when recorded into the caller's
    /// encoder; plus one per overflow re-run).
    pub submissions: u32,
    /// Readbacks (1 plus one per overflow re-run).
    pub readbacks: u32,
    /// Re-runs after an overflow.
    pub reruns: u32,
    /// Where the batch's time went (wall-clock on the host; GPU passes with pass timers).
    pub timings: BatchTimings,
}

impl PartialEq for GpuBatch {
    fn eq(&self, other: &Self) -> bool {
        // Destructured so that a new field is a compile error here, not silently ignored.
        let Self {
            results,
            node_pairs_tested,
            levels,
            host_levels,
            submissions,
            readbacks,
            reruns,
            timings: _,
        } = self;
        *results == other.results
            && *node_pairs_tested == other.node_pairs_tested
            && *levels == other.levels
            && *host_levels == other.host_levels
            && *submissions == other.submissions
            && *readbacks == other.readbacks
            && *reruns == other.reruns
    }
}

impl Eq for GpuBatch {}

/// Where a batch's time went. The host times are wall-clock; the `gpu_*` times come from GPU
/// timestamps and are only filled when the context has pass timers
/// ([`GpuContext::enable_pass_timers`], [`crate::HeadlessOptions::pass_timers`]).
///
/// ```no_run
/// # fn main() -> Result<(), frcd_gpgpu::GpuError> {
/// let ctx = frcd_gpgpu::GpuContext::headless_with(&frcd_gpgpu::HeadlessOptions {
///     pass_timers: true,
///     ..Default::default()
/// })?;
/// # let batch: Vec<frcd_gpgpu::BodyPair<'_>> = Vec::new();
/// let mut scratch = frcd_gpgpu::QueryScratch::default();
/// let t = ctx.collide_batch(&batch, &mut scratch)?.timings;
/// println!(
///     "waited {:?} (GPU: levels {:?}, triangles {:?}), CPU re-decision {:?}",
///     t.wait, t.gpu_levels, t.gpu_triangles, t.decide
/// );
/// # Ok(()) }
/// ```
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct BatchTimings {
    /// From the start of the readback (just after frcd-gpgpu's submission, or when
    /// [`PendingBatch::resolve`] is called) until the answer's bytes are on the host: the GPU
    /// work, the copy and the map; summed over overflow re-runs.
    pub wait: std::time::Duration,
    /// The CPU's part after the readback: decoding, the exact re-decision of every reported
    /// triangle pair, sorting.
    pub decide: std::time::Duration,
    /// The CPU's descent of the top of the pair trees before the submission
    /// ([`GpuContext::set_host_front`]; zero when off).
    pub host_front: std::time::Duration,
    /// GPU time of each traversal level (the level's test and the next level's arguments), in
    /// order; empty without pass timers. Levels past the last with work take almost nothing.
    pub gpu_levels: Vec<std::time::Duration>,
    /// GPU time of the triangle pass (its arguments and the tests); `None` without pass timers.
    pub gpu_triangles: Option<std::time::Duration>,
    /// GPU time of the whole dispatch chain, first timestamp to last; `None` without pass
    /// timers.
    pub gpu_total: Option<std::time::Duration>,
}

/// One body pair of a batch: `(mesh_a, pose_a, mesh_b, pose_b)`.
pub type BodyPair<'a> = (&'a GpuMesh, &'a Pose, &'a GpuMesh, &'a Pose);

struct Buffers {
    ctx_id: u64,
    frontier_cap: u32,
    output_cap: u32,
    tri_cap: u32,
    pair_cap: u32,
    frontier: [wgpu::Buffer; 2],
    state: wgpu::Buffer,
    /// Indirect arguments of the traversal levels, by level mod 3 (level L dispatches with
    /// `args[L % 3]`, raises `args[(L + 1) % 3]` and resets `args[(L + 2) % 3]`); `args[0]`
    /// also holds the triangle pass's.
    args: [wgpu::Buffer; 3],
    out: wgpu::Buffer,
    params: wgpu::Buffer,
    pairs: wgpu::Buffer,
    /// The pairs' f32 poses and arena bases as texels (both passes read them there).
    poses: wgpu::Texture,
    staging: wgpu::Buffer,
    /// Pass timers: the timestamp queries and the buffer they resolve into.
    timers: Option<(wgpu::QuerySet, wgpu::Buffer)>,
    /// Byte offset of the output in the staging buffer (after the state and the timestamps).
    out_offset: u64,
    /// Level L's bind group is `trav_bg[L % 6]` (frontiers by L mod 2, arguments and
    /// counters by L mod 3).
    trav_bg: [wgpu::BindGroup; 6],
    /// The triangle pass: triangle list in, output out.
    tri_bg: wgpu::BindGroup,
    /// The one-pass traversal's bindings (its two frontier halves: one buffer of twice the
    /// frontier's capacity), made when the context runs it ([`GpuContext::set_one_pass`]).
    one_pass: Option<(wgpu::Buffer, wgpu::BindGroup)>,
}

/// Caller-owned GPU buffers of pair queries (frontiers, output, pair table, staging), sized by
/// capacity, grown on overflow and kept for the next frame. One per thread issuing queries;
/// tied to the first context it is used with.
pub struct QueryScratch {
    frontier_cap: u32,
    output_cap: u32,
    /// Triangle pairs of overlapping leaves, listed for the triangle pass.
    tri_cap: u32,
    pair_cap: u32,
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
            .field("triangle_list_capacity", &self.tri_cap)
            .field("pair_capacity", &self.pair_cap)
            .finish()
    }
}

impl QueryScratch {
    /// Scratch whose first buffers hold `frontier` node pairs per level and `output` triangle
    /// pairs (at least 1 each); the list of triangle pairs to test starts at four times the
    /// frontier. Too small is only slower: overflow re-runs the batch.
    pub fn with_capacity(frontier: u32, output: u32) -> Self {
        Self {
            frontier_cap: frontier.max(1),
            output_cap: output.max(1),
            tri_cap: frontier.max(1).saturating_mul(4),
            pair_cap: 16,
            bufs: None,
        }
    }

    /// Current capacities `(frontier pairs per level, output pairs)`.
    pub fn capacity(&self) -> (u32, u32) {
        (self.frontier_cap, self.output_cap)
    }

    fn ensure(&mut self, ctx: &GpuContext, pairs: u32, roots: u32) -> Result<(), GpuError> {
        self.pair_cap = self.pair_cap.max(pairs.next_power_of_two());
        self.frontier_cap = self.frontier_cap.max(roots);
        if let Some(b) = &self.bufs {
            if b.ctx_id != ctx.id {
                return Err(GpuError::ForeignObject("QueryScratch"));
            }
            if b.frontier_cap == self.frontier_cap
                && b.output_cap == self.output_cap
                && b.tri_cap == self.tri_cap
                && b.pair_cap == self.pair_cap
                && b.timers.is_some() == ctx.pass_timers
                && b.one_pass.is_some() == (ctx.one_pass > 0)
            {
                return Ok(());
            }
        }
        // A level (and the triangle pass) dispatches ceil(n / 64) workgroups as an x × y grid:
        // the capacities stop at what one dispatch can cover, which keeps every indirect
        // argument within the device's limits (the context skips wgpu's validation of them);
        // `run` refuses a batch that needs more.
        // (The one-pass traversal dispatches a fixed number of workgroups: no such bound.)
        if ctx.one_pass == 0 {
            let most = dispatchable(ctx);
            // A level runs one invocation per frontier entry.
            self.frontier_cap = self.frontier_cap.min(most);
            self.tri_cap = self.tri_cap.min(most);
        }
        let fsize = self.frontier_cap as u64 * ENTRY_BYTES;
        let osize = self.output_cap as u64 * ENTRY_BYTES;
        let tsize = self.tri_cap as u64 * ENTRY_BYTES;
        let psize = self.pair_cap as u64 * PAIR_BYTES;
        ctx.check_storage(&[
            ("frontier", fsize),
            ("output", osize),
            ("triangle list", tsize),
            ("pair table", psize),
            (
                "one-pass frontier halves",
                if ctx.one_pass > 0 { 2 * fsize } else { 0 },
            ),
        ])?;
        use wgpu::BufferUsages as B;
        let d = &ctx.device;
        let buf = |label: &str, size: u64, usage: B| ctx.buffer(label, size, usage);
        let frontier = [
            buf("frcd-gpgpu frontier 0", fsize, B::STORAGE | B::COPY_DST),
            buf("frcd-gpgpu frontier 1", fsize, B::STORAGE),
        ];
        let state = buf(
            "frcd-gpgpu state",
            STATE_BYTES,
            B::STORAGE | B::COPY_SRC | B::COPY_DST,
        );
        let args = [0, 1, 2].map(|k| {
            buf(
                &format!("frcd-gpgpu indirect args {k}"),
                16,
                B::STORAGE | B::INDIRECT | B::COPY_DST,
            )
        });
        // Which counters and arguments a level uses, one uniform per level mod 3.
        let level = [0u32, 1, 2].map(|k| {
            let b = buf("frcd-gpgpu level", LEVEL_BYTES, B::UNIFORM | B::COPY_DST);
            let slots = Level {
                slots: [k, (k + 1) % 3, (k + 2) % 3, 0],
            };
            ctx.queue.write_buffer(&b, 0, bytemuck::bytes_of(&slots));
            b
        });
        let out = buf("frcd-gpgpu output", osize, B::STORAGE | B::COPY_SRC);
        let tris = buf("frcd-gpgpu triangle list", tsize, B::STORAGE);
        let params = buf("frcd-gpgpu params", PARAMS_BYTES, B::UNIFORM | B::COPY_DST);
        let pairs = buf("frcd-gpgpu pair table", psize, B::STORAGE | B::COPY_DST);
        // `prepare` refused batches with more rows than the device's 2D textures hold.
        let pose_rows = self
            .pair_cap
            .div_ceil(POSE_PAIRS_PER_ROW)
            .min(ctx.limits.max_texture_dimension_2d)
            .max(1);
        let poses = d.create_texture(&wgpu::TextureDescriptor {
            label: Some("frcd-gpgpu poses"),
            size: wgpu::Extent3d {
                width: POSE_PAIRS_PER_ROW * POSE_TEXELS,
                height: pose_rows,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba32Uint,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let poses_view = poses.create_view(&wgpu::TextureViewDescriptor::default());
        let timers = ctx.pass_timers.then(|| {
            let set = d.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("frcd-gpgpu pass timers"),
                ty: wgpu::QueryType::Timestamp,
                count: MAX_TIMERS,
            });
            let resolved = buf(
                "frcd-gpgpu pass timers",
                TIMER_BYTES,
                B::QUERY_RESOLVE | B::COPY_SRC,
            );
            (set, resolved)
        });
        let out_offset = STATE_BYTES + if timers.is_some() { TIMER_BYTES } else { 0 };
        let staging = buf(
            "frcd-gpgpu staging",
            out_offset + osize,
            B::MAP_READ | B::COPY_DST,
        );
        let trav = |input: &wgpu::Buffer, output: &wgpu::Buffer, list: &wgpu::Buffer, k: usize| {
            d.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("frcd-gpgpu traversal"),
                layout: &ctx.pipes.trav_bgl,
                entries: &[
                    crate::context::entry(0, input),
                    crate::context::entry(1, output),
                    crate::context::entry(2, &state),
                    crate::context::entry(3, list),
                    crate::context::entry(4, &params),
                    crate::context::entry(5, &pairs),
                    crate::context::entry(6, &args[(k + 1) % 3]),
                    crate::context::entry(7, &args[(k + 2) % 3]),
                    crate::context::entry(8, &level[k]),
                    wgpu::BindGroupEntry {
                        binding: 9,
                        resource: wgpu::BindingResource::TextureView(&poses_view),
                    },
                ],
            })
        };
        let trav_bg = [0, 1, 2, 3, 4, 5].map(|l| {
            let (input, output) = (&frontier[l % 2], &frontier[(l + 1) % 2]);
            trav(input, output, &tris, l % 3)
        });
        // The triangle pass reads the list and writes the output, dispatched with `args[0]`;
        // its bindings 3 and 6-8 are unused (buffers other than `args[0]` fill the layout).
        let tri_bg = trav(&tris, &out, &frontier[0], 0);
        let one_pass = (ctx.one_pass > 0).then(|| {
            let halves = buf("frcd-gpgpu one-pass frontier halves", 2 * fsize, B::STORAGE);
            let bg = d.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("frcd-gpgpu one-pass traversal"),
                layout: &ctx.pipes.one_pass_bgl,
                entries: &[
                    crate::context::entry(0, &frontier[0]),
                    crate::context::entry(2, &state),
                    crate::context::entry(3, &tris),
                    crate::context::entry(4, &params),
                    crate::context::entry(5, &pairs),
                    wgpu::BindGroupEntry {
                        binding: 9,
                        resource: wgpu::BindingResource::TextureView(&poses_view),
                    },
                    crate::context::entry(10, &halves),
                    crate::context::entry(11, &out),
                ],
            });
            (halves, bg)
        });
        self.bufs = Some(Buffers {
            ctx_id: ctx.id,
            frontier_cap: self.frontier_cap,
            output_cap: self.output_cap,
            tri_cap: self.tri_cap,
            pair_cap: self.pair_cap,
            frontier,
            state,
            args,
            out,
            params,
            pairs,
            poses,
            staging,
            timers,
            out_offset,
            trav_bg,
            tri_bg,
            one_pass,
        });
        Ok(())
    }
}

/// The frontier capacity a level runs with: the scratch's, held below 2^31 / (4 ×
/// `leaf_pairs`) so that one level's triangle pairs (up to four leaf pairs per entry, each of up
/// to `leaf_pairs` triangle pairs) stay below 2^31 and the list's counter never wraps.
fn level_cap(frontier_cap: u32, leaf_pairs: u64) -> u32 {
    let wrap = ((1u64 << 31) - 1) / (4 * leaf_pairs.max(1));
    (frontier_cap as u64).min(wrap) as u32
}

/// The x × y grid of 64-invocation workgroups for `m` invocations: ceil(m / 64) workgroups,
/// x = min(groups, `max_groups`), y = ceil(groups / x) (0 × 0 for none); the shaders' `grid_x`
/// and their raises of the next pass's arguments use the same formula.
fn grid_args(m: u32, max_groups: u32) -> [u32; 2] {
    let groups = m.div_ceil(crate::context::WG);
    let x = groups.min(max_groups);
    [x, if x > 0 { groups.div_ceil(x) } else { 0 }]
}

/// Entries one x × y dispatch of 64-invocation workgroups covers on `ctx`'s device (at most
/// `u32::MAX`).
fn dispatchable(ctx: &GpuContext) -> u32 {
    let groups = ctx.limits.max_compute_workgroups_per_dimension as u64;
    (crate::context::WG as u64 * groups * groups).min(u32::MAX as u64) as u32
}

/// The two meshes of a pair (shared with their trees, not copied), for the exact re-decision.
type TrianglePair = (Arc<TriMesh>, Arc<TriMesh>);

/// A batch checked and converted for the GPU; independent of the meshes' lifetimes.
struct Prepared {
    /// One `PairInfo` per pair.
    infos: Vec<PairInfo>,
    /// Per pair, the bound on both meshes' axes' deviation from orthonormal (the pose texture's
    /// fifth texel).
    eps: Vec<f32>,
    frames: Vec<RelativeFrame>,
    tris: Vec<TrianglePair>,
    levels: u32,
    /// Most triangle pairs one leaf pair of the batch lists.
    leaf_pairs: u64,
    /// The triangle pass's exact path is on ([`GpuContext::set_exact_offsets`]).
    exact: bool,
    /// The first level's entries (the roots, or the CPU's front: `front.rs`).
    roots: Vec<[u32; 4]>,
    /// Workgroups of the one-pass traversal, 0 for the level chain ([`GpuContext::set_one_pass`]);
    /// set to 0 when a one-pass run ran out of its loop budget (`ONE_PASS_LOOP_BUDGET`), so the
    /// re-run takes the level chain.
    one_pass: u32,
    /// Box tests the CPU made descending the front, and the time it took.
    host_tests: u64,
    host_steps: u32,
    host_time: std::time::Duration,
}

impl Prepared {
    /// Workgroups of the one-pass traversal for the next run, 0 for the level chain.
    fn one_pass(&self) -> u32 {
        self.one_pass
    }
}

/// Reported pairs below which the re-decision stays on the calling thread. Measured on an H200's
/// 16-core host: at 2,755 pairs the pool's hand-off and the other cores' cold caches made the
/// re-decision no faster than one thread (0.40-0.50 against 0.42 ms), at 5,882 faster (0.55
/// against 0.84 ms). On a 2-core host with lavapipe (2026-12-02), where the GPU's worker
/// threads are idle once the answer is read, the 64-part checker frame (2,587 reported pairs)
/// took 0.92 of its time with 1,024 here instead of 4,096 (median of six alternated rounds;
/// `check_pipelined` 0.83).
#[cfg(feature = "parallel")]
const PARALLEL_DECISIONS: usize = 1024;

/// Reported pairs whose triangles are fetched together before they are tested.
const GATHER: usize = 32;

/// Turns the GPU's reported entries `(pair, tri_a, tri_b | uncertain flag, _)` into one answer
/// per body pair: checks every index, decides with the exact test the pairs `recheck` asks for,
/// and sorts each answer's pairs (a pair reported twice is an internal error).
///
/// Why this shape: each pair `(a, b)` travels as one `u64` key `a << 32 | b << 1 | bit`, the bit
/// first the GPU's uncertain flag, then "dropped" (the exact test found the pair disjoint),
/// scattered by body pair after one counting pass, so a batch costs two passes over the entries
/// plus one integer sort per answer; a pair reported twice sorts next to itself, dropped or not. The tuple-by-tuple version it replaces
/// (a decision record per entry, collected through rayon, then a sort of `(u32, u32)`s) cost
/// 80 ns per reported pair even when no exact test ran.
fn decide_entries(
    p: &Prepared,
    entries: &[u32],
    recheck: crate::Recheck,
) -> Result<Vec<GpuCollision>, GpuError> {
    let n_pairs = p.frames.len();
    let counts: Vec<(u32, u32)> = p
        .tris
        .iter()
        .map(|(a, b)| (a.triangle_count() as u32, b.triangle_count() as u32))
        .collect();
    // Pass 1: check every entry and count each body pair's share.
    let mut starts = vec![0usize; n_pairs + 1];
    let mut uncertain = vec![0usize; n_pairs];
    for e in entries.chunks_exact(4) {
        let (k, ia, tag) = (e[0] as usize, e[1], e[2]);
        let ib = tag & !UNCERTAIN_FLAG;
        let Some(&(na, nb)) = counts.get(k) else {
            return Err(GpuError::Internal(format!("pair index {k} out of range")));
        };
        if ia >= na || ib >= nb {
            return Err(GpuError::Internal(format!(
                "pair {k}: triangle pair ({ia}, {ib}) out of range"
            )));
        }
        starts[k + 1] += 1;
        uncertain[k] += usize::from(tag & UNCERTAIN_FLAG != 0);
    }
    for k in 0..n_pairs {
        starts[k + 1] += starts[k];
    }
    // Pass 2: scatter the keys by body pair, in the GPU's order.
    let mut keys = vec![0u64; starts[n_pairs]];
    let mut next = starts.clone();
    for e in entries.chunks_exact(4) {
        let k = e[0] as usize;
        let (ib, flagged) = (e[2] & !UNCERTAIN_FLAG, e[2] & UNCERTAIN_FLAG != 0);
        keys[next[k]] = (u64::from(e[1]) << 32) | (u64::from(ib) << 1) | u64::from(flagged);
        next[k] += 1;
    }
    let mut segments: Vec<(usize, &mut [u64])> = Vec::with_capacity(n_pairs);
    let mut rest = keys.as_mut_slice();
    for k in 0..n_pairs {
        let (seg, tail) = rest.split_at_mut(starts[k + 1] - starts[k]);
        segments.push((k, seg));
        rest = tail;
    }
    let all = recheck == crate::Recheck::All;
    let decide = |(k, seg): (usize, &mut [u64])| -> Result<GpuCollision, GpuError> {
        let (frame, (ta, tb)) = (&p.frames[k], &p.tris[k]);
        // With Recheck::All the GPU's "touching" is not trusted either (WGSL's float rules, a
        // driver bug). The exact test's filter decides most pairs in floats; their cost is
        // fetching both triangles from meshes the GPU's work left cold. So a block's triangles
        // are fetched first, in one loop of independent loads that the processor overlaps,
        // then tested. Returns the certified pairs the test refuted.
        let (ia_tris, ib_tris) = (ta.indices(), tb.indices());
        let (a_verts, b_verts) = (ta.vertices(), tb.vertices());
        let test_block = |block: &mut [u64]| -> usize {
            const NONE: Triangle = Triangle::new(DVec3::ZERO, DVec3::ZERO, DVec3::ZERO);
            let mut corners = [([0u32; 3], [0u32; 3]); GATHER];
            let mut at = [0usize; GATHER];
            let mut flagged = [false; GATHER];
            let mut n = 0;
            for (i, key) in block.iter_mut().enumerate() {
                let f = *key & 1 != 0;
                *key &= !1;
                if f || all {
                    let (ia, ib) = ((*key >> 32) as usize, (*key as u32 >> 1) as usize);
                    corners[n] = (ia_tris[ia], ib_tris[ib]);
                    (at[n], flagged[n]) = (i, f);
                    n += 1;
                }
            }
            let mut fetched = [(NONE, NONE); GATHER];
            for (f, (ca, cb)) in fetched.iter_mut().zip(&corners).take(n) {
                let v = |verts: &[DVec3], c: [u32; 3]| {
                    Triangle::new(
                        verts[c[0] as usize],
                        verts[c[1] as usize],
                        verts[c[2] as usize],
                    )
                };
                *f = (v(a_verts, *ca), v(b_verts, *cb));
            }
            let mut refuted = 0;
            for j in 0..n {
                let (a, b) = &fetched[j];
                if !frcd_tritri::intersects(Method::Exact, a, &frame.triangle(b)) {
                    block[at[j]] |= 1;
                    refuted += usize::from(!flagged[j]);
                }
            }
            refuted
        };
        #[cfg(feature = "parallel")]
        let tested = if all { seg.len() } else { uncertain[k] };
        #[cfg(feature = "parallel")]
        let refuted: usize = if tested >= PARALLEL_DECISIONS {
            use rayon::prelude::*;
            seg.par_chunks_mut(GATHER).map(test_block).sum()
        } else {
            seg.chunks_mut(GATHER).map(test_block).sum()
        };
        #[cfg(not(feature = "parallel"))]
        let refuted: usize = seg.chunks_mut(GATHER).map(test_block).sum();
        seg.sort_unstable();
        if seg.windows(2).any(|w| w[0] >> 1 == w[1] >> 1) {
            return Err(GpuError::Internal(
                "a triangle pair was reported twice".into(),
            ));
        }
        let certified = starts[k + 1] - starts[k] - uncertain[k];
        Ok(GpuCollision {
            pairs: seg
                .iter()
                .filter(|&&key| key & 1 == 0)
                .map(|&key| ((key >> 32) as u32, key as u32 >> 1))
                .collect(),
            gpu_decided: certified - refuted,
            gpu_refuted: refuted,
            uncertain: uncertain[k],
            ..GpuCollision::default()
        })
    };
    #[cfg(feature = "parallel")]
    if entries.len() / 4 >= PARALLEL_DECISIONS {
        use rayon::prelude::*;
        return segments.into_par_iter().map(decide).collect();
    }
    segments.into_iter().map(decide).collect()
}

/// Uploads the pairs' f32 poses and arena bases into the pose texture (whole rows; the tail of
/// the last row is zero and never read).
fn write_poses(queue: &wgpu::Queue, poses: &wgpu::Texture, infos: &[PairInfo], eps: &[f32]) {
    let rows = (infos.len() as u32).div_ceil(POSE_PAIRS_PER_ROW);
    let mut bytes = vec![0u8; rows as usize * POSE_ROW_BYTES];
    for (texels, (info, eps)) in bytes
        .chunks_exact_mut(POSE_TEXELS as usize * 16)
        .zip(infos.iter().zip(eps))
    {
        texels.copy_from_slice(bytemuck::cast_slice(&pose_texels(info, *eps)));
    }
    queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture: poses,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        &bytes,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(POSE_ROW_BYTES as u32),
            rows_per_image: Some(rows),
        },
        wgpu::Extent3d {
            width: POSE_PAIRS_PER_ROW * POSE_TEXELS,
            height: rows,
            depth_or_array_layers: 1,
        },
    );
}

/// One pair's five pose texels (`traverse.wgsl`'s `load_pose`): rows of R with t's
/// coordinates in w, as f32 bits, the arena bases, then the bound on both meshes' axes'
/// deviation from orthonormal (`eps_A + eps_B`, rounded up) and `PairInfo::fix`'s first three
/// words (the triangle pass's path and grid exponents).
fn pose_texels(info: &PairInfo, eps: f32) -> [[u32; 4]; 5] {
    let row = |r: &[f32; 4], t: f32| [r[0].to_bits(), r[1].to_bits(), r[2].to_bits(), t.to_bits()];
    [
        row(&info.r0, info.t[0]),
        row(&info.r1, info.t[1]),
        row(&info.r2, info.t[2]),
        info.base,
        [
            eps.to_bits(),
            info.fix[0] as u32,
            info.fix[1] as u32,
            info.fix[2] as u32,
        ],
    ]
}

/// Timestamps a batch writes with pass timers on (0: too deep to time).
fn timer_count(p: &Prepared) -> u32 {
    // The one-pass traversal: before and after its dispatch.
    let n = if p.one_pass() > 0 { 2 } else { p.levels + 2 };
    if n <= MAX_TIMERS { n } else { 0 }
}

/// The relative pose as the shader's `PairInfo`: rows of R, then t (f32, rounded to nearest;
/// the shaders' error bounds include this rounding), the meshes' arena bases, and the exact
/// path's fixed-point pose ([`crate::pack::ExactPose`]) where `exact` and the pair's ranges
/// allow it (else `fix.x = 0`: the rotated path).
fn pair_info(frame: &RelativeFrame, a: &GpuMesh, b: &GpuMesh, exact: bool) -> PairInfo {
    let m = frame.m;
    let row = |k: usize| {
        [
            m.x_axis[k] as f32,
            m.y_axis[k] as f32,
            m.z_axis[k] as f32,
            0.0,
        ]
    };
    let words = exact
        .then(|| crate::pack::ExactPose::new(&m, frame.t, a.grid, b.grid))
        .flatten()
        .map(|e| e.words())
        .unwrap_or(crate::pack::ExactWords {
            fix: [0, a.grid.unwrap_or(0), b.grid.unwrap_or(0), 0],
            ..Default::default()
        });
    PairInfo {
        r0: row(0),
        r1: row(1),
        r2: row(2),
        t: [frame.t.x as f32, frame.t.y as f32, frame.t.z as f32, 0.0],
        base: [a.node_base, a.tri_base, b.node_base, b.tri_base],
        fix: words.fix,
        m_lo0: words.m_lo[0],
        m_lo1: words.m_lo[1],
        m_lo2: words.m_lo[2],
        m_hi0: words.m_hi[0],
        m_hi1: words.m_hi[1],
        m_hi2: words.m_hi[2],
        t01: words.t01,
        t23: words.t23,
        t4: words.t4,
    }
}

/// A batch recorded into the caller's command encoder by [`GpuContext::encode_batch`]. Submit
/// the encoder, then call [`PendingBatch::resolve`] with the submission index: it waits for that
/// submission only.
#[must_use = "a pending batch does nothing until resolved"]
pub struct PendingBatch<'s> {
    ctx: &'s GpuContext,
    scratch: &'s mut QueryScratch,
    prepared: Prepared,
}

impl std::fmt::Debug for PendingBatch<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PendingBatch")
            .field("pairs", &self.prepared.frames.len())
            .finish()
    }
}

impl PendingBatch<'_> {
    /// Reads the answer of a batch whose encoder the caller submitted as `submission` (the
    /// index `Queue::submit` returned). Waits for that submission only. On a buffer overflow the
    /// batch is re-run on frcd-gpgpu's own submissions (counted in the answer).
    pub fn resolve(mut self, submission: wgpu::SubmissionIndex) -> Result<GpuBatch, GpuError> {
        let mut answer = GpuBatch::default();
        self.ctx.run(
            &mut self.prepared,
            self.scratch,
            &mut answer,
            Some(submission),
        )
    }
}

/// A batch frcd-gpgpu submitted on its own ([`GpuContext::submit_batch`]) and has not read back
/// yet: owned (no borrow of the context or scratch), so it can be kept across frames while the
/// caller works, e.g. the CPU deciding frame k while the GPU traverses frame k+1.
/// [`GpuContext::resolve_batch`] reads it (waiting on its own submission only) and gives the
/// scratch back. Dropping it unresolved is allowed (the work is discarded).
#[must_use = "a submitted batch is read by GpuContext::resolve_batch"]
pub struct SubmittedBatch {
    ctx_id: u64,
    prepared: Prepared,
    scratch: QueryScratch,
    index: wgpu::SubmissionIndex,
}

impl std::fmt::Debug for SubmittedBatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SubmittedBatch")
            .field("pairs", &self.prepared.frames.len())
            .finish()
    }
}

impl SubmittedBatch {
    /// Body pairs in the batch.
    pub fn len(&self) -> usize {
        self.prepared.frames.len()
    }

    /// True for a batch of no pairs.
    pub fn is_empty(&self) -> bool {
        self.prepared.frames.is_empty()
    }
}

impl GpuContext {
    /// Every touching triangle pair of two uploaded meshes at two poses (surface mode), equal to
    /// [`frcd_obb::oracle::pairs`]. A batch of one ([`GpuContext::collide_batch`]): one
    /// submission and one readback, unless a buffer of `scratch` overflows: then the query is
    /// re-run with larger buffers (counted in the answer).
    pub fn collide(
        &self,
        a: &GpuMesh,
        pose_a: &Pose,
        b: &GpuMesh,
        pose_b: &Pose,
        scratch: &mut QueryScratch,
    ) -> Result<GpuCollision, GpuError> {
        let batch = self.collide_batch(&[(a, pose_a, b, pose_b)], scratch)?;
        let mut r = batch.results.into_iter().next().unwrap_or_default();
        r.submissions = batch.submissions;
        r.readbacks = batch.readbacks;
        r.reruns = batch.reruns;
        Ok(r)
    }

    /// Every touching triangle pair of every body pair of a frame, in **one** dispatch chain,
    /// **one** submission and **one** readback (plus one of each per overflow re-run): the
    /// frontier carries the pair index, all meshes live in the context's arena. Each result
    /// equals [`frcd_obb::oracle::pairs`] for its pair.
    ///
    /// ```no_run
    /// # use frcd_gpgpu::{GpuContext, QueryScratch};
    /// # use frcd_obb::{BuildOptions, ObbTree};
    /// # use frcd_geom::{shapes, DVec3, Pose};
    /// let ctx = GpuContext::headless()?;
    /// let m = ctx.upload(&ObbTree::build(&shapes::icosphere(1.0, 3), &BuildOptions::default()))?;
    /// let poses: Vec<Pose> = (0..4).map(|k| Pose::from_translation(DVec3::X * k as f64)).collect();
    /// let pairs: Vec<_> = (0..3).map(|k| (&m, &poses[k], &m, &poses[k + 1])).collect();
    /// let frame = ctx.collide_batch(&pairs, &mut QueryScratch::default())?;
    /// assert_eq!(frame.results.len(), 3);
    /// assert_eq!(frame.submissions, 1);
    /// # Ok::<(), frcd_gpgpu::GpuError>(())
    /// ```
    pub fn collide_batch(
        &self,
        pairs: &[BodyPair<'_>],
        scratch: &mut QueryScratch,
    ) -> Result<GpuBatch, GpuError> {
        if pairs.is_empty() {
            return Ok(GpuBatch::default());
        }
        let mut prepared = self.prepare(pairs)?;
        let mut answer = GpuBatch::default();
        self.run(&mut prepared, scratch, &mut answer, None)
    }

    /// Records a batch into the caller's command encoder (an engine's frame) and returns a
    /// [`PendingBatch`]; after submitting the encoder, [`PendingBatch::resolve`] reads the
    /// answer, waiting on that submission only. Buffer uploads (poses, root pairs) are queued
    /// with `Queue::write_buffer` and land before the caller's submission.
    pub fn encode_batch<'s>(
        &'s self,
        encoder: &mut wgpu::CommandEncoder,
        pairs: &[BodyPair<'_>],
        scratch: &'s mut QueryScratch,
    ) -> Result<PendingBatch<'s>, GpuError> {
        let prepared = self.prepare(pairs)?;
        self.record(encoder, &prepared, scratch)?;
        Ok(PendingBatch {
            ctx: self,
            scratch,
            prepared,
        })
    }

    /// Records and submits a batch now (one submission) and returns it unread: the GPU works
    /// while the caller does something else; [`GpuContext::resolve_batch`] reads it. `scratch`
    /// moves into the batch and comes back from `resolve_batch` (keep two to have one batch in
    /// flight while the previous one is read). Each result equals
    /// [`frcd_obb::oracle::pairs`] for its pair, as with [`GpuContext::collide_batch`].
    ///
    /// ```no_run
    /// # use frcd_gpgpu::{GpuContext, QueryScratch};
    /// # use frcd_obb::{BuildOptions, ObbTree};
    /// # use frcd_geom::{shapes, DVec3, Pose};
    /// let ctx = GpuContext::headless()?;
    /// let m = ctx.upload(&ObbTree::build(&shapes::icosphere(1.0, 3), &BuildOptions::default()))?;
    /// let (p, q) = (Pose::IDENTITY, Pose::from_translation(DVec3::X));
    /// let next = ctx.submit_batch(&[(&m, &p, &m, &q)], QueryScratch::default())?;
    /// // ... CPU work of the previous frame here ...
    /// let (frame, _scratch) = ctx.resolve_batch(next)?;
    /// assert!(frame.results[0].collide());
    /// # Ok::<(), frcd_gpgpu::GpuError>(())
    /// ```
    pub fn submit_batch(
        &self,
        pairs: &[BodyPair<'_>],
        mut scratch: QueryScratch,
    ) -> Result<SubmittedBatch, GpuError> {
        let prepared = self.prepare(pairs)?;
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frcd-gpgpu batch"),
            });
        if !prepared.frames.is_empty() {
            self.record(&mut enc, &prepared, &mut scratch)?;
        }
        let index = self.submit(enc.finish());
        Ok(SubmittedBatch {
            ctx_id: self.id,
            prepared,
            scratch,
            index,
        })
    }

    /// Reads a batch of [`GpuContext::submit_batch`] (waiting on its submission only; re-runs
    /// on overflow as [`GpuContext::collide_batch`] does) and returns the answer and the
    /// scratch. A batch of another context is [`GpuError::ForeignObject`].
    pub fn resolve_batch(
        &self,
        batch: SubmittedBatch,
    ) -> Result<(GpuBatch, QueryScratch), GpuError> {
        if batch.ctx_id != self.id {
            return Err(GpuError::ForeignObject("SubmittedBatch"));
        }
        let SubmittedBatch {
            mut prepared,
            mut scratch,
            index,
            ..
        } = batch;
        if prepared.frames.is_empty() {
            return Ok((
                GpuBatch {
                    submissions: 1,
                    ..GpuBatch::default()
                },
                scratch,
            ));
        }
        let mut answer = GpuBatch {
            submissions: 1,
            ..GpuBatch::default()
        };
        let out = self.run(&mut prepared, &mut scratch, &mut answer, Some(index))?;
        Ok((out, scratch))
    }

    fn prepare(&self, pairs: &[BodyPair<'_>]) -> Result<Prepared, GpuError> {
        // The pose texture holds `POSE_PAIRS_PER_ROW` pairs per row, as many rows as the
        // device's 2D textures allow (8,192 by WebGPU's defaults: 2.1M pairs).
        let most = (u32::MAX as u64 / 2)
            .min(POSE_PAIRS_PER_ROW as u64 * self.limits.max_texture_dimension_2d as u64);
        if pairs.len() as u64 >= most {
            return Err(GpuError::CapacityExceeded {
                what: "body pairs in one batch",
                needed: pairs.len() as u64,
                limit: most - 1,
            });
        }
        let mut p = Prepared {
            infos: Vec::with_capacity(pairs.len()),
            eps: Vec::with_capacity(pairs.len()),
            frames: Vec::with_capacity(pairs.len()),
            tris: Vec::with_capacity(pairs.len()),
            levels: 0,
            leaf_pairs: 0,
            exact: self.exact_offsets,
            roots: Vec::new(),
            one_pass: self.one_pass,
            host_tests: 0,
            host_steps: 0,
            host_time: std::time::Duration::ZERO,
        };
        for (k, &(a, pose_a, b, pose_b)) in pairs.iter().enumerate() {
            for m in [a, b] {
                if m.ctx_id != self.id {
                    return Err(GpuError::ForeignObject("GpuMesh"));
                }
            }
            for (name, pose) in [("pose_a", pose_a), ("pose_b", pose_b)] {
                if !pose.is_valid() {
                    return Err(GpuError::InvalidInput(format!(
                        "pair {k}: {name} is not finite or its rotation is not a unit \
                         quaternion: {pose:?}"
                    )));
                }
            }
            let frame = RelativeFrame::new(pose_a, pose_b);
            let tmag = frame.t.abs().max_element();
            if tmag > crate::pack::MAX_MAGNITUDE {
                return Err(GpuError::MagnitudeOutOfRange {
                    what: format!("pair {k}: translation of pose_b in pose_a's frame"),
                    value: tmag,
                    limit: crate::pack::MAX_MAGNITUDE,
                });
            }
            p.infos.push(pair_info(&frame, a, b, self.exact_offsets));
            p.eps
                .push(crate::pack::round_up(a.eps as f64 + b.eps as f64));
            p.frames.push(frame);
            p.tris.push((a.mesh.clone(), b.mesh.clone()));
            p.leaf_pairs = p.leaf_pairs.max(a.max_leaf as u64 * b.max_leaf as u64);
        }
        let started = std::time::Instant::now();
        let front = crate::front::host_front(pairs, self.host_front);
        if self.host_front > 0 {
            p.host_time = started.elapsed();
        }
        p.levels = front.levels;
        p.roots = front.entries;
        p.host_tests = front.tests;
        p.host_steps = front.steps;
        Ok(p)
    }

    /// Sizes the scratch, queues the uploads and records the dispatch chain and the copies to
    /// the staging buffer.
    fn record(
        &self,
        enc: &mut wgpu::CommandEncoder,
        p: &Prepared,
        scratch: &mut QueryScratch,
    ) -> Result<(), GpuError> {
        let n = p.frames.len() as u32;
        let n_roots = p.roots.len() as u32;
        scratch.ensure(self, n, n_roots)?;
        let bufs = scratch.bufs.as_ref().expect("ensured");
        // One level lists at most its entries × 4 child pairs × the largest leaf pair's
        // triangle pairs; every reservation that takes the triangle counter past 2^31 brings it
        // back there (`reserve_tris`), so below 2^31 per level it never wraps (a wrapped
        // counter would look like a short list: pairs lost). The level's capacity is held
        // below that (`level_cap`); a batch that needs more is refused after its run.
        let level_cap = level_cap(bufs.frontier_cap, p.leaf_pairs);
        let max_groups = self.limits.max_compute_workgroups_per_dimension;
        self.queue.write_buffer(
            &bufs.params,
            0,
            bytemuck::bytes_of(&Params {
                caps: [level_cap, bufs.output_cap, max_groups, n],
                // The one-pass traversal's loop budget, and what one round of its listed
                // leaf pairs' tests takes at most: the round's iteration, and the loops over
                // the two leaves' triangles (na + na nb <= 2 na nb iterations).
                caps2: [
                    bufs.tri_cap,
                    self.one_pass_budget,
                    (1 + 2 * p.leaf_pairs).min(u32::MAX as u64) as u32,
                    0,
                ],
                // Each workgroup's frontier region (in each half) and triangle list region are
                // its share of the capacities.
                one_pass: [
                    p.one_pass(),
                    level_cap / p.one_pass().max(1),
                    n_roots.min(level_cap),
                    p.levels,
                ],
            }),
        );
        if n == 0 {
            // Still a valid chain: the state below says the frontier is empty.
            self.queue
                .write_buffer(&bufs.pairs, 0, &[0u8; PAIR_BYTES as usize]);
        } else {
            self.queue
                .write_buffer(&bufs.pairs, 0, bytemuck::cast_slice(&p.infos));
            write_poses(&self.queue, &bufs.poses, &p.infos, &p.eps);
        }
        if n_roots > 0 {
            // The roots as themselves (bit 31: the node, not its first child;
            // `traverse.wgsl`), or the CPU's front.
            self.queue
                .write_buffer(&bufs.frontier[0], 0, bytemuck::cast_slice(&p.roots));
        }
        // The batch starts with its roots (at most the level's capacity) in frontier 0 and
        // every other counter at 0; `needed` holds the root count, so a batch with more roots
        // than the level's capacity (only where `level_cap` holds it below the scratch's) is
        // refused after its run. The triangle pass's arguments start empty, and the traversal
        // raises them.
        let roots = n_roots.min(level_cap);
        let start = State {
            counts: [roots, 0, 0],
            // (The one-pass traversal's `needed` is its regions' demand alone; `run` compares
            // the root count with the level's capacity itself.)
            needed: if p.one_pass() > 0 { 0 } else { n_roots },
            tri_args: [0, 1, 1],
            ..State::default()
        };
        self.queue
            .write_buffer(&bufs.state, 0, bytemuck::bytes_of(&start));
        // Level 0 covers the roots; levels 1 and 2 start from one workgroup (each level raises
        // the next one's arguments and resets those of the level after next).
        let [x, y] = grid_args(roots, max_groups);
        self.queue
            .write_buffer(&bufs.args[0], 0, bytemuck::cast_slice(&[x, y, 1, 0]));
        for args in &bufs.args[1..] {
            self.queue
                .write_buffer(args, 0, bytemuck::cast_slice(&[1u32, 1, 1, 0]));
        }
        let arena_bg = self
            .arena
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .bind
            .clone();
        let timers = bufs.timers.as_ref().filter(|_| timer_count(p) > 0);
        if let (true, Some((_, one_pass_bg))) = (p.one_pass() > 0, &bufs.one_pass) {
            // Every level and the triangle tests in one dispatch of `p.one_pass()` workgroups.
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("frcd-gpgpu one-pass traversal"),
                timestamp_writes: None,
            });
            if let Some((set, _)) = timers {
                pass.write_timestamp(set, 0);
            }
            pass.set_pipeline(if p.exact {
                &self.pipes.traverse_all
            } else {
                &self.pipes.traverse_all_rotated
            });
            pass.set_bind_group(0, &arena_bg, &[]);
            pass.set_bind_group(1, one_pass_bg, &[]);
            pass.dispatch_workgroups(p.one_pass(), 1, 1);
            if let Some((set, _)) = timers {
                pass.write_timestamp(set, 1);
            }
        } else {
            self.record_level_chain(enc, p, bufs, &arena_bg, timers);
        }
        enc.copy_buffer_to_buffer(&bufs.state, 0, &bufs.staging, 0, STATE_BYTES);
        if let Some((set, resolved)) = timers {
            let n = timer_count(p);
            enc.resolve_query_set(set, 0..n, resolved, 0);
            enc.copy_buffer_to_buffer(resolved, 0, &bufs.staging, STATE_BYTES, n as u64 * 8);
        }
        let out_bytes = bufs.output_cap as u64 * ENTRY_BYTES;
        enc.copy_buffer_to_buffer(&bufs.out, 0, &bufs.staging, bufs.out_offset, out_bytes);
        Ok(())
    }

    /// Records the level chain: one dispatch per level of the pair trees, then the triangle
    /// pass.
    fn record_level_chain(
        &self,
        enc: &mut wgpu::CommandEncoder,
        p: &Prepared,
        bufs: &Buffers,
        arena_bg: &wgpu::BindGroup,
        timers: Option<&(wgpu::QuerySet, wgpu::Buffer)>,
    ) {
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("frcd-gpgpu traversal"),
                timestamp_writes: None,
            });
            let stamp = |pass: &mut wgpu::ComputePass<'_>, k: u32| {
                if let Some((set, _)) = timers {
                    pass.write_timestamp(set, k);
                }
            };
            stamp(&mut pass, 0);
            // Level L reads frontier L % 2 and dispatches with the arguments the level before
            // it wrote (the CPU's for level 0): one dispatch per level, no control pass
            // (each such single-invocation pass cost 20-70 µs on lavapipe).
            pass.set_pipeline(&self.pipes.traverse);
            pass.set_bind_group(0, arena_bg, &[]);
            for level in 0..p.levels as usize {
                pass.set_bind_group(1, &bufs.trav_bg[level % 6], &[]);
                pass.dispatch_workgroups_indirect(&bufs.args[level % 3], 0);
                stamp(&mut pass, level as u32 + 1);
            }
        }
        // Every listed triangle pair, one per invocation, with the arguments the levels raised
        // as they listed them (`State::tri_args`, copied to an indirect buffer: the triangle
        // pass binds the state as storage, which a dispatch cannot also read its arguments
        // from). A copy, not a control pass: no shader invocation, no worker hand-off on a
        // software driver.
        enc.copy_buffer_to_buffer(&bufs.state, TRI_ARGS_OFFSET, &bufs.args[0], 0, 12);
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("frcd-gpgpu triangle pass"),
                timestamp_writes: None,
            });
            pass.set_pipeline(if p.exact {
                &self.pipes.triangles
            } else {
                &self.pipes.triangles_rotated
            });
            pass.set_bind_group(0, arena_bg, &[]);
            pass.set_bind_group(1, &bufs.tri_bg, &[]);
            pass.dispatch_workgroups_indirect(&bufs.args[0], 0);
            if let Some((set, _)) = timers {
                pass.write_timestamp(set, p.levels + 1);
            }
        }
    }

    /// Reads back (after `first`, the caller's submission, when given; else records and
    /// submits its own), re-runs on overflow, and decides every reported pair exactly.
    fn run(
        &self,
        p: &mut Prepared,
        scratch: &mut QueryScratch,
        answer: &mut GpuBatch,
        mut first: Option<wgpu::SubmissionIndex>,
    ) -> Result<GpuBatch, GpuError> {
        let (state, ticks, entries) = loop {
            let index = match first.take() {
                Some(i) => i,
                None => {
                    let mut enc =
                        self.device
                            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                                label: Some("frcd-gpgpu batch"),
                            });
                    self.record(&mut enc, p, scratch)?;
                    answer.submissions += 1;
                    self.submit(enc.finish())
                }
            };
            let bufs = scratch.bufs.as_ref().expect("recorded");
            let out_bytes = bufs.output_cap as u64 * ENTRY_BYTES;
            let (out_offset, output_cap) = (bufs.out_offset as usize, bufs.output_cap);
            let n_ticks = if bufs.timers.is_some() {
                timer_count(p) as usize
            } else {
                0
            };
            let waited = std::time::Instant::now();
            // Only the entries written are copied out of the mapped buffer, not the capacity.
            let (state, ticks, entries) =
                self.read_back_with(&bufs.staging, bufs.out_offset + out_bytes, index, |bytes| {
                    let state: State = bytemuck::pod_read_unaligned(&bytes[..STATE_BYTES as usize]);
                    let ticks: Vec<u64> =
                        bytemuck::pod_collect_to_vec(&bytes[STATE_BYTES as usize..][..n_ticks * 8]);
                    let written = if state.out <= output_cap {
                        state.out as usize
                    } else {
                        0
                    };
                    let entries: Vec<u32> = bytemuck::pod_collect_to_vec(
                        &bytes[out_offset..][..written * ENTRY_BYTES as usize],
                    );
                    (state, ticks, entries)
                })?;
            answer.timings.wait += waited.elapsed();
            answer.readbacks += 1;
            // A one-pass workgroup that would have run past its loop budget stopped (`counts[2]`
            // set): the answer is incomplete, and the batch re-runs as the level chain.
            if p.one_pass() > 0 && state.counts[2] != 0 {
                log::debug!(
                    "frcd-gpgpu: the one-pass traversal ran out of its loop budget, re-running as the level chain"
                );
                p.one_pass = 0;
                answer.reruns += 1;
                continue;
            }
            // What the last level appended (nothing when the traversal finished; the one-pass
            // traversal adds what a workgroup left after the most levels to `counts[1]`).
            let cur = if p.one_pass() > 0 {
                state.counts[1]
            } else {
                state.counts[p.levels as usize % 3]
            };
            let out_count = state.out;
            // The one-pass traversal's regions hold (level capacity / G) entries each, and an
            // overflowing one reports its demand times G: that is compared with what the
            // regions hold, not the whole buffer (the level capacity can be below it,
            // `level_cap`), so a stopped workgroup is never taken for a finished one; its first
            // level is copied from the whole first buffer into its region, so the roots must
            // fit the regions too.
            let n_roots = p.roots.len() as u32;
            let (needed, short) = match p.one_pass() {
                0 => (state.needed, state.needed > bufs.frontier_cap),
                g => {
                    let lc = level_cap(bufs.frontier_cap, p.leaf_pairs);
                    (
                        state.needed.max(n_roots),
                        state.needed > lc / g * g || n_roots > lc / g * g,
                    )
                }
            };
            let mut rerun = false;
            // The level chain's dispatches cover at most `most` entries (the one-pass
            // traversal's workgroups loop over theirs).
            let most = if p.one_pass() == 0 {
                dispatchable(self)
            } else {
                u32::MAX
            };
            for (what, count, limit) in [
                (
                    "node pairs one level lists (workgroups per dimension squared × 64)",
                    needed,
                    most,
                ),
                (
                    "node pairs one level lists (2^31 triangle pairs / (4 × the largest leaf pair's))",
                    needed,
                    // The one-pass traversal's regions of the largest level hold a multiple of G.
                    match p.one_pass() {
                        0 => level_cap(u32::MAX, p.leaf_pairs),
                        g => level_cap(u32::MAX, p.leaf_pairs) / g * g,
                    },
                ),
                (
                    "triangle pairs one batch lists (workgroups per dimension squared × 64)",
                    state.tris,
                    most,
                ),
            ] {
                if count > limit {
                    return Err(GpuError::CapacityExceeded {
                        what,
                        needed: count as u64,
                        limit: limit as u64,
                    });
                }
            }
            if short {
                scratch.frontier_cap = needed.max(bufs.frontier_cap.saturating_mul(2));
                rerun = true;
            }
            if out_count > bufs.output_cap {
                scratch.output_cap = out_count.max(bufs.output_cap.saturating_mul(2));
                rerun = true;
            }
            if state.tris > bufs.tri_cap {
                scratch.tri_cap = state.tris.max(bufs.tri_cap.saturating_mul(2));
                rerun = true;
            }
            if rerun {
                log::debug!(
                    "frcd-gpgpu: overflow (frontier {needed}/{}, output {out_count}/{}, triangle list {}/{}), re-running",
                    bufs.frontier_cap,
                    bufs.output_cap,
                    state.tris,
                    bufs.tri_cap
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
                    "{cur} node pairs left after {} levels",
                    p.levels
                )));
            }
            answer.levels = state.levels;
            answer.host_levels = p.host_steps;
            // Four slots per frontier entry (`traverse.wgsl`), plus the CPU's front.
            answer.node_pairs_tested = 4 * state.pairs_tested as u64 + p.host_tests;
            break (state, ticks, entries);
        };
        debug_assert_eq!(entries.len(), state.out as usize * 4);
        if ticks.len() >= 2 {
            let period = f64::from(self.queue.get_timestamp_period());
            let span = |a: u64, b: u64| {
                std::time::Duration::from_nanos((b.saturating_sub(a) as f64 * period) as u64)
            };
            let last = ticks.len() - 1;
            answer.timings.gpu_levels =
                ticks[..last].windows(2).map(|w| span(w[0], w[1])).collect();
            // The one-pass traversal's triangle tests are inside its one dispatch.
            answer.timings.gpu_triangles =
                (p.one_pass() == 0).then(|| span(ticks[last - 1], ticks[last]));
            answer.timings.gpu_total = Some(span(ticks[0], ticks[last]));
        }
        let deciding = std::time::Instant::now();
        let mut results = decide_entries(p, &entries, self.recheck)?;
        for (r, info) in results.iter_mut().zip(&p.infos) {
            r.exact_offsets = info.fix[0] != 0;
            r.levels = answer.levels;
            r.node_pairs_tested = answer.node_pairs_tested;
            r.submissions = answer.submissions;
            r.readbacks = answer.readbacks;
            r.reruns = answer.reruns;
        }
        answer.results = results;
        answer.timings.decide = deciding.elapsed();
        answer.timings.host_front = p.host_time;
        Ok(std::mem::take(answer))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A level's capacity keeps its worst case (every entry with four leaf pairs of the
    /// largest size) below 2^31 triangle pairs, and is the largest that does; below that bound
    /// the scratch's capacity is kept.
    #[test]
    fn level_capacity_keeps_the_triangle_counter_below_2_pow_31() {
        for lp in [1u64, 4, 16, 4096, 64 * 64] {
            let cap = level_cap(u32::MAX, lp) as u64;
            assert!(4 * cap * lp < 1 << 31, "leaf pair {lp}");
            assert!(4 * (cap + 1) * lp >= 1 << 31, "leaf pair {lp}");
            assert_eq!(level_cap(1000, lp), 1000);
        }
    }

    /// Two meshes of two triangles each: A's triangle 0 and B's triangle 1 cross, every other
    /// pair is far apart (B's poses are the identity, so the frame is too).
    fn two_by_two() -> Prepared {
        let tri = |o: DVec3| {
            vec![
                o + DVec3::new(-1.0, -1.0, 0.0),
                o + DVec3::new(1.0, -1.0, 0.0),
                o + DVec3::new(0.0, 1.0, 0.0),
            ]
        };
        let mesh = |a: Vec<DVec3>, b: Vec<DVec3>| {
            let vertices = [a, b].concat();
            Arc::new(TriMesh::new(vertices, vec![[0, 1, 2], [3, 4, 5]]).expect("valid mesh"))
        };
        // A: triangle 0 in the plane z = 0 at the origin, triangle 1 far away.
        let a = mesh(tri(DVec3::ZERO), tri(DVec3::new(50.0, 0.0, 0.0)));
        // B: triangle 0 far away, triangle 1 standing in the plane y = 0 through A's triangle 0.
        let standing: Vec<DVec3> = tri(DVec3::ZERO)
            .into_iter()
            .map(|v| DVec3::new(v.x, 0.0, v.y))
            .collect();
        let b = mesh(tri(DVec3::new(0.0, 50.0, 0.0)), standing);
        let frame = RelativeFrame::new(&Pose::IDENTITY, &Pose::IDENTITY);
        Prepared {
            infos: Vec::new(),
            eps: Vec::new(),
            frames: vec![frame, frame],
            tris: vec![(a.clone(), b.clone()), (a, b)],
            levels: 0,
            leaf_pairs: 0,
            exact: false,
            roots: Vec::new(),
            one_pass: 0,
            host_tests: 0,
            host_steps: 0,
            host_time: std::time::Duration::ZERO,
        }
    }

    fn entry(k: u32, ia: u32, ib: u32, uncertain: bool) -> [u32; 4] {
        [k, ia, ib | if uncertain { UNCERTAIN_FLAG } else { 0 }, 0]
    }

    #[test]
    fn reported_pairs_are_decided_counted_and_sorted_per_body_pair() {
        let p = two_by_two();
        // Body pair 1 gets the pairs out of order; body pair 0 gets a certified pair that does
        // not touch (a GPU breaking its bound) and an uncertain one that does not either.
        let entries: Vec<u32> = [
            entry(1, 1, 0, true),
            entry(0, 0, 1, false),
            entry(1, 0, 1, false),
            entry(0, 1, 1, false),
            entry(0, 1, 0, true),
        ]
        .concat();
        let all = decide_entries(&p, &entries, crate::Recheck::All).expect("valid entries");
        assert_eq!(all[0].pairs, vec![(0, 1)]);
        assert_eq!(
            (all[0].gpu_decided, all[0].gpu_refuted, all[0].uncertain),
            (1, 1, 1)
        );
        assert_eq!(all[1].pairs, vec![(0, 1)]);
        assert_eq!(
            (all[1].gpu_decided, all[1].gpu_refuted, all[1].uncertain),
            (1, 0, 1)
        );
        // Trusting the certified pairs keeps the refuted one and still tests the uncertain ones.
        let trusted =
            decide_entries(&p, &entries, crate::Recheck::Uncertain).expect("valid entries");
        assert_eq!(trusted[0].pairs, vec![(0, 1), (1, 1)]);
        assert_eq!(
            (
                trusted[0].gpu_decided,
                trusted[0].gpu_refuted,
                trusted[0].uncertain
            ),
            (2, 0, 1)
        );
        assert_eq!(trusted[1].pairs, vec![(0, 1)]);
    }

    #[test]
    fn bad_entries_are_internal_errors() {
        let p = two_by_two();
        for bad in [
            entry(2, 0, 0, false),
            entry(0, 2, 0, false),
            entry(0, 0, 2, true),
        ] {
            let err = decide_entries(&p, &bad, crate::Recheck::All).unwrap_err();
            assert!(matches!(err, GpuError::Internal(_)), "{err}");
        }
        // Twice, also where the exact test drops one copy (uncertain and disjoint) and not the
        // other (certified, taken as reported).
        for (twice, recheck) in [
            (
                [entry(0, 0, 1, false), entry(0, 0, 1, true)],
                crate::Recheck::Uncertain,
            ),
            (
                [entry(1, 1, 1, true), entry(1, 1, 1, false)],
                crate::Recheck::Uncertain,
            ),
            (
                [entry(1, 1, 1, false), entry(1, 1, 1, false)],
                crate::Recheck::All,
            ),
        ] {
            let err = decide_entries(&p, &twice.concat(), recheck).unwrap_err();
            assert!(err.to_string().contains("twice"), "{err}");
        }
    }

    #[test]
    fn a_large_batch_decides_every_reported_pair() {
        // Two rows of 70 triangles, A's flat and B's standing, 10 apart: A's i touches B's j
        // only where i = j. Body pair 0 reports all 4,900 pairs (above the parallel threshold
        // within one answer), body pairs 1-3 a few each; some flagged uncertain.
        const N: u32 = 70;
        let row = |standing: bool| {
            let mut vertices = Vec::new();
            for i in 0..N {
                let x = 10.0 * f64::from(i);
                for (u, v) in [(-1.0, -1.0), (1.0, -1.0), (0.0, 1.0)] {
                    vertices.push(if standing {
                        DVec3::new(x + u, 0.0, v)
                    } else {
                        DVec3::new(x + u, v, 0.0)
                    });
                }
            }
            let indices = (0..N).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
            Arc::new(TriMesh::new(vertices, indices).expect("valid mesh"))
        };
        let (a, b) = (row(false), row(true));
        let frame = RelativeFrame::new(&Pose::IDENTITY, &Pose::IDENTITY);
        let p = Prepared {
            infos: Vec::new(),
            eps: Vec::new(),
            frames: vec![frame; 4],
            tris: vec![(a, b); 4],
            levels: 0,
            leaf_pairs: 0,
            exact: false,
            roots: Vec::new(),
            one_pass: 0,
            host_tests: 0,
            host_steps: 0,
            host_time: std::time::Duration::ZERO,
        };
        let flagged = |i: u32, j: u32| (i * 7 + j).is_multiple_of(5);
        let mut entries = Vec::new();
        for i in (0..N).rev() {
            for j in 0..N {
                entries.extend(entry(0, i, j, flagged(i, j)));
            }
        }
        for k in 1..4u32 {
            entries.extend(entry(k, k + 1, k, false));
            entries.extend(entry(k, k, k, k == 2));
        }
        for recheck in [crate::Recheck::All, crate::Recheck::Uncertain] {
            let got = decide_entries(&p, &entries, recheck).expect("valid entries");
            let n_flagged = (0..N)
                .flat_map(|i| (0..N).map(move |j| flagged(i, j)))
                .filter(|&f| f)
                .count();
            let certified_apart = (0..N)
                .flat_map(|i| (0..N).map(move |j| (i, j)))
                .filter(|&(i, j)| i != j && !flagged(i, j))
                .count();
            let r = &got[0];
            assert_eq!(r.uncertain, n_flagged);
            if recheck == crate::Recheck::All {
                assert_eq!(r.pairs, (0..N).map(|i| (i, i)).collect::<Vec<_>>());
                assert_eq!(r.gpu_refuted, certified_apart);
            } else {
                // The certified pairs are taken as reported; the flagged ones are decided.
                let want: Vec<(u32, u32)> = (0..N)
                    .flat_map(|i| (0..N).map(move |j| (i, j)))
                    .filter(|&(i, j)| i == j || !flagged(i, j))
                    .collect();
                assert_eq!(r.pairs, want);
                assert_eq!(r.gpu_refuted, 0);
            }
            assert_eq!(
                r.gpu_decided + r.gpu_refuted + r.uncertain,
                (N * N) as usize
            );
            for (k, r) in got.iter().enumerate().skip(1) {
                let k = k as u32;
                let want = if recheck == crate::Recheck::All {
                    vec![(k, k)]
                } else {
                    vec![(k, k), (k + 1, k)]
                };
                assert_eq!(r.pairs, want, "body pair {k}");
            }
        }
    }
}
