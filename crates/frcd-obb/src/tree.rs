use crate::nodes::{self, TNode};
use frcd_geom::fit::FitMethod;
use frcd_geom::{Aabb, DVec3, Obb, Sphere, TriMesh, Triangle};
use std::sync::Arc;

/// One node of an [`ObbTree`] as the build produces it, and the f64 view of a stored node
/// ([`ObbTree::node`]), in depth-first order.
///
/// An internal node's left child is the next node (`index + 1`); its right child is `right`.
/// A leaf (`count > 0`) holds the triangles `tree.leaf_triangles()[first .. first + count]`
/// (indices into the input mesh). The tree stores its nodes in a compact 64-byte f32 form;
/// a view's box is an f64 box with orthonormal axes that holds the stored one, hence every
/// triangle below the node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// The node's box, in the mesh's local frame.
    #[doc(hidden)]
    pub obb: Obb,
    /// Index of the right child (internal nodes); unused (0) in leaves.
    #[doc(hidden)]
    pub right: u32,
    /// First entry in the triangle order (leaves).
    #[doc(hidden)]
    pub first: u32,
    /// Number of triangles (0 for internal nodes).
    #[doc(hidden)]
    pub count: u32,
}

impl Node {
    /// True for a leaf.
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }
}

static NEXT_UID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

/// How to build an [`ObbTree`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct BuildOptions {
    /// Rule choosing each node's box axes. The default, [`FitMethod::VertexCovariance`], gave the
    /// fastest all-pairs queries and the fastest build in `benches/benches/obb.rs` (`obb/fit`,
    /// `obb/build`; see the crate README). With it a leaf of two triangles takes the frame of
    /// their plane and their longest unshared edge instead (tighter on the quads of a
    /// tessellation, whose diagonal's ends the covariance counts twice); a one-triangle leaf
    /// always takes its own frame.
    pub fit: FitMethod,
    /// Most triangles in a leaf (a node with at most this many triangles becomes a leaf).
    /// `0` is treated as `1`. The default, 2, was measured against 1 on every bench class with
    /// the 64-byte f32 nodes (`FRCD_BENCH_LEAF`, see the crate README): leaf 2 was faster on the
    /// dense sweep (all pairs 14 %), the knots and the fandisk pair, 10-16 % slower on the
    /// railway CAD pairs, and it holds mesh + tree at about 108-117 B per triangle against
    /// 156-165 at leaf 1 (target ≤ 150).
    pub max_leaf_triangles: u32,
    /// Rule choosing where each internal node splits its triangles. The default,
    /// [`SplitMethod::SurfaceCost`], makes trees that need 4-6× fewer box tests per query on
    /// real CAD parts (railway wagon and bogie frames) and 10-15 % fewer on smooth meshes than
    /// [`SplitMethod::MajorAxisMean`] (PQP's rule), for a build that takes about 1.5× as long
    /// (`benches/benches/build.rs`; figures in `docs/performance/cpu-core.md`).
    #[cfg_attr(feature = "serde", serde(default))]
    pub split: SplitMethod,
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self {
            fit: FitMethod::VertexCovariance,
            max_leaf_triangles: 2,
            split: SplitMethod::default(),
        }
    }
}

/// Where an internal node of an [`ObbTree`] splits its triangles in two.
///
/// Both rules cut across one of the node's box axes, sending each triangle to the side of its
/// centroid; they differ in which axis and where. The rule changes only the tree's shape: every
/// box holds its triangles and every query answers the same under either.
///
/// ```
/// use frcd_obb::{BuildOptions, ObbTree, SplitMethod};
/// let mesh = frcd_geom::shapes::icosphere(1.0, 3);
/// let fast_build = BuildOptions { split: SplitMethod::MajorAxisMean, ..BuildOptions::default() };
/// let a = ObbTree::build(&mesh, &fast_build);
/// let b = ObbTree::build(&mesh, &BuildOptions::default());
/// // Different shapes, the same triangles below the roots.
/// assert_eq!(a.leaf_triangles().len(), b.leaf_triangles().len());
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum SplitMethod {
    /// The cut of least cost among 15 candidate planes across each of the node's three box
    /// axes (16 bins of the triangles' centroids per axis), the cost of a side being its
    /// triangle count times `xy + yz + zx + ((x + y + z) / 3)²` for the extents `x, y, z` of
    /// its triangles in the node's frame: the box's surface, which predicts how often a side is
    /// visited, plus a term for the other tree's boxes it is tested against. A node of 3 or 4
    /// triangles takes the cheapest of all its partitions instead. Falls back to
    /// [`SplitMethod::MajorAxisMean`]'s cut where no candidate leaves both sides non-empty.
    /// One more pass per node than `MajorAxisMean`.
    #[default]
    SurfaceCost,
    /// The plane through the triangles' mean across the box's major axis (the rule of PQP and
    /// RAPID): one pass per node, the fastest build, and trees that split elongated CAD parts
    /// badly (a long part cut across its length keeps both halves' boxes as wide as the part).
    MajorAxisMean,
}

