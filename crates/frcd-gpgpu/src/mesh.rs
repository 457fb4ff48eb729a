use crate::pack::{NODE_TEXELS, PackedTree, TRI_TEXELS, TexLayout, pack_tree_rows};
use crate::{GpuContext, GpuError};
use frcd_geom::TriMesh;
use frcd_obb::ObbTree;
use std::sync::Arc;

/// Shape of the context's mesh arena (see [`GpuContext::upload`]): every mesh of a context lives
/// in one node texture and one triangle texture, so a whole batch of body pairs is traversed in
/// one dispatch chain. `None`: the default (1,024 items per row, 64 rows per layer, clamped to
/// the device's texture limits). Both are rounded down to powers of two (the shaders then find
/// an item's texel with shifts and masks instead of integer divisions, which a software driver
/// runs lane by lane). Small values exercise the row and layer splitting in tests.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ArenaOptions {
    /// Items (nodes or triangles) per texture row.
    pub items_per_row: Option<u32>,
    /// Rows per texture array layer.
    pub rows_per_layer: Option<u32>,
}

/// One arena texture: `rows_per_layer × layers` rows of `items_per_row` items; meshes take
/// whole rows, allocated in order.
pub(crate) struct ArenaTex {
    texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    pub layout: TexLayout,
    next_row: u64,
    max_layers: u32,
    label: &'static str,
    /// `Rgba32Uint` (nodes: f32 bits and links) or `Rgba32Float` (triangles).
    format: wgpu::TextureFormat,
}

/// The mesh arena of a context (behind its mutex).
pub(crate) struct Arena {
    pub nodes: ArenaTex,
    pub tris: ArenaTex,
    pub layout: wgpu::Buffer,
    pub bind: wgpu::BindGroup,
    /// Bumped whenever a texture is reallocated (the bind group changes).
    pub generation: u64,
}

fn arena_texture(
    ctx_device: &wgpu::Device,
    label: &'static str,
    layout: &TexLayout,
    format: wgpu::TextureFormat,
) -> wgpu::Texture {
    ctx_device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: layout.width(),
            height: layout.rows_per_layer,
            depth_or_array_layers: layout.layers,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_DST
            | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    })
}

fn view_of(t: &wgpu::Texture, label: &'static str) -> wgpu::TextureView {
    t.create_view(&wgpu::TextureViewDescriptor {
        label: Some(label),
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    })
}

/// Layers for `rows` rows: at least 2 (wgpu's GL backend makes a one-layer texture a
/// `TEXTURE_2D`, read as zeros through a `texture_2d_array` binding) and never a multiple of 6
/// on a square layer (GL makes that a cube map).
fn layers_for(layout: &TexLayout, layers: u32) -> u32 {
    let layers = layers.max(crate::pack::MIN_LAYERS);
    if layout.width() == layout.rows_per_layer && layers.is_multiple_of(6) {
        layers + 1
    } else {
        layers
    }
}

impl ArenaTex {
    fn new(
        device: &wgpu::Device,
        label: &'static str,
        texels_per_item: u32,
        format: wgpu::TextureFormat,
        opts: &ArenaOptions,
        limits: &wgpu::Limits,
    ) -> Result<Self, GpuError> {
        let dim = limits.max_texture_dimension_2d;
        let pow2_down = |x: u32| if x == 0 { 1 } else { 1u32 << x.ilog2() };
        let per_row = pow2_down(
            opts.items_per_row
                .unwrap_or(1024)
                .min(dim / texels_per_item),
        );
        let rows = pow2_down(opts.rows_per_layer.unwrap_or(64).min(dim));
        if dim < texels_per_item || limits.max_texture_array_layers < crate::pack::MIN_LAYERS {
            return Err(GpuError::Unsupported {
                adapter: String::new(),
                what: "texture size (one item per row, two layers)",
                needed: texels_per_item as u64,
                available: dim as u64,
            });
        }
        let mut layout = TexLayout {
            texels_per_item,
            items_per_row: per_row,
            rows_per_layer: rows,
            layers: 0,
        };
        layout.layers = layers_for(&layout, 2);
        let texture = arena_texture(device, label, &layout, format);
        Ok(Self {
            view: view_of(&texture, label),
            texture,
            layout,
            next_row: 0,
            max_layers: limits.max_texture_array_layers,
            label,
            format,
        })
    }

