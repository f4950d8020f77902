//! Time-series line plots: several named series, axes with ticks and labels, a title, a legend.
//!
//! For force traces from the haptic loop and convergence curves from the simulator.

use super::font::{draw_text, text_width};
use super::heat_map::frame;
use super::{MAX_PICTURE_SIDE, PixelRect, PlotError, colour, format_number};
use crate::image::RgbaImage;
use tiny_skia::{
    Color, FillRule, LineCap, LineJoin, Mask, Paint, PathBuilder, Pixmap, Rect, Stroke, Transform,
};

/// Most series one plot draws; further series are ignored.
pub const MAX_SERIES: usize = 16;
/// Most points drawn per series; further points are ignored.
pub const MAX_POINTS: usize = 1 << 20;
/// Tick marks aimed for along each axis.
const TICKS_TARGET: f64 = 5.0;
const MARGIN_PX: f32 = 10.0;
const TITLE_PX: f32 = 12.0;
const LABEL_PX: f32 = 9.0;
const TICK_PX: f32 = 4.0;
const LINE_WIDTH_PX: f32 = 2.0;
/// Smallest plotting area that still shows something.
const MIN_PLOT_SIDE_PX: f32 = 16.0;

/// One named curve.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Name shown in the legend.
    pub name: String,
    /// Line colour, linear RGBA 0..1.
    pub colour: [f32; 4],
    /// (x, y) samples in drawing order; a non-finite point breaks the line.
    pub points: Vec<[f64; 2]>,
}

/// A line plot of several series against a shared x axis (usually time).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LinePlot {
    /// Title above the plot.
    pub title: String,
    /// Label under the x axis, e.g. "TIME S".
    pub x_label: String,
    /// Label above the y axis, e.g. "FORCE N".
    pub y_label: String,
    /// The curves.
    pub series: Vec<Series>,
    /// Fixed x range; `None` fits the data, widened to whole ticks.
    pub x_range: Option<(f64, f64)>,
    /// Fixed y range; `None` fits the data, widened to whole ticks.
    pub y_range: Option<(f64, f64)>,
}

/// A drawn plot and its mapping from data to pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct PlotPicture {
    /// The picture.
    pub image: RgbaImage,
    /// The plotting area inside the axes.
    pub area: PixelRect,
    /// The x range the area spans.
    pub x_range: (f64, f64),
    /// The y range the area spans.
    pub y_range: (f64, f64),
}

impl PlotPicture {
    /// The pixel where data point `p` is drawn.
    pub fn data_to_pixel(&self, p: [f64; 2]) -> [f32; 2] {
        to_pixel(self.area, self.x_range, self.y_range, p)
    }
}

fn to_pixel(area: PixelRect, xr: (f64, f64), yr: (f64, f64), p: [f64; 2]) -> [f32; 2] {
    let fx = (p[0] - xr.0) / (xr.1 - xr.0);
    let fy = (p[1] - yr.0) / (yr.1 - yr.0);
    [
        area.x + (fx as f32) * area.w,
        area.y + area.h - (fy as f32) * area.h,
    ]
}

/// A tick spacing of 1, 2 or 5 times a power of ten giving about `TICKS_TARGET` ticks.
fn tick_step(span: f64) -> f64 {
    let raw = span / TICKS_TARGET;
    let power = 10f64.powf(raw.log10().floor());
    let m = raw / power;
    power
        * if m < 1.5 {
            1.0
        } else if m < 3.5 {
            2.0
        } else if m < 7.5 {
            5.0
        } else {
            10.0
        }
}

/// The range to draw: fixed if given and sane, else the data's, widened to whole ticks.
fn axis_range(fixed: Option<(f64, f64)>, values: impl Iterator<Item = f64>) -> (f64, f64) {
    if let Some((lo, hi)) = fixed.filter(|(lo, hi)| lo.is_finite() && hi.is_finite() && lo < hi) {
        return (lo, hi);
    }
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    let (lo, hi) = if lo > hi {
        (0.0, 1.0)
    } else if lo == hi {
        (
            lo - 0.5f64.max(lo.abs() * 0.1),
            hi + 0.5f64.max(hi.abs() * 0.1),
        )
    } else {
        (lo, hi)
    };
    let step = tick_step(hi - lo);
    ((lo / step).floor() * step, (hi / step).ceil() * step)
}

