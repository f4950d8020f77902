//! The wgpu renderer: lit meshes with transparency, line lists, and an offscreen path.
//!
//! [`Renderer`] is embeddable: the host owns the device, queue and render pass, calls
//! [`Renderer::prepare`] before the pass and [`Renderer::paint`] inside it. It knows nothing
//! of egui; the app wraps it in an `egui_wgpu` callback. [`offscreen`] creates its own
//! headless device and renders a [`Scene`] to RGBA or PNG.
//!
//! An object's mesh is uploaded whole when its `Arc<Mesh>` changes, unless the caller handed
//! [`Renderer::patch_object`] the [`MeshPatch`] that turned the uploaded mesh into the new
//! one: then [`Renderer::prepare`] writes only the patch's vertex and triangle ranges into the
//! object's buffers, which patched objects get with spare room.
//!
//! A host that keeps its picture between frames draws through a [`KeptPicture`]: a prepare
//! that changed only the lines (a peer's pointer, a touch tool) then costs a copy of the kept
//! objects and the lines, not the objects' draw, and one that only patched opaque meshes
//! draws the objects again only within the pixels the patches reach (`region`).

mod kept;
pub mod offscreen;
mod region;

pub use kept::{KeptFrame, KeptPicture};

use crate::mesh::MeshError;
use crate::mesh::octree::MeshPatch;
use crate::mesh::{Aabb, Mesh};
use crate::scene::{PICK_RUN_TRIANGLES, PickRuns, Scene, SceneObject};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use region::{Below, Screen};
use std::collections::{BTreeMap, BTreeSet};
use std::ops::Range;
use std::sync::Arc;
use wgpu::util::DeviceExt;

/// Most objects one frame may draw.
pub const MAX_DRAWN_OBJECTS: usize = 1 << 16;
/// Most line segments one frame may draw.
pub const MAX_LINES: usize = 1 << 20;

/// Spare room a patched object's buffers get beyond its mesh, as a divisor of its length
/// (a quarter more): patches that move grown blocks to the end of the mesh fit for a while
/// before the buffers are allocated and uploaded again.
pub const PATCH_SPARE_DIVISOR: usize = 4;
/// Least spare room, in vertices and in triangles, a patched object's buffers get.
pub const MIN_PATCH_SPARE: usize = 1024;

/// Why [`Renderer::patch_object`] refused a patch.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum PatchError {
    /// The object index is not below [`MAX_DRAWN_OBJECTS`].
    #[error("object {0} is beyond the limit {MAX_DRAWN_OBJECTS}")]
    ObjectIndex(usize),
    /// The patch's lengths are not the mesh's.
    #[error(
        "the patch has {patch_vertices} vertices and {patch_triangles} triangles, the mesh {mesh_vertices} and {mesh_triangles}"
    )]
    Lengths {
        /// `MeshPatch::n_vertices`.
        patch_vertices: usize,
        /// `MeshPatch::n_triangles`.
        patch_triangles: usize,
        /// The mesh's vertices.
        mesh_vertices: usize,
        /// The mesh's triangles.
        mesh_triangles: usize,
    },
    /// A range is reversed, out of order, overlaps the one before or runs past the mesh.
    #[error("{what} range {start}..{end} is out of order or beyond {len}")]
    Range {
        /// "vertex" or "triangle".
        what: &'static str,
        /// Its start.
        start: usize,
        /// Its end.
        end: usize,
        /// The mesh's vertices or triangles.
        len: usize,
    },
}

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
    /// More objects than [`MAX_DRAWN_OBJECTS`].
    #[error("{0} objects exceed the limit {MAX_DRAWN_OBJECTS}")]
    TooManyObjects(usize),
    /// More lines than [`MAX_LINES`].
    #[error("{0} lines exceed the limit {MAX_LINES}")]
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

impl ObjectUniform {
    /// The uniform block of `o`: its placement, the matrix for its normals and its material.
    fn of(o: &crate::scene::SceneObject) -> ObjectUniform {
        ObjectUniform {
            world_from_object: o.world_from_object.to_cols_array_2d(),
            normal_matrix: o.world_from_object.inverse().transpose().to_cols_array_2d(),
            material: [
                o.material.ambient,
                o.material.diffuse,
                o.material.specular,
                o.material.shininess,
            ],
            opacity: [o.material.opacity, 0.0, 0.0, 0.0],
        }
    }
}

