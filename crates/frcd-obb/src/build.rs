//! Building an [`ObbTree`](crate::ObbTree)'s hierarchy: top-down splits with a fitted box per
//! node.
//!
//! The output: depth-first nodes (left child = next node, `right`; leaves `first`/`count`) and
//! the `order` permutation of input-mesh triangle indices that leaves index. Each box is made
//! in f64 in the mesh's local frame and written straight into the compact f32 traversal layout
//! of `nodes.rs` ([`build_compact`], what [`ObbTree::build`](crate::ObbTree::build) uses); the
//! tests also read the f64 boxes (`build_nodes`, the same build into `Vec<Node>`) and check
//! that converting them gives exactly the compact nodes.

use crate::nodes::{LEAF, TNode, compact_box};
use crate::tree::{BuildOptions, Node, SplitMethod};
use frcd_geom::fit::{
    FitMethod, area_weighted_axes, fit_obb, hull_surface_axes, symmetric_eigen_axes,
};
use frcd_geom::{DMat3, DVec3, Obb, TriMesh, Triangle};

/// A triangle as the build moves it: its vertices, its largest `|p|₁` (the box's rounding
/// slack scales with it) and its index in the input mesh.
#[derive(Clone, Copy, Debug)]
struct Item {
    v: [DVec3; 3],
    mag: f64,
    id: u32,
}

impl Item {
    const ZERO: Item = Item {
        v: [DVec3::ZERO; 3],
        mag: 0.0,
        id: 0,
    };

    fn triangle(&self) -> Triangle {
        Triangle { v: self.v }
    }
}

/// Builds the nodes (depth-first, node 0 the root) and the leaf order of `mesh`'s triangles.
///
/// Each internal node costs one pass over its triangles ([`SplitMethod::MajorAxisMean`]; two
/// and a binning of compact copies with [`SplitMethod::SurfaceCost`], see
/// [`box_and_cost_split`]), which projects its vertices on the fitted axes (the box) and
/// partitions the triangles about the split plane, a sum of the smaller side's moments (the
/// larger side's follow by difference, see [`side_moments`]; both give the children's means
/// and covariances, see [`Moments`]), and one eigen-solve; a leaf's axes come from the moments
/// its parent summed (or, for two triangles, from their plane: [`node_fit`]). The partition is
/// branchless and out of place: each triangle is copied to the front (left) or the back
/// (right) of the same range of a second buffer, which the children read from (the two
/// buffers alternate by depth), so a node's triangles are one contiguous slice.
#[cfg(test)]
pub(crate) fn build_nodes(mesh: &TriMesh, options: &BuildOptions) -> (Vec<Node>, Vec<u32>) {
    let mut nodes: Vec<Node> = Vec::new();
    let order = build_into(mesh, options, &mut nodes);
    (nodes, order)
}

/// The build (`build_nodes` in the tests) straight into the traversal layout (`nodes.rs`):
/// each box converted to its compact f32 form as it is made, without the f64 node list.
/// Returns the nodes, the leaf order and its leaf-end bits (bit `k` set when leaf-order entry `k` is the last of its leaf).
pub(crate) fn build_compact(
    mesh: &TriMesh,
    options: &BuildOptions,
) -> (Vec<TNode>, Vec<u32>, Vec<u64>) {
    let mut sink = Compact {
        nodes: Vec::new(),
        ends: vec![0u64; mesh.triangle_count().div_ceil(64).max(1)],
    };
    let order = build_into(mesh, options, &mut sink);
    (sink.nodes, order, sink.ends)
}

/// Where the build puts its nodes, depth-first.
trait Sink {
    fn reserve(&mut self, n: usize);
    fn len(&self) -> usize;
    fn internal(&mut self, obb: &Obb);
    fn leaf(&mut self, obb: &Obb, first: u32, count: u32);
    /// Links internal node `parent` to its right child `right`.
    fn set_right(&mut self, parent: u32, right: u32);
}

impl Sink for Vec<Node> {
    fn reserve(&mut self, n: usize) {
        Vec::reserve(self, n);
    }
    fn len(&self) -> usize {
        Vec::len(self)
    }
    fn internal(&mut self, obb: &Obb) {
        self.push(Node {
            obb: *obb,
            right: 0,
            first: 0,
            count: 0,
        });
    }
    fn leaf(&mut self, obb: &Obb, first: u32, count: u32) {
        self.push(Node {
            obb: *obb,
            right: 0,
            first,
            count,
        });
    }
    fn set_right(&mut self, parent: u32, right: u32) {
        self[parent as usize].right = right;
    }
}

/// The traversal layout being built.
struct Compact {
    nodes: Vec<TNode>,
    ends: Vec<u64>,
}

impl Sink for Compact {
    fn reserve(&mut self, n: usize) {
        self.nodes.reserve(n);
    }
    fn len(&self) -> usize {
        self.nodes.len()
    }
    fn internal(&mut self, obb: &Obb) {
        let (c, h, u) = compact_box(obb);
        self.nodes.push(TNode { c, h, u, link: 0 });
    }
    fn leaf(&mut self, obb: &Obb, first: u32, count: u32) {
        let (c, h, u) = compact_box(obb);
        let last = (first + count - 1) as usize;
        self.ends[last / 64] |= 1 << (last % 64);
        self.nodes.push(TNode {
            c,
            h,
            u,
            link: LEAF | first,
        });
    }
    fn set_right(&mut self, parent: u32, right: u32) {
        self.nodes[parent as usize].link = right;
    }
}

/// The build proper, into `sink`; returns the leaf order.
fn build_into(mesh: &TriMesh, options: &BuildOptions, sink: &mut impl Sink) -> Vec<u32> {
    let n = mesh.triangle_count();
    let leaf = options.max_leaf_triangles.max(1) as usize;
    let mut front: Vec<Item> = mesh
        .triangles()
        .enumerate()
        .map(|(i, t)| Item {
            v: t.v,
            mag: magnitude(&t),
            id: i as u32,
        })
        .collect();
    let mut back = vec![Item::ZERO; n];
    let mut probes = match options.split {
        SplitMethod::SurfaceCost => vec![Probe::default(); n],
        SplitMethod::MajorAxisMean => Vec::new(),
    };
    let mut bins = [[Bin::EMPTY; BINS]; 3];
    let mut order = vec![0u32; n];
    let nodes = sink;
    // About what a tree takes: 1.13-1.22 nodes per triangle at leaf size 2 on the bench meshes
    // (a leaf holds one triangle or two), so the array rarely grows and rarely needs the
    // shrinking copy of `ObbTree::from_compact`.
    nodes.reserve((2 * n).div_ceil(leaf) + n / 4);
    let root = {
        let sum = front.iter().map(|t| t.triangle().centroid()).sum::<DVec3>();
        let m = Moments::of(&front, sum / n.max(1) as f64);
        let (axes, second) = node_fit(&m, &front, options.fit, leaf);
        (m.mean(n.max(1)), axes, second)
    };
    let mut stack = vec![Pending {
        lo: 0,
        hi: n,
        parent: u32::MAX,
        in_back: false,
        mean: root.0,
        axes: root.1,
        second: root.2,
    }];
    while let Some(Pending {
        lo,
        hi,
        parent,
        in_back,
        mean,
        axes,
        second,
    }) = stack.pop()
    {
        let index = nodes.len() as u32;
        if parent != u32::MAX {
            nodes.set_right(parent, index);
        }
        let (src, dst) = if in_back {
            (&back[lo..hi], &mut front[lo..hi])
        } else {
            (&front[lo..hi], &mut back[lo..hi])
        };
        if hi - lo <= leaf {
            for (o, t) in order[lo..hi].iter_mut().zip(src) {
                *o = t.id;
            }
            nodes.leaf(
                &leaf_obb(src, axes, options.fit),
                lo as u32,
                (hi - lo) as u32,
            );
            continue;
        }
        let axes = axes.unwrap_or_else(|| match options.fit {
            FitMethod::AreaWeighted => {
                area_weighted_axes(&src.iter().map(Item::triangle).collect::<Vec<_>>())
            }
            FitMethod::HullSurface => {
                hull_surface_axes(&src.iter().flat_map(|t| t.v).collect::<Vec<_>>())
            }
            FitMethod::VertexCovariance => symmetric_eigen_axes(vertex_covariance(src, mean)),
        });
        let (obb, mid) = match options.split {
            SplitMethod::SurfaceCost => {
                box_and_cost_split(axes, mean, src, dst, &mut probes[lo..hi], &mut bins)
            }
            SplitMethod::MajorAxisMean => box_and_split(axes, mean, src, dst),
        };
        nodes.internal(&obb);
        // Both children's axes here, one eigen-solve after the other: independent, so their
        // long division and square-root chains overlap in the processor.
        let (ls, rs) = dst.split_at(mid);
        let [left, right] = side_moments(ls, rs, mean, second.as_ref());
        let (la, lm) = node_fit(&left, ls, options.fit, leaf);
        let (ra, rm) = node_fit(&right, rs, options.fit, leaf);
        stack.push(Pending {
            lo: lo + mid,
            hi,
            parent: index,
            in_back: !in_back,
            mean: right.mean(rs.len()),
            axes: ra,
            second: rm,
        });
        stack.push(Pending {
            lo,
            hi: lo + mid,
            parent: u32::MAX,
            in_back: !in_back,
            mean: left.mean(ls.len()),
            axes: la,
            second: lm,
        });
    }
    order
}

/// A node waiting on the build's stack: what its parent found out about it.
struct Pending {
    /// Its triangles' range in the buffers.
    lo: usize,
    hi: usize,
    /// The internal node whose `right` it is, or `u32::MAX` (a left child: the next node).
    parent: u32,
    /// Whether its triangles are in `back` (else in `front`).
    in_back: bool,
    /// Its vertices' mean.
    mean: DVec3,
    /// Its axes and second moments about `mean` ([`node_fit`]), when known.
    axes: Option<DMat3>,
    second: Option<[f64; 6]>,
}

