use frcd_geom::{Aabb, Obb, Sphere, Triangle};

/// One node of an [`ObbTree`], in a flat array in depth-first order.
///
/// An internal node's left child is the next node (`index + 1`); its right child is `right`.
/// A leaf (`count > 0`) holds the triangles `tree.leaf_triangles()[first .. first + count]`
/// (indices into the input mesh).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// The node's box, in the mesh's local frame.
    pub obb: Obb,
    /// Index of the right child (internal nodes); unused (0) in leaves.
    pub right: u32,
    /// First entry in the triangle order (leaves).
    pub first: u32,
    /// Number of triangles (0 for internal nodes).
    pub count: u32,
}

impl Node {
    /// True for a leaf.
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }
}

/// An OBB tree over one mesh, in the mesh's local frame.
#[derive(Clone, Debug)]
pub struct ObbTree {
    pub(crate) nodes: Vec<Node>,
    pub(crate) order: Vec<u32>,
    pub(crate) triangles: Vec<Triangle>,
    pub(crate) sphere: Sphere,
    pub(crate) aabb: Aabb,
}

impl ObbTree {
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
}
