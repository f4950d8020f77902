//! Which session the window is in: sharing it (its invite), joining another with an invite,
//! opening a demo's own session, and the word for where it stands (solo, offline, N peers).

use eframe::egui;

use super::ERROR_COLOUR;
use super::app::SculptApp;
use ::app::clock;
use ::app::engine::{Engine, EngineConfig, lock};

/// The Share and Join state of the top bar.
#[derive(Default)]
pub struct Session {
    /// The invite is shown (after "Share").
    pub show_invite: bool,
    /// The session was shared or joined: no peers then means offline, not solo.
    pub shared: bool,
    /// The invite typed into "Join", and why it was refused.
    pub join_input: Option<(String, Option<String>)>,
}

impl SculptApp {
    /// Solo, N peers, or offline with edits waiting: what the title bar says.
    pub(super) fn presence_text(&self) -> String {
        let view = lock(self.engine.view());
        let (to_send, to_receive) = view.progress();
        match self.rows.n_online {
            0 if self.session.shared => {
                format!("offline · {} ops kept, waiting for peers", view.n_ops())
            }
            0 => "solo".to_string(),
            n if to_send + to_receive > 0 => {
                format!("{n} peer(s) · syncing: {to_send} to send, {to_receive} to receive")
            }
            n => format!("{n} peer(s) · in sync"),
        }
    }

    /// Lets peers in with this session's invite; `show_invite` is whether to show it now.
    pub(super) fn share(&mut self, show_invite: bool) {
        self.session.show_invite = show_invite;
        self.session.shared = true;
        if let Err(e) = self.engine.share() {
            self.status = e.to_string();
        }
    }

    /// Leaves this session and joins the one `invite` opens, in its own store directory
    /// beside this one.
    pub(super) fn join(&mut self, text: &str) -> Result<(), String> {
        let invite = replication::net::invite::Invite::parse(text).map_err(|e| e.to_string())?;
        let mut config = self.config.clone();
        config.store = ::app::dirs::store_beside(
            &self.config.store,
            &::app::engine::store::joined_dir_name(&invite),
        );
        config.invite = Some(invite);
        config.demo = None;
        self.switch_session(config, true)?;
        self.status = "joined the session; syncing".into();
        Ok(())
    }

    /// Leaves this session and opens `demo`'s own, in its store directory beside this one
    /// (made and given the demo's objects the first time).
    pub(super) fn open_demo(&mut self, demo: &'static ::app::demos::Demo) -> Result<(), String> {
        let mut config = self.config.clone();
        config.store = ::app::dirs::store_beside(&self.config.store, &demo.store_dir_name());
        config.invite = None;
        config.demo = Some(demo);
        self.switch_session(config, false)?;
        self.status = format!("{}: {}", demo.title, demo.about);
        Ok(())
    }

    /// Starts an engine on `config` and puts it in the place of this one (which stops), with
    /// the window's per-session state cleared.
    fn switch_session(&mut self, mut config: EngineConfig, shared: bool) -> Result<(), String> {
        // The servo felt the session left.
        self.set_touching(false)?;
        // The session left is still listening while the new one starts.
        config.network.listen.set_port(0);
        let engine = Engine::start(config.clone(), clock::now().wall).map_err(|e| e.to_string())?;
        let waker = self.waker.clone();
        lock(engine.view()).set_waker(Box::new(move || waker()));
        self.engine = engine;
        self.config = config;
        self.session.shared = shared;
        self.objects.reset();
        self.selected = None;
        self.rows.reset();
        self.presence.following = None;
        self.presence.sent = None;
        Ok(())
    }

    /// The invite field of "Join…", with the reason a code was refused (its column).
    pub(super) fn join_ui(&mut self, ui: &mut egui::Ui) {
        let Some((mut text, mut error)) = self.session.join_input.take() else {
            return;
        };
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
                        self.session.join_input = None;
                        return;
                    }
                    Err(e) => error = Some(e),
                }
            }
            self.session.join_input = Some((text.clone(), error.clone()));
        });
        if let Some(e) = self
            .session
            .join_input
            .as_ref()
            .and_then(|(_, e)| e.as_ref())
        {
            ui.colored_label(ERROR_COLOUR, e);
        }
    }

    /// This session's invite, while shown.
    pub(super) fn invite_ui(&self, ui: &mut egui::Ui) {
        if !self.session.show_invite {
            return;
        }
        ui.horizontal(|ui| {
            ui.label("Invite (a secret: give it only to who should join):");
            let code = self.engine.invite().to_string();
            ui.monospace(&code);
            if ui.button("Copy").clicked() {
                ui.ctx().copy_text(code);
            }
        });
        ui.weak("They run: sculpt --invite CODE (same LAN), or add --dial ADDR / --discovery ADDR");
    }
}
