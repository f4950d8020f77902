//! Sculpting: the brush, strokes drawn with it (by a drag on a surface or with the touch
//! device's button held), their preview meshed while drawn, the one op each ends in, and the
//! Tool panel that sets the brush.

use std::time::Instant;

use eframe::egui;
use glam::{DVec3, Vec3};
use model::scene::ObjectId;
use render::scene::{Line, Scene};
use render::snapshot::render_from_scene;

use super::app::SculptApp;
use super::viewport::{StrokeEvent, StrokePhase};
use ::app::brush::{Brush, BrushOp, Stroke};
use ::app::clock;
use ::app::engine::lock;
use model::object::{Axis, Edit, PaintValue, Paintable, ToolKind};

/// Colour of the brush outline and the stroke being drawn.
const BRUSH_COLOUR: [f32; 4] = [1.0, 1.0, 1.0, 1.0];
/// Milliseconds between preview meshes of a stroke being drawn.
const PREVIEW_MILLIS: u64 = 120;

/// The brush and the stroke drawn with it.
#[derive(Default)]
pub struct Sculpt {
    /// The brush a drag sculpts with.
    pub brush: Brush,
    /// A drag on a surface sculpts (otherwise it orbits).
    pub active: bool,
    /// The stroke being drawn.
    pub stroke: Option<Stroke>,
    /// When the stroke's last preview was sent to the mesher.
    preview_at: Option<Instant>,
    /// The last stroke's points (scene coordinates), for the state dump.
    pub last_stroke: Option<Vec<DVec3>>,
}

impl SculptApp {
    /// One frame of a sculpting drag: begin on the surface under the pointer, follow the
    /// surface, author one op at the end; a preview of the stroke is meshed meanwhile.
    pub(super) fn stroke_event(
        &mut self,
        event: StrokeEvent,
        size_px: [u32; 2],
        scene: &Scene,
        ids: &[ObjectId],
    ) {
        let ray = self.view.camera.ray_through_pixel(event.px, size_px);
        let hit = scene.pick(&ray);
        let at_scene = hit.map(|h| {
            render_from_scene()
                .inverse()
                .transform_point3(h.point_in_world)
                .as_dvec3()
        });
        match event.phase {
            StrokePhase::Begin => {
                let (Some(hit), Some(at)) = (hit, at_scene) else {
                    self.status = "start a stroke on an object's surface".into();
                    return;
                };
                if let Some(id) = ids.get(hit.object_idx) {
                    self.begin_stroke(id.0, at);
                }
            }
            StrokePhase::Move => {
                if let (Some(stroke), Some(at)) = (&mut self.sculpt.stroke, at_scene) {
                    stroke.push(at);
                    self.preview_stroke();
                }
            }
            StrokePhase::End => self.finish_stroke(at_scene),
        }
    }

    /// Begins a stroke of the brush on `object` at `at` (scene coordinates), which selects it.
    fn begin_stroke(&mut self, object: u64, at: DVec3) {
        let begun = Stroke::begin(&lock(self.engine.view()), object, self.sculpt.brush, at);
        match begun {
            Ok(stroke) => {
                self.selected = Some(object);
                self.sculpt.stroke = Some(stroke);
                self.sculpt.preview_at = None;
            }
            Err(e) => self.status = e,
        }
    }

    /// Ends the stroke in progress at `at` (scene coordinates) and authors its one op. The
    /// whole stroke is meshed at once, as a last preview timed from this frame's input, so it
    /// is drawn while the engine stores the op; the scene's own mesh follows (usually the same,
    /// so nothing is drawn again; without the stroke where the fold rejected it).
    fn finish_stroke(&mut self, at: Option<DVec3>) {
        let Some(mut stroke) = self.sculpt.stroke.take() else {
            return;
        };
        if let Some(at) = at {
            stroke.push(at);
        }
        let planned = stroke.finish(&lock(self.engine.view()));
        self.sculpt.last_stroke = Some(stroke.scene_points().to_vec());
        match planned.and_then(|planned| self.author(planned)) {
            Ok(()) => {
                let input_at = self.stats.frame_start();
                self.send_preview(stroke.object, stroke.edit(), Some(input_at));
            }
            Err(e) => {
                self.status = e;
                self.objects.remesh_previews(true);
            }
        }
    }

    /// Meshes the stroked object with the stroke so far, at most every [`PREVIEW_MILLIS`].
    fn preview_stroke(&mut self) {
        let now = clock::now().instant;
        if self
            .sculpt
            .preview_at
            .is_some_and(|t| now.duration_since(t).as_millis() < u128::from(PREVIEW_MILLIS))
        {
            return;
        }
        let Some((object, edit)) = self.sculpt.stroke.as_ref().map(|s| (s.object, s.edit())) else {
            return;
        };
        self.send_preview(object, edit, None);
        self.sculpt.preview_at = Some(now);
    }

    /// Hands the mesher `object` with a stroke's `edit` applied, at once; `edit_input_at`
    /// times it as the edit whose input the frame that started then took.
    fn send_preview(&mut self, object: u64, edit: Edit, edit_input_at: Option<Instant>) {
        let now = clock::now().instant;
        let id = ObjectId(object);
        let (object, world_from_group) = {
            let view = lock(self.engine.view());
            let scene = view.scene();
            let Some(entry) = scene.scene_object(id) else {
                return;
            };
            let mut object = entry.object.clone();
            if object.apply(edit).is_err() {
                return;
            }
            (object, scene.world_from_group(entry.group))
        };
        let t_secs = self.scene_clock.secs(now);
        self.objects
            .preview(id, object, world_from_group, now, t_secs, edit_input_at);
        self.objects.flush();
    }