/// GPU copies of one object's mesh and uniforms.
struct GpuObject {
    mesh: Arc<Mesh>,
    /// What the draw order needs of `mesh`, found once per uploaded mesh, not per frame.
    layout: MeshLayout,
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    /// Vertices `vertices` holds room for.
    vertex_capacity: usize,
    /// Triangles `indices` holds room for.
    triangle_capacity: usize,
    n_indices: u32,
    uniform: wgpu::Buffer,
    /// What `uniform` holds, once written.
    uniform_value: Option<ObjectUniform>,
    /// Drawn with back faces culled (`SceneObject::closed`).
    closed: bool,
    /// The scene object's boxes around runs of triangles, for a draw within a region.
    pick_runs: PickRuns,
    bind_group: wgpu::BindGroup,
}

/// What sorting the draws needs of a mesh: scanned when the mesh is uploaded, so a frame that
/// changes nothing reads two fields instead of every vertex.
#[derive(Clone, Copy, Debug)]
struct MeshLayout {
    /// Some vertex colour is less than opaque.
    translucent_vertices: bool,
    /// The centre of the mesh's bounds, in object space (the origin for an empty mesh).
    centre: Vec3,
}

impl MeshLayout {
    fn of(mesh: &Mesh) -> MeshLayout {
        MeshLayout {
            translucent_vertices: mesh.has_translucent_vertices(),
            centre: mesh
                .bounds()
                .map_or(Vec3::ZERO, |b| Vec3::from_array(b.centre())),
        }
    }
}

/// What an object's next upload may be: the patches handed in since the last prepare, merged.
struct PendingPatch {
    /// The mesh the first patch was made from: the buffers must hold it.
    base: Arc<Mesh>,
    /// The mesh the last patch made.
    mesh: Arc<Mesh>,
    full: bool,
    vertex_ranges: Vec<Range<usize>>,
    triangle_ranges: Vec<Range<usize>>,
}

/// Draws [`Scene`]s into a host's render pass.
pub struct Renderer {
    opaque: wgpu::RenderPipeline,
    /// Opaque and closed: back faces culled.
    opaque_closed: wgpu::RenderPipeline,
    transparent_back: wgpu::RenderPipeline,
    transparent_front: wgpu::RenderPipeline,
    lines: wgpu::RenderPipeline,
    globals: wgpu::Buffer,
    globals_bind_group: wgpu::BindGroup,
    object_layout: wgpu::BindGroupLayout,
    objects: Vec<GpuObject>,
    /// The last prepare's buffers while a prepare finds them again ([`Kept`]); empty
    /// between prepares, kept for its capacity, so that a frame allocates nothing for it.
    held: Vec<Option<GpuObject>>,
    /// Opaque object indexes first, then transparent ones far to near.
    draw_order: Vec<usize>,
    n_opaque: usize,
    line_buffer: Option<(wgpu::Buffer, u32)>,
    /// The vertices in `line_buffer`.
    line_vertices: Vec<LineVertex>,
    /// The globals and the background the last prepare wrote.
    last_frame: Option<(Globals, [f32; 4])>,
    /// Whether the last prepare changed anything its draw shows.
    changed: bool,
    /// What prepares changed below the lines (the globals, the background, the objects)
    /// since a [`KeptPicture`] last drew it.
    below: Below,
    /// Per object index, the patches handed in since the last prepare.
    pending: BTreeMap<usize, PendingPatch>,
    /// Mesh bytes (vertices and indices) the last prepare wrote.
    mesh_bytes_uploaded: u64,
    /// The camera's projection and the picture's size of the last prepare.
    screen: Option<Screen>,
    /// Indices the last draw within a region drew, of how many its opaque objects hold.
    region_indices: [std::sync::atomic::AtomicU64; 2],
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

/// The four mesh pipelines: opaque (both sides, and the front side of a closed mesh), then a
/// transparent object's far side and near side.
fn mesh_pipelines(
    device: &wgpu::Device,
    format: wgpu::TextureFormat,
    depth: Option<wgpu::TextureFormat>,
    globals_layout: &wgpu::BindGroupLayout,
    object_layout: &wgpu::BindGroupLayout,
) -> [wgpu::RenderPipeline; 4] {
    let module = device.create_shader_module(wgpu::include_wgsl!("shaders/mesh.wgsl"));
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("render mesh"),
        bind_group_layouts: &[Some(globals_layout), Some(object_layout)],
        immediate_size: 0,
    });
    let attrs = wgpu::vertex_attr_array![
        0 => Float32x3, 1 => Float32x3, 2 => Float32x4, 3 => Float32x3
    ];
    let buffers = [Some(wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<MeshVertex>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &attrs,
    })];
    let kind = |label, cull_mode, blend, depth_write| PipelineKind {
        label,
        module: &module,
        layout: &layout,
        buffers: &buffers,
        topology: wgpu::PrimitiveTopology::TriangleList,
        cull_mode,
        blend,
        depth_write,
    };
    let opaque = kind("render opaque", None, false, true);
    let opaque_closed = kind("render opaque closed", Some(wgpu::Face::Back), false, true);
    // Transparent objects draw their far side first, then their near side.
    let back = kind(
        "render transparent back",
        Some(wgpu::Face::Front),
        true,
        false,
    );
    let front = kind(
        "render transparent front",
        Some(wgpu::Face::Back),
        true,
        false,
    );
    [opaque, opaque_closed, back, front].map(|k| pipeline(device, format, depth, k))
}

