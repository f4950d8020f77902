//! The other peers: the presence this window publishes (pointer, touch tool, selection,
//! camera), theirs drawn in the viewport, following one's camera, and the Peers panel
//! (this user's name and colour, each peer met, the sessions on the LAN, network news).

use eframe::egui;
use glam::Vec3;
use render::mesh::Aabb;
use render::scene::Scene;
use render::snapshot::render_from_scene;

use super::app::SculptApp;
use ::app::engine::{PeerRow, lock};
use replication::PeerId;
use replication::sync::ephemeral::presence::{CameraPose, Presence};

/// Half the size of another peer's pointer cross, in world units.
const PRESENCE_CROSS_SIZE: f32 = 0.06;
/// Half the size of the cross (in a box) that marks another peer's touch tool, world units.
const PRESENCE_TOOL_SIZE: f32 = 0.15;
/// What a forked author's mark means.
const FORKED_HOVER: &str = "this identity signed two different edits with one number: \
                            it runs as two copies, or from a restored backup, or it is \
                            hostile; its edits from that number on count for nothing, \
                            everywhere";
/// News lines the peers panel shows (the latest).
const MAX_NEWS_SHOWN: usize = 20;
/// What the scene check's mark means.
const SCENE_CHECK_HOVER: &str = "peers compare their scene hashes whenever both hold the same \
                                 edits; where they differ, each refolds the objects that \
                                 differ from its edit log";

/// What this window told the other peers, and whose camera it follows.
#[derive(Default)]
pub struct PresenceState {
    /// The presence last handed to the engine.
    pub sent: Option<Presence>,
    /// The peer whose camera this window follows.
    pub following: Option<PeerId>,
}

/// What the session's membership looks like to the Peers panel.
struct Membership {
    expelled: std::collections::BTreeSet<PeerId>,
    forked: std::collections::BTreeMap<PeerId, u64>,
    /// This peer founded the session, so it may expel members.
    founder: bool,
}

/// What a click in a peer's row asks for.
#[derive(Default)]
struct PeerClicks {
    /// Follow this peer's camera (`Some(None)`: stop following).
    follow: Option<Option<PeerId>>,
    /// A membership command to run (`expel: ...`, `readmit: ...`).
    membership: Option<String>,
}

impl SculptApp {
    /// Hands this window's presence to the engine when it changed.
    pub(super) fn publish_presence(&mut self) {
        let live = self.touch.live.as_ref();
        let mut presence = self.engine.presence();
        presence.pointer = self.view.pointer.map(|p| p.to_array());
        presence.tool = live.map(|live| {
            render_from_scene()
                .transform_point3(live.stats().hip_world.as_vec3())
                .to_array()
        });
        presence.holds_tool_with = self.touch.hold_with.filter(|_| live.is_some()).map(|p| p.0);
        presence.tool_body =
            (live.is_some() && self.touch.body.is_tangible()).then(|| self.touch.body.to_wire());
        presence.selected = self.selected;
        let c = &self.view.camera;
        presence.camera = Some(CameraPose {
            target: c.target.to_array(),
            orbit: [c.yaw, c.pitch, c.distance],
        });
        if self.presence.sent.as_ref() != Some(&presence)
            && self.engine.set_presence(presence.clone()).is_ok()
        {
            self.presence.sent = Some(presence);
        }
    }

    /// Copies the followed peer's camera, while it is connected.
    pub(super) fn follow(&mut self) {
        let Some(peer) = self.presence.following else {
            return;
        };
        let camera = lock(self.engine.view())
            .presence()
            .get(&peer)
            .map(|p| p.camera);
        match camera {
            Some(Some(pose)) => {
                let c = &mut self.view.camera;
                c.target = Vec3::from_array(pose.target);
                [c.yaw, c.pitch, c.distance] = pose.orbit;
                self.view.moved = true;
            }
            Some(None) => {}
            None => self.presence.following = None,
        }
    }

    /// Other peers' pointers (a cross), touch tools (a larger cross in a box) and selections
    /// (a box) in their colours.
    pub(super) fn draw_presence(&self, scene: &mut Scene) {
        let view = lock(self.engine.view());
        for p in view.presence().values() {
            let [r, g, b] = p.colour.map(|c| f32::from(c) / 255.0);
            let colour = [r, g, b, 1.0];
            if let Some(at) = p.pointer {
                scene.add_crosshair(Vec3::from_array(at), PRESENCE_CROSS_SIZE, colour);
            }
            if let Some(at) = p.tool.map(Vec3::from_array) {
                scene.add_crosshair(at, PRESENCE_TOOL_SIZE, colour);
                let half = Vec3::splat(PRESENCE_TOOL_SIZE * 0.35);
                scene.add_box(
                    Aabb::new((at - half).to_array(), (at + half).to_array()),
                    colour,
                );
            }
            if let Some(b) = p.selected.and_then(|id| self.objects.drawn_box(id)) {
                scene.add_box(b, colour);
            }
        }
    }

