//! CPU side of the texture mapping: an f64 OBB tree becomes f32 texels, rounded so that the f32
//! boxes contain the f64 ones.
//!
//! Layout (2D arrays, nodes `rgba32uint`, triangles `rgba32float`, item `i` at slot `i` in
//! row-major order over (layer, row, item-in-row), see [`TexLayout::slot`]):
//!
//! | item | texels |
//! |---|---|
//! | node | `(c, link) (a0, h0 \| leaf) (a1, h1) (a2, h2)`: f32 bits, 64 bytes (one cache line) |
//! | triangle (leaf order) | `(o0, mesh index) (o1, k word 1) (o2, k word 2)` |
//!
//! Nodes are in breadth-first order with siblings side by side ([`sibling_order`]): an internal
//! node's `link` is its first child (the second is the next slot), a leaf's
//! `first | (count - 1) << 24`; bit 31 of `h0`'s word (a sign bit, `h0 >= 0`) marks a leaf
//! ([`node_texels_of`]). The axes' deviation from orthonormal is one bound per mesh
//! ([`PackedTree::eps`], the largest of its nodes'), which the pair's pose carries to the shader.
//! Triangle indices are stored as f32, exact below 2^24, so trees are limited to 2^24 nodes and
//! triangles ([`MAX_ITEMS`]).
//!
//! **Triangles about a grid point.** Each mesh gets a power-of-two grid `g = 2^e`
//! ([`grid_exponent`]: `e = ceil(log2 S) - GRID_BITS`, `S` the largest vertex coordinate), and
//! each triangle a reference point `c = k g` (its centroid snapped to the grid, `|k_i| <=
//! 2^GRID_BITS`); the texels hold the offsets `o = v - c` (f64, rounded to nearest f32) and `k`
//! packed into two f32-exact integers ([`pack_k`]). The triangle pass then computes
//! `R c_B + t - c_A` exactly in integer arithmetic ([`ExactPose`]) and rotates only the small
//! offsets in f32 (issue 10: far fewer uncertain pairs). A mesh too small for the grid's range
//! (`e < GRID_MIN_EXP`) or with every vertex at the origin keeps `k = 0` (offsets are the
//! vertices) and its pairs take the rotated path.
//!
//! **Box rounding.** A node's f64 box is the parallelepiped `{c + A s : |s_i| <= h_i}`. Its f32
//! image keeps `c32 = fl(c)`, `A32 = fl(A)` (rounded to nearest) and inflates the half extents by
//! `eta = (u ‖c‖₂ + √3 u ‖h‖₂) / σ_min(A32)` (`u = 2^-24`), rounded up: any point `c + A s` equals
//! `c32 + A32 (s + Δs)` with `‖Δs‖∞ <= ‖A32⁻¹‖ ‖(c - c32) + (A - A32) s‖₂ <= eta`, so the f32 box
//! holds the f64 box. The GPU's separating-axis test (Gottschalk's form, which assumes orthonormal
//! axes) widens its error bound by the mesh's largest [`ObbF32::axes_deviation`] (the bound only
//! grows with it, so one bound per mesh is as safe as one per node), so `A32`'s residual
//! non-orthogonality never culls a pair; it also bounds its own arithmetic.

use crate::GpuError;
use frcd_geom::{DMat3, DVec3, Obb};
use frcd_obb::ObbTree;

/// Texels per node (64 bytes).
pub const NODE_TEXELS: u32 = 4;
/// Bit 31 of a node's texel 1 `w` word: the node is a leaf.
pub const LEAF_FLAG: u32 = 0x8000_0000;
/// Texels per triangle.
pub const TRI_TEXELS: u32 = 3;
/// Indices are stored as f32 and must stay exact: at most this many nodes or triangles.
pub const MAX_ITEMS: u64 = 1 << 24;
/// Unit roundoff of f32 round-to-nearest, 2^-24.
pub const U32: f64 = 1.0 / 16_777_216.0;
/// Largest magnitude of any coordinate, half extent or relative translation the GPU accepts
/// (2^36 ≈ 6.9e10): the error bounds of `traverse.wgsl` evaluate cubes of coordinate
/// differences in f32, which must stay finite (WGSL may assume finite math).
pub const MAX_MAGNITUDE: f64 = 68_719_476_736.0;
/// Fewest texture array layers a packed texture gets (see [`TexLayout::new`]).
pub const MIN_LAYERS: u32 = 2;
/// Grid coordinates of triangle reference points are at most `2^GRID_BITS` in magnitude.
pub const GRID_BITS: i32 = 13;
/// Smallest grid exponent a mesh gets (smaller meshes store their vertices, `k = 0`): the
/// triangle pass's fine grid `2^(e_B - R_FRAC_BITS)` must stay a normal f32 (>= 2^-96 here).
pub const GRID_MIN_EXP: i32 = -50;
/// Fractional bits of the fixed-point rotation of the exact path (`|M / 2^46 - R| <= 2^-47`).
pub const R_FRAC_BITS: i32 = 46;
/// Bias of a packed grid coordinate (16 bits each).
const K_BIAS: i64 = 1 << 15;

/// Where the items of one kind live in a 2D array texture.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TexLayout {
    /// Texels per item.
    pub texels_per_item: u32,
    /// Items per texture row.
    pub items_per_row: u32,
    /// Rows per array layer (the texture's height).
    pub rows_per_layer: u32,
    /// Array layers.
    pub layers: u32,
}