/// The pipeline of line lists (arrows, boxes, cursors).
fn line_pipeline(
    device: &wgpu::Device,
    format: wgpu::TextureFormat,
    depth: Option<wgpu::TextureFormat>,
    globals_layout: &wgpu::BindGroupLayout,
) -> wgpu::RenderPipeline {
    let module = device.create_shader_module(wgpu::include_wgsl!("shaders/line.wgsl"));
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("render lines"),
        bind_group_layouts: &[Some(globals_layout)],
        immediate_size: 0,
    });
    let attrs = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x4];
    let buffers = [Some(wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<LineVertex>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &attrs,
    })];
    pipeline(
        device,
        format,
        depth,
        PipelineKind {
            label: "render lines",
            module: &module,
            layout: &layout,
            buffers: &buffers,
            topology: wgpu::PrimitiveTopology::LineList,
            cull_mode: None,
            blend: true,
            depth_write: true,
        },
    )
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
        let globals_layout = uniform_layout(device, "render globals");
        let object_layout = uniform_layout(device, "render object");
        let [opaque, opaque_closed, transparent_back, transparent_front] =
            mesh_pipelines(device, format, depth, &globals_layout, &object_layout);
        let lines = line_pipeline(device, format, depth, &globals_layout);
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
            opaque_closed,
            transparent_back,
            transparent_front,
            lines,
            globals,
            globals_bind_group,
            object_layout,
            objects: Vec::new(),
            held: Vec::new(),
            draw_order: Vec::new(),
            n_opaque: 0,
            line_buffer: None,
            line_vertices: Vec::new(),
            last_frame: None,
            changed: true,
            below: Below::All,
            pending: BTreeMap::new(),
            screen: None,
            region_indices: Default::default(),
            mesh_bytes_uploaded: 0,
        }
    }

    /// Hands in the patch that turned object `object_idx`'s mesh `base` into `mesh` (what
    /// [`crate::mesh::octree::OctreeMesher::mesh_update`] returns), for the next
    /// [`Renderer::prepare`] whose scene holds `mesh` at that index.
    ///
    /// That prepare writes only the patch's ranges when the object's buffers hold `base` and
    /// have room for the new lengths; otherwise (a `full` patch, a mesh that outgrew the
    /// buffers, buffers holding another mesh, a scene holding another mesh) it uploads `mesh`
    /// whole, into buffers with spare room ([`PATCH_SPARE_DIVISOR`]). Several patches before
    /// one prepare are merged when each starts from the last one's `mesh`. Patches not used by
    /// the next prepare are dropped.
    pub fn patch_object(
        &mut self,
        object_idx: usize,
        base: &Arc<Mesh>,
        mesh: &Arc<Mesh>,
        patch: &MeshPatch,
    ) -> Result<(), PatchError> {
        if object_idx >= MAX_DRAWN_OBJECTS {
            return Err(PatchError::ObjectIndex(object_idx));
        }
        let (n_vertices, n_triangles) = (mesh.n_vertices(), mesh.n_triangles());
        if patch.n_vertices != n_vertices || patch.n_triangles != n_triangles {
            return Err(PatchError::Lengths {
                patch_vertices: patch.n_vertices,
                patch_triangles: patch.n_triangles,
                mesh_vertices: n_vertices,
                mesh_triangles: n_triangles,
            });
        }
        check_ranges("vertex", &patch.vertex_ranges, n_vertices)?;
        check_ranges("triangle", &patch.triangle_ranges, n_triangles)?;
        let next = match self.pending.remove(&object_idx) {
            Some(p) if Arc::ptr_eq(&p.mesh, base) => PendingPatch {
                base: p.base,
                mesh: Arc::clone(mesh),
                full: p.full || patch.full,
                vertex_ranges: union(&p.vertex_ranges, &patch.vertex_ranges, n_vertices),
                triangle_ranges: union(&p.triangle_ranges, &patch.triangle_ranges, n_triangles),
            },
            // A patch from a mesh the pending ones did not make: nothing to chain, whole.
            Some(p) => PendingPatch {
                full: true,
                mesh: Arc::clone(mesh),
                ..p
            },
            None => PendingPatch {
                base: Arc::clone(base),
                mesh: Arc::clone(mesh),
                full: patch.full,
                vertex_ranges: patch.vertex_ranges.clone(),
                triangle_ranges: patch.triangle_ranges.clone(),
            },
        };
        self.pending.insert(object_idx, next);
        Ok(())
    }

    /// Mesh bytes (vertices and indices) the last [`Renderer::prepare`] wrote to the GPU.
    pub fn mesh_bytes_uploaded(&self) -> u64 {
        self.mesh_bytes_uploaded
    }

    /// Whether the last [`Renderer::prepare`] changed anything its draw shows (the camera,
    /// the light, the background, an object's mesh, place or material, the lines): a host
    /// that keeps the last picture it drew may show it again instead of drawing (the window
    /// does, so that frames for its panels alone cost a software rasteriser nothing).
    pub fn changed(&self) -> bool {
        self.changed
    }

    /// Uploads what changed in `scene` for a target of `size_px` pixels and sorts the draws.
    ///
    /// Meshes are uploaded again only when an object's `Arc<Mesh>` is a different allocation,
    /// and then only the ranges of a patch handed to [`Renderer::patch_object`] where one
    /// applies; uniforms and lines are written only when they differ from what the buffers
    /// hold.
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
        size_px: [u32; 2],
    ) -> Result<(), PrepareError> {
        if scene.objects.len() > MAX_DRAWN_OBJECTS {
            return Err(PrepareError::TooManyObjects(scene.objects.len()));
        }
        if scene.lines.len() > MAX_LINES {
            return Err(PrepareError::TooManyLines(scene.lines.len()));
        }
        // A prepare that fails leaves nothing to show again.
        self.changed = true;
        let below_before = std::mem::replace(&mut self.below, Below::All);
        self.validate_new_meshes(scene)?;
        let aspect = size_px[0].max(1) as f32 / size_px[1].max(1) as f32;
        let eye = scene.camera.eye();
        let g = Globals {
            view_proj: scene.camera.view_projection(aspect).to_cols_array_2d(),
            eye: eye.extend(1.0).to_array(),
            light_towards: scene.light_towards.extend(0.0).to_array(),
        };
        let frame = (g, scene.background);
        let frame_changed = self.objects.len() != scene.objects.len()
            || self.last_frame.is_none_or(|(last, background)| {
                bytemuck::bytes_of(&last) != bytemuck::bytes_of(&g) || background != frame.1
            });
        if frame_changed {
            queue.write_buffer(&self.globals, 0, bytemuck::bytes_of(&g));
            self.last_frame = Some(frame);
        }
        let screen = Screen {
            view_proj: glam::Mat4::from_cols_array_2d(&g.view_proj),
            size_px,
        };
        let below = self.prepare_objects(device, queue, scene, &screen);
        self.screen = Some(screen);
        let mut changed = frame_changed || below != Below::Same;
        self.sort_draws(scene, eye);
        // Kept until a kept picture draws below the lines again.
        let below = if frame_changed { Below::All } else { below };
        self.below = below_before.join(below);
        changed |= self.upload_lines(device, scene);
        self.changed = changed;
        Ok(())
    }

    /// Uploads `scene`'s objects' meshes (or their patches) and uniforms where they differ
    /// from what the buffers hold; returns what that changed below the lines on `screen`
    /// (within a region where the only changes are patches of opaque objects).
    fn prepare_objects(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
        screen: &Screen,
    ) -> Below {
        let mut below = Below::Same;
        self.mesh_bytes_uploaded = 0;
        let mut pending = std::mem::take(&mut self.pending);
        let mut held = std::mem::take(&mut self.held);
        held.extend(self.objects.drain(..).map(Some));
        let mut kept = Kept::new(held);
        for (i, o) in scene.objects.iter().enumerate() {
            let gpu = match kept.take(i, &o.mesh) {
                Some((gpu, moved)) => {
                    // Another object came or went before it: the same buffers, drawn in
                    // another place in the order.
                    if moved {
                        below = Below::All;
                    }
                    gpu
                }
                None => {
                    let patch = pending.remove(&i).filter(|p| Arc::ptr_eq(&p.mesh, &o.mesh));
                    let base = patch.as_ref().and_then(|p| kept.take_mesh(&p.base));
                    let (gpu, drawn) = self.patch_or_upload(device, queue, o, base, patch, screen);
                    below = below.join(drawn);
                    gpu
                }
            };
            self.objects.push(gpu);
            let u = ObjectUniform::of(o);
            let gpu = &mut self.objects[i];
            if gpu
                .uniform_value
                .is_none_or(|w| bytemuck::bytes_of(&w) != bytemuck::bytes_of(&u))
            {
                queue.write_buffer(&gpu.uniform, 0, bytemuck::bytes_of(&u));
                gpu.uniform_value = Some(u);
                below = Below::All;
            }
            if gpu.closed != o.closed {
                below = Below::All;
            }
            gpu.closed = o.closed;
            gpu.pick_runs.clone_from(&o.pick_runs);
        }
        self.held = kept.into_spare();
        below
    }

    /// The buffers of scene object `o`, whose mesh is new to them: `base`'s (the buffers that
    /// held `patch`'s base) with the patch written in where it fits, else new ones with the
    /// whole mesh. Returns them and what that changed below the lines.
    fn patch_or_upload(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        o: &SceneObject,
        base: Option<GpuObject>,
        patch: Option<PendingPatch>,
        screen: &Screen,
    ) -> (GpuObject, Below) {
        if let (Some(mut gpu), Some(p)) = (base, &patch) {
            let was_opaque = !gpu.layout.translucent_vertices;
            if write_patch(queue, &mut gpu, p, &mut self.mesh_bytes_uploaded) {
                let drawn = match was_opaque && !gpu.layout.translucent_vertices {
                    true => patch_region(p, o, screen),
                    false => Below::All,
                };
                return (gpu, drawn);
            }
        }
        let gpu = self.upload(device, queue, &o.mesh, patch.is_some());
        (gpu, Below::All)
    }
    /// Validates the meshes of `scene` not uploaded yet. One already uploaded was validated
    /// then: a frame that changes nothing does not scan every mesh again.
    fn validate_new_meshes(&self, scene: &Scene) -> Result<(), PrepareError> {
        // The meshes held anywhere, gathered only once an object is not at its place.
        let mut held: Option<BTreeSet<*const Mesh>> = None;
        for (object_idx, o) in scene.objects.iter().enumerate() {
            let here =
                (self.objects.get(object_idx)).is_some_and(|g| Arc::ptr_eq(&g.mesh, &o.mesh));
            let uploaded = here
                || held
                    .get_or_insert_with(|| {
                        self.objects.iter().map(|g| Arc::as_ptr(&g.mesh)).collect()
                    })
                    .contains(&Arc::as_ptr(&o.mesh));
            if !uploaded {
                o.mesh
                    .validate()
                    .map_err(|source| PrepareError::Mesh { object_idx, source })?;
            }
        }
        Ok(())
    }

    /// Uploads `mesh` whole into new buffers, with spare room when `spare` (for an object
    /// that is patched).
    fn upload(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        mesh: &Arc<Mesh>,
        spare: bool,
    ) -> GpuObject {
        let (n_vertices, n_triangles) = (mesh.n_vertices(), mesh.n_triangles());
        let room = |n: usize| {
            if spare {
                n + (n / PATCH_SPARE_DIVISOR).max(MIN_PATCH_SPARE)
            } else {
                n
            }
        };
        let (vertex_capacity, triangle_capacity) = (room(n_vertices), room(n_triangles));
        let vertices = mesh_vertices(mesh, 0..n_vertices);
        let vertex_bytes: &[u8] = bytemuck::cast_slice(&vertices);
        let index_bytes: &[u8] = bytemuck::cast_slice(&mesh.indices);
        // wgpu rejects empty buffers; a zero-length draw needs none of the content.
        let buffer = |label, usage, bytes: usize| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: (bytes as u64).max(wgpu::COPY_BUFFER_ALIGNMENT),
                usage: usage | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let vertex_buf = buffer(
            "render vertices",
            wgpu::BufferUsages::VERTEX,
            vertex_capacity * std::mem::size_of::<MeshVertex>(),
        );
        let index_buf = buffer(
            "render indices",
            wgpu::BufferUsages::INDEX,
            triangle_capacity * TRIANGLE_BYTES,
        );
        queue.write_buffer(&vertex_buf, 0, vertex_bytes);
        queue.write_buffer(&index_buf, 0, index_bytes);
        self.mesh_bytes_uploaded += (vertex_bytes.len() + index_bytes.len()) as u64;
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
            layout: MeshLayout::of(mesh),
            vertices: vertex_buf,
            indices: index_buf,
            vertex_capacity,
            triangle_capacity,
            n_indices: mesh.indices.len() as u32,
            uniform,
            uniform_value: None,
            closed: false,
            pick_runs: PickRuns::default(),
            bind_group,
        }
    }

    /// Opaque objects first, then transparent ones from the farthest centre to the nearest.
    fn sort_draws(&mut self, scene: &Scene, eye: Vec3) {
        // `prepare` has uploaded every object, so `self.objects[i]` holds object i's mesh.
        let depth = |i: usize| {
            let c = self.objects[i].layout.centre;
            (scene.objects[i].world_from_object.transform_point3(c) - eye).length()
        };
        let transparent = |i: usize| {
            scene.objects[i].material.is_transparent()
                || self.objects[i].layout.translucent_vertices
        };
        let (opaque, mut transparent): (Vec<usize>, Vec<usize>) =
            (0..scene.objects.len()).partition(|&i| !transparent(i));
        transparent.sort_by(|&a, &b| depth(b).total_cmp(&depth(a)).then(a.cmp(&b)));
        self.n_opaque = opaque.len();
        self.draw_order = opaque;
        self.draw_order.extend(transparent);
    }

    /// Uploads `scene`'s lines unless the buffer holds them already; returns whether it
    /// did not.
    fn upload_lines(&mut self, device: &wgpu::Device, scene: &Scene) -> bool {
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
        let (new, held): (&[u8], &[u8]) = (
            bytemuck::cast_slice(&vertices),
            bytemuck::cast_slice(&self.line_vertices),
        );
        if new == held {
            return false;
        }
        self.line_buffer = (!vertices.is_empty()).then(|| {
            let buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("render lines"),
                contents: bytemuck::cast_slice(&vertices),
                usage: wgpu::BufferUsages::VERTEX,
            });
            (buf, vertices.len() as u32)
        });
        self.line_vertices = vertices;
        true
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
        self.paint_below(pass);
        self.paint_above(pass);
    }

    /// Records the draws below the lines: the opaque objects.
    fn paint_below(&self, pass: &mut wgpu::RenderPass<'_>) {
        self.paint_opaque(pass, None);
    }

    /// Records the draws of the opaque objects as [`Renderer::paint_below`] does, for a pass
    /// that draws only within `region` (`[x0, y0, x1, y1]` pixels, under a scissor): of an
    /// object whose runs of triangles are boxed ([`PickRuns`]), only the runs whose box may
    /// reach the region. The others make no pixel there, so the pixels are the same.
    pub(super) fn paint_below_within(&self, pass: &mut wgpu::RenderPass<'_>, region: [u32; 4]) {
        let [drawn, held] = self.paint_opaque(pass, Some(region));
        let relaxed = std::sync::atomic::Ordering::Relaxed;
        self.region_indices[0].store(drawn, relaxed);
        self.region_indices[1].store(held, relaxed);
    }

    /// Records the opaque objects' draws, within `region` when one is given; returns the
    /// indices drawn and those the objects hold.
    fn paint_opaque(&self, pass: &mut wgpu::RenderPass<'_>, region: Option<[u32; 4]>) -> [u64; 2] {
        pass.set_bind_group(0, &self.globals_bind_group, &[]);
        let mut ranges = Vec::new();
        let (mut drawn, mut held) = (0, 0);
        for &i in &self.draw_order[..self.n_opaque] {
            let o = &self.objects[i];
            pass.set_pipeline(if o.closed {
                &self.opaque_closed
            } else {
                &self.opaque
            });
            ranges.clear();
            let runs = o.pick_runs.runs_made_for(&o.mesh);
            match (region, self.screen, runs, o.uniform_value) {
                (Some(region), Some(screen), Some(runs), Some(u)) => {
                    let world_from_object = glam::Mat4::from_cols_array_2d(&u.world_from_object);
                    runs_within(runs, &screen, world_from_object, region, &mut ranges);
                }
                _ => ranges.push(0..o.n_indices),
            }
            drawn += draw_ranges(pass, o, &ranges);
            held += u64::from(o.n_indices);
        }
        [drawn, held]
    }

    /// Of the last draw within a region: the indices drawn, and those its opaque objects hold.
    pub fn region_indices(&self) -> [u64; 2] {
        self.region_indices
            .each_ref()
            .map(|n| n.load(std::sync::atomic::Ordering::Relaxed))
    }

    /// Records the draws from the lines up: the lines, then the transparent objects far to
    /// near.
    fn paint_above(&self, pass: &mut wgpu::RenderPass<'_>) {
        pass.set_bind_group(0, &self.globals_bind_group, &[]);
        if let Some((buf, n)) = &self.line_buffer {
            pass.set_pipeline(&self.lines);
            pass.set_vertex_buffer(0, buf.slice(..));
            pass.draw(0..*n, 0..1);
        }
        for &i in &self.draw_order[self.n_opaque..] {
            pass.set_pipeline(&self.transparent_back);
            draw_object(pass, &self.objects[i]);
            pass.set_pipeline(&self.transparent_front);
            draw_object(pass, &self.objects[i]);
        }
    }

    /// The object indexes in the order the last [`Renderer::paint`] draws them.
    pub fn draw_order(&self) -> &[usize] {
        &self.draw_order
    }
}