/// A node's axes and second moments ([`Moments::fit`]) from the `moments` its parent summed,
/// except that a leaf of two triangles under the vertex covariance takes their plane's frame
/// ([`pair_frame`]): tighter (about 10-13 % fewer triangle tests in all-pairs queries on the
/// icospheres and the torus knots) and without an eigen-solve.
fn node_fit(
    moments: &Moments,
    items: &[Item],
    fit: FitMethod,
    leaf: usize,
) -> (Option<DMat3>, Option<[f64; 6]>) {
    if let [a, b] = items
        && leaf >= 2
        && fit == FitMethod::VertexCovariance
        && let Some(axes) = pair_frame(a, b)
    {
        return (Some(axes), None);
    }
    moments.fit(items, fit)
}

/// The box of a leaf (at least one triangle): a lone triangle's own frame, else the axes of the
/// fit rule (for the vertex covariance, from the moments the parent summed, or for two
/// triangles their plane's frame, see [`node_fit`]).
fn leaf_obb(items: &[Item], axes: Option<DMat3>, fit: FitMethod) -> Obb {
    if let [t] = items
        && let Some(frame) = triangle_frame(&t.triangle())
    {
        return leaf_box(items, frame);
    }
    match axes {
        Some(axes) => leaf_box(items, axes),
        None => fit_obb(&items.iter().map(Item::triangle).collect::<Vec<_>>(), fit),
    }
}

/// The box with `axes` of a leaf's triangles (at least one): [`Obb::from_points_with_axes`]
/// over their vertices (the same values; the bounds by plain compare-select, see
/// [`min_lane`], and the magnitude from the items' own).
fn leaf_box(items: &[Item], axes: DMat3) -> Obb {
    let t = axes.transpose();
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    let mut mag = 0.0f64;
    for item in items {
        for p in &item.v {
            let q = (t * *p).to_array();
            for k in 0..3 {
                lo[k] = min_lane(lo[k], q[k]);
                hi[k] = max_lane(hi[k], q[k]);
            }
        }
        mag = max_lane(mag, item.mag);
    }
    Obb::from_projection_bounds(axes, DVec3::from_array(lo), DVec3::from_array(hi), mag)
}

/// Sums over a node's triangles, gathered by its parent's pass: the vertices' first and second
/// moments about a reference point `r` near the node (the parent's mean), from which the
/// node's mean (the split point) and covariance follow without another pass.
#[derive(Clone, Copy, Debug)]
struct Moments {
    r: DVec3,
    first: DVec3,
    second: [f64; 6],
}

impl Moments {
    fn new(r: DVec3) -> Self {
        Self {
            r,
            first: DVec3::ZERO,
            second: [0.0; 6],
        }
    }

    /// The moments of `items` about `r` (in the AVX2 build where the CPU has it: the same
    /// sums, term by term, so the same bits).
    fn of(items: &[Item], r: DVec3) -> Self {
        #[cfg(target_arch = "x86_64")]
        if crate::isa::has_avx2() {
            // SAFETY: the running CPU has AVX2 (`isa::has_avx2`), the one feature
            // `of_avx2` is compiled with.
            #[allow(unsafe_code)]
            return unsafe { Self::of_avx2(items, r) };
        }
        Self::of_plain(items, r)
    }

    /// [`Moments::of`] in the baseline build.
    fn of_plain(items: &[Item], r: DVec3) -> Self {
        let mut m = Self::new(r);
        for t in items {
            m.add(&t.v);
        }
        m
    }

    /// [`Moments::of`] with AVX2 intrinsics: per vertex `d = p − r` in one register, the
    /// first moment `+= d` and the six second-moment sums as the lanes of `d.xxxy · d.xyzy`
    /// and `d.yz · d.zz`; each sum takes the same terms in the same order as [`Moments::add`].
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(unsafe_code)]
    fn of_avx2(items: &[Item], r: DVec3) -> Self {
        use core::arch::x86_64::*;
        let r4 = _mm256_setr_pd(r.x, r.y, r.z, 0.0);
        let mut first = _mm256_setzero_pd();
        let mut s0 = _mm256_setzero_pd();
        let mut s1 = _mm_setzero_pd();
        for t in items {
            for p in &t.v {
                let d = _mm256_sub_pd(_mm256_setr_pd(p.x, p.y, p.z, 0.0), r4);
                first = _mm256_add_pd(first, d);
                // [dx, dx, dx, dy] · [dx, dy, dz, dy]: second[0..4].
                let a = _mm256_permute4x64_pd::<0b01_00_00_00>(d);
                let b = _mm256_permute4x64_pd::<0b01_10_01_00>(d);
                s0 = _mm256_add_pd(s0, _mm256_mul_pd(a, b));
                // [dy, dz] · [dz, dz]: second[4..6].
                let yz = _mm256_castpd256_pd128(_mm256_permute4x64_pd::<0b00_00_10_01>(d));
                let zz = _mm256_castpd256_pd128(_mm256_permute4x64_pd::<0b00_00_10_10>(d));
                s1 = _mm_add_pd(s1, _mm_mul_pd(yz, zz));
            }
        }
        let (mut f, mut lo, mut hi) = ([0.0f64; 4], [0.0f64; 4], [0.0f64; 2]);
        // SAFETY: unaligned stores into arrays of the stored widths.
        unsafe {
            _mm256_storeu_pd(f.as_mut_ptr(), first);
            _mm256_storeu_pd(lo.as_mut_ptr(), s0);
            _mm_storeu_pd(hi.as_mut_ptr(), s1);
        }
        Self {
            r,
            first: DVec3::new(f[0], f[1], f[2]),
            second: [lo[0], lo[1], lo[2], lo[3], hi[0], hi[1]],
        }
    }

    #[inline(always)]
    fn add(&mut self, v: &[DVec3; 3]) {
        for p in v {
            let d = *p - self.r;
            self.first += d;
            self.second[0] += d.x * d.x;
            self.second[1] += d.x * d.y;
            self.second[2] += d.x * d.z;
            self.second[3] += d.y * d.y;
            self.second[4] += d.y * d.z;
            self.second[5] += d.z * d.z;
        }
    }

    /// The vertex-covariance axes of the node `items` these moments were summed over (from
    /// the moments; from a second pass when they are too far from the reference point) and
    /// the node's second moments about its mean (the upper triangle of the covariance times
    /// the vertex count, which gives its children's moments by difference, see
    /// [`side_moments`]), or `None` where the node will not need them: a lone triangle (a leaf
    /// in its own frame) and other fit rules (the node fits itself).
    fn fit(&self, items: &[Item], fit: FitMethod) -> (Option<DMat3>, Option<[f64; 6]>) {
        if fit != FitMethod::VertexCovariance || items.len() < 2 {
            return (None, None);
        }
        let cov = self
            .covariance(items.len())
            .unwrap_or_else(|| vertex_covariance(items, self.mean(items.len())));
        let count = (3 * items.len()) as f64;
        let second = [
            cov.x_axis.x,
            cov.y_axis.x,
            cov.z_axis.x,
            cov.y_axis.y,
            cov.z_axis.y,
            cov.z_axis.z,
        ]
        .map(|c| c * count);
        (Some(symmetric_eigen_axes(cov)), Some(second))
    }

    /// The mean of the `count` triangles' vertices (also the mean of their centroids), from
    /// the first moment about `r` (no separate sum, and exact offsets cost no precision).
    fn mean(&self, count: usize) -> DVec3 {
        self.r + self.first / (3 * count) as f64
    }

    /// The vertices' covariance `Σ d dᵀ / 3n − m mᵀ` (`m` the mean of `d`), or `None` where the
    /// node's mean lies so far from `r` (over 10 standard deviations) that the subtraction would
    /// cancel more than a few digits: then the caller takes the two-pass covariance about the
    /// mean instead.
    fn covariance(&self, count: usize) -> Option<DMat3> {
        let inv = 1.0 / (3 * count) as f64;
        let m = self.first * inv;
        let s = self.second.map(|x| x * inv);
        let c = [
            s[0] - m.x * m.x,
            s[1] - m.x * m.y,
            s[2] - m.x * m.z,
            s[3] - m.y * m.y,
            s[4] - m.y * m.z,
            s[5] - m.z * m.z,
        ];
        let trace = c[0] + c[3] + c[5];
        // Also `None` for NaN (overflowed sums): every comparison with it fails.
        let close = m.length_squared() <= 100.0 * trace;
        if !close || !trace.is_finite() {
            return None;
        }
        Some(DMat3::from_cols(
            DVec3::new(c[0], c[1], c[2]),
            DVec3::new(c[1], c[3], c[4]),
            DVec3::new(c[2], c[4], c[5]),
        ))
    }
}

/// The largest `p.abs().element_sum()` over the triangle's vertices.
fn magnitude(t: &Triangle) -> f64 {
    t.v.iter().fold(0.0f64, |m, p| m.max(p.abs().element_sum()))
}

/// The covariance of the triangles' vertices about `mean` (their mean: the mean of the
/// centroids), centred so large offsets cost no precision.
fn vertex_covariance(items: &[Item], mean: DVec3) -> DMat3 {
    let mut c = [0.0f64; 6];
    for t in items {
        for p in t.v {
            let d = p - mean;
            c[0] += d.x * d.x;
            c[1] += d.x * d.y;
            c[2] += d.x * d.z;
            c[3] += d.y * d.y;
            c[4] += d.y * d.z;
            c[5] += d.z * d.z;
        }
    }
    let c = c.map(|x| x / (3 * items.len()) as f64);
    DMat3::from_cols(
        DVec3::new(c[0], c[1], c[2]),
        DVec3::new(c[1], c[3], c[4]),
        DVec3::new(c[2], c[4], c[5]),
    )
}

