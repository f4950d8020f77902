//! The wgpu renderer: lit meshes with transparency, line lists, and an offscreen path.
//!
//! [`Renderer`] is embeddable: the host owns the device, queue and render pass, calls
//! [`Renderer::prepare`] before the pass and [`Renderer::paint`] inside it. It knows nothing
//! of egui; the app wraps it in an `egui_wgpu` callback. [`offscreen`] creates its own
//! headless device and renders a [`Scene`] to RGBA or PNG.

pub mod offscreen;

use crate::mesh::Mesh;
use crate::mesh::MeshError;
use crate::scene::Scene;
use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use std::sync::Arc;
use wgpu::util::DeviceExt;

/// Most objects one frame may draw.
pub const OBJECTS_MAX: usize = 1 << 16;
/// Most line segments one frame may draw.
pub const LINES_MAX: usize = 1 << 20;

/// Why a scene could not be prepared for drawing.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PrepareError {
    /// An object's mesh is malformed.
    #[error("object {object_idx}: {source}")]
    Mesh {
        /// Index of the object.
        object_idx: usize,
        /// What is wrong with its mesh.
        source: MeshError,
    },
    /// More objects than [`OBJECTS_MAX`].
    #[error("{0} objects exceed the limit {OBJECTS_MAX}")]
    TooManyObjects(usize),
    /// More lines than [`LINES_MAX`].
    #[error("{0} lines exceed the limit {LINES_MAX}")]
    TooManyLines(usize),
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct MeshVertex {
    position: [f32; 3],
    normal: [f32; 3],
    colour: [f32; 4],
    /// The mesh's ambient colour, or the vertex colour when it has none.
    ambient: [f32; 3],
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct LineVertex {
    position: [f32; 3],
    colour: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Globals {
    view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    light_towards: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ObjectUniform {
    world_from_object: [[f32; 4]; 4],
    normal_matrix: [[f32; 4]; 4],
    material: [f32; 4],
    opacity: [f32; 4],
}

/// GPU copies of one object's mesh and uniforms.
struct GpuObject {
    mesh: Arc<Mesh>,
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    n_indices: u32,
    uniform: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

/// Draws [`Scene`]s into a host's render pass.
pub struct Renderer {
    opaque: wgpu::RenderPipeline,
    transparent_back: wgpu::RenderPipeline,
    transparent_front: wgpu::RenderPipeline,
    lines: wgpu::RenderPipeline,
    globals: wgpu::Buffer,
    globals_bind_group: wgpu::BindGroup,
    object_layout: wgpu::BindGroupLayout,
    objects: Vec<GpuObject>,
    /// Opaque object indexes first, then transparent ones far to near.
    draw_order: Vec<usize>,
    n_opaque: usize,
    line_buffer: Option<(wgpu::Buffer, u32)>,
}

fn uniform_layout(device: &wgpu::Device, label: &str) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries: &[wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        }],
    })
}

/// What differs between the renderer's pipelines.
struct PipelineKind<'a> {
    label: &'a str,
    module: &'a wgpu::ShaderModule,
    layout: &'a wgpu::PipelineLayout,
    buffers: &'a [Option<wgpu::VertexBufferLayout<'a>>],
    topology: wgpu::PrimitiveTopology,
    cull_mode: Option<wgpu::Face>,
    blend: bool,
    depth_write: bool,
}

