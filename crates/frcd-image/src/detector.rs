//! The image-space detector: pipelines, uploaded meshes, per-query scratch and the query itself.

use crate::acs;
use crate::view::{View, ViewAxis};
use crate::{ImageContext, ImageError, Which};
use frcd_geom::{Aabb, DVec3, Pose, TriMesh};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32FloatStencil8;
const FACING_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R8Uint;
/// Facing code `fs_peel` writes for back faces (`select(2u, 1u, front)`; front faces write 1).
const BACK_CODE: u32 = 2;
/// With the view frame `(u, v, depth)` right-handed and depth growing away from the eye, a face
/// whose outward normal points at the eye (the ray enters the solid there) is clockwise in NDC,
/// i.e. a back face for `FrontFace::Ccw`.
const ENTERING_CODE: u32 = BACK_CODE;

static NEXT_DETECTOR_ID: AtomicU64 = AtomicU64::new(1);

/// Options of one query. Plain data with [`Default`].
#[derive(Clone, Debug, PartialEq)]
pub struct ImageOptions {
    /// Pixels across the longer lateral side of the overlap region (64..=2048 is the tested
    /// range; the device's texture and storage-buffer limits bound it). Default 256.
    pub resolution: u32,
    /// View axis rule. Default [`ViewAxis::Auto`] (the overlap box's shortest axis).
    pub view_axis: ViewAxis,
    /// Most surface layers peeled per mesh inside the overlap region before the query fails with
    /// [`ImageError::TooManyLayers`]. Default 64.
    pub max_layers: u32,
    /// Also compute the accurate colliding set (triangle ids of both meshes crossing interfering
    /// pixels). Default false.
    pub colliding_set: bool,
    /// Dilation, in pixels, of the interfering mask used for the colliding set: a triangle is
    /// reported when it crosses the `(2·dilation + 1)²` neighbourhood of an interfering pixel.
    /// Default 1 (covers the f32 and sub-pixel placement of edges).
    pub dilation: u32,
}

impl Default for ImageOptions {
    fn default() -> Self {
        Self {
            resolution: 256,
            view_axis: ViewAxis::Auto,
            max_layers: 64,
            colliding_set: false,
            dilation: 1,
        }
    }
}

/// A mesh uploaded once into GPU vertex (f32, relative to its box centre) and index buffers.
///
/// Created by [`ImageDetector::upload`], which refuses meshes that are not closed, manifold and
/// consistently oriented. Keeps a shared copy of the f64 mesh for the colliding set and the CPU
/// reference.
#[derive(Debug)]
pub struct ImageMesh {
    detector: u64,
    name: String,
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
    center: DVec3,
    aabb: Aabb,
    radius: f64,
    mesh: Arc<TriMesh>,
}

impl ImageMesh {
    /// The caller's label given at upload.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The f64 mesh as uploaded.
    pub fn mesh(&self) -> &TriMesh {
        &self.mesh
    }

    /// The local point vertices were uploaded relative to (the centre of the mesh's box).
    pub fn center(&self) -> DVec3 {
        self.center
    }

    /// Largest distance of a vertex from [`ImageMesh::center`].
    pub fn radius(&self) -> f64 {
        self.radius
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.index_count as usize / 3
    }
}

/// Error bounds of one query (A-frame units). See the crate documentation for the error model.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorBounds {
    /// Side of one pixel.
    pub pixel_size: f64,
    /// Bound on the depth error of any rasterized surface point: depth-buffer quantum plus f32
    /// rounding of vertices, matrices and interpolation, `2^-20 · (depth range + ρ)` where ρ is
    /// the meshes' radii plus their centres' distances from the image centre.
    pub depth: f64,
    /// Bound on the lateral displacement of any rasterized edge: `pixel_size / 16` (Vulkan's
    /// minimum of 4 sub-pixel bits) plus the f32 part of `depth`.
    pub lateral: f64,
    /// Solids farther apart than this never produce an interfering pixel:
    /// `2 · (depth + lateral)`.
    pub separation: f64,
    /// Interference is always detected when `A ∩ B` contains a ball of this radius:
    /// `pixel_size / √2 + separation`.
    pub detection_radius: f64,
}

/// A per-pixel image of one query (row-major, row 0 at the top, see [`View::pixel_center`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PixelImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// True where the pixel's centre ray is inside both solids at some depth.
    pub mask: Vec<bool>,
    /// Length of the pixel's centre ray inside both solids (A-frame units).
    pub lengths: Vec<f32>,
}

impl PixelImage {
    /// True when pixel `(column, row)` interferes.
    pub fn get(&self, column: u32, row: u32) -> bool {
        self.mask[(row * self.width + column) as usize]
    }
}

/// The accurate colliding set: triangles of A and of B crossing the dilated interfering mask,
/// ascending ids.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CollidingSet {
    /// Triangle indices into mesh A.
    pub tris_a: Vec<u32>,
    /// Triangle indices into mesh B.
    pub tris_b: Vec<u32>,
}

