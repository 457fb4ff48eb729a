//! The accurate colliding set, computed on the CPU from the read-back interfering mask.
//!
//! The software rasterizer has no conservative rasterization, so a triangle's fragments do not
//! tell every pixel it crosses (a sliver or a sub-pixel triangle may produce none at all).
//! Instead every triangle is projected in f64 and tested exactly, in 2D, against the squares of
//! the dilated interfering pixels it may cross: a triangle crossing such a square is never missed.

use crate::PixelImage;
use crate::view::View;
use frcd_geom::{DVec2, DVec3, Pose, TriMesh};

/// Triangles of `mesh_a` (at `pose_a` in the A-frame) and `mesh_b` (at `pose_b`) that cross a
/// pixel within `dilation` pixels (Chebyshev) of an interfering pixel of `image`, and whose depth
/// range meets the region's (widened by `margin`). Ascending ids.
#[allow(clippy::too_many_arguments)]
pub fn colliding_set(
    view: &View,
    image: &PixelImage,
    dilation: u32,
    margin: f64,
    mesh_a: &TriMesh,
    pose_a: &Pose,
    mesh_b: &TriMesh,
    pose_b: &Pose,
) -> (Vec<u32>, Vec<u32>) {
    let (w, h) = (image.width as i64, image.height as i64);
    if !image.mask.iter().any(|m| *m) {
        return (Vec::new(), Vec::new());
    }
    // Dilate the mask (separable max filter), then a summed-area table over it.
    let d = dilation as i64;
    let mut rows = vec![false; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            if image.mask[(y * w + x) as usize] {
                for xx in (x - d).max(0)..=(x + d).min(w - 1) {
                    rows[(y * w + xx) as usize] = true;
                }
            }
        }
    }
    let mut dil = vec![false; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            if rows[(y * w + x) as usize] {
                for yy in (y - d).max(0)..=(y + d).min(h - 1) {
                    dil[(yy * w + x) as usize] = true;
                }
            }
        }
    }
    let sw = (w + 1) as usize;
    let mut sat = vec![0u32; sw * (h + 1) as usize];
    for y in 0..h as usize {
        for x in 0..w as usize {
            sat[(y + 1) * sw + x + 1] =
                dil[y * w as usize + x] as u32 + sat[y * sw + x + 1] + sat[(y + 1) * sw + x]
                    - sat[y * sw + x];
        }
    }
    let any_in = |x0: i64, y0: i64, x1: i64, y1: i64| -> bool {
        let (x0, y0, x1, y1) = (x0 as usize, y0 as usize, x1 as usize + 1, y1 as usize + 1);
        sat[y1 * sw + x1] + sat[y0 * sw + x0] - sat[y0 * sw + x1] - sat[y1 * sw + x0] > 0
    };
    let s = view.pixel_size;
    let (zlo, zhi) = (
        view.region.min[view.axis] - margin,
        view.region.max[view.axis] + margin,
    );
    let top = view.v0 + h as f64 * s;
    let collect = |mesh: &TriMesh, pose: &Pose| -> Vec<u32> {
        let pts: Vec<DVec3> = mesh
            .vertices()
            .iter()
            .map(|p| view.to_view(pose.transform_point(*p)))
            .collect();
        let mut out = Vec::new();
        for (t, tri) in mesh.indices().iter().enumerate() {
            let q = tri.map(|i| pts[i as usize]);
            let (mn, mx) = (q[0].min(q[1]).min(q[2]), q[0].max(q[1]).max(q[2]));
            if mx.z < zlo || mn.z > zhi {
                continue;
            }
            // Pixel column x spans [u0 + x s, u0 + (x+1) s]; row y spans v in
            // [top − (y+1) s, top − y s]. Widen by `margin` so rounding only adds candidates.
            let x0 = ((mn.x - margin - view.u0) / s).floor() as i64;
            let x1 = ((mx.x + margin - view.u0) / s).floor() as i64;
            let y0 = ((top - mx.y - margin) / s).floor() as i64;
            let y1 = ((top - mn.y + margin) / s).floor() as i64;
            if x1 < 0 || y1 < 0 || x0 >= w || y0 >= h {
                continue;
            }
            let (x0, y0, x1, y1) = (x0.max(0), y0.max(0), x1.min(w - 1), y1.min(h - 1));
            if !any_in(x0, y0, x1, y1) {
                continue;
            }
            let tri2 = [q[0].truncate(), q[1].truncate(), q[2].truncate()];
            let hit = (y0..=y1).any(|y| {
                (x0..=x1).any(|x| {
                    dil[(y * w + x) as usize] && {
                        let lo = DVec2::new(view.u0 + x as f64 * s, top - (y + 1) as f64 * s);
                        triangle_meets_box(&tri2, lo - margin, lo + s + margin)
                    }
                })
            });
            if hit {
                out.push(t as u32);
            }
        }
        out
    };
    (collect(mesh_a, pose_a), collect(mesh_b, pose_b))
}

/// Separating-axis test of a (possibly degenerate) 2D triangle against a closed box.
pub(crate) fn triangle_meets_box(t: &[DVec2; 3], lo: DVec2, hi: DVec2) -> bool {
    let (mn, mx) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
    if mx.x < lo.x || mn.x > hi.x || mx.y < lo.y || mn.y > hi.y {
        return false;
    }
    let corners = [lo, DVec2::new(hi.x, lo.y), hi, DVec2::new(lo.x, hi.y)];
    for k in 0..3 {
        let e = t[(k + 1) % 3] - t[k];
        let n = e.perp();
        if n == DVec2::ZERO {
            continue;
        }
        let tp = [n.dot(t[0]), n.dot(t[1]), n.dot(t[2])];
        let (tmin, tmax) = (tp[0].min(tp[1]).min(tp[2]), tp[0].max(tp[1]).max(tp[2]));
        let bp = corners.map(|c| n.dot(c));
        let (bmin, bmax) = (
            bp[0].min(bp[1]).min(bp[2]).min(bp[3]),
            bp[0].max(bp[1]).max(bp[2]).max(bp[3]),
        );
        if tmax < bmin || tmin > bmax {
            return false;
        }
    }
    true
}
