//! The side panel: Peers, Tool and Touch (drawn by their own modules), then the objects with
//! their lease holders, the chat with the command line and its inline errors, and the
//! history with undo.

use eframe::egui;

use super::ERROR_COLOUR;
use super::app::SculptApp;
use ::app::engine::lock;

/// Height of the chat list, in points.
const CHAT_HEIGHT_POINTS: f32 = 180.0;

/// The commands, shown under the input.
const COMMAND_HELP: &str = "\
plain text is chat; commands change the selected object:
  shape: <formula>          its solid (f >= 0 inside)
  colour: <r>, <g>, <b>     formulas or numbers 0..1 (or r=..; g=..; b=..;)
  new: <formula>            a new object (its box is fitted to the solid)
  density: / tension: / friction: / depth: <formula or off>
  transparency: / shininess: / texture: <formula or off>
  force: x=..; y=..; z=..;  a force field of u, v, w, t
  name: <text>              rename it
  lease / hold / release    take it over, take it if free, give it back
  undo / redo               your last edit of it
  expel: / readmit: <name or id>   the founder removes a member, or takes it back";

/// The lease buttons beside the selected object: the command, and what it does.
const LEASE_BUTTONS: [(&str, &str); 3] = [
    ("lease", "take it over (others may take it back)"),
    ("hold", "take it only if nobody holds it"),
    ("release", "give it back"),
];

impl SculptApp {
    /// The side panel, top to bottom.
    pub(super) fn side_ui(&mut self, ui: &mut egui::Ui) {
        self.peers_ui(ui);
        ui.separator();
        self.tool_ui(ui);
        ui.separator();
        self.touch_ui(ui);
        ui.separator();
        self.objects_ui(ui);
        ui.separator();
        self.chat_ui(ui);
        ui.separator();
        self.history_ui(ui);
    }

    /// The objects: each with why it is not drawn and who holds it; the selected one with
    /// its lease buttons; then this user's last rejected edit.
    fn objects_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("Objects");
        let now = ::app::clock::now().wall;
        let rows: Vec<(u64, String, Option<String>)> = {
            let view = lock(self.engine.view());
            view.scene()
                .objects()
                .map(|(id, _)| {
                    let holder = view
                        .lease(id.0)
                        .filter(|l| l.holds_at(now))
                        .map(|l| self.rows.display_name(&l.holder.short()));
                    (id.0, view.object_label(id.0), holder)
                })
                .collect()
        };
        for (id, label, holder) in rows {
            let detail = match self
                .objects
                .tracked
                .get(&model::scene::ObjectId(id))
                .and_then(|t| t.skipped.as_ref())
            {
                Some(why) => format!(" (not drawn: {why})"),
                None => String::new(),
            };
            let held = holder.map_or_else(String::new, |h| format!(" · held by {h}"));
            let selected = self.selected == Some(id);
            ui.horizontal(|ui| {
                if ui
                    .selectable_label(selected, format!("{label}{detail}{held}"))
                    .clicked()
                {
                    self.selected = Some(id);
                }
                if selected {
                    for (word, tip) in LEASE_BUTTONS {
                        if ui.small_button(word).on_hover_text(tip).clicked() {
                            self.submit(word);
                        }
                    }
                }
            });
        }
        let rejected = lock(self.engine.view()).my_rejections().first().cloned();
        if let Some(rejected) = rejected {
            ui.colored_label(
                ERROR_COLOUR,
                format!("Your last rejected edit: {}", rejected.why),
            )
            .on_hover_text(rejected.remedy);
        }
    }

    /// The chat, the command line with its error, and the commands' help.
    fn chat_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("Chat and commands");
        egui::ScrollArea::vertical()
            .id_salt("chat")
            .max_height(CHAT_HEIGHT_POINTS)
            .stick_to_bottom(true)
            .show(ui, |ui| {
                if self.rows.chat.is_empty() {
                    ui.weak("no messages yet");
                }
                for row in &self.rows.chat {
                    let who = self.rows.display_name(&row.author);
                    ui.label(format!("[{}] {who}: {}", row.time, row.text));
                }
            });
        let target = self.selected.map_or_else(
            || "nothing selected".into(),
            |id| lock(self.engine.view()).object_label(id),
        );
        ui.label(format!("selected: {target}"));
        let response = ui.add(
            egui::TextEdit::singleline(&mut self.command.input)
                .hint_text("chat, or shape: / colour: / new: / undo / redo")
                .desired_width(f32::INFINITY)
                .font(egui::TextStyle::Monospace),
        );
        if response.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter)) {
            let line = self.command.input.clone();
            self.submit(&line);
            response.request_focus();
        }
        if let Some(error) = &self.command.error {
            ui.label(egui::RichText::new(error).monospace().color(ERROR_COLOUR));
        }
        ui.collapsing("commands", |ui| {
            ui.label(egui::RichText::new(COMMAND_HELP).monospace().small());
        });
    }

    /// Who did what and whether it counted; this user's own edits can be undone here. Only
    /// the rows in view are laid out (up to `MAX_HISTORY_ROWS` are listed, every frame).
    fn history_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("History");
        let row_height = ui.spacing().interact_size.y;
        let n_rows = self.rows.history.len();
        egui::ScrollArea::vertical()
            .id_salt("history")
            .stick_to_bottom(true)
            .show_rows(ui, row_height, n_rows, |ui, in_view| {
                let mut undo = None;
                for row in &self.rows.history[in_view] {
                    let text = format!(
                        "[{}] {}: {} — {}",
                        row.time,
                        self.rows.display_name(&row.author),
                        row.what,
                        row.status
                    );
                    ui.horizontal(|ui| {
                        ui.set_min_height(row_height);
                        if row.status.starts_with("rejected") {
                            ui.colored_label(ERROR_COLOUR, text);
                        } else if row.status == "undone" {
                            ui.weak(text);
                        } else {
                            ui.label(text);
                        }
                        if row.undoable
                            && ui
                                .small_button("undo")
                                .on_hover_text("undo this edit of yours")
                                .clicked()
                        {
                            undo = Some(row.op);
                        }
                    });
                }
                if let Some(op) = undo {
                    self.undo_op(op);
                }
            });
    }
}
