//! Heat maps: a scalar function sampled over a rectangle, coloured, with a labelled legend.

use super::font::draw_text;
use super::{MAX_PICTURE_SIDE, PixelRect, PlotError, format_number};
use crate::image::RgbaImage;
use tiny_skia::{Color, Paint, Pixmap, PremultipliedColorU8, Rect, Transform};

const MARGIN_PX: f32 = 8.0;
const TITLE_PX: f32 = 12.0;
const LABEL_PX: f32 = 10.0;
const LEGEND_BAR_PX: f32 = 16.0;
/// Room for the legend bar, its gap and its labels.
const LEGEND_PX: f32 = 110.0;
/// Smallest plotting area that still shows something.
const MIN_PLOT_SIDE_PX: f32 = 8.0;
/// Colour of samples that are NaN or infinite.
const NOT_FINITE_RGB: [f32; 3] = [1.0, 0.0, 1.0];
/// Viridis, sampled at five points and interpolated linearly.
const COLOUR_STOPS: [[f32; 3]; 5] = [
    [0.267, 0.005, 0.329],
    [0.229, 0.322, 0.545],
    [0.128, 0.567, 0.551],
    [0.369, 0.789, 0.383],
    [0.993, 0.906, 0.144],
];

/// What to sample and how to label it.
#[derive(Clone, Debug, PartialEq)]
pub struct HeatMapSettings {
    /// Range of the horizontal coordinate (left to right).
    pub x: (f32, f32),
    /// Range of the vertical coordinate (bottom to top).
    pub y: (f32, f32),
    /// Fixed colour range; `None` uses the sampled minimum and maximum.
    pub range: Option<(f32, f32)>,
    /// Title drawn above the map.
    pub title: String,
    /// Picture width in pixels.
    pub width: u32,
    /// Picture height in pixels.
    pub height: u32,
}

/// A drawn heat map and where its parts are, for tests and overlays.
#[derive(Clone, Debug, PartialEq)]
pub struct HeatMapPicture {
    /// The picture.
    pub image: RgbaImage,
    /// Where the sampled rectangle is drawn.
    pub map: PixelRect,
    /// Where the legend bar is drawn (maximum at the top).
    pub legend: PixelRect,
    /// The value range the colours span.
    pub range: (f32, f32),
}

/// Viridis colour for `t` in 0..1 (clamped).
pub fn colour_map(t: f32) -> [f32; 3] {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = t * (COLOUR_STOPS.len() - 1) as f32;
    let i = (s.floor() as usize).min(COLOUR_STOPS.len() - 2);
    let f = s - i as f32;
    std::array::from_fn(|k| COLOUR_STOPS[i][k] + f * (COLOUR_STOPS[i + 1][k] - COLOUR_STOPS[i][k]))
}

fn opaque(rgb: [f32; 3]) -> PremultipliedColorU8 {
    let b = rgb.map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8);
    PremultipliedColorU8::from_rgba(b[0], b[1], b[2], 255)
        .unwrap_or(PremultipliedColorU8::TRANSPARENT)
}