/// The pixels a patch of the opaque object `o` may change on `screen`.
fn patch_region(p: &PendingPatch, o: &crate::scene::SceneObject, screen: &Screen) -> Below {
    if o.material.is_transparent() {
        return Below::All;
    }
    match region::patch_bounds(&p.base, &p.mesh, &p.vertex_ranges, &p.triangle_ranges) {
        Some(bounds) => screen.region(o.world_from_object, bounds),
        None => Below::Same,
    }
}

/// Records the draw of object `o` with the pipeline set.
/// Appends to `ranges` the index ranges of the `runs` (of [`PICK_RUN_TRIANGLES`]) whose box,
/// placed by `world_from_object`, may reach `region` on `screen`; adjacent runs join.
fn runs_within(
    runs: &[Option<Aabb>],
    screen: &Screen,
    world_from_object: glam::Mat4,
    [x0, y0, x1, y1]: [u32; 4],
    ranges: &mut Vec<Range<u32>>,
) {
    let run_indices = (3 * PICK_RUN_TRIANGLES) as u32;
    for (k, b) in runs.iter().enumerate() {
        let reaches = b.is_none_or(|b| {
            let bounds = [glam::Vec3::from_array(b.lo), glam::Vec3::from_array(b.hi)];
            match screen.region(world_from_object, bounds) {
                Below::Same => false,
                Below::All => true,
                Below::Region([a0, b0, a1, b1]) => a0 < x1 && x0 < a1 && b0 < y1 && y0 < b1,
            }
        });
        if !reaches {
            continue;
        }
        let start = k as u32 * run_indices;
        match ranges.last_mut() {
            Some(last) if last.end == start => last.end = start + run_indices,
            _ => ranges.push(start..start + run_indices),
        }
    }
}