/// An OBB tree over one mesh, in the mesh's local frame.
///
/// ```
/// use frcd_obb::{BuildOptions, ObbTree};
/// let mesh = frcd_geom::shapes::icosphere(1.0, 2);
/// let tree = ObbTree::build(&mesh, &BuildOptions::default());
/// assert!(tree.node_count() < 2 * mesh.triangle_count());
/// assert_eq!(tree.triangles().len(), mesh.triangle_count());
/// ```
#[derive(Clone, Debug)]
pub struct ObbTree {
    /// Traversal nodes (depth-first, node 0 the root), 64 bytes each.
    pub(crate) nodes: Vec<TNode>,
    pub(crate) order: Vec<u32>,
    /// Bit `k` set when leaf-order entry `k` ends its leaf.
    pub(crate) ends: Vec<u64>,
    /// The mesh, shared (the tree keeps no copy of its triangles).
    pub(crate) mesh: Arc<TriMesh>,
    pub(crate) sphere: Sphere,
    pub(crate) aabb: Aabb,
    /// Largest |coordinate| norm of the mesh (local frame), for error bounds.
    pub(crate) radius_from_origin: f64,
    /// An upper bound on every vertex's distance from the local origin (tighter than
    /// `radius_from_origin`, the box corner's): how far a rotation can move the geometry,
    /// for the coherence cache's motion bound.
    pub(crate) vertex_radius: f64,
    /// One vertex per connected component (for the point-in-mesh parity tests).
    pub(crate) component_points: Vec<DVec3>,
    /// Per connected component (same order), its vertices of least and greatest x, y and z
    /// (`TriMesh::component_extremes`): one of them outside a convex region (a box holding
    /// the other mesh) puts the component outside that mesh, with no parity test.
    pub(crate) component_extremes: Vec<[DVec3; 6]>,
    /// Identity of this build (clones share it: same structure), for caches.
    pub(crate) uid: u64,
    /// Every edge has an even number of incident triangles (parity tests are meaningful).
    pub(crate) closed: bool,
    /// The derived four-lane layer of the wide traversal (`wide.rs`): the nodes two levels
    /// below each internal node at even depth, in lanes, and per node its quad's index · 4 +
    /// lanes − 1 (or [`crate::wide::NO_QUAD`]) and its [`crate::wide::NodeMeta`]. Built by
    /// the first collision query, so the build and trees never queried pay nothing.
    pub(crate) quads: std::sync::OnceLock<crate::wide::Quads>,
    /// Whether the first query builds the quad layer (see [`ObbTree::with_quad_layer`]).
    quad_layer: bool,
    /// Distance volumes (one rectangle swept sphere per node), built on the first distance or
    /// tolerance query (`crate::distance`), so collision-only users pay no memory.
    pub(crate) distance_volumes: std::sync::OnceLock<Vec<crate::distance::rss::DNode>>,
}

impl ObbTree {
    /// Builds the tree: each node's box is fitted with `options.fit`; a node is split by the
    /// plane through the mean of its triangles' centroids, across its box's major axis (the
    /// other two axes are tried when one side would be empty, and the list is halved when all
    /// three fail); nodes with at most `options.max_leaf_triangles` triangles become leaves. A
    /// one-triangle leaf gets the triangle's own frame (longest edge, normal): a flat box, the
    /// tightest there is, whatever the fit rule.
    /// `O(n log n)` for balanced splits; an explicit stack keeps degenerate inputs off the call
    /// stack.
    ///
    /// The tree holds the mesh: this clones it once into an [`Arc`]; use
    /// [`ObbTree::build_shared`] to share a mesh you already hold in an `Arc` without a copy.
    pub fn build(mesh: &TriMesh, options: &BuildOptions) -> ObbTree {
        Self::build_shared(Arc::new(mesh.clone()), options)
    }