    /// The touch device's button: pressed on a touched object, the current brush starts a
    /// stroke at the haptic interface point; held, the stroke follows it; released, the
    /// stroke is one op (touch-sculpting).
    pub(super) fn touch_button(&mut self, down: bool) {
        let Some(live) = &self.touch.live else {
            return;
        };
        live.set_button(down);
        let s = live.stats();
        if !down {
            self.finish_stroke(Some(s.hip_world));
            return;
        }
        let Some(object) = s.top_id else {
            self.status = "touch an object to sculpt it with the device".into();
            return;
        };
        self.begin_stroke(object, s.hip_world);
    }

    /// While the touch device's button is held, the stroke follows the haptic interface
    /// point (previewed as a drawn stroke is).
    pub(super) fn follow_touch_stroke(&mut self) {
        let Some(live) = &self.touch.live else {
            return;
        };
        if !live.button_down() {
            return;
        }
        let hip = live.stats().hip_world;
        if let Some(stroke) = &mut self.sculpt.stroke {
            stroke.push(hip);
            self.preview_stroke();
        }
    }

    /// The brush's outline where it would act (under the pointer) and the stroke drawn so far.
    pub(super) fn draw_brush(&self, scene: &mut Scene) {
        if !self.sculpt.active {
            return;
        }
        let tool = self.sculpt.brush.tool();
        if let Some(p) = self.view.pointer {
            let at = glam::Mat4::from_translation(p) * render_from_scene();
            scene.add_tool(&tool, at, BRUSH_COLOUR);
        }
        if let Some(stroke) = &self.sculpt.stroke {
            let to_world = render_from_scene();
            let points: Vec<Vec3> = stroke
                .scene_points()
                .iter()
                .map(|p| to_world.transform_point3(p.as_vec3()))
                .collect();
            for pair in points.windows(2) {
                scene.lines.push(Line {
                    from: pair[0],
                    to: pair[1],
                    colour: BRUSH_COLOUR,
                });
            }
        }
    }

    /// The Tool panel: navigate or sculpt, what the brush does, its shape, size, blend and
    /// mirror plane.
    pub(super) fn tool_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("Tool");
        ui.horizontal(|ui| {
            ui.selectable_value(&mut self.sculpt.active, false, "Navigate")
                .on_hover_text("drag orbits (Esc)");
            ui.selectable_value(&mut self.sculpt.active, true, "Sculpt")
                .on_hover_text("drag on a surface sculpts, right-drag orbits (B)");
        });
        if !self.sculpt.active {
            return;
        }
        let b = &mut self.sculpt.brush;
        ui.horizontal(|ui| {
            ui.selectable_value(&mut b.op, BrushOp::Add, "add");
            ui.selectable_value(&mut b.op, BrushOp::Carve, "carve");
            let painting = matches!(b.op, BrushOp::Paint(..));
            if ui.selectable_label(painting, "paint").clicked() && !painting {
                b.op = BrushOp::Paint(Paintable::Density, PaintValue::Scalar(0.8));
            }
        });
        if let BrushOp::Paint(property, value) = &mut b.op {
            ui.horizontal(|ui| paint_ui(ui, property, value));
        }
        ui.horizontal(|ui| shape_ui(ui, b));
        let [lo, hi] = ::app::brush::RADIUS_RANGE;
        ui.add(
            egui::Slider::new(&mut b.radius, lo..=1.0_f64.min(hi))
                .logarithmic(true)
                .text("radius"),
        );
        let blend_max = b.radius * 2.0;
        ui.add(egui::Slider::new(&mut b.blend, 0.0..=blend_max).text("blend"));
    }
}

/// What a painting brush paints: the property, and its value (a colour or a number).
fn paint_ui(ui: &mut egui::Ui, property: &mut Paintable, value: &mut PaintValue) {
    egui::ComboBox::from_id_salt("paint-property")
        .selected_text(::app::brush::paint_name(*property))
        .show_ui(ui, |ui| {
            for p in Paintable::ALL {
                ui.selectable_value(property, p, ::app::brush::paint_name(p));
            }
        });
    match (*property, &mut *value) {
        (Paintable::Color, PaintValue::Color(c)) => {
            ui.color_edit_button_rgb(c);
        }
        (Paintable::Color, v) => *v = PaintValue::Color([1.0, 0.2, 0.2]),
        (_, PaintValue::Scalar(x)) => {
            ui.add(egui::Slider::new(x, 0.0..=1.0).text("value"));
        }
        (_, v) => *v = PaintValue::Scalar(0.8),
    }
}

/// The brush's shape and its mirror plane.
fn shape_ui(ui: &mut egui::Ui, b: &mut Brush) {
    for kind in ToolKind::ALL {
        ui.selectable_value(&mut b.shape, kind, kind.label());
    }
    ui.label("mirror");
    egui::ComboBox::from_id_salt("mirror")
        .selected_text(match b.mirror {
            None => "off",
            Some(Axis::X) => "x",
            Some(Axis::Y) => "y",
            Some(Axis::Z) => "z",
        })
        .show_ui(ui, |ui| {
            ui.selectable_value(&mut b.mirror, None, "off");
            ui.selectable_value(&mut b.mirror, Some(Axis::X), "x");
            ui.selectable_value(&mut b.mirror, Some(Axis::Y), "y");
            ui.selectable_value(&mut b.mirror, Some(Axis::Z), "z");
        });
}