fn ticks(range: (f64, f64)) -> (Vec<f64>, f64) {
    let step = tick_step(range.1 - range.0);
    let first = (range.0 / step - 1e-9).ceil() as i64;
    let last = (range.1 / step + 1e-9).floor() as i64;
    // At most a dozen ticks: the step guarantees it, the cap keeps a bad range from looping.
    (
        (first..=last).take(12).map(|i| i as f64 * step).collect(),
        step,
    )
}

/// Grid lines across `area`, tick marks and tick labels at each axis's ticks; `axes` holds,
/// for x then y, the range the area spans, the ticks and their step.
fn draw_grid(
    pixmap: &mut Pixmap,
    area: PixelRect,
    axes: [((f64, f64), &[f64], f64); 2],
    ink: Color,
) {
    let [(x_range, x_ticks, x_step), (y_range, y_ticks, y_step)] = axes;
    let grid = paint(Color::from_rgba8(225, 225, 225, 255));
    let ink_paint = paint(ink);
    let to_px = |p: [f64; 2]| to_pixel(area, x_range, y_range, p);
    for &x in x_ticks {
        let [px, _] = to_px([x, y_range.0]);
        let px = px.round();
        fill(pixmap, Rect::from_xywh(px, area.y, 1.0, area.h), &grid);
        fill(
            pixmap,
            Rect::from_xywh(px, area.y + area.h, 1.0, TICK_PX),
            &ink_paint,
        );
        let label = format_number(x, x_step);
        draw_text(
            pixmap,
            &label,
            px - text_width(&label, LABEL_PX) / 2.0,
            area.y + area.h + TICK_PX + 4.0,
            LABEL_PX,
            ink,
        );
    }
    for &y in y_ticks {
        let [_, py] = to_px([x_range.0, y]);
        let py = py.round();
        fill(pixmap, Rect::from_xywh(area.x, py, area.w, 1.0), &grid);
        fill(
            pixmap,
            Rect::from_xywh(area.x - TICK_PX, py, TICK_PX, 1.0),
            &ink_paint,
        );
        let label = format_number(y, y_step);
        draw_text(
            pixmap,
            &label,
            area.x - TICK_PX - 4.0 - text_width(&label, LABEL_PX),
            py - LABEL_PX / 2.0,
            LABEL_PX,
            ink,
        );
    }
}

fn paint(c: Color) -> Paint<'static> {
    let mut p = Paint::default();
    p.set_color(c);
    p.anti_alias = true;
    p
}

impl LinePlot {
    fn series_drawn(&self) -> impl Iterator<Item = &Series> {
        self.series.iter().take(MAX_SERIES)
    }

    /// Draws the plot at `width` x `height` pixels.
    pub fn render(&self, width: u32, height: u32) -> Result<PlotPicture, PlotError> {
        let points = || {
            self.series_drawn()
                .flat_map(|s| s.points.iter().take(MAX_POINTS))
        };
        let x_range = axis_range(self.x_range, points().map(|p| p[0]));
        let y_range = axis_range(self.y_range, points().map(|p| p[1]));
        let (x_ticks, x_step) = ticks(x_range);
        let (y_ticks, y_step) = ticks(y_range);
        let y_label_w = y_ticks
            .iter()
            .map(|&v| text_width(&format_number(v, y_step), LABEL_PX))
            .fold(0.0, f32::max);
        let left = MARGIN_PX + y_label_w + TICK_PX + 4.0;
        let top = MARGIN_PX + TITLE_PX + MARGIN_PX + LABEL_PX + 8.0;
        let area = PixelRect {
            x: left,
            y: top,
            w: width as f32 - left - MARGIN_PX,
            h: height as f32 - top - (TICK_PX + 4.0 + LABEL_PX + 6.0 + LABEL_PX + MARGIN_PX),
        };
        if width > MAX_PICTURE_SIDE
            || height > MAX_PICTURE_SIDE
            || area.w < MIN_PLOT_SIDE_PX
            || area.h < MIN_PLOT_SIDE_PX
        {
            return Err(PlotError::BadSize(width, height));
        }
        let mut pixmap = Pixmap::new(width, height).ok_or(PlotError::BadSize(width, height))?;
        pixmap.fill(Color::WHITE);
        let ink = Color::from_rgba8(20, 20, 20, 255);
        self.draw_labels(&mut pixmap, area, ink);
        let to_px = |p: [f64; 2]| to_pixel(area, x_range, y_range, p);
        draw_grid(
            &mut pixmap,
            area,
            [(x_range, &x_ticks, x_step), (y_range, &y_ticks, y_step)],
            ink,
        );
        self.draw_series(&mut pixmap, area, &to_px);
        frame(&mut pixmap, area, ink);
        self.draw_legend(&mut pixmap, area);
        Ok(PlotPicture {
            image: RgbaImage::from_pixmap(&pixmap),
            area,
            x_range,
            y_range,
        })
    }

