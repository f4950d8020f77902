//! Headless rendering: a private device draws a [`Scene`] into an RGBA image or a PNG file.

use super::kept::picture_texture;
use super::{KeptFrame, KeptPicture, PrepareError, Renderer};
use crate::scene::Scene;
use plot::image::{PngError, RgbaImage};
use std::path::Path;

/// Largest offscreen image side in pixels.
pub const MAX_OFFSCREEN_SIDE: u32 = 8192;
const COLOUR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Why an offscreen render failed.
#[derive(Debug, thiserror::Error)]
pub enum OffscreenError {
    /// No GPU or software adapter exists; tests treat this as "skip".
    #[error("no wgpu adapter: {0}")]
    NoAdapter(String),
    /// The adapter refused to create a device.
    #[error("cannot create device: {0}")]
    Device(String),
    /// Width or height is zero or above [`MAX_OFFSCREEN_SIDE`].
    #[error("image size {0}x{1} out of range")]
    BadSize(u32, u32),
    /// The scene could not be prepared.
    #[error(transparent)]
    Prepare(#[from] PrepareError),
    /// Reading the image back from the GPU failed.
    #[error("readback failed: {0}")]
    Readback(String),
    /// Writing the PNG failed.
    #[error(transparent)]
    Png(#[from] PngError),
}

/// A private device and renderer for offscreen frames; reuse it for many frames.
pub struct Headless {
    device: wgpu::Device,
    queue: wgpu::Queue,
    renderer: Renderer,
    adapter_info: wgpu::AdapterInfo,
}

impl Headless {
    /// Creates a device on the default adapter (Vulkan on llvmpipe in CI).
    pub fn new() -> Result<Self, OffscreenError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter =
            pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
                .map_err(|e| OffscreenError::NoAdapter(e.to_string()))?;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("render offscreen"),
            required_limits: wgpu::Limits::downlevel_defaults(),
            ..Default::default()
        }))
        .map_err(|e| OffscreenError::Device(e.to_string()))?;
        let renderer = Renderer::new(&device, &queue, COLOUR_FORMAT, Some(DEPTH_FORMAT));
        Ok(Self {
            device,
            queue,
            renderer,
            adapter_info: adapter.get_info(),
        })
    }

    /// The renderer behind the frames, for what [`Headless::render`] does not cover, such as
    /// handing it a mesh patch ([`Renderer::patch_object`]) before the next frame.
    pub fn renderer_mut(&mut self) -> &mut Renderer {
        &mut self.renderer
    }

    /// A one-line description of the adapter, for golden-image annotations.
    pub fn adapter_description(&self) -> String {
        let i = &self.adapter_info;
        format!(
            "{} ({:?}, driver {} {})",
            i.name, i.backend, i.driver, i.driver_info
        )
    }

    /// Renders `scene` at `width` x `height`.
    pub fn render(
        &mut self,
        scene: &Scene,
        width: u32,
        height: u32,
    ) -> Result<RgbaImage, OffscreenError> {
        check_size(width, height)?;
        self.renderer
            .prepare(&self.device, &self.queue, scene, [width, height])?;
        let [colour, depth] = self.targets([width, height]);
        let colour_view = colour.create_view(&Default::default());
        let depth_view = depth.create_view(&Default::default());
        let mut encoder = self.device.create_command_encoder(&Default::default());
        self.renderer.draw_into(
            &mut encoder,
            "offscreen",
            &colour_view,
            &depth_view,
            scene.background,
        );
        self.finish(encoder, &colour)
    }

    /// A picture of `width` x `height` for [`Headless::render_kept`].
    pub fn kept_picture(&self, width: u32, height: u32) -> Result<KeptPicture, OffscreenError> {
        check_size(width, height)?;
        Ok(KeptPicture::new(
            &self.device,
            [width, height],
            [COLOUR_FORMAT, DEPTH_FORMAT],
            wgpu::TextureUsages::empty(),
            &[],
        ))
    }

    /// Renders `scene` into `picture` as a window keeps it between frames
    /// ([`KeptPicture::draw`]); also returns what was drawn.
    pub fn render_kept(
        &mut self,
        scene: &Scene,
        picture: &mut KeptPicture,
    ) -> Result<(RgbaImage, KeptFrame), OffscreenError> {
        self.renderer
            .prepare(&self.device, &self.queue, scene, picture.size_px())?;
        let mut encoder = self.device.create_command_encoder(&Default::default());
        let kept = picture.draw(
            &mut self.renderer,
            &self.device,
            &mut encoder,
            "offscreen kept",
            scene.background,
        );
        Ok((self.finish(encoder, picture.colour())?, kept))
    }

    /// Copies `colour` out after what `encoder` recorded, submits, and reads it back.
    fn finish(
        &self,
        mut encoder: wgpu::CommandEncoder,
        colour: &wgpu::Texture,
    ) -> Result<RgbaImage, OffscreenError> {
        let size = colour.size();
        let (width, height) = (size.width, size.height);
        let padded_row = (4 * width).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
            * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let readback = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("offscreen readback"),
            size: u64::from(padded_row) * u64::from(height),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        encoder.copy_texture_to_buffer(
            colour.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded_row),
                    rows_per_image: Some(height),
                },
            },
            size,
        );
        self.queue.submit([encoder.finish()]);
        self.read_back(&readback, width, height, padded_row)
    }

    /// The colour and depth textures of a frame of `size_px`.
    fn targets(&self, size_px: [u32; 2]) -> [wgpu::Texture; 2] {
        let target = |format, usage, label| {
            picture_texture(&self.device, label, size_px, format, usage, &[])
        };
        let colour = target(
            COLOUR_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            "offscreen colour",
        );
        let depth = target(
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
            "offscreen depth",
        );
        [colour, depth]
    }

    /// Waits for the frame copied into `readback` (rows `padded_row` bytes apart) and takes
    /// its pixels.
    fn read_back(
        &self,
        readback: &wgpu::Buffer,
        width: u32,
        height: u32,
        padded_row: u32,
    ) -> Result<RgbaImage, OffscreenError> {
        let row_bytes = 4 * width;
        let slice = readback.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            // The receiver waits below; a failed send only means it gave up.
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| OffscreenError::Readback(e.to_string()))?;
        rx.recv()
            .map_err(|e| OffscreenError::Readback(e.to_string()))?
            .map_err(|e| OffscreenError::Readback(e.to_string()))?;
        let mut pixels = Vec::with_capacity((row_bytes * height) as usize);
        {
            let view = slice
                .get_mapped_range()
                .map_err(|e| OffscreenError::Readback(e.to_string()))?;
            for row in view.chunks_exact(padded_row as usize) {
                pixels.extend_from_slice(&row[..row_bytes as usize]);
            }
        }
        readback.unmap();
        Ok(RgbaImage {
            width,
            height,
            pixels,
        })
    }
}

/// Refuses an image side of zero or above [`MAX_OFFSCREEN_SIDE`].
fn check_size(width: u32, height: u32) -> Result<(), OffscreenError> {
    if width == 0 || height == 0 || width > MAX_OFFSCREEN_SIDE || height > MAX_OFFSCREEN_SIDE {
        return Err(OffscreenError::BadSize(width, height));
    }
    Ok(())
}

/// Renders `scene` on a fresh headless device.
pub fn render_to_rgba(scene: &Scene, width: u32, height: u32) -> Result<RgbaImage, OffscreenError> {
    Headless::new()?.render(scene, width, height)
}

/// Renders `scene` on a fresh headless device and writes a PNG to `path`.
pub fn render_png(
    scene: &Scene,
    width: u32,
    height: u32,
    path: &Path,
) -> Result<(), OffscreenError> {
    Ok(render_to_rgba(scene, width, height)?.save_png(path)?)
}