impl TexLayout {
    /// The layout of `items` items (at least one slot) of `texels_per_item` texels, in textures
    /// at most `max_width` texels wide and `max_rows` tall with at most `max_layers` layers:
    /// a single row when it fits, else full rows, else full layers.
    pub fn new(
        items: usize,
        texels_per_item: u32,
        max_width: u32,
        max_rows: u32,
        max_layers: u32,
    ) -> Result<Self, GpuError> {
        let items = items.max(1) as u64;
        let per_row_max = (max_width / texels_per_item) as u64;
        if per_row_max == 0 || max_rows == 0 || max_layers == 0 {
            return Err(GpuError::MeshTooLarge {
                what: "texture width in texels (one item per row)",
                needed: texels_per_item as u64,
                limit: max_width as u64,
            });
        }
        if max_layers < MIN_LAYERS {
            return Err(GpuError::MeshTooLarge {
                what: "texture array layers (at least 2 are needed)",
                needed: MIN_LAYERS as u64,
                limit: max_layers as u64,
            });
        }
        let rows_total = items.div_ceil(per_row_max);
        // Always at least two layers: wgpu's GL backend makes a one-layer texture a
        // `TEXTURE_2D`, which a `texture_2d_array` binding then reads as zeros (every box
        // empty: pairs silently lost). Two layers make it a `TEXTURE_2D_ARRAY` everywhere.
        let (items_per_row, rows, layers) = if rows_total == 1 {
            (items.div_ceil(2), 1, 2)
        } else if rows_total <= 2 * max_rows as u64 {
            (per_row_max, rows_total.div_ceil(2), 2)
        } else {
            let layers = rows_total.div_ceil(max_rows as u64);
            if layers > max_layers as u64 {
                return Err(GpuError::MeshTooLarge {
                    what: "texture array layers",
                    needed: layers,
                    limit: max_layers as u64,
                });
            }
            (per_row_max, max_rows as u64, layers)
        };
        // A square texture with a multiple of 6 layers becomes a cube map on GL: add a layer.
        let width = items_per_row * texels_per_item as u64;
        let layers = if width == rows && layers % 6 == 0 {
            if layers + 1 > max_layers as u64 {
                return Err(GpuError::MeshTooLarge {
                    what: "texture array layers",
                    needed: layers + 1,
                    limit: max_layers as u64,
                });
            }
            layers + 1
        } else {
            layers
        };
        Ok(Self {
            texels_per_item,
            items_per_row: items_per_row as u32,
            rows_per_layer: rows as u32,
            layers: layers as u32,
        })
    }

    /// Texture width in texels.
    pub fn width(&self) -> u32 {
        self.items_per_row * self.texels_per_item
    }

    /// Texels in the whole texture (all layers).
    pub fn texel_count(&self) -> usize {
        self.width() as usize * self.rows_per_layer as usize * self.layers as usize
    }

    /// `(column, row, layer)` of texel `k` of item `i` (the shaders' `load`).
    pub fn slot(&self, i: u32, k: u32) -> (u32, u32, u32) {
        let row_g = i / self.items_per_row;
        let col = (i % self.items_per_row) * self.texels_per_item + k;
        (
            col,
            row_g % self.rows_per_layer,
            row_g / self.rows_per_layer,
        )
    }

    /// Index of texel `k` of item `i` in a layer-major, row-major texel array.
    pub fn linear(&self, i: u32, k: u32) -> usize {
        let (x, y, l) = self.slot(i, k);
        (l as usize * self.rows_per_layer as usize + y as usize) * self.width() as usize
            + x as usize
    }

    /// `[items_per_row, rows_per_layer, a, b]` as the shaders' `vec4<u32>`.
    pub fn uniform(&self, a: u32, b: u32) -> [u32; 4] {
        [self.items_per_row, self.rows_per_layer, a, b]
    }
}

/// The largest texture the packing may use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TexLimits {
    /// Texels per row.
    pub max_width: u32,
    /// Rows per layer.
    pub max_rows: u32,
    /// Array layers.
    pub max_layers: u32,
}

/// A tree packed into texel arrays, ready to upload.
#[derive(Clone, Debug)]
pub struct PackedTree {
    /// Node texels as words (layout [`PackedTree::node_layout`]; see [`node_texels_of`]).
    pub nodes: Vec<[u32; 4]>,
    /// The largest of the nodes' [`ObbF32::axes_deviation`]: the mesh's bound on its f32 axes'
    /// distance to an orthonormal frame.
    pub eps: f32,
    /// Placement of nodes.
    pub node_layout: TexLayout,
    /// Triangle texels in leaf order (layout [`PackedTree::tri_layout`]).
    pub tris: Vec<[f32; 4]>,
    /// Placement of triangles.
    pub tri_layout: TexLayout,
    /// Depth of the tree (a single leaf: 1): the traversal records this many levels.
    pub depth: u32,
    /// Exponent of the mesh's reference-point grid (`None`: every `k = 0`, see the module docs).
    pub grid: Option<i32>,
}

/// `x` rounded to the nearest f32 at or above it (f32::MAX for values above it, +inf stays).
pub fn round_up(x: f64) -> f32 {
    let f = x as f32;
    if (f as f64) < x { f.next_up() } else { f }
}

/// `x` rounded to the nearest f32 at or below it.
pub fn round_down(x: f64) -> f32 {
    let f = x as f32;
    if (f as f64) > x { f.next_down() } else { f }
}

/// `x` rounded to an f32 at or above it that flush-to-zero cannot move: [`round_up`], with a
/// subnormal result moved up to the next zero or normal value (a positive one to
/// `f32::MIN_POSITIVE`, a negative one to zero).
///
/// For bounds a shader only compares. WGSL lets an implementation flush subnormal operands to
/// zero even in a comparison (NVIDIA's Vulkan driver does: on an H200 a box rounded up to the
/// subnormal `1.4e-45` compared as `0`, below a neighbour's inner bound, and the pair was
/// reported as surely overlapping). A zero or normal value compares as stored.
///
/// ```
/// use frcd_gpgpu::pack::round_up_normal;
/// assert_eq!(round_up_normal(1e-300), f32::MIN_POSITIVE);
/// assert_eq!(round_up_normal(-1e-300), 0.0);
/// assert_eq!(round_up_normal(0.5), 0.5);
/// ```
pub fn round_up_normal(x: f64) -> f32 {
    let f = round_up(x);
    match f.is_subnormal() {
        true if f > 0.0 => f32::MIN_POSITIVE,
        true => 0.0,
        false => f,
    }
}