/// Draws `ranges` of `o`'s indices (clipped to what it holds); returns how many.
fn draw_ranges(pass: &mut wgpu::RenderPass<'_>, o: &GpuObject, ranges: &[Range<u32>]) -> u64 {
    if o.n_indices == 0 || ranges.is_empty() {
        return 0;
    }
    pass.set_bind_group(1, &o.bind_group, &[]);
    pass.set_vertex_buffer(0, o.vertices.slice(..));
    pass.set_index_buffer(o.indices.slice(..), wgpu::IndexFormat::Uint32);
    let mut drawn = 0;
    for r in ranges {
        let end = r.end.min(o.n_indices);
        if r.start < end {
            pass.draw_indexed(r.start..end, 0, 0..1);
            drawn += u64::from(end - r.start);
        }
    }
    drawn
}

/// Draws all of `o`'s indices.
fn draw_object(pass: &mut wgpu::RenderPass<'_>, o: &GpuObject) {
    draw_ranges(pass, o, std::slice::from_ref(&(0..o.n_indices)));
}

/// Bytes of one triangle in an index buffer.
const TRIANGLE_BYTES: usize = 3 * std::mem::size_of::<u32>();

/// The GPU vertices of `mesh`'s vertices `range`.
fn mesh_vertices(mesh: &Mesh, range: Range<usize>) -> Vec<MeshVertex> {
    range
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
        .collect()
}

