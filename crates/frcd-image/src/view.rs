//! The orthographic view of one query, computed in f64 on the CPU.

use frcd_geom::{Aabb, DMat3, DVec3, Pose};

/// How the view axis is chosen (axes of mesh A's local frame).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ViewAxis {
    /// The overlap box's shortest axis (the default; see [`View`]).
    #[default]
    Auto,
    /// A's local x axis.
    X,
    /// A's local y axis.
    Y,
    /// A's local z axis.
    Z,
}

/// The orthographic view of one query, in mesh A's local frame (the "A-frame").
///
/// - **Region**: the overlap of A's box and B's box mapped into the A-frame. `A ∩ B` lies inside
///   it, so only surface layers inside it need to be peeled.
/// - **View axis** ([`ViewAxis::Auto`]): the region's *shortest* axis. The image then spans the two
///   longer extents, and the thin dimension of a shallow penetration (two bodies just pressed
///   together give a flat overlap box) is measured in depth, to float depth precision, instead of
///   in pixels. It also gives the shortest rays, so the fewest surface layers (least depth
///   complexity) per pixel.
/// - **Pixels**: square, `pixel_size = max(lateral extents) / resolution`; the image is
///   `ceil(extent / pixel_size)` pixels along each lateral axis, centred on the region, so at most
///   one partial pixel per side is wasted.
/// - **Depth range**: from in front of *both* meshes' boxes (so every face of A in front of the
///   region still counts for parity) to just behind the region.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// View (depth) axis index in the A-frame: 0, 1 or 2.
    pub axis: usize,
    /// The overlap region in the A-frame.
    pub region: Aabb,
    /// Side of one (square) pixel, in A-frame units.
    pub pixel_size: f64,
    /// Image width in pixels (along A-frame axis `(axis + 1) % 3`).
    pub width: u32,
    /// Image height in pixels (along A-frame axis `(axis + 2) % 3`).
    pub height: u32,
    /// A-frame coordinate of the image's left edge (along the width axis).
    pub u0: f64,
    /// A-frame coordinate of the image's bottom edge (along the height axis).
    pub v0: f64,
    /// A-frame coordinate of the near plane along the view axis (depth 0).
    pub near: f64,
    /// A-frame coordinate of the far plane along the view axis (depth 1).
    pub far: f64,
}

impl View {
    /// The overlap region of A's local box and B's box mapped by `rel` (B's pose in the A-frame),
    /// or `None` when the boxes are disjoint.
    pub fn overlap(aabb_a: &Aabb, aabb_b_local: &Aabb, rel: &Pose) -> Option<(Aabb, Aabb)> {
        let b = aabb_b_local.transformed(rel);
        if !aabb_a.intersects(&b) {
            return None;
        }
        Some((aabb_a.intersection(&b), b))
    }

    /// Builds the view for `region` (inside `a_box` and `b_box`, all in the A-frame) at
    /// `resolution` pixels across. `resolution` must be at least 1.
    pub fn new(region: Aabb, a_box: &Aabb, b_box: &Aabb, axis: ViewAxis, resolution: u32) -> Self {
        let ext = region.max - region.min;
        let axis = match axis {
            ViewAxis::X => 0,
            ViewAxis::Y => 1,
            ViewAxis::Z => 2,
            ViewAxis::Auto => {
                let e = ext.to_array();
                (0..3)
                    .min_by(|&i, &j| e[i].total_cmp(&e[j]))
                    .expect("three axes")
            }
        };
        let (iu, iv) = ((axis + 1) % 3, (axis + 2) % 3);
        let (eu, ev) = (ext[iu], ext[iv]);
        let mut lateral = eu.max(ev);
        if lateral <= 0.0 {
            // A degenerate (segment or point) region: one pixel the size of its depth, or of
            // the boxes if even that is zero.
            lateral = ext[axis].max(1e-9 * (a_box.half_extents().max_element() + 1e-300));
        }
        let s = lateral / resolution.max(1) as f64;
        let width = ((eu / s).ceil() as u32).clamp(1, resolution.max(1));
        let height = ((ev / s).ceil() as u32).clamp(1, resolution.max(1));
        let c = region.center();
        let u0 = c[iu] - 0.5 * width as f64 * s;
        let v0 = c[iv] - 0.5 * height as f64 * s;
        let near0 = a_box.min[axis].min(b_box.min[axis]);
        let far0 = region.max[axis];
        let span = (far0 - near0).max(lateral).max(1e-300);
        // Margins keep every face clear of the clip planes after f32 rounding.
        let margin = span * (1.0 / 1024.0);
        Self {
            axis,
            region,
            pixel_size: s,
            width,
            height,
            u0,
            v0,
            near: near0 - margin,
            far: far0 + margin,
        }
    }

    /// A-frame axis indices `(u, v, depth)`: a right-handed permutation of `(x, y, z)`.
    pub fn axes(&self) -> (usize, usize, usize) {
        ((self.axis + 1) % 3, (self.axis + 2) % 3, self.axis)
    }

    /// `(u, v)` A-frame coordinates of the centre of pixel `(column, row)`; row 0 is the top
    /// (largest v), as in the framebuffer.
    pub fn pixel_center(&self, column: u32, row: u32) -> (f64, f64) {
        (
            self.u0 + (column as f64 + 0.5) * self.pixel_size,
            self.v0 + (self.height as f64 - row as f64 - 0.5) * self.pixel_size,
        )
    }

    /// A point of the A-frame as `(u, v, depth coordinate)`.
    pub fn to_view(&self, p: DVec3) -> DVec3 {
        let (iu, iv, iw) = self.axes();
        DVec3::new(p[iu], p[iv], p[iw])
    }

    /// Area of one pixel.
    pub fn pixel_area(&self) -> f64 {
        self.pixel_size * self.pixel_size
    }

    /// Depth (in `[0, 1]`) of the A-frame coordinate `w` along the view axis.
    pub fn depth_of(&self, w: f64) -> f64 {
        (w - self.near) / (self.far - self.near)
    }

    /// The column-major clip-from-local matrix (f32) for a mesh whose vertices were uploaded
    /// relative to `center` (its local frame) and whose pose in the A-frame is `pose`.
    ///
    /// Composed in f64: `ndc = S · P · (R (center + p) + t − c_image)`, with the translation
    /// `R center + t − c_image` computed in f64 before rounding, so the f32 entries are of the size
    /// of the region and the meshes, never of world coordinates.
    pub fn clip_from_local(&self, pose: &Pose, center: DVec3) -> [[f32; 4]; 4] {
        let (iu, iv, iw) = self.axes();
        let r: DMat3 = pose.rotation_matrix();
        let rows = [r.row(iu), r.row(iv), r.row(iw)];
        let t = pose.transform_point(center);
        let cu = self.u0 + 0.5 * self.width as f64 * self.pixel_size;
        let cv = self.v0 + 0.5 * self.height as f64 * self.pixel_size;
        let su = 2.0 / (self.width as f64 * self.pixel_size);
        let sv = 2.0 / (self.height as f64 * self.pixel_size);
        let sw = 1.0 / (self.far - self.near);
        let scale = [su, sv, sw];
        let trans = [
            (t[iu] - cu) * su,
            (t[iv] - cv) * sv,
            (t[iw] - self.near) * sw,
        ];
        let mut m = [[0f32; 4]; 4];
        for (i, row) in rows.iter().enumerate() {
            for j in 0..3 {
                m[j][i] = (row[j] * scale[i]) as f32;
            }
            m[3][i] = trans[i] as f32;
        }
        m[3][3] = 1.0;
        m
    }
}