/// `x` rounded to an f32 at or below it that flush-to-zero cannot move: [`round_down`], with a
/// subnormal result moved down to the next zero or normal value (a positive one to zero, a
/// negative one to `-f32::MIN_POSITIVE`). See [`round_up_normal`].
///
/// ```
/// use frcd_gpgpu::pack::round_down_normal;
/// assert_eq!(round_down_normal(1e-300), 0.0);
/// assert_eq!(round_down_normal(-1e-300), -f32::MIN_POSITIVE);
/// ```
pub fn round_down_normal(x: f64) -> f32 {
    let f = round_down(x);
    match f.is_subnormal() {
        true if f < 0.0 => -f32::MIN_POSITIVE,
        true => 0.0,
        false => f,
    }
}

/// An OBB in f32 whose parallelepiped `{c + A s : |s_i| <= h_i}` holds the f64 one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObbF32 {
    /// Centre, rounded to nearest.
    pub center: [f32; 3],
    /// Axes (columns), rounded to nearest.
    pub axes: [[f32; 3]; 3],
    /// Half extents, inflated and rounded up.
    pub half_extents: [f32; 3],
}

impl ObbF32 {
    /// An upper bound on `max_i ‖a_i - q_i‖₂` over the columns of the f32 axes `A` and of some
    /// orthonormal `Q` (the polar factor): `‖A - Q‖₂ = ‖P - I‖₂ <= ‖AᵀA - I‖₂ <= 3 max|AᵀA - I|`
    /// (`A = QP`, each eigenvalue `λ` of `AᵀA` has `|√λ - 1| <= |λ - 1|`). The GPU's box test
    /// (Gottschalk's form, which assumes orthonormal axes) inflates its error bound by it. The
    /// Gram entries are computed in f64 from the f32 axes (products exact, sums off by < 1e-15,
    /// covered by the added 1e-15), rounded up.
    pub fn axes_deviation(&self) -> f32 {
        let a = self
            .axes
            .map(|c| DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64));
        let mut dev = 0f64;
        for i in 0..3 {
            for k in 0..3 {
                let g = a[i].dot(a[k]) - if i == k { 1.0 } else { 0.0 };
                dev = dev.max(g.abs());
            }
        }
        round_up(3.0 * (dev + 1e-15))
    }
}

fn v3(v: DVec3) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

fn back(v: [f32; 3]) -> DVec3 {
    DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64)
}

/// Rounds a node box to f32 outward (see the module docs). `node` only names the node in
/// errors: non-finite boxes and axes that are not orthonormal to 1e-3 are refused.
pub fn obb_to_f32(obb: &Obb, node: usize) -> Result<ObbF32, GpuError> {
    let a = obb.axes;
    if !(obb.center.is_finite() && a.is_finite() && obb.half_extents.is_finite())
        || obb.half_extents.min_element() < 0.0
    {
        return Err(GpuError::InvalidInput(format!(
            "OBB node {node} is not finite or has a negative extent"
        )));
    }
    let mag = obb
        .center
        .abs()
        .max_element()
        .max(obb.half_extents.max_element());
    if mag > MAX_MAGNITUDE {
        return Err(GpuError::MagnitudeOutOfRange {
            what: format!("OBB node {node}"),
            value: mag,
            limit: MAX_MAGNITUDE,
        });
    }
    let gram = a.transpose() * a - DMat3::IDENTITY;
    let deviation = [gram.x_axis, gram.y_axis, gram.z_axis]
        .iter()
        .map(|c| c.abs().max_element())
        .fold(0.0, f64::max);
    if deviation > 1e-3 {
        return Err(GpuError::BadNodeAxes { node, deviation });
    }
    // ‖AᵀA - I‖₂ <= 3·deviation bounds σ_min(A)² from below; A32 differs by ‖·‖_F <= √3 u.
    let sigma_min = (1.0 - 3.0 * deviation).sqrt() - 3f64.sqrt() * U32 * 1.001;
    let axes = [v3(a.x_axis), v3(a.y_axis), v3(a.z_axis)];
    let center = v3(obb.center);
    // The residual is taken from the actual rounding, with the u-bound as a floor for safety.
    let dc = (obb.center - back(center)).length();
    let da = (a.x_axis - back(axes[0])).length_squared()
        + (a.y_axis - back(axes[1])).length_squared()
        + (a.z_axis - back(axes[2])).length_squared();
    let residual = dc.max(U32 * obb.center.length())
        + da.sqrt().max(3f64.sqrt() * U32) * obb.half_extents.length();
    // 1e-6 relative margin covers the f64 arithmetic of this bound.
    let eta = residual / sigma_min * (1.0 + 1e-6);
    let h = obb.half_extents;
    Ok(ObbF32 {
        center,
        axes,
        half_extents: [
            round_up(h.x + eta),
            round_up(h.y + eta),
            round_up(h.z + eta),
        ],
    })
}

/// The GPU's node order: breadth first, the two children of a node side by side. Returns the
/// tree's node index at each slot and, per slot, the slot of its first child (0 for a leaf).
/// A node reached twice, or a child index out of range, is an error.
pub fn sibling_order(tree: &ObbTree) -> Result<(Vec<usize>, Vec<u32>), GpuError> {
    sibling_order_of(tree.node_count(), |i| {
        let node = tree.node(i as u32);
        (!node.is_leaf()).then(|| (i + 1, node.right as usize))
    })
}