    /// Reserves `rows` whole rows; grows the texture (GPU copy of the old layers) when full.
    /// Returns the first row and whether the texture was reallocated.
    fn alloc(&mut self, ctx: &GpuContext, rows: u64) -> Result<(u64, bool), GpuError> {
        let per_layer = self.layout.rows_per_layer as u64;
        let have = per_layer * self.layout.layers as u64;
        let start = self.next_row;
        let end = start + rows;
        let mut grown = false;
        if end > have {
            let needed = end.div_ceil(per_layer);
            let want = needed.max(2 * self.layout.layers as u64);
            let layers = want.min(self.max_layers as u64);
            if layers < needed {
                return Err(GpuError::MeshTooLarge {
                    what: "mesh arena texture array layers",
                    needed,
                    limit: self.max_layers as u64,
                });
            }
            let mut layout = self.layout;
            layout.layers = layers_for(&layout, layers as u32);
            if layout.layers > self.max_layers {
                layout.layers = layers as u32;
            }
            let texture = arena_texture(&ctx.device, self.label, &layout, self.format);
            let mut enc = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("frcd-gpgpu arena growth"),
                });
            enc.copy_texture_to_texture(
                self.texture.as_image_copy(),
                texture.as_image_copy(),
                wgpu::Extent3d {
                    width: self.layout.width(),
                    height: self.layout.rows_per_layer,
                    depth_or_array_layers: self.layout.layers,
                },
            );
            ctx.queue.submit([enc.finish()]);
            self.view = view_of(&texture, self.label);
            self.texture = texture;
            self.layout = layout;
            grown = true;
        }
        self.next_row = end;
        Ok((start, grown))
    }

    /// Writes `texels` (whole rows, row-major, 16 bytes each) from global row `row0` on.
    fn write(&self, ctx: &GpuContext, row0: u64, texels: &[[u32; 4]]) {
        let width = self.layout.width() as usize;
        let per_layer = self.layout.rows_per_layer as u64;
        let rows = (texels.len() / width) as u64;
        let mut r = 0u64;
        while r < rows {
            let g = row0 + r;
            let (layer, row) = (g / per_layer, g % per_layer);
            let n = (per_layer - row).min(rows - r);
            let chunk = &texels[r as usize * width..(r + n) as usize * width];
            ctx.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &self.texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d {
                        x: 0,
                        y: row as u32,
                        z: layer as u32,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                bytemuck::cast_slice(chunk),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(width as u32 * 16),
                    rows_per_image: Some(n as u32),
                },
                wgpu::Extent3d {
                    width: width as u32,
                    height: n as u32,
                    depth_or_array_layers: 1,
                },
            );
            r += n;
        }
    }
}

impl Arena {
    pub(crate) fn new(
        device: &wgpu::Device,
        bgl: &wgpu::BindGroupLayout,
        limits: &wgpu::Limits,
        opts: &ArenaOptions,
    ) -> Result<Self, GpuError> {
        let nodes = ArenaTex::new(
            device,
            "frcd-gpgpu node arena",
            NODE_TEXELS,
            wgpu::TextureFormat::Rgba32Uint,
            opts,
            limits,
        )?;
        let tris = ArenaTex::new(
            device,
            "frcd-gpgpu triangle arena",
            TRI_TEXELS,
            wgpu::TextureFormat::Rgba32Float,
            opts,
            limits,
        )?;
        let layout = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frcd-gpgpu arena layout"),
            size: 32,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: true,
        });
        {
            // Powers of two (see `ArenaTex::new`) and their logarithms, for `slot`'s shifts.
            let shape = |l: &TexLayout| {
                [
                    l.items_per_row,
                    l.rows_per_layer,
                    l.items_per_row.trailing_zeros(),
                    l.rows_per_layer.trailing_zeros(),
                ]
            };
            let n = shape(&nodes.layout);
            let t = shape(&tris.layout);
            let words: [u32; 8] = [n[0], n[1], n[2], n[3], t[0], t[1], t[2], t[3]];
            layout
                .slice(..)
                .get_mapped_range_mut()
                .expect("mapped at creation")
                .copy_from_slice(bytemuck::cast_slice(&words));
        }
        layout.unmap();
        let bind = Self::bind_group(device, bgl, &nodes, &tris, &layout);
        Ok(Self {
            nodes,
            tris,
            layout,
            bind,
            generation: 0,
        })
    }

    fn bind_group(
        device: &wgpu::Device,
        bgl: &wgpu::BindGroupLayout,
        nodes: &ArenaTex,
        tris: &ArenaTex,
        layout: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("frcd-gpgpu arena"),
            layout: bgl,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&nodes.view),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&tris.view),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: layout.as_entire_binding(),
                },
            ],
        })
    }
}

/// One body's OBB tree and triangles resident on the GPU (uploaded once into the context's
/// arena), plus the f64 triangles the CPU needs to re-decide the pairs the GPU reports.
///
/// The arena never frees rows: memory of a dropped mesh is returned when its context is
/// dropped.
pub struct GpuMesh {
    pub(crate) ctx_id: u64,
    /// First node / first triangle slot in the arena.
    pub(crate) node_base: u32,
    pub(crate) tri_base: u32,
    pub(crate) depth: u32,
    /// Most triangles in one leaf (a leaf pair lists up to the product of two such counts).
    pub(crate) max_leaf: u32,
    /// The tree's mesh (shared, not copied), for the CPU's exact re-decision.
    pub(crate) mesh: Arc<TriMesh>,
    /// Exponent of the triangles' reference-point grid (`pack::grid_exponent`).
    pub(crate) grid: Option<i32>,
    /// The largest deviation of the nodes' f32 axes from orthonormal (`pack::PackedTree::eps`).
    pub(crate) eps: f32,
    /// The tree and its packed order, for the CPU's descent of the top of each pair tree
    /// (`front.rs`); kept only when the context's front was on at the upload.
    pub(crate) host: Option<std::sync::Arc<crate::front::HostTree>>,
    bytes: u64,
}