/// Samples `f(xs, ys, out)` (bulk: one call for every pixel) and draws the heat map.
pub fn heat_map(
    mut f: impl FnMut(&[f32], &[f32], &mut [f32]),
    s: &HeatMapSettings,
) -> Result<HeatMapPicture, PlotError> {
    let good = |r: (f32, f32)| r.0.is_finite() && r.1.is_finite() && r.0 < r.1;
    if !good(s.x) || !good(s.y) || s.range.is_some_and(|r| !good(r)) {
        return Err(PlotError::BadRectangle);
    }
    let map = PixelRect {
        x: MARGIN_PX,
        y: MARGIN_PX + TITLE_PX + MARGIN_PX,
        w: s.width as f32 - 2.0 * MARGIN_PX - LEGEND_PX,
        h: s.height as f32 - 3.0 * MARGIN_PX - TITLE_PX,
    };
    if s.width > MAX_PICTURE_SIDE
        || s.height > MAX_PICTURE_SIDE
        || map.w < MIN_PLOT_SIDE_PX
        || map.h < MIN_PLOT_SIDE_PX
    {
        return Err(PlotError::BadSize(s.width, s.height));
    }
    let mut pixmap = Pixmap::new(s.width, s.height).ok_or(PlotError::BadSize(s.width, s.height))?;
    pixmap.fill(Color::WHITE);
    let (mw, mh) = (map.w as usize, map.h as usize);
    let (xs, ys) = pixel_centres(s, mw, mh);
    let mut values = vec![0.0f32; mw * mh];
    f(&xs, &ys, &mut values);
    let range = s.range.unwrap_or_else(|| fitted_range(&values));
    let stride = s.width as usize;
    let pixels = pixmap.pixels_mut();
    for j in 0..mh {
        for i in 0..mw {
            let v = values[j * mw + i];
            let rgb = if v.is_finite() {
                colour_map((v - range.0) / (range.1 - range.0))
            } else {
                NOT_FINITE_RGB
            };
            pixels[(map.y as usize + j) * stride + map.x as usize + i] = opaque(rgb);
        }
    }
    let legend = PixelRect {
        x: map.x + map.w + 2.0 * MARGIN_PX,
        y: map.y,
        w: LEGEND_BAR_PX,
        h: map.h,
    };
    for j in 0..legend.h as usize {
        let rgb = colour_map(1.0 - (j as f32 + 0.5) / legend.h);
        for i in 0..legend.w as usize {
            pixels[(legend.y as usize + j) * stride + legend.x as usize + i] = opaque(rgb);
        }
    }
    let ink = Color::from_rgba8(20, 20, 20, 255);
    draw_text(&mut pixmap, &s.title, MARGIN_PX, MARGIN_PX, TITLE_PX, ink);
    legend_labels(&mut pixmap, legend, range, ink);
    frame(&mut pixmap, map, ink);
    frame(&mut pixmap, legend, ink);
    Ok(HeatMapPicture {
        image: RgbaImage::from_pixmap(&pixmap),
        map,
        legend,
        range,
    })
}

/// The points of `s`'s rectangle at the centres of a `mw` x `mh` grid of pixels, row by row
/// from the top: their x and their y coordinates.
fn pixel_centres(s: &HeatMapSettings, mw: usize, mh: usize) -> (Vec<f32>, Vec<f32>) {
    let mut xs = Vec::with_capacity(mw * mh);
    let mut ys = Vec::with_capacity(mw * mh);
    for j in 0..mh {
        let y = s.y.1 - (j as f32 + 0.5) / mh as f32 * (s.y.1 - s.y.0);
        for i in 0..mw {
            xs.push(s.x.0 + (i as f32 + 0.5) / mw as f32 * (s.x.1 - s.x.0));
            ys.push(y);
        }
    }
    (xs, ys)
}

/// The finite values' minimum and maximum, widened when they are equal; (0, 1) for none.
fn fitted_range(values: &[f32]) -> (f32, f32) {
    let finite = values.iter().copied().filter(|v| v.is_finite());
    let (lo, hi) = finite.fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if lo > hi {
        (0.0, 1.0)
    } else if lo == hi {
        (lo - 0.5, hi + 0.5)
    } else {
        (lo, hi)
    }
}

/// The range's maximum beside the top of the legend bar, its minimum beside the bottom.
fn legend_labels(pixmap: &mut Pixmap, legend: PixelRect, range: (f32, f32), ink: Color) {
    // Three significant digits of the span are enough to read the legend.
    let step = 10f64.powf(f64::from(range.1 - range.0).log10().floor() - 2.0);
    let label_x = legend.x + legend.w + 4.0;
    draw_text(
        pixmap,
        &format_number(f64::from(range.1), step),
        label_x,
        legend.y,
        LABEL_PX,
        ink,
    );
    draw_text(
        pixmap,
        &format_number(f64::from(range.0), step),
        label_x,
        legend.y + legend.h - LABEL_PX,
        LABEL_PX,
        ink,
    );
}

