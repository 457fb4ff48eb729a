//! Fitting oriented bounding boxes to triangles.
//!
//! Three rules choose the axes; the extents always come from projecting every vertex on them
//! ([`Obb::from_points_with_axes`]), so the box holds the triangles whatever the axes.
//!
//! - [`FitMethod::VertexCovariance`]: eigenvectors of the covariance of the 3n triangle vertices
//!   (PQP's default);
//! - [`FitMethod::AreaWeighted`]: the area-weighted covariance of the triangles themselves
//!   (RAPID 2), insensitive to uneven tessellation;
//! - [`FitMethod::HullSurface`]: the same moments over the convex hull's surface (the OBBTree
//!   paper), insensitive to interior vertices too.

use crate::{Obb, Triangle};
use glam::{DMat3, DVec3};

/// How to choose an OBB's axes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum FitMethod {
    /// Covariance of the vertices (PQP).
    #[default]
    VertexCovariance,
    /// Area-weighted covariance of the triangles (RAPID 2).
    AreaWeighted,
    /// Area-weighted covariance of the convex hull surface (Gottschalk et al. 1996).
    HullSurface,
}

/// Fits an OBB to triangles with the given rule. Falls back to the vertex covariance when a rule
/// has no area to weigh (all triangles degenerate) and, for [`FitMethod::HullSurface`], to the
/// area-weighted rule when the hull cannot be built (non-finite input); to world axes when the
/// covariance is singular in every direction. The box always holds every vertex
/// ([`Obb::from_points_with_axes`]).
///
/// ```
/// use frcd_geom::{fit::{fit_obb, FitMethod}, shapes, Pose, DVec3, DQuat};
/// let mesh = shapes::cuboid(DVec3::new(3.0, 1.0, 0.5))
///     .transformed(&Pose::new(DVec3::ZERO, DQuat::from_rotation_z(0.3)));
/// let tris: Vec<_> = mesh.triangles().collect();
/// let obb = fit_obb(&tris, FitMethod::AreaWeighted);
/// assert!(tris.iter().all(|t| t.v.iter().all(|p| obb.contains_point(*p))));
/// assert!((obb.volume() - 12.0).abs() < 1e-9);
/// ```
pub fn fit_obb(triangles: &[Triangle], method: FitMethod) -> Obb {
    // Streamed, not collected: tree builds call this once per node, and copying every node's
    // vertices into a fresh Vec cost more than the fit itself.
    let points = || triangles.iter().flat_map(|t| t.v);
    let axes = match method {
        FitMethod::VertexCovariance => covariance_axes_of(points()),
        FitMethod::AreaWeighted => area_weighted_axes(triangles),
        FitMethod::HullSurface => hull_surface_axes(&points().collect::<Vec<_>>()),
    };
    Obb::from_point_iter_with_axes(points(), axes)
}

/// A reference point for conditioning: the centre of the points' bounding box (`ZERO` for none).
fn local_centre(points: impl Iterator<Item = DVec3>) -> DVec3 {
    let b = points.fold(crate::Aabb::EMPTY, |b, p| b.grown(p));
    if b.is_empty() || !b.min.is_finite() || !b.max.is_finite() {
        DVec3::ZERO
    } else {
        b.center()
    }
}

