//! A CPU reference for the GPU passes: the same view rays (pixel centres), cast in f64 through
//! every triangle of both meshes, with the exact inside-both length per pixel.
//!
//! It isolates what the GPU adds (f32 vertices and matrices, depth quantisation, sub-pixel edge
//! placement) from what the sampling itself misses, so a test can demand that every pixel where
//! the GPU disagrees is one the error bounds explain: its ray passes within the lateral bound of a
//! silhouette edge, or two surface crossings on it lie within twice the depth bound.

use crate::detector::ErrorBounds;
use crate::view::View;
use crate::{ImageResult, PixelImage};
use frcd_geom::{DVec2, DVec3, Pose, TriMesh};
use std::collections::HashMap;

/// Per-pixel reference of one view, row-major like [`PixelImage`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReferenceImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Exact (f64) length of the pixel's centre ray inside both solids.
    pub lengths: Vec<f64>,
    /// True where the ray is inside both solids at some depth (closed: touching counts).
    pub mask: Vec<bool>,
    /// True where the GPU may legitimately differ: the ray passes within `bounds.lateral` of a
    /// silhouette edge, or two crossings on it are closer than their depth uncertainties.
    pub ambiguous: Vec<bool>,
    /// How far the GPU's length may differ from `lengths` at an unambiguous pixel: the sum, over
    /// the crossings that bound the inside-both intervals, of `depth + lateral · |∇z|` (a steep
    /// face turns the lateral placement error into a depth error).
    pub tolerance: Vec<f64>,
}

impl ReferenceImage {
    /// Reference volume: Σ length × pixel area.
    pub fn volume(&self, view: &View) -> f64 {
        self.lengths.iter().sum::<f64>() * view.pixel_area()
    }
}

/// Casts the view's pixel-centre rays through `mesh_a` at `pose_a` and `mesh_b` at `pose_b` (both
/// in the A-frame), in f64.
pub fn reference_image(
    view: &View,
    bounds: &ErrorBounds,
    mesh_a: &TriMesh,
    pose_a: &Pose,
    mesh_b: &TriMesh,
    pose_b: &Pose,
) -> ReferenceImage {
    let (w, h) = (view.width as i64, view.height as i64);
    let n = (w * h) as usize;
    let s = view.pixel_size;
    let lat = bounds.lateral;
    let top = view.v0 + h as f64 * s;
    let mut ambiguous = vec![false; n];
    // (pixel, depth, mesh, depth uncertainty) for every crossing.
    let mut crossings: Vec<(u32, f64, u8, f64)> = Vec::new();
    // Pixel-centre index ranges covering [lo, hi] in u and v.
    let cols = |lo: f64, hi: f64| -> (i64, i64) {
        (
            (((lo - view.u0) / s) - 0.5).ceil().max(0.0) as i64,
            ((((hi - view.u0) / s) - 0.5).floor() as i64).min(w - 1),
        )
    };
    let rows = |lo: f64, hi: f64| -> (i64, i64) {
        (
            (((top - hi) / s) - 0.5).ceil().max(0.0) as i64,
            ((((top - lo) / s) - 0.5).floor() as i64).min(h - 1),
        )
    };
    let center = |x: i64, y: i64| -> DVec2 {
        DVec2::new(view.u0 + (x as f64 + 0.5) * s, top - (y as f64 + 0.5) * s)
    };
    for (k, (mesh, pose)) in [(mesh_a, pose_a), (mesh_b, pose_b)].into_iter().enumerate() {
        let pts: Vec<DVec3> = mesh
            .vertices()
            .iter()
            .map(|p| view.to_view(pose.transform_point(*p)))
            .collect();
        // Facing of each triangle along the view axis: sign of its projected signed area.
        let facing: Vec<f64> = mesh
            .indices()
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| pts[i as usize].truncate());
                (b - a).perp_dot(c - a)
            })
            .collect();
        // Silhouette edges: the two triangles of the edge face opposite ways (or one is edge-on).
        let mut edge_tris: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
        for (t, tri) in mesh.indices().iter().enumerate() {
            for e in 0..3 {
                let (p, q) = (tri[e], tri[(e + 1) % 3]);
                edge_tris.entry((p.min(q), p.max(q))).or_default().push(t);
            }
        }
        for (&(p, q), tris) in &edge_tris {
            let sil = tris.len() != 2
                || facing[tris[0]] == 0.0
                || facing[tris[1]] == 0.0
                || (facing[tris[0]] > 0.0) != (facing[tris[1]] > 0.0);
            if !sil {
                continue;
            }
            let (a, b) = (pts[p as usize].truncate(), pts[q as usize].truncate());
            let (mn, mx) = (a.min(b) - lat, a.max(b) + lat);
            let (x0, x1) = cols(mn.x, mx.x);
            let (y0, y1) = rows(mn.y, mx.y);
            for y in y0..=y1 {
                for x in x0..=x1 {
                    if segment_distance(center(x, y), a, b) <= lat {
                        ambiguous[(y * w + x) as usize] = true;
                    }
                }
            }
        }
        for (t, tri) in mesh.indices().iter().enumerate() {
            if facing[t] == 0.0 {
                continue; // edge-on: its silhouette band is already ambiguous
            }
            let q = tri.map(|i| pts[i as usize]);
            let (mn, mx) = (q[0].min(q[1]).min(q[2]), q[0].max(q[1]).max(q[2]));
            let nrm = (q[1] - q[0]).cross(q[2] - q[0]);
            let err = bounds.depth + lat * nrm.truncate().length() / nrm.z.abs();
            let (x0, x1) = cols(mn.x, mx.x);
            let (y0, y1) = rows(mn.y, mx.y);
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let c = center(x, y);
                    if let Some(z) = crossing(tri, &q, c) {
                        crossings.push(((y * w + x) as u32, z, k as u8, err));
                    }
                }
            }
        }
    }
    crossings.sort_unstable_by(|p, q| p.0.cmp(&q.0).then(p.1.total_cmp(&q.1)));
    let mut lengths = vec![0.0; n];
    let mut mask = vec![false; n];
    let mut tolerance = vec![0.0; n];
    let mut i = 0;
    while i < crossings.len() {
        let px = crossings[i].0 as usize;
        let mut j = i;
        let mut inside = [false, false];
        let mut entered = f64::NAN;
        while j < crossings.len() && crossings[j].0 as usize == px {
            let (_, z, k, err) = crossings[j];
            if j > i && z - crossings[j - 1].1 <= err + crossings[j - 1].3 {
                ambiguous[px] = true;
            }
            let before = inside[0] && inside[1];
            inside[k as usize] = !inside[k as usize];
            let after = inside[0] && inside[1];
            if !before && after {
                entered = z;
                mask[px] = true;
                tolerance[px] += err;
            } else if before && !after {
                lengths[px] += z - entered;
                tolerance[px] += err;
            }
            j += 1;
        }
        i = j;
    }
    ReferenceImage {
        width: view.width,
        height: view.height,
        lengths,
        mask,
        ambiguous,
        tolerance,
    }
}

