//! Saving and loading a built tree (feature `serde`): [`SavedTree`] holds the hierarchy (nodes,
//! leaf order) and a digest of the mesh it was built over; [`ObbTree::from_saved`] checks it
//! against the mesh (same triangle count, same digest) and checks its structure (links in range,
//! the leaf order a permutation, finite boxes), so a stale or damaged file gives a typed error
//! rather than a wrong answer or a panic.

use crate::nodes::{LEAF, TNode};
use crate::tree::ObbTree;
use frcd_geom::TriMesh;
use std::sync::Arc;

/// Format version written by [`ObbTree::to_saved`].
const VERSION: u32 = 1;

/// One saved node (the tree's compact node, field for field).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
struct SavedNode {
    c: [f32; 3],
    h: [f32; 3],
    u: [[f32; 3]; 3],
    link: u32,
}

/// A built [`ObbTree`] in a serialisable form, without the mesh (save the mesh separately; a
/// digest of it is kept so loading can refuse another mesh).
///
/// ```
/// use std::sync::Arc;
/// use frcd_obb::{BuildOptions, ObbTree};
/// let mesh = Arc::new(frcd_geom::shapes::icosphere(1.0, 2));
/// let tree = ObbTree::build_shared(mesh.clone(), &BuildOptions::default());
/// let json = serde_json::to_string(&tree.to_saved()).unwrap();
/// let back = ObbTree::from_saved(serde_json::from_str(&json).unwrap(), mesh).unwrap();
/// assert_eq!(back.node_count(), tree.node_count());
/// ```
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SavedTree {
    version: u32,
    triangle_count: u64,
    mesh_digest: u64,
    nodes: Vec<SavedNode>,
    order: Vec<u32>,
    ends: Vec<u64>,
}

/// Why a [`SavedTree`] could not be loaded.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[non_exhaustive]
pub enum LoadError {
    /// Written by another format version.
    #[error("saved tree has format version {found}, this build reads {expected}")]
    Version {
        /// Version in the file.
        found: u32,
        /// Version this build reads.
        expected: u32,
    },
    /// The tree was built over a mesh with another triangle count.
    #[error("saved tree was built over {saved} triangles, the mesh has {mesh}")]
    TriangleCount {
        /// Triangles when saved.
        saved: u64,
        /// Triangles of the mesh given.
        mesh: u64,
    },
    /// Same triangle count, other vertices or indices.
    #[error("saved tree was built over another mesh (digest {saved:#018x}, mesh {mesh:#018x})")]
    MeshDigest {
        /// Digest when saved.
        saved: u64,
        /// Digest of the mesh given.
        mesh: u64,
    },
    /// The hierarchy is damaged: what is wrong and where.
    #[error("saved tree is damaged: {what} (at {index})")]
    Corrupt {
        /// What failed.
        what: &'static str,
        /// Node, leaf-order entry or word index.
        index: usize,
    },
}

/// FNV-1a over the mesh's vertex bits and indices.
fn digest(mesh: &TriMesh) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |x: u64| {
        for b in x.to_le_bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    eat(mesh.vertex_count() as u64);
    for v in mesh.vertices() {
        eat(v.x.to_bits());
        eat(v.y.to_bits());
        eat(v.z.to_bits());
    }
    for t in mesh.indices() {
        eat(t[0] as u64 | (t[1] as u64) << 32);
        eat(t[2] as u64);
    }
    h
}

impl ObbTree {
    /// The tree's hierarchy in a serialisable form (see [`SavedTree`]).
    pub fn to_saved(&self) -> SavedTree {
        SavedTree {
            version: VERSION,
            triangle_count: self.triangle_count() as u64,
            mesh_digest: digest(&self.mesh),
            nodes: self
                .nodes
                .iter()
                .map(|n| SavedNode {
                    c: n.c,
                    h: n.h,
                    u: n.u,
                    link: n.link,
                })
                .collect(),
            order: self.order.clone(),
            ends: self.ends.clone(),
        }
    }