/// The answer of one query, in solid mode (one solid inside the other collides).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImageResult {
    /// True when some pixel's view ray is inside both solids.
    pub collide: bool,
    /// Number of interfering pixels.
    pub interfering_pixels: u64,
    /// Estimate of the volume of `A ∩ B`: sum over pixels of (length inside both) × pixel area.
    pub volume: f64,
    /// A-posteriori estimate of the volume's quadrature error: for each pixel, pixel area times
    /// half the largest length difference to a 4-neighbour, plus the depth bound on each
    /// interfering pixel. Not a guarantee: a feature narrower than a pixel can be missed whole.
    pub volume_error_estimate: f64,
    /// Per-pixel mask and lengths (empty when the boxes do not overlap).
    pub image: PixelImage,
    /// The view used (`None` when the boxes do not overlap and no GPU work was done).
    pub view: Option<View>,
    /// Surface layers peeled inside the region: `[of A, of B]`.
    pub layers: [u32; 2],
    /// Error bounds of this query.
    pub bounds: ErrorBounds,
    /// The accurate colliding set, when [`ImageOptions::colliding_set`] was asked for.
    pub colliding_set: Option<CollidingSet>,
}

/// Caller-owned per-query GPU state: square targets and buffers of the largest resolution used
/// so far, allocated once and reused by every query that fits (whatever the overlap's aspect
/// ratio); create one per thread with [`ImageScratch::default`].
#[derive(Debug, Default)]
pub struct ImageScratch {
    inner: Option<Scratch>,
    allocations: u32,
}

impl ImageScratch {
    /// Size `(width, height)` in pixels of the targets held now (`None` before the first query).
    pub fn capacity(&self) -> Option<(u32, u32)> {
        self.inner.as_ref().map(|s| (s.width, s.height))
    }

    /// How many times targets were allocated (once per larger resolution).
    pub fn allocations(&self) -> u32 {
        self.allocations
    }
}

#[derive(Debug)]
struct Chain {
    /// Ping-pong depth/stencil targets: layer L renders into `depth[L % 2]`.
    depth_views: [wgpu::TextureView; 2],
    facing_view: wgpu::TextureView,
    /// Bind group (peel pipeline, group 1) reading `depth[i]` as the previous layer.
    prev_bg: [wgpu::BindGroup; 2],
    /// Resolve bind group reading layer `depth[i]`.
    resolve_bg: [wgpu::BindGroup; 2],
    counters: wgpu::Buffer,
}

#[derive(Debug)]
struct Scratch {
    detector: u64,
    width: u32,
    height: u32,
    chains: [Chain; 2],
    draw: [wgpu::Buffer; 2],
    draw_bg: [wgpu::BindGroup; 2],
    params: wgpu::Buffer,
    lengths: wgpu::Buffer,
    mask: wgpu::Buffer,
    readback: wgpu::Buffer,
    counter_readback: wgpu::Buffer,
}

/// The image-space interference detector (Zou's method (c): CInDeR ray parity with depth and
/// stencil in the RECODE/Heidelberger box-overlap view volume). Holds the pipelines; meshes are
/// uploaded once with [`ImageDetector::upload`]; queries take `&self`.
#[derive(Debug)]
pub struct ImageDetector {
    ctx: ImageContext,
    id: u64,
    draw_bgl: wgpu::BindGroupLayout,
    prev_bgl: wgpu::BindGroupLayout,
    peel: wgpu::RenderPipeline,
    parity: wgpu::RenderPipeline,
    resolve: wgpu::ComputePipeline,
    /// Last field: the pipelines and the context are dropped under `frcd_gpu::creation_lock`.
    _release: frcd_gpu::ReleaseCreationLock,
}

/// Dropping a detector releases its pipelines and context under `frcd_gpu::creation_lock`
/// (NVIDIA's driver was seen to hang in `vkDestroyDevice` while other threads created devices).
impl Drop for ImageDetector {
    fn drop(&mut self) {
        frcd_gpu::hold_creation_lock_for_drop();
    }
}

/// The WGSL sources of the detector (also validated by a CPU-only naga test).
pub const RASTER_WGSL: &str = include_str!("../shaders/raster.wgsl");
/// The resolve compute shader.
pub const RESOLVE_WGSL: &str = include_str!("../shaders/resolve.wgsl");

use frcd_gpu::describe;

