//! The panels around the viewport: the top bar (who and where), the side panel (objects, the
//! chat with the command line and its inline errors, the history) and the status line.

use eframe::egui;

use super::app::{FileAction, SculptApp};
use ::app::clock::{self, Now};
use ::app::engine::lock;

/// Colour of errors.
const ERROR_COLOUR: egui::Color32 = egui::Color32::from_rgb(255, 110, 100);
/// What a forked author's mark means.
const FORKED_HOVER: &str = "this identity signed two different edits with one number: \
                            it runs as two copies, or from a restored backup, or it is \
                            hostile; its edits from that number on count for nothing, \
                            everywhere";
/// Colour of notices.
const NOTICE_COLOUR: egui::Color32 = egui::Color32::from_rgb(240, 200, 90);
/// Ops still to receive from which the catch-up bar shows.
const CATCH_UP_SHOWN_MIN: u64 = 50;
/// News lines the peers panel shows (the latest).
const NEWS_SHOWN_MAX: usize = 20;
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

impl SculptApp {
    /// Solo, N peers, or offline with edits waiting: what the title bar says.
    pub(super) fn presence_text(&self) -> String {
        let view = lock(self.engine.view());
        let (to_send, to_receive) = view.progress();
        match self.n_online {
            0 if self.shared => format!("offline · {} ops kept, waiting for peers", view.n_ops()),
            0 => "solo".to_string(),
            n if to_send + to_receive > 0 => {
                format!("{n} peer(s) · syncing: {to_send} to send, {to_receive} to receive")
            }
            n => format!("{n} peer(s) · in sync"),
        }
    }