    /// [`ObbTree::build`] on a shared mesh: the tree keeps this `Arc` (no copy of the mesh) and
    /// reads triangles through it.
    ///
    /// ```
    /// use std::sync::Arc;
    /// use frcd_obb::{BuildOptions, ObbTree};
    /// let mesh = Arc::new(frcd_geom::shapes::icosphere(1.0, 2));
    /// let tree = ObbTree::build_shared(mesh.clone(), &BuildOptions::default());
    /// assert!(Arc::ptr_eq(tree.mesh(), &mesh));
    /// assert_eq!(tree.triangle(7), mesh.triangle(7));
    /// ```
    pub fn build_shared(mesh: Arc<TriMesh>, options: &BuildOptions) -> ObbTree {
        // The build writes the compact traversal layout (`nodes.rs`) directly.
        let (nodes, order, ends) = crate::build::build_compact(&mesh, options);
        ObbTree::from_compact(mesh, nodes, order, ends)
    }

    /// The tree from compact nodes, the leaf order and its end bits (checked by the caller).
    pub(crate) fn from_compact(
        mesh: Arc<TriMesh>,
        mut nodes: Vec<TNode>,
        order: Vec<u32>,
        ends: Vec<u64>,
    ) -> Self {
        // The build pushes nodes one by one (their count is known only at the end) into an
        // array sized by estimate. A spare eighth or less is kept: shrinking copies the whole
        // array (64-byte alignment rules out a reallocation in place), 2-5 % of a build.
        if nodes.capacity() - nodes.len() > nodes.len() / 8 {
            nodes.shrink_to_fit();
        }
        let points = mesh.vertices();
        let sphere = Sphere::from_points(points);
        let (component_points, component_extremes) = components(&mesh);
        let aabb = mesh.aabb();
        let radius_from_origin = aabb.min.abs().max(aabb.max.abs()).length();
        let vertex_radius = points.iter().fold(0.0f64, |r, p| r.max(norm_bound(*p)));
        ObbTree {
            quads: std::sync::OnceLock::new(),
            quad_layer: true,
            nodes,
            order,
            ends,
            sphere,
            aabb,
            radius_from_origin,
            vertex_radius,
            component_points,
            component_extremes,
            closed: mesh.topology().is_closed(),
            uid: NEXT_UID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
            mesh,
            distance_volumes: std::sync::OnceLock::new(),
        }
    }
}

impl ObbTree {
    /// The quad layer of the wide traversal, built on first use.
    #[inline]
    pub(crate) fn quads(&self) -> &crate::wide::Quads {
        self.quads.get_or_init(|| {
            if self.quad_layer {
                crate::wide::build_quads(&self.nodes)
            } else {
                crate::wide::Quads::without_quads(&self.nodes)
            }
        })
    }

    /// The tree with or without the wide traversal's quad layer (on by default). The layer
    /// copies the nodes two levels below each internal node at even depth into four-lane
    /// blocks (with the per-node quad entries and metas, about 92 B per triangle at leaf 2,
    /// built by the first collision query), so a traversal step loads its lanes instead of
    /// gathering four nodes. Without it mesh + tree take about 108-117 B per triangle, plus
    /// about 15 for the per-node quad entries and metas once queried, and the box work is
    /// slower (the crate README gives the measured cost); answers are the same either way.
    ///
    /// ```
    /// use frcd_obb::{BuildOptions, ObbTree};
    /// let mesh = frcd_geom::shapes::icosphere(1.0, 3);
    /// let lean = ObbTree::build(&mesh, &BuildOptions::default()).with_quad_layer(false);
    /// let fast = ObbTree::build(&mesh, &BuildOptions::default());
    /// let (id, q) = (frcd_geom::Pose::IDENTITY, frcd_obb::Request::default());
    /// assert_eq!(frcd_obb::collide(&lean, &id, &lean, &id, &q).collide, true);
    /// frcd_obb::collide(&fast, &id, &fast, &id, &q);
    /// assert!(lean.memory_bytes() < fast.memory_bytes());
    /// ```
    pub fn with_quad_layer(mut self, on: bool) -> Self {
        if on != self.quad_layer {
            self.quad_layer = on;
            self.quads = std::sync::OnceLock::new();
        }
        self
    }