impl ImageDetector {
    /// Builds the pipelines on `ctx`'s device.
    pub fn new(ctx: ImageContext) -> Result<Self, ImageError> {
        let device = ctx.device().clone();
        // One creator at a time (NVIDIA's driver can hang on concurrent pipeline creation).
        let creating = frcd_gpu::creation_lock();
        // Shader translation failures (e.g. GLSL, which cannot textureLoad a depth texture)
        // are Internal errors, the rest Validation: capture both as a typed error.
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let internal = device.push_error_scope(wgpu::ErrorFilter::Internal);
        let raster = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("frcd-image raster"),
            source: wgpu::ShaderSource::Wgsl(frcd_gpu::with_prelude(RASTER_WGSL).into()),
        });
        let resolve_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("frcd-image resolve"),
            source: wgpu::ShaderSource::Wgsl(frcd_gpu::with_prelude(RESOLVE_WGSL).into()),
        });
        let draw_bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("frcd-image draw"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let prev_bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("frcd-image prev depth"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Depth,
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            }],
        });
        let peel_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("frcd-image peel"),
            bind_group_layouts: &[Some(&draw_bgl), Some(&prev_bgl)],
            immediate_size: 0,
        });
        let parity_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("frcd-image parity"),
            bind_group_layouts: &[Some(&draw_bgl)],
            immediate_size: 0,
        });
        let vertex_layout = wgpu::VertexBufferLayout {
            array_stride: 12,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &[wgpu::VertexAttribute {
                format: wgpu::VertexFormat::Float32x3,
                offset: 0,
                shader_location: 0,
            }],
        };
        let primitive = wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            front_face: wgpu::FrontFace::Ccw,
            cull_mode: None,
            ..Default::default()
        };
        let peel = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("frcd-image peel"),
            layout: Some(&peel_layout),
            vertex: wgpu::VertexState {
                module: &raster,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[Some(vertex_layout.clone())],
            },
            primitive,
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Less),
                stencil: wgpu::StencilState::default(),
                bias: wgpu::DepthBiasState::default(),
            }),
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &raster,
                entry_point: Some("fs_peel"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: FACING_FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        let invert = wgpu::StencilFaceState {
            compare: wgpu::CompareFunction::Always,
            fail_op: wgpu::StencilOperation::Keep,
            depth_fail_op: wgpu::StencilOperation::Keep,
            pass_op: wgpu::StencilOperation::Invert,
        };
        let parity = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("frcd-image parity"),
            layout: Some(&parity_layout),
            vertex: wgpu::VertexState {
                module: &raster,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[Some(vertex_layout)],
            },
            primitive,
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(false),
                depth_compare: Some(wgpu::CompareFunction::Less),
                stencil: wgpu::StencilState {
                    front: invert,
                    back: invert,
                    read_mask: 1,
                    write_mask: 1,
                },
                bias: wgpu::DepthBiasState::default(),
            }),
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &raster,
                entry_point: Some("fs_parity"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: FACING_FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::empty(),
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        let resolve = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("frcd-image resolve"),
            layout: None,
            module: &resolve_module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let internal = pollster::block_on(internal.pop());
        let failed = pollster::block_on(scope.pop()).or(internal);
        drop(creating);
        if let Some(e) = failed {
            return Err(ImageError::Gpu {
                stage: "pipeline creation",
                message: describe(&e),
            });
        }
        Ok(Self {
            ctx,
            id: NEXT_DETECTOR_ID.fetch_add(1, Ordering::Relaxed),
            draw_bgl,
            prev_bgl,
            peel,
            parity,
            resolve,
            _release: frcd_gpu::ReleaseCreationLock::default(),
        })
    }

    /// A detector on a headless device ([`ImageContext::headless`]).
    pub fn headless() -> Result<Self, ImageError> {
        Self::new(ImageContext::headless()?)
    }

    /// The context the detector runs on.
    pub fn context(&self) -> &ImageContext {
        &self.ctx
    }

    /// Uploads `mesh` once: vertices as f32 relative to the centre of its box, indices as u32.
    /// `name` labels the mesh in errors. Refuses meshes that are not closed, manifold and
    /// consistently oriented ([`ImageError::NotSolid`], with the topology report).
    pub fn upload(&self, name: &str, mesh: &TriMesh) -> Result<ImageMesh, ImageError> {
        self.upload_shared(name, Arc::new(mesh.clone()))
    }

    /// As [`ImageDetector::upload`], sharing the caller's `Arc` instead of copying the mesh.
    pub fn upload_shared(&self, name: &str, mesh: Arc<TriMesh>) -> Result<ImageMesh, ImageError> {
        check_solid(name, &mesh)?;
        let aabb = mesh.aabb();
        let center = aabb.center();
        let max = self.ctx.device().limits().max_buffer_size;
        let vbytes = mesh.vertex_count() as u64 * 12;
        let ibytes = mesh.triangle_count() as u64 * 12;
        if vbytes.max(ibytes) > max || mesh.triangle_count() > (u32::MAX / 3) as usize {
            return Err(ImageError::MeshTooLarge {
                name: name.to_string(),
                bytes: vbytes.max(ibytes),
                max,
            });
        }
        let mut radius = 0f64;
        let verts: Vec<[f32; 3]> = mesh
            .vertices()
            .iter()
            .map(|p| {
                let d = *p - center;
                radius = radius.max(d.length());
                [d.x as f32, d.y as f32, d.z as f32]
            })
            .collect();
        let idx: Vec<u32> = mesh.indices().iter().flatten().copied().collect();
        let device = self.ctx.device();
        let vertices = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frcd-image vertices"),
            size: vbytes,
            usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.ctx
            .queue()
            .write_buffer(&vertices, 0, bytemuck::cast_slice(&verts));
        let indices = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frcd-image indices"),
            size: ibytes,
            usage: wgpu::BufferUsages::INDEX | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.ctx
            .queue()
            .write_buffer(&indices, 0, bytemuck::cast_slice(&idx));
        Ok(ImageMesh {
            detector: self.id,
            name: name.to_string(),
            vertices,
            indices,
            index_count: idx.len() as u32,
            center,
            aabb,
            radius,
            mesh,
        })
    }

    /// Interference of solid `a` at `pose_a` with solid `b` at `pose_b` (solid mode).
    ///
    /// Works in A's local frame: B's pose relative to A is composed in f64, the view covers the
    /// overlap of A's box and B's box (see [`View`]); boxes that do not overlap answer at once
    /// without GPU work.
    pub fn query(
        &self,
        scratch: &mut ImageScratch,
        a: &ImageMesh,
        pose_a: &Pose,
        b: &ImageMesh,
        pose_b: &Pose,
        options: &ImageOptions,
    ) -> Result<ImageResult, ImageError> {
        for (m, w) in [(a, Which::A), (b, Which::B)] {
            if m.detector != self.id {
                return Err(ImageError::ForeignMesh { which: w });
            }
        }
        for (p, w) in [(pose_a, Which::A), (pose_b, Which::B)] {
            if !p.is_valid() {
                return Err(ImageError::InvalidPose { which: w });
            }
        }
        if options.resolution == 0 {
            return Err(ImageError::Resolution {
                requested: 0,
                reason: "must be at least 1".into(),
            });
        }
        let rel = pose_b.relative_to(pose_a);
        let Some((region, b_box)) = View::overlap(&a.aabb, &b.aabb, &rel) else {
            return Ok(ImageResult::default());
        };
        let view = View::new(
            region,
            &a.aabb,
            &b_box,
            options.view_axis,
            options.resolution,
        );
        let limits = self.ctx.device().limits();
        let (w, h) = (view.width, view.height);
        if w.max(h) > limits.max_texture_dimension_2d {
            return Err(ImageError::Resolution {
                requested: options.resolution,
                reason: format!(
                    "image {w}x{h} exceeds max_texture_dimension_2d {}",
                    limits.max_texture_dimension_2d
                ),
            });
        }
        let pixels = w as u64 * h as u64;
        if pixels * 4 > limits.max_storage_buffer_binding_size {
            return Err(ImageError::Resolution {
                requested: options.resolution,
                reason: format!(
                    "{pixels} pixels exceed max_storage_buffer_binding_size {}",
                    limits.max_storage_buffer_binding_size
                ),
            });
        }
        let bounds = self.bounds(&view, a, b, &rel);
        let device = self.ctx.device();
        let queue = self.ctx.queue();
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let internal = device.push_error_scope(wgpu::ErrorFilter::Internal);
        let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let outcome = self.run(scratch, &view, a, b, &rel, options);
        let oom = pollster::block_on(oom.pop());
        let internal = pollster::block_on(internal.pop());
        let val = pollster::block_on(scope.pop());
        if let Some(e) = oom.or(internal).or(val) {
            return Err(ImageError::Gpu {
                stage: "query",
                message: describe(&e),
            });
        }
        let (pixels, layers) = outcome?;
        let _ = queue;
        let Readback {
            lengths,
            mask,
            interfering: interfering_pixels,
            length_sum,
        } = pixels;
        let area = view.pixel_area();
        let volume = length_sum * area;
        let volume_error_estimate = volume_error_estimate(&lengths, w, h, area)
            + interfering_pixels as f64 * area * 4.0 * bounds.depth;
        let image = PixelImage {
            width: w,
            height: h,
            mask,
            lengths,
        };
        let colliding_set = options.colliding_set.then(|| {
            let (tris_a, tris_b) = acs::colliding_set(
                &view,
                &image,
                options.dilation,
                bounds.separation,
                a.mesh(),
                &Pose::IDENTITY,
                b.mesh(),
                &rel,
            );
            CollidingSet { tris_a, tris_b }
        });
        Ok(ImageResult {
            collide: interfering_pixels > 0,
            interfering_pixels,
            volume,
            volume_error_estimate,
            image,
            view: Some(view),
            layers,
            bounds,
            colliding_set,
        })
    }

    /// [`ImageDetector::query`] with a fresh scratch (allocates textures each call).
    pub fn query_once(
        &self,
        a: &ImageMesh,
        pose_a: &Pose,
        b: &ImageMesh,
        pose_b: &Pose,
        options: &ImageOptions,
    ) -> Result<ImageResult, ImageError> {
        self.query(&mut ImageScratch::default(), a, pose_a, b, pose_b, options)
    }

    fn bounds(&self, view: &View, a: &ImageMesh, b: &ImageMesh, rel: &Pose) -> ErrorBounds {
        let (iu, iv, iw) = view.axes();
        let mut c = DVec3::ZERO;
        c[iu] = view.u0 + 0.5 * view.width as f64 * view.pixel_size;
        c[iv] = view.v0 + 0.5 * view.height as f64 * view.pixel_size;
        c[iw] = 0.5 * (view.near + view.far);
        let rho = a.radius
            + b.radius
            + (a.center - c).length()
            + (rel.transform_point(b.center) - c).length()
            + view.pixel_size * (view.width.max(view.height) as f64);
        let f32_part = (view.far - view.near + rho) * 2f64.powi(-20);
        let depth = f32_part;
        let lateral = view.pixel_size / 16.0 + f32_part;
        let separation = 2.0 * (depth + lateral);
        ErrorBounds {
            pixel_size: view.pixel_size,
            depth,
            lateral,
            separation,
            detection_radius: view.pixel_size / std::f64::consts::SQRT_2 + separation,
        }
    }

    /// The scratch's targets are square, `side` pixels (the query's resolution) or more, and
    /// are kept for every later image that fits: a query renders into the `w × h` corner
    /// (viewport and scissor), so a changing overlap aspect ratio reallocates nothing.
    fn scratch<'s>(&self, scratch: &'s mut ImageScratch, w: u32, h: u32, side: u32) -> &'s Scratch {
        let fits = matches!(&scratch.inner, Some(s) if s.detector == self.id && s.width >= w && s.height >= h);
        if !fits {
            let side = side.max(w).max(h);
            scratch.inner = Some(self.make_scratch(side, side));
            scratch.allocations += 1;
        }
        scratch.inner.as_ref().expect("just made")
    }

    fn make_scratch(&self, w: u32, h: u32) -> Scratch {
        let device = self.ctx.device();
        let size = wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        };
        let pixels = w as u64 * h as u64;
        let storage = |label| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: pixels * 4,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let lengths = storage("frcd-image lengths");
        let mask = storage("frcd-image mask");
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frcd-image params"),
            size: 32,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let draw: [wgpu::Buffer; 2] = std::array::from_fn(|_| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("frcd-image draw"),
                size: 64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        });
        let draw_bg: [wgpu::BindGroup; 2] = std::array::from_fn(|i| {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("frcd-image draw"),
                layout: &self.draw_bgl,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: draw[i].as_entire_binding(),
                }],
            })
        });
        let resolve_bgl = self.resolve.get_bind_group_layout(0);
        let chains: [Chain; 2] = std::array::from_fn(|_| {
            let depth: [wgpu::Texture; 2] = std::array::from_fn(|_| {
                device.create_texture(&wgpu::TextureDescriptor {
                    label: Some("frcd-image depth"),
                    size,
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: DEPTH_FORMAT,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                        | wgpu::TextureUsages::TEXTURE_BINDING,
                    view_formats: &[],
                })
            });
            let facing = device.create_texture(&wgpu::TextureDescriptor {
                label: Some("frcd-image facing"),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: FACING_FORMAT,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            });
            let facing_view = facing.create_view(&Default::default());
            let aspect_view = |t: &wgpu::Texture, aspect| {
                t.create_view(&wgpu::TextureViewDescriptor {
                    aspect,
                    ..Default::default()
                })
            };
            let depth_only: [wgpu::TextureView; 2] =
                std::array::from_fn(|i| aspect_view(&depth[i], wgpu::TextureAspect::DepthOnly));
            let stencil_only: [wgpu::TextureView; 2] =
                std::array::from_fn(|i| aspect_view(&depth[i], wgpu::TextureAspect::StencilOnly));
            let counters = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("frcd-image counters"),
                size: 8,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let prev_bg = std::array::from_fn(|i| {
                device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("frcd-image prev"),
                    layout: &self.prev_bgl,
                    entries: &[wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::TextureView(&depth_only[i]),
                    }],
                })
            });
            let resolve_bg = std::array::from_fn(|i| {
                device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("frcd-image resolve"),
                    layout: &resolve_bgl,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: params.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 1,
                            resource: wgpu::BindingResource::TextureView(&depth_only[i]),
                        },
                        wgpu::BindGroupEntry {
                            binding: 2,
                            resource: wgpu::BindingResource::TextureView(&stencil_only[i]),
                        },
                        wgpu::BindGroupEntry {
                            binding: 3,
                            resource: wgpu::BindingResource::TextureView(&facing_view),
                        },
                        wgpu::BindGroupEntry {
                            binding: 4,
                            resource: lengths.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 5,
                            resource: mask.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 6,
                            resource: counters.as_entire_binding(),
                        },
                    ],
                })
            });
            Chain {
                depth_views: std::array::from_fn(|i| depth[i].create_view(&Default::default())),
                facing_view,
                prev_bg,
                resolve_bg,
                counters,
            }
        });
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frcd-image readback"),
            size: pixels * 8,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let counter_readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frcd-image counter readback"),
            size: 16,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Scratch {
            detector: self.id,
            width: w,
            height: h,
            chains,
            draw,
            draw_bg,
            params,
            lengths,
            mask,
            readback,
            counter_readback,
        }
    }

    /// Encodes and runs the peeling chains; returns raw lengths, mask and layer counts.
    #[allow(clippy::type_complexity)]
    fn run(
        &self,
        scratch: &mut ImageScratch,
        view: &View,
        a: &ImageMesh,
        b: &ImageMesh,
        rel: &Pose,
        options: &ImageOptions,
    ) -> Result<(Readback, [u32; 2]), ImageError> {
        let (w, h) = (view.width, view.height);
        let s = self.scratch(scratch, w, h, options.resolution);
        let device = self.ctx.device();
        let queue = self.ctx.queue();
        let mats = [
            view.clip_from_local(&Pose::IDENTITY, a.center),
            view.clip_from_local(rel, b.center),
        ];
        for (buf, m) in s.draw.iter().zip(&mats) {
            queue.write_buffer(buf, 0, bytemuck::cast_slice(m));
        }
        let region_depth = view.depth_of(view.region.min[view.axis]);
        let params = frcd_gpu::layout::ResolveParams {
            width: w,
            height: h,
            entering_code: ENTERING_CODE,
            _pad0: 0,
            depth_ref: region_depth as f32,
            depth_scale: (view.far - view.near) as f32,
            _pad1: 0.0,
            _pad2: 0.0,
        };
        queue.write_buffer(&s.params, 0, bytemuck::bytes_of(&params));
        // The first layer peels from just in front of the region: fragments of X in front of it
        // cannot be in A ∩ B (it lies inside both boxes); Y's faces there still count for parity.
        let start_depth = (region_depth - 2f64.powi(-16)).max(0.0) as f32;

        let meshes = [a, b];
        let mut enc = device.create_command_encoder(&Default::default());
        enc.clear_buffer(&s.lengths, 0, None);
        enc.clear_buffer(&s.mask, 0, None);
        for chain in &s.chains {
            // Layer 0 renders into depth[0] and reads depth[1] as "previous".
            let _ = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("frcd-image start depth"),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &chain.depth_views[1],
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(start_depth),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(0),
                        store: wgpu::StoreOp::Store,
                    }),
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
        }
        let mut active = [true, true];
        let mut layers = [0u32; 2];
        let groups = (w.div_ceil(8), h.div_ceil(8));
        for layer in 0..options.max_layers {
            let cur = (layer % 2) as usize;
            let prev = 1 - cur;
            for c in 0..2 {
                if !active[c] {
                    continue;
                }
                let (x, y) = (meshes[c], meshes[1 - c]);
                let chain = &s.chains[c];
                enc.clear_buffer(&chain.counters, 0, None);
                {
                    let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                        label: Some("frcd-image peel+parity"),
                        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                            view: &chain.facing_view,
                            depth_slice: None,
                            resolve_target: None,
                            ops: wgpu::Operations {
                                load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                                store: wgpu::StoreOp::Store,
                            },
                        })],
                        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                            view: &chain.depth_views[cur],
                            depth_ops: Some(wgpu::Operations {
                                load: wgpu::LoadOp::Clear(1.0),
                                store: wgpu::StoreOp::Store,
                            }),
                            stencil_ops: Some(wgpu::Operations {
                                load: wgpu::LoadOp::Clear(0),
                                store: wgpu::StoreOp::Store,
                            }),
                        }),
                        timestamp_writes: None,
                        occlusion_query_set: None,
                        multiview_mask: None,
                    });
                    pass.set_viewport(0.0, 0.0, w as f32, h as f32, 0.0, 1.0);
                    pass.set_scissor_rect(0, 0, w, h);
                    // Peel: the nearest surface of X strictly behind the previous layer.
                    pass.set_pipeline(&self.peel);
                    pass.set_bind_group(0, &s.draw_bg[c], &[]);
                    pass.set_bind_group(1, &chain.prev_bg[prev], &[]);
                    pass.set_vertex_buffer(0, x.vertices.slice(..));
                    pass.set_index_buffer(x.indices.slice(..), wgpu::IndexFormat::Uint32);
                    pass.draw_indexed(0..x.index_count, 0, 0..1);
                    // Parity: every face of Y in front of that layer flips stencil bit 0.
                    pass.set_pipeline(&self.parity);
                    pass.set_bind_group(0, &s.draw_bg[1 - c], &[]);
                    pass.set_vertex_buffer(0, y.vertices.slice(..));
                    pass.set_index_buffer(y.indices.slice(..), wgpu::IndexFormat::Uint32);
                    pass.draw_indexed(0..y.index_count, 0, 0..1);
                }
                {
                    let mut pass = enc.begin_compute_pass(&Default::default());
                    pass.set_pipeline(&self.resolve);
                    pass.set_bind_group(0, &chain.resolve_bg[cur], &[]);
                    pass.dispatch_workgroups(groups.0, groups.1, 1);
                }
                enc.copy_buffer_to_buffer(&chain.counters, 0, &s.counter_readback, c as u64 * 8, 8);
            }
            let index = queue.submit([enc.finish()]);
            let counts: Vec<u32> =
                bytemuck::cast_slice(&read_buffer(device, &s.counter_readback, 16, index)?)
                    .to_vec();
            for c in 0..2 {
                if active[c] {
                    if counts[2 * c] == 0 {
                        active[c] = false;
                    } else {
                        layers[c] += 1;
                    }
                }
            }
            enc = device.create_command_encoder(&Default::default());
            if !active[0] && !active[1] {
                break;
            }
        }
        if let Some(c) = (0..2).find(|&c| active[c]) {
            return Err(ImageError::TooManyLayers {
                which: if c == 0 { Which::A } else { Which::B },
                max_layers: options.max_layers,
            });
        }
        let bytes = w as u64 * h as u64 * 4;
        enc.copy_buffer_to_buffer(&s.lengths, 0, &s.readback, 0, bytes);
        enc.copy_buffer_to_buffer(&s.mask, 0, &s.readback, bytes, bytes);
        let index = queue.submit([enc.finish()]);
        // Decoded in place from the mapped buffer: at 2,048² pixels the copies and passes this
        // replaces cost more CPU time than the GPU's whole query on an H200.
        let pixels = frcd_gpu::read_back_with(device, &s.readback, bytes * 2, index, |raw| {
            Readback::decode(raw, (w * h) as usize)
        })
        .map_err(readback_error)?;
        Ok((pixels, layers))
    }
}

