//! The `--dump-state` JSON: what the window shows, one function per section (the session,
//! this window's own state, the touch servo, the objects, the lists, the timings). Tests
//! read it; its keys and shapes are kept as they are.

use model::object::Paintable;
use model::scene::ObjectId;
use serde_json::{Map, Value, json};

use crate::window::app::SculptApp;
use ::app::engine::{View, lock};
use ::app::samples::Samples;
use ::app::touch::shared::SharedState;

impl SculptApp {
    /// What the window shows, as JSON (the `--dump-state` hook).
    pub(super) fn state_json(&self) -> Value {
        let mut view = lock(self.engine.view());
        let sections = [
            self.session_json(&mut view),
            self.window_json(&view),
            json!({ "touch": self.touch_json(&view) }),
            json!({ "objects": self.objects_json(&view) }),
            self.rows_json(&view),
            self.timings_json(),
        ];
        let mut state = Map::new();
        for section in sections {
            if let Value::Object(section) = section {
                state.extend(section);
            }
        }
        Value::Object(state)
    }

    /// The session: this peer, the store, the log and the scene.
    fn session_json(&self, view: &mut View) -> Value {
        json!({
            "peer": view.peer_id().short(),
            "store": self.engine.store_dir().display().to_string(),
            "store_error": view.store_error(),
            "notices": view.notices(),
            "n_ops": view.n_ops(),
            "n_loaded": view.n_loaded(),
            "scene_hash": view.scene_hash_hex(),
            "scene_check": {
                "mismatches": view.scene_check().n_mismatches,
                "agrees": view.scene_check().agrees,
            },
            "snapshot": crate::cli::join_json(view.snapshot()),
            "name": self.engine.presence().name,
            "my_rejections": view.my_rejections().iter().map(|r| r.why.clone()).collect::<Vec<_>>(),
        })
    }

    /// This window: time, layout, the presence it sent, the selection, the brush and the
    /// last stroke, the command line and the status lines.
    fn window_json(&self, view: &View) -> Value {
        let sent = self.presence.sent.as_ref();
        json!({
            "time_secs": self.frame_time_secs,
            "window_points": self.layout.window_points,
            "side_panel_points": self.layout.side_panel_points,
            "my_tool": sent.and_then(|p| p.tool),
            "my_tool_body": sent.and_then(|p| p.tool_body),
            "playing": self.scene_clock.playing(),
            "selected": self.selected.map(|id| view.object_label(id)),
            "tool": self.sculpt.brush.describe(),
            "sculpting": self.sculpt.active,
            "last_stroke": self.sculpt.last_stroke.as_ref().map(|points| {
                points.iter().map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>()
            }),
            "probes": self.probes(view),
            "input_error": self.command.error,
            "status": self.status,
            "pick": self.pick_status,
        })
    }

    /// The touch servo while touching (null otherwise).
    fn touch_json(&self, view: &View) -> Value {
        let Some(live) = &self.touch.live else {
            return Value::Null;
        };
        let s = live.stats();
        let density = self.sampled_density_in(view);
        json!({
            "hip": s.hip_world.to_array(),
            "force": s.force_newtons.to_array(),
            "steady_force": self.hooks.steady_force,
            "n_stalls": s.n_stalls,
            "top_id": s.top_id,
            "n_ticks": s.n_ticks,
            "n_overruns": s.n_overruns,
            "period_micros": s.period_micros,
            "n_scenes_taken": s.n_scenes_taken,
            "compute_micros": s.compute_micros,
            "device_status": self.touch.spacemouse.as_ref().map(|(d, _)| d.status().text()),
            "energy_joules": s.energy_joules,
            "sampled_density": density,
            "sampling_colour": ::app::touch::probe::sampling_colour(density),
            "n_plotted": self.touch.force_history.len(),
            "recording": self.touch.recording.as_ref().map(|(r, _)| r.n_rows()),
            "force_output": live.force_output_ref().status(),
            "zone_centre": live.zone().center_world.to_array(),
            "zone_size": live.zone_size(),
            "zone_depth": live.zone_depth_text(),
            "n_force_writes": live.force_output_ref().n_writes(),
            "shared_tool": self.shared_tool_json(),
        })
    }

    /// The tool held with another peer, while touching (null without one).
    fn shared_tool_json(&self) -> Value {
        let Some(tool) = &self.touch.shared_tool else {
            return Value::Null;
        };
        let st = tool.stats();
        let (state, with) = match self.touch.shared_state {
            SharedState::Alone => ("alone", None),
            SharedState::Waiting(p) => ("waiting", Some(p)),
            SharedState::Coupled(p) => ("coupled", Some(p)),
        };
        json!({
            "state": state,
            "with": with.map(|p| p.short()),
            "n_sent": st.n_sent,
            "n_received": st.n_received,
            "n_dropped": st.n_dropped,
            "force": st.force_newtons.to_array(),
            "energy_in_joules": st.energy_in_joules,
            "energy_out_joules": st.energy_out_joules,
        })
    }