/// The buffers a renderer held before a prepare, found again by mesh: an object keeps its
/// buffers when others come or go before it in the scene's order (its place moved), so only
/// new meshes are uploaded.
struct Kept {
    objects: Vec<Option<GpuObject>>,
    /// Each held mesh's places, by the mesh's address: made on the first search (a frame
    /// whose objects all stay in place makes none).
    by_mesh: Option<BTreeMap<*const Mesh, Vec<usize>>>,
}

impl Kept {
    fn new(objects: Vec<Option<GpuObject>>) -> Kept {
        Kept {
            objects,
            by_mesh: None,
        }
    }

    /// The buffers no object took, dropped, and the emptied list for the next prepare.
    fn into_spare(self) -> Vec<Option<GpuObject>> {
        let mut objects = self.objects;
        objects.clear();
        objects
    }

    /// The buffers that hold `mesh`, those at place `i` first; and whether they were at
    /// another place.
    fn take(&mut self, i: usize, mesh: &Arc<Mesh>) -> Option<(GpuObject, bool)> {
        let here = (self.objects.get(i).and_then(Option::as_ref))
            .is_some_and(|g| Arc::ptr_eq(&g.mesh, mesh));
        if here {
            return self.objects[i].take().map(|g| (g, false));
        }
        self.take_mesh(mesh).map(|g| (g, true))
    }