    /// The nodes, depth-first (node 0 is the root), as f64 views ([`ObbTree::node`]); builds
    /// the list (the tree stores compact f32 nodes).
    pub fn nodes(&self) -> Vec<Node> {
        (0..self.nodes.len() as u32).map(|i| self.node(i)).collect()
    }
    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }
    /// Node `i` (`i < node_count()`) as an f64 view: links as built, and an f64 box with
    /// orthonormal axes holding the stored f32 box, hence every triangle below the node.
    pub fn node(&self, i: u32) -> Node {
        let n = &self.nodes[i as usize];
        let (right, first, count) = if n.is_leaf() {
            (0, n.first(), nodes::leaf_len(&self.ends, n.first()))
        } else {
            (n.right(), 0, 0)
        };
        Node {
            obb: n.obb(),
            right,
            first,
            count,
        }
    }
    /// Mesh triangle indices in leaf order: a leaf holds `order[first .. first + count]`.
    pub fn leaf_triangles(&self) -> &[u32] {
        &self.order
    }
    /// The mesh's triangles (local frame), indexed as in the input mesh, read through the mesh
    /// (the tree keeps no copy): use [`ObbTree::triangle`] for one.
    pub fn triangles(&self) -> impl ExactSizeIterator<Item = Triangle> + '_ {
        self.mesh.triangles()
    }
    /// Number of triangles of the mesh.
    pub fn triangle_count(&self) -> usize {
        self.mesh.triangle_count()
    }
    /// The mesh the tree was built over (shared, not copied).
    pub fn mesh(&self) -> &Arc<TriMesh> {
        &self.mesh
    }
    /// Bounding sphere of the whole mesh (local frame), part of the hybrid top volume.
    pub fn bounding_sphere(&self) -> Sphere {
        self.sphere
    }
    /// Axis-aligned box of the whole mesh (local frame), part of the hybrid top volume.
    pub fn aabb(&self) -> Aabb {
        self.aabb
    }
    /// True when every edge of the mesh has exactly two incident triangles, so the mesh bounds a
    /// solid and solid-mode queries can test containment in it.
    pub fn is_closed(&self) -> bool {
        self.closed
    }
    /// One vertex of each connected component of the mesh (local frame): the points whose
    /// parity is tested in solid mode.
    pub fn component_points(&self) -> &[DVec3] {
        &self.component_points
    }
    // --- Crate-internal view of the hierarchy -------------------------------------------------
    // Queries other than the collision traversal (distance, tolerance) walk the tree only through
    // these five functions, so the node layout can change (wider nodes, relative or f32 boxes)
    // without touching them. Keep their meaning when the layout changes.

    /// The root node's id.
    #[allow(dead_code)]
    pub(crate) fn root_node(&self) -> u32 {
        0
    }
    /// A node's box in the mesh's local frame, in f64, containing every triangle below it.
    #[allow(dead_code)]
    pub(crate) fn node_obb(&self, node: u32) -> Obb {
        self.nodes[node as usize].obb()
    }
    /// The children of an internal node (none for a leaf).
    #[allow(dead_code)]
    pub(crate) fn node_children(&self, node: u32) -> impl Iterator<Item = u32> + '_ {
        let n = &self.nodes[node as usize];
        let kids = if n.is_leaf() {
            [0, 0]
        } else {
            [node + 1, n.right()]
        };
        kids.into_iter().take(if n.is_leaf() { 0 } else { 2 })
    }
    /// The input-mesh triangle indices of a leaf (empty for an internal node).
    #[allow(dead_code)]
    #[inline]
    pub(crate) fn node_triangles(&self, node: u32) -> &[u32] {
        let n = &self.nodes[node as usize];
        if !n.is_leaf() {
            return &[];
        }
        let first = n.first();
        let count = nodes::leaf_len(&self.ends, first);
        &self.order[first as usize..(first + count) as usize]
    }
    /// Triangle `tri` (input-mesh index, `< triangle_count()`) in the mesh's local frame.
    #[inline]
    pub fn triangle(&self, tri: u32) -> Triangle {
        self.mesh.triangle(tri as usize)
    }

    /// Heap and inline bytes held by the tree itself (nodes, the quad layer of the wide
    /// traversal once a collision query has built it, leaf order and its end bits,
    /// component points), not counting the mesh, which it shares through an `Arc` (count it
    /// once with [`TriMesh::memory_bytes`] however many trees share it; [`ObbTree::build`]
    /// gives the tree its own copy, [`ObbTree::build_shared`] none). Mesh plus tree, divided by
    /// the triangle count, is the per-triangle cost reported in the crate README.
    ///
    /// ```
    /// use std::sync::Arc;
    /// use frcd_obb::{BuildOptions, ObbTree};
    /// let mesh = Arc::new(frcd_geom::shapes::icosphere(1.0, 3));
    /// let tree = ObbTree::build_shared(mesh.clone(), &BuildOptions::default());
    /// // A first query builds the wide traversal's quad layer.
    /// frcd_obb::collide(&tree, &Default::default(), &tree, &Default::default(), &Default::default());
    /// let per_triangle = (mesh.memory_bytes() + tree.memory_bytes()) / mesh.triangle_count();
    /// // 64-byte traversal nodes plus the wide traversal's quad layer (256 bytes per internal
    /// // node at even depth) and the mesh.
    /// assert!(per_triangle > 64 && per_triangle < 300, "{per_triangle}");
    /// ```
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.nodes.capacity() * std::mem::size_of::<TNode>()
            + self.quads.get().map_or(0, |q| q.memory_bytes())
            + self.order.capacity() * std::mem::size_of::<u32>()
            + self.ends.capacity() * std::mem::size_of::<u64>()
            + self.component_points.capacity() * std::mem::size_of::<DVec3>()
            + self.component_extremes.capacity() * std::mem::size_of::<[DVec3; 6]>()
    }

    /// Depth of the tree (a single leaf has depth 1).
    pub fn depth(&self) -> usize {
        let mut best = 0;
        let mut stack = vec![(0u32, 1usize)];
        while let Some((i, d)) = stack.pop() {
            best = best.max(d);
            let node = &self.nodes[i as usize];
            if !node.is_leaf() {
                stack.push((i + 1, d + 1));
                stack.push((node.right(), d + 1));
            }
        }
        best
    }
}