/// The area-weighted covariance of the surface made of `triangles` (RAPID 2 / OBBTree moments),
/// `C_ij = Σ_k (A_k/12)(9 m_i m_j + p_i p_j + q_i q_j + r_i r_j) / A − μ_i μ_j` with `A = Σ A_k`,
/// `μ = Σ A_k m_k / A`: the exact second central moment of the surface with uniform density.
/// Moments are taken relative to a local centre (the bounding-box centre) so large offsets cost
/// no precision. `None` when the total area is zero or not finite.
pub fn area_weighted_covariance(triangles: &[Triangle]) -> Option<DMat3> {
    let o = local_centre(triangles.iter().flat_map(|t| t.v));
    let mut area = 0.0;
    let mut first = DVec3::ZERO;
    let mut second = [[0.0f64; 3]; 3];
    for t in triangles {
        let [p, q, r] = t.v.map(|v| v - o);
        let a = 0.5 * (q - p).cross(r - p).length();
        if a == 0.0 {
            continue;
        }
        let m = (p + q + r) / 3.0;
        area += a;
        first += a * m;
        let (m, p, q, r) = (m.to_array(), p.to_array(), q.to_array(), r.to_array());
        for i in 0..3 {
            for j in i..3 {
                second[i][j] +=
                    a / 12.0 * (9.0 * m[i] * m[j] + p[i] * p[j] + q[i] * q[j] + r[i] * r[j]);
            }
        }
    }
    if !(area > 0.0 && area.is_finite()) {
        return None;
    }
    let mu = (first / area).to_array();
    let c = |i: usize, j: usize| second[i.min(j)][i.max(j)] / area - mu[i] * mu[j];
    let cov = DMat3::from_cols_array_2d(&[
        [c(0, 0), c(0, 1), c(0, 2)],
        [c(1, 0), c(1, 1), c(1, 2)],
        [c(2, 0), c(2, 1), c(2, 2)],
    ]);
    cov.is_finite().then_some(cov)
}

/// Axes of the area-weighted triangle covariance (RAPID 2), falling back to the vertex
/// covariance when the triangles have no area.
pub fn area_weighted_axes(triangles: &[Triangle]) -> DMat3 {
    match area_weighted_covariance(triangles) {
        Some(c) => symmetric_eigen_axes(c),
        None => {
            let points: Vec<DVec3> = triangles.iter().flat_map(|t| t.v).collect();
            vertex_covariance_axes(&points)
        }
    }
}

/// Axes of the area-weighted covariance of the convex hull's surface (Gottschalk, Lin &
/// Manocha 1996): insensitive to tessellation and to interior geometry. A planar hull uses the
/// polygon's area; a segment or point falls back to the vertex covariance; non-finite input
/// falls back to the vertex covariance too.
pub fn hull_surface_axes(points: &[DVec3]) -> DMat3 {
    match crate::hull::convex_hull(points) {
        Ok(h) => match area_weighted_covariance(&h.surface_triangles()) {
            Some(c) => symmetric_eigen_axes(c),
            None => vertex_covariance_axes(points),
        },
        Err(_) => vertex_covariance_axes(points),
    }
}

/// Eigenvectors of the vertex covariance, as a right-handed orthonormal basis sorted by
/// decreasing eigenvalue (column 0 is the major axis).
pub fn vertex_covariance_axes(points: &[DVec3]) -> DMat3 {
    covariance_axes_of(points.iter().copied())
}

/// [`vertex_covariance_axes`] over any re-iterable sequence of points (two passes).
fn covariance_axes_of(points: impl Iterator<Item = DVec3> + Clone) -> DMat3 {
    let (sum, count) = points
        .clone()
        .fold((DVec3::ZERO, 0usize), |(s, c), p| (s + p, c + 1));
    if count == 0 {
        return DMat3::IDENTITY;
    }
    // Centre first: the covariance of shifted data is better conditioned at large offsets.
    let n = count as f64;
    let mean = sum / n;
    let mut c = [[0.0f64; 3]; 3];
    for p in points {
        let d = (p - mean).to_array();
        for i in 0..3 {
            for j in i..3 {
                c[i][j] += d[i] * d[j];
            }
        }
    }
    let cov = DMat3::from_cols_array_2d(&[
        [c[0][0], c[0][1], c[0][2]],
        [c[0][1], c[1][1], c[1][2]],
        [c[0][2], c[1][2], c[2][2]],
    ]) * (1.0 / n);
    symmetric_eigen_axes(cov)
}