fn pipeline(
    device: &wgpu::Device,
    colour: wgpu::TextureFormat,
    depth: Option<wgpu::TextureFormat>,
    k: PipelineKind<'_>,
) -> wgpu::RenderPipeline {
    let blend = if k.blend {
        wgpu::BlendState {
            color: wgpu::BlendComponent {
                src_factor: wgpu::BlendFactor::SrcAlpha,
                dst_factor: wgpu::BlendFactor::OneMinusSrcAlpha,
                operation: wgpu::BlendOperation::Add,
            },
            alpha: wgpu::BlendComponent {
                src_factor: wgpu::BlendFactor::One,
                dst_factor: wgpu::BlendFactor::OneMinusSrcAlpha,
                operation: wgpu::BlendOperation::Add,
            },
        }
    } else {
        wgpu::BlendState::REPLACE
    };
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(k.label),
        layout: Some(k.layout),
        vertex: wgpu::VertexState {
            module: k.module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: k.buffers,
        },
        primitive: wgpu::PrimitiveState {
            topology: k.topology,
            front_face: wgpu::FrontFace::Ccw,
            cull_mode: k.cull_mode,
            ..Default::default()
        },
        depth_stencil: depth.map(|format| wgpu::DepthStencilState {
            format,
            depth_write_enabled: Some(k.depth_write),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: k.module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: colour,
                blend: Some(blend),
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

impl Renderer {
    /// Builds the pipelines for a colour target `format` and an optional depth format
    /// (without depth, meshes are drawn in order with no occlusion test).
    pub fn new(
        device: &wgpu::Device,
        _queue: &wgpu::Queue,
        format: wgpu::TextureFormat,
        depth: Option<wgpu::TextureFormat>,
    ) -> Self {
        let mesh_module = device.create_shader_module(wgpu::include_wgsl!("shaders/mesh.wgsl"));
        let line_module = device.create_shader_module(wgpu::include_wgsl!("shaders/line.wgsl"));
        let globals_layout = uniform_layout(device, "render globals");
        let object_layout = uniform_layout(device, "render object");
        let mesh_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("render mesh"),
            bind_group_layouts: &[Some(&globals_layout), Some(&object_layout)],
            immediate_size: 0,
        });
        let line_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("render lines"),
            bind_group_layouts: &[Some(&globals_layout)],
            immediate_size: 0,
        });
        let mesh_attrs = wgpu::vertex_attr_array![
            0 => Float32x3, 1 => Float32x3, 2 => Float32x4, 3 => Float32x3
        ];
        let mesh_buffers = [Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<MeshVertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &mesh_attrs,
        })];
        let line_attrs = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x4];
        let line_buffers = [Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<LineVertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &line_attrs,
        })];
        let mesh_kind = |label, cull_mode, blend, depth_write| PipelineKind {
            label,
            module: &mesh_module,
            layout: &mesh_layout,
            buffers: &mesh_buffers,
            topology: wgpu::PrimitiveTopology::TriangleList,
            cull_mode,
            blend,
            depth_write,
        };
        let opaque = pipeline(
            device,
            format,
            depth,
            mesh_kind("render opaque", None, false, true),
        );
        // Transparent objects draw their far side first, then their near side.
        let transparent_back = pipeline(
            device,
            format,
            depth,
            mesh_kind(
                "render transparent back",
                Some(wgpu::Face::Front),
                true,
                false,
            ),
        );
        let transparent_front = pipeline(
            device,
            format,
            depth,
            mesh_kind(
                "render transparent front",
                Some(wgpu::Face::Back),
                true,
                false,
            ),
        );
        let lines = pipeline(
            device,
            format,
            depth,
            PipelineKind {
                label: "render lines",
                module: &line_module,
                layout: &line_layout,
                buffers: &line_buffers,
                topology: wgpu::PrimitiveTopology::LineList,
                cull_mode: None,
                blend: true,
                depth_write: true,
            },
        );
        let globals = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("render globals"),
            size: std::mem::size_of::<Globals>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let globals_bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("render globals"),
            layout: &globals_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: globals.as_entire_binding(),
            }],
        });
        Self {
            opaque,
            transparent_back,
            transparent_front,
            lines,
            globals,
            globals_bind_group,
            object_layout,
            objects: Vec::new(),
            draw_order: Vec::new(),
            n_opaque: 0,
            line_buffer: None,
        }
    }

    /// Uploads what changed in `scene` for a target of `size_px` pixels and sorts the draws.
    ///
    /// Meshes are uploaded again only when an object's `Arc<Mesh>` is a different allocation.
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
        size_px: [u32; 2],
    ) -> Result<(), PrepareError> {
        if scene.objects.len() > OBJECTS_MAX {
            return Err(PrepareError::TooManyObjects(scene.objects.len()));
        }
        if scene.lines.len() > LINES_MAX {
            return Err(PrepareError::TooManyLines(scene.lines.len()));
        }
        for (object_idx, o) in scene.objects.iter().enumerate() {
            o.mesh
                .validate()
                .map_err(|source| PrepareError::Mesh { object_idx, source })?;
        }
        let aspect = size_px[0].max(1) as f32 / size_px[1].max(1) as f32;
        let eye = scene.camera.eye();
        let g = Globals {
            view_proj: scene.camera.view_projection(aspect).to_cols_array_2d(),
            eye: eye.extend(1.0).to_array(),
            light_towards: scene.light_towards.extend(0.0).to_array(),
        };
        queue.write_buffer(&self.globals, 0, bytemuck::bytes_of(&g));
        self.objects.truncate(scene.objects.len());
        for (i, o) in scene.objects.iter().enumerate() {
            let fresh = self
                .objects
                .get(i)
                .is_none_or(|g| !Arc::ptr_eq(&g.mesh, &o.mesh));
            if fresh {
                let gpu = self.upload(device, &o.mesh);
                if i < self.objects.len() {
                    self.objects[i] = gpu;
                } else {
                    self.objects.push(gpu);
                }
            }
            let u = ObjectUniform {
                world_from_object: o.world_from_object.to_cols_array_2d(),
                normal_matrix: o.world_from_object.inverse().transpose().to_cols_array_2d(),
                material: [
                    o.material.ambient,
                    o.material.diffuse,
                    o.material.specular,
                    o.material.shininess,
                ],
                opacity: [o.material.opacity, 0.0, 0.0, 0.0],
            };
            queue.write_buffer(&self.objects[i].uniform, 0, bytemuck::bytes_of(&u));
        }
        self.sort_draws(scene, eye);
        self.upload_lines(device, scene);
        Ok(())
    }

    fn upload(&self, device: &wgpu::Device, mesh: &Arc<Mesh>) -> GpuObject {
        let vertices: Vec<MeshVertex> = (0..mesh.n_vertices())
            .map(|i| MeshVertex {
                position: mesh.positions[i],
                normal: mesh.normals[i],
                colour: mesh.colours[i],
                ambient: match mesh.ambient.get(i) {
                    Some(a) => *a,
                    None => {
                        let c = mesh.colours[i];
                        [c[0], c[1], c[2]]
                    }
                },
            })
            .collect();
        // wgpu rejects empty buffers; a zero-length draw needs none of the content.
        let vertex_bytes: &[u8] = if vertices.is_empty() {
            &[0; 4]
        } else {
            bytemuck::cast_slice(&vertices)
        };
        let index_bytes: &[u8] = if mesh.indices.is_empty() {
            &[0; 4]
        } else {
            bytemuck::cast_slice(&mesh.indices)
        };
        let vertex_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("render vertices"),
            contents: vertex_bytes,
            usage: wgpu::BufferUsages::VERTEX,
        });
        let index_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("render indices"),
            contents: index_bytes,
            usage: wgpu::BufferUsages::INDEX,
        });
        let uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("render object"),
            size: std::mem::size_of::<ObjectUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("render object"),
            layout: &self.object_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: uniform.as_entire_binding(),
            }],
        });
        GpuObject {
            mesh: Arc::clone(mesh),
            vertices: vertex_buf,
            indices: index_buf,
            n_indices: mesh.indices.len() as u32,
            uniform,
            bind_group,
        }
    }

    /// Opaque objects first, then transparent ones from the farthest centre to the nearest.
    fn sort_draws(&mut self, scene: &Scene, eye: Vec3) {
        let depth = |i: usize| {
            let o = &scene.objects[i];
            let c = o
                .mesh
                .bounds()
                .map_or(Vec3::ZERO, |b| Vec3::from_array(b.centre()));
            (o.world_from_object.transform_point3(c) - eye).length()
        };
        let (opaque, mut transparent): (Vec<usize>, Vec<usize>) =
            (0..scene.objects.len()).partition(|&i| !scene.objects[i].is_transparent());
        transparent.sort_by(|&a, &b| depth(b).total_cmp(&depth(a)).then(a.cmp(&b)));
        self.n_opaque = opaque.len();
        self.draw_order = opaque;
        self.draw_order.extend(transparent);
    }

    fn upload_lines(&mut self, device: &wgpu::Device, scene: &Scene) {
        let vertices: Vec<LineVertex> = scene
            .lines
            .iter()
            .flat_map(|l| {
                [
                    LineVertex {
                        position: l.from.to_array(),
                        colour: l.colour,
                    },
                    LineVertex {
                        position: l.to.to_array(),
                        colour: l.colour,
                    },
                ]
            })
            .collect();
        self.line_buffer = (!vertices.is_empty()).then(|| {
            let buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("render lines"),
                contents: bytemuck::cast_slice(&vertices),
                usage: wgpu::BufferUsages::VERTEX,
            });
            (buf, vertices.len() as u32)
        });
    }

    /// Records into `encoder` one pass that clears `colour` to `background` and `depth` to
    /// the far plane, then draws the last prepared scene: what the offscreen path and an
    /// embedding window both do with their own targets.
    pub fn draw_into(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        label: &str,
        colour: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        background: [f32; 4],
    ) {
        let [r, g, b, a] = background.map(f64::from);
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some(label),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: colour,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color { r, g, b, a }),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        self.paint(&mut pass);
    }

    /// Records the draws of the last prepared scene into `pass`.
    pub fn paint(&self, pass: &mut wgpu::RenderPass<'_>) {
        pass.set_bind_group(0, &self.globals_bind_group, &[]);
        let draw = |pass: &mut wgpu::RenderPass<'_>, o: &GpuObject| {
            if o.n_indices == 0 {
                return;
            }
            pass.set_bind_group(1, &o.bind_group, &[]);
            pass.set_vertex_buffer(0, o.vertices.slice(..));
            pass.set_index_buffer(o.indices.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..o.n_indices, 0, 0..1);
        };
        pass.set_pipeline(&self.opaque);
        for &i in &self.draw_order[..self.n_opaque] {
            draw(pass, &self.objects[i]);
        }
        if let Some((buf, n)) = &self.line_buffer {
            pass.set_pipeline(&self.lines);
            pass.set_vertex_buffer(0, buf.slice(..));
            pass.draw(0..*n, 0..1);
        }
        for &i in &self.draw_order[self.n_opaque..] {
            pass.set_pipeline(&self.transparent_back);
            draw(pass, &self.objects[i]);
            pass.set_pipeline(&self.transparent_front);
            draw(pass, &self.objects[i]);
        }
    }

    /// The object indexes in the order the last [`Renderer::paint`] draws them.
    pub fn draw_order(&self) -> &[usize] {
        &self.draw_order
    }
}
