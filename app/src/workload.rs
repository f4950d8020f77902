//! Long sessions made at once, for tests and benchmarks: a store that a peer opens as if its
//! user had sculpted for hours, without authoring each op through an engine (one fsync each).

use std::path::Path;

use model::object::{Edit, EditOp, Formula, Geometry, ObjectData, Pose, ToolShape};
use replication::net::{Invite, SessionKeys};
use replication::shape::{IdSource, ShapePayload};
use replication::{Log, Timestamp};

use crate::engine::store;

/// Most edits [`carved_session`] makes (the log's own bound is higher; this keeps a test's
/// store under about 40 MB).
pub const MAX_WORKLOAD_EDITS: usize = 200_000;

/// Founds a new session in `dir` (which must hold none) whose founder made one ball and
/// carved it `n_edits` times, each a small sphere somewhere on its surface, all stored.
/// Returns the number of ops stored and the session's invite.
pub fn carved_session(
    dir: &Path,
    n_edits: usize,
    now: Timestamp,
) -> Result<(usize, Invite), String> {
    if n_edits > MAX_WORKLOAD_EDITS {
        return Err(format!("at most {MAX_WORKLOAD_EDITS} edits"));
    }
    let opened = store::open(dir, None, now).map_err(|e| e.to_string())?;
    if !opened.log.is_empty() {
        return Err(format!("{} already holds a session", dir.display()));
    }
    let keypair = opened.keypair;
    let me = keypair.peer_id();
    let mut log: Log<ShapePayload> = opened.log;
    log.set_session_id(SessionKeys::from_invite(&opened.invite).session_id());
    let mut payloads = Vec::with_capacity(n_edits + 2);
    payloads.extend(crate::engine::founding_payload(
        opened.founder_nonce,
        &log,
        me,
    ));
    let ball = IdSource::first(me);
    let formula = Formula::new("0.8 - sqrt(x^2 + y^2 + z^2)").map_err(|e| e.to_string())?;
    payloads.push(ball.create(
        ObjectData {
            name: "carved ball".into(),
            geometry: Some(Geometry {
                domain: Some(crate::new_object::new_object_domain()),
                ..Geometry::implicit(formula)
            }),
            ..ObjectData::default()
        },
        None,
    ));
    // Points spread over the sphere by the golden angle: every edit lands somewhere new.
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    for i in 0..n_edits {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n_edits as f64;
        let r = (1.0 - z * z).sqrt();
        let a = golden * i as f64;
        let at = glam::DVec3::new(r * a.cos(), r * a.sin(), z) * 0.8;
        let stamp = Edit::stamp(
            EditOp::Subtract,
            ToolShape::Sphere { radius: 0.03 },
            Pose::at(at),
        );
        payloads.push(ShapePayload::edit(ball.id(), stamp).map_err(|e| e.to_string())?);
    }
    let mut store = opened.store;
    let mut ids = Vec::with_capacity(payloads.len());
    for (i, payload) in payloads.into_iter().enumerate() {
        let at = Timestamp(now.0 + i as u64);
        let (op, _) = (log.author(&keypair, at, payload)).map_err(|e| e.to_string())?;
        ids.push(op.op().id());
    }
    let ops: Vec<_> = ids.iter().filter_map(|id| log.get(id)).collect();
    store.append(&ops).map_err(|e| e.to_string())?;
    Ok((ops.len(), opened.invite))
}