impl std::fmt::Debug for GpuMesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuMesh")
            .field("triangles", &self.mesh.triangle_count())
            .field("depth", &self.depth)
            .field("node_base", &self.node_base)
            .field("tri_base", &self.tri_base)
            .finish()
    }
}

impl GpuMesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.mesh.triangle_count()
    }
    /// Depth of the tree (a single leaf: 1).
    pub fn depth(&self) -> u32 {
        self.depth
    }
    /// Bytes of arena texture this mesh occupies (whole rows of nodes and triangles).
    pub fn uploaded_bytes(&self) -> u64 {
        self.bytes
    }
}

/// Most triangles one leaf of an uploaded tree may hold (trees for the GPU have small leaves:
/// the builder's default is 2, the hybrid checker's 4). A traversal invocation lists every
/// triangle pair of up to four overlapping leaf pairs in loops, and a software driver such as
/// llvmpipe silently ends a shader's loops once they have run 65,535 iterations in all (Mesa's
/// `LP_MAX_TGSI_LOOP_ITERATIONS`): four leaf pairs of 64 take at most 4 × (64 + 64²) = 16,640.
/// Leaves of 160 lost pairs there (measured 2026-12-02, when the limit was 256).
pub const MAX_LEAF_TRIANGLES: u32 = 64;

impl GpuContext {
    /// Uploads a tree (nodes and triangles, local frame, f32 rounded outward) once into the
    /// context's arena; queries then upload only poses. The arena grows (a GPU copy) when full.
    /// A tree with a leaf of more than [`MAX_LEAF_TRIANGLES`] triangles is
    /// [`GpuError::MeshTooLarge`]. With the CPU front on ([`GpuContext::set_host_front`]) the
    /// mesh also keeps a copy of the tree on the host, for the CPU's share of the traversal.
    pub fn upload(&self, tree: &ObbTree) -> Result<GpuMesh, GpuError> {
        // Node by node: `ObbTree::nodes` would build a whole f64 copy of the tree only for this.
        let max_leaf = (0..tree.node_count() as u32)
            .map(|i| tree.node(i))
            .filter(|n| n.is_leaf())
            .map(|n| n.count)
            .max()
            .unwrap_or(0);
        if max_leaf > MAX_LEAF_TRIANGLES {
            return Err(GpuError::MeshTooLarge {
                what: "triangles in one leaf of the tree",
                needed: max_leaf as u64,
                limit: MAX_LEAF_TRIANGLES as u64,
            });
        }
        let mut arena = self.arena.lock().unwrap_or_else(|e| e.into_inner());
        let PackedTree {
            nodes,
            node_layout,
            tris,
            tri_layout,
            depth,
            grid,
            eps,
        } = pack_tree_rows(
            tree,
            arena.nodes.layout.items_per_row,
            arena.tris.layout.items_per_row,
        )?;
        // Before the arena is touched: a refusal leaves it as it was.
        let host = if self.host_front > 0 {
            let (bfs, first_child) = crate::pack::sibling_order(tree)?;
            Some(crate::front::HostTree::new(tree, &bfs, &first_child))
        } else {
            None
        };
        let node_rows = node_layout.rows_per_layer as u64;
        let tri_rows = tri_layout.rows_per_layer as u64;
        let (node_row, g1) = arena.nodes.alloc(self, node_rows)?;
        let (tri_row, g2) = arena.tris.alloc(self, tri_rows)?;
        let node_base = node_row * arena.nodes.layout.items_per_row as u64;
        let tri_base = tri_row * arena.tris.layout.items_per_row as u64;
        for (what, base) in [
            ("node arena slots", node_base),
            ("triangle arena slots", tri_base),
        ] {
            if base + (1 << 24) > u32::MAX as u64 {
                return Err(GpuError::MeshTooLarge {
                    what,
                    needed: base,
                    limit: u32::MAX as u64 - (1 << 24),
                });
            }
        }
        arena.nodes.write(self, node_row, &nodes);
        arena.tris.write(self, tri_row, bytemuck::cast_slice(&tris));
        if g1 || g2 {
            let Arena {
                nodes,
                tris,
                layout,
                ..
            } = &*arena;
            let bind = Arena::bind_group(&self.device, &self.pipes.arena_bgl, nodes, tris, layout);
            arena.bind = bind;
            arena.generation += 1;
        }
        let bytes = (nodes.len() + tris.len()) as u64 * 16;
        Ok(GpuMesh {
            ctx_id: self.id,
            node_base: node_base as u32,
            tri_base: tri_base as u32,
            depth,
            max_leaf,
            mesh: tree.mesh().clone(),
            grid,
            eps,
            host,
            bytes,
        })
    }
}