/// The image as read back, decoded in one pass.
struct Readback {
    /// Length inside both solids per pixel, 0 where the mask is clear.
    lengths: Vec<f32>,
    /// Interfering pixels.
    mask: Vec<bool>,
    /// How many pixels interfere.
    interfering: u64,
    /// Σ lengths in f64, summed in pixel order.
    length_sum: f64,
}

impl Readback {
    /// `raw` holds `pixels` f32 lengths, then `pixels` u32 mask words (non-zero: interfering).
    fn decode(raw: &[u8], pixels: usize) -> Self {
        let (len_bytes, mask_bytes) = raw.split_at(pixels * 4);
        // The mapped range is aligned (wgpu maps at 8-byte alignment); copy only if it is not.
        let lengths_in: std::borrow::Cow<[f32]> = match bytemuck::try_cast_slice(len_bytes) {
            Ok(v) => v.into(),
            Err(_) => bytemuck::pod_collect_to_vec(len_bytes).into(),
        };
        let mask_in: std::borrow::Cow<[u32]> = match bytemuck::try_cast_slice(mask_bytes) {
            Ok(v) => v.into(),
            Err(_) => bytemuck::pod_collect_to_vec(mask_bytes).into(),
        };
        // Separate passes over exact-size iterators vectorise; the f64 sum stays in pixel order.
        let lengths: Vec<f32> = lengths_in
            .iter()
            .zip(mask_in.iter())
            .map(|(&l, &m)| if m != 0 { l } else { 0.0 })
            .collect();
        let mask: Vec<bool> = mask_in.iter().map(|&m| m != 0).collect();
        let interfering = mask.iter().map(|&m| u64::from(m)).sum();
        let length_sum = lengths.iter().fold(-0.0f64, |s, &l| s + l as f64);
        Self {
            lengths,
            mask,
            interfering,
            length_sum,
        }
    }
}