/// Eigenvectors of a symmetric 3×3 matrix ([`crate::eigen::symmetric_eigen`], closed form with
/// a Jacobi fallback), returned as the columns of a right-handed orthonormal basis sorted by
/// decreasing eigenvalue. The identity for a zero or non-finite matrix.
pub fn symmetric_eigen_axes(m: DMat3) -> DMat3 {
    let Some((_, v)) = crate::eigen::symmetric_eigen(m) else {
        return DMat3::IDENTITY;
    };
    // Already orthonormal to rounding (finite: checked there); major axis first, right-handed.
    let (x, y) = (v.z_axis, v.y_axis);
    DMat3::from_cols(x, y, x.cross(y))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Pose, shapes};
    use glam::DQuat;

    #[test]
    fn eigen_axes_recover_a_rotated_box() {
        let q = DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1);
        let mesh = shapes::cuboid(DVec3::new(4.0, 2.0, 1.0))
            .transformed(&Pose::new(DVec3::new(1e5, 0.0, 0.0), q));
        let tris: Vec<_> = mesh.triangles().collect();
        // Unique corners: the covariance is diagonal in the box frame.
        let axes = vertex_covariance_axes(mesh.vertices());
        let r = DMat3::from_quat(q);
        assert!(axes.x_axis.dot(r.x_axis).abs() > 1.0 - 1e-9);
        assert!(axes.y_axis.dot(r.y_axis).abs() > 1.0 - 1e-9);
        let tight = Obb::from_points_with_axes(mesh.vertices(), axes);
        assert!((tight.volume() - 64.0).abs() < 1e-6);
        // Triangle vertices repeat corners unevenly (PQP's bias); the box must still hold them.
        for method in [
            FitMethod::VertexCovariance,
            FitMethod::AreaWeighted,
            FitMethod::HullSurface,
        ] {
            let obb = fit_obb(&tris, method);
            for t in &tris {
                for p in t.v {
                    assert!(obb.contains_point(p), "{method:?}");
                }
            }
        }
    }

    /// Splits one triangle 1 → 4, `levels` times (a triangle soup; T-junctions do not matter to
    /// the fit).
    fn refine(t: Triangle, levels: u32) -> Vec<Triangle> {
        let mut out = vec![t];
        for _ in 0..levels {
            out = out
                .iter()
                .flat_map(|t| {
                    let [a, b, c] = t.v;
                    let (ab, bc, ca) = ((a + b) / 2.0, (b + c) / 2.0, (c + a) / 2.0);
                    [
                        Triangle::new(a, ab, ca),
                        Triangle::new(b, bc, ab),
                        Triangle::new(c, ca, bc),
                        Triangle::new(ab, bc, ca),
                    ]
                })
                .collect();
        }
        out
    }

    fn alignment(axes: DMat3, r: DMat3) -> f64 {
        // Smallest |cos| between a fitted axis and the matching true axis.
        [
            axes.x_axis.dot(r.x_axis).abs(),
            axes.y_axis.dot(r.y_axis).abs(),
            axes.z_axis.dot(r.z_axis).abs(),
        ]
        .into_iter()
        .fold(1.0, f64::min)
    }

    #[test]
    fn surface_rules_ignore_uneven_tessellation() {
        let q = DQuat::from_euler(glam::EulerRot::XYZ, 0.4, 0.2, -0.9);
        let r = DMat3::from_quat(q);
        let pose = Pose::new(DVec3::new(-3e4, 2e4, 7.0), q);
        let boxm = shapes::cuboid(DVec3::new(4.0, 2.0, 1.0));
        // One triangle of the -z face split into 4^5 pieces: 1024 extra triangles crowd one
        // corner of one face.
        let mut tris: Vec<Triangle> = refine(boxm.triangle(0), 5);
        tris.extend((1..12).map(|i| boxm.triangle(i)));
        let tris: Vec<Triangle> = tris.iter().map(|t| t.transformed(&pose)).collect();
        let pts: Vec<DVec3> = tris.iter().flat_map(|t| t.v).collect();
        let vc = vertex_covariance_axes(&pts);
        let aw = area_weighted_axes(&tris);
        let hs = hull_surface_axes(&pts);
        assert!(
            alignment(vc, r) < 0.999,
            "vertex covariance should be biased: {}",
            alignment(vc, r)
        );
        assert!(alignment(aw, r) > 1.0 - 1e-9, "{}", alignment(aw, r));
        assert!(alignment(hs, r) > 1.0 - 1e-9, "{}", alignment(hs, r));
        for method in [
            FitMethod::VertexCovariance,
            FitMethod::AreaWeighted,
            FitMethod::HullSurface,
        ] {
            let obb = fit_obb(&tris, method);
            assert!(pts.iter().all(|p| obb.contains_point(*p)), "{method:?}");
            if method != FitMethod::VertexCovariance {
                assert!(
                    (obb.volume() / 64.0 - 1.0).abs() < 1e-9,
                    "{method:?} {}",
                    obb.volume()
                );
            } else {
                assert!(obb.volume() > 64.0 * (1.0 + 1e-6));
            }
        }
    }

    #[test]
    fn hull_rule_ignores_interior_geometry() {
        // A long box with a heavily tessellated, differently rotated body inside it: the
        // area-weighted rule follows the inner body, the hull rule only sees the outer box.
        let outer = shapes::cuboid(DVec3::new(5.0, 2.0, 1.0));
        let inner = shapes::subdivide(&shapes::subdivide(&shapes::cuboid(DVec3::new(
            1.5, 0.3, 0.3,
        ))))
        .transformed(&Pose::new(DVec3::ZERO, DQuat::from_rotation_z(1.0)));
        let mut tris: Vec<Triangle> = outer.triangles().collect();
        tris.extend(inner.triangles());
        let pts: Vec<DVec3> = tris.iter().flat_map(|t| t.v).collect();
        let hs = hull_surface_axes(&pts);
        assert!(alignment(hs, DMat3::IDENTITY) > 1.0 - 1e-9);
        let obb = fit_obb(&tris, FitMethod::HullSurface);
        assert!((obb.volume() - 80.0).abs() < 1e-9);
        assert!(pts.iter().all(|p| obb.contains_point(*p)));
    }

    #[test]
    fn degenerate_inputs_fall_back() {
        // Flat: a planar polygon hull; its covariance has a zero eigenvalue along the normal.
        let n = DVec3::new(1.0, 2.0, 3.0).normalize();
        let u = n.any_orthonormal_vector();
        let v = n.cross(u);
        let tris: Vec<Triangle> = (0..10)
            .map(|i| {
                let a = i as f64;
                Triangle::new(u * a, u * a + v * 2.0, u * (a + 1.0))
            })
            .collect();
        for method in [
            FitMethod::VertexCovariance,
            FitMethod::AreaWeighted,
            FitMethod::HullSurface,
        ] {
            let obb = fit_obb(&tris, method);
            assert!(obb.axes.z_axis.dot(n).abs() > 1.0 - 1e-9, "{method:?}");
            assert!(obb.half_extents.z < 1e-12);
            assert!(
                tris.iter()
                    .all(|t| t.v.iter().all(|p| obb.contains_point(*p)))
            );
        }
        // Zero-area triangles (segments on one line) and a single point.
        let line: Vec<Triangle> = (0..4)
            .map(|i| {
                let a = DVec3::new(i as f64, 2.0 * i as f64, 0.0);
                Triangle::new(a, a + DVec3::new(1.0, 2.0, 0.0), a)
            })
            .collect();
        for method in [
            FitMethod::VertexCovariance,
            FitMethod::AreaWeighted,
            FitMethod::HullSurface,
        ] {
            let obb = fit_obb(&line, method);
            assert!(
                line.iter()
                    .all(|t| t.v.iter().all(|p| obb.contains_point(*p)))
            );
            assert!(obb.volume() < 1e-20, "{method:?}");
            let one = [Triangle::new(DVec3::ONE, DVec3::ONE, DVec3::ONE)];
            assert!(fit_obb(&one, method).contains_point(DVec3::ONE));
            assert_eq!(fit_obb(&[], method).volume(), 0.0);
        }
    }
}
