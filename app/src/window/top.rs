//! The bars around the viewport: the menu bar (what every button and shortcut does, in one
//! place to find it), the top bar (who and where, time, Share and Join, the file field, the
//! catch-up bar, errors and notices) and the status line.

use eframe::egui;

use super::app::SculptApp;
use super::transfer::FileAction;
use super::{ERROR_COLOUR, NOTICE_COLOUR};
use ::app::engine::lock;

/// Ops still to receive from which the catch-up bar shows.
const MIN_CATCH_UP_SHOWN: u64 = 50;

/// The brushes the Tool menu offers: its label, and the `tool:` line it runs.
const TOOL_MENU: [(&str, &str); 5] = [
    ("Add", "add"),
    ("Carve", "carve"),
    ("Paint density", "paint density 0.9"),
    ("Paint tension", "paint tension 0.9"),
    ("Paint colour", "paint colour 1 0.3 0.3"),
];

/// The Object menu: its label, and the command it runs on the selection.
const OBJECT_MENU: [(&str, &str); 3] = [
    ("Take it over (weak lease)", "lease"),
    ("Hold it (strong lease)", "hold"),
    ("Release it", "release"),
];

impl SculptApp {
    /// The top panel: the menu bar, then the top bar and what shows under it.
    pub(super) fn top_ui(&mut self, ui: &mut egui::Ui) {
        self.menu_ui(ui);
        ui.horizontal(|ui| self.top_bar_ui(ui));
        self.join_ui(ui);
        self.file_ui(ui);
        self.catch_up_ui(ui);
        self.invite_ui(ui);
        self.problems_ui(ui);
    }