/// One vertex per connected component (triangles connected through shared vertex indices).
/// An upper bound on `|p|`: the computed length rounded up (three squares, two sums and a
/// square root, each within half an ulp: under 3ε in all), or, where squares could underflow or
/// overflow, `√3 · max |p_k|` rounded up.
fn norm_bound(p: DVec3) -> f64 {
    let m = p.abs().max_element();
    if (1e-150..=1e150).contains(&m) {
        p.length() * (1.0 + 1e-15)
    } else {
        m * (1.732_050_807_568_877_3 * (1.0 + 1e-15))
    }
}

/// Per connected component of `mesh`: one vertex (its lowest-index one), and its extreme
/// vertices on each axis.
fn components(mesh: &TriMesh) -> (Vec<DVec3>, Vec<[DVec3; 6]>) {
    let vertices = mesh.vertices();
    mesh.component_extremes()
        .iter()
        .map(|(v, e)| (vertices[*v as usize], e.map(|x| vertices[x as usize])))
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The node array keeps at most an eighth spare (it once held up to twice the nodes it
    /// used, about 64 B per triangle; an exact fit costs a copy of the array, 2-5 % of a
    /// build), the leaf order none, and `memory_bytes` counts what is allocated.
    #[test]
    fn built_tree_holds_little_spare_capacity() {
        for (mesh, leaf) in [
            (frcd_geom::shapes::icosphere(1.0, 4), 1),
            (frcd_geom::shapes::icosphere(1.0, 4), 2),
            (frcd_geom::shapes::torus(1.0, 0.3, 40, 12).unwrap(), 4),
        ] {
            let options = BuildOptions {
                max_leaf_triangles: leaf,
                ..BuildOptions::default()
            };
            let tree = ObbTree::build(&mesh, &options);
            let (len, capacity) = (tree.nodes.len(), tree.nodes.capacity());
            assert!(
                capacity - len <= len / 8,
                "leaf {leaf}: {capacity} for {len}"
            );
            assert_eq!(tree.order.capacity(), tree.order.len(), "leaf {leaf}");
            let bytes = tree.memory_bytes();
            let exact = std::mem::size_of::<ObbTree>()
                + capacity * std::mem::size_of::<TNode>()
                + tree.order.len() * 4
                + tree.ends.capacity() * 8
                + tree.component_points.capacity() * std::mem::size_of::<DVec3>()
                + tree.component_extremes.capacity() * std::mem::size_of::<[DVec3; 6]>();
            assert_eq!(bytes, exact, "leaf {leaf}");
        }
    }
}
