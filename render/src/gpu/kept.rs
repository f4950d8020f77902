//! A picture kept between frames in two layers, so that a frame whose only change is the
//! lines draws only the lines.
//!
//! A peer's pointer and tool are lines, and move many times a second while the scene stands
//! still: on a software rasteriser drawing the objects again costs tens of milliseconds a
//! frame, copying a kept picture of them one or two. [`KeptPicture::draw`] keeps the objects
//! below the lines (the opaque ones, colour and depth) aside; when a prepare changed only the
//! lines, it copies them back and draws the lines and the transparent objects over them.
//! The pixels are those of one pass drawing everything ([`Renderer::draw_into`]): the same
//! draws in the same order, the later ones depth-tested against the same depths.
//!
//! The cost: a second colour and depth texture at the picture's size (8 bytes a pixel, about
//! 4 MB at 900x600), and their copies on a frame that draws everything.

use super::Renderer;

/// The picture a host shows, and the layer below its lines kept aside, at one size.
pub struct KeptPicture {
    size_px: [u32; 2],
    colour: wgpu::Texture,
    colour_view: wgpu::TextureView,
    depth: wgpu::Texture,
    depth_view: wgpu::TextureView,
    below_colour: wgpu::Texture,
    below_depth: wgpu::Texture,
    /// Whether the layer below holds a drawing (a new picture holds none).
    holds_below: bool,
}

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
        let size = wgpu::Extent3d {
            width: size_px[0].max(1),
            height: size_px[1].max(1),
            depth_or_array_layers: 1,
        };
        let texture = |label, format, usage, view_formats| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats,
            })
        };
        let copied = wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::COPY_DST;
        let drawn = wgpu::TextureUsages::RENDER_ATTACHMENT | copied;
        let colour_texture = texture("kept picture colour", colour, drawn | usage, view_formats);
        let depth_texture = texture("kept picture depth", depth, drawn, &[]);
        KeptPicture {
            size_px,
            colour_view: colour_texture.create_view(&Default::default()),
            depth_view: depth_texture.create_view(&Default::default()),
            colour: colour_texture,
            depth: depth_texture,
            below_colour: texture("kept picture below the lines", colour, copied, &[]),
            below_depth: texture("kept picture depth below the lines", depth, copied, &[]),
            holds_below: false,
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
    /// last drew it (or it holds none yet), else the kept layer below with the lines and the
    /// transparent objects drawn again over it. Returns whether it drew the layer below.
    ///
    /// One renderer draws into one kept picture: what changed is the renderer's.
    pub fn draw(
        &mut self,
        renderer: &mut Renderer,
        encoder: &mut wgpu::CommandEncoder,
        label: &str,
        background: [f32; 4],
    ) -> bool {
        let below = renderer.below_changed || !self.holds_below;
        if below {
            let [r, g, b, a] = background.map(f64::from);
            let clear = wgpu::LoadOp::Clear(wgpu::Color { r, g, b, a });
            let mut pass = self.pass(encoder, label, clear, wgpu::LoadOp::Clear(1.0));
            renderer.paint_below(&mut pass);
            drop(pass);
            self.copy(
                encoder,
                [&self.colour, &self.depth],
                [&self.below_colour, &self.below_depth],
            );
            renderer.below_changed = false;
            self.holds_below = true;
        } else {
            self.copy(
                encoder,
                [&self.below_colour, &self.below_depth],
                [&self.colour, &self.depth],
            );
        }
        let mut pass = self.pass(encoder, label, wgpu::LoadOp::Load, wgpu::LoadOp::Load);
        renderer.paint_above(&mut pass);
        below
    }

    /// A pass over the picture that loads its colour and depth as told and stores both.
    fn pass<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        label: &str,
        colour: wgpu::LoadOp<wgpu::Color>,
        depth: wgpu::LoadOp<f32>,
    ) -> wgpu::RenderPass<'e> {
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some(label),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &self.colour_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: colour,
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.depth_view,
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

    /// Copies each of `from` whole into the same-sized texture of `to`.
    fn copy(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        from: [&wgpu::Texture; 2],
        to: [&wgpu::Texture; 2],
    ) {
        for (from, to) in from.into_iter().zip(to) {
            encoder.copy_texture_to_texture(from.as_image_copy(), to.as_image_copy(), from.size());
        }
    }
}