/// [`sibling_order`] over `n` nodes whose internal ones have the children `children(i)`.
fn sibling_order_of(
    n: usize,
    children: impl Fn(usize) -> Option<(usize, usize)>,
) -> Result<(Vec<usize>, Vec<u32>), GpuError> {
    let mut order = Vec::with_capacity(n);
    let mut first_child = Vec::with_capacity(n);
    let mut seen = vec![false; n];
    let mut visit = |i: usize, order: &mut Vec<usize>| {
        if i >= n || std::mem::replace(&mut seen[i], true) {
            return Err(GpuError::InvalidInput(format!(
                "OBB tree: node {i} is out of range or the child of two nodes"
            )));
        }
        order.push(i);
        Ok(())
    };
    visit(0, &mut order)?;
    let mut k = 0;
    while k < order.len() {
        match children(order[k]) {
            None => first_child.push(0),
            Some((left, right)) => {
                first_child.push(order.len() as u32);
                visit(left, &mut order)?;
                visit(right, &mut order)?;
            }
        }
        k += 1;
    }
    Ok((order, first_child))
}

/// A node's four texels as `traverse.wgsl`'s `load_node` reads them: `(c, link) (a0, h0 | leaf)
/// (a1, h1) (a2, h2)`, f32 bits. `link` is the first child of an internal node (the second is
/// the next slot, see [`sibling_order`]), or a leaf's
/// `first | (count - 1) << 24` (`first < 2^24`, `1 <= count <= 256`, checked by the caller);
/// `leaf` sets bit 31 of `h0`'s word, whose sign bit is free (`h0 >= 0`).
pub fn node_texels_of(b: &ObbF32, link: u32, leaf: bool) -> [[u32; 4]; 4] {
    let bits = |v: [f32; 3], w: u32| [v[0].to_bits(), v[1].to_bits(), v[2].to_bits(), w];
    let h = b.half_extents.map(f32::to_bits);
    [
        bits(b.center, link),
        bits(b.axes[0], h[0] | if leaf { LEAF_FLAG } else { 0 }),
        bits(b.axes[1], h[1]),
        bits(b.axes[2], h[2]),
    ]
}

fn depth_of(tree: &ObbTree) -> u32 {
    let nodes = tree.nodes();
    let mut best = 0;
    let mut stack = vec![(0usize, 1u32)];
    while let Some((i, d)) = stack.pop() {
        best = best.max(d);
        let n = &nodes[i];
        if !n.is_leaf() {
            stack.push((i + 1, d + 1));
            stack.push((n.right as usize, d + 1));
        }
    }
    best
}

/// The structure the shaders trust: a non-empty tree, node and triangle counts whose indices
/// are exact in f32, and one leaf-order entry per triangle.
fn check_tree(tree: &ObbTree) -> Result<(), GpuError> {
    let (nodes, order, n_tris) = (tree.nodes(), tree.leaf_triangles(), tree.triangle_count());
    if nodes.is_empty() || n_tris == 0 {
        return Err(GpuError::InvalidInput("empty tree".into()));
    }
    for (what, n) in [
        ("node count (f32-exact indices)", nodes.len()),
        ("triangle count (f32-exact indices)", n_tris),
    ] {
        if n as u64 >= MAX_ITEMS {
            return Err(GpuError::MeshTooLarge {
                what,
                needed: n as u64,
                limit: MAX_ITEMS - 1,
            });
        }
    }
    if order.len() != n_tris {
        return Err(GpuError::InvalidInput(format!(
            "leaf order has {} entries for {} triangles",
            order.len(),
            n_tris
        )));
    }
    Ok(())
}

/// Checks the tree's structure (the shaders trust it) and packs it.
pub fn pack_tree(tree: &ObbTree, limits: &TexLimits) -> Result<PackedTree, GpuError> {
    let nodes = tree.nodes();
    let n_tris = tree.triangle_count();
    check_tree(tree)?;
    let node_layout = TexLayout::new(
        nodes.len(),
        NODE_TEXELS,
        limits.max_width,
        limits.max_rows,
        limits.max_layers,
    )?;
    let tri_layout = TexLayout::new(
        n_tris,
        TRI_TEXELS,
        limits.max_width,
        limits.max_rows,
        limits.max_layers,
    )?;
    pack_into(tree, node_layout, tri_layout)
}

/// Packs a tree into whole rows of `node_items_per_row` nodes and `tri_items_per_row`
/// triangles (one "layer" of as many rows as needed): the rows a mesh takes in the arena.
pub fn pack_tree_rows(
    tree: &ObbTree,
    node_items_per_row: u32,
    tri_items_per_row: u32,
) -> Result<PackedTree, GpuError> {
    let rows = |n: usize, per: u32, tpi: u32| TexLayout {
        texels_per_item: tpi,
        items_per_row: per.max(1),
        rows_per_layer: (n.max(1) as u64).div_ceil(per.max(1) as u64) as u32,
        layers: 1,
    };
    let node_layout = rows(tree.nodes().len(), node_items_per_row, NODE_TEXELS);
    let tri_layout = rows(tree.triangle_count(), tri_items_per_row, TRI_TEXELS);
    pack_into(tree, node_layout, tri_layout)
}

