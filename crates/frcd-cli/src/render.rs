//! `frcd render`: an offscreen wgpu picture of one frame, flat shaded, interfering triangles in
//! red, bodies contained in another in orange; written as PNG.

use anyhow::{Context, Result, bail};
use frcd_geom::{Aabb, DVec3, Pose};
use frcd_io::Scene;
use glam::{DMat4, Mat4};
use std::path::Path;

/// What to highlight on one body.
pub struct Marks {
    /// Per triangle: part of a touching pair.
    pub triangles: Vec<bool>,
    /// The body lies inside another (or holds one), without surface contact.
    pub contained: bool,
}

const SHADER: &str = r#"
struct U { m: mat4x4<f32> };
@group(0) @binding(0) var<uniform> u: U;
struct V { @builtin(position) pos: vec4<f32>, @location(0) color: vec3<f32> };
@vertex fn vs(@location(0) p: vec3<f32>, @location(1) c: vec3<f32>) -> V {
    var o: V;
    o.pos = u.m * vec4<f32>(p, 1.0);
    o.color = c;
    return o;
}
@fragment fn fs(v: V) -> @location(0) vec4<f32> { return vec4<f32>(v.color, 1.0); }
"#;

const PALETTE: [[f32; 3]; 8] = [
    [0.55, 0.62, 0.72],
    [0.62, 0.66, 0.55],
    [0.70, 0.62, 0.50],
    [0.58, 0.55, 0.70],
    [0.50, 0.68, 0.66],
    [0.70, 0.58, 0.62],
    [0.64, 0.64, 0.64],
    [0.52, 0.60, 0.52],
];

/// Renders `poses` of `scene` to `output` (PNG, `width` x `height`).
pub fn render_png(
    scene: &Scene,
    poses: &[Pose],
    marks: &[Marks],
    width: u32,
    height: u32,
    frame_all: bool,
    output: &Path,
) -> Result<()> {
    let bodies = scene.bodies();
    // Framing: the moving bodies (a long track would make the assembly a dot), or everything.
    let mut focus = Aabb::EMPTY;
    let mut everything = Aabb::EMPTY;
    for (b, p) in bodies.iter().zip(poses) {
        let bx = b.mesh.aabb().transformed(p);
        everything = everything.union(&bx);
        if frame_all || !b.is_static {
            focus = focus.union(&bx);
        }
    }
    if focus.is_empty() {
        focus = everything;
    }
    let assembly_center = focus.center();
    // With interference, frame the bodies involved and look from the side of the contact.
    let mut hot_focus = Aabb::EMPTY;
    let (mut hot_sum, mut hot_n) = (DVec3::ZERO, 0usize);
    if !frame_all {
        for ((b, p), m) in bodies.iter().zip(poses).zip(marks) {
            let mut any = m.contained;
            for (t, tri) in b.mesh.triangles().enumerate() {
                if m.triangles.get(t).copied().unwrap_or(false) {
                    any = true;
                    hot_sum += p.transform_point((tri.v[0] + tri.v[1] + tri.v[2]) / 3.0);
                    hot_n += 1;
                }
            }
            if any && !b.is_static {
                hot_focus = hot_focus.union(&b.mesh.aabb().transformed(p));
            }
        }
    }
    let mut dir = DVec3::new(0.9, -1.3, 0.8);
    if !hot_focus.is_empty() {
        focus = hot_focus;
        if hot_n > 0 {
            let c = hot_sum / hot_n as f64;
            if c.y > assembly_center.y {
                dir.y = -dir.y;
            }
            dir.z = 0.45;
        }
    }
    if focus.is_empty() {
        bail!("the scene has no geometry to render");
    }
    let center = focus.center();
    let radius = focus.half_extents().length().max(1e-9);
    // Vertices relative to the focus centre, in f32, shading baked per face.
    let light = DVec3::new(0.4, -0.5, 0.75).normalize();
    let mut verts: Vec<f32> = Vec::new();
    let mut hot: Vec<f32> = Vec::new();
    for (i, ((b, p), m)) in bodies.iter().zip(poses).zip(marks).enumerate() {
        let base = if b.is_static {
            [0.45, 0.45, 0.47]
        } else if m.contained {
            [0.95, 0.55, 0.15]
        } else {
            PALETTE[i % PALETTE.len()]
        };
        for (t, tri) in b.mesh.triangles().enumerate() {
            let w: Vec<DVec3> = tri
                .v
                .iter()
                .map(|&v| p.transform_point(v) - center)
                .collect();
            let n = (w[1] - w[0]).cross(w[2] - w[0]).normalize_or_zero();
            let shade = (0.3 + 0.7 * n.dot(light).abs()) as f32;
            let is_hot = m.triangles.get(t).copied().unwrap_or(false);
            let color = if is_hot { [1.0, 0.08, 0.05] } else { base };
            let dst = if is_hot { &mut hot } else { &mut verts };
            for v in &w {
                dst.extend_from_slice(&[v.x as f32, v.y as f32, v.z as f32]);
                dst.extend_from_slice(&[color[0] * shade, color[1] * shade, color[2] * shade]);
            }
        }
    }
    // Interfering triangles are drawn last and without depth test: the contact is usually
    // hidden between parts (a brake block inside the wheel), so it shows through them.
    let solid_count = (verts.len() / 6) as u32;
    verts.extend_from_slice(&hot);
    let vertex_count = (verts.len() / 6) as u32;
    // Camera: three-quarter view from front-right and above, perspective framing the focus box.
    let aspect = width as f64 / height as f64;
    let fov_y = 30f64.to_radians();
    let half = (fov_y / 2.0).tan().min((fov_y / 2.0).tan() * aspect);
    let dist = radius / half.atan().sin() * 1.05;
    let dir = dir.normalize();
    let eye = dir * dist;
    let view = DMat4::look_at_rh(eye, DVec3::ZERO, DVec3::Z);
    let near = (dist - 2.0 * radius).max(dist * 0.02);
    let far = dist
        + (everything.half_extents().length() + (everything.center() - center).length()) * 2.0
        + radius;
    let proj = DMat4::perspective_rh(fov_y, aspect, near, far);
    let m: Mat4 = (proj * view).as_mat4();
    let pixels = draw(&verts, solid_count, vertex_count, m, width, height)?;
    // Encoded in memory, then written atomically: a failed write never leaves a broken PNG.
    let mut bytes = Vec::new();
    let mut enc = png::Encoder::new(&mut bytes, width, height);
    enc.set_color(png::ColorType::Rgba);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header().context("cannot encode the PNG")?;
    w.write_image_data(&pixels)
        .context("cannot encode the PNG")?;
    w.finish().context("cannot encode the PNG")?;
    frcd_io::write_atomic(output, &bytes)?;
    Ok(())
}