    /// The Peers panel: this user, each peer met with how it was reached, its round trip and
    /// what is still to sync, then the sessions on the LAN and the latest network news.
    pub(super) fn peers_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading(format!("Peers ({} online)", self.rows.n_online));
        self.me_ui(ui);
        if self.rows.peers.is_empty() {
            ui.weak("nobody met yet");
        }
        let membership = {
            let view = lock(self.engine.view());
            Membership {
                expelled: view.expelled().clone(),
                forked: view.forked().clone(),
                founder: view.founder_nonce().is_some(),
            }
        };
        let mut clicks = PeerClicks::default();
        for p in &self.rows.peers {
            ui.horizontal(|ui| {
                self.peer_row_ui(ui, p, &membership, &mut clicks);
            });
            if p.online {
                scene_check_ui(ui, p);
            }
        }
        if let Some(f) = clicks.follow {
            self.presence.following = f;
        }
        if let Some(line) = clicks.membership {
            self.submit(&line);
        }
        self.lan_ui(ui);
        egui::CollapsingHeader::new("network news")
            .id_salt("news")
            .show(ui, |ui| {
                for line in self.rows.news.iter().rev().take(MAX_NEWS_SHOWN) {
                    ui.small(line);
                }
            });
    }

    /// The name and colour others see this user by.
    fn me_ui(&mut self, ui: &mut egui::Ui) {
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
    }

    /// One peer's row: its colour, name and id, its marks, the founder's expel or readmit,
    /// and (online) how it is reached and whether this window follows it.
    fn peer_row_ui(
        &self,
        ui: &mut egui::Ui,
        p: &PeerRow,
        membership: &Membership,
        clicks: &mut PeerClicks,
    ) {
        let [r, g, b] = p.colour;
        let colour = egui::Color32::from_rgb(r, g, b);
        let (dot, _) = ui.allocate_exact_size(egui::vec2(10.0, 10.0), egui::Sense::hover());
        ui.painter().circle_filled(dot.center(), 5.0, colour);
        ui.strong(&p.name);
        ui.weak(p.peer.short());
        let out = membership.expelled.contains(&p.peer);
        if out {
            ui.colored_label(egui::Color32::LIGHT_RED, "expelled");
        }
        if let Some(seq) = membership.forked.get(&p.peer) {
            ui.colored_label(egui::Color32::LIGHT_RED, format!("forked at #{seq}"))
                .on_hover_text(FORKED_HOVER);
        }
        if membership.founder {
            let word = if out { "readmit" } else { "expel" };
            let hover = "as the session's founder: its ops from now on count for nothing, \
                         and every peer closes its connections to it (readmit undoes it)";
            if ui.small_button(word).on_hover_text(hover).clicked() {
                clicks.membership = Some(format!("{word}: {}", p.peer.to_hex()));
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
        let following = self.presence.following == Some(p.peer);
        if ui.selectable_label(following, "follow").clicked() {
            clicks.follow = Some((!following).then_some(p.peer));
        }
    }

    /// The sessions announced on the LAN (DNS-SD).
    fn lan_ui(&self, ui: &mut egui::Ui) {
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
    }
}

/// A peer's scene check, on a short line of its own under its row (the row alone sets how
/// wide the panel grows): whether its scene agreed with ours when last compared, and the
/// mismatches found with it (the last one on hover).
fn scene_check_ui(ui: &mut egui::Ui, p: &PeerRow) {
    let (colour, word) = match (p.scene_agrees, p.scene_mismatches) {
        (Some(false), _) => (egui::Color32::LIGHT_RED, "scene differs".to_string()),
        (Some(true), 0) => (egui::Color32::LIGHT_GREEN, "same scene".to_string()),
        (Some(true), n) => (egui::Color32::YELLOW, format!("same scene · {n} repaired")),
        (None, 0) => return,
        (None, n) => (egui::Color32::YELLOW, format!("{n} scene mismatch(es)")),
    };
    let hover = match &p.last_mismatch {
        Some(last) => format!("{SCENE_CHECK_HOVER}\n\nlast: {last}"),
        None => SCENE_CHECK_HOVER.to_string(),
    };
    ui.label(egui::RichText::new(word).small().color(colour))
        .on_hover_text(hover);
}
