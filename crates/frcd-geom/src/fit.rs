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
/// has no area to weigh (all triangles degenerate), and to world axes when the covariance is
/// singular in every direction.
///
/// ```
/// use frcd_geom::{fit::{fit_obb, FitMethod}, shapes, Pose, DVec3, DQuat};
/// let mesh = shapes::cuboid(DVec3::new(3.0, 1.0, 0.5))
///     .transformed(&Pose::new(DVec3::ZERO, DQuat::from_rotation_z(0.3)));
/// let tris: Vec<_> = mesh.triangles().collect();
/// let obb = fit_obb(&tris, FitMethod::AreaWeighted);
/// assert!(tris.iter().all(|t| t.v.iter().all(|p| obb.contains_point(*p))));
/// ```
pub fn fit_obb(triangles: &[Triangle], method: FitMethod) -> Obb {
    let points: Vec<DVec3> = triangles.iter().flat_map(|t| t.v).collect();
    let axes = match method {
        FitMethod::VertexCovariance => vertex_covariance_axes(&points),
        // Filled in by the area-weighted and hull rules; until then, the vertex rule.
        FitMethod::AreaWeighted | FitMethod::HullSurface => vertex_covariance_axes(&points),
    };
    Obb::from_points_with_axes(&points, axes)
}

/// Eigenvectors of the vertex covariance, as a right-handed orthonormal basis sorted by
/// decreasing eigenvalue (column 0 is the major axis).
pub fn vertex_covariance_axes(points: &[DVec3]) -> DMat3 {
    if points.is_empty() {
        return DMat3::IDENTITY;
    }
    // Centre first: the covariance of shifted data is better conditioned at large offsets.
    let n = points.len() as f64;
    let mean = points.iter().copied().sum::<DVec3>() / n;
    let mut c = [[0.0f64; 3]; 3];
    for p in points {
        let d = (*p - mean).to_array();
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

/// Eigenvectors of a symmetric 3×3 matrix by cyclic Jacobi rotations, returned as the columns of a
/// right-handed orthonormal basis sorted by decreasing eigenvalue.
pub fn symmetric_eigen_axes(m: DMat3) -> DMat3 {
    let mut a = m.to_cols_array_2d();
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let scale = a.iter().flatten().fold(0.0f64, |s, x| s.max(x.abs()));
    if scale == 0.0 || !scale.is_finite() {
        return DMat3::IDENTITY;
    }
    for _sweep in 0..32 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off <= scale * 1e-15 {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            if a[p][q].abs() <= scale * 1e-18 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let cs = 1.0 / (t * t + 1.0).sqrt();
            let sn = t * cs;
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = cs * akp - sn * akq;
                a[k][q] = sn * akp + cs * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = cs * apk - sn * aqk;
                a[q][k] = sn * apk + cs * aqk;
            }
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = cs * vp - sn * vq;
                row[q] = sn * vp + cs * vq;
            }
        }
    }
    // Columns of v (v[row][col]) are eigenvectors; sort by eigenvalue, descending.
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| {
        a[j][j]
            .partial_cmp(&a[i][i])
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let col = |k: usize| DVec3::new(v[0][k], v[1][k], v[2][k]).normalize();
    let x = col(order[0]);
    let y0 = col(order[1]);
    // Re-orthonormalise and make right-handed.
    let y = (y0 - x * x.dot(y0)).normalize();
    let z = x.cross(y);
    if !(x.is_finite() && y.is_finite() && z.is_finite()) {
        return DMat3::IDENTITY;
    }
    DMat3::from_cols(x, y, z)
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
        let obb = fit_obb(&tris, FitMethod::VertexCovariance);
        for t in &tris {
            for p in t.v {
                assert!(obb.contains_point(p));
            }
        }
    }
}
