//! The panels around the viewport: the top bar (who and where), the side panel (objects, the
//! chat with the command line and its inline errors, the history) and the status line.

use eframe::egui;

use super::app::SculptApp;
use crate::clock::Now;

/// Colour of errors.
const ERROR_COLOUR: egui::Color32 = egui::Color32::from_rgb(255, 110, 100);
/// Colour of notices.
const NOTICE_COLOUR: egui::Color32 = egui::Color32::from_rgb(240, 200, 90);
/// Height of the chat list, in points.
const CHAT_HEIGHT_POINTS: f32 = 180.0;

/// The commands, shown under the input.
const COMMAND_HELP: &str = "\
plain text is chat; commands change the selected object:
  shape: <formula>          its solid (f >= 0 inside)
  colour: <r>, <g>, <b>     formulas or numbers 0..1 (or r=..; g=..; b=..;)
  new: <formula>            a new object
  undo / redo               your last edit of it";

impl SculptApp {
    pub(super) fn top_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            ui.strong("sculpt");
            ui.label(format!(
                "solo peer {} · store {} · {} ops",
                self.session.peer_id().short(),
                self.session.dir().display(),
                self.session.n_ops()
            ));
        });
        if let Some(error) = self.session.store_error() {
            ui.colored_label(ERROR_COLOUR, format!("Store error: {error}"));
            ui.colored_label(
                ERROR_COLOUR,
                "Nothing stored was changed or deleted; edits in this window are not saved.",
            );
        }
        for notice in self.session.notices() {
            ui.colored_label(NOTICE_COLOUR, notice);
        }
        let viewport_error = self.viewport.lock().ok().and_then(|r| r.error.clone());
        if let Some(error) = viewport_error {
            ui.colored_label(ERROR_COLOUR, format!("Cannot draw the scene: {error}"));
        }
    }

    pub(super) fn status_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            ui.label(&self.pick_status);
            ui.separator();
            let n_meshing = self.n_meshing();
            if n_meshing > 0 {
                ui.spinner();
                ui.label(format!("meshing {n_meshing} object(s)"));
            } else {
                let n_triangles: usize = self.objects.values().map(|t| t.n_triangles).sum();
                ui.label(format!("{n_triangles} triangles"));
            }
            ui.separator();
            if let Some(ms) = self.stats.edit_to_mesh_ms.last() {
                ui.label(format!("last edit drawn after {ms:.0} ms"));
                ui.separator();
            }
            ui.label(&self.status);
        });
    }

    pub(super) fn side_ui(&mut self, ui: &mut egui::Ui, now: Now) {
        ui.heading("Objects");
        let ids: Vec<u64> = self.session.scene().objects().map(|(id, _)| id.0).collect();
        for id in ids {
            let label = self.session.object_label(id);
            let detail =
                self.objects
                    .get(&fdsl::scene::ObjectId(id))
                    .map_or_else(String::new, |t| match &t.skipped {
                        Some(why) => format!(" (not drawn: {why})"),
                        None => String::new(),
                    });
            let selected = self.selected == Some(id);
            if ui
                .selectable_label(selected, format!("{label}{detail}"))
                .clicked()
            {
                self.selected = Some(id);
            }
        }
        ui.separator();
        ui.heading("Chat and commands");
        egui::ScrollArea::vertical()
            .id_salt("chat")
            .max_height(CHAT_HEIGHT_POINTS)
            .stick_to_bottom(true)
            .show(ui, |ui| {
                if self.chat.is_empty() {
                    ui.weak("no messages yet");
                }
                for row in &self.chat {
                    ui.label(format!("[{}] {}: {}", row.time, row.author, row.text));
                }
            });
        let target = self.selected.map_or_else(
            || "nothing selected".into(),
            |id| self.session.object_label(id),
        );
        ui.label(format!("selected: {target}"));
        let response = ui.add(
            egui::TextEdit::singleline(&mut self.input)
                .hint_text("chat, or shape: / colour: / new: / undo / redo")
                .desired_width(f32::INFINITY)
                .font(egui::TextStyle::Monospace),
        );
        if response.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter)) {
            let line = self.input.clone();
            self.submit(&line, now);
            response.request_focus();
        }
        if let Some(error) = &self.input_error {
            ui.label(egui::RichText::new(error).monospace().color(ERROR_COLOUR));
        }
        ui.collapsing("commands", |ui| {
            ui.label(egui::RichText::new(COMMAND_HELP).monospace().small());
        });
        ui.separator();
        ui.heading("History");
        egui::ScrollArea::vertical()
            .id_salt("history")
            .stick_to_bottom(true)
            .show(ui, |ui| {
                for row in &self.history {
                    let text = format!(
                        "[{}] {}: {} — {}",
                        row.time, row.author, row.what, row.status
                    );
                    if row.status.starts_with("rejected") {
                        ui.colored_label(ERROR_COLOUR, text);
                    } else if row.status == "undone" {
                        ui.weak(text);
                    } else {
                        ui.label(text);
                    }
                }
            });
    }
}
