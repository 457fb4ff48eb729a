use crate::pack::{PackedTree, TexLayout, TexLimits, pack_tree};
use crate::{GpuContext, GpuError};
use frcd_geom::Triangle;
use frcd_obb::ObbTree;
use std::sync::atomic::{AtomicU64, Ordering};

static NEXT_MESH_ID: AtomicU64 = AtomicU64::new(1);

/// Options of [`GpuContext::upload_with`]: caps on the texture size below the device's limits
/// (to test the row / layer splitting on small meshes). `None`: the device's limit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UploadOptions {
    /// Most texels per texture row.
    pub max_texture_width: Option<u32>,
    /// Most rows per texture layer.
    pub max_texture_rows: Option<u32>,
}

/// One body's OBB tree and triangles resident on the GPU (uploaded once), plus the f64
/// triangles the CPU needs to re-decide uncertain pairs.
pub struct GpuMesh {
    pub(crate) ctx_id: u64,
    pub(crate) id: u64,
    pub(crate) node_view: wgpu::TextureView,
    pub(crate) tri_view: wgpu::TextureView,
    pub(crate) info: wgpu::Buffer,
    pub(crate) depth: u32,
    pub(crate) node_layout: TexLayout,
    pub(crate) tri_layout: TexLayout,
    pub(crate) triangles: Vec<Triangle>,
    bytes: u64,
}

impl std::fmt::Debug for GpuMesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuMesh")
            .field("triangles", &self.triangles.len())
            .field("depth", &self.depth)
            .field("node_layout", &self.node_layout)
            .field("tri_layout", &self.tri_layout)
            .finish()
    }
}

impl GpuMesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }
    /// Depth of the tree (a single leaf: 1).
    pub fn depth(&self) -> u32 {
        self.depth
    }
    /// Placement of the nodes in their texture (rows, layers).
    pub fn node_layout(&self) -> TexLayout {
        self.node_layout
    }
    /// Placement of the triangles in their texture.
    pub fn triangle_layout(&self) -> TexLayout {
        self.tri_layout
    }
    /// Bytes uploaded for this mesh (both textures and the description).
    pub fn uploaded_bytes(&self) -> u64 {
        self.bytes
    }
}

fn upload_texture(
    ctx: &GpuContext,
    label: &str,
    layout: &TexLayout,
    texels: &[[f32; 4]],
) -> wgpu::TextureView {
    let size = wgpu::Extent3d {
        width: layout.width(),
        height: layout.rows_per_layer,
        depth_or_array_layers: layout.layers,
    };
    let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba32Float,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    ctx.queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture: &texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        bytemuck::cast_slice(texels),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(layout.width() * 16),
            rows_per_image: Some(layout.rows_per_layer),
        },
        size,
    );
    texture.create_view(&wgpu::TextureViewDescriptor {
        label: Some(label),
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    })
}

impl GpuContext {
    /// Uploads a tree (nodes and triangles, local frame, f32 rounded outward) once; queries then
    /// upload only poses.
    pub fn upload(&self, tree: &ObbTree) -> Result<GpuMesh, GpuError> {
        self.upload_with(tree, &UploadOptions::default())
    }

    /// [`GpuContext::upload`] with texture-size caps.
    pub fn upload_with(
        &self,
        tree: &ObbTree,
        options: &UploadOptions,
    ) -> Result<GpuMesh, GpuError> {
        let dim = self.limits.max_texture_dimension_2d;
        let limits = TexLimits {
            max_width: options.max_texture_width.map_or(dim, |w| w.min(dim)),
            max_rows: options.max_texture_rows.map_or(dim, |r| r.min(dim)),
            max_layers: self.limits.max_texture_array_layers,
        };
        let PackedTree {
            nodes,
            node_layout,
            tris,
            tri_layout,
            depth,
        } = pack_tree(tree, &limits)?;
        let node_view = upload_texture(self, "frcd-gpgpu nodes", &node_layout, &nodes);
        let tri_view = upload_texture(self, "frcd-gpgpu triangles", &tri_layout, &tris);
        let info_words: [u32; 8] = {
            let n = node_layout.uniform(tree.nodes().len() as u32, depth);
            let t = tri_layout.uniform(tree.triangles().len() as u32, 0);
            [n[0], n[1], n[2], n[3], t[0], t[1], t[2], t[3]]
        };
        let info = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frcd-gpgpu mesh info"),
            size: 32,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.queue
            .write_buffer(&info, 0, bytemuck::cast_slice(&info_words));
        let bytes = (nodes.len() + tris.len()) as u64 * 16 + 32;
        Ok(GpuMesh {
            ctx_id: self.id,
            id: NEXT_MESH_ID.fetch_add(1, Ordering::Relaxed),
            node_view,
            tri_view,
            info,
            depth,
            node_layout,
            tri_layout,
            triangles: tree.triangles().to_vec(),
            bytes,
        })
    }
}
