use frcd_geom::fit::{FitMethod, fit_obb};
use frcd_geom::{Aabb, DMat3, DVec3, Obb, Sphere, TriMesh, Triangle};

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
    pub fn build(mesh: &TriMesh, options: &BuildOptions) -> ObbTree {
        let triangles: Vec<Triangle> = mesh.triangles().collect();
        let n = triangles.len();
        let leaf = options.max_leaf_triangles.max(1) as usize;
        let mut order: Vec<u32> = (0..n as u32).collect();
        // Triangles permuted alongside `order`, so a node's triangles are one contiguous slice.
        let mut perm: Vec<Triangle> = triangles.clone();
        let mut centroids: Vec<DVec3> = triangles.iter().map(|t| t.centroid()).collect();
        let mut nodes: Vec<Node> = Vec::with_capacity(2 * n.div_ceil(leaf));
        // (lo, hi, parent whose `right` this node is, or u32::MAX)
        let mut stack: Vec<(usize, usize, u32)> = vec![(0, n, u32::MAX)];
        while let Some((lo, hi, parent)) = stack.pop() {
            let index = nodes.len() as u32;
            if parent != u32::MAX {
                nodes[parent as usize].right = index;
            }
            if hi - lo <= leaf {
                let obb = match &perm[lo..hi] {
                    [t] => triangle_obb(t).unwrap_or_else(|| fit_obb(&perm[lo..hi], options.fit)),
                    tris => fit_obb(tris, options.fit),
                };
                nodes.push(Node {
                    obb,
                    right: 0,
                    first: lo as u32,
                    count: (hi - lo) as u32,
                });
                continue;
            }
            let obb = fit_obb(&perm[lo..hi], options.fit);
            let mid = split(
                &obb,
                &mut order[lo..hi],
                &mut perm[lo..hi],
                &mut centroids[lo..hi],
            ) + lo;
            nodes.push(Node {
                obb,
                right: 0,
                first: 0,
                count: 0,
            });
            stack.push((mid, hi, index));
            stack.push((lo, mid, u32::MAX));
        }
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
            distance_volumes: std::sync::OnceLock::new(),
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

/// The box of one triangle in its own frame (longest edge, in-plane normal to it, normal):
/// flat and tight whatever the fit rule. `None` for a triangle without a usable normal.
fn triangle_obb(t: &Triangle) -> Option<Obb> {
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
    Some(Obb::from_points_with_axes(&t.v, DMat3::from_cols(x, y, z)))
}

/// Partitions a node's triangles; returns the size of the left part (in `1..len`).
fn split(obb: &Obb, order: &mut [u32], perm: &mut [Triangle], centroids: &mut [DVec3]) -> usize {
    let len = order.len();
    let mean = centroids.iter().copied().sum::<DVec3>() / len as f64;
    let axes = [obb.axes.x_axis, obb.axes.y_axis, obb.axes.z_axis];
    for axis in axes {
        let cut = axis.dot(mean);
        // Hoare-style partition of the three parallel arrays: `< cut` left.
        let mut i = 0;
        let mut j = len;
        while i < j {
            if axis.dot(centroids[i]) < cut {
                i += 1;
            } else {
                j -= 1;
                order.swap(i, j);
                perm.swap(i, j);
                centroids.swap(i, j);
            }
        }
        if i > 0 && i < len {
            return i;
        }
    }
    // All centroids project to the same point on every axis: halve the list.
    len / 2
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
