//! [`RgbaImage`]: the 8-bit image type that offscreen renders and plots produce, with PNG IO.

use std::path::Path;

/// Why a PNG could not be encoded, decoded or written.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PngError {
    /// Width or height is zero or does not match the pixel data.
    #[error("image size {0}x{1} is invalid")]
    BadSize(u32, u32),
    /// The PNG codec failed.
    #[error("png codec: {0}")]
    Codec(String),
    /// Reading or writing the file failed.
    #[error("png file: {0}")]
    Io(String),
}

/// An 8-bit sRGB RGBA image, rows top to bottom, straight alpha.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RgbaImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `4 * width * height` bytes.
    pub pixels: Vec<u8>,
}

impl RgbaImage {
    /// The RGBA of pixel (x, y), `None` outside the image.
    pub fn pixel(&self, x: u32, y: u32) -> Option<[u8; 4]> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let i = 4 * (y as usize * self.width as usize + x as usize);
        self.pixels.get(i..i + 4).and_then(|p| p.try_into().ok())
    }

    /// Encodes as PNG (opaque pixels round-trip exactly).
    pub fn to_png(&self) -> Result<Vec<u8>, PngError> {
        let size = tiny_skia::IntSize::from_wh(self.width, self.height)
            .ok_or(PngError::BadSize(self.width, self.height))?;
        // tiny-skia stores premultiplied colour: premultiply so that encoding restores ours.
        let mut data = self.pixels.clone();
        for p in data.chunks_exact_mut(4) {
            for k in 0..3 {
                p[k] = ((u16::from(p[k]) * u16::from(p[3]) + 127) / 255) as u8;
            }
        }
        let pixmap = tiny_skia::Pixmap::from_vec(data, size)
            .ok_or(PngError::BadSize(self.width, self.height))?;
        pixmap
            .encode_png()
            .map_err(|e| PngError::Codec(e.to_string()))
    }

    /// Decodes a PNG.
    pub fn from_png(bytes: &[u8]) -> Result<Self, PngError> {
        let pixmap =
            tiny_skia::Pixmap::decode_png(bytes).map_err(|e| PngError::Codec(e.to_string()))?;
        Ok(Self::from_pixmap(&pixmap))
    }

    /// Converts a tiny-skia pixmap (premultiplied) to straight alpha.
    pub fn from_pixmap(pixmap: &tiny_skia::Pixmap) -> Self {
        let pixels = pixmap.pixels().iter().flat_map(|p| {
            let c = p.demultiply();
            [c.red(), c.green(), c.blue(), c.alpha()]
        });
        Self {
            width: pixmap.width(),
            height: pixmap.height(),
            pixels: pixels.collect(),
        }
    }

    /// Writes the image as a PNG file.
    pub fn save_png(&self, path: &Path) -> Result<(), PngError> {
        std::fs::write(path, self.to_png()?)
            .map_err(|e| PngError::Io(format!("{}: {e}", path.display())))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trips_opaque_pixels_and_rejects_garbage() {
        let pixels: Vec<u8> = (0..3 * 2)
            .flat_map(|i| [i as u8 * 40, 255 - i as u8, 7, 255])
            .collect();
        let image = RgbaImage {
            width: 3,
            height: 2,
            pixels,
        };
        let back = RgbaImage::from_png(&image.to_png().unwrap()).unwrap();
        assert_eq!(back, image);
        assert_eq!(back.pixel(2, 1), Some([200, 250, 7, 255]));
        assert_eq!(back.pixel(3, 0), None);
        assert!(matches!(
            RgbaImage::from_png(b"not a png"),
            Err(PngError::Codec(_))
        ));
        let short = RgbaImage {
            width: 3,
            height: 2,
            pixels: vec![0; 5],
        };
        assert_eq!(short.to_png(), Err(PngError::BadSize(3, 2)));
    }
}