fn pack_into(
    tree: &ObbTree,
    node_layout: TexLayout,
    tri_layout: TexLayout,
) -> Result<PackedTree, GpuError> {
    let nodes = tree.nodes();
    let order = tree.leaf_triangles();
    check_tree(tree)?;
    let mut node_texels = vec![[0u32; 4]; node_layout.texel_count()];
    let mut eps = 0f32;
    for (i, n) in nodes.iter().enumerate() {
        let ok = if n.is_leaf() {
            n.count >= 1
                && n.count <= crate::MAX_LEAF_TRIANGLES
                && n.first as usize + n.count as usize <= order.len()
        } else {
            (n.right as usize) > i + 1 && (n.right as usize) < nodes.len()
        };
        if !ok {
            return Err(GpuError::InvalidInput(format!(
                "OBB node {i}: child or triangle range out of bounds"
            )));
        }
    }
    // Siblings side by side (breadth first): a node's children are `link` and `link + 1`, so a
    // traversal entry names both children of each node with one index.
    let (bfs, first_child) = sibling_order(tree)?;
    for (slot, &i) in bfs.iter().enumerate() {
        let n = &nodes[i];
        let b = obb_to_f32(&n.obb, i)?;
        eps = eps.max(b.axes_deviation());
        let link = if n.is_leaf() {
            n.first | (n.count - 1) << 24
        } else {
            first_child[slot]
        };
        for (k, texel) in node_texels_of(&b, link, n.is_leaf())
            .into_iter()
            .enumerate()
        {
            node_texels[node_layout.linear(slot as u32, k as u32)] = texel;
        }
    }
    let grid = grid_exponent(tree)?;
    let mut tri_texels = vec![[0f32; 4]; tri_layout.texel_count()];
    for (slot, &index) in order.iter().enumerate() {
        let tri = ((index as usize) < tree.triangle_count())
            .then(|| tree.triangle(index))
            .ok_or_else(|| {
                GpuError::InvalidInput(format!("leaf order names triangle {index}, out of range"))
            })?;
        let k = match grid {
            Some(e) => grid_point(&tri.v, e),
            None => [0; 3],
        };
        let c = grid_coords(k, grid.unwrap_or(0));
        let (w1, w2) = pack_k(k);
        for j in 0..3 {
            let o = v3(tri.v[j] - c);
            let w = [index as f32, w1, w2][j];
            tri_texels[tri_layout.linear(slot as u32, j as u32)] = [o[0], o[1], o[2], w];
        }
    }
    Ok(PackedTree {
        nodes: node_texels,
        eps,
        node_layout,
        tris: tri_texels,
        tri_layout,
        depth: depth_of(tree),
        grid,
    })
}

/// The largest vertex coordinate magnitude of the tree's triangles, after checking every
/// vertex is finite and within [`MAX_MAGNITUDE`].
fn vertex_magnitude(tree: &ObbTree) -> Result<f64, GpuError> {
    let mut mag = 0f64;
    for index in 0..tree.triangle_count() as u32 {
        let tri = tree.triangle(index);
        if !tri.is_finite() {
            return Err(GpuError::InvalidInput(format!(
                "triangle {index} has a non-finite coordinate"
            )));
        }
        let m = tri
            .v
            .iter()
            .map(|p| p.abs().max_element())
            .fold(0.0, f64::max);
        if m > MAX_MAGNITUDE {
            return Err(GpuError::MagnitudeOutOfRange {
                what: format!("triangle {index}"),
                value: m,
                limit: MAX_MAGNITUDE,
            });
        }
        mag = mag.max(m);
    }
    Ok(mag)
}

/// The exponent `e` of a tree's reference-point grid: the smallest `m` with `2^m >= S` (`S` the
/// largest vertex coordinate magnitude) minus [`GRID_BITS`], so every centroid snaps to
/// `|k_i| <= 2^GRID_BITS`. `None` when `e < GRID_MIN_EXP` or every vertex is at the origin.
/// Refuses non-finite vertices and magnitudes above [`MAX_MAGNITUDE`].
pub fn grid_exponent(tree: &ObbTree) -> Result<Option<i32>, GpuError> {
    Ok(grid_exponent_for(vertex_magnitude(tree)?))
}

/// [`grid_exponent`] of a mesh whose largest vertex coordinate magnitude is `s` (finite, at
/// most [`MAX_MAGNITUDE`]).
pub fn grid_exponent_for(s: f64) -> Option<i32> {
    if !(s > 0.0 && s <= MAX_MAGNITUDE) {
        return None;
    }
    // s <= 2^36: m in [-1074, 36]; powi of 2 is exact there.
    let mut m = s.log2().ceil() as i32;
    while 2f64.powi(m) < s {
        m += 1;
    }
    while m > -1074 && 2f64.powi(m - 1) >= s {
        m -= 1;
    }
    let e = m - GRID_BITS;
    (e >= GRID_MIN_EXP).then_some(e)
}

/// The grid point `k` (units of `2^e`) nearest the triangle's centroid, clamped to
/// `|k_i| <= 2^GRID_BITS` (any integer point is valid; near the centroid keeps offsets small).
pub fn grid_point(v: &[DVec3; 3], e: i32) -> [i64; 3] {
    let c = (v[0] + v[1] + v[2]) / 3.0;
    let lim = (1i64 << GRID_BITS) as f64;
    let inv = 2f64.powi(-e);
    [c.x, c.y, c.z].map(|x| (x * inv).round().clamp(-lim, lim) as i64)
}

/// `k 2^e` (exact in f64: `|k| <= 2^15`).
pub fn grid_coords(k: [i64; 3], e: i32) -> DVec3 {
    let g = 2f64.powi(e);
    DVec3::new(k[0] as f64 * g, k[1] as f64 * g, k[2] as f64 * g)
}

/// Packs `k` (`|k_i| < 2^15`) into two f32-exact integers below 2^24 (texels 1 and 2's `w`):
/// biased by 2^15 to 16 bits each, `x | (y & 0xff) << 16` and `y >> 8 | z << 8`.
pub fn pack_k(k: [i64; 3]) -> (f32, f32) {
    let b = k.map(|x| (x + K_BIAS).clamp(0, 0xffff) as u32);
    let w1 = b[0] | (b[1] & 0xff) << 16;
    let w2 = b[1] >> 8 | b[2] << 8;
    (w1 as f32, w2 as f32)
}

/// Inverse of [`pack_k`] (the shader's `unpack_k`).
pub fn unpack_k(w1: f32, w2: f32) -> [i64; 3] {
    let (w1, w2) = (w1 as u32, w2 as u32);
    let x = (w1 & 0xffff) as i64;
    let y = ((w1 >> 16) | (w2 & 0xff) << 8) as i64;
    let z = (w2 >> 8) as i64;
    [x - K_BIAS, y - K_BIAS, z - K_BIAS]
}

