//! The 3D viewport: the orbit camera's mouse handling and picking (`viewport_ui`), and the
//! window's frame of it: the scene it draws (objects, other peers, the touch tool, the
//! brush) and what a click, a drag or the pointer does there. Drawing on the GPU is
//! `gpu.rs`.

pub(super) mod gpu;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use eframe::egui;
use eframe::egui_wgpu;
use glam::Vec3;
use model::scene::ObjectId;
use render::camera::Camera;
use render::mesh::Mesh;
use render::mesh::octree::MeshPatch;
use render::scene::{PickHit, Scene};
use render::snapshot::{View, frame, render_from_scene};

use super::app::SculptApp;
use super::objects::MAX_EDIT_WAIT_MILLIS;
use ::app::clock;
use gpu::{ViewportCallback, ViewportReport};

/// Largest viewport side in pixels (the texture is this big at most).
pub const MAX_VIEWPORT_SIDE_PX: u32 = 8192;
/// Radians of orbit per point dragged.
const ORBIT_RADIANS_PER_POINT: f32 = 0.01;
/// Zoom factor per point of scroll, as an exponent.
const ZOOM_PER_SCROLL_POINT: f32 = 0.002;
/// Shift+wheel moves the touch tool by this fraction of the scene's radius per point.
const TOUCH_DEPTH_PER_SCROLL_POINT: f32 = 0.002;

/// The camera, how the user has moved it, and what the pointer is over.
#[derive(Clone, Debug, Default)]
pub struct ViewState {
    /// The current camera.
    pub camera: Camera,
    /// Whether the user moved it (then new meshes no longer re-frame the view).
    pub moved: bool,
    /// The surface point under the pointer, in the renderer's world.
    pub pointer: Option<Vec3>,
}

/// The view the camera starts from and returns to.
pub fn home_view() -> View {
    View {
        name: "home".into(),
        yaw: 0.78,
        pitch: 0.45,
    }
}

/// What the user did in the viewport this frame.
#[derive(Clone, Copy, Debug, Default)]
pub struct ViewportInput {
    /// A click hit this (object index into the drawn scene, point).
    pub picked: Option<PickHit>,
    /// A click that hit nothing.
    pub missed: bool,
    /// Double-click (or `F`): frame everything again.
    pub reset: bool,
    /// The viewport's size in pixels.
    pub size_px: [u32; 2],
    /// Where the pointer hovers, in pixels of the viewport, when it moved this frame.
    pub hover_px: Option<[f32; 2]>,
    /// The user dragged or zoomed the camera this frame.
    pub moved: bool,
    /// A sculpting drag (primary button while a tool is active): where, and which phase.
    pub stroke: Option<StrokeEvent>,
    /// Shift+wheel while touching: points of scroll to move the touch tool in depth
    /// (positive: away from the camera).
    pub depth_scroll: f32,
    /// While touching, the primary button went down (true) or up (false) on the viewport:
    /// the touch device's button.
    pub touch_button: Option<bool>,
}

/// What the pointer does in the viewport besides navigating.
#[derive(Clone, Copy, Debug, Default)]
pub struct Modes {
    /// A primary drag sculpts (secondary orbits).
    pub sculpting: bool,
    /// The touch tool follows the pointer; Shift+wheel moves it in depth; a primary drag is
    /// the device's button (touch-sculpting) and the secondary one orbits.
    pub touching: bool,
}

/// One frame of a sculpting drag.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StrokeEvent {
    /// Begin, move or end.
    pub phase: StrokePhase,
    /// The pointer, in pixels of the viewport.
    pub px: [f32; 2],
}

/// The phases of a drag.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StrokePhase {
    /// The button went down on the viewport.
    Begin,
    /// The pointer moved with the button down.
    Move,
    /// The button came up.
    End,
}