    /// Buffers that hold `mesh`, wherever they were.
    fn take_mesh(&mut self, mesh: &Arc<Mesh>) -> Option<GpuObject> {
        let objects = &mut self.objects;
        let by_mesh = self.by_mesh.get_or_insert_with(|| {
            let mut by_mesh: BTreeMap<*const Mesh, Vec<usize>> = BTreeMap::new();
            for (k, g) in objects.iter().enumerate() {
                if let Some(g) = g {
                    by_mesh.entry(Arc::as_ptr(&g.mesh)).or_default().push(k);
                }
            }
            by_mesh
        });
        let places = by_mesh.get(&Arc::as_ptr(mesh))?;
        places.iter().find_map(|&k| objects[k].take())
    }
}

fn write_patch(
    queue: &wgpu::Queue,
    gpu: &mut GpuObject,
    patch: &PendingPatch,
    uploaded: &mut u64,
) -> bool {
    let mesh = &patch.mesh;
    let (n_vertices, n_triangles) = (mesh.n_vertices(), mesh.n_triangles());
    if patch.full
        || !Arc::ptr_eq(&gpu.mesh, &patch.base)
        || n_vertices > gpu.vertex_capacity
        || n_triangles > gpu.triangle_capacity
    {
        return false;
    }
    let vertex_bytes = std::mem::size_of::<MeshVertex>();
    for r in &patch.vertex_ranges {
        let vertices = mesh_vertices(mesh, r.clone());
        let bytes: &[u8] = bytemuck::cast_slice(&vertices);
        queue.write_buffer(&gpu.vertices, (r.start * vertex_bytes) as u64, bytes);
        *uploaded += bytes.len() as u64;
    }
    for r in &patch.triangle_ranges {
        let bytes: &[u8] = bytemuck::cast_slice(&mesh.indices[3 * r.start..3 * r.end]);
        queue.write_buffer(&gpu.indices, (r.start * TRIANGLE_BYTES) as u64, bytes);
        *uploaded += bytes.len() as u64;
    }
    gpu.mesh = Arc::clone(mesh);
    gpu.layout = MeshLayout::of(mesh);
    gpu.n_indices = (3 * n_triangles) as u32;
    true
}

