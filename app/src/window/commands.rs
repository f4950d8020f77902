//! The command line and the shortcuts: a typed (or scripted) line planned into an op and
//! handed to the engine, one op in flight at a time, its error shown inline; and the named
//! shortcuts the keyboard, the menus and scripts share.

use std::time::Instant;

use eframe::egui;

use super::app::SculptApp;
use ::app::clock;
use ::app::command::{self, Planned};
use ::app::engine::{Pending, Validated, lock};

/// The command/chat input, and the one op on its way to the store.
#[derive(Default)]
pub struct CommandLine {
    /// The text in the input.
    pub input: String,
    /// Why the last line was refused (shown under the input).
    pub error: Option<String>,
    /// An op on its way to the store (a command's, a stroke's, an import's or an undo's),
    /// with what it does and the start of the frame that took its input: the next waits
    /// until it is stored.
    pending: Option<(Pending, Planned, Instant)>,
}

impl CommandLine {
    /// Whether an op is on its way to the store.
    pub fn is_pending(&self) -> bool {
        self.pending.is_some()
    }

    /// A line was taken: the input is cleared and its error forgotten.
    fn taken(&mut self) {
        self.error = None;
        self.input.clear();
    }
}

impl SculptApp {
    /// Runs one line of the command/chat input: hands its op to the engine, or shows its
    /// error. One line at a time: the next waits until this one's op is stored.
    pub(super) fn submit(&mut self, line: &str) {
        let Some(command) = command::parse(line) else {
            return;
        };
        // The touch tool's body and the brush are this window's own: no op.
        if let command::Command::Probe(text) = command {
            match self.touch.body.parse(text) {
                Ok(body) => {
                    self.touch.body = body;
                    self.command.taken();
                    self.status = format!("touch tool: {}", body.describe());
                }
                Err(e) => self.command.error = Some(e),
            }
            return;
        }
        if let command::Command::Tool(text) = command {
            match self.sculpt.brush.parse(text) {
                Ok(brush) => {
                    self.sculpt.brush = brush;
                    self.sculpt.active = true;
                    self.command.taken();
                    self.status = format!("tool: {} (drag on a surface)", brush.describe());
                }
                Err(e) => self.command.error = Some(e),
            }
            return;
        }
        if self.command.is_pending() {
            self.command.error = Some("the last command is still being saved; try again".into());
            return;
        }
        let planned = command::plan(command, &lock(self.engine.view()), self.selected);
        let authored = planned.and_then(|planned| self.author(planned));
        if let Err(error) = authored {
            self.command.error = Some(error);
        }
    }

    /// Hands `planned`'s op to the engine; its reply arrives in a later frame.
    pub(super) fn author(&mut self, planned: Planned) -> Result<(), String> {
        let pending = self
            .engine
            .author_validated(planned.payload.clone())
            .map_err(|e| e.to_string())?;
        let input_at = self.stats.frame_start();
        self.command.pending = Some((pending, planned, input_at));
        Ok(())
    }

    /// Takes the reply to the pending op, if it came.
    pub(super) fn receive_reply(&mut self) {
        let Some(reply) = self
            .command
            .pending
            .as_ref()
            .and_then(|(p, _, _)| p.try_take())
        else {
            return;
        };
        let Some((_, planned, input_at)) = self.command.pending.take() else {
            return;
        };
        match reply {
            Ok(_) => {
                self.command.taken();
                self.status = planned.summary;
                if planned.select.is_some() {
                    self.selected = planned.select;
                }
                self.objects.remesh_previews(false);
                self.objects.edited(input_at);
            }
            Err(e) => {
                self.command.error = Some(e);
                self.objects.remesh_previews(true);
            }
        }
    }

    /// Undoes one of this peer's own ops chosen in the history list.
    pub(super) fn undo_op(&mut self, op: replication::OpId) {
        if self.command.is_pending() {
            return;
        }
        let payload = match Validated::new(replication::shape::ShapePayload::Undo(op)) {
            Ok(payload) => payload,
            Err(e) => {
                self.status = e;
                return;
            }
        };
        let planned = Planned {
            payload,
            summary: "undid an edit chosen in the history".into(),
            select: None,
        };
        if let Err(e) = self.author(planned) {
            self.status = e;
        }
    }

    /// Runs a named shortcut (also what the keyboard does): undo, redo, sculpt, navigate,
    /// play, pause, space.
    pub(super) fn shortcut_named(&mut self, name: &str) -> Result<(), String> {
        match name.to_ascii_lowercase().as_str() {
            "undo" | "ctrl+z" => self.submit("undo"),
            "redo" | "ctrl+y" | "ctrl+shift+z" => self.submit("redo"),
            "sculpt" | "b" => self.sculpt.active = true,
            "play" => self.set_playing(true),
            "pause" => self.set_playing(false),
            "space" => self.set_playing(!self.scene_clock.playing()),
            "navigate" | "escape" => {
                self.sculpt.active = false;
                self.sculpt.stroke = None;
            }
            other => {
                return Err(format!(
                    "unknown shortcut `{other}` (undo, redo, sculpt, navigate, play, pause, space)"
                ));
            }
        }
        Ok(())
    }

    /// Keyboard shortcuts, unless a text field has the keyboard.
    pub(super) fn shortcuts(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let pressed = |key| ctx.input(|i| i.key_pressed(key));
        let (command, shift) = ctx.input(|i| (i.modifiers.command, i.modifiers.shift));
        let action = if command && shift && pressed(egui::Key::Z) {
            Some("redo")
        } else if command && pressed(egui::Key::Z) {
            Some("undo")
        } else if command && pressed(egui::Key::Y) {
            Some("redo")
        } else if pressed(egui::Key::Escape) {
            Some("navigate")
        } else if pressed(egui::Key::B) {
            Some("sculpt")
        } else if pressed(egui::Key::Space) {
            Some("space")
        } else {
            None
        };
        if let Some(action) = action {
            let _ = self.shortcut_named(action);
        }
    }

    /// Runs or stops the scene's time.
    pub(super) fn set_playing(&mut self, playing: bool) {
        self.scene_clock.set_playing(playing, clock::now().instant);
    }
}