/// Takes the rest of `ui` for the viewport and handles orbit (drag), zoom (scroll), reset
/// (double-click or `F`) and picking (click, on `scene`: what the last frame drew); while
/// touching, Shift+scroll moves the touch tool in depth instead of zooming. Returns the
/// input and the viewport's rectangle, which [`viewport_paint`] draws once the input has
/// been acted on.
pub fn viewport_input(
    ui: &mut egui::Ui,
    modes: Modes,
    view: &mut ViewState,
    scene: &Scene,
    sphere: Option<(Vec3, f32)>,
) -> (ViewportInput, egui::Rect) {
    let (rect, response) =
        ui.allocate_exact_size(ui.available_size(), egui::Sense::click_and_drag());
    let ppp = ui.ctx().pixels_per_point();
    let size_px = [
        ((rect.width() * ppp).round() as u32).clamp(1, MAX_VIEWPORT_SIDE_PX),
        ((rect.height() * ppp).round() as u32).clamp(1, MAX_VIEWPORT_SIDE_PX),
    ];
    let mut input = ViewportInput {
        size_px,
        ..ViewportInput::default()
    };
    let at_px = |pos: egui::Pos2| [(pos.x - rect.min.x) * ppp, (pos.y - rect.min.y) * ppp];
    primary_button(&response, modes, at_px, &mut input);
    orbit(&response, modes, view, &mut input);
    if response.hovered() {
        scroll_and_hover(ui, &response, modes, view, at_px, &mut input);
    }
    let key_reset =
        !ui.ctx().egui_wants_keyboard_input() && ui.input(|i| i.key_pressed(egui::Key::F));
    if response.double_clicked() || key_reset {
        input.reset = true;
        view.moved = false;
    }
    if !view.moved {
        view.camera = frame(sphere, &home_view(), size_px[0], size_px[1]);
    }
    if response.clicked()
        && let Some(pos) = response.interact_pointer_pos()
    {
        let ray = view.camera.ray_through_pixel(at_px(pos), size_px);
        input.picked = scene.pick(&ray);
        input.missed = input.picked.is_none();
    }
    (input, rect)
}

/// Draws `scene` (its camera set from `view`) with `patches` applied in the viewport's
/// `rect`, `size_px` pixels.
pub fn viewport_paint(
    ui: &egui::Ui,
    (rect, size_px): (egui::Rect, [u32; 2]),
    view: &ViewState,
    mut scene: Scene,
    patches: Vec<(usize, Arc<Mesh>, Arc<Mesh>, MeshPatch)>,
    report: &Arc<Mutex<ViewportReport>>,
) {
    scene.camera = view.camera;
    ui.painter().add(egui_wgpu::Callback::new_paint_callback(
        rect,
        ViewportCallback {
            scene,
            patches,
            size_px,
            report: Arc::clone(report),
        },
    ));
}

/// The primary button: a sculpting drag's phases, or (while touching) the touch device's
/// button, which sculpts at the tool rather than under the pointer.
fn primary_button(
    response: &egui::Response,
    modes: Modes,
    at_px: impl Fn(egui::Pos2) -> [f32; 2],
    input: &mut ViewportInput,
) {
    let primary = egui::PointerButton::Primary;
    if modes.sculpting
        && !modes.touching
        && let Some(pos) = response.interact_pointer_pos()
    {
        let phase = if response.drag_started_by(primary) {
            Some(StrokePhase::Begin)
        } else if response.drag_stopped_by(primary) {
            Some(StrokePhase::End)
        } else if response.dragged_by(primary) {
            Some(StrokePhase::Move)
        } else {
            None
        };
        input.stroke = phase.map(|phase| StrokeEvent {
            phase,
            px: at_px(pos),
        });
    }
    if modes.touching {
        if response.drag_started_by(primary) {
            input.touch_button = Some(true);
        } else if response.drag_stopped_by(primary) {
            input.touch_button = Some(false);
        }
    }
}

/// Orbits the camera by a drag: either button when navigating, the secondary one while
/// the primary sculpts or touches.
fn orbit(response: &egui::Response, modes: Modes, view: &mut ViewState, input: &mut ViewportInput) {
    let orbiting = if modes.sculpting || modes.touching {
        response.dragged_by(egui::PointerButton::Secondary)
    } else {
        response.dragged_by(egui::PointerButton::Primary)
            || response.dragged_by(egui::PointerButton::Secondary)
    };
    let d = response.drag_delta();
    if orbiting && d != egui::Vec2::ZERO {
        view.camera.orbit(
            -d.x * ORBIT_RADIANS_PER_POINT,
            d.y * ORBIT_RADIANS_PER_POINT,
        );
        view.moved = true;
        input.moved = true;
    }
}

/// Over the viewport: the wheel zooms (or, with Shift while touching, moves the touch tool
/// in depth), and a moving pointer is where it hovers.
fn scroll_and_hover(
    ui: &egui::Ui,
    response: &egui::Response,
    modes: Modes,
    view: &mut ViewState,
    at_px: impl Fn(egui::Pos2) -> [f32; 2],
    input: &mut ViewportInput,
) {
    let (scroll, shift) = ui.input(|i| (i.smooth_scroll_delta.y, i.modifiers.shift));
    if modes.touching && shift {
        // egui turns Shift+wheel into horizontal scrolling on some platforms.
        let both = ui.input(|i| i.smooth_scroll_delta);
        input.depth_scroll = -(both.x + both.y);
    } else if scroll != 0.0 {
        view.camera.zoom((-scroll * ZOOM_PER_SCROLL_POINT).exp());
        view.moved = true;
        input.moved = true;
    }
    if let Some(pos) = response.hover_pos()
        && ui.input(|i| i.pointer.is_moving())
    {
        input.hover_px = Some(at_px(pos));
    }
}

