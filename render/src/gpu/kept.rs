//! A picture kept between frames in two layers, so that a frame whose only change is the
//! lines draws only the lines, and one whose only change is a mesh patch draws the objects
//! again only where the patch reaches.
//!
//! A peer's pointer and tool are lines, and move many times a second while the scene stands
//! still: on a software rasteriser drawing the objects again costs tens of milliseconds a
//! frame, copying a kept picture of them one or two. [`KeptPicture::draw`] draws the objects
//! below the lines (the opaque ones, colour and depth) into a layer kept aside and copies it
//! into the picture, then draws the lines and the transparent objects over them; when a
//! prepare changed only the lines, the kept layer is copied as it is. When it patched opaque
//! meshes and nothing else, the rectangle of pixels the patches may change
//! (`super::region`) is cleared in the kept layer (colour copied from a picture of the
//! background alone, depth reset by one triangle) and the objects drawn again under a
//! scissor there.
//! The pixels are those of one pass drawing everything ([`Renderer::draw_into`]): the same
//! draws in the same order, the later ones depth-tested against the same depths.
//!
//! The cost: a second colour and depth texture at the picture's size (8 bytes a pixel: about
//! 4.3 MB at 900x600, 66 MB at 3840x2160), a picture of the background as large as the
//! largest region drawn, and the copy of the kept layer on every frame that draws.

use super::Renderer;
use super::region::Below;

/// Resets the depth under the scissor to the far plane, colour untouched: one triangle
/// over the picture.
const DEPTH_RESET_SHADER: &str = r"
@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv.x * 2.0 - 1.0, uv.y * 2.0 - 1.0, 0.5, 1.0);
}

struct Out {
    @location(0) colour: vec4<f32>,
    @builtin(frag_depth) depth: f32,
};

@fragment
fn fs_main() -> Out {
    return Out(vec4<f32>(0.0), 1.0);
}
";

/// What [`KeptPicture::draw`] drew.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KeptFrame {
    /// Everything.
    Whole,
    /// The objects within `[x0, x1) x [y0, y1)` pixels (a mesh patch changed only those),
    /// then the lines and the transparent objects.
    Region([u32; 4]),
    /// The lines and the transparent objects over the kept objects.
    LinesOnly,
}

/// The picture a host shows, and the layer below its lines kept aside, at one size.
pub struct KeptPicture {
    size_px: [u32; 2],
    colour: wgpu::Texture,
    depth: wgpu::Texture,
    below_colour: wgpu::Texture,
    below_depth: wgpu::Texture,
    /// Views of the picture's colour and depth, then of the layer below's.
    views: [wgpu::TextureView; 2],
    below_views: [wgpu::TextureView; 2],
    /// Whether the layer below holds a drawing (a new picture holds none).
    holds_below: bool,
    /// A picture of the background alone, as large as the largest region drawn so far: a
    /// region is cleared by copying from it, bytes as a clear writes them.
    blank: Option<Blank>,
    colour_format: wgpu::TextureFormat,
    depth_reset: wgpu::RenderPipeline,
}

/// A picture of one background, `size_px` large.
struct Blank {
    texture: wgpu::Texture,
    size_px: [u32; 2],
    background: [f32; 4],
}

/// Blank pictures are made in steps of this many pixels a side, so that a stroke's growing
/// regions make few of them.
const BLANK_STEP_PX: u32 = 128;