/// One pass over a node's triangles `src` (at least two): its box with the given axes (exactly
/// [`Obb::from_points_with_axes`] over their vertices) and a partition about the plane through
/// `mean` across the major axis, written to `dst` (the left part first, the right part from the
/// back). Returns the box and the size of the left part (in `1..len`). The other two axes are
/// tried when one side would be empty, and the list is halved when all three fail.
fn box_and_split(axes: DMat3, mean: DVec3, src: &[Item], dst: &mut [Item]) -> (Obb, usize) {
    let len = src.len();
    debug_assert_eq!(len, dst.len());
    let t = axes.transpose();
    let axis = axes.x_axis;
    // Centroid `s / 3` against `cut`, as `s` against `3 cut`: no division per triangle.
    let cut3 = 3.0 * axis.dot(mean);
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    let mut mag = 0.0f64;
    // Branchless: each triangle goes to `dst[l]` (left) or `dst[r - 1]` (right).
    let (mut l, mut r) = (0usize, len);
    for item in src {
        let [a, b, c] = item.v;
        for p in [a, b, c] {
            let q = t * p;
            lo = lo.min(q);
            hi = hi.max(q);
        }
        mag = mag.max(item.mag);
        let right = axis.dot(a + b + c) >= cut3;
        let k = if right { r - 1 } else { l };
        dst[k] = *item;
        l += (!right) as usize;
        r -= right as usize;
    }
    let obb = Obb::from_projection_bounds(axes, lo, hi, mag);
    (obb, kept_or_fallback(&axes, mean, dst, l))
}

/// What [`box_and_cost_split`] keeps of a triangle between its passes, in the node's box frame
/// relative to the node's mean, in f32: three times its centroid (the sum of its vertices) and
/// the bounds of its vertices as `[lo.x, lo.y, lo.z, 0, −hi.x, −hi.y, −hi.z, 0]` (both halves
/// merge by `min`, so a merge is two four-lane minimums). Only the tree's shape depends on
/// these values (boxes are made from the f64 vertices), so their rounding costs no correctness.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(16))]
struct Probe {
    bounds: [f32; 8],
    sum: [f32; 4],
}

/// Candidate cuts per axis for [`SplitMethod::SurfaceCost`] (the bins' inner boundaries).
const BINS: usize = 16;

/// The triangles of one bin of one axis: how many, and the bounds of their vertices (as in
/// [`Probe::bounds`]).
#[derive(Clone, Copy)]
#[repr(C, align(16))]
struct Bin {
    bounds: [f32; 8],
    count: u32,
}

impl Bin {
    const EMPTY: Bin = Bin {
        bounds: [f32::INFINITY; 8],
        count: 0,
    };

    #[inline(always)]
    fn merge(&mut self, bounds: &[f32; 8], count: u32) {
        // Plain compares (`minps`) rather than `f32::min`'s NaN handling: probes are never
        // NaN (finite f64 values converted), and a bound only feeds a cost.
        // Indexed, not zipped: the zipped form compiled to scalar code and made the whole
        // surface-cost build about 20 % slower (knot: 90 against 73 ms).
        #[allow(clippy::needless_range_loop)]
        for i in 0..8 {
            let (b, p) = (self.bounds[i], bounds[i]);
            self.bounds[i] = if p < b { p } else { b };
        }
        self.count += count;
    }
}

/// One side (left or right) of each of an axis's candidate cuts, as columns: the extents of
/// its triangles' vertex bounds and its triangle count.
struct Sides {
    extent: [[f32; BINS]; 3],
    count: [u32; BINS],
}

impl Sides {
    const EMPTY: Sides = Sides {
        extent: [[0.0; BINS]; 3],
        count: [0; BINS],
    };

    /// Candidate `b`'s side: the triangles merged into `acc`. An empty side's extents are
    /// −inf (its bounds +inf) and its cost NaN; [`cheapest_cut`] never reads that cost (a
    /// candidate with an empty side is skipped), so no clamp is spent on it.
    #[inline(always)]
    fn set(&mut self, b: usize, acc: &Bin) {
        for k in 0..3 {
            self.extent[k][b] = -(acc.bounds[k + 4] + acc.bounds[k]);
        }
        self.count[b] = acc.count;
    }

    /// Every candidate side's cost (a vectorised loop over all `BINS` columns): its
    /// triangle count times the surface measure of its extents (see
    /// [`SplitMethod::SurfaceCost`]). In f32: extents beyond about 10¹⁹ give an infinite cost
    /// and counts beyond 2²⁴ round, and ties then keep the first candidate (a shape choice,
    /// never a correctness one).
    #[inline(always)]
    fn costs(&self) -> [f32; BINS] {
        let [x, y, z] = &self.extent;
        let mut out = [0.0f32; BINS];
        for b in 0..BINS {
            out[b] = side_cost(x[b], y[b], z[b], self.count[b]);
        }
        out
    }
}

/// A side's cost for [`SplitMethod::SurfaceCost`]: its triangle `count` times the surface
/// measure `xy + yz + zx + ((x + y + z) / 3)²` of its extents.
#[inline(always)]
fn side_cost(x: f32, y: f32, z: f32, count: u32) -> f32 {
    let mean = (x + y + z) * (1.0 / 3.0);
    (x * y + y * z + z * x + mean * mean) * count as f32
}

/// The bin of a centroid coordinate `sum` on an axis binned from `min` with `scale` bins per
/// unit (the same function places a triangle in the choice and in the partition, so the
/// chosen cut leaves exactly the counted triangles on each side).
#[inline(always)]
fn bin_of(sum: f32, min: f32, scale: f32, bins: usize) -> usize {
    // Clamped as a float first (a NaN would land in the last bin; `cheapest_cut` bins only
    // axes whose range is finite, so every coordinate is): the conversion is then in range.
    let x = (sum - min) * scale;
    let last = (bins - 1) as f32;
    let x = if x < last { x } else { last };
    let x = if x > 0.0 { x } else { 0.0 };
    // SAFETY: `x` is finite and in `0..=last` (the two selects above turn every value, NaN
    // included, into one of `0`, `last` or an `x` between them), so it truncates to a value
    // in range of i32. The checked `as` spent a compare, a NaN test and two selects on each
    // of the build's millions of calls (4 % of a build's instructions).
    #[allow(unsafe_code)]
    let i = unsafe { x.to_int_unchecked::<i32>() };
    i as usize
}

/// The cut of least [`Sides::costs`] over the node's probes, or `None` where no axis has two
/// distinct (finite) centroid coordinates to cut between. `bins` is scratch space (one set per
/// build: only the node's `nb` bins per axis are emptied, not all of them).
#[inline(always)]
fn cheapest_cut(
    probes: &[Probe],
    min: [f32; 3],
    max: [f32; 3],
    bins: &mut [[Bin; BINS]; 3],
) -> Option<Cut> {
    // Small nodes (most of a tree's nodes) get one bin per triangle: the same candidates a
    // sorted sweep would mostly see, for a fraction of the fixed cost of 16 bins.
    let nb = probes.len().clamp(2, BINS);
    let scale = [0, 1, 2].map(|k| nb as f32 / (max[k] - min[k]));
    let usable = [0, 1, 2].map(|k| max[k] > min[k] && scale[k].is_finite() && scale[k] > 0.0);
    if !usable.iter().any(|&u| u) {
        return None;
    }
    fill_bins(probes, min, scale, nb, bins);
    let total = probes.len() as u32;
    let mut best: Option<(f32, usize, usize)> = None;
    for k in (0..3).filter(|&k| usable[k]) {
        // Both sides of every candidate (cut after bin `b`) first, as columns of extents and
        // counts; then all candidates' costs in one loop the compiler vectorises, instead of
        // one cost at a time in the sweeps.
        let mut sides = [Sides::EMPTY; 2];
        let mut acc = Bin::EMPTY;
        for (b, bin) in bins[k][..nb - 1].iter().enumerate() {
            acc.merge(&bin.bounds, bin.count);
            sides[0].set(b, &acc);
        }
        let mut acc = Bin::EMPTY;
        for (b, bin) in bins[k][1..nb].iter().enumerate().rev() {
            acc.merge(&bin.bounds, bin.count);
            sides[1].set(b, &acc);
        }
        let (l, r) = (sides[0].costs(), sides[1].costs());
        for b in 0..nb - 1 {
            let left = sides[0].count[b];
            if left == 0 || left == total {
                continue;
            }
            let cost = l[b] + r[b];
            // Strictly less: ties keep the earlier axis (the major axis first).
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, k, b));
            }
        }
    }
    best.map(|(_, k, b)| Cut {
        axis: k,
        min: min[k],
        scale: scale[k],
        bins: nb,
        last_left: b,
    })
}

/// Empties the first `nb` bins of each axis and merges each probe into its bin on each axis
/// (bins of `min`, `scale`, `nb` as [`bin_of`]).
/// In the AVX2 build where the CPU has it (`isa.rs`): a merge is one 256-bit minimum.
#[inline(always)]
fn fill_bins(
    probes: &[Probe],
    min: [f32; 3],
    scale: [f32; 3],
    nb: usize,
    bins: &mut [[Bin; BINS]; 3],
) {
    #[cfg(target_arch = "x86_64")]
    if crate::isa::has_avx2() {
        // SAFETY: the running CPU has AVX2 (`isa::has_avx2`), the one feature
        // `fill_bins_avx2` is compiled with.
        #[allow(unsafe_code)]
        unsafe {
            fill_bins_avx2(probes, min, scale, nb, bins)
        };
        return;
    }
    fill_bins_plain(probes, min, scale, nb, bins);
}

/// [`fill_bins`] in the baseline build.
fn fill_bins_plain(
    probes: &[Probe],
    min: [f32; 3],
    scale: [f32; 3],
    nb: usize,
    bins: &mut [[Bin; BINS]; 3],
) {
    for axis in bins.iter_mut() {
        axis[..nb].fill(Bin::EMPTY);
    }
    for p in probes {
        for k in 0..3 {
            bins[k][bin_of(p.sum[k], min[k], scale[k], nb)].merge(&p.bounds, 1);
        }
    }
}

