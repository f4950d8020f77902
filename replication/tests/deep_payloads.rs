//! Ops and snapshots whose formulas nest as deep as fdsl allows decode, validate and fold on a
//! thread with a 256 KiB stack (the budget of the app's engine thread), and the `x^x^...`
//! chain that once overflowed the engine thread of every peer is refused there.
#![allow(clippy::unwrap_used, reason = "test helpers unwrap")]

use std::sync::Arc;

use fdsl::limits::{MAX_NESTING_DEPTH, MAX_STATEMENT_DEPTH};
use model::object::{ColorDef, Formula, Geometry, ObjectData, Physics, Property, compiled};
use replication::materialize::Materialized;
use replication::pending::Origin;
use replication::shape::{ShapePayload, ShapeScene};
use replication::{Keypair, Log, Op, Payload, Timestamp};
use testkit::stack::on_small_stack;

type SLog = Log<ShapePayload>;
type SScene = Materialized<ShapePayload, ShapeScene>;

/// Statements nested to their limit, an expression nested to its limit inside the deepest.
fn deepest_formula(value: &str) -> Formula {
    let n = MAX_STATEMENT_DEPTH - 1;
    // The pending `-` is one level of the expression.
    let m = MAX_NESTING_DEPTH - 1;
    Formula::new(format!(
        "function frep(x,y,z) {{ r = 0; {}r = {value} - {}x{};{} return r; }}",
        "{ ".repeat(n),
        "(".repeat(m),
        ")".repeat(m),
        " }".repeat(n)
    ))
    .unwrap()
}

/// An object with the deepest formula in its geometry, its colour and its density.
fn deepest_object() -> ObjectData {
    ObjectData {
        name: "deep".into(),
        geometry: Some(Geometry::implicit(deepest_formula("0.5"))),
        appearance: model::object::Appearance {
            diffuse: Some(ColorDef::Rgb(
                Formula::new(format!(
                    "r = {}x{}; g = 0.5; b = y;",
                    "(".repeat(MAX_NESTING_DEPTH),
                    ")".repeat(MAX_NESTING_DEPTH)
                ))
                .unwrap(),
            )),
            ..Default::default()
        }
        .into(),
        physics: Physics {
            density: Some(Property::new(deepest_formula("2"))),
            ..Physics::default()
        }
        .into(),
        ..ObjectData::default()
    }
}

fn create(data: ObjectData) -> ShapePayload {
    ShapePayload::Create {
        object: 1,
        counter: None,
        data: Arc::new(data),
        group: None,
    }
}

/// The bytes of `payload` signed by a peer, as they arrive from the network.
fn received(payload: ShapePayload) -> Vec<u8> {
    let mut log = SLog::default();
    let key = Keypair::from_seed([7; 32]);
    let (op, _) = log.author(&key, Timestamp(1), payload).unwrap();
    op.encoded().to_vec()
}

#[test]
fn the_deepest_formulas_decode_validate_and_fold_on_a_small_stack() {
    let bytes = received(create(deepest_object()));
    let scene = on_small_stack(|| {
        // Nothing cached: the decoder and the fold each compile every formula.
        compiled::clear();
        let op =
            Op::<ShapePayload>::decode_verified(&bytes, &replication::op::UNNAMED_SESSION).unwrap();
        compiled::clear();
        let mut log = SLog::default();
        let mut scene = SScene::fold(&log);
        let insertion = log.insert(Timestamp(2), op, Origin(1)).unwrap();
        scene.apply_insertion(&log, &insertion);
        scene
    });
    assert_eq!(scene.scene().scene().objects().count(), 1);
}

#[test]
fn a_power_chain_past_the_limit_is_refused_on_a_small_stack() {
    // 7,000 levels, 14 KB: well under the payload and formula limits. An honest log refuses
    // to author it, so the payload's bytes are what a hostile peer signs and sends.
    let attack = Formula::new("x^".repeat(7_000) + "x").unwrap();
    let payload = create(ObjectData {
        geometry: Some(Geometry::implicit(attack)),
        ..ObjectData::default()
    });
    let mut bytes = Vec::new();
    payload.encode(&mut bytes);
    on_small_stack(|| {
        compiled::clear();
        let refused = ShapePayload::decode(&bytes);
        assert!(refused.is_err(), "{refused:?}");
    });
}
