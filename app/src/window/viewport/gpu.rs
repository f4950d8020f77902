//! The viewport's drawing: render's `Renderer` embedded in egui's frame through an
//! `egui_wgpu` paint callback.
//!
//! Why two steps: the renderer writes linear colour and relies on an sRGB target to encode it
//! (as render's offscreen path does), while egui draws into a non-sRGB surface. So
//! `prepare` renders the scene into the callback's own sRGB texture (with its own depth
//! buffer), and `paint` copies that texture into egui's pass, reading the encoded bytes as
//! they are. The picture in the window then matches `sculpt render`'s pictures.
//!
//! The picture texture outlives the frame: a frame whose scene changes nothing the renderer
//! draws (`Renderer::changed`), as when only the panels or the status line change, copies the
//! last picture again instead of drawing the scene; one whose scene changed only its lines (a
//! peer's pointer or tool moved) draws them over a kept copy of the objects (`KeptPicture`),
//! and one that patched a mesh draws the objects again only where the patch reaches.
//! On a software rasteriser drawing a large mesh takes tens of milliseconds, and such frames
//! would otherwise hold up the next one.

use std::sync::{Arc, Mutex};

use eframe::egui;
use eframe::egui_wgpu::{CallbackResources, CallbackTrait, ScreenDescriptor};
use render::gpu::{KeptFrame, KeptPicture, Renderer};
use render::mesh::Mesh;
use render::mesh::octree::MeshPatch;
use render::scene::Scene;

use ::app::clock;
use ::app::samples::Samples;

/// Where the renderer draws (encodes linear colour to sRGB on write).
const COLOUR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// The same bytes read without decoding, for a non-sRGB surface.
const COLOUR_BYTES_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

const BLIT_SHADER: &str = r"
@group(0) @binding(0) var picture: texture_2d<f32>;
@group(0) @binding(1) var picture_sampler: sampler;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

// One triangle that covers the viewport.
@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> VertexOut {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    var out: VertexOut;
    out.clip = vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, 0.0, 1.0);
    out.uv = uv;
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    return textureSample(picture, picture_sampler, in.uv);
}
";

/// The picture at the viewport's size, kept between frames, and its bindings for the blit.
struct Target {
    picture: KeptPicture,
    bind_group: wgpu::BindGroup,
}

/// What the callback keeps between frames, in egui_wgpu's `CallbackResources`.
pub struct ViewportResources {
    renderer: Renderer,
    blit: wgpu::RenderPipeline,
    blit_layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    /// The format `paint` reads the picture as: raw bytes for a non-sRGB surface, decoded
    /// colour for an sRGB one (which encodes again on write).
    read_format: wgpu::TextureFormat,
    target: Option<Target>,
}

impl ViewportResources {
    /// Pipelines for egui's surface format `surface`.
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, surface: wgpu::TextureFormat) -> Self {
        let renderer = Renderer::new(device, queue, COLOUR_FORMAT, Some(DEPTH_FORMAT));
        let blit_layout = blit_bind_group_layout(device);
        let blit = blit_pipeline(device, &blit_layout, surface);
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("sculpt viewport picture"),
            ..Default::default()
        });
        let read_format = if surface.is_srgb() {
            COLOUR_FORMAT
        } else {
            COLOUR_BYTES_FORMAT
        };
        Self {
            renderer,
            blit,
            blit_layout,
            sampler,
            read_format,
            target: None,
        }
    }

    /// Makes the picture `size_px` big; returns whether it made a new one (which holds no
    /// picture yet).
    fn ensure_target(&mut self, device: &wgpu::Device, size_px: [u32; 2]) -> bool {
        let fresh = (self.target.as_ref()).is_none_or(|t| t.picture.size_px() != size_px);
        if fresh {
            let picture = KeptPicture::new(
                device,
                size_px,
                [COLOUR_FORMAT, DEPTH_FORMAT],
                wgpu::TextureUsages::TEXTURE_BINDING,
                &[COLOUR_BYTES_FORMAT],
            );
            let read_view = picture.colour().create_view(&wgpu::TextureViewDescriptor {
                format: Some(self.read_format),
                ..Default::default()
            });
            let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("sculpt viewport picture"),
                layout: &self.blit_layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::TextureView(&read_view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: wgpu::BindingResource::Sampler(&self.sampler),
                    },
                ],
            });
            self.target = Some(Target {
                picture,
                bind_group,
            });
        }
        fresh
    }
}

/// The picture's bindings for the blit: the texture and its sampler.
fn blit_bind_group_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("sculpt viewport picture"),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: true },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
        ],
    })
}