/// The relative pose of a body pair for the triangle pass's exact path: `R` in fixed point
/// (`M = round(R 2^46)`, so `|M / 2^46 - R| <= 2^-47` per entry) and `t` on a fine grid `f`
/// (`T = round(t / f)`, `|T f - t| <= f / 2`), with both meshes' grid exponents. Two modes:
///
/// - **1** (A's grid within `2^-46 .. 2^16` of B's): `f = 2^(e_B - 46)` and
///   `W = R c_B + t - c_A` is, in units of `f`, the integer `M k_B + T - k_A 2^(e_A - e_B + 46)`.
/// - **2** (B's grid more than 2^16 below A's, or B without a grid): B's vertices are rebuilt in
///   f32 (`o_B + c_B`, B being small next to A) and only `W = t - c_A` is exact: `f = 2^(e_A -
///   46)`, `W / f = T - k_A 2^46`.
///
/// The shader computes `W / f` exactly in integer limbs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ExactPose {
    /// 1 or 2 (see above).
    pub mode: i32,
    /// `M[i][j] = round(R_ij 2^46)`.
    pub m: [[i64; 3]; 3],
    /// `T = round(t / f)`, `|T| < 2^78`.
    pub t: [i128; 3],
    /// Grid exponent of A.
    pub ea: i32,
    /// Grid exponent of B (0 without a grid: its `k` are 0).
    pub eb: i32,
}

impl ExactPose {
    /// Shift of A's grid coordinates against the fine grid: `e_A - e_B + 46` (mode 1) or 46.
    pub fn shift_a(&self) -> i32 {
        match self.mode {
            1 => self.ea - self.eb + R_FRAC_BITS,
            _ => R_FRAC_BITS,
        }
    }

    /// Exponent of the fine grid: `e_B - 46` (mode 1) or `e_A - 46`.
    pub fn fine_exponent(&self) -> i32 {
        match self.mode {
            1 => self.eb - R_FRAC_BITS,
            _ => self.ea - R_FRAC_BITS,
        }
    }

    /// The exact path's pose, or `None` where its integer ranges cannot hold (A without a
    /// grid, A's grid more than 2^46 below B's, or `|T| >= 2^78`): that pair then takes the
    /// rotated path.
    pub fn new(m: &DMat3, t: DVec3, ea: Option<i32>, eb: Option<i32>) -> Option<Self> {
        let ea = ea?;
        let (mode, eb) = match eb {
            Some(eb) if (-R_FRAC_BITS..=16).contains(&(ea - eb)) => (1, eb),
            Some(eb) if ea - eb > 16 => (2, eb),
            Some(_) => return None,
            None => (2, 0),
        };
        let scale = 2f64.powi(R_FRAC_BITS);
        let mut mm = [[0i64; 3]; 3];
        for (i, row) in mm.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                let r = m.col(j)[i];
                if !r.is_finite() || r.abs() > 1.0 + 1e-6 {
                    return None;
                }
                *x = (r * scale).round() as i64;
            }
        }
        let mut out = Self {
            mode,
            m: mm,
            t: [0; 3],
            ea,
            eb,
        };
        // t / f: exact scaling by a power of two (|t| <= 2^37, -ef <= 96: no overflow).
        let inv_f = 2f64.powi(-out.fine_exponent());
        let lim = 2f64.powi(78);
        for i in 0..3 {
            let v = (t[i] * inv_f).round();
            if !v.is_finite() || v.abs() >= lim {
                return None;
            }
            out.t[i] = v as i128;
        }
        Some(out)
    }

    /// `W / f`, exactly (i128): `M k_B + T - k_A 2^shift` (mode 1) or `T - k_A 2^46` (mode 2).
    pub fn w_units(&self, ka: [i64; 3], kb: [i64; 3]) -> [i128; 3] {
        std::array::from_fn(|i| {
            let mk: i128 = match self.mode {
                1 => (0..3).map(|j| self.m[i][j] as i128 * kb[j] as i128).sum(),
                _ => 0,
            };
            mk + self.t[i] - ((ka[i] as i128) << self.shift_a())
        })
    }

    /// The shader's words: `fix = (mode, e_A, e_B, 0)`; per column `j` of `M`, rows' low limbs
    /// `M0 | M1 << 16` (u32) and high limbs `M >> 32` (i32); `T`'s limbs `T0 | T1 << 16`,
    /// `T2 | T3 << 16` (u32) and `T >> 64` (i32), per coordinate.
    pub fn words(&self) -> ExactWords {
        let mut w = ExactWords {
            fix: [self.mode, self.ea, self.eb, 0],
            ..Default::default()
        };
        for j in 0..3 {
            for i in 0..3 {
                let m = self.m[i][j];
                w.m_lo[j][i] = (m & 0xffff) as u32 | (((m >> 16) & 0xffff) as u32) << 16;
                w.m_hi[j][i] = (m >> 32) as i32;
            }
        }
        for i in 0..3 {
            let t = self.t[i];
            let limb = |k: u32| ((t >> (16 * k)) & 0xffff) as u32;
            w.t01[i] = limb(0) | limb(1) << 16;
            w.t23[i] = limb(2) | limb(3) << 16;
            w.t4[i] = (t >> 64) as i32;
        }
        w
    }
}

/// [`ExactPose::words`]: what `PairInfo` carries for the exact path (zeros: the rotated path,
/// with `fix = (0, e_A, e_B, 0)`, the grid exponents still needed to rebuild vertices).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ExactWords {
    /// `(path, e_A, e_B, 0)`, path 1 or 2: exact ([`ExactPose`]'s modes), 0: rotated.
    pub fix: [i32; 4],
    /// Per column of `M`: `M0 | M1 << 16` per row (w unused).
    pub m_lo: [[u32; 4]; 3],
    /// Per column of `M`: `M >> 32` per row.
    pub m_hi: [[i32; 4]; 3],
    /// `T0 | T1 << 16` per coordinate.
    pub t01: [u32; 4],
    /// `T2 | T3 << 16` per coordinate.
    pub t23: [u32; 4],
    /// `T >> 64` per coordinate.
    pub t4: [i32; 4],
}