    /// The menu bar.
    fn menu_ui(&mut self, ui: &mut egui::Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| self.file_menu_ui(ui));
            ui.menu_button("Edit", |ui| self.edit_menu_ui(ui));
            ui.menu_button("View", |ui| self.view_menu_ui(ui));
            ui.menu_button("Tool", |ui| self.tool_menu_ui(ui));
            ui.menu_button("Object", |ui| {
                for (word, line) in OBJECT_MENU {
                    if ui.button(word).clicked() {
                        self.submit(line);
                    }
                }
            });
            ui.menu_button("Scenes", |ui| {
                for demo in ::app::demos::DEMOS {
                    if ui.button(demo.title).on_hover_text(demo.about).clicked()
                        && let Err(e) = self.open_demo(demo)
                    {
                        self.status = e;
                    }
                }
            });
            ui.menu_button("Session", |ui| {
                if ui.button("Share…").clicked() {
                    self.share(true);
                }
                if ui.button("Join…").clicked() {
                    self.session.join_input = Some((String::new(), None));
                }
            });
        });
    }

    fn file_menu_ui(&mut self, ui: &mut egui::Ui) {
        if ui
            .button("Import a scene or mesh… (.wrl .stl .obj .glb, or drop it here)")
            .clicked()
        {
            self.transfer.input = Some((FileAction::Import, String::new(), None));
        }
        if ui
            .button("Export the selection… (.stl .obj .glb .wrl)")
            .clicked()
        {
            self.transfer.input = Some((FileAction::Export, String::new(), None));
        }
    }

    fn edit_menu_ui(&mut self, ui: &mut egui::Ui) {
        if ui
            .button("Undo your last edit of the selection   Ctrl+Z")
            .clicked()
        {
            self.submit("undo");
        }
        if ui.button("Redo   Ctrl+Y").clicked() {
            self.submit("redo");
        }
    }

    fn view_menu_ui(&mut self, ui: &mut egui::Ui) {
        if ui.button("Frame everything   F or double-click").clicked() {
            self.view.moved = false;
        }
        let playing = self.scene_clock.playing();
        let word = if playing {
            "Pause time   Space"
        } else {
            "Run time   Space"
        };
        if ui.button(word).clicked() {
            self.set_playing(!playing);
        }
        if self.presence.following.is_some() && ui.button("Stop following").clicked() {
            self.presence.following = None;
        }
    }

    fn tool_menu_ui(&mut self, ui: &mut egui::Ui) {
        if ui.button("Navigate   Esc").clicked() {
            let _ = self.shortcut_named("navigate");
        }
        if ui.button("Sculpt   B").clicked() {
            let _ = self.shortcut_named("sculpt");
        }
        ui.separator();
        for (word, line) in TOOL_MENU {
            if ui.button(word).clicked() {
                self.submit(&format!("tool: {line}"));
            }
        }
    }

    /// Who and where (peer, presence, store, ops), the scene's time with Play or Pause, and
    /// Share and Join.
    fn top_bar_ui(&mut self, ui: &mut egui::Ui) {
        let presence = self.presence_text();
        ui.strong("sculpt");
        let view = lock(self.engine.view());
        ui.label(format!(
            "peer {} · {presence} · store {} · {} ops",
            view.peer_id().short(),
            self.engine.store_dir().display(),
            view.n_ops()
        ));
        drop(view);
        let now = ::app::clock::now().instant;
        let playing = self.scene_clock.playing();
        ui.label(format!("time {:.1} s", self.scene_clock.secs(now)));
        let (word, tip) = if playing {
            ("Pause", "pause the scene's time (motions, fields)   Space")
        } else {
            ("Play", "run the scene's time (motions, fields)   Space")
        };
        if ui.button(word).on_hover_text(tip).clicked() {
            self.set_playing(!playing);
        }
        if ui
            .button("Share…")
            .on_hover_text("show this session's invite, to give to whoever should join")
            .clicked()
        {
            self.share(!self.session.show_invite);
        }
        if ui
            .button("Join…")
            .on_hover_text("join another session with its invite")
            .clicked()
        {
            self.session.join_input = match self.session.join_input {
                Some(_) => None,
                None => Some((String::new(), None)),
            };
        }
    }

    /// A progress bar while this peer receives a large catch-up.
    fn catch_up_ui(&mut self, ui: &mut egui::Ui) {
        let view = lock(self.engine.view());
        let (_, to_receive) = view.progress();
        if to_receive < MIN_CATCH_UP_SHOWN {
            return;
        }
        let have = view.n_ops() as u64;
        let total = have + to_receive;
        drop(view);
        ui.add(
            egui::ProgressBar::new(have as f32 / total.max(1) as f32)
                .text(format!("catching up: {have} of {total} ops")),
        );
    }

    /// The store's error, this identity's fork, the session's notices and why the viewport
    /// cannot draw.
    fn problems_ui(&self, ui: &mut egui::Ui) {
        let view = lock(self.engine.view());
        if let Some(error) = view.store_error() {
            ui.colored_label(ERROR_COLOUR, format!("Store error: {error}"));
        }
        if let Some(seq) = view.forked().get(&view.peer_id()) {
            ui.colored_label(ERROR_COLOUR, own_fork_text(*seq));
        }
        for notice in view.notices() {
            ui.colored_label(NOTICE_COLOUR, notice);
        }
        drop(view);
        let viewport_error = self.viewport.lock().ok().and_then(|r| r.error.clone());
        if let Some(error) = viewport_error {
            ui.colored_label(ERROR_COLOUR, format!("Cannot draw the scene: {error}"));
        }
    }

    /// The status line: the pick, meshing or triangles, the last edit's time to show, and
    /// the status.
    pub(super) fn status_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            ui.label(&self.pick_status);
            ui.separator();
            let n_meshing = self.objects.n_meshing();
            if n_meshing > 0 {
                ui.spinner();
                ui.label(format!("meshing {n_meshing} object(s)"));
            } else {
                let n_triangles = self.objects.n_triangles();
                ui.label(format!("{n_triangles} triangles"));
            }
            ui.separator();
            if let Some(ms) = self.objects.stats.edit_to_pixels_ms.last() {
                ui.label(format!("last edit on screen after {ms:.0} ms"));
                ui.separator();
            }
            let join = (lock(self.engine.view()).snapshot()).map(|s| (s.busy, s.text()));
            if let Some((busy, text)) = join.filter(|(_, text)| !text.is_empty()) {
                if busy {
                    ui.spinner();
                }
                ui.label(text);
                ui.separator();
            }
            ui.label(&self.status);
        });
    }
}

/// What it means that this peer's own identity forked at `seq`, and what to do.
fn own_fork_text(seq: u64) -> String {
    format!(
        "This identity signed two different edits as #{seq}: another copy of this store is \
         running, or it was restored from an older copy. Its edits from #{seq} on count for \
         nothing, on every peer. Close the other copy; to go on editing, join again with a \
         new store."
    )
}
