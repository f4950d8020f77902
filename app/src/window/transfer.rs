//! Files in and out of the session from the window: scenes and meshes imported (from the
//! File menu, a dropped file or a script), their ops authored one at a time; the selection
//! (or the scene) exported on a thread of its own; and the File menu's path field.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::mpsc::Receiver;

use eframe::egui;
use model::scene::ObjectId;
use replication::shape::ShapePayload;

use super::ERROR_COLOUR;
use super::app::SculptApp;
use ::app::command::Planned;
use ::app::engine::{Validated, lock};

/// What the File menu's path field does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileAction {
    /// Bring a scene or mesh file into the session.
    Import,
    /// Write the selection (or the scene) to a file.
    Export,
    /// Record the touch tool's path to a file.
    RecordTouch,
}

/// Imports and exports under way, and the path field.
#[derive(Default)]
pub struct Transfer {
    /// The File menu's path field: what it does, the path typed, and the last error.
    pub input: Option<(FileAction, String, Option<String>)>,
    /// Ops of an import still to author, one at a time.
    import_queue: VecDeque<ShapePayload>,
    /// An export running on its own thread.
    export: Option<Receiver<Result<String, String>>>,
}

impl Transfer {
    /// Whether nothing is being imported or exported.
    pub fn is_idle(&self) -> bool {
        self.import_queue.is_empty() && self.export.is_none()
    }
}

impl SculptApp {
    /// Plans the ops of a scene or mesh file and queues them; nothing is authored when the
    /// file is refused.
    pub(super) fn import_file(&mut self, path: &Path) -> Result<(), String> {
        let next = lock(self.engine.view()).next_object();
        let imported = ::app::transfer::import(path, next).map_err(|e| e.to_string())?;
        self.status = format!(
            "importing {} ({} ops)",
            path.display(),
            imported.payloads.len()
        );
        self.transfer.import_queue.extend(imported.payloads);
        Ok(())
    }

    /// Exports the selected object (or the whole scene) to `path` on a thread of its own.
    pub(super) fn export_file(&mut self, path: PathBuf) -> Result<(), String> {
        if self.transfer.export.is_some() {
            return Err("an export is still running".into());
        }
        if formats::registry::FileFormat::of(&path).is_none() {
            return Err(format!(
                "export to {}: give a file ending in {}",
                path.display(),
                formats::registry::EXTENSIONS.join(", ")
            ));
        }
        let scene = lock(self.engine.view()).scene().clone();
        let object = self.selected.map(ObjectId);
        let depth = self.objects.depth;
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::Builder::new()
            .name("sculpt-export".into())
            .spawn(move || {
                let result = ::app::transfer::export(&scene, object, &path, depth)
                    .map(|report| report.to_string())
                    .map_err(|e| e.to_string());
                let _ = tx.send(result);
            })
            .map_err(|e| e.to_string())?;
        self.transfer.export = Some(rx);
        self.status = "exporting…".into();
        Ok(())
    }

    /// Files dropped on the window are imported, the next import op is authored, and an
    /// export's result reaches the status line.
    pub(super) fn transfer_frame(&mut self, ctx: &egui::Context) {
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_path_buf())
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        });
        for path in dropped {
            if let Err(e) = self.import_file(&path) {
                self.status = e;
            }
        }
        self.author_imports();
        if let Some(result) = self
            .transfer
            .export
            .as_ref()
            .and_then(|rx| rx.try_recv().ok())
        {
            self.transfer.export = None;
            self.status = match result {
                Ok(report) => report.lines().next().unwrap_or("exported").to_string(),
                Err(e) => format!("export failed: {e}"),
            };
        }
    }

    /// Authors the next queued import op once the last op is stored.
    fn author_imports(&mut self) {
        if self.command.is_pending() {
            return;
        }
        let Some(payload) = self.transfer.import_queue.pop_front() else {
            return;
        };
        // Refused as the engine's reply would refuse it: shown, and the next op goes on.
        let payload = match Validated::new(payload) {
            Ok(payload) => payload,
            Err(e) => {
                self.command.error = Some(e);
                return;
            }
        };
        let planned = Planned {
            payload,
            summary: format!("imported; {} ops to go", self.transfer.import_queue.len()),
            select: None,
        };
        if let Err(e) = self.author(planned) {
            self.status = format!("import stopped: {e}");
            self.transfer.import_queue.clear();
        }
    }

    /// The File menu's path field (import, export or record the touch path), with its error.
    pub(super) fn file_ui(&mut self, ui: &mut egui::Ui) {
        let Some((action, mut text, mut error)) = self.transfer.input.take() else {
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
                let path = PathBuf::from(text.trim());
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
            self.transfer.input = Some((action, text, error));
        }
    }
}