/// Depth where the view ray through `c` crosses the triangle, by a consistent edge rule:
/// each edge's side test is computed with its endpoints in canonical (index) order, so two
/// triangles sharing an edge never both claim (or both miss) a point on it.
fn crossing(idx: &[u32; 3], q: &[DVec3; 3], c: DVec2) -> Option<f64> {
    let mut e = [0.0; 3];
    for (k, ek) in e.iter_mut().enumerate() {
        let (i, j) = (k, (k + 1) % 3);
        let (lo, hi, sign) = if idx[i] < idx[j] {
            (q[i].truncate(), q[j].truncate(), 1.0)
        } else {
            (q[j].truncate(), q[i].truncate(), -1.0)
        };
        let mut v = sign * (hi - lo).perp_dot(c - lo);
        if v == 0.0 {
            // On the edge's line: a tie broken by the edge's canonical direction, opposite for
            // the two triangles of a shared edge.
            let d = hi - lo;
            let owns = d.y > 0.0 || (d.y == 0.0 && d.x > 0.0);
            v = if owns == (sign > 0.0) {
                f64::MIN_POSITIVE
            } else {
                -f64::MIN_POSITIVE
            };
        }
        *ek = v;
    }
    let area: f64 = e.iter().sum();
    let inside = if area > 0.0 {
        e.iter().all(|v| *v > 0.0)
    } else {
        e.iter().all(|v| *v < 0.0)
    };
    if !inside {
        return None;
    }
    // Barycentric weights: e[k] is opposite vertex (k + 2) % 3.
    let z = (e[1] * q[0].z + e[2] * q[1].z + e[0] * q[2].z) / area;
    Some(z)
}

fn segment_distance(p: DVec2, a: DVec2, b: DVec2) -> f64 {
    let d = b - a;
    let l2 = d.length_squared();
    let t = if l2 > 0.0 {
        ((p - a).dot(d) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + d * t)).length()
}

/// How a GPU result agrees with the reference, pixel by pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Agreement {
    /// Pixels where the masks differ at a pixel the bounds explain (ambiguous).
    pub explained: usize,
    /// Pixels where the masks differ although the reference is unambiguous there.
    pub unexplained: usize,
    /// Largest length difference at unambiguous pixels where both interfere.
    pub max_length_error: f64,
    /// Unambiguous pixels where the length differs by more than the pixel's tolerance (plus the
    /// f32 accumulation of the lengths, `4 · bounds.depth`).
    pub length_violations: usize,
    /// Pixels interfering in the reference.
    pub reference_pixels: usize,
}

/// Compares a GPU [`ImageResult`] with the reference of the same view.
pub fn agreement(result: &ImageResult, reference: &ReferenceImage) -> Agreement {
    let slack = 4.0 * result.bounds.depth;
    let img: &PixelImage = &result.image;
    let mut a = Agreement::default();
    for i in 0..reference.mask.len() {
        let (g, r) = (img.mask[i], reference.mask[i]);
        a.reference_pixels += r as usize;
        if g != r {
            if reference.ambiguous[i] {
                a.explained += 1;
            } else {
                a.unexplained += 1;
            }
        } else if g && !reference.ambiguous[i] {
            let e = (img.lengths[i] as f64 - reference.lengths[i]).abs();
            a.max_length_error = a.max_length_error.max(e);
            if e > reference.tolerance[i] + slack {
                a.length_violations += 1;
            }
        }
    }
    a
}