    /// The menu bar: what every button and shortcut does, in one place to find it.
    fn menu_ui(&mut self, ui: &mut egui::Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui
                    .button("Import a scene or mesh… (.wrl .stl .obj .glb, or drop it here)")
                    .clicked()
                {
                    self.file_input = Some((FileAction::Import, String::new(), None));
                }
                if ui
                    .button("Export the selection… (.stl .obj .glb .wrl)")
                    .clicked()
                {
                    self.file_input = Some((FileAction::Export, String::new(), None));
                }
            });
            ui.menu_button("Edit", |ui| {
                if ui
                    .button("Undo your last edit of the selection   Ctrl+Z")
                    .clicked()
                {
                    self.submit("undo");
                }
                if ui.button("Redo   Ctrl+Y").clicked() {
                    self.submit("redo");
                }
            });
            ui.menu_button("View", |ui| {
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
                if self.following.is_some() && ui.button("Stop following").clicked() {
                    self.following = None;
                }
            });
            ui.menu_button("Tool", |ui| {
                if ui.button("Navigate   Esc").clicked() {
                    let _ = self.shortcut_named("navigate");
                }
                if ui.button("Sculpt   B").clicked() {
                    let _ = self.shortcut_named("sculpt");
                }
                ui.separator();
                for (word, line) in [
                    ("Add", "add"),
                    ("Carve", "carve"),
                    ("Paint density", "paint density 0.9"),
                    ("Paint tension", "paint tension 0.9"),
                    ("Paint colour", "paint colour 1 0.3 0.3"),
                ] {
                    if ui.button(word).clicked() {
                        self.submit(&format!("tool: {line}"));
                    }
                }
            });
            ui.menu_button("Object", |ui| {
                for (word, line) in [
                    ("Take it over (weak lease)", "lease"),
                    ("Hold it (strong lease)", "hold"),
                    ("Release it", "release"),
                ] {
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
                    self.show_invite = true;
                    self.shared = true;
                    if let Err(e) = self.engine.share() {
                        self.status = e.to_string();
                    }
                }
                if ui.button("Join…").clicked() {
                    self.join_input = Some((String::new(), None));
                }
            });
        });
    }

    pub(super) fn top_ui(&mut self, ui: &mut egui::Ui) {
        self.menu_ui(ui);
        let presence = self.presence_text();
        ui.horizontal(|ui| {
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
                self.show_invite = !self.show_invite;
                self.shared = true;
                if let Err(e) = self.engine.share() {
                    self.status = e.to_string();
                }
            }
            if ui
                .button("Join…")
                .on_hover_text("join another session with its invite")
                .clicked()
            {
                self.join_input = match self.join_input {
                    Some(_) => None,
                    None => Some((String::new(), None)),
                };
            }
        });
        self.join_ui(ui);
        self.file_ui(ui);
        self.catch_up_ui(ui);
        if self.show_invite {
            ui.horizontal(|ui| {
                ui.label("Invite (a secret: give it only to who should join):");
                let code = self.engine.invite().to_string();
                ui.monospace(&code);
                if ui.button("Copy").clicked() {
                    ui.ctx().copy_text(code);
                }
            });
            ui.weak(
                "They run: sculpt --invite CODE (same LAN), or add --dial ADDR / --discovery ADDR",
            );
        }
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

    /// The invite field of "Join…", with the reason a code was refused (its column).
    fn join_ui(&mut self, ui: &mut egui::Ui) {
        let Some((mut text, error)) = self.join_input.take() else {
            return;
        };
        let mut error = error;
        ui.horizontal(|ui| {
            ui.label("Invite:");
            let response = ui.add(
                egui::TextEdit::singleline(&mut text)
                    .hint_text("xxxxx-xxxxx-...")
                    .font(egui::TextStyle::Monospace)
                    .desired_width(360.0),
            );
            let entered = response.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
            if ui.button("Join").clicked() || entered {
                match self.join(&text) {
                    Ok(()) => {
                        self.join_input = None;
                        return;
                    }
                    Err(e) => error = Some(e),
                }
            }
            self.join_input = Some((text.clone(), error.clone()));
        });
        if let Some(e) = self.join_input.as_ref().and_then(|(_, e)| e.as_ref()) {
            ui.colored_label(ERROR_COLOUR, e);
        }
    }

    /// The File menu's path field.
    fn file_ui(&mut self, ui: &mut egui::Ui) {
        let Some((action, mut text, mut error)) = self.file_input.take() else {
            return;
        };
        let mut done = false;
        ui.horizontal(|ui| {
            ui.label(match action {
                FileAction::Import => "Import file:",
                FileAction::Export => "Export to:",
                FileAction::RecordTouch => "Record the touch path to (.csv):",
            });
            let response = ui.add(
                egui::TextEdit::singleline(&mut text)
                    .hint_text("/path/to/file")
                    .desired_width(360.0),
            );
            let entered = response.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
            if ui.button("OK").clicked() || entered {
                let path = std::path::PathBuf::from(text.trim());
                let result = match action {
                    FileAction::Import => self.import_file(&path),
                    FileAction::Export => self.export_file(path),
                    FileAction::RecordTouch => self.start_touch_recording(&path),
                };
                match result {
                    Ok(()) => done = true,
                    Err(e) => error = Some(e),
                }
            }
            if ui.button("Cancel").clicked() {
                done = true;
            }
        });
        if let Some(e) = &error {
            ui.colored_label(ERROR_COLOUR, e);
        }
        if !done {
            self.file_input = Some((action, text, error));
        }
    }

    /// A progress bar while this peer receives a large catch-up.
    fn catch_up_ui(&mut self, ui: &mut egui::Ui) {
        let view = lock(self.engine.view());
        let (_, to_receive) = view.progress();
        if to_receive < CATCH_UP_SHOWN_MIN {
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

    /// The tool panel: navigate or sculpt, what the brush does, its shape, size, blend and
    /// mirror plane.
    fn tool_ui(&mut self, ui: &mut egui::Ui) {
        use ::app::brush::BrushOp;
        use model::object::{Axis, PaintValue, Paintable, ToolKind};
        ui.heading("Tool");
        ui.horizontal(|ui| {
            ui.selectable_value(&mut self.sculpting, false, "Navigate")
                .on_hover_text("drag orbits (Esc)");
            ui.selectable_value(&mut self.sculpting, true, "Sculpt")
                .on_hover_text("drag on a surface sculpts, right-drag orbits (B)");
        });
        if !self.sculpting {
            return;
        }
        let b = &mut self.brush;
        ui.horizontal(|ui| {
            ui.selectable_value(&mut b.op, BrushOp::Add, "add");
            ui.selectable_value(&mut b.op, BrushOp::Carve, "carve");
            let painting = matches!(b.op, BrushOp::Paint(..));
            if ui.selectable_label(painting, "paint").clicked() && !painting {
                b.op = BrushOp::Paint(Paintable::Density, PaintValue::Scalar(0.8));
            }
        });
        if let BrushOp::Paint(property, value) = &mut b.op {
            ui.horizontal(|ui| {
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
            });
        }
        ui.horizontal(|ui| {
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
        });
        let [lo, hi] = ::app::brush::RADIUS_RANGE;
        ui.add(
            egui::Slider::new(&mut b.radius, lo..=1.0_f64.min(hi))
                .logarithmic(true)
                .text("radius"),
        );
        let blend_max = b.radius * 2.0;
        ui.add(egui::Slider::new(&mut b.blend, 0.0..=blend_max).text("blend"));
    }

    /// The name a user chose for the author with this short id, with the id: `Bo
    /// (7b3c0dc8)`; just the id when no name is known.
    fn display_name(&self, short: &str) -> String {
        match self.names.get(short) {
            Some(name) if name != short => format!("{name} ({short})"),
            _ => short.to_string(),
        }
    }

    /// The peers panel: each connected peer with how it was reached, its round trip and
    /// what is still to sync, then the latest network news.
    fn peers_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading(format!("Peers ({} online)", self.n_online));
        let mut me = self.engine.presence();
        let before = me.clone();
        ui.horizontal(|ui| {
            ui.label("You:");
            ui.color_edit_button_srgb(&mut me.colour)
                .on_hover_text("the colour others see your pointer and selection in");
            ui.add(
                egui::TextEdit::singleline(&mut me.name)
                    .desired_width(120.0)
                    .char_limit(replication::sync::ephemeral::presence::MAX_NAME_BYTES),
            )
            .on_hover_text("the name others see");
        });
        if me != before {
            let _ = self.engine.set_presence(me);
        }
        if self.peers.is_empty() {
            ui.weak("nobody met yet");
        }
        let mut follow = None;
        let mut membership = None;
        let (expelled, forked, founder) = {
            let view = lock(self.engine.view());
            let forked = view.forked().clone();
            (
                view.expelled().clone(),
                forked,
                view.founder_nonce().is_some(),
            )
        };
        for p in &self.peers {
            let [r, g, b] = p.colour;
            let colour = egui::Color32::from_rgb(r, g, b);
            ui.horizontal(|ui| {
                let (dot, _) = ui.allocate_exact_size(egui::vec2(10.0, 10.0), egui::Sense::hover());
                ui.painter().circle_filled(dot.center(), 5.0, colour);
                ui.strong(&p.name);
                ui.weak(p.peer.short());
                let out = expelled.contains(&p.peer);
                if out {
                    ui.colored_label(egui::Color32::LIGHT_RED, "expelled");
                }
                if let Some(seq) = forked.get(&p.peer) {
                    ui.colored_label(egui::Color32::LIGHT_RED, format!("forked at #{seq}"))
                        .on_hover_text(FORKED_HOVER);
                }
                if founder {
                    let (word, line) = if out {
                        ("readmit", "readmit")
                    } else {
                        ("expel", "expel")
                    };
                    let hover = "as the session's founder: its ops from now on count for nothing, \
                                 and every peer closes its connections to it (readmit undoes it)";
                    if ui.small_button(word).on_hover_text(hover).clicked() {
                        membership = Some(format!("{line}: {}", p.peer.to_hex()));
                    }
                }
                if !p.online {
                    ui.weak("offline");
                    return;
                }
                let rtt = p
                    .rtt_micros
                    .map_or_else(|| "?".to_string(), |r| format!("{:.1} ms", r as f64 / 1e3));
                ui.label(format!(
                    "{} · {} · rtt {rtt} · {} to send, {} to receive",
                    p.how, p.addr, p.to_send, p.to_receive
                ));
                let following = self.following == Some(p.peer);
                if ui.selectable_label(following, "follow").clicked() {
                    follow = Some((!following).then_some(p.peer));
                }
            });
        }
        if let Some(f) = follow {
            self.following = f;
        }
        if let Some(line) = membership {
            self.submit(&line);
        }
        let lan = lock(self.engine.view()).lan_sessions().to_vec();
        egui::CollapsingHeader::new(format!("on this network ({})", lan.len()))
            .id_salt("lan")
            .show(ui, |ui| {
                if lan.is_empty() {
                    ui.weak("no sessions announced here (found by DNS-SD, no server needed)");
                }
                for s in &lan {
                    let whose = if s.ours { " · this session" } else { "" };
                    ui.label(format!(
                        "{} · {} · {} peer(s){whose}",
                        s.name, s.host, s.n_peers
                    ))
                    .on_hover_text("to join, ask for its invite and use Join…");
                }
            });
        egui::CollapsingHeader::new("network news")
            .id_salt("news")
            .show(ui, |ui| {
                for line in self.news.iter().rev().take(NEWS_SHOWN_MAX) {
                    ui.small(line);
                }
            });
    }

    pub(super) fn side_ui(&mut self, ui: &mut egui::Ui, _now: Now) {
        self.peers_ui(ui);
        ui.separator();
        self.tool_ui(ui);
        ui.separator();
        self.touch_ui(ui);
        ui.separator();
        ui.heading("Objects");
        let now = clock::now().wall;
        let rows: Vec<(u64, String, Option<String>)> = {
            let view = lock(self.engine.view());
            view.scene()
                .objects()
                .map(|(id, _)| {
                    let holder = view
                        .lease(id.0)
                        .filter(|l| l.holds_at(now))
                        .map(|l| self.display_name(&l.holder.short()));
                    (id.0, view.object_label(id.0), holder)
                })
                .collect()
        };
        for (id, label, holder) in rows {
            let detail = self.objects.get(&model::scene::ObjectId(id)).map_or_else(
                String::new,
                |t| match &t.skipped {
                    Some(why) => format!(" (not drawn: {why})"),
                    None => String::new(),
                },
            );
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
                    for (word, tip) in [
                        ("lease", "take it over (others may take it back)"),
                        ("hold", "take it only if nobody holds it"),
                        ("release", "give it back"),
                    ] {
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
                    let who = self.display_name(&row.author);
                    ui.label(format!("[{}] {who}: {}", row.time, row.text));
                }
            });
        let target = self.selected.map_or_else(
            || "nothing selected".into(),
            |id| lock(self.engine.view()).object_label(id),
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
            self.submit(&line);
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
                let mut undo = None;
                for row in &self.history {
                    let text = format!(
                        "[{}] {}: {} — {}",
                        row.time,
                        self.display_name(&row.author),
                        row.what,
                        row.status
                    );
                    ui.horizontal(|ui| {
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

impl SculptApp {
    /// The Touch section: start or stop touching with the mouse, and what the servo feels.
    fn touch_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("Touch");
        let on = self.touch.is_some();
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
        let mut with_3d_mouse = self.spacemouse.is_some();
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
        if let Some((driver, _)) = &self.spacemouse {
            ui.label(driver.status().text());
        }
        let Some(live) = &self.touch else {
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
        ui.label(format!("your tool: {}", self.tool_body.describe()))
            .on_hover_text(
                "others feel your tool when it has tension or density: set them with \
                 `probe: radius 0.1 tension 0.8 friction 0.3 density 1` (or `probe: off`)",
            );
        self.shared_tool_ui(ui);
        match &self.touch_recording {
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
                    self.file_input = Some((FileAction::RecordTouch, String::new(), None));
                }
            }
        }
    }

    /// The haptic zone: its size (stiffness scales with it) and where it sits.
    fn zone_ui(&mut self, ui: &mut egui::Ui) {
        let Some(live) = &self.touch else {
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
            .and_then(|id| self.objects.get(&model::scene::ObjectId(id)))
            .and_then(|t| t.drawn_box)
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
            && let Some(live) = &mut self.touch
        {
            live.set_zone(center, size);
        }
    }

    /// The force-feedback device the force goes to: listed on demand, chosen, and its state.
    fn force_output_ui(&mut self, ui: &mut egui::Ui) {
        let Some(live) = &self.touch else {
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
                if let Some(Ok(list)) = &self.force_devices {
                    for d in list {
                        let label = ::app::touch::force_output::label(d);
                        ui.selectable_value(&mut choice, Some((d.vendor_id, d.product_id)), label);
                    }
                }
            })
            .response
            .on_hover_text(tip);
        if ui.button("Find devices").clicked() && self.force_listing.is_none() {
            self.force_listing = Some(::app::touch::force_output::list_in_background());
        }
        if let Some(Err(why)) = &self.force_devices {
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
        let online: Vec<(replication::PeerId, String)> = {
            let view = lock(self.engine.view());
            view.peers()
                .iter()
                .filter(|r| r.online)
                .map(|r| (r.peer, view.peer_label(r.peer)))
                .collect()
        };
        let shown = |p: Option<replication::PeerId>| {
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
        let mut choice = self.hold_with;
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
        self.hold_with = choice;
        let Some(tool) = &self.shared_tool else {
            return;
        };
        use ::app::touch::shared::SharedState;
        match self.shared_state {
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
        let history = &self.force_history;
        let peak = history.peak_newtons();
        ui.label(format!(
            "last {:.0} s: peak {peak:.2} N · energy {:.2} mJ",
            ::app::touch::record::FORCE_HISTORY_SECS,
            energy_joules * 1e3
        ));
        let (response, painter) =
            ui.allocate_painter(egui::vec2(ui.available_width(), 60.0), egui::Sense::hover());
        let rect = response.rect;
        painter.rect_filled(rect, 2.0, egui::Color32::from_gray(24));
        let Some(last) = history.samples().last().map(|s| s.t_secs) else {
            return;
        };
        let window = ::app::touch::record::FORCE_HISTORY_SECS;
        let x = |t: f64| rect.left() + rect.width() * (1.0 - ((last - t) / window) as f32);
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

/// What it means that this peer's own identity forked at `seq`, and what to do.
fn own_fork_text(seq: u64) -> String {
    format!(
        "This identity signed two different edits as #{seq}: another copy of this store is \
         running, or it was restored from an older copy. Its edits from #{seq} on count for \
         nothing, on every peer. Close the other copy; to go on editing, join again with a \
         new store."
    )
}