    /// The title above the plot, the y axis's label over the axis and the x axis's under it.
    fn draw_labels(&self, pixmap: &mut Pixmap, area: PixelRect, ink: Color) {
        let (width, height) = (pixmap.width(), pixmap.height());
        let title_x = (width as f32 - text_width(&self.title, TITLE_PX)) / 2.0;
        draw_text(
            pixmap,
            &self.title,
            title_x.max(MARGIN_PX),
            MARGIN_PX,
            TITLE_PX,
            ink,
        );
        draw_text(
            pixmap,
            &self.y_label,
            MARGIN_PX,
            area.y - LABEL_PX - 10.0,
            LABEL_PX,
            ink,
        );
        let x_label_x = area.x + (area.w - text_width(&self.x_label, LABEL_PX)) / 2.0;
        draw_text(
            pixmap,
            &self.x_label,
            x_label_x,
            height as f32 - MARGIN_PX - LABEL_PX,
            LABEL_PX,
            ink,
        );
    }

    fn draw_series(
        &self,
        pixmap: &mut Pixmap,
        area: PixelRect,
        to_px: &impl Fn([f64; 2]) -> [f32; 2],
    ) {
        // Clip to the plotting area so fixed ranges can cut curves off.
        let mut clip = Mask::new(pixmap.width(), pixmap.height());
        if let (Some(clip), Some(rect)) = (
            clip.as_mut(),
            Rect::from_xywh(area.x, area.y, area.w, area.h),
        ) {
            clip.fill_path(
                &PathBuilder::from_rect(rect),
                FillRule::Winding,
                false,
                Transform::identity(),
            );
        }
        let stroke = Stroke {
            width: LINE_WIDTH_PX,
            line_cap: LineCap::Round,
            line_join: LineJoin::Round,
            ..Stroke::default()
        };
        for s in self.series_drawn() {
            let mut pb = PathBuilder::new();
            let mut pen_down = false;
            for p in s.points.iter().take(MAX_POINTS) {
                let [x, y] = to_px(*p);
                // Far-off points would overflow the rasteriser; treat them like gaps.
                if !(x.is_finite() && y.is_finite() && x.abs() < 1e6 && y.abs() < 1e6) {
                    pen_down = false;
                    continue;
                }
                if pen_down {
                    pb.line_to(x, y)
                } else {
                    pb.move_to(x, y)
                }
                pen_down = true;
            }
            if let Some(path) = pb.finish() {
                pixmap.stroke_path(
                    &path,
                    &paint(colour(s.colour)),
                    &stroke,
                    Transform::identity(),
                    clip.as_ref(),
                );
            }
        }
    }

    fn draw_legend(&self, pixmap: &mut Pixmap, area: PixelRect) {
        let n = self.series_drawn().count();
        if n == 0 {
            return;
        }
        let row = LABEL_PX + 6.0;
        let name_w = self
            .series_drawn()
            .map(|s| text_width(&s.name, LABEL_PX))
            .fold(0.0, f32::max);
        let w = 4.0 + 16.0 + 4.0 + name_w + 4.0;
        let h = 4.0 + n as f32 * row;
        let x = area.x + area.w - w - 4.0;
        let y = area.y + 4.0;
        fill(
            pixmap,
            Rect::from_xywh(x, y, w, h),
            &paint(Color::from_rgba8(255, 255, 255, 230)),
        );
        frame(
            pixmap,
            PixelRect { x, y, w, h },
            Color::from_rgba8(120, 120, 120, 255),
        );
        for (i, s) in self.series_drawn().enumerate() {
            let ry = y + 4.0 + i as f32 * row;
            fill(
                pixmap,
                Rect::from_xywh(x + 4.0, ry + LABEL_PX / 2.0 - 1.0, 16.0, 3.0),
                &paint(colour(s.colour)),
            );
            draw_text(
                pixmap,
                &s.name,
                x + 24.0,
                ry,
                LABEL_PX,
                Color::from_rgba8(20, 20, 20, 255),
            );
        }
    }
}