/// [`fill_bins`] with AVX2 intrinsics: [`Bin::merge`]'s `p < b ? p : b` is `vminps p, b`, so
/// the bins get the same bits. (The compiler's own AVX2 build of the merge loop turned the
/// select into masked stores, slower than the baseline.)
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(unsafe_code)]
fn fill_bins_avx2(
    probes: &[Probe],
    min: [f32; 3],
    scale: [f32; 3],
    nb: usize,
    bins: &mut [[Bin; BINS]; 3],
) {
    use core::arch::x86_64::*;
    // Emptied with 256-bit stores too: a 256-bit load of a bin written by narrower stores
    // would wait for them instead of taking their data forwarded.
    let empty = _mm256_set1_ps(f32::INFINITY);
    for axis in bins.iter_mut() {
        for bin in &mut axis[..nb] {
            // SAFETY: `bounds` is eight f32 (an unaligned store).
            unsafe { _mm256_storeu_ps(bin.bounds.as_mut_ptr(), empty) };
            bin.count = 0;
        }
    }
    for p in probes {
        // SAFETY: `bounds` is eight f32 (unaligned loads and stores).
        let pb = unsafe { _mm256_loadu_ps(p.bounds.as_ptr()) };
        for k in 0..3 {
            let bin = &mut bins[k][bin_of(p.sum[k], min[k], scale[k], nb)];
            let at = bin.bounds.as_mut_ptr();
            // SAFETY: as above.
            unsafe { _mm256_storeu_ps(at, _mm256_min_ps(pb, _mm256_loadu_ps(at))) };
            bin.count += 1;
        }
    }
}

/// A cut chosen by [`cheapest_cut`]: triangles whose centroid falls in bins `..=last_left` of
/// `axis` go left.
#[derive(Clone, Copy, Debug)]
struct Cut {
    axis: usize,
    min: f32,
    scale: f32,
    bins: usize,
    last_left: usize,
}

/// [`SplitMethod::SurfaceCost`]'s version of [`box_and_split`]: the same box, with the cut
/// chosen by [`cheapest_cut`]. Two passes: the first projects the vertices (the box) and keeps
/// each triangle's [`Probe`], the bins are then filled from the probes, and the second pass
/// partitions. A node of at most [`EXHAUSTIVE_MAX`] triangles takes [`cheapest_partition`]
/// instead of binning. Where no cut is usable, the cut of
/// [`box_and_split`] (through `mean` across the major axis) is taken.
fn box_and_cost_split(
    axes: DMat3,
    mean: DVec3,
    src: &[Item],
    dst: &mut [Item],
    probes: &mut [Probe],
    bins: &mut [[Bin; BINS]; 3],
) -> (Obb, usize) {
    #[cfg(target_arch = "x86_64")]
    if crate::isa::has_avx2() {
        // SAFETY: the running CPU has AVX2 (`isa::has_avx2`), the one feature
        // `box_and_cost_split_avx2` is compiled with.
        #[allow(unsafe_code)]
        return unsafe { box_and_cost_split_avx2(axes, mean, src, dst, probes, bins) };
    }
    box_and_cost_split_body(axes, mean, src, dst, probes, bins)
}

/// [`box_and_cost_split`] compiled with AVX2 (the same operations: the same cut).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn box_and_cost_split_avx2(
    axes: DMat3,
    mean: DVec3,
    src: &[Item],
    dst: &mut [Item],
    probes: &mut [Probe],
    bins: &mut [[Bin; BINS]; 3],
) -> (Obb, usize) {
    box_and_cost_split_body(axes, mean, src, dst, probes, bins)
}

/// The body of [`box_and_cost_split`], inlined into each of its instruction-set builds.
#[inline(always)]
fn box_and_cost_split_body(
    axes: DMat3,
    mean: DVec3,
    src: &[Item],
    dst: &mut [Item],
    probes: &mut [Probe],
    bins: &mut [[Bin; BINS]; 3],
) -> (Obb, usize) {
    let len = src.len();
    debug_assert!(len == dst.len() && len == probes.len());
    let t = axes.transpose();
    let m = t * mean;
    let (lo, hi, mag) = project(&t, m, src, probes);
    // The centroids' range, in a pass of its own over the probes (in the pass above its six
    // accumulators spilled registers).
    let mut smin = [f32::INFINITY; 4];
    let mut smax = [f32::NEG_INFINITY; 4];
    for p in probes.iter() {
        for k in 0..4 {
            let v = p.sum[k];
            smin[k] = if v < smin[k] { v } else { smin[k] };
            smax[k] = if v > smax[k] { v } else { smax[k] };
        }
    }
    let (smin, smax) = ([smin[0], smin[1], smin[2]], [smax[0], smax[1], smax[2]]);
    let obb = Obb::from_projection_bounds(axes, lo, hi, mag);
    let left = if len <= EXHAUSTIVE_MAX {
        let mask = cheapest_partition(probes);
        partition(src, dst, |i| mask >> i & 1 != 0)
    } else {
        match cheapest_cut(probes, smin, smax, bins) {
            Some(c) => partition(src, dst, |i| {
                bin_of(probes[i].sum[c.axis], c.min, c.scale, c.bins) > c.last_left
            }),
            None => partition(src, dst, |i| probes[i].sum[0] >= 0.0),
        }
    };
    (obb, kept_or_fallback(&axes, mean, dst, left))
}

/// [`box_and_cost_split`]'s first pass: the bounds of the vertices `t · p` of `src`'s triangles
/// (the rows of `t` are the box axes), their largest magnitude, and each triangle's [`Probe`]
/// relative to `m` (the node's mean in the same frame). Run in the AVX2 build where the CPU
/// has it (as the wide traversal, `isa.rs`): the same operations in the same order, so the
/// same bits, in one 256-bit register per vertex instead of two 128-bit ones.
fn project(t: &DMat3, m: DVec3, src: &[Item], probes: &mut [Probe]) -> (DVec3, DVec3, f64) {
    #[cfg(target_arch = "x86_64")]
    if crate::isa::has_avx2() {
        // SAFETY: the running CPU has AVX2 (`isa::has_avx2`), the one feature
        // `project_avx2` is compiled with.
        #[allow(unsafe_code)]
        return unsafe { project_avx2(t, m, src, probes) };
    }
    project_body(t, m, src, probes)
}

/// [`project_body`] written with AVX2 intrinsics, one 256-bit register per vertex (the
/// compiler's own vectorisation of the lane arrays shuffled more than it computed): the same
/// IEEE operations in the same order and with the same operands, so the same bits, NaN and
/// signed zeros included (`vminpd x, y` is `x < y ? x : y`, which is [`min_lane`]`(y, x)`).
/// Tested against [`project_body`] (`both_projections_give_the_same_bits`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(unsafe_code)]
fn project_avx2(t: &DMat3, m: DVec3, src: &[Item], probes: &mut [Probe]) -> (DVec3, DVec3, f64) {
    use core::arch::x86_64::*;
    let col = |c: DVec3| _mm256_setr_pd(c.x, c.y, c.z, 0.0);
    let (c0, c1, c2) = (col(t.x_axis), col(t.y_axis), col(t.z_axis));
    let m4 = col(m);
    let m3 = _mm256_mul_pd(_mm256_set1_pd(3.0), m4);
    // Lane 3 of a product is ±0 (0 times a coordinate); the probes' padding is +0.
    let keep = _mm256_castsi256_pd(_mm256_setr_epi64x(-1, -1, -1, 0));
    let mut lo = _mm256_set1_pd(f64::INFINITY);
    let mut hi = _mm256_set1_pd(f64::NEG_INFINITY);
    let mut mag = 0.0f64;
    for (item, probe) in src.iter().zip(probes.iter_mut()) {
        // `t * p` lane by lane: `(t₀ₖ pₓ + t₁ₖ p_y) + t₂ₖ p_z`.
        macro_rules! project {
            ($p:expr) => {
                _mm256_add_pd(
                    _mm256_add_pd(
                        _mm256_mul_pd(c0, _mm256_set1_pd($p.x)),
                        _mm256_mul_pd(c1, _mm256_set1_pd($p.y)),
                    ),
                    _mm256_mul_pd(c2, _mm256_set1_pd($p.z)),
                )
            };
        }
        let a = project!(item.v[0]);
        let b = project!(item.v[1]);
        let c = project!(item.v[2]);
        let tlo = _mm256_min_pd(c, _mm256_min_pd(b, a));
        let thi = _mm256_max_pd(c, _mm256_max_pd(b, a));
        lo = _mm256_min_pd(tlo, lo);
        hi = _mm256_max_pd(thi, hi);
        let sum = _mm256_sub_pd(_mm256_add_pd(_mm256_add_pd(a, b), c), m3);
        let l = _mm256_cvtpd_ps(_mm256_and_pd(_mm256_sub_pd(tlo, m4), keep));
        let h = _mm256_cvtpd_ps(_mm256_and_pd(_mm256_sub_pd(m4, thi), keep));
        let sum = _mm256_cvtpd_ps(_mm256_and_pd(sum, keep));
        // SAFETY: `Probe` is `repr(C)`: `bounds` is eight f32 at offset 0, `sum` four at 32;
        // the stores are unaligned ones.
        unsafe {
            let at = (probe as *mut Probe).cast::<f32>();
            _mm_storeu_ps(at, l);
            _mm_storeu_ps(at.add(4), h);
            _mm_storeu_ps(at.add(8), sum);
        }
        mag = max_lane(mag, item.mag);
    }
    let mut out = [[0.0f64; 4]; 2];
    // SAFETY: two unaligned stores into arrays of four f64.
    unsafe {
        _mm256_storeu_pd(out[0].as_mut_ptr(), lo);
        _mm256_storeu_pd(out[1].as_mut_ptr(), hi);
    }
    let v = |x: [f64; 4]| DVec3::new(x[0], x[1], x[2]);
    (v(out[0]), v(out[1]), mag)
}