/// Ok when `mesh` is a closed, manifold, consistently oriented surface (what ray parity needs);
/// otherwise [`ImageError::NotSolid`] with its topology report. [`ImageDetector::upload`] calls it.
pub fn check_solid(name: &str, mesh: &TriMesh) -> Result<(), ImageError> {
    let topology = mesh.topology();
    if topology.is_closed_oriented_manifold() {
        Ok(())
    } else {
        Err(ImageError::NotSolid {
            name: name.to_string(),
            topology: Box::new(topology.clone()),
        })
    }
}

/// Maps `size` bytes of `buffer` after submission `index`, waiting for that submission only
/// (not for an engine's other work on the device).
fn read_buffer(
    device: &wgpu::Device,
    buffer: &wgpu::Buffer,
    size: u64,
    index: wgpu::SubmissionIndex,
) -> Result<Vec<u8>, ImageError> {
    frcd_gpu::read_back(device, buffer, size, index).map_err(readback_error)
}

/// A failed readback as a typed error with its whole cause chain.
fn readback_error(e: frcd_gpu::SetupError) -> ImageError {
    let mut message = e.to_string();
    let mut src = std::error::Error::source(&e);
    while let Some(s) = src {
        message.push_str(&format!(": {s}"));
        src = s.source();
    }
    ImageError::Gpu {
        stage: "readback",
        message,
    }
}

