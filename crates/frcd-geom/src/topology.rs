use glam::DVec3;
#[cfg(test)]
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

    /// The report, in `O(n log n)` for `n` triangles whatever the input (sorts, no hashing: a
    /// crafted mesh cannot make it quadratic), without an allocation per vertex.
    pub(crate) fn compute(vertices: &[DVec3], indices: &[[u32; 3]]) -> Self {
        let mut t = Topology::default();
        let proper = |tri: &[u32; 3]| tri[0] != tri[1] && tri[1] != tri[2] && tri[0] != tri[2];
        // Every directed edge as a sortable pair: the undirected edge (lower index, higher
        // index: 32 bits each, so any u32 index) and its direction (a > b).
        let mut directed: Vec<(u64, bool)> = Vec::with_capacity(indices.len() * 3);
        for tri in indices {
            if !proper(tri) {
                t.index_degenerate += 1;
                continue;
            }
            for k in 0..3 {
                directed.push(edge_word(tri[k], tri[(k + 1) % 3]));
            }
        }
        directed.sort_unstable();
        let mut bad_vertex = vec![false; vertices.len()];
        for run in directed.chunk_by(|x, y| x.0 == y.0) {
            t.edges += 1;
            let (a, b) = edge_ends(run[0].0);
            let (a, b) = (a as usize, b as usize);
            match run.len() {
                1 => t.boundary_edges += 1,
                2 => {}
                _ => {
                    t.non_manifold_edges += 1;
                    bad_vertex[a] = true;
                    bad_vertex[b] = true;
                }
            }
            let backward = run.iter().filter(|x| x.1).count();
            let forward = run.len() - backward;
            t.orientation_conflicts += forward.saturating_sub(1) + backward.saturating_sub(1);
        }
        // Fans: around each vertex, link triangles that share an edge through the vertex. The
        // incident triangles of every vertex in one flat array (counts, then offsets).
        // usize: three entries per triangle can pass u32 on the largest meshes.
        let mut start = vec![0usize; vertices.len() + 1];
        for tri in indices.iter().filter(|tri| proper(tri)) {
            for &v in tri {
                start[v as usize + 1] += 1;
            }
        }
        for v in 0..vertices.len() {
            start[v + 1] += start[v];
        }
        let mut fill = start.clone();
        let mut incident = vec![0u32; start[vertices.len()]];
        for (i, tri) in indices.iter().enumerate() {
            if !proper(tri) {
                continue;
            }
            for &v in tri {
                incident[fill[v as usize]] = i as u32;
                fill[v as usize] += 1;
            }
        }
        // Reused by every vertex: (other vertex, position of the triangle in the fan).
        let mut by_other: Vec<(u32, u32)> = Vec::new();
        let mut parent: Vec<usize> = Vec::new();
        for v in 0..vertices.len() {
            let tris = &incident[start[v]..start[v + 1]];
            if tris.len() < 2 || bad_vertex[v] {
                continue;
            }
            // Union-find over the incident triangles, linked through their other vertices:
            // entries sorted by other vertex, neighbours in a run share an edge through `v`.
            fn find(p: &mut [usize], mut i: usize) -> usize {
                while p[i] != i {
                    p[i] = p[p[i]];
                    i = p[i];
                }
                i
            }
            parent.clear();
            parent.extend(0..tris.len());
            by_other.clear();
            for (k, &ti) in tris.iter().enumerate() {
                for &o in &indices[ti as usize] {
                    if o as usize != v {
                        by_other.push((o, k as u32));
                    }
                }
            }
            by_other.sort_unstable();
            for w in by_other.windows(2) {
                if w[0].0 == w[1].0 {
                    let (a, b) = (
                        find(&mut parent, w[0].1 as usize),
                        find(&mut parent, w[1].1 as usize),
                    );
                    parent[a] = b;
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
        t.components = component_vertices(vertices.len(), indices).len();
        t
    }

    /// The straightforward version [`Topology::compute`] replaced (hash maps, a list per
    /// vertex): the tests check both give the same report.
    #[cfg(test)]
    pub(crate) fn compute_reference(vertices: &[DVec3], indices: &[[u32; 3]]) -> Self {
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
        t.components = component_vertices(vertices.len(), indices).len();
        t
    }
}

/// The directed edge `a → b` as its undirected edge's sort key (lower index in the high 32
/// bits, higher in the low 32: distinct for any two u32 index pairs) and its direction.
fn edge_word(a: u32, b: u32) -> (u64, bool) {
    ((a.min(b) as u64) << 32 | a.max(b) as u64, a > b)
}

/// The (lower, higher) vertex indices of an [`edge_word`] key.
fn edge_ends(key: u64) -> (u32, u32) {
    ((key >> 32) as u32, key as u32)
}

/// The lowest-index vertex of each connected component of the used vertices (linked through
/// shared triangles, union-find), in index order: one entry per component.
pub(crate) fn component_vertices(vertex_count: usize, indices: &[[u32; 3]]) -> Vec<u32> {
    components(vertex_count, indices, None).0
}

/// [`component_vertices`], and per component (in the same order) its vertices of least and
/// greatest x, y and z: `[min x, max x, min y, max y, min z, max z]` (the lowest index on ties).
pub(crate) fn component_extremes(
    vertices: &[crate::DVec3],
    indices: &[[u32; 3]],
) -> (Vec<u32>, Vec<[u32; 6]>) {
    components(vertices.len(), indices, Some(vertices))
}

fn components(
    vertex_count: usize,
    indices: &[[u32; 3]],
    extremes_of: Option<&[crate::DVec3]>,
) -> (Vec<u32>, Vec<[u32; 6]>) {
    let mut parent: Vec<u32> = (0..vertex_count as u32).collect();
    fn root(p: &mut [u32], mut i: u32) -> u32 {
        while p[i as usize] != i {
            p[i as usize] = p[p[i as usize] as usize];
            i = p[i as usize];
        }
        i
    }
    let mut used = vec![false; vertex_count];
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
    // Each root's component number, in the order of the components' lowest vertices.
    let mut number = vec![u32::MAX; vertex_count];
    let mut out = Vec::new();
    let mut extremes: Vec<[u32; 6]> = Vec::new();
    for v in (0..vertex_count as u32).filter(|&v| used[v as usize]) {
        let r = root(&mut parent, v) as usize;
        if number[r] == u32::MAX {
            number[r] = out.len() as u32;
            out.push(v);
            if extremes_of.is_some() {
                extremes.push([v; 6]);
            }
        }
        if let Some(p) = extremes_of {
            let e = &mut extremes[number[r] as usize];
            let at = p[v as usize].to_array();
            for axis in 0..3 {
                // Strict comparisons: the lowest index wins a tie (vertices come in order).
                if at[axis] < p[e[2 * axis] as usize][axis] {
                    e[2 * axis] = v;
                }
                if at[axis] > p[e[2 * axis + 1] as usize][axis] {
                    e[2 * axis + 1] = v;
                }
            }
        }
    }
    (out, extremes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Edge keys are exact over the whole u32 range (a first version packed the direction
    /// into the key and lost the top bit of indices from 2^31 on).
    #[test]
    fn edge_words_are_distinct_and_decode_over_the_whole_index_range() {
        let big = [
            0,
            1,
            (1 << 31) - 1,
            1 << 31,
            (1 << 31) + 1,
            u32::MAX - 1,
            u32::MAX,
        ];
        let mut keys = std::collections::HashSet::new();
        for &a in &big {
            for &b in &big {
                let (key, backward) = edge_word(a, b);
                assert_eq!(edge_ends(key), (a.min(b), a.max(b)));
                assert_eq!(backward, a > b);
                assert_eq!(edge_word(b, a).0, key, "one key per undirected edge");
                keys.insert(key);
            }
        }
        assert_eq!(keys.len(), big.len() * (big.len() + 1) / 2);
    }

    /// The sort-based report equals the hash-map one on soups with every kind of defect
    /// (repeated and flipped triangles, index-degenerate ones, fans pinched at a vertex, many
    /// components), drawn from a small vertex set so that edges repeat often.
    #[test]
    fn sorted_report_equals_the_hash_map_report() {
        let mut x = 0x2545_F491_4F6C_DD1Du64;
        let mut next = |m: u32| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x % m as u64) as u32
        };
        for case in 0..400 {
            let nv = 4 + next(40);
            let vertices: Vec<DVec3> = (0..nv).map(|i| DVec3::splat(i as f64)).collect();
            let nt = next(120);
            let mut indices: Vec<[u32; 3]> =
                (0..nt).map(|_| [next(nv), next(nv), next(nv)]).collect();
            if case % 3 == 0 {
                // A closed, oriented shape's triangles too (a tetrahedron), maybe flipped.
                let tet = [[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]];
                indices.extend(tet.iter().map(|t| {
                    if case % 2 == 0 {
                        *t
                    } else {
                        [t[0], t[2], t[1]]
                    }
                }));
            }
            assert_eq!(
                Topology::compute(&vertices, &indices),
                Topology::compute_reference(&vertices, &indices),
                "case {case}: {indices:?}"
            );
        }
        // A bowtie (two fans at vertex 0) and a closed tetrahedron, exactly.
        let v: Vec<DVec3> = (0..5).map(|i| DVec3::splat(i as f64)).collect();
        let bowtie = Topology::compute(&v, &[[0, 1, 2], [0, 3, 4]]);
        assert_eq!(
            (
                bowtie.non_manifold_vertices,
                bowtie.boundary_edges,
                bowtie.edges
            ),
            (1, 6, 6)
        );
        let tet = Topology::compute(&v, &[[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]]);
        assert!(tet.is_closed_oriented_manifold() && tet.edges == 6 && tet.components == 1);
        let flipped = Topology::compute(&v, &[[0, 1, 2], [0, 1, 3], [1, 3, 2], [2, 3, 0]]);
        // One face flipped: each of its three edges runs the same way in both its triangles.
        assert!(flipped.is_closed() && flipped.orientation_conflicts == 3);
    }
}