/// The body of [`project`] (the baseline build): each lane computes what `t * p` computes for
/// its row, `(t₀ₖ pₓ + t₁ₖ p_y) + t₂ₖ p_z`, and the probe what [`Probe`] documents.
#[inline(always)]
fn project_body(t: &DMat3, m: DVec3, src: &[Item], probes: &mut [Probe]) -> (DVec3, DVec3, f64) {
    let col = |c: DVec3| [c.x, c.y, c.z];
    let cols = [col(t.x_axis), col(t.y_axis), col(t.z_axis)];
    let m = col(m);
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    let mut mag = 0.0f64;
    for (item, probe) in src.iter().zip(probes.iter_mut()) {
        let mut q = [[0.0f64; 3]; 3];
        for (q, p) in q.iter_mut().zip(&item.v) {
            for k in 0..3 {
                q[k] = cols[0][k] * p.x + cols[1][k] * p.y + cols[2][k] * p.z;
            }
        }
        let [a, b, c] = q;
        let mut out = Probe::default();
        for k in 0..3 {
            let tlo = min_lane(min_lane(a[k], b[k]), c[k]);
            let thi = max_lane(max_lane(a[k], b[k]), c[k]);
            lo[k] = min_lane(lo[k], tlo);
            hi[k] = max_lane(hi[k], thi);
            out.bounds[k] = (tlo - m[k]) as f32;
            out.bounds[k + 4] = (m[k] - thi) as f32;
            out.sum[k] = (a[k] + b[k] + c[k] - 3.0 * m[k]) as f32;
        }
        *probe = out;
        mag = max_lane(mag, item.mag);
    }
    let v = |x: [f64; 3]| DVec3::new(x[0], x[1], x[2]);
    (v(lo), v(hi), mag)
}

/// `min(a, b)` as a plain compare and select (`minsd`/`minpd`): a NaN `b` is skipped (the
/// build's accumulators start finite and never take one), like [`f64::min`], whose NaN test
/// costs four more instructions per lane; only the sign of a zero may differ.
#[inline(always)]
fn min_lane(a: f64, b: f64) -> f64 {
    if b < a { b } else { a }
}

/// `max(a, b)` as [`min_lane`].
#[inline(always)]
fn max_lane(a: f64, b: f64) -> f64 {
    if b > a { b } else { a }
}

/// Copies `src` into `dst`, the triangles for which `right(i)` is false to the front in order
/// and the others to the back (branchless); returns how many went to the front.
#[inline(always)]
fn partition(src: &[Item], dst: &mut [Item], right: impl Fn(usize) -> bool) -> usize {
    let (mut l, mut r) = (0usize, src.len());
    for (i, item) in src.iter().enumerate() {
        let right = right(i);
        let k = if right { r - 1 } else { l };
        dst[k] = *item;
        l += (!right) as usize;
        r -= right as usize;
    }
    l
}

/// The largest node [`cheapest_partition`] splits (a quarter of a tree's internal nodes have
/// 3 triangles and another quarter 4).
const EXHAUSTIVE_MAX: usize = 4;

/// For a node of at most [`EXHAUSTIVE_MAX`] triangles (at least two): the partition of least
/// surface cost (as [`Sides::costs`]) among all of them into two non-empty sides (3 for three
/// triangles, 7 for four), as the bit mask of the triangles going right; `0` where no cost is
/// finite (the caller's fallback then splits).
fn cheapest_partition(probes: &[Probe]) -> u32 {
    let n = probes.len();
    debug_assert!((2..=EXHAUSTIVE_MAX).contains(&n));
    let full = (1u32 << n) - 1;
    let mut best = (f32::INFINITY, 0u32);
    // Each partition once: the masks that send the last triangle right, all but `full`.
    for mask in (1 << (n - 1))..full {
        let cost = subset_cost(probes, mask) + subset_cost(probes, full & !mask);
        // Strictly less: NaN and infinite costs never win.
        if cost < best.0 {
            best = (cost, mask);
        }
    }
    best.1
}

/// The surface cost ([`side_cost`]) of the probes whose bits are set in `mask`. (A function,
/// not a closure: a closure was left out of line, also in the AVX2 build.)
#[inline(always)]
fn subset_cost(probes: &[Probe], mask: u32) -> f32 {
    let mut acc = Bin::EMPTY;
    for (i, p) in probes.iter().enumerate() {
        if mask >> i & 1 != 0 {
            acc.merge(&p.bounds, 1);
        }
    }
    let (x, y, z) = (
        -(acc.bounds[4] + acc.bounds[0]),
        -(acc.bounds[5] + acc.bounds[1]),
        -(acc.bounds[6] + acc.bounds[2]),
    );
    side_cost(x, y, z, acc.count)
}

/// The end of both partitions: the left part's size `left` when both sides are non-empty,
/// else [`split_fallback`]'s partition of `dst`.
fn kept_or_fallback(axes: &DMat3, mean: DVec3, dst: &mut [Item], left: usize) -> usize {
    if left > 0 && left < dst.len() {
        left
    } else {
        split_fallback(axes, mean, dst)
    }
}

/// The [`Moments`] of a node's two sides `left` and `right` about the node's `mean`: the
/// smaller side summed, the larger one the node's `second` moments about its mean (from
/// [`Moments::fit`]) minus the smaller side's, so a split sums only about a third of its
/// triangles. The larger side is summed too where `second` is unknown or the difference
/// cancels more than six of its digits (its trace under 10⁻⁶ of the node's): the moments only
/// choose the children's axes and means, but these should stay as good as summed ones.
fn side_moments(
    left: &[Item],
    right: &[Item],
    mean: DVec3,
    second: Option<&[f64; 6]>,
) -> [Moments; 2] {
    let Some(total) = second else {
        return [Moments::of(left, mean), Moments::of(right, mean)];
    };
    let left_smaller = left.len() <= right.len();
    let (small, large) = if left_smaller {
        (left, right)
    } else {
        (right, left)
    };
    let small = Moments::of(small, mean);
    let trace = |s: &[f64; 6]| s[0] + s[3] + s[5];
    let mut rest = Moments::new(mean);
    rest.first = -small.first;
    for ((r, t), s) in rest.second.iter_mut().zip(total).zip(&small.second) {
        *r = t - s;
    }
    // Also false for NaN.
    let large = if trace(&rest.second) > 1e-6 * trace(total) {
        rest
    } else {
        Moments::of(large, mean)
    };
    if left_smaller {
        [small, large]
    } else {
        [large, small]
    }
}

/// Axes for a leaf of two triangles: the normal of their area-weighted mean plane and, in
/// that plane, the longest of their edges that they do not share. A quad split along its
/// diagonal gets its sides (the vertex covariance counts the diagonal's ends twice and tilts
/// the box toward it), for two square roots instead of an eigen-solve. `None` where the
/// normals cancel or every unshared edge is degenerate (the caller takes the covariance).
fn pair_frame(a: &Item, b: &Item) -> Option<DMat3> {
    let (na, nb) = (a.triangle().normal(), b.triangle().normal());
    let sum = na + nb;
    // Folded more than about 120° (a fin, a crease): no plane fits both, take the covariance.
    // (NaN passes here and fails the finiteness test below.)
    if sum.length() < 0.5 * (na.length() + nb.length()) {
        return None;
    }
    let n = sum.normalize_or_zero();
    let mut x = DVec3::ZERO;
    let mut longest = 0.0f64;
    for (t, other) in [(a, b), (b, a)] {
        for i in 0..3 {
            let (p, q) = (t.v[i], t.v[(i + 1) % 3]);
            if other.v.contains(&p) && other.v.contains(&q) {
                continue;
            }
            let e = q - p;
            // Projected into the plane twice: once leaves up to a rounding of |e| along `n`
            // when `e` is nearly normal to it, the second removes that (the axes must be
            // orthonormal to rounding, not to the edge's angle).
            let e = e - n * n.dot(e);
            let e = e - n * n.dot(e);
            let l = e.length_squared();
            if l > longest {
                longest = l;
                x = e;
            }
        }
    }
    let x = x.normalize_or_zero();
    if n == DVec3::ZERO || x == DVec3::ZERO || !(n.is_finite() && x.is_finite()) {
        return None;
    }
    Some(DMat3::from_cols(x, n.cross(x), n))
}

/// The box of one triangle in its own frame ([`triangle_frame`]), as a leaf gets it.
#[cfg(test)]
fn triangle_obb(t: &Triangle) -> Option<Obb> {
    triangle_frame(t).map(|axes| Obb::from_points_with_axes(&t.v, axes))
}

/// One triangle's own frame (longest edge, in-plane normal to it, normal), in which its box is
/// flat and tight whatever the fit rule. `None` for a triangle without a usable normal.
fn triangle_frame(t: &Triangle) -> Option<DMat3> {
    let e = [t.v[1] - t.v[0], t.v[2] - t.v[1], t.v[0] - t.v[2]];
    let longest = e
        .iter()
        .copied()
        .max_by(|a, b| a.length_squared().total_cmp(&b.length_squared()))?;
    let x = longest.normalize_or_zero();
    let n = t.normal().normalize_or_zero();
    let z = (n - x * x.dot(n)).normalize_or_zero();
    if x == DVec3::ZERO || z == DVec3::ZERO || !(x.is_finite() && z.is_finite()) {
        return None;
    }
    let y = z.cross(x);
    Some(DMat3::from_cols(x, y, z))
}

