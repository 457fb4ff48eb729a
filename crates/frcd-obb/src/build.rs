//! Building an [`ObbTree`](crate::ObbTree)'s hierarchy: top-down splits with a fitted box per
//! node.
//!
//! The output contract, which the traversal layout is converted from: depth-first `Vec<Node>`
//! with f64 boxes in the mesh's local frame (left child = next node, `right`; leaves
//! `first`/`count`) and the `order` permutation of input-mesh triangle indices that leaves index.

use crate::tree::{BuildOptions, Node};
use frcd_geom::fit::fit_obb;
use frcd_geom::{DMat3, DVec3, Obb, TriMesh, Triangle};

/// Builds the nodes (depth-first, node 0 the root) and the leaf order of `mesh`'s triangles.
pub(crate) fn build_nodes(mesh: &TriMesh, options: &BuildOptions) -> (Vec<Node>, Vec<u32>) {
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
    (nodes, order)
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