#[cfg(test)]
mod tests {
    use super::*;
    use frcd_geom::{DQuat, Pose, shapes};
    use frcd_obb::BuildOptions;

    #[test]
    fn layout_single_row_rows_and_layers() {
        let l = TexLayout::new(10, 5, 1000, 100, 4).unwrap();
        assert_eq!((l.items_per_row, l.rows_per_layer, l.layers), (5, 1, 2));
        let l = TexLayout::new(10, 5, 12, 100, 4).unwrap();
        assert_eq!((l.items_per_row, l.rows_per_layer, l.layers), (2, 3, 2));
        // Never one layer (GL), never square with 6k layers (GL cube maps).
        for n in 1..200 {
            for (w, r) in [(5, 1), (10, 2), (15, 3), (30, 6)] {
                if let Ok(l) = TexLayout::new(n, 5, w, r, 64) {
                    assert!(l.layers >= 2, "{n} {w} {r}");
                    assert!(!(l.width() == l.rows_per_layer && l.layers % 6 == 0));
                    assert!(
                        l.items_per_row as usize * l.rows_per_layer as usize * l.layers as usize
                            >= n
                    );
                }
            }
        }
        let l = TexLayout::new(10, 5, 12, 2, 4).unwrap();
        assert_eq!((l.items_per_row, l.rows_per_layer, l.layers), (2, 2, 3));
        assert!(matches!(
            TexLayout::new(10, 5, 12, 2, 2),
            Err(GpuError::MeshTooLarge { .. })
        ));
        assert!(TexLayout::new(1, 5, 4, 2, 2).is_err());
        // Every slot distinct and inside the texture.
        let mut seen = std::collections::HashSet::new();
        for i in 0..10 {
            for k in 0..5 {
                let (x, y, z) = l.slot(i, k);
                assert!(x < l.width() && y < l.rows_per_layer && z < l.layers);
                assert!(seen.insert(l.linear(i, k)));
                assert!(l.linear(i, k) < l.texel_count());
            }
        }
    }

    #[test]
    fn rounding_is_directed() {
        for x in [0.1, -0.1, 1e-40, 3.0, 1e300, -1e300, 0.0] {
            assert!(round_up(x) as f64 >= x, "{x}");
            assert!(round_down(x) as f64 <= x, "{x}");
        }
    }

    /// Solves `A32 s = p - c32` in f64 and checks `|s_i| <= h32_i`.
    fn inside(b: &ObbF32, p: DVec3) -> bool {
        let a = DMat3::from_cols(back(b.axes[0]), back(b.axes[1]), back(b.axes[2]));
        let s = a.inverse() * (p - back(b.center));
        (0..3).all(|i| s[i].abs() <= b.half_extents[i] as f64)
    }

    fn subtree_triangles(tree: &ObbTree, i: usize, out: &mut Vec<u32>) {
        let n = &tree.node(i as u32);
        if n.is_leaf() {
            out.extend_from_slice(
                &tree.leaf_triangles()[n.first as usize..(n.first + n.count) as usize],
            );
        } else {
            subtree_triangles(tree, i + 1, out);
            subtree_triangles(tree, n.right as usize, out);
        }
    }

    #[test]
    fn f32_boxes_hold_every_vertex_far_from_the_origin() {
        // A mesh far from its local origin, rotated: rounding of centres and axes is large.
        let pose = Pose::new(
            DVec3::new(3.0e3, -1.7e3, 512.3),
            DQuat::from_axis_angle(DVec3::new(0.3, -1.1, 2.0).normalize(), 2.2),
        );
        let mesh = shapes::icosphere(0.7, 3).transformed(&pose);
        let tree = ObbTree::build(&mesh, &BuildOptions::default());
        for (i, n) in tree.nodes().iter().enumerate() {
            let b = obb_to_f32(&n.obb, i).unwrap();
            let mut tris = Vec::new();
            subtree_triangles(&tree, i, &mut tris);
            for t in tris {
                for p in tree.triangle(t).v {
                    assert!(inside(&b, p), "node {i} misses {p:?}");
                }
            }
        }
    }

    #[test]
    fn sibling_order_puts_children_side_by_side_and_refuses_shared_or_missing_ones() {
        // 0 -> (1, 4); 1 -> (2, 3): breadth first 0, 1, 4, 2, 3.
        let tree = |i: usize| match i {
            0 => Some((1, 4)),
            1 => Some((2, 3)),
            _ => None,
        };
        let (order, first) = sibling_order_of(5, tree).unwrap();
        assert_eq!(order, vec![0, 1, 4, 2, 3]);
        assert_eq!(first, vec![1, 3, 0, 0, 0]);
        // Node 2 is both 0's right child and 1's left child.
        let shared = |i: usize| match i {
            0 => Some((1, 2)),
            1 => Some((2, 3)),
            _ => None,
        };
        assert!(matches!(
            sibling_order_of(4, shared),
            Err(GpuError::InvalidInput(m)) if m.contains("node 2")
        ));
        let missing = |i: usize| (i == 0).then_some((1, 7));
        assert!(matches!(
            sibling_order_of(3, missing),
            Err(GpuError::InvalidInput(m)) if m.contains("node 7")
        ));
    }

