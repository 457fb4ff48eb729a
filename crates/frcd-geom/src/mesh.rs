use crate::{Aabb, Topology, Triangle, predicates};
use glam::DVec3;
use std::collections::HashMap;
use std::sync::OnceLock;

/// Why a mesh was refused. Each variant names the offending element.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MeshError {
    /// The mesh has no triangles (or no vertices).
    #[error("empty mesh: {vertices} vertices, {triangles} triangles")]
    Empty {
        /// Number of vertices given.
        vertices: usize,
        /// Number of triangles given.
        triangles: usize,
    },
    /// A vertex coordinate is NaN or infinite.
    #[error("vertex {vertex} has a non-finite coordinate: {value:?}")]
    NonFiniteVertex {
        /// Index of the vertex.
        vertex: usize,
        /// The vertex as given.
        value: [f64; 3],
    },
    /// A triangle refers to a vertex that does not exist.
    #[error(
        "triangle {triangle}, corner {corner}: index {index} out of range (mesh has {vertex_count} vertices)"
    )]
    IndexOutOfRange {
        /// Index of the triangle.
        triangle: usize,
        /// Which corner (0, 1, 2).
        corner: usize,
        /// The bad index.
        index: u32,
        /// Number of vertices.
        vertex_count: usize,
    },
    /// More vertices or triangles than 32-bit indices can address.
    #[error("too many elements: {what} = {count} exceeds u32")]
    TooLarge {
        /// "vertices" or "triangles".
        what: &'static str,
        /// The count given.
        count: usize,
    },
}

/// What validation found that does not make a mesh unusable, reported rather than dropped.
#[derive(Clone, Debug, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MeshReport {
    /// Triangles of exactly zero area (collinear or repeated vertices), by index.
    pub degenerate: Vec<u32>,
    /// Pairs `(first, later)` of triangles with the same three vertex indices (any order).
    pub duplicates: Vec<(u32, u32)>,
    /// Vertices no triangle refers to.
    pub unreferenced_vertices: usize,
}

impl MeshReport {
    /// True when nothing was found.
    pub fn is_clean(&self) -> bool {
        self.degenerate.is_empty() && self.duplicates.is_empty() && self.unreferenced_vertices == 0
    }
}

/// A validated indexed triangle mesh (f64 vertices, `u32` indices).
///
/// Construction checks every index and coordinate and returns a typed [`MeshError`]; degenerate and
/// duplicate triangles are kept and listed in [`TriMesh::report`]. The topology report is computed
/// on first use and cached.
///
/// ```
/// use frcd_geom::{TriMesh, MeshError, DVec3};
/// let v = vec![DVec3::ZERO, DVec3::X, DVec3::Y];
/// let mesh = TriMesh::new(v.clone(), vec![[0, 1, 2]]).unwrap();
/// assert_eq!(mesh.triangle_count(), 1);
/// assert!(matches!(TriMesh::new(v, vec![[0, 1, 3]]),
///     Err(MeshError::IndexOutOfRange { triangle: 0, corner: 2, index: 3, .. })));
/// ```
#[derive(Debug)]
pub struct TriMesh {
    vertices: Vec<DVec3>,
    indices: Vec<[u32; 3]>,
    report: MeshReport,
    aabb: Aabb,
    topology: OnceLock<Topology>,
}

impl Clone for TriMesh {
    fn clone(&self) -> Self {
        Self {
            vertices: self.vertices.clone(),
            indices: self.indices.clone(),
            report: self.report.clone(),
            aabb: self.aabb,
            topology: self.topology.clone(),
        }
    }
}