    /// Each object of the scene: what it is, its lease, and how it is meshed and drawn.
    fn objects_json(&self, view: &View) -> Value {
        view.scene()
            .objects()
            .map(|(id, entry)| {
                let data = entry.object.data();
                let tracked = self.objects.tracked.get(&id);
                let history = entry.object.history();
                json!({
                    "id": id.0,
                    "name": view.object_label(id.0),
                    "n_edits": history.len(),
                    "n_active_edits": history.entries().iter().filter(|e| e.active).count(),
                    "lease_holder": view.lease(id.0).map(|l| l.holder.short()),
                    "geometry": data.geometry.as_ref().map(|g| format!("{:?}", g.shape)),
                    "diffuse": data.appearance.diffuse.as_ref().map(|c| format!("{c:?}")),
                    "n_triangles": tracked.map(|t| t.n_triangles),
                    "skipped": tracked.and_then(|t| t.skipped.clone()),
                    "mesh_secs": tracked.map(|t| t.mesh_secs),
                    "mesh_kind": tracked.and_then(|t| t.kind).map(|k| k.name()),
                    "previewed": tracked.map(|t| t.previewed),
                    "closed": tracked.and_then(|t| t.drawn.as_ref()).map(|d| d.closed),
                    "mesh_t_secs": tracked.map(|t| t.drawn_t_secs),
                    "world_from_object": tracked
                        .and_then(|t| t.world_from_object_now())
                        .map(|m| m.to_cols_array()),
                })
            })
            .collect()
    }

    /// The lists the panels show: peers, their presence, news, chat and history.
    fn rows_json(&self, view: &View) -> Value {
        let peers: Vec<Value> = view
            .peers()
            .iter()
            .map(|p| {
                json!({
                    "peer": p.peer.short(), "name": p.name, "online": p.online,
                    "addr": p.addr, "how": p.how,
                    "rtt_micros": p.rtt_micros, "to_send": p.to_send, "to_receive": p.to_receive,
                })
            })
            .collect();
        let presence: Vec<Value> = view
            .presence()
            .iter()
            .map(|(peer, p)| {
                json!({
                    "peer": peer.short(), "name": p.name, "colour": p.colour,
                    "pointer": p.pointer, "tool": p.tool, "selected": p.selected,
                })
            })
            .collect();
        let chat: Vec<Value> = self
            .rows
            .chat
            .iter()
            .map(|c| json!({ "author": c.author, "time": c.time, "text": c.text }))
            .collect();
        let history: Vec<Value> = self.rows.history.iter()
            .map(|h| {
                json!({ "author": h.author, "time": h.time, "what": h.what, "status": h.status })
            })
            .collect();
        json!({
            "peers": peers,
            "presence": presence,
            "news": self.rows.news,
            "chat": chat,
            "history": history,
        })
    }

    /// Frames, meshes and the viewport's uploads, with their times.
    fn timings_json(&self) -> Value {
        let report = self.viewport.lock().ok();
        let report = report.as_deref();
        json!({
            "viewport_error": report.and_then(|r| r.error.clone()),
            "prepare_ms": report.map(|r| summary(&r.prepare_ms)),
            "frames": self.stats.n_frames,
            "ui_ms": summary(&self.stats.ui_ms),
            "frame_interval_ms": summary(&self.stats.frame_interval_ms),
            "edit_to_mesh_ms": self.objects.stats.edit_to_mesh_ms.values(),
            "edit_to_pixels_ms": self.objects.stats.edit_to_pixels_ms.values(),
            "remote_edit_to_pixels_ms": self.objects.stats.remote_edit_to_pixels_ms.values(),
            "remote_edit_to_mesh_ms": self.objects.stats.remote_edit_to_mesh_ms.values(),
            "patch_ms": self.objects.stats.patch_ms.values(),
            "meshes": json!({
                "patched": self.objects.stats.n_patched,
                "whole": self.objects.stats.n_whole,
                "coarse": self.objects.stats.n_coarse,
                "edits_superseded": self.objects.stats.n_edits_superseded,
                "edits_awaited": self.objects.stats.n_edits_awaited,
                "edit_waits_expired": self.objects.stats.n_edit_waits_expired,
            }),
            "last_upload_bytes": report.map(|r| r.last_upload_bytes),
            "min_upload_bytes": report.and_then(|r| r.min_upload_bytes),
            "patches_refused": report.map(|r| r.n_patches_refused),
            "viewport_frames": report.map(|r| json!({ "drawn": r.n_drawn, "regions": r.n_regions, "lines_only": r.n_lines_only, "reused": r.n_reused })),
        })
    }

    /// The selected object's value and scalar properties at the last stroke's points (scene
    /// coordinates), for tests that check what a stroke did through the engine. Points map
    /// into the object as a stroke maps them (its group's transform, then its own).
    fn probes(&self, view: &View) -> Value {
        let (Some(points), Some(id)) = (&self.sculpt.last_stroke, self.selected) else {
            return Value::Null;
        };
        let scene = view.scene();
        let Some(entry) = scene.scene_object(ObjectId(id)) else {
            return Value::Null;
        };
        let scene_from_object = scene
            .world_from_group(entry.group)
            .then(&entry.object.data().transform);
        let Some(object_from_scene) = scene_from_object.inverse() else {
            return Value::Null;
        };
        let mut sampler = entry.object.sampler();
        let rows: Vec<Value> = points
            .iter()
            .map(|p| {
                let q = object_from_scene.point(*p);
                json!({
                    "at": [p.x, p.y, p.z],
                    "value": sampler.value(q, 0.0),
                    "density": sampler.scalar(Paintable::Density, q, 0.0),
                    "tension": sampler.scalar(Paintable::Tension, q, 0.0),
                })
            })
            .collect();
        Value::Array(rows)
    }
}

/// Mean, median, 95th percentile and maximum of some samples (null with none).
fn summary(samples: &Samples) -> Value {
    samples.summary().map_or(
        Value::Null,
        |s| json!({ "n": s.n, "mean": s.mean, "p50": s.p50, "p95": s.p95, "max": s.max }),
    )
}
