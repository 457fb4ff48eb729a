use glam::DVec3;
use std::collections::HashMap;

/// Topology of an indexed triangle mesh, on its vertex indices (weld first for STL).
///
/// - *closed*: every edge has exactly two incident triangles;
/// - *manifold*: every edge has at most two incident triangles and every vertex's incident
///   triangles form a single fan;
/// - *oriented*: no directed edge occurs twice (neighbours agree on orientation).
///
/// Ray-parity tests (point in mesh, image space) need [`Topology::is_closed_oriented_manifold`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Topology {
    /// Undirected edges.
    pub edges: usize,
    /// Edges with one incident triangle.
    pub boundary_edges: usize,
    /// Edges with three or more incident triangles.
    pub non_manifold_edges: usize,
    /// Vertices whose incident triangles form more than one fan (or that touch a non-manifold edge).
    pub non_manifold_vertices: usize,
    /// Directed edges that occur more than once (orientation conflicts).
    pub orientation_conflicts: usize,
    /// Connected components (triangles connected through shared vertices).
    pub components: usize,
    /// Triangles that repeat a vertex index (they have no proper edges).
    pub index_degenerate: usize,
}

impl Topology {
    /// True when no edge is a boundary edge and every edge is shared by exactly two triangles.
    pub fn is_closed(&self) -> bool {
        self.boundary_edges == 0 && self.non_manifold_edges == 0 && self.index_degenerate == 0
    }

    /// True when every edge and vertex is manifold.
    pub fn is_manifold(&self) -> bool {
        self.non_manifold_edges == 0
            && self.non_manifold_vertices == 0
            && self.index_degenerate == 0
    }

    /// True when neighbouring triangles agree on orientation.
    pub fn is_oriented(&self) -> bool {
        self.orientation_conflicts == 0
    }

    /// Closed, manifold and consistently oriented: a proper solid boundary (up to
    /// self-intersection, which topology cannot see).
    pub fn is_closed_oriented_manifold(&self) -> bool {
        self.is_closed() && self.is_manifold() && self.is_oriented()
    }

    pub(crate) fn compute(vertices: &[DVec3], indices: &[[u32; 3]]) -> Self {
        let mut t = Topology::default();
        // Undirected edge -> (count, directed count a<b, directed count a>b)
        let mut edges: HashMap<(u32, u32), [u32; 3]> =
            HashMap::with_capacity(indices.len() * 3 / 2);
        for tri in indices {
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                t.index_degenerate += 1;
                continue;
            }
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                let e = edges.entry((a.min(b), a.max(b))).or_insert([0; 3]);
                e[0] += 1;
                e[if a < b { 1 } else { 2 }] += 1;
            }
        }
        t.edges = edges.len();
        let mut bad_vertex = vec![false; vertices.len()];
        for (&(a, b), c) in &edges {
            match c[0] {
                1 => t.boundary_edges += 1,
                2 => {}
                _ => {
                    t.non_manifold_edges += 1;
                    bad_vertex[a as usize] = true;
                    bad_vertex[b as usize] = true;
                }
            }
            t.orientation_conflicts += (c[1].saturating_sub(1) + c[2].saturating_sub(1)) as usize;
        }
        // Fans: around each vertex, link triangles that share an edge through the vertex.
        let mut incident: Vec<Vec<u32>> = vec![Vec::new(); vertices.len()];
        for (i, tri) in indices.iter().enumerate() {
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                continue;
            }
            for &v in tri {
                incident[v as usize].push(i as u32);
            }
        }
        for (v, tris) in incident.iter().enumerate() {
            if tris.len() < 2 || bad_vertex[v] {
                continue;
            }
            // Union-find over the incident triangles by their other vertices.
            let mut parent: Vec<usize> = (0..tris.len()).collect();
            fn find(p: &mut [usize], mut i: usize) -> usize {
                while p[i] != i {
                    p[i] = p[p[i]];
                    i = p[i];
                }
                i
            }
            let mut by_other: HashMap<u32, usize> = HashMap::new();
            for (k, &ti) in tris.iter().enumerate() {
                for &o in &indices[ti as usize] {
                    if o as usize == v {
                        continue;
                    }
                    if let Some(&j) = by_other.get(&o) {
                        let (a, b) = (find(&mut parent, k), find(&mut parent, j));
                        parent[a] = b;
                    } else {
                        by_other.insert(o, k);
                    }
                }
            }
            let roots = (0..tris.len())
                .filter(|&k| find(&mut parent, k) == k)
                .count();
            if roots > 1 {
                bad_vertex[v] = true;
            }
        }
        t.non_manifold_vertices = bad_vertex.iter().filter(|b| **b).count();
        // Components through shared vertices.
        let mut parent: Vec<u32> = (0..vertices.len() as u32).collect();
        fn root(p: &mut [u32], mut i: u32) -> u32 {
            while p[i as usize] != i {
                p[i as usize] = p[p[i as usize] as usize];
                i = p[i as usize];
            }
            i
        }
        let mut used = vec![false; vertices.len()];
        for tri in indices {
            for &v in tri {
                used[v as usize] = true;
            }
            let r0 = root(&mut parent, tri[0]);
            for &v in &tri[1..] {
                let r = root(&mut parent, v);
                if r != r0 {
                    parent[r as usize] = r0;
                }
            }
        }
        t.components = (0..vertices.len() as u32)
            .filter(|&v| used[v as usize] && root(&mut parent, v) == v)
            .count();
        t
    }
}