/// Checks that `ranges` are ascending, disjoint and within `len`.
fn check_ranges(what: &'static str, ranges: &[Range<usize>], len: usize) -> Result<(), PatchError> {
    let mut end_before = 0;
    for r in ranges {
        if r.start > r.end || r.start < end_before || r.end > len {
            return Err(PatchError::Range {
                what,
                start: r.start,
                end: r.end,
                len,
            });
        }
        end_before = r.end;
    }
    Ok(())
}

/// The union of two lists of ascending ranges, cut at `len`, ascending with touching ranges
/// merged.
fn union(a: &[Range<usize>], b: &[Range<usize>], len: usize) -> Vec<Range<usize>> {
    let mut all: Vec<Range<usize>> = a
        .iter()
        .chain(b)
        .map(|r| r.start.min(len)..r.end.min(len))
        .filter(|r| !r.is_empty())
        .collect();
    all.sort_unstable_by_key(|r| r.start);
    let mut out: Vec<Range<usize>> = Vec::with_capacity(all.len());
    for r in all {
        match out.last_mut() {
            Some(last) if r.start <= last.end => last.end = last.end.max(r.end),
            _ => out.push(r),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn union_merges_overlapping_and_touching_ranges_and_cuts_at_the_length() {
        assert_eq!(
            union(&[0..2, 5..7, 20..30], &[1..3, 7..9, 12..13], 25),
            vec![0..3, 5..9, 12..13, 20..25]
        );
        assert_eq!(
            union(&[26..28, 29..30], &[], 25),
            Vec::<Range<usize>>::new()
        );
    }

    #[test]
    fn ranges_out_of_order_or_beyond_the_mesh_are_refused() {
        assert_eq!(check_ranges("vertex", &[0..2, 2..5], 5), Ok(()));
        let err = |start, end| {
            Err(PatchError::Range {
                what: "vertex",
                start,
                end,
                len: 5,
            })
        };
        assert_eq!(check_ranges("vertex", &[0..2, 1..3], 5), err(1, 3));
        assert_eq!(check_ranges("vertex", &[0..1, 3..6], 5), err(3, 6));
        #[expect(clippy::reversed_empty_ranges, reason = "the case under test")]
        let reversed = [0..1, 4..2];
        assert_eq!(check_ranges("vertex", &reversed, 5), err(4, 2));
    }
}
