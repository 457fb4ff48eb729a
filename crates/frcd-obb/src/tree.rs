use frcd_geom::fit::FitMethod;
use frcd_geom::{Aabb, DVec3, Obb, Sphere, TriMesh, Triangle};

/// One node of an [`ObbTree`], in a flat array in depth-first order.
///
/// An internal node's left child is the next node (`index + 1`); its right child is `right`.
/// A leaf (`count > 0`) holds the triangles `tree.leaf_triangles()[first .. first + count]`
/// (indices into the input mesh).
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
    /// `obb/build`; see the crate README).
    pub fit: FitMethod,
    /// Most triangles in a leaf (a node with at most this many triangles becomes a leaf).
    /// `0` is treated as `1`. The default, 1, was measured against 2 and 4 on every bench class
    /// (`FRCD_BENCH_LEAF`, see the crate README): 1 was fastest or within noise on the dense
    /// sweep and the real CAD pairs (leaf 4 was 1.6-2.5× slower on the wagon/bogie pairs), 2
    /// about 25 % faster on the near-contact knots; larger leaves save memory and build time.
    pub max_leaf_triangles: u32,
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self {
            fit: FitMethod::VertexCovariance,
            max_leaf_triangles: 1,
        }
    }
}

/// An OBB tree over one mesh, in the mesh's local frame.
///
/// ```
/// use frcd_obb::{BuildOptions, ObbTree};
/// let mesh = frcd_geom::shapes::icosphere(1.0, 2);
/// let tree = ObbTree::build(&mesh, &BuildOptions::default());
/// assert_eq!(tree.nodes().len(), 2 * mesh.triangle_count() - 1);
/// assert_eq!(tree.triangles().len(), mesh.triangle_count());
/// ```
#[derive(Clone, Debug)]
pub struct ObbTree {
    pub(crate) nodes: Vec<Node>,
    pub(crate) order: Vec<u32>,
    pub(crate) triangles: Vec<Triangle>,
    pub(crate) sphere: Sphere,
    pub(crate) aabb: Aabb,
    /// Largest |coordinate| norm of the mesh (local frame), for error bounds.
    pub(crate) radius_from_origin: f64,
    /// One vertex per connected component (for the point-in-mesh parity tests).
    pub(crate) component_points: Vec<DVec3>,
    /// Identity of this build (clones share it: same structure), for caches.
    pub(crate) uid: u64,
    /// Every edge has an even number of incident triangles (parity tests are meaningful).
    pub(crate) closed: bool,
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
    pub fn build(mesh: &TriMesh, options: &BuildOptions) -> ObbTree {
        let triangles: Vec<Triangle> = mesh.triangles().collect();
        let (nodes, order) = crate::build::build_nodes(mesh, options);
        let points = mesh.vertices();
        let sphere = Sphere::from_points(points);
        let aabb = mesh.aabb();
        let radius_from_origin = aabb.min.abs().max(aabb.max.abs()).length();
        ObbTree {
            nodes,
            order,
            triangles,
            sphere,
            aabb,
            radius_from_origin,
            component_points: component_points(mesh),
            closed: mesh.topology().is_closed(),
            uid: NEXT_UID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
        }
    }

    /// The nodes, depth-first; node 0 is the root.
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }
    /// Mesh triangle indices in leaf order: a leaf holds `order[first .. first + count]`.
    pub fn leaf_triangles(&self) -> &[u32] {
        &self.order
    }
    /// The mesh's triangles (local frame), indexed as in the input mesh.
    pub fn triangles(&self) -> &[Triangle] {
        &self.triangles
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
        self.nodes[node as usize].obb
    }
    /// The children of an internal node (none for a leaf).
    #[allow(dead_code)]
    pub(crate) fn node_children(&self, node: u32) -> impl Iterator<Item = u32> + '_ {
        let n = &self.nodes[node as usize];
        let kids = if n.is_leaf() {
            [0, 0]
        } else {
            [node + 1, n.right]
        };
        kids.into_iter().take(if n.is_leaf() { 0 } else { 2 })
    }
    /// The input-mesh triangle indices of a leaf (empty for an internal node).
    #[allow(dead_code)]
    pub(crate) fn node_triangles(&self, node: u32) -> &[u32] {
        let n = &self.nodes[node as usize];
        &self.order[n.first as usize..(n.first + n.count) as usize]
    }
    /// Triangle `tri` (input-mesh index) in the mesh's local frame.
    #[allow(dead_code)]
    pub(crate) fn triangle(&self, tri: u32) -> Triangle {
        self.triangles[tri as usize]
    }

    /// Heap and inline bytes held by the tree (nodes, triangle copies, leaf order, component
    /// points), not counting the mesh it was built from: divide by the triangle count for the
    /// per-triangle cost reported in the crate README.
    ///
    /// ```
    /// use frcd_obb::{BuildOptions, ObbTree};
    /// let mesh = frcd_geom::shapes::icosphere(1.0, 3);
    /// let tree = ObbTree::build(&mesh, &BuildOptions::default());
    /// assert!(tree.memory_bytes() > 72 * mesh.triangle_count());
    /// ```
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.nodes.capacity() * std::mem::size_of::<Node>()
            + self.order.capacity() * std::mem::size_of::<u32>()
            + self.triangles.capacity() * std::mem::size_of::<Triangle>()
            + self.component_points.capacity() * std::mem::size_of::<DVec3>()
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
                stack.push((node.right, d + 1));
            }
        }
        best
    }
}

/// One vertex per connected component (triangles connected through shared vertex indices).
fn component_points(mesh: &TriMesh) -> Vec<DVec3> {
    let n = mesh.vertex_count();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn find(p: &mut [u32], mut i: u32) -> u32 {
        while p[i as usize] != i {
            p[i as usize] = p[p[i as usize] as usize];
            i = p[i as usize];
        }
        i
    }
    let mut used = vec![false; n];
    for tri in mesh.indices() {
        for &v in tri {
            used[v as usize] = true;
        }
        let r0 = find(&mut parent, tri[0]);
        for &v in &tri[1..] {
            let r = find(&mut parent, v);
            if r != r0 {
                parent[r as usize] = r0;
            }
        }
    }
    let mut seen = vec![false; n];
    let mut out = Vec::new();
    for v in 0..n as u32 {
        if !used[v as usize] {
            continue;
        }
        let r = find(&mut parent, v);
        if !seen[r as usize] {
            seen[r as usize] = true;
            out.push(mesh.vertices()[v as usize]);
        }
    }
    out
}