/// [`box_and_split`]'s partition when the major axis leaves one side empty: the other two axes,
/// then halving, in place. Returns the size of the left part (in `1..len`).
fn split_fallback(obb_axes: &DMat3, mean: DVec3, items: &mut [Item]) -> usize {
    let len = items.len();
    for axis in [obb_axes.y_axis, obb_axes.z_axis] {
        let cut = axis.dot(mean);
        let mut i = 0;
        let mut j = len;
        while i < j {
            if axis.dot(items[i].triangle().centroid()) < cut {
                i += 1;
            } else {
                j -= 1;
                items.swap(i, j);
            }
        }
        if i > 0 && i < len {
            return i;
        }
    }
    // All centroids project to the same point on every axis: halve the list.
    len / 2
}

#[cfg(test)]
mod tests {
    use super::*;
    use frcd_geom::Pose;

    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        }
        fn point(&mut self) -> DVec3 {
            DVec3::new(self.next(), self.next(), self.next())
        }
    }

    fn soup(tris: &[[DVec3; 3]]) -> TriMesh {
        let vertices = tris.iter().flatten().copied().collect();
        let indices = (0..tris.len() as u32)
            .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
            .collect();
        TriMesh::new(vertices, indices).expect("valid soup")
    }

    /// `None` where the scale overflows (the mixed mesh at the huge scale).
    fn scaled(mesh: &TriMesh, s: f64, offset: DVec3) -> Option<TriMesh> {
        let v = mesh.vertices().iter().map(|&p| p * s + offset).collect();
        TriMesh::new(v, mesh.indices().to_vec()).ok()
    }

    /// Random and degenerate meshes, at unit, subnormal, huge and offset scales.
    fn meshes() -> Vec<(String, TriMesh)> {
        let mut rng = Rng(9);
        let random: Vec<[DVec3; 3]> = (0..300)
            .map(|_| {
                let c = rng.point() * 10.0;
                [c + rng.point(), c + rng.point(), c + rng.point()]
            })
            .collect();
        let d = DVec3::new(1.0, 2.0, -0.5);
        let collinear: Vec<[DVec3; 3]> = (0..40)
            .map(|i| {
                let a = i as f64;
                [d * a, d * (a + 0.5), d * (a + 2.0)]
            })
            .collect();
        let (u, v) = (DVec3::new(1.0, 1.0, 0.0), DVec3::new(0.0, 1.0, 3.0));
        let coplanar: Vec<[DVec3; 3]> = (0..60)
            .map(|_| {
                let mut p = || u * rng.next() + v * rng.next();
                [p(), p(), p()]
            })
            .collect();
        let point = vec![[DVec3::splat(0.25); 3]; 17];
        let t = [DVec3::ZERO, DVec3::X, DVec3::new(0.3, 0.7, 0.1)];
        let duplicates = vec![t; 33];
        let sphere = frcd_geom::shapes::icosphere(1.0, 3).transformed(&Pose::new(
            DVec3::new(0.1, -0.2, 0.3),
            frcd_geom::DQuat::from_rotation_y(0.4),
        ));
        let mut mixed = random.clone();
        mixed.extend(random.iter().take(50).map(|t| t.map(|p| p * 1e-9)));
        mixed.extend(random.iter().take(50).map(|t| t.map(|p| p * 1e9)));
        let base: Vec<(&str, TriMesh)> = vec![
            ("random", soup(&random)),
            ("collinear", soup(&collinear)),
            ("coplanar", soup(&coplanar)),
            ("point", soup(&point)),
            ("duplicates", soup(&duplicates)),
            ("sphere", sphere),
            ("mixed", soup(&mixed)),
        ];
        let mut out = Vec::new();
        for (name, m) in base {
            for (label, s, offset) in [
                ("subnormal", 2f64.powi(-1062), DVec3::ZERO),
                ("huge", 1e305, DVec3::ZERO),
                ("offset", 1e-3, DVec3::new(1e9, -3e8, 7e7)),
            ] {
                out.extend(scaled(&m, s, offset).map(|m| (format!("{name} {label}"), m)));
            }
            out.push((name.to_string(), m));
        }
        out
    }

    /// Walks the depth-first nodes; returns each node's range in `order` (`lo..hi`).
    fn ranges(nodes: &[Node], n: usize) -> Vec<(usize, usize)> {
        let mut out = vec![(0, 0); nodes.len()];
        // Children first: a node's range is the union of its children's.
        fn walk(nodes: &[Node], i: usize, out: &mut [(usize, usize)], next: &mut usize) {
            let node = &nodes[i];
            if node.is_leaf() {
                assert_eq!(node.first as usize, *next, "leaves in depth-first order");
                out[i] = (*next, *next + node.count as usize);
                *next += node.count as usize;
                return;
            }
            assert!(
                node.right as usize > i + 1,
                "right child after the left subtree"
            );
            walk(nodes, i + 1, out, next);
            walk(nodes, node.right as usize, out, next);
            out[i] = (out[i + 1].0, out[node.right as usize].1);
        }
        let mut next = 0;
        walk(nodes, 0, &mut out, &mut next);
        assert_eq!(next, n, "the leaves hold every triangle once");
        out
    }

    #[test]
    fn every_box_holds_its_triangles_and_equals_the_projection_box() {
        for (name, mesh) in meshes() {
            for fit in [
                FitMethod::VertexCovariance,
                FitMethod::AreaWeighted,
                FitMethod::HullSurface,
            ] {
                for (leaf, split) in [1, 3].into_iter().flat_map(|l| {
                    [SplitMethod::SurfaceCost, SplitMethod::MajorAxisMean].map(|s| (l, s))
                }) {
                    let options = BuildOptions {
                        fit,
                        max_leaf_triangles: leaf,
                        split,
                    };
                    let (nodes, order) = build_nodes(&mesh, &options);
                    let n = mesh.triangle_count();
                    let mut seen = vec![false; n];
                    for &t in &order {
                        assert!(!std::mem::replace(&mut seen[t as usize], true));
                    }
                    assert!(seen.iter().all(|&s| s), "{name}: order is a permutation");
                    let leaves = nodes.iter().filter(|x| x.is_leaf()).count();
                    assert_eq!(nodes.len(), 2 * leaves - 1, "{name}: a binary tree");
                    for (i, &(lo, hi)) in ranges(&nodes, n).iter().enumerate() {
                        let obb = nodes[i].obb;
                        assert!(obb.half_extents.is_finite() && obb.center.is_finite());
                        assert!(obb.half_extents.cmpge(DVec3::ZERO).all());
                        let o = obb.axes.transpose() * obb.axes - DMat3::IDENTITY;
                        assert!(o.to_cols_array().iter().all(|x| x.abs() < 1e-12));
                        let points: Vec<DVec3> = order[lo..hi]
                            .iter()
                            .flat_map(|&t| mesh.triangle(t as usize).v)
                            .collect();
                        for p in &points {
                            assert!(
                                obb.contains_point(*p),
                                "{name} {fit:?} {split:?} leaf {leaf}: node {i} misses {p}"
                            );
                        }
                        if !nodes[i].is_leaf() {
                            // The fused pass builds exactly the box of the node's points.
                            assert_eq!(obb, Obb::from_points_with_axes(&points, obb.axes));
                            assert!(hi - lo > leaf as usize);
                        } else {
                            assert!(hi - lo <= leaf as usize && hi > lo);
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn compact_build_equals_the_converted_f64_build() {
        for (name, mesh) in meshes() {
            for fit in [FitMethod::VertexCovariance, FitMethod::AreaWeighted] {
                for (leaf, split) in [
                    (1, SplitMethod::SurfaceCost),
                    (2, SplitMethod::SurfaceCost),
                    (5, SplitMethod::SurfaceCost),
                    (2, SplitMethod::MajorAxisMean),
                ] {
                    let options = BuildOptions {
                        fit,
                        max_leaf_triangles: leaf,
                        split,
                    };
                    let (nodes, order) = build_nodes(&mesh, &options);
                    let (want_nodes, want_ends) = crate::nodes::compact(&nodes, order.len());
                    let (got_nodes, got_order, got_ends) = build_compact(&mesh, &options);
                    assert_eq!(got_order, order, "{name} {fit:?} {leaf}");
                    assert_eq!(got_nodes, want_nodes, "{name} {fit:?} {leaf}");
                    assert_eq!(got_ends, want_ends, "{name} {fit:?} {leaf}");
                }
            }
        }
    }

    /// The old build (a fit per node, then a separate split pass): the fused build must give
    /// trees as tight (total box surface within a few percent).
    fn reference_surface(mesh: &TriMesh) -> f64 {
        let mut items: Vec<Item> = mesh
            .triangles()
            .enumerate()
            .map(|(i, t)| Item {
                v: t.v,
                mag: magnitude(&t),
                id: i as u32,
            })
            .collect();
        let mut scratch = items.clone();
        let mut total = 0.0;
        let mut stack = vec![(0, items.len())];
        while let Some((lo, hi)) = stack.pop() {
            let tris: Vec<Triangle> = items[lo..hi].iter().map(Item::triangle).collect();
            let obb = fit_obb(&tris, FitMethod::VertexCovariance);
            let obb = match &tris[..] {
                [t] => triangle_obb(t).unwrap_or(obb),
                _ => obb,
            };
            total += surface(&obb);
            if hi - lo <= 1 {
                continue;
            }
            let mean = tris.iter().map(Triangle::centroid).sum::<DVec3>() / (hi - lo) as f64;
            let (_, mid) = box_and_split(obb.axes, mean, &items[lo..hi], &mut scratch[lo..hi]);
            items[lo..hi].copy_from_slice(&scratch[lo..hi]);
            stack.push((lo, lo + mid));
            stack.push((lo + mid, hi));
        }
        total
    }

    fn surface(obb: &Obb) -> f64 {
        let e = obb.half_extents;
        8.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    #[test]
    fn trees_are_as_tight_as_the_per_node_fit() {
        let knot = frcd_geom::shapes::torus_knot(&frcd_geom::shapes::TorusKnotParams {
            tubular_segments: 200,
            radial_segments: 12,
            ..Default::default()
        })
        .expect("valid knot");
        for (name, mesh) in [
            ("sphere", frcd_geom::shapes::icosphere(1.0, 4)),
            ("knot", knot),
        ] {
            // The reference splits down to one triangle per leaf.
            let leaf_one = BuildOptions {
                max_leaf_triangles: 1,
                split: SplitMethod::MajorAxisMean,
                ..BuildOptions::default()
            };
            let (nodes, _) = build_nodes(&mesh, &leaf_one);
            let got: f64 = nodes.iter().map(|n| surface(&n.obb)).sum();
            let want = reference_surface(&mesh);
            assert!(
                (got / want - 1.0).abs() < 0.03,
                "{name}: total box surface {got} against {want}"
            );
        }
    }

    /// A flat `length × width` plate at height `z`, `n × n` rectangles of two triangles each.
    fn plate(n: u32, length: f64, width: f64, z: f64) -> TriMesh {
        let mut vertices = Vec::new();
        for i in 0..=n {
            for j in 0..=n {
                let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
                vertices.push(DVec3::new(x * length, y * width, z));
            }
        }
        let at = |i: u32, j: u32| i * (n + 1) + j;
        let mut indices = Vec::new();
        for i in 0..n {
            for j in 0..n {
                indices.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                indices.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        TriMesh::new(vertices, indices).expect("valid plate")
    }

    /// Two parallel 10 × 8 plates 5 apart: the vertices spread most along the plates' length
    /// (variance 8.3, against 6.25 across the gap and 5.3 across the width), so the mean cut
    /// across the major axis halves both plates (each child's box 5 × 8 × 5), where the surface
    /// cost separates the plates (each child flat: 116 per triangle against 141).
    #[test]
    fn surface_cost_separates_parallel_plates_that_the_mean_cut_halves() {
        let mesh = frcd_geom::shapes::merge(&[plate(8, 10.0, 8.0, 0.0), plate(8, 10.0, 8.0, 5.0)])
            .expect("two plates");
        let n = mesh.triangle_count();
        let plate_of = |t: u32| (mesh.triangle(t as usize).v[0].z > 2.5) as usize;
        for (split, separates) in [
            (SplitMethod::SurfaceCost, true),
            (SplitMethod::MajorAxisMean, false),
        ] {
            let options = BuildOptions {
                split,
                ..BuildOptions::default()
            };
            let (nodes, order) = build_nodes(&mesh, &options);
            let left = ranges(&nodes, n)[1];
            let plates: Vec<usize> = order[left.0..left.1].iter().map(|&t| plate_of(t)).collect();
            let one_plate = plates.iter().all(|&p| p == plates[0]) && plates.len() == n / 2;
            assert_eq!(
                one_plate, separates,
                "{split:?}: the root's left child holds {plates:?}"
            );
            // The children's boxes: flat (depth 0) when the plates are apart.
            let depth = nodes[1].obb.half_extents.min_element();
            assert_eq!(
                depth < 1e-9,
                separates,
                "{split:?}: left child's box {:?}",
                nodes[1].obb
            );
        }
    }

    /// A long quad split along its diagonal: the vertex covariance counts the diagonal's ends
    /// twice and tilts the box toward it (10 × 1 gives a box 1.3 wide); the leaf's plane frame
    /// gives the quad's own sides.
    #[test]
    fn a_leaf_of_two_triangles_gets_its_quads_sides() {
        let pose = Pose::new(
            DVec3::new(3.0, -2.0, 7.5),
            frcd_geom::DQuat::from_axis_angle(DVec3::new(0.3, -0.8, 0.5).normalize(), 0.7),
        );
        let corner = |x: f64, y: f64| pose.transform_point(DVec3::new(x, y, 0.0));
        let (a, b, c, d) = (
            corner(0.0, 0.0),
            corner(10.0, 0.0),
            corner(10.0, 1.0),
            corner(0.0, 1.0),
        );
        let mesh = TriMesh::new(vec![a, b, c, d], vec![[0, 1, 2], [0, 2, 3]]).unwrap();
        let (nodes, _) = build_nodes(&mesh, &BuildOptions::default());
        assert_eq!(nodes.len(), 1, "two triangles make one leaf at leaf size 2");
        let mut h = nodes[0].obb.half_extents.to_array();
        h.sort_by(f64::total_cmp);
        assert!(
            h[0] < 1e-9 && (h[1] - 0.5).abs() < 1e-9 && (h[2] - 5.0).abs() < 1e-9,
            "{h:?}"
        );
        // What the covariance's axes would give (the test's reason to exist).
        let items: Vec<Item> = mesh
            .triangles()
            .map(|t| Item {
                v: t.v,
                mag: magnitude(&t),
                id: 0,
            })
            .collect();
        let moments = Moments::of(&items, DVec3::ZERO);
        let (axes, _) = moments.fit(&items, FitMethod::VertexCovariance);
        let tilted = Obb::from_point_iter_with_axes(mesh.vertices().iter().copied(), axes.unwrap());
        let mut t = tilted.half_extents.to_array();
        t.sort_by(f64::total_cmp);
        assert!(t[1] > 0.6, "covariance box {t:?}");
    }

    /// The larger side's moments by difference equal the summed ones (to a few digits of the
    /// node's spread), and where the difference would cancel (a tight cluster beside far
    /// triangles) they are summed instead.
    #[test]
    fn side_moments_by_difference_equal_the_sums() {
        let mut rng = Rng(0x51de);
        let tri = |rng: &mut Rng, centre: DVec3, size: f64| {
            let v = [0; 3].map(|_| centre + (rng.point() - 0.5) * size);
            Item {
                v,
                mag: magnitude(&Triangle { v }),
                id: 0,
            }
        };
        let spread: Vec<Item> = (0..40)
            .map(|_| {
                let centre = DVec3::new(1e4, -3e3, 2.0) + rng.point() * 5.0;
                tri(&mut rng, centre, 1.0)
            })
            .collect();
        let mut cluster: Vec<Item> = (0..30)
            .map(|_| tri(&mut rng, DVec3::new(1.0, 2.0, 3.0), 1e-7))
            .collect();
        // Two far triangles mirrored through the cluster's centre: the node's mean is the
        // cluster's, whose second moment about it (about 10⁻¹²) is far below the rounding of
        // the node's (about 10⁷ × 2⁻⁵²).
        let far = tri(&mut rng, DVec3::new(1e3, 10.0, -4.0), 1.0);
        let mirror = |p: DVec3| 2.0 * DVec3::new(1.0, 2.0, 3.0) - p;
        cluster.push(far);
        cluster.push(Item {
            v: far.v.map(mirror),
            ..far
        });
        for items in [spread, cluster] {
            let r = items[0].v[0];
            let all = Moments::of(&items, r);
            let mean = all.mean(items.len());
            let (_, second) = all.fit(&items, FitMethod::VertexCovariance);
            for mid in [1, 2, items.len() / 3, items.len() / 2, items.len() - 2] {
                let (l, rr) = items.split_at(mid);
                let by_difference = side_moments(l, rr, mean, second.as_ref());
                let summed = [Moments::of(l, mean), Moments::of(rr, mean)];
                for (d, s) in by_difference.iter().zip(&summed) {
                    let scale = s.second[0] + s.second[3] + s.second[5];
                    for k in 0..6 {
                        let err = (d.second[k] - s.second[k]).abs();
                        assert!(
                            err <= 1e-6 * scale,
                            "mid {mid}: {:?} against {:?}",
                            d.second,
                            s.second
                        );
                    }
                    assert!(
                        (d.first - s.first).length()
                            <= 1e-6 * scale.sqrt() * 3.0 * items.len() as f64
                    );
                }
            }
        }
    }

    /// `bin_of` converts without a range check: every input, NaN and infinities included,
    /// must land in `0..bins`.
    #[test]
    fn bin_of_keeps_every_input_in_range() {
        let values = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN,
            -0.0,
            0.0,
            1e-40,
            0.49,
            7.99,
            15.0,
            16.0,
            3e9,
        ];
        for bins in 2..=BINS {
            for &sum in &values {
                for &min in &[0.0f32, -1.0, f32::MIN, f32::NAN] {
                    for &scale in &[1.0f32, 0.5, 1e30, f32::INFINITY, f32::NAN] {
                        let b = bin_of(sum, min, scale, bins);
                        assert!(b < bins, "bin_of({sum}, {min}, {scale}, {bins}) = {b}");
                    }
                }
            }
        }
    }

    /// Nodes of up to `EXHAUSTIVE_MAX` triangles take the cheapest of all their partitions:
    /// never costlier than any other partition, the binned cut's included, and none at all
    /// (the caller's fallback) when no cost is finite.
    /// The AVX2 build of the first pass gives the baseline's bits: bounds, magnitude and every
    /// probe, over ordinary, huge (overflowing to infinities and NaN), subnormal and signed-zero
    /// coordinates and random axes.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn both_projections_give_the_same_bits() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("SKIP: no AVX2 on this CPU");
            return;
        }
        let same = |t: &DMat3, m: DVec3, items: &[Item], what: &str| -> Vec<Probe> {
            let mut p0 = vec![Probe::default(); items.len()];
            let mut p1 = vec![Probe::default(); items.len()];
            let r0 = project_body(t, *t * m, items, &mut p0);
            // SAFETY: the CPU has AVX2 (checked above).
            #[allow(unsafe_code)]
            let r1 = unsafe { project_avx2(t, *t * m, items, &mut p1) };
            let bits = |v: DVec3| v.to_array().map(f64::to_bits);
            assert_eq!(bits(r0.0), bits(r1.0), "{what}: lo");
            assert_eq!(bits(r0.1), bits(r1.1), "{what}: hi");
            assert_eq!(r0.2.to_bits(), r1.2.to_bits(), "{what}: magnitude");
            let f = |p: &Probe| {
                let mut out = p.bounds.map(f32::to_bits).to_vec();
                out.extend(p.sum.map(f32::to_bits));
                out
            };
            for (a, b) in p0.iter().zip(&p1) {
                assert_eq!(f(a), f(b), "{what}: probe");
            }
            p0
        };
        let item = |v: [DVec3; 3]| Item {
            v,
            mag: magnitude(&Triangle { v }),
            id: 0,
        };
        // Signed zeros, in every order of the vertices and of two triangles: with the identity
        // axes and a zero mean, `(−0, −1, −1)` projects to −0 on x and `(0, 1, 1)` to +0, and
        // the probes keep the sign, so an operand order that differs from the baseline's shows.
        let zeros = [
            DVec3::new(-0.0, -1.0, -1.0),
            DVec3::new(0.0, 1.0, 1.0),
            DVec3::new(2.0, 1.0, 1.0),
        ];
        let mut negative_zeros = 0;
        for code in 0..27 * 27 {
            let tri = |c: usize| item([zeros[c % 3], zeros[c / 3 % 3], zeros[c / 9]]);
            let items = [tri(code % 27), tri(code / 27)];
            let probes = same(&DMat3::IDENTITY, DVec3::ZERO, &items, "signed zeros");
            negative_zeros += probes
                .iter()
                .filter(|p| p.bounds[0].to_bits() == (-0.0f32).to_bits())
                .count();
        }
        assert!(negative_zeros > 0, "the cases hold no −0 bound");
        // Infinite projections (a sum of products past the largest f64) and NaN centroid
        // sums (+inf and −inf vertices in one triangle), under a rotation with no zero entry,
        // for every sign pattern of the coordinates.
        let axes = DMat3::from_quat(frcd_geom::DQuat::from_axis_angle(
            DVec3::new(1.0, 2.0, 3.0).normalize(),
            0.7,
        ));
        let big = 1.5e308;
        let mut nans = 0;
        for code in 0..8 {
            let s = |bit: usize| if code >> bit & 1 == 0 { big } else { -big };
            let v = DVec3::new(s(0), s(1), s(2));
            let items = [item([v, -v, DVec3::ONE]), item([DVec3::ZERO, v, DVec3::X])];
            let probes = same(&axes.transpose(), DVec3::ZERO, &items, "overflow");
            nans += probes
                .iter()
                .filter(|p| p.sum[..3].iter().any(|x| x.is_nan()))
                .count();
        }
        assert!(nans > 0, "the cases hold no NaN sum");
        let mut rng = Rng(0xa2);
        // Signed zeros (with the identity axes a vertex `(−0, −1, −1)` projects to −0 and
        // `(0, 1, 1)` to +0, so the order of a minimum's operands shows), values whose sums
        // overflow to ±infinity and then NaN, subnormals.
        let specials = [0.0, -0.0, 1.5e308, -1.5e308, 4e-320, -4e-320, 1.0, -1.0];
        for round in 0..200 {
            let q = frcd_geom::DQuat::from_axis_angle(
                DVec3::new(rng.next() - 0.5, rng.next() - 0.5, rng.next() + 0.1).normalize(),
                rng.next() * 7.0,
            );
            let axes = if round % 10 == 0 {
                DMat3::IDENTITY
            } else {
                DMat3::from_quat(q)
            };
            let t = axes.transpose();
            let m = DVec3::new(rng.next() - 0.5, rng.next(), -rng.next()) * 10.0;
            let mut coord = |k: usize| {
                if round % 10 == 0 || (round + k).is_multiple_of(3) {
                    specials[(rng.next() * 8.0) as usize % 8]
                } else {
                    (rng.next() - 0.5) * 20.0
                }
            };
            let items: Vec<Item> = (0..1 + round % 37)
                .map(|i| {
                    let v = [0, 1, 2]
                        .map(|j| DVec3::new(coord(i + j), coord(i + j + 1), coord(i + 2 * j)));
                    let t = Triangle { v };
                    Item {
                        v,
                        mag: magnitude(&t),
                        id: i as u32,
                    }
                })
                .collect();
            same(&t, m, &items, &format!("round {round}"));
        }
    }

    /// The AVX2 build of the binning fills the bins with the baseline's bits and counts, over
    /// probes with signed zeros and every node size up to beyond the bin count.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn both_binnings_give_the_same_bits() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("SKIP: no AVX2 on this CPU");
            return;
        }
        let mut rng = Rng(0xb1);
        let value = |rng: &mut Rng| match (rng.next() * 8.0) as u32 {
            0 => 0.0f32,
            1 => -0.0,
            _ => (rng.next() * 4.0 - 2.0) as f32,
        };
        for n in 1..40 {
            let probes: Vec<Probe> = (0..n)
                .map(|_| Probe {
                    bounds: [0; 8].map(|_| value(&mut rng)),
                    sum: [0; 4].map(|_| value(&mut rng)),
                })
                .collect();
            let nb = n.clamp(2, BINS);
            let min = [-2.0f32; 3];
            let scale = [nb as f32 / 4.0; 3];
            // Stale contents, as a build leaves them.
            let mut plain = [[Bin::EMPTY; BINS]; 3];
            for axis in plain.iter_mut() {
                for bin in axis.iter_mut() {
                    bin.bounds = [0; 8].map(|_| value(&mut rng));
                    bin.count = 7;
                }
            }
            let mut wide = plain;
            fill_bins_plain(&probes, min, scale, nb, &mut plain);
            // SAFETY: the CPU has AVX2 (checked above).
            #[allow(unsafe_code)]
            unsafe {
                fill_bins_avx2(&probes, min, scale, nb, &mut wide)
            };
            for k in 0..3 {
                for b in 0..nb {
                    let (x, y) = (&plain[k][b], &wide[k][b]);
                    assert_eq!(x.count, y.count, "n {n} axis {k} bin {b}");
                    assert_eq!(
                        x.bounds.map(f32::to_bits),
                        y.bounds.map(f32::to_bits),
                        "n {n} axis {k} bin {b}"
                    );
                }
            }
        }
    }

    /// The AVX2 build of the moment sums gives the baseline's bits.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn both_moment_sums_give_the_same_bits() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("SKIP: no AVX2 on this CPU");
            return;
        }
        let mut rng = Rng(0xc3);
        for n in 0..50 {
            let items: Vec<Item> = (0..n)
                .map(|i| Item {
                    v: [0; 3].map(|_| rng.point() * 1e3 - DVec3::splat(500.0)),
                    mag: 0.0,
                    id: i,
                })
                .collect();
            let r = rng.point() * 500.0;
            let plain = Moments::of_plain(&items, r);
            // SAFETY: the CPU has AVX2 (checked above).
            #[allow(unsafe_code)]
            let wide = unsafe { Moments::of_avx2(&items, r) };
            assert_eq!(
                plain.first.to_array().map(f64::to_bits),
                wide.first.to_array().map(f64::to_bits),
                "n {n}"
            );
            assert_eq!(
                plain.second.map(f64::to_bits),
                wide.second.map(f64::to_bits),
                "n {n}"
            );
        }
    }

    #[test]
    fn small_nodes_take_the_cheapest_of_all_partitions() {
        let mut rng = Rng(0x5a11);
        let mut bins = [[Bin::EMPTY; BINS]; 3];
        let cost = |probes: &[Probe], mask: u32| {
            let mut acc = Bin::EMPTY;
            for (i, p) in probes.iter().enumerate() {
                if mask >> i & 1 != 0 {
                    acc.merge(&p.bounds, 1);
                }
            }
            let e = [0, 1, 2].map(|k| (-(acc.bounds[k + 4] + acc.bounds[k])) as f64);
            let mean = (e[0] + e[1] + e[2]) / 3.0;
            (e[0] * e[1] + e[1] * e[2] + e[2] * e[0] + mean * mean) * acc.count as f64
        };
        for n in 2..=EXHAUSTIVE_MAX {
            let full = (1u32 << n) - 1;
            let both = |probes: &[Probe], m: u32| cost(probes, m) + cost(probes, full & !m);
            for _ in 0..300 {
                let probes: Vec<Probe> = (0..n)
                    .map(|_| {
                        let (a, b) = (rng.point() * 4.0 - 2.0, rng.point() * 0.5);
                        let (lo, hi) = (a.as_vec3(), (a + b).as_vec3());
                        let sum = (3.0 * (a + 0.5 * b)).as_vec3();
                        Probe {
                            bounds: [lo.x, lo.y, lo.z, 0.0, -hi.x, -hi.y, -hi.z, 0.0],
                            sum: [sum.x, sum.y, sum.z, 0.0],
                        }
                    })
                    .collect();
                let mask = cheapest_partition(&probes);
                assert!(mask != 0 && mask != full, "n {n}: mask {mask:b}");
                let best = both(&probes, mask);
                for other in 1..full {
                    assert!(
                        best <= both(&probes, other) * (1.0 + 1e-5),
                        "n {n}: {mask:b} against {other:b}"
                    );
                }
                let smin = [0, 1, 2].map(|k| {
                    probes
                        .iter()
                        .map(|p| p.sum[k])
                        .fold(f32::INFINITY, f32::min)
                });
                let smax = [0, 1, 2].map(|k| {
                    probes
                        .iter()
                        .map(|p| p.sum[k])
                        .fold(f32::NEG_INFINITY, f32::max)
                });
                if let Some(c) = cheapest_cut(&probes, smin, smax, &mut bins) {
                    let binned = probes.iter().enumerate().fold(0u32, |m, (i, p)| {
                        let right = bin_of(p.sum[c.axis], c.min, c.scale, c.bins) > c.last_left;
                        m | (right as u32) << i
                    });
                    if binned != 0 && binned != full {
                        assert!(best <= both(&probes, binned) * (1.0 + 1e-5));
                    }
                }
            }
        }
        let bad = vec![
            Probe {
                bounds: [f32::NAN; 8],
                sum: [0.0; 4],
            };
            3
        ];
        assert_eq!(cheapest_partition(&bad), 0);
    }
}