    #[test]
    fn packed_tree_round_trips_through_the_layout() {
        let mesh = shapes::icosphere(1.0, 2);
        let tree = ObbTree::build(&mesh, &BuildOptions::default());
        let limits = TexLimits {
            max_width: 17,
            max_rows: 7,
            max_layers: 64,
        };
        let p = pack_tree(&tree, &limits).unwrap();
        assert!(p.node_layout.layers > 1 && p.tri_layout.layers > 1);
        let mut eps = 0f32;
        let (bfs, _) = sibling_order(&tree).unwrap();
        let mut slot_of = vec![usize::MAX; bfs.len()];
        for (slot, &i) in bfs.iter().enumerate() {
            slot_of[i] = slot;
        }
        assert!(
            slot_of.iter().all(|&s| s != usize::MAX),
            "every node has a slot"
        );
        for (i, n) in tree.nodes().iter().enumerate() {
            let slot = slot_of[i] as u32;
            let t: [[u32; 4]; 4] =
                std::array::from_fn(|k| p.nodes[p.node_layout.linear(slot, k as u32)]);
            let b = obb_to_f32(&n.obb, i).unwrap();
            eps = eps.max(b.axes_deviation());
            let f = |x: u32| f32::from_bits(x);
            assert_eq!([f(t[0][0]), f(t[0][1]), f(t[0][2])], b.center);
            for k in 0..3 {
                assert_eq!([f(t[k + 1][0]), f(t[k + 1][1]), f(t[k + 1][2])], b.axes[k]);
                assert_eq!(f(t[k + 1][3] & !LEAF_FLAG), b.half_extents[k]);
            }
            assert_eq!(t[1][3] & LEAF_FLAG != 0, n.is_leaf(), "node {i}");
            if n.is_leaf() {
                assert_eq!(t[0][3] & 0xff_ffff, n.first);
                assert_eq!((t[0][3] >> 24) + 1, n.count);
            } else {
                // The children side by side, in the tree's order (left, then right).
                assert_eq!(bfs[t[0][3] as usize], i + 1, "node {i}'s first child");
                assert_eq!(
                    bfs[t[0][3] as usize + 1],
                    n.right as usize,
                    "node {i}'s second"
                );
            }
        }
        assert_eq!(p.eps, eps);
        assert!(eps > 0.0);
        let e = p.grid.expect("a unit sphere has a grid");
        assert_eq!(e, -GRID_BITS);
        for (slot, &index) in tree.leaf_triangles().iter().enumerate() {
            let t: [[f32; 4]; 3] =
                std::array::from_fn(|j| p.tris[p.tri_layout.linear(slot as u32, j as u32)]);
            assert_eq!(t[0][3] as u32, index);
            // Offsets from the reference point k 2^e, k the centroid's nearest grid point.
            let tri = tree.triangle(index);
            let k = unpack_k(t[1][3], t[2][3]);
            assert_eq!(k, grid_point(&tri.v, e));
            assert!(k.iter().all(|x| x.abs() <= 1 << GRID_BITS));
            let c = grid_coords(k, e);
            for (tj, v) in t.iter().zip(tri.v) {
                assert_eq!(tj[0], (v.x - c.x) as f32);
                assert_eq!(tj[2], (v.z - c.z) as f32);
                // Small: within a triangle's size plus half a grid step of 0.
                assert!(tj[1].abs() < 0.2, "{tj:?}");
            }
        }
        assert!(p.depth >= 7, "{}", p.depth);
    }

    #[test]
    fn bad_axes_are_refused() {
        let obb = Obb {
            center: DVec3::ZERO,
            axes: DMat3::from_cols(DVec3::X, DVec3::X, DVec3::Z),
            half_extents: DVec3::ONE,
        };
        assert!(matches!(
            obb_to_f32(&obb, 3),
            Err(GpuError::BadNodeAxes { node: 3, .. })
        ));
    }

    #[test]
    fn grid_coordinates_round_trip_and_grids_follow_the_magnitude() {
        for k in [
            [0, 0, 0],
            [-16384, 16384, 7],
            [12345, -1, -16384],
            [1, 255, 256],
        ] {
            let (w1, w2) = pack_k(k);
            assert!(w1 < 16_777_216.0 && w2 < 16_777_216.0);
            assert_eq!(unpack_k(w1, w2), k);
        }
        assert_eq!(grid_exponent_for(1.0), Some(-GRID_BITS));
        assert_eq!(grid_exponent_for(1.5), Some(1 - GRID_BITS));
        assert_eq!(grid_exponent_for(0.0), None);
        assert_eq!(grid_exponent_for(1e-12), None);
        assert_eq!(grid_exponent_for(MAX_MAGNITUDE), Some(36 - GRID_BITS));
        assert_eq!(grid_exponent_for(f64::NAN), None);
    }

    #[test]
    fn exact_poses_choose_their_mode_or_refuse() {
        let r = DMat3::from_quat(DQuat::from_rotation_z(0.3));
        let t = DVec3::new(1.0, -2.0, 0.5);
        // Grids close: mode 1; B's grid far below A's (or none): mode 2; A's far below B's or
        // A without a grid: the rotated path.
        assert_eq!(ExactPose::new(&r, t, Some(-14), Some(-10)).unwrap().mode, 1);
        assert_eq!(ExactPose::new(&r, t, Some(-14), Some(-30)).unwrap().mode, 1);
        assert_eq!(ExactPose::new(&r, t, Some(-14), Some(-31)).unwrap().mode, 2);
        assert_eq!(ExactPose::new(&r, t, Some(-14), None).unwrap().mode, 2);
        assert!(ExactPose::new(&r, t, Some(-50), Some(-3)).is_none());
        assert!(ExactPose::new(&r, t, None, Some(-14)).is_none());
        // W / f exactly: k_A = k_B = 0 leaves T = t / f.
        let e = ExactPose::new(&r, t, Some(-14), Some(-14)).unwrap();
        assert_eq!(e.w_units([0; 3], [0; 3])[0], 1i128 << 60);
        // The words hold M and T limb by limb.
        let w = e.words();
        let m00 = w.m_lo[0][0] as i64 & 0xffff
            | ((w.m_lo[0][0] >> 16) as i64) << 16
            | (w.m_hi[0][0] as i64) << 32;
        assert_eq!(m00, e.m[0][0]);
        let t1 = (w.t01[1] & 0xffff) as i128
            | ((w.t01[1] >> 16) as i128) << 16
            | ((w.t23[1] & 0xffff) as i128) << 32
            | ((w.t23[1] >> 16) as i128) << 48
            | (w.t4[1] as i128) << 64;
        assert_eq!(t1, e.t[1]);
        assert_eq!(t1, -(1i128 << 61));
    }
}