/// Σ over pixels of `area · ½ · max |ℓ_i − ℓ_j|` over 4-neighbours j (outside the image counts
/// as 0): the midpoint rule's error where the length varies, largest at the projected rim.
/// Rows are walked as slices (no per-neighbour bounds test); the sum runs in pixel order, as
/// in [`volume_error_estimate_reference`], so the two agree bit for bit.
fn volume_error_estimate(lengths: &[f32], w: u32, h: u32, area: f64) -> f64 {
    let w = w as usize;
    if w == 0 {
        return 0.0;
    }
    let rows: Vec<&[f32]> = lengths.chunks_exact(w).take(h as usize).collect();
    let zeros = vec![0.0f32; w];
    // Each row's maxima first (independent per pixel, so they vectorise), then the sum in
    // pixel order.
    let mut m = vec![0.0f64; w];
    let mut sum = 0.0;
    let diff = |a: f32, b: f32| (a as f64 - b as f64).abs();
    for (y, row) in rows.iter().enumerate() {
        let up: &[f32] = if y > 0 { rows[y - 1] } else { &zeros };
        let down: &[f32] = rows.get(y + 1).copied().unwrap_or(&zeros);
        for (((m, &l), &u), &d) in m.iter_mut().zip(row.iter()).zip(up).zip(down) {
            *m = 0.0f64.max(diff(l, d)).max(diff(l, u));
        }
        // Right neighbours (the last pixel's is outside: 0), then left ones.
        for (m, pair) in m.iter_mut().zip(row.windows(2)) {
            *m = m.max(diff(pair[0], pair[1]));
        }
        m[w - 1] = m[w - 1].max(diff(row[w - 1], 0.0));
        for (m, pair) in m[1..].iter_mut().zip(row.windows(2)) {
            *m = m.max(diff(pair[1], pair[0]));
        }
        m[0] = m[0].max(diff(row[0], 0.0));
        for &v in &m {
            sum += 0.5 * v;
        }
    }
    sum * area
}