/// A one-pixel outline just outside `r`.
pub(crate) fn frame(pixmap: &mut Pixmap, r: PixelRect, c: Color) {
    let mut paint = Paint::default();
    paint.set_color(c);
    let sides = [
        Rect::from_xywh(r.x - 1.0, r.y - 1.0, r.w + 2.0, 1.0),
        Rect::from_xywh(r.x - 1.0, r.y + r.h, r.w + 2.0, 1.0),
        Rect::from_xywh(r.x - 1.0, r.y, 1.0, r.h),
        Rect::from_xywh(r.x + r.w, r.y, 1.0, r.h),
    ];
    for side in sides.into_iter().flatten() {
        pixmap.fill_rect(side, &paint, Transform::identity(), None);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> HeatMapSettings {
        HeatMapSettings {
            x: (-1.0, 1.0),
            y: (0.0, 2.0),
            range: None,
            title: "DENSITY Z=0".into(),
            width: 240,
            height: 160,
        }
    }

    fn close(p: [u8; 4], rgb: [f32; 3]) -> bool {
        (0..3).all(|k| (f32::from(p[k]) - rgb[k] * 255.0).abs() <= 2.0)
    }

    #[test]
    fn ramp_in_x_spans_the_colour_map_and_the_legend_ends_match() {
        let pic = heat_map(|xs, _, out| out.copy_from_slice(xs), &settings()).unwrap();
        let m = pic.map;
        let (left, right) = ((m.x) as u32, (m.x + m.w - 1.0) as u32);
        let mid_y = (m.y + m.h / 2.0) as u32;
        // The automatic range is the sampled one: the outermost pixel centres, half a pixel in.
        let half_pixel = 1.0 / m.w;
        assert!(close(
            pic.image.pixel(left, mid_y).unwrap(),
            colour_map(0.0)
        ));
        assert!(close(
            pic.image.pixel(right, mid_y).unwrap(),
            colour_map(1.0)
        ));
        assert!(close(
            pic.image.pixel((m.x + m.w / 2.0) as u32, mid_y).unwrap(),
            colour_map(0.5 + half_pixel / 2.0)
        ));
        let l = pic.legend;
        let top = pic
            .image
            .pixel((l.x + l.w / 2.0) as u32, l.y as u32)
            .unwrap();
        let bottom = pic
            .image
            .pixel((l.x + l.w / 2.0) as u32, (l.y + l.h - 1.0) as u32)
            .unwrap();
        assert!(close(top, colour_map(1.0)) || close(top, colour_map(1.0 - 0.5 / l.h)));
        assert!(close(bottom, colour_map(0.5 / l.h)), "{bottom:?}");
        assert!(
            (pic.range.0 + 1.0 - half_pixel).abs() < 1e-5
                && (pic.range.1 - 1.0 + half_pixel).abs() < 1e-5,
            "{:?}",
            pic.range
        );
        // Min and max labels put ink to the right of the bar.
        let inked = |y0: f32| {
            (0..10).any(|dy| {
                (0..40).any(|dx| {
                    pic.image
                        .pixel((l.x + l.w + 4.0) as u32 + dx, y0 as u32 + dy)
                        .is_some_and(|p| p[0] < 128)
                })
            })
        };
        assert!(inked(l.y) && inked(l.y + l.h - 10.0));
    }

    #[test]
    fn fixed_range_and_non_finite_samples() {
        let s = HeatMapSettings {
            range: Some((0.0, 1.0)),
            ..settings()
        };
        let pic = heat_map(
            |xs, ys, out| {
                for i in 0..xs.len() {
                    out[i] = if xs[i] < 0.0 { f32::NAN } else { ys[i] * 10.0 }
                }
            },
            &s,
        )
        .unwrap();
        let m = pic.map;
        let p = pic
            .image
            .pixel(m.x as u32 + 2, (m.y + m.h / 2.0) as u32)
            .unwrap();
        assert_eq!(p, [255, 0, 255, 255]);
        // Values above the fixed range clamp to its top colour.
        let top_right = pic
            .image
            .pixel((m.x + m.w - 2.0) as u32, m.y as u32 + 1)
            .unwrap();
        assert!(close(top_right, colour_map(1.0)));
    }

    #[test]
    fn bad_settings_are_errors() {
        let f = |_: &[f32], _: &[f32], _: &mut [f32]| {};
        assert_eq!(
            heat_map(
                f,
                &HeatMapSettings {
                    width: 20,
                    ..settings()
                }
            ),
            Err(PlotError::BadSize(20, 160))
        );
        assert_eq!(
            heat_map(
                f,
                &HeatMapSettings {
                    x: (1.0, 1.0),
                    ..settings()
                }
            ),
            Err(PlotError::BadRectangle)
        );
    }
}