fn fill(pixmap: &mut Pixmap, r: Option<Rect>, p: &Paint<'_>) {
    if let Some(r) = r {
        pixmap.fill_rect(r, p, Transform::identity(), None);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RED: [f32; 4] = [1.0, 0.0, 0.0, 1.0];
    const BLUE: [f32; 4] = [0.0, 0.0, 1.0, 1.0];

    fn plot() -> LinePlot {
        LinePlot {
            title: "FORCE TRACE".into(),
            x_label: "TIME S".into(),
            y_label: "FORCE N".into(),
            series: vec![
                Series {
                    name: "FLAT".into(),
                    colour: RED,
                    points: vec![[0.0, 0.5], [10.0, 0.5]],
                },
                Series {
                    name: "RAMP".into(),
                    colour: BLUE,
                    points: (0..=10)
                        .map(|i| [f64::from(i), f64::from(i) / 10.0])
                        .collect(),
                },
            ],
            x_range: None,
            y_range: None,
        }
    }

    #[test]
    fn lines_cross_the_pixels_their_data_map_to() {
        let pic = plot().render(320, 200).unwrap();
        assert_eq!(pic.x_range, (0.0, 10.0));
        assert_eq!(pic.y_range, (0.0, 1.0));
        let [x, y] = pic.data_to_pixel([2.5, 0.5]);
        assert_eq!(pic.image.pixel(x as u32, y as u32), Some([255, 0, 0, 255]));
        let [x, y] = pic.data_to_pixel([7.0, 0.7]);
        let p = pic.image.pixel(x as u32, y as u32).unwrap();
        assert!(p[2] > 200 && p[0] < 60, "ramp pixel {p:?}");
        // Axis frame at the bottom-left corner, white background outside the plot.
        let a = pic.area;
        assert_eq!(
            pic.image.pixel((a.x - 1.0) as u32, (a.y + a.h) as u32),
            Some([20, 20, 20, 255])
        );
        assert_eq!(pic.image.pixel(1, 1), Some([255, 255, 255, 255]));
    }

    #[test]
    fn ticks_labels_title_and_legend_are_drawn() {
        let pic = plot().render(320, 200).unwrap();
        let a = pic.area;
        let dark = |x0: f32, y0: f32, w: f32, h: f32| {
            (0..h as u32).any(|dy| {
                (0..w as u32).any(|dx| {
                    pic.image
                        .pixel(x0 as u32 + dx, y0 as u32 + dy)
                        .is_some_and(|p| p[0] < 100 && p[2] < 100)
                })
            })
        };
        assert!(
            dark(a.x - 30.0, a.y + a.h - 8.0, 26.0, 16.0),
            "y tick label 0"
        );
        assert!(
            dark(a.x - 10.0, a.y + a.h + 6.0, 20.0, 12.0),
            "x tick label 0"
        );
        assert!(dark(100.0, 10.0, 120.0, 12.0), "title");
        // The legend swatches sit in the top-right corner in series order.
        let swatch = |colour: [u8; 4]| {
            (0..60).any(|dx| {
                (0..40).any(|dy| {
                    pic.image
                        .pixel((a.x + a.w) as u32 - 60 + dx, a.y as u32 + dy)
                        == Some(colour)
                })
            })
        };
        assert!(swatch([255, 0, 0, 255]) && swatch([0, 0, 255, 255]));
    }

    #[test]
    fn fixed_range_clips_and_nice_ticks_cover_the_data() {
        let p = LinePlot {
            y_range: Some((0.0, 0.4)),
            ..plot()
        };
        let pic = p.render(320, 200).unwrap();
        let [x, _] = pic.data_to_pixel([2.5, 0.5]);
        for y in 0..pic.area.y as u32 - 1 {
            assert_ne!(
                pic.image.pixel(x as u32, y),
                Some([255, 0, 0, 255]),
                "clipped line drawn at y {y}"
            );
        }
        assert_eq!(axis_range(None, [0.13, 1.87].into_iter()), (0.0, 2.0));
        let (lo, hi) = axis_range(None, [3.0, 3.0].into_iter());
        assert!(lo < 3.0 && 3.0 < hi && hi - lo <= 1.5, "{lo} {hi}");
        assert_eq!(axis_range(None, std::iter::empty()), (0.0, 1.0));
        assert_eq!(tick_step(47.0), 10.0);
        assert_eq!(ticks((0.0, 1.0)).0.len(), 6);
    }

    #[test]
    fn tiny_pictures_are_errors_and_empty_plots_draw() {
        assert_eq!(plot().render(30, 30), Err(PlotError::BadSize(30, 30)));
        let empty = LinePlot::default().render(200, 120).unwrap();
        assert_eq!(empty.x_range, (0.0, 1.0));
    }
}
