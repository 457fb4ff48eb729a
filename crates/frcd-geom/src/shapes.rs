//! Procedural closed meshes with outward normals, for tests, benches and demos.
//!
//! Every shape here is a closed, consistently oriented 2-manifold with positive signed volume
//! (tested). Sizes are in the caller's units; shapes are centred on the origin unless stated.

use crate::TriMesh;
use glam::DVec3;
use std::collections::HashMap;

fn build(vertices: Vec<DVec3>, indices: Vec<[u32; 3]>) -> TriMesh {
    TriMesh::new(vertices, indices).expect("procedural shapes are valid by construction")
}

/// An axis-aligned box centred on the origin with the given half extents (12 triangles).
///
/// ```
/// let b = frcd_geom::shapes::cuboid(frcd_geom::DVec3::new(1.0, 2.0, 3.0));
/// assert_eq!(b.triangle_count(), 12);
/// assert!((b.signed_volume() - 48.0).abs() < 1e-12);
/// ```
pub fn cuboid(half: DVec3) -> TriMesh {
    let v: Vec<DVec3> = (0..8)
        .map(|i| {
            DVec3::new(
                if i & 1 == 0 { -half.x } else { half.x },
                if i & 2 == 0 { -half.y } else { half.y },
                if i & 4 == 0 { -half.z } else { half.z },
            )
        })
        .collect();
    let idx = vec![
        [0, 2, 1],
        [1, 2, 3], // -z
        [4, 5, 6],
        [5, 7, 6], // +z
        [0, 1, 4],
        [1, 5, 4], // -y
        [2, 6, 3],
        [3, 6, 7], // +y
        [0, 4, 2],
        [2, 4, 6], // -x
        [1, 3, 5],
        [3, 7, 5], // +x
    ];
    build(v, idx)
}

/// A geodesic sphere: an icosahedron subdivided `level` times (each level splits every triangle
/// into four), vertices projected on the sphere. `20 · 4^level` triangles.
///
/// ```
/// let s = frcd_geom::shapes::icosphere(2.0, 3);
/// assert_eq!(s.triangle_count(), 20 * 64);
/// ```
pub fn icosphere(radius: f64, level: u32) -> TriMesh {
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<DVec3> = [
        (-1.0, phi, 0.0),
        (1.0, phi, 0.0),
        (-1.0, -phi, 0.0),
        (1.0, -phi, 0.0),
        (0.0, -1.0, phi),
        (0.0, 1.0, phi),
        (0.0, -1.0, -phi),
        (0.0, 1.0, -phi),
        (phi, 0.0, -1.0),
        (phi, 0.0, 1.0),
        (-phi, 0.0, -1.0),
        (-phi, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| DVec3::new(x, y, z).normalize())
    .collect();
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut next = Vec::with_capacity(f.len() * 4);
        let mut midpoint = |a: u32, b: u32, v: &mut Vec<DVec3>| -> u32 {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                v.push((v[a as usize] + v[b as usize]).normalize());
                (v.len() - 1) as u32
            })
        };
        for [a, b, c] in f {
            let ab = midpoint(a, b, &mut v);
            let bc = midpoint(b, c, &mut v);
            let ca = midpoint(c, a, &mut v);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = next;
    }
    for p in &mut v {
        *p *= radius;
    }
    build(v, f)
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn assert_solid(m: &TriMesh) {
        let t = m.topology();
        assert!(t.is_closed_oriented_manifold(), "{t:?}");
        assert!(
            m.report().degenerate.is_empty(),
            "degenerate: {:?}",
            m.report().degenerate
        );
        assert!(m.report().duplicates.is_empty());
        assert!(m.signed_volume() > 0.0, "normals point inward");
    }

    #[test]
    fn cuboid_is_solid() {
        let b = cuboid(DVec3::new(1.0, 2.0, 3.0));
        assert_solid(&b);
        assert_eq!(b.topology().components, 1);
    }

    #[test]
    fn icosphere_is_solid_and_round() {
        for level in 0..4 {
            let s = icosphere(3.0, level);
            assert_solid(&s);
            assert_eq!(s.triangle_count(), 20 * 4usize.pow(level));
            for p in s.vertices() {
                assert!((p.length() - 3.0).abs() < 1e-12);
            }
        }
        let v = icosphere(1.0, 5).signed_volume();
        let exact = 4.0 / 3.0 * std::f64::consts::PI;
        assert!(v < exact && v > 0.99 * exact, "{v}");
    }
}
