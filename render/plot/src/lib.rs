//! 2D pictures with tiny-skia: heat-map slices of scalar functions and time-series plots.
//!
//! Both return an [`RgbaImage`](crate::image::RgbaImage) to save as PNG. Text uses the small
//! built-in stroke font in [`font`]. This is its own crate (under `render/`, named directly by its
//! users) so that haptic's force traces and the simulator's reports draw with it
//! without depending on wgpu.
#![warn(missing_docs)]

pub mod font;
pub mod heat_map;
pub mod image;
pub mod series;

use tiny_skia::Color;

/// Most decimals an axis or legend number gets.
const MAX_NUMBER_DECIMALS: usize = 6;
/// Largest picture side in pixels.
pub const MAX_PICTURE_SIDE: u32 = 8192;

/// Why a picture could not be drawn.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PlotError {
    /// Width or height is too small for the layout or above [`MAX_PICTURE_SIDE`].
    #[error("picture size {0}x{1} out of range")]
    BadSize(u32, u32),
    /// The sampled rectangle is empty or not finite.
    #[error("rectangle is empty or not finite")]
    BadRectangle,
}

/// A rectangle of pixels: `x, y` top-left, then width and height.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelRect {
    /// Left edge.
    pub x: f32,
    /// Top edge.
    pub y: f32,
    /// Width.
    pub w: f32,
    /// Height.
    pub h: f32,
}

/// Straight-alpha linear RGBA 0..1 as a tiny-skia colour (clamped).
pub(crate) fn colour(c: [f32; 4]) -> Color {
    let c = c.map(|x| {
        if x.is_finite() {
            x.clamp(0.0, 1.0)
        } else {
            0.0
        }
    });
    Color::from_rgba(c[0], c[1], c[2], c[3]).unwrap_or(Color::BLACK)
}

/// Compact decimal text for `v` with as many decimals as a spacing of `step` needs.
pub fn format_number(v: f64, step: f64) -> String {
    if !v.is_finite() {
        return "NAN".to_owned();
    }
    let magnitude = v.abs().max(step.abs());
    if magnitude >= 1e6 || (magnitude > 0.0 && magnitude < 1e-3) {
        return format!("{v:.2e}").to_uppercase();
    }
    let decimals = if step > 0.0 && step.is_finite() {
        // The fewest decimals that write the step exactly (0.25 needs 2, 0.1 needs 1).
        (0..=MAX_NUMBER_DECIMALS)
            .find(|&d| {
                let scaled = step * 10f64.powi(d as i32);
                (scaled - scaled.round()).abs() < 1e-6 * scaled
            })
            .unwrap_or(MAX_NUMBER_DECIMALS)
    } else {
        3
    };
    let s = format!("{v:.decimals$}");
    // "-0" and "-0.0" read as noise on an axis.
    if s.trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        s.trim_start_matches('-').to_owned()
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_formatted_to_the_step() {
        assert_eq!(format_number(0.5, 0.1), "0.5");
        assert_eq!(format_number(20.0, 10.0), "20");
        assert_eq!(format_number(-0.0, 0.5), "0.0");
        assert_eq!(format_number(1.25, 0.25), "1.25");
        assert_eq!(format_number(2.0e7, 1.0e6), "2.00E7");
        assert_eq!(format_number(f64::NAN, 1.0), "NAN");
    }
}