fn draw(
    verts: &[f32],
    solid_count: u32,
    count: u32,
    m: Mat4,
    width: u32,
    height: u32,
) -> Result<Vec<u8>> {
    use wgpu::util::DeviceExt;
    // Device setup and readback are frcd-gpu's (shared with the GPU backends).
    let adapter = frcd_gpu::request_adapter(&frcd_gpu::AdapterOptions::default())
        .context("no GPU adapter for rendering")?;
    let (device, queue) = frcd_gpu::request_device(
        &adapter,
        "frcd render",
        wgpu::Features::empty(),
        wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
    )
    .context("cannot create a GPU device for rendering")?;
    let max = device.limits().max_texture_dimension_2d;
    if width > max || height > max {
        bail!("image size {width}x{height} exceeds the device's texture limit {max}");
    }
    // All three filters: a driver may fail a pipeline with an internal error rather than a
    // validation one (as NVIDIA's GL through EGL did with frcd-gpgpu's on an H200), and an
    // error no scope catches panics in wgpu's default handler.
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let internal = device.push_error_scope(wgpu::ErrorFilter::Internal);
    let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("frcd render"),
        source: wgpu::ShaderSource::Wgsl(SHADER.into()),
    });
    let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("frcd render matrix"),
        contents: bytemuck::cast_slice(&m.to_cols_array()),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    // An empty scene still needs a non-empty buffer.
    let data: &[f32] = if verts.is_empty() { &[0.0; 6] } else { verts };
    let vbuf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("frcd render vertices"),
        contents: bytemuck::cast_slice(data),
        usage: wgpu::BufferUsages::VERTEX,
    });
    let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: None,
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
    let bg = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &bgl,
        entries: &[wgpu::BindGroupEntry {
            binding: 0,
            resource: uniform.as_entire_binding(),
        }],
    });
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: None,
        bind_group_layouts: &[Some(&bgl)],
        immediate_size: 0,
    });
    let color_format = wgpu::TextureFormat::Rgba8Unorm;
    let depth_format = wgpu::TextureFormat::Depth32Float;
    let make_pipeline = |compare: wgpu::CompareFunction| {
        device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("frcd render"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &shader,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: 24,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3],
                })],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                cull_mode: None,
                ..Default::default()
            },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: depth_format,
                depth_write_enabled: Some(true),
                depth_compare: Some(compare),
                stencil: wgpu::StencilState::default(),
                bias: wgpu::DepthBiasState::default(),
            }),
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &shader,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: color_format,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        })
    };
    let pipeline = make_pipeline(wgpu::CompareFunction::LessEqual);
    let xray = make_pipeline(wgpu::CompareFunction::Always);
    let size = wgpu::Extent3d {
        width,
        height,
        depth_or_array_layers: 1,
    };
    let target = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("frcd render color"),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: color_format,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let depth = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("frcd render depth"),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: depth_format,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
        view_formats: &[],
    });
    let target_view = target.create_view(&Default::default());
    let depth_view = depth.create_view(&Default::default());
    let row = (width * 4).div_ceil(256) * 256;
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("frcd render readback"),
        size: row as u64 * height as u64,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut enc = device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("frcd render"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &target_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color {
                        r: 0.93,
                        g: 0.94,
                        b: 0.96,
                        a: 1.0,
                    }),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &depth_view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        if count > 0 {
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bg, &[]);
            pass.set_vertex_buffer(0, vbuf.slice(..));
            pass.draw(0..solid_count, 0..1);
            if count > solid_count {
                pass.set_pipeline(&xray);
                pass.draw(solid_count..count, 0..1);
            }
        }
    }
    enc.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture: &target,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &readback,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(height),
            },
        },
        size,
    );
    let index = queue.submit([enc.finish()]);
    let oom = pollster::block_on(oom.pop());
    let internal = pollster::block_on(internal.pop());
    if let Some(e) = oom.or(internal).or(pollster::block_on(scope.pop())) {
        bail!("GPU rendering failed: {}", frcd_gpu::describe(&e));
    }
    let mapped = frcd_gpu::read_back(&device, &readback, readback.size(), index)
        .context("GPU readback failed")?;
    let mut pixels = Vec::with_capacity((width * height * 4) as usize);
    for y in 0..height as usize {
        let start = y * row as usize;
        pixels.extend_from_slice(&mapped[start..start + width as usize * 4]);
    }
    Ok(pixels)
}