    /// Loads a saved tree over `mesh`, which must be the mesh it was built over (checked by
    /// triangle count and digest); the structure is checked so that no query on the result can
    /// index out of range.
    pub fn from_saved(saved: SavedTree, mesh: Arc<TriMesh>) -> Result<ObbTree, LoadError> {
        if saved.version != VERSION {
            return Err(LoadError::Version {
                found: saved.version,
                expected: VERSION,
            });
        }
        let t = mesh.triangle_count();
        if saved.triangle_count != t as u64 {
            return Err(LoadError::TriangleCount {
                saved: saved.triangle_count,
                mesh: t as u64,
            });
        }
        let d = digest(&mesh);
        if saved.mesh_digest != d {
            return Err(LoadError::MeshDigest {
                saved: saved.mesh_digest,
                mesh: d,
            });
        }
        let corrupt = |what, index| Err(LoadError::Corrupt { what, index });
        // Leaf order: a permutation of the triangles.
        if saved.order.len() != t {
            return corrupt("leaf order length differs from the triangle count", 0);
        }
        let mut seen = vec![false; t];
        for (k, &x) in saved.order.iter().enumerate() {
            match seen.get_mut(x as usize) {
                Some(s) if !*s => *s = true,
                _ => return corrupt("leaf order entry out of range or repeated", k),
            }
        }
        // End bits: one word per 64 entries, the last entry ends a leaf, nothing beyond it.
        if saved.ends.len() != t.div_ceil(64).max(1) {
            return corrupt("leaf end bits have the wrong length", 0);
        }
        if t > 0 {
            let last = t - 1;
            if saved.ends[last / 64] >> (last % 64) & 1 == 0 {
                return corrupt("last leaf-order entry does not end a leaf", last);
            }
            let tail = saved.ends[last / 64] >> (last % 64) >> 1;
            if tail != 0 {
                return corrupt("leaf end bits beyond the triangle count", last / 64);
            }
        }
        // Nodes: finite boxes; children after their parent and inside the array; leaves start
        // inside the leaf order.
        let n = saved.nodes.len();
        if n == 0 {
            return corrupt("no nodes", 0);
        }
        let mut nodes = Vec::with_capacity(n);
        for (i, s) in saved.nodes.into_iter().enumerate() {
            let finite = s.c.iter().chain(&s.h).chain(s.u.iter().flatten());
            if !finite.clone().all(|x| x.is_finite()) || s.h.iter().any(|&x| x < 0.0) {
                return corrupt("non-finite or negative box", i);
            }
            // The SAT's slack assumes axes orthonormal to f32 precision (nodes.rs).
            if crate::nodes::gram_deviation(
                &s.u.map(|a| frcd_geom::DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64)),
            ) > crate::nodes::ETA
            {
                return corrupt("box axes not orthonormal", i);
            }
            let ok = if s.link & LEAF != 0 {
                ((s.link & !LEAF) as usize) < t
            } else {
                (s.link as usize) > i + 1 && (s.link as usize) < n
            };
            if !ok {
                return corrupt("child or leaf start out of range", i);
            }
            nodes.push(TNode {
                c: s.c,
                h: s.h,
                u: s.u,
                link: s.link,
            });
        }
        Ok(ObbTree::from_compact(mesh, nodes, saved.order, saved.ends))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BuildOptions, Mode, Request, collide};
    use frcd_geom::{DVec3, Pose, shapes};

    fn round_trip(s: &SavedTree) -> SavedTree {
        serde_json::from_str(&serde_json::to_string(s).unwrap()).unwrap()
    }

    #[test]
    fn a_loaded_tree_answers_as_the_built_one() {
        let mesh = Arc::new(shapes::icosphere(1.0, 3));
        let tree = ObbTree::build_shared(mesh.clone(), &BuildOptions::default());
        let back = ObbTree::from_saved(round_trip(&tree.to_saved()), mesh).unwrap();
        assert_eq!(back.to_saved(), tree.to_saved());
        let all = Request {
            mode: Mode::AllPairs,
            ..Request::default()
        };
        let pose = Pose::from_translation(DVec3::new(1.7, 0.1, 0.0));
        let x = collide(&tree, &Pose::IDENTITY, &tree, &pose, &all);
        let y = collide(&back, &Pose::IDENTITY, &back, &pose, &all);
        assert!(!x.pairs.is_empty());
        assert_eq!(x.pairs, y.pairs);
    }

    #[test]
    fn another_mesh_or_a_damaged_file_is_refused() {
        let mesh = Arc::new(shapes::icosphere(1.0, 3));
        let tree = ObbTree::build_shared(mesh.clone(), &BuildOptions::default());
        let saved = tree.to_saved();
        let other = Arc::new(shapes::icosphere(1.0, 2));
        assert!(matches!(
            ObbTree::from_saved(saved.clone(), other),
            Err(LoadError::TriangleCount { .. })
        ));
        let moved = Arc::new(shapes::icosphere(1.0 + 1e-12, 3));
        assert!(matches!(
            ObbTree::from_saved(saved.clone(), moved),
            Err(LoadError::MeshDigest { .. })
        ));
        let mut bad = saved.clone();
        bad.nodes[0].link = 0;
        assert!(matches!(
            ObbTree::from_saved(bad, mesh.clone()),
            Err(LoadError::Corrupt { index: 0, .. })
        ));
        let mut bad = saved.clone();
        bad.order[3] = bad.order[4];
        assert!(matches!(
            ObbTree::from_saved(bad, mesh.clone()),
            Err(LoadError::Corrupt { index: 4, .. })
        ));
        let mut bad = saved.clone();
        bad.nodes[5].h[1] = f32::NAN;
        assert!(matches!(
            ObbTree::from_saved(bad, mesh.clone()),
            Err(LoadError::Corrupt { index: 5, .. })
        ));
        let mut bad = saved;
        bad.version = 99;
        assert!(matches!(
            ObbTree::from_saved(bad, mesh),
            Err(LoadError::Version { found: 99, .. })
        ));
    }
}