impl TriMesh {
    /// Validates and builds a mesh. Vertices are used as given (no welding): see
    /// [`TriMesh::from_triangle_soup`] and [`TriMesh::welded`] for that.
    pub fn new(vertices: Vec<DVec3>, indices: Vec<[u32; 3]>) -> Result<Self, MeshError> {
        if vertices.is_empty() || indices.is_empty() {
            return Err(MeshError::Empty {
                vertices: vertices.len(),
                triangles: indices.len(),
            });
        }
        if vertices.len() > u32::MAX as usize {
            return Err(MeshError::TooLarge {
                what: "vertices",
                count: vertices.len(),
            });
        }
        if indices.len() > u32::MAX as usize {
            return Err(MeshError::TooLarge {
                what: "triangles",
                count: indices.len(),
            });
        }
        if let Some((i, p)) = vertices.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(MeshError::NonFiniteVertex {
                vertex: i,
                value: p.to_array(),
            });
        }
        let n = vertices.len();
        for (t, tri) in indices.iter().enumerate() {
            for (corner, &index) in tri.iter().enumerate() {
                if index as usize >= n {
                    return Err(MeshError::IndexOutOfRange {
                        triangle: t,
                        corner,
                        index,
                        vertex_count: n,
                    });
                }
            }
        }
        let report = Self::inspect(&vertices, &indices);
        let aabb = Aabb::from_points(vertices.iter());
        Ok(Self {
            vertices,
            indices,
            report,
            aabb,
            topology: OnceLock::new(),
        })
    }

    /// Validates and builds a mesh from an engine's f32 data, borrowed: `glam::Vec3` or
    /// `[f32; 3]` positions and `[u32; 3]` triangles.
    ///
    /// Each coordinate is widened to f64 straight into the mesh's own storage (one allocation,
    /// no intermediate `Vec<DVec3>`); widening is exact, so the mesh holds exactly the engine's
    /// points. Validation and errors are those of [`TriMesh::new`], with the same indices:
    /// a NaN or infinite coordinate is [`MeshError::NonFiniteVertex`] naming the vertex, a bad
    /// index is [`MeshError::IndexOutOfRange`] naming the triangle and corner.
    ///
    /// An engine with a flat `&[f32]` (x, y, z, x, ...) or `&[u32]` buffer can view it as
    /// `&[[f32; 3]]` / `&[[u32; 3]]` without copying (e.g. `bytemuck::cast_slice`).
    ///
    /// ```
    /// use frcd_geom::{MeshError, TriMesh};
    /// use glam::Vec3;
    /// let engine_vertices = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
    /// let engine_indices = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
    /// let mesh = TriMesh::from_f32(&engine_vertices, &engine_indices)?;
    /// assert!(mesh.topology().is_closed_oriented_manifold());
    /// assert_eq!(mesh.vertices()[1].x, 1.0);
    ///
    /// // Plain arrays work the same; 0.1f32 is kept exactly (not rounded to 0.1f64).
    /// let arrays = [[0.0f32, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 1.0, f32::NAN]];
    /// assert!(matches!(TriMesh::from_f32(&arrays, &[[0, 1, 2]]),
    ///     Err(MeshError::NonFiniteVertex { vertex: 2, .. })));
    /// let ok = TriMesh::from_f32(&arrays[..2], &[[0, 1, 1]]).map(|m| m.vertices()[1].x);
    /// assert_eq!(ok, Ok(f64::from(0.1f32)));
    /// # Ok::<(), MeshError>(())
    /// ```
    pub fn from_f32<P>(vertices: &[P], indices: &[[u32; 3]]) -> Result<Self, MeshError>
    where
        P: Copy + Into<[f32; 3]>,
    {
        // Counts first, so a refused mesh allocates nothing.
        if vertices.is_empty() || indices.is_empty() {
            return Err(MeshError::Empty {
                vertices: vertices.len(),
                triangles: indices.len(),
            });
        }
        let widened: Vec<DVec3> = vertices
            .iter()
            .map(|&p| {
                let [x, y, z] = p.into();
                DVec3::new(f64::from(x), f64::from(y), f64::from(z))
            })
            .collect();
        // `new` runs the one validation path; f32 -> f64 keeps NaN and infinities, so the
        // errors name the same vertex the caller passed.
        Self::new(widened, indices.to_vec())
    }

    /// Bytes this mesh holds on the heap plus its own size: vertices (24 B each), triangles
    /// (12 B each) and the validation report. About 24 B per triangle for a closed mesh
    /// (half as many vertices as triangles).
    ///
    /// ```
    /// use frcd_geom::{TriMesh, DVec3};
    /// let m = TriMesh::new(vec![DVec3::ZERO, DVec3::X, DVec3::Y], vec![[0, 1, 2]]).unwrap();
    /// assert!(m.memory_bytes() >= 3 * 24 + 12);
    /// ```
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.vertices.capacity() * std::mem::size_of::<DVec3>()
            + self.indices.capacity() * std::mem::size_of::<[u32; 3]>()
            + self.report.degenerate.capacity() * std::mem::size_of::<u32>()
            + self.report.duplicates.capacity() * std::mem::size_of::<(u32, u32)>()
    }

    fn inspect(vertices: &[DVec3], indices: &[[u32; 3]]) -> MeshReport {
        let mut report = MeshReport::default();
        let mut seen: HashMap<[u32; 3], u32> = HashMap::with_capacity(indices.len());
        let mut used = vec![false; vertices.len()];
        for (t, tri) in indices.iter().enumerate() {
            let [a, b, c] = tri.map(|i| vertices[i as usize]);
            if predicates::collinear3(a, b, c) {
                report.degenerate.push(t as u32);
            }
            let mut key = *tri;
            key.sort_unstable();
            if let Some(&first) = seen.get(&key) {
                report.duplicates.push((first, t as u32));
            } else {
                seen.insert(key, t as u32);
            }
            for &i in tri {
                used[i as usize] = true;
            }
        }
        report.unreferenced_vertices = used.iter().filter(|u| !**u).count();
        report
    }

    /// Builds a mesh from unindexed triangles (STL), welding vertices with bit-identical
    /// coordinates (`-0.0` and `0.0` are the same point).
    ///
    /// ```
    /// use frcd_geom::{TriMesh, DVec3};
    /// let (a, b, c, d) = (DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z);
    /// let m = TriMesh::from_triangle_soup(&[[a, b, c], [a, c, d]]).unwrap();
    /// assert_eq!(m.vertex_count(), 4);
    /// ```
    ///
    /// A non-finite coordinate is reported as [`MeshError::NonFiniteVertex`] with
    /// `vertex = 3 · triangle + corner`, the position in the soup.
    pub fn from_triangle_soup(triangles: &[[DVec3; 3]]) -> Result<Self, MeshError> {
        for (t, tri) in triangles.iter().enumerate() {
            for (k, p) in tri.iter().enumerate() {
                if !p.is_finite() {
                    return Err(MeshError::NonFiniteVertex {
                        vertex: 3 * t + k,
                        value: p.to_array(),
                    });
                }
            }
        }
        let mut map: HashMap<[u64; 3], u32> = HashMap::with_capacity(triangles.len());
        let mut vertices = Vec::new();
        let mut indices = Vec::with_capacity(triangles.len());
        for tri in triangles {
            let mut idx = [0u32; 3];
            for (k, p) in tri.iter().enumerate() {
                let key = position_key(*p);
                idx[k] = *map.entry(key).or_insert_with(|| {
                    vertices.push(*p);
                    (vertices.len() - 1) as u32
                });
            }
            indices.push(idx);
        }
        Self::new(vertices, indices)
    }

    /// A copy with vertices closer than `tolerance` (Euclidean, transitively) merged into one, and
    /// unreferenced vertices dropped. `tolerance = 0` (or negative, or NaN) merges bit-identical
    /// positions only. A merged cluster takes the position of its lowest-index vertex.
    /// Triangles are kept (a triangle may become degenerate; the report says so).
    pub fn welded(&self, tolerance: f64) -> Self {
        let n = self.vertices.len();
        let mut parent: Vec<u32> = (0..n as u32).collect();
        fn find(p: &mut [u32], mut i: u32) -> u32 {
            while p[i as usize] != i {
                p[i as usize] = p[p[i as usize] as usize];
                i = p[i as usize];
            }
            i
        }
        if tolerance > 0.0 {
            // Grid cells at least `tolerance` wide, and wide enough that cell coordinates stay
            // below 2^30 (so the division's rounding is far below one cell); the 2^-20 margin
            // keeps two points within `tolerance` in the same or adjacent cells despite that
            // rounding.
            let max_abs = self
                .vertices
                .iter()
                .fold(0.0f64, |m, p| m.max(p.abs().max_element()));
            let cell = tolerance.max(max_abs * (-30f64).exp2()) * (1.0 + (-20f64).exp2());
            let key = |p: DVec3| {
                let k = (p / cell).floor();
                // |k| <= 2^30 unless the tolerance is infinite (then every vertex is in cell 0).
                [k.x, k.y, k.z].map(|x| if x.is_finite() { x as i64 } else { 0 })
            };
            let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
            for (i, p) in self.vertices.iter().enumerate() {
                grid.entry(key(*p)).or_default().push(i as u32);
            }
            let t2 = tolerance * tolerance;
            for (i, p) in self.vertices.iter().enumerate() {
                let k = key(*p);
                for dx in -1..=1 {
                    for dy in -1..=1 {
                        for dz in -1..=1 {
                            if let Some(list) = grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                                for &j in list {
                                    if (j as usize) > i
                                        && self.vertices[j as usize].distance_squared(*p) <= t2
                                    {
                                        let (a, b) =
                                            (find(&mut parent, i as u32), find(&mut parent, j));
                                        if a != b {
                                            parent[a.max(b) as usize] = a.min(b);
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
            }
        } else {
            let mut map: HashMap<[u64; 3], u32> = HashMap::new();
            for (i, p) in self.vertices.iter().enumerate() {
                let first = *map.entry(position_key(*p)).or_insert(i as u32);
                parent[i] = first;
            }
        }
        let mut remap = vec![u32::MAX; n];
        let mut vertices = Vec::new();
        let indices: Vec<[u32; 3]> = self
            .indices
            .iter()
            .map(|tri| {
                tri.map(|i| {
                    let root = find(&mut parent, i) as usize;
                    if remap[root] == u32::MAX {
                        remap[root] = vertices.len() as u32;
                        vertices.push(self.vertices[root]);
                    }
                    remap[root]
                })
            })
            .collect();
        Self::new(vertices, indices).expect("welding a valid mesh keeps it valid")
    }

    /// The vertices.
    #[inline]
    pub fn vertices(&self) -> &[DVec3] {
        &self.vertices
    }

    /// The triangles as vertex-index triples.
    #[inline]
    pub fn indices(&self) -> &[[u32; 3]] {
        &self.indices
    }

    /// Number of vertices.
    #[inline]
    pub fn vertex_count(&self) -> usize {
        self.vertices.len()
    }

    /// Number of triangles.
    #[inline]
    pub fn triangle_count(&self) -> usize {
        self.indices.len()
    }

    /// Triangle `i` with its vertex positions. Panics if `i` is out of range (a programming
    /// error: indices come from this mesh).
    #[inline]
    pub fn triangle(&self, i: usize) -> Triangle {
        let [a, b, c] = self.indices[i];
        Triangle::new(
            self.vertices[a as usize],
            self.vertices[b as usize],
            self.vertices[c as usize],
        )
    }

    /// All triangles with positions.
    pub fn triangles(&self) -> impl ExactSizeIterator<Item = Triangle> + '_ {
        (0..self.indices.len()).map(|i| self.triangle(i))
    }

    /// What validation found (degenerate, duplicate triangles; unreferenced vertices).
    #[inline]
    pub fn report(&self) -> &MeshReport {
        &self.report
    }

    /// The axis-aligned box of the vertices.
    #[inline]
    pub fn aabb(&self) -> Aabb {
        self.aabb
    }

    /// The topology report (computed once, then cached).
    pub fn topology(&self) -> &Topology {
        self.topology
            .get_or_init(|| Topology::compute(&self.vertices, &self.indices))
    }

    /// The lowest-index vertex of each connected component (triangles linked through shared
    /// vertices), in index order: one vertex per component, unused vertices in none.
    ///
    /// ```
    /// use frcd_geom::{DVec3, shapes::icosphere};
    /// let a = icosphere(1.0, 1);
    /// let b = a.transformed(&frcd_geom::Pose::from_translation(DVec3::X * 5.0));
    /// let both = frcd_geom::shapes::merge(&[a.clone(), b]).unwrap();
    /// assert_eq!(both.component_vertices().len(), 2);
    /// assert_eq!(both.component_vertices()[0], 0);
    /// ```
    pub fn component_vertices(&self) -> Vec<u32> {
        crate::topology::component_vertices(self.vertices.len(), &self.indices)
    }

    /// Per connected component, in [`TriMesh::component_vertices`]' order: its lowest-index
    /// vertex (that method's entry) and its vertices of least and greatest coordinate on each
    /// axis, `[min x, max x, min y, max y, min z, max z]` (vertex indices, the lowest on ties).
    /// Every point of a component's surface lies in the box the extremes span, and each face of
    /// that box holds one of them; so a component with one of them outside a convex region is
    /// not inside it. One pass over the mesh gives both.
    ///
    /// ```
    /// use frcd_geom::{shapes::{icosphere, merge}, DVec3, Pose};
    /// let a = icosphere(1.0, 1);
    /// let b = a.transformed(&Pose::from_translation(DVec3::X * 5.0));
    /// let both = merge(&[a, b]).unwrap();
    /// let ext = both.component_extremes();
    /// assert_eq!(ext.len(), 2);
    /// assert_eq!(ext.iter().map(|e| e.0).collect::<Vec<_>>(), both.component_vertices());
    /// let v = both.vertices();
    /// assert_eq!(v[ext[0].1[1] as usize].x, 1.0); // the first sphere's greatest x
    /// assert_eq!(v[ext[1].1[0] as usize].x, 4.0); // the second's least x
    /// ```
    pub fn component_extremes(&self) -> Vec<(u32, [u32; 6])> {
        let (lowest, extremes) = crate::topology::component_extremes(&self.vertices, &self.indices);
        lowest.into_iter().zip(extremes).collect()
    }

    /// Signed volume by the divergence theorem (positive for a closed mesh with outward normals).
    pub fn signed_volume(&self) -> f64 {
        // Relative to the box centre to limit cancellation for large offsets.
        let o = self.aabb.center();
        self.triangles()
            .map(|t| (t.v[0] - o).dot((t.v[1] - o).cross(t.v[2] - o)))
            .sum::<f64>()
            / 6.0
    }

    /// A copy with every vertex mapped by `pose`.
    ///
    /// # Panics
    /// When a mapped vertex is not finite (a non-finite pose, or coordinates overflowing near
    /// `f64::MAX`); use [`TriMesh::try_transformed`] for untrusted poses.
    pub fn transformed(&self, pose: &crate::Pose) -> Self {
        self.try_transformed(pose)
            .expect("a finite rigid map keeps a valid mesh valid")
    }

    /// A copy with every vertex mapped by `pose`, or [`MeshError::NonFiniteVertex`] naming the
    /// first vertex whose image is not finite.
    pub fn try_transformed(&self, pose: &crate::Pose) -> Result<Self, MeshError> {
        let v: Vec<DVec3> = self
            .vertices
            .iter()
            .map(|p| pose.transform_point(*p))
            .collect();
        Self::new(v, self.indices.clone())
    }
}

/// Hash key of a position: the bit patterns, with -0.0 folded to 0.0.
fn position_key(p: DVec3) -> [u64; 3] {
    p.to_array()
        .map(|x| if x == 0.0 { 0u64 } else { x.to_bits() })
}