impl KeptPicture {
    /// Textures for pictures of `size_px` pixels in the renderer's `colour` and `depth`
    /// formats; the picture's colour texture also gets `usage` and `view_formats` (how the
    /// host reads it).
    pub fn new(
        device: &wgpu::Device,
        size_px: [u32; 2],
        [colour, depth]: [wgpu::TextureFormat; 2],
        usage: wgpu::TextureUsages,
        view_formats: &[wgpu::TextureFormat],
    ) -> KeptPicture {
        let texture = |label, format, usage, view_formats| {
            picture_texture(device, label, size_px, format, usage, view_formats)
        };
        let copied = wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::COPY_DST;
        let drawn = wgpu::TextureUsages::RENDER_ATTACHMENT | copied;
        let colour_texture = texture("kept picture colour", colour, drawn | usage, view_formats);
        let depth_texture = texture("kept picture depth", depth, drawn, &[]);
        let below_colour = texture("kept picture below the lines", colour, drawn, &[]);
        let below_depth = texture("kept picture depth below the lines", depth, drawn, &[]);
        KeptPicture {
            size_px,
            views: [&colour_texture, &depth_texture].map(|t| t.create_view(&Default::default())),
            colour: colour_texture,
            depth: depth_texture,
            below_views: [&below_colour, &below_depth].map(|t| t.create_view(&Default::default())),
            below_colour,
            below_depth,
            holds_below: false,
            blank: None,
            colour_format: colour,
            depth_reset: depth_reset_pipeline(device, colour, depth),
        }
    }

    /// The picture's size in pixels.
    pub fn size_px(&self) -> [u32; 2] {
        self.size_px
    }

    /// The picture's colour texture (what the host shows).
    pub fn colour(&self) -> &wgpu::Texture {
        &self.colour
    }

    /// Records into `encoder` the last scene `renderer` prepared, over a clear of
    /// `background`: all of it when anything below the lines changed since this picture
    /// last drew it (or it holds none yet); the objects within a region when only patches of
    /// opaque objects changed there; else the kept layer below alone. The lines and the
    /// transparent objects are drawn again over it in every case.
    ///
    /// One renderer draws into one kept picture: what changed is the renderer's. `device`
    /// is the picture's, for a picture of the background as large as a region.
    pub fn draw(
        &mut self,
        renderer: &mut Renderer,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        label: &str,
        background: [f32; 4],
    ) -> KeptFrame {
        let below = if self.holds_below {
            renderer.below
        } else {
            Below::All
        };
        // The layer below is drawn in place, then copied into the picture.
        let frame = match below {
            Below::All => {
                let [r, g, b, a] = background.map(f64::from);
                let clear = wgpu::LoadOp::Clear(wgpu::Color { r, g, b, a });
                let mut pass = render_pass(
                    encoder,
                    label,
                    &self.below_views,
                    (clear, wgpu::LoadOp::Clear(1.0)),
                );
                renderer.paint_below(&mut pass);
                KeptFrame::Whole
            }
            Below::Region(region) => {
                self.clear_region(device, encoder, background, region);
                self.redraw_region(renderer, encoder, label, region);
                KeptFrame::Region(region)
            }
            Below::Same => KeptFrame::LinesOnly,
        };
        self.restore(encoder);
        renderer.below = Below::Same;
        self.holds_below = true;
        let mut pass = render_pass(encoder, label, &self.views, LOAD_BOTH);
        renderer.paint_above(&mut pass);
        frame
    }