/// The per-pixel form of [`volume_error_estimate`], kept as its test oracle.
#[cfg(test)]
fn volume_error_estimate_reference(lengths: &[f32], w: u32, h: u32, area: f64) -> f64 {
    let (w, h) = (w as i64, h as i64);
    let at = |x: i64, y: i64| -> f64 {
        if x < 0 || y < 0 || x >= w || y >= h {
            0.0
        } else {
            lengths[(y * w + x) as usize] as f64
        }
    };
    let mut sum = 0.0;
    for y in 0..h {
        for x in 0..w {
            let l = at(x, y);
            let m = [(1, 0), (-1, 0), (0, 1), (0, -1)]
                .iter()
                .map(|(dx, dy)| (l - at(x + dx, y + dy)).abs())
                .fold(0.0, f64::max);
            sum += 0.5 * m;
        }
    }
    sum * area
}

#[cfg(test)]
mod readback_tests {
    use super::*;

    fn lcg(seed: &mut u64) -> u64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        *seed >> 33
    }

    /// The one-pass decode equals the old path (copy, then mask, zeroed lengths, count, sum),
    /// bit for bit, on images with garbage lengths under clear mask words.
    #[test]
    fn decode_equals_the_copying_path() {
        let mut seed = 7;
        for (w, h) in [(1, 1), (3, 1), (1, 5), (37, 23), (256, 129)] {
            let n = w * h;
            let lengths: Vec<f32> = (0..n)
                .map(|_| lcg(&mut seed) as f32 / 7.0e8 - 1.0)
                .collect();
            let words: Vec<u32> = (0..n).map(|_| (lcg(&mut seed) % 3) as u32 * 5).collect();
            let mut raw: Vec<u8> = bytemuck::cast_slice(&lengths).to_vec();
            raw.extend_from_slice(bytemuck::cast_slice(&words));
            let got = Readback::decode(&raw, n);
            let mask: Vec<bool> = words.iter().map(|m| *m != 0).collect();
            let want: Vec<f32> = lengths
                .iter()
                .zip(&mask)
                .map(|(l, m)| if *m { *l } else { 0.0 })
                .collect();
            assert_eq!(got.mask, mask);
            assert_eq!(got.lengths, want);
            assert_eq!(got.interfering, mask.iter().filter(|m| **m).count() as u64);
            let sum = want.iter().map(|l| *l as f64).sum::<f64>();
            assert_eq!(got.length_sum.to_bits(), sum.to_bits(), "{w}x{h}");
            // An unaligned buffer decodes the same (the copying fallback).
            let mut shifted = vec![0u8];
            shifted.extend_from_slice(&raw);
            let again = Readback::decode(&shifted[1..], n);
            assert_eq!(again.lengths, want);
        }
    }

    /// The row-slice estimate equals the per-pixel reference bit for bit, borders, thin
    /// images and NaN lengths included.
    #[test]
    fn error_estimate_equals_the_reference() {
        let mut seed = 11;
        for (w, h) in [(1, 1), (1, 7), (9, 1), (2, 2), (64, 33), (129, 70)] {
            let mut lengths: Vec<f32> = (0..w * h)
                .map(|_| match lcg(&mut seed) % 4 {
                    0 => 0.0,
                    _ => lcg(&mut seed) as f32 / 1.0e9,
                })
                .collect();
            if w * h > 3 {
                lengths[2] = f32::NAN;
            }
            let (w, h) = (w as u32, h as u32);
            let fast = volume_error_estimate(&lengths, w, h, 0.25);
            let reference = volume_error_estimate_reference(&lengths, w, h, 0.25);
            assert_eq!(fast.to_bits(), reference.to_bits(), "{w}x{h}");
        }
    }
}