impl SculptApp {
    /// The viewport's frame: the scene drawn, then what the user (or a script) did there.
    /// The viewport's frame: its input is acted on first (picks and strokes on what the last
    /// frame drew), then what that changed is drawn, so that a stroke's lines, the pointer
    /// and a released stroke's mesh show in the frame that took their input.
    pub(super) fn central_ui(&mut self, ui: &mut egui::Ui) {
        let (scene, ids) = self.objects.drawn_scene(self.selected);
        let sphere = self.objects.bounding_sphere();
        let modes = Modes {
            sculpting: self.sculpt.active,
            touching: self.touch.live.is_some(),
        };
        let (input, rect) = viewport_input(ui, modes, &mut self.view, &scene, sphere);
        self.viewport_acts(input, &scene, &ids);
        let deadline = self.stats.frame_start() + Duration::from_millis(MAX_EDIT_WAIT_MILLIS);
        self.objects
            .await_sent_edits(clock::now().instant, deadline);
        let (scene, ids) = self.drawn_scene();
        let patches = self.objects.take_patches(&ids);
        let at = (rect, input.size_px);
        viewport_paint(ui, at, &self.view, scene, patches, &self.viewport);
    }

    /// Acts on the viewport's `input`: a stroke, a pick, the pointer and the touch tool, on
    /// `scene` as the last frame drew it (its objects' ids in `ids`).
    fn viewport_acts(&mut self, mut input: ViewportInput, scene: &Scene, ids: &[ObjectId]) {
        let sphere = self.objects.bounding_sphere();
        if let Some(event) = self.hooks.scripted_stroke(input.size_px) {
            input.stroke = Some(event);
        }
        if let Some(event) = input.stroke {
            self.stroke_event(event, input.size_px, scene, ids);
        } else if input.picked.is_some() || input.missed {
            self.picked(input.picked, ids);
        }
        if input.moved {
            self.presence.following = None;
        }
        if let Some(px) = input.hover_px {
            let ray = self.view.camera.ray_through_pixel(px, input.size_px);
            self.view.pointer = scene.pick(&ray).map(|hit| hit.point_in_world);
        }
        self.touch_frame(input.touch_button);
        if input.hover_px.is_some() || input.depth_scroll != 0.0 {
            let depth =
                input.depth_scroll * TOUCH_DEPTH_PER_SCROLL_POINT * sphere.map_or(1.0, |s| s.1);
            self.touch_follow(input.hover_px, input.size_px, depth);
        }
        if let Some(at) = self.hooks.take_pick_if_ready(self.is_idle()) {
            let size_px = input.size_px;
            let px = [at[0] * size_px[0] as f32, at[1] * size_px[1] as f32];
            let ray = self.view.camera.ray_through_pixel(px, size_px);
            let hit = scene.pick(&ray);
            self.picked(hit, ids);
        }
    }

    /// What the viewport draws: objects in id order (their ids alongside, for picking),
    /// arrows, the selection's box, other peers, the touch tool and the brush.
    fn drawn_scene(&self) -> (Scene, Vec<ObjectId>) {
        let (mut scene, ids) = self.objects.drawn_scene(self.selected);
        self.draw_presence(&mut scene);
        self.draw_touch(&mut scene);
        self.draw_brush(&mut scene);
        (scene, ids)
    }

    /// Shows what a click hit in the status line and selects the object.
    fn picked(&mut self, hit: Option<PickHit>, ids: &[ObjectId]) {
        let Some(hit) = hit else {
            self.pick_status = "nothing there".into();
            return;
        };
        let Some(id) = ids.get(hit.object_idx) else {
            return;
        };
        self.selected = Some(id.0);
        // The renderer's world is +z up; formulas live in the scene's +y-up space.
        let p = render_from_scene()
            .inverse()
            .transform_point3(hit.point_in_world);
        self.pick_status = format!(
            "picked {} at ({:.3}, {:.3}, {:.3}) (scene coordinates)",
            ::app::engine::lock(self.engine.view()).object_label(id.0),
            p.x,
            p.y,
            p.z
        );
    }
}