    /// Copies `background` into `[x0, y0, x1, y1]` of the picture, from a blank picture made
    /// (and cleared) when the one held is smaller or of another background.
    fn clear_region(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        background: [f32; 4],
        [x0, y0, x1, y1]: [u32; 4],
    ) {
        let need = [x1 - x0, y1 - y0];
        let fits = (self.blank.as_ref())
            .is_some_and(|b| b.background == background && (0..2).all(|a| b.size_px[a] >= need[a]));
        if !fits {
            let size_px = [0, 1].map(|a| {
                let held = self.blank.as_ref().map_or(0, |b| b.size_px[a]);
                let step = need[a].max(held).div_ceil(BLANK_STEP_PX) * BLANK_STEP_PX;
                step.min(self.size_px[a]).max(need[a]).max(1)
            });
            let texture = blank_picture(device, encoder, self.colour_format, size_px, background);
            self.blank = Some(Blank {
                texture,
                size_px,
                background,
            });
        }
        let Some(blank) = &self.blank else {
            return;
        };
        encoder.copy_texture_to_texture(
            blank.texture.as_image_copy(),
            wgpu::TexelCopyTextureInfo {
                texture: &self.below_colour,
                mip_level: 0,
                origin: wgpu::Origin3d { x: x0, y: y0, z: 0 },
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::Extent3d {
                width: need[0],
                height: need[1],
                depth_or_array_layers: 1,
            },
        );
    }

    /// Resets `[x0, y0, x1, y1]` of the picture's depth to the far plane and draws the
    /// objects below the lines there.
    fn redraw_region(
        &self,
        renderer: &Renderer,
        encoder: &mut wgpu::CommandEncoder,
        label: &str,
        [x0, y0, x1, y1]: [u32; 4],
    ) {
        let mut pass = render_pass(encoder, label, &self.below_views, LOAD_BOTH);
        pass.set_scissor_rect(x0, y0, x1 - x0, y1 - y0);
        pass.set_pipeline(&self.depth_reset);
        pass.draw(0..3, 0..1);
        renderer.paint_below_within(&mut pass, [x0, y0, x1, y1]);
    }

    /// Copies the layer kept below the lines into the picture.
    fn restore(&self, encoder: &mut wgpu::CommandEncoder) {
        let below = [&self.below_colour, &self.below_depth];
        copy(encoder, below, [&self.colour, &self.depth]);
    }
}

/// Loads colour and depth as they are.
const LOAD_BOTH: (wgpu::LoadOp<wgpu::Color>, wgpu::LoadOp<f32>) =
    (wgpu::LoadOp::Load, wgpu::LoadOp::Load);

/// A pass over a colour and a depth view that loads each as told and stores both.
fn render_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    [colour_view, depth_view]: &[wgpu::TextureView; 2],
    (colour, depth): (wgpu::LoadOp<wgpu::Color>, wgpu::LoadOp<f32>),
) -> wgpu::RenderPass<'e> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: colour_view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: colour,
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: depth_view,
            depth_ops: Some(wgpu::Operations {
                load: depth,
                store: wgpu::StoreOp::Store,
            }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// A two-dimensional texture of `size_px` pixels (at least one a side), one sample, one level.
pub(super) fn picture_texture(
    device: &wgpu::Device,
    label: &str,
    size_px: [u32; 2],
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
    view_formats: &[wgpu::TextureFormat],
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: size_px[0].max(1),
            height: size_px[1].max(1),
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats,
    })
}

/// A picture of `size_px` pixels in `format`, cleared to `background` by `encoder`.
fn blank_picture(
    device: &wgpu::Device,
    encoder: &mut wgpu::CommandEncoder,
    format: wgpu::TextureFormat,
    size_px: [u32; 2],
    background: [f32; 4],
) -> wgpu::Texture {
    let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
    let texture = picture_texture(
        device,
        "kept picture background",
        size_px,
        format,
        usage,
        &[],
    );
    let [r, g, b, a] = background.map(f64::from);
    let view = texture.create_view(&Default::default());
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("kept picture background"),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: &view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color { r, g, b, a }),
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: None,
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    });
    texture
}

/// Copies each of `from` whole into the same-sized texture of `to`.
fn copy(encoder: &mut wgpu::CommandEncoder, from: [&wgpu::Texture; 2], to: [&wgpu::Texture; 2]) {
    for (from, to) in from.into_iter().zip(to) {
        encoder.copy_texture_to_texture(from.as_image_copy(), to.as_image_copy(), from.size());
    }
}

/// The pipeline that resets depth to the far plane under the scissor, writing no colour.
fn depth_reset_pipeline(
    device: &wgpu::Device,
    colour: wgpu::TextureFormat,
    depth: wgpu::TextureFormat,
) -> wgpu::RenderPipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("kept picture depth reset"),
        source: wgpu::ShaderSource::Wgsl(DEPTH_RESET_SHADER.into()),
    });
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("kept picture depth reset"),
        bind_group_layouts: &[],
        immediate_size: 0,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("kept picture depth reset"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: Some(wgpu::DepthStencilState {
            format: depth,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Always),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: colour,
                blend: None,
                write_mask: wgpu::ColorWrites::empty(),
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}
