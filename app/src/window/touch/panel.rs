//! The Touch section of the side panel: touching on or off, the 3D mouse, what the servo
//! feels and a plot of it, the haptic zone, the force-feedback device, the tool's body, the
//! tool held with another peer, and recording the path.

use eframe::egui;

use crate::window::app::SculptApp;
use crate::window::transfer::FileAction;
use ::app::engine::lock;
use ::app::touch::record::FORCE_HISTORY_SECS;
use ::app::touch::shared::SharedState;
use replication::PeerId;

impl SculptApp {
    /// The Touch section: start or stop touching with the mouse, and what the servo feels.
    pub(in crate::window) fn touch_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("Touch");
        self.touch_switches_ui(ui);
        let Some(live) = &self.touch.live else {
            return;
        };
        let s = live.stats();
        let touched = s.top_id.map_or_else(
            || "nothing".to_string(),
            |id| lock(self.engine.view()).object_label(id),
        );
        ui.label(format!(
            "force {:.2} N · touching {touched}",
            s.force_newtons.length()
        ));
        ui.label(format!(
            "servo: {} ticks, {} late · tick compute p50 {} µs, p99.9 {} µs, max {} µs",
            s.n_ticks, s.n_overruns, s.compute_micros[0], s.compute_micros[2], s.compute_micros[3]
        ));
        self.force_plot_ui(ui, s.energy_joules);
        self.zone_ui(ui);
        self.force_output_ui(ui);
        ui.label(format!("your tool: {}", self.touch.body.describe()))
            .on_hover_text(
                "others feel your tool when it has tension or density: set them with \
                 `probe: radius 0.1 tension 0.8 friction 0.3 density 1` (or `probe: off`)",
            );
        self.shared_tool_ui(ui);
        self.recording_ui(ui);
    }

    /// Touching on or off, and the 3D mouse with its state.
    fn touch_switches_ui(&mut self, ui: &mut egui::Ui) {
        let on = self.touch.live.is_some();
        let word = if on {
            "Stop touching"
        } else {
            "Touch with the mouse"
        };
        let tip = "run the 1 kHz haptic servo on this scene: the tool follows the pointer \
                   (Shift+wheel: depth) and the force a Falcon-class device would give is drawn";
        if ui.button(word).on_hover_text(tip).clicked()
            && let Err(e) = self.set_touching(!on)
        {
            self.status = format!("cannot touch: {e}");
        }
        let mut with_3d_mouse = self.touch.spacemouse.is_some();
        let tip = "move the tool with a 3D mouse (3Dconnexion SpaceMouse): push the cap to \
                   move it, its left button sculpts; plugging and unplugging are fine";
        if ui
            .checkbox(&mut with_3d_mouse, "3D mouse")
            .on_hover_text(tip)
            .changed()
            && let Err(e) = self.set_spacemouse(with_3d_mouse)
        {
            self.status = format!("cannot use the 3D mouse: {e}");
        }
        if let Some((driver, _)) = &self.touch.spacemouse {
            ui.label(driver.status().text());
        }
    }

    /// Recording the tool's path: start (asking where) or stop.
    fn recording_ui(&mut self, ui: &mut egui::Ui) {
        match &self.touch.recording {
            Some((recorder, _)) => {
                let word = format!("Stop recording ({} points)", recorder.n_rows());
                if ui.button(word).clicked() {
                    self.stop_touch_recording();
                }
            }
            None => {
                let tip = "write the tool's path as CSV (t,x,y,z,button), which \
                           `sculpt touch SCENE --trace FILE --out FORCES.csv` replays headless";
                if ui.button("Record the path…").on_hover_text(tip).clicked() {
                    self.transfer.input = Some((FileAction::RecordTouch, String::new(), None));
                }
            }
        }
    }

    /// The haptic zone: its size (stiffness scales with it) and where it sits.
    fn zone_ui(&mut self, ui: &mut egui::Ui) {
        let Some(live) = &self.touch.live else {
            return;
        };
        let mut center = live.zone().center_world;
        let mut size = live.zone_size();
        let range = ::app::touch::live::ZONE_SIZE_RANGE;
        let tip = "how much of the scene the device's workspace covers: a larger zone reaches \
                   further and feels softer per scene unit";
        let changed = ui
            .add(
                egui::Slider::new(&mut size, range.0..=range.1)
                    .logarithmic(true)
                    .text("zone size"),
            )
            .on_hover_text(tip)
            .changed();
        ui.weak(live.zone_depth_text()).on_hover_text(
            "objects without a depth of their own feel a surface zone as deep as the device \
             reaches its largest force at its largest stiffness; give one with FDepth or \
             `depth:`",
        );
        let selected_centre = self
            .selected
            .and_then(|id| self.objects.drawn_box(id))
            .map(|b| {
                let mid = (glam::Vec3::from_array(b.lo) + glam::Vec3::from_array(b.hi)) * 0.5;
                render::snapshot::render_from_scene()
                    .inverse()
                    .transform_point3(mid)
                    .as_dvec3()
            });
        let centre_clicked = ui
            .add_enabled(
                selected_centre.is_some(),
                egui::Button::new("Centre the zone on the selection"),
            )
            .clicked();
        if centre_clicked && let Some(c) = selected_centre {
            center = c;
        }
        if (changed || centre_clicked)
            && let Some(live) = &mut self.touch.live
        {
            live.set_zone(center, size);
        }
    }

    /// The force-feedback device the force goes to: listed on demand, chosen, and its state.
    fn force_output_ui(&mut self, ui: &mut egui::Ui) {
        let Some(live) = &self.touch.live else {
            return;
        };
        ui.label(live.force_output_ref().status());
        let chosen = live
            .force_output_ref()
            .device()
            .map(|d| (d.vendor_id, d.product_id));
        let mut choice = chosen;
        let tip = "send the force to a HID force-feedback device (a joystick or a HID PID \
                   device renders its x component); unplugging it only stops the force";
        egui::ComboBox::from_label("force-feedback device")
            .selected_text(match chosen {
                Some((v, p)) => format!("{v:04x}:{p:04x}"),
                None => "none".into(),
            })
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut choice, None, "none");
                if let Some(Ok(list)) = &self.touch.force_devices {
                    for d in list {
                        let label = ::app::touch::force_output::label(d);
                        ui.selectable_value(&mut choice, Some((d.vendor_id, d.product_id)), label);
                    }
                }
            })
            .response
            .on_hover_text(tip);
        if ui.button("Find devices").clicked() && self.touch.force_listing.is_none() {
            self.touch.force_listing = Some(::app::touch::force_output::list_in_background());
        }
        if let Some(Err(why)) = &self.touch.force_devices {
            ui.label(why.clone());
        }
        if choice != chosen
            && let Err(e) = self.set_force_output(choice)
        {
            self.status = e;
        }
    }

    /// Holding the tool with another peer: whom, where that stands, and what the coupling does.
    fn shared_tool_ui(&mut self, ui: &mut egui::Ui) {
        let online: Vec<(PeerId, String)> = {
            let view = lock(self.engine.view());
            view.peers()
                .iter()
                .filter(|r| r.online)
                .map(|r| (r.peer, view.peer_label(r.peer)))
                .collect()
        };
        let shown = |p: Option<PeerId>| {
            p.map_or_else(
                || "nobody".to_string(),
                |p| {
                    online
                        .iter()
                        .find(|(q, _)| *q == p)
                        .map_or_else(|| p.short(), |(_, name)| name.clone())
                },
            )
        };
        let tip = "hold the tool together with another peer: once they hold it with you too, \
                   your devices are coupled and each feels the other (wave variables keep the \
                   coupling stable whatever the network delay)";
        let mut choice = self.touch.hold_with;
        egui::ComboBox::from_label("hold the tool with")
            .selected_text(shown(choice))
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut choice, None, "nobody");
                for (peer, name) in &online {
                    ui.selectable_value(&mut choice, Some(*peer), name);
                }
            })
            .response
            .on_hover_text(tip);
        self.touch.hold_with = choice;
        let Some(tool) = &self.touch.shared_tool else {
            return;
        };
        match self.touch.shared_state {
            SharedState::Alone => {}
            SharedState::Waiting(p) => {
                ui.label(format!(
                    "waiting for {} to hold it with you",
                    shown(Some(p))
                ));
            }
            SharedState::Coupled(p) => {
                let st = tool.stats();
                ui.label(format!(
                    "coupled with {}: {:.2} N from the link · wave energy in {:.1} mJ, out {:.1} mJ",
                    shown(Some(p)),
                    st.force_newtons.length(),
                    st.energy_in_joules * 1e3,
                    st.energy_out_joules * 1e3
                ));
            }
        }
    }

    /// The last seconds of force (orange, newtons) and of the passivity observer's energy
    /// (blue, joules, around its zero line), each scaled to its own peak.
    fn force_plot_ui(&self, ui: &mut egui::Ui, energy_joules: f64) {
        let history = &self.touch.force_history;
        let peak = history.peak_newtons();
        ui.label(format!(
            "last {FORCE_HISTORY_SECS:.0} s: peak {peak:.2} N · energy {:.2} mJ",
            energy_joules * 1e3
        ));
        let (response, painter) =
            ui.allocate_painter(egui::vec2(ui.available_width(), 60.0), egui::Sense::hover());
        let rect = response.rect;
        painter.rect_filled(rect, 2.0, egui::Color32::from_gray(24));
        let Some(last) = history.samples().last().map(|s| s.t_secs) else {
            return;
        };
        let x =
            |t: f64| rect.left() + rect.width() * (1.0 - ((last - t) / FORCE_HISTORY_SECS) as f32);
        let force_scale = if peak > 0.0 { peak } else { 1.0 };
        let energy_peak = history
            .samples()
            .map(|s| s.energy_joules.abs())
            .fold(0.0, f64::max);
        let energy_scale = if energy_peak > 0.0 { energy_peak } else { 1.0 };
        let mid = rect.center().y;
        painter.line_segment(
            [egui::pos2(rect.left(), mid), egui::pos2(rect.right(), mid)],
            egui::Stroke::new(1.0, egui::Color32::from_gray(60)),
        );
        let force: Vec<egui::Pos2> = history
            .samples()
            .map(|s| {
                let y = rect.bottom() - rect.height() * (s.force_newtons / force_scale) as f32;
                egui::pos2(x(s.t_secs), y)
            })
            .collect();
        let energy: Vec<egui::Pos2> = history
            .samples()
            .map(|s| {
                let y = mid - 0.5 * rect.height() * (s.energy_joules / energy_scale) as f32;
                egui::pos2(x(s.t_secs), y)
            })
            .collect();
        let orange = egui::Color32::from_rgb(240, 160, 60);
        let blue = egui::Color32::from_rgb(90, 160, 240);
        painter.add(egui::Shape::line(energy, egui::Stroke::new(1.0, blue)));
        painter.add(egui::Shape::line(force, egui::Stroke::new(1.5, orange)));
    }
}