/// The pipeline that copies the picture into egui's pass (one triangle over the viewport),
/// writing egui's surface format `surface`.
fn blit_pipeline(
    device: &wgpu::Device,
    blit_layout: &wgpu::BindGroupLayout,
    surface: wgpu::TextureFormat,
) -> wgpu::RenderPipeline {
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("sculpt viewport picture"),
        bind_group_layouts: &[Some(blit_layout)],
        immediate_size: 0,
    });
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("sculpt viewport picture"),
        source: wgpu::ShaderSource::Wgsl(BLIT_SHADER.into()),
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("sculpt viewport picture"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: surface,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// What the paint callback tells the UI: why the scene could not be drawn, and how long
/// preparing each frame took (the renderer's `prepare` and recording its pass, on the CPU).
#[derive(Debug)]
pub struct ViewportReport {
    /// Why the last frame could not be prepared.
    pub error: Option<String>,
    /// Milliseconds per frame that drew the scene, the latest [`MAX_PREPARE_SAMPLES`].
    pub prepare_ms: Samples,
    /// Mesh bytes the last prepare that uploaded any wrote (`Renderer::mesh_bytes_uploaded`).
    pub last_upload_bytes: u64,
    /// The fewest mesh bytes a prepare that uploaded any wrote (a patch's, once one went up).
    pub min_upload_bytes: Option<u64>,
    /// Patches the renderer refused (it uploads those meshes whole).
    pub n_patches_refused: u64,
    /// Frames that drew the scene.
    pub n_drawn: u64,
    /// Frames that drew the objects again only where mesh patches changed them, over the
    /// kept picture of the rest.
    pub n_regions: u64,
    /// Frames that drew only the lines (and the transparent objects) again, over the kept
    /// picture of the rest: another peer's pointer or tool moved.
    pub n_lines_only: u64,
    /// Frames that showed the last picture again, the scene unchanged.
    pub n_reused: u64,
}

/// Frames whose prepare times are kept.
pub const MAX_PREPARE_SAMPLES: usize = 600;

impl Default for ViewportReport {
    fn default() -> Self {
        ViewportReport {
            error: None,
            prepare_ms: Samples::new(MAX_PREPARE_SAMPLES),
            last_upload_bytes: 0,
            min_upload_bytes: None,
            n_patches_refused: 0,
            n_drawn: 0,
            n_regions: 0,
            n_lines_only: 0,
            n_reused: 0,
        }
    }
}

/// One frame's draw of the viewport: the scene (meshes are shared `Arc`s, so this is cheap)
/// and the viewport's size in pixels.
pub struct ViewportCallback {
    /// What to draw.
    pub scene: Scene,
    /// Patches of meshes swapped in since the last frame, by index into `scene.objects`, for
    /// `Renderer::patch_object`.
    pub patches: Vec<(usize, Arc<Mesh>, Arc<Mesh>, MeshPatch)>,
    /// The viewport in physical pixels.
    pub size_px: [u32; 2],
    /// Where failures and times are reported to the UI.
    pub report: Arc<Mutex<ViewportReport>>,
}

impl CallbackTrait for ViewportCallback {
    fn prepare(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        _screen: &ScreenDescriptor,
        encoder: &mut wgpu::CommandEncoder,
        resources: &mut CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        let Some(res) = resources.get_mut::<ViewportResources>() else {
            return Vec::new();
        };
        let start = clock::now().instant;
        let mut n_refused = 0;
        for (idx, base, mesh, patch) in &self.patches {
            // A refused patch costs only its upload: the mesh then goes up whole.
            n_refused += u64::from(res.renderer.patch_object(*idx, base, mesh, patch).is_err());
        }
        let prepared = res
            .renderer
            .prepare(device, queue, &self.scene, self.size_px);
        if let Ok(mut report) = self.report.lock() {
            report.error = prepared.as_ref().err().map(ToString::to_string);
            report.n_patches_refused += n_refused;
            let uploaded = res.renderer.mesh_bytes_uploaded();
            if uploaded > 0 {
                report.last_upload_bytes = uploaded;
                report.min_upload_bytes = Some(
                    report
                        .min_upload_bytes
                        .map_or(uploaded, |m| m.min(uploaded)),
                );
            }
        }
        if prepared.is_err() {
            res.target = None;
            return Vec::new();
        }
        let fresh = res.ensure_target(device, self.size_px);
        let Some(target) = &mut res.target else {
            return Vec::new();
        };
        let drawn = fresh || res.renderer.changed();
        if !drawn {
            if let Ok(mut report) = self.report.lock() {
                report.n_reused += 1;
            }
            return Vec::new();
        }
        let kept = (target.picture).draw(
            &mut res.renderer,
            device,
            encoder,
            "sculpt viewport",
            self.scene.background,
        );
        if let Ok(mut report) = self.report.lock() {
            let n = match kept {
                KeptFrame::Whole => &mut report.n_drawn,
                KeptFrame::Region(_) => &mut report.n_regions,
                KeptFrame::LinesOnly => &mut report.n_lines_only,
            };
            *n += 1;
        }
        let ms = clock::now().instant.duration_since(start).as_secs_f64() * 1e3;
        if let Ok(mut report) = self.report.lock() {
            report.prepare_ms.push(ms);
        }
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        pass: &mut wgpu::RenderPass<'static>,
        resources: &CallbackResources,
    ) {
        let Some(res) = resources.get::<ViewportResources>() else {
            return;
        };
        let Some(target) = (res.target.as_ref()).filter(|t| t.picture.size_px() == self.size_px)
        else {
            return;
        };
        pass.set_pipeline(&res.blit);
        pass.set_bind_group(0, &target.bind_group, &[]);
        pass.draw(0..3, 0..1);
    }
}
