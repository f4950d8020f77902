//! The fdsl payload end to end in the core: ops over the object model fold to the same scene
//! on every peer whatever the delivery order; concurrent property writes resolve by the
//! order, concurrent sculpting edits all apply; undo/redo and leases act on real objects;
//! hostile payload bytes are refused.
#![allow(clippy::unwrap_used, reason = "test helpers outside #[test] functions")]

use std::sync::Arc;

use glam::DVec3;
use model::object::{
    ColorDef, Domain, Edit, EditOp, Field, Formula, Geometry, ObjectData, PaintValue, Paintable,
    Pose, Shape, Shared, ToolShape,
};
use model::scene::ObjectId as SceneObjectId;
use proptest::prelude::*;
use replication::materialize::Materialized;
use replication::payload::{LeaseAction, MAX_PAYLOAD_BYTES};
use replication::pending::Origin;
use replication::shape::{
    DERIVED_ID_BIT, IdSource, ShapePayload, ShapeScene, may_create, object_id, parts,
};
use replication::{Keypair, Log, Payload, Timestamp, VerifiedOp};

type SLog = Log<ShapePayload>;
type SScene = Materialized<ShapePayload, ShapeScene>;

fn key(i: u8) -> Keypair {
    Keypair::from_seed([i + 1; 32])
}

fn sphere_data() -> ObjectData {
    ObjectData {
        name: "ball".into(),
        geometry: Some(Geometry::implicit(
            Formula::new("1 - x^2 - y^2 - z^2").unwrap(),
        )),
        ..ObjectData::default()
    }
}

fn carve(at: DVec3) -> ShapePayload {
    carve_at(1, at)
}

fn carve_at(object: u64, at: DVec3) -> ShapePayload {
    ShapePayload::edit(
        object,
        Edit::stamp(
            EditOp::Subtract,
            ToolShape::Sphere { radius: 0.2 },
            Pose::at(at),
        ),
    )
    .expect("a valid edit")
}

fn color(rgb: [f32; 3]) -> ShapePayload {
    ShapePayload::Set {
        object: 1,
        field: Box::new(Field::Diffuse(Some(ColorDef::Constant(rgb)))),
    }
}

/// Peer 0 creates the ball; every peer then authors `per_peer` ops concurrently (knowing only
/// the creation), mixing carves, paints, colour writes, undos and chat.
fn concurrent_workload(n_peers: u8, per_peer: usize) -> Vec<VerifiedOp<ShapePayload>> {
    let mut base = SLog::default();
    let (create, _) = base
        .author(
            &key(0),
            Timestamp(1),
            ShapePayload::Create {
                object: 1,
                counter: None,
                data: std::sync::Arc::new(sphere_data()),
                group: None,
            },
        )
        .unwrap();
    let mut ops = vec![create];
    for p in 0..n_peers {
        let mut log = base.clone();
        let mut last_edit = None;
        for i in 0..per_peer {
            let x = (p as f64 * 0.3 + i as f64 * 0.07).sin() * 0.8;
            let payload = match i % 5 {
                0 | 1 => carve(DVec3::new(x, 0.5, 0.0)),
                2 => color([p as f32 / n_peers as f32, 0.5, i as f32 / per_peer as f32]),
                3 => match last_edit {
                    Some(id) => ShapePayload::Undo(id),
                    None => ShapePayload::Chat(format!("{p}:{i}")),
                },
                _ => ShapePayload::edit(
                    1,
                    Edit::stamp(
                        EditOp::Paint {
                            property: Paintable::Density,
                            value: PaintValue::Scalar(p as f64 + 1.0),
                        },
                        ToolShape::Sphere { radius: 0.3 },
                        Pose::at(DVec3::new(0.0, x, 0.0)),
                    ),
                )
                .expect("a valid edit"),
            };
            let is_edit = matches!(payload, ShapePayload::Edit { .. });
            let (op, _) = log
                .author(&key(p), Timestamp(100 + i as u64), payload)
                .unwrap();
            if is_edit {
                last_edit = Some(op.id());
            }
            ops.push(op);
        }
    }
    ops
}

fn deliver(ops: &[VerifiedOp<ShapePayload>]) -> (SLog, SScene) {
    let mut log = SLog::default();
    let mut scene = SScene::fold(&log);
    for op in ops {
        let ins = log.insert(Timestamp(0), op.clone(), Origin(1)).unwrap();
        scene.apply_insertion(&log, &ins);
    }
    (log, scene)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Any delivery order of the same ops gives the same scene, and the incremental fold
    /// equals a fold from scratch.
    #[test]
    fn every_delivery_order_gives_the_same_scene(seed in any::<u64>()) {
        let ops = concurrent_workload(3, 12);
        let (_, reference) = deliver(&ops);
        let mut shuffled = ops.clone();
        // A deterministic shuffle from the seed.
        let mut rng = testkit::rng::XorShift64(seed | 1);
        for i in (1..shuffled.len()).rev() {
            shuffled.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
        }
        let (log, scene) = deliver(&shuffled);
        prop_assert_eq!(scene.scene_hash(), reference.scene_hash());
        let scratch = SScene::fold(&log);
        prop_assert_eq!(scratch.scene_hash(), scene.scene_hash());
        prop_assert!(scratch.scene() == scene.scene());
    }
}

#[test]
fn concurrent_writes_resolve_by_the_order_and_edits_all_apply() {
    let ops = concurrent_workload(2, 6);
    let (log, scene) = deliver(&ops);
    let object = scene
        .scene()
        .scene()
        .object(SceneObjectId(1))
        .expect("the ball exists");
    // The colour is the last colour write in the linear order.
    let last_color = log
        .entries()
        .filter(|e| e.active)
        .filter_map(|e| match e.op.payload() {
            ShapePayload::Set { field, .. } => match &**field {
                Field::Diffuse(c) => Some(c.clone()),
                _ => None,
            },
            _ => None,
        })
        .last()
        .unwrap();
    assert_eq!(object.data().appearance.diffuse, last_color);
    // Every active edit of both peers is in the history, in the order.
    let active_edits = log
        .entries()
        .filter(|e| e.active && matches!(e.op.payload(), ShapePayload::Edit { .. }))
        .count();
    assert_eq!(object.history().len(), active_edits);
    assert_eq!(scene.scene().edit_ops(1).len(), active_edits);
    assert!(active_edits >= 6, "both peers' edits apply");
}

/// Issue 50 with the object model's scene, where carves add up (so an edit applied twice or
/// not at all shows in the hash): a peer joined from a snapshot at any point of a concurrent
/// workload delivered out of order, then given the rest, ends with the full peer's scene.
#[test]
fn a_peer_joined_from_a_snapshot_at_any_point_folds_the_rest_as_a_full_peer() {
    use replication::snapshot::{Snapshot, verify};
    // Creation first (every op depends on it), then each peer's ops in turn, the last peer's
    // first: a peer's ops sort among those held before them.
    let ops = concurrent_workload(3, 10);
    let mut peers: Vec<&[VerifiedOp<ShapePayload>]> = ops[1..].chunks(10).collect();
    peers.reverse();
    let ops: Vec<_> = std::iter::once(&ops[0])
        .chain(peers.into_iter().flatten())
        .cloned()
        .collect();
    let (full_log, full_scene) = deliver(&ops);
    for k in (1..ops.len()).step_by(3) {
        let (prefix, prefix_scene) = deliver(&ops[..k]);
        assert_eq!(prefix.len(), k, "each peer's ops in order: nothing waits");
        let bytes = Snapshot::capture(&prefix, &prefix_scene).encode().unwrap();
        let (mut log, mut scene) = Snapshot::<ShapePayload>::decode(&bytes)
            .unwrap()
            .join::<ShapeScene>(SLog::default(), Timestamp(0))
            .unwrap();
        verify(&log, &log.session_id(), |_| {}).unwrap();
        // What the prefix parked (its deps later in the order) is not in the snapshot: sync
        // sends it again.
        let parked = ops[..k].iter().filter(|op| !prefix.contains(&op.id()));
        for op in parked.chain(&ops[k..]) {
            let ins = log.insert(Timestamp(0), op.clone(), Origin(1)).unwrap();
            scene.apply_insertion(&log, &ins);
        }
        assert_eq!(log.len(), full_log.len());
        assert_eq!(
            scene.scene_hash(),
            full_scene.scene_hash(),
            "joined after {k}"
        );
    }
}

#[test]
fn undo_then_redo_restores_the_scene_and_snapshots_round_trip() {
    let a = key(0);
    let mut log = SLog::default();
    let mut scene = SScene::fold(&log);
    let author = |log: &mut SLog, scene: &mut SScene, p: ShapePayload| {
        let (op, ins) = log.author(&a, Timestamp(10), p).unwrap();
        scene.apply_insertion(log, &ins);
        op.id()
    };
    author(
        &mut log,
        &mut scene,
        ShapePayload::Create {
            object: 1,
            counter: None,
            data: std::sync::Arc::new(sphere_data()),
            group: None,
        },
    );
    let edits: Vec<_> = (0..4)
        .map(|i| {
            author(
                &mut log,
                &mut scene,
                carve(DVec3::new(i as f64 * 0.3 - 0.45, 0.9, 0.0)),
            )
        })
        .collect();
    let before = scene.scene_hash();
    let mut sampler = scene
        .scene()
        .scene()
        .object(SceneObjectId(1))
        .unwrap()
        .sampler();
    assert!(
        sampler.value(DVec3::new(-0.45, 0.9, 0.0), 0.0) < 0.0,
        "carved"
    );
    for id in edits.iter().rev() {
        author(&mut log, &mut scene, ShapePayload::Undo(*id));
    }
    let undone = scene.scene_hash();
    assert_ne!(undone, before);
    let mut sampler = scene
        .scene()
        .scene()
        .object(SceneObjectId(1))
        .unwrap()
        .sampler();
    assert!(
        sampler.value(DVec3::new(-0.45, 0.85, 0.0), 0.0) > 0.0,
        "undone"
    );
    for id in &edits {
        author(&mut log, &mut scene, ShapePayload::Redo(*id));
    }
    assert_eq!(scene.scene_hash(), before, "undo n times then redo n times");
}

#[test]
fn a_weak_takeover_rejects_the_former_holders_edits() {
    let (a, b) = (key(0), key(1));
    let mut log = SLog::default();
    let create = ShapePayload::Create {
        object: 1,
        counter: None,
        data: std::sync::Arc::new(sphere_data()),
        group: None,
    };
    log.author(&a, Timestamp(1), create).unwrap();
    let acquire = |strong| {
        ShapePayload::Lease(LeaseAction::Acquire {
            object: 1,
            strong,
            ttl_micros: 60_000_000,
        })
    };
    log.author(&a, Timestamp(2), acquire(false)).unwrap();
    log.author(&b, Timestamp(3), acquire(false)).unwrap();
    let (late, _) = log
        .author(&a, Timestamp(4), carve(DVec3::new(0.0, 0.9, 0.0)))
        .unwrap();
    assert!(!log.is_active(&late.id()), "A lost the object to B");
    let rejected = log.rejected_by(&a.peer_id());
    assert_eq!(rejected.len(), 1);
    let scene = SScene::fold(&log);
    let object = scene.scene().scene().object(SceneObjectId(1)).unwrap();
    assert_eq!(
        object.history().len(),
        0,
        "the rejected edit is not in the scene"
    );
}

#[test]
fn payloads_are_small_and_hostile_bytes_are_refused() {
    let edit = carve(DVec3::new(0.1, 0.2, 0.3));
    let mut bytes = Vec::new();
    edit.encode(&mut bytes);
    assert!(bytes.len() < 200, "a carve is {} bytes", bytes.len());
    assert_eq!(ShapePayload::decode(&bytes).unwrap(), edit);
    let mut create = Vec::new();
    ShapePayload::Create {
        object: 1,
        counter: None,
        data: std::sync::Arc::new(sphere_data()),
        group: None,
    }
    .encode(&mut create);
    assert!(create.len() < 1024);
    for cut in 0..bytes.len() {
        assert!(ShapePayload::decode(&bytes[..cut]).is_err());
    }
    // A formula that does not compile is refused at decode, so it never reaches a fold.
    let mut bad = Vec::new();
    ShapePayload::Set {
        object: 1,
        field: Box::new(Field::Transparency(Some(Formula::new("1 +").unwrap()))),
    }
    .encode(&mut bad);
    assert!(ShapePayload::decode(&bad).is_err());
    // An edit that does not compile (a radius of NaN) is refused at decode: its encoding is a
    // valid edit's with the radius's eight bytes replaced.
    let radius = 0.123_456_789_f64;
    let valid = ShapePayload::edit(
        1,
        Edit::stamp(
            EditOp::Union,
            ToolShape::Sphere { radius },
            Pose::at(DVec3::ZERO),
        ),
    )
    .unwrap();
    let mut bad = Vec::new();
    valid.encode(&mut bad);
    assert!(ShapePayload::decode(&bad).is_ok());
    let at = bad
        .windows(8)
        .position(|w| w == radius.to_le_bytes())
        .expect("the radius in the encoding");
    bad[at..at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    assert!(ShapePayload::decode(&bad).is_err());
    let mut rng = 0x1234_5678u64;
    for _ in 0..2000 {
        let len = (rng % 64) as usize;
        let junk: Vec<u8> = (0..len)
            .map(|_| {
                rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1);
                (rng >> 33) as u8
            })
            .collect();
        let _ = ShapePayload::decode(&junk);
    }
}

/// Ops signed before objects held grids (version 1 of the object encoding) are still read,
/// verified and folded: a store or a peer from then loses nothing.
#[test]
fn ops_signed_before_grids_still_verify_and_fold() {
    let create = include_bytes!("../../tests/data/format-v1/create.bin");
    let set = include_bytes!("../../tests/data/format-v1/set.bin");
    let create =
        replication::Op::<ShapePayload>::decode_verified(create, &replication::op::UNNAMED_SESSION)
            .unwrap();
    let set =
        replication::Op::<ShapePayload>::decode_verified(set, &replication::op::UNNAMED_SESSION)
            .unwrap();
    assert_eq!(create.author(), Keypair::from_seed([9; 32]).peer_id());
    let ShapePayload::Create {
        object: 7, data, ..
    } = create.payload()
    else {
        panic!("{:?}", create.payload());
    };
    assert!(data.grids.is_empty());
    let mut log = SLog::default();
    // Received now (they were signed in 2023).
    let now = Timestamp(1_800_000_000_000_000);
    log.insert(now, create.clone(), Origin(1)).unwrap();
    log.insert(now, set, Origin(1)).unwrap();
    let scene = SScene::fold(&log);
    let object = scene.scene().scene().object(SceneObjectId(7)).unwrap();
    assert_eq!(object.data().name, "pot");
    assert!(object.data().physics.density.is_some());
    // The payload is canonical in version 1, though today's encoder writes other bytes.
    let encoded = create.encoded();
    let start = encoded.windows(4).position(|w| w == b"clay").unwrap() - 4;
    let payload = &encoded[start..encoded.len() - 64];
    assert_eq!(payload[0], model::object::codec::VERSION_1);
    assert!(create.payload().is_canonical(payload));
    let mut today = Vec::new();
    create.payload().encode(&mut today);
    assert_ne!(today, payload);
    assert!(!create.payload().is_canonical(&today[..today.len() - 1]));
    // The same payload with its name's length as an overlong varint is not canonical.
    let mut overlong = payload.to_vec();
    overlong[4] |= 0x80;
    overlong.insert(5, 0);
    assert!(!ShapePayload::decode(&overlong).is_ok_and(|p| p.is_canonical(&overlong)));
}

/// A ball as an icosphere mesh of 5,120 triangles: about 60 KB, four ops' worth.
fn mesh_ball(object: u64) -> ShapePayload {
    let mesh = model::mesh::shapes::icosphere(1.0, 4);
    ShapePayload::Create {
        object,
        counter: None,
        data: std::sync::Arc::new(ObjectData {
            name: "mesh ball".into(),
            geometry: Some(Geometry {
                shape: Shape::Mesh(Arc::new(mesh)),
                ..Geometry::implicit_in(
                    Formula::new("0").unwrap(),
                    Domain::new(DVec3::ZERO, DVec3::splat(2.5)),
                )
            }),
            ..ObjectData::default()
        }),
        group: None,
    }
}

fn object_data(scene: &SScene, object: u64) -> Option<ObjectData> {
    let o = scene.scene().scene().object(SceneObjectId(object))?;
    Some(o.data().clone())
}

#[test]
fn a_change_larger_than_an_op_is_authored_in_parts_and_folds_whole_in_any_order() {
    let whole = mesh_ball(1);
    let ShapePayload::Create { data, .. } = &whole else {
        unreachable!()
    };
    let expected = (**data).clone();
    let ops = parts::split(whole).unwrap();
    assert!(ops.len() >= 4, "{} ops", ops.len());
    let mut author = SLog::default();
    let mut signed = Vec::new();
    for (i, payload) in ops.into_iter().enumerate() {
        let mut bytes = Vec::new();
        payload.encode(&mut bytes);
        assert!(bytes.len() <= MAX_PAYLOAD_BYTES, "op {i}: {}", bytes.len());
        assert_eq!(ShapePayload::decode(&bytes).unwrap(), payload);
        let (op, _) = author.author(&key(0), Timestamp(10), payload).unwrap();
        signed.push(op);
    }
    // A carve by another peer that saw the mesh, and a concurrent colour that did not: it
    // sorts before the assembly on some peers' logs for a while, so objects refold.
    let (carve_op, _) = author
        .clone()
        .author(&key(1), Timestamp(20), carve(DVec3::new(0.0, 1.0, 0.0)))
        .unwrap();
    let (colour_op, _) = SLog::default()
        .author(&key(2), Timestamp(5), color([0.9, 0.1, 0.1]))
        .unwrap();
    signed.push(carve_op);
    signed.push(colour_op);

    let (_, reference) = deliver(&signed);
    let folded = object_data(&reference, 1).expect("the object is made");
    assert_eq!(folded.geometry, expected.geometry);
    assert_eq!(folded.name, expected.name);
    let mut sampler = reference
        .scene()
        .scene()
        .object(SceneObjectId(1))
        .unwrap()
        .sampler();
    assert!(sampler.value(DVec3::ZERO, 0.0) > 0.5, "inside the mesh");
    assert!(
        sampler.value(DVec3::new(0.0, 0.95, 0.0), 0.0) < 0.0,
        "carved after assembly"
    );
    let scratch = SScene::fold(&deliver(&signed).0);
    assert_eq!(scratch.scene_hash(), reference.scene_hash());

    // Reversed and rotated deliveries wait for the causal past and end the same.
    for rotation in [0, 3, signed.len() / 2] {
        let mut order: Vec<_> = signed.iter().rev().cloned().collect();
        order.rotate_left(rotation);
        let (log, scene) = deliver(&order);
        assert_eq!(log.len(), signed.len());
        assert_eq!(
            scene.scene_hash(),
            reference.scene_hash(),
            "rotation {rotation}"
        );
    }

    // Parts held before their assembly are part of the scene's state, so its hash.
    let (half, _) = deliver(&signed[..3]);
    let held = SScene::fold(&half);
    assert!(
        object_data(&held, 1).is_none(),
        "not made before its assembly"
    );
    assert_ne!(
        held.scene_hash(),
        SScene::fold(&SLog::default()).scene_hash(),
        "held parts are part of the scene's state"
    );
}

#[test]
fn an_assembly_without_its_parts_or_of_something_else_changes_nothing() {
    let ops = parts::split(mesh_ball(1)).unwrap();
    let (last, pieces) = ops.split_last().unwrap();
    let ShapePayload::Assemble { parts: hashes, .. } = last else {
        panic!("{last:?}")
    };
    let scene_of = |payloads: Vec<ShapePayload>| {
        let mut log = SLog::default();
        let mut scene = SScene::fold(&log);
        for p in payloads {
            let (_, ins) = log.author(&key(0), Timestamp(10), p).unwrap();
            scene.apply_insertion(&log, &ins);
        }
        scene
    };
    let assemble = |object, parts: Vec<[u8; 32]>| ShapePayload::Assemble { object, parts };

    // One part missing.
    let mut missing = pieces.to_vec();
    missing.remove(2);
    missing.push(last.clone());
    assert!(object_data(&scene_of(missing), 1).is_none());

    // Another object's parts.
    let mut elsewhere = pieces.to_vec();
    elsewhere.push(assemble(2, hashes.clone()));
    let scene = scene_of(elsewhere);
    assert!(object_data(&scene, 1).is_none() && object_data(&scene, 2).is_none());

    // Parts in the wrong order do not decode; then they are consumed, and the right
    // assembly after them finds nothing.
    let mut reversed = pieces.to_vec();
    reversed.push(assemble(1, hashes.iter().rev().copied().collect()));
    reversed.push(last.clone());
    assert!(object_data(&scene_of(reversed), 1).is_none());

    // A second assembly of parts already consumed makes nothing again.
    let mut twice = ops.clone();
    twice.push(ShapePayload::Delete { object: 1 });
    twice.push(last.clone());
    assert!(object_data(&scene_of(twice), 1).is_none());

    // Parts that encode something other than a creation or a property of the object.
    for inner in [
        ShapePayload::Chat("x".repeat(MAX_PAYLOAD_BYTES)),
        carve(DVec3::ZERO),
        ShapePayload::Set {
            object: 2,
            field: Box::new(Field::Name("other".into())),
        },
    ] {
        let mut bytes = Vec::new();
        inner.encode(&mut bytes);
        let mut payloads = Vec::new();
        let mut hashes = Vec::new();
        for piece in bytes.chunks(1000) {
            hashes.push(parts::part_hash(piece));
            payloads.push(ShapePayload::Part {
                object: 1,
                bytes: piece.to_vec(),
            });
        }
        payloads.splice(0..0, ops.iter().cloned());
        payloads.push(assemble(1, hashes));
        let scene = scene_of(payloads);
        let data = object_data(&scene, 1).unwrap();
        assert_eq!(data.name, "mesh ball", "{inner:?} changed nothing");
    }

    // Decoding refuses empty parts and assemblies of no or too many parts.
    for bad in [
        ShapePayload::Part {
            object: 1,
            bytes: Vec::new(),
        },
        assemble(1, Vec::new()),
        assemble(1, vec![[0; 32]; parts::MAX_PARTS + 1]),
    ] {
        let mut bytes = Vec::new();
        bad.encode(&mut bytes);
        assert!(ShapePayload::decode(&bytes).is_err(), "{bad:?}");
    }

    // Splitting: too large for parts, and kinds that are never split.
    let too_big = ShapePayload::Chat("x".repeat(MAX_PAYLOAD_BYTES));
    assert!(matches!(
        parts::split(too_big),
        Err(parts::SplitError::NotSplittable { .. })
    ));
    let small = color([0.1, 0.2, 0.3]);
    assert_eq!(parts::split(small.clone()).unwrap(), vec![small]);
}

/// A member who knows the id an honest peer is about to use cannot create the object first:
/// ids derive from their author's key and counter, and no other author's `Create` makes it,
/// however early it sorts, with or without a counter, whole or in parts.
#[test]
fn a_member_cannot_take_an_object_id_another_peer_is_about_to_use() {
    let (honest, member) = (key(0), key(1));
    let ids = IdSource::first(honest.peer_id());
    let target = ids.id();
    let stolen = || ObjectData {
        name: "stolen".into(),
        ..sphere_data()
    };
    // The member's ops, authored before anything of the honest peer's: Lamport 1 onwards, so
    // each sorts before the honest creation below.
    let mut bogus = vec![
        ShapePayload::Create {
            object: target,
            counter: None,
            data: std::sync::Arc::new(stolen()),
            group: None,
        },
        ShapePayload::Create {
            object: target,
            counter: Some(ids.counter),
            data: std::sync::Arc::new(stolen()),
            group: None,
        },
    ];
    let ShapePayload::Create { data: big, .. } = mesh_ball(target) else {
        unreachable!()
    };
    bogus.extend(
        parts::split(ShapePayload::Create {
            object: target,
            counter: Some(7),
            data: big,
            group: None,
        })
        .unwrap(),
    );
    let mut member_log = SLog::default();
    let member_ops: Vec<_> = bogus
        .into_iter()
        .map(|p| member_log.author(&member, Timestamp(1), p).unwrap().0)
        .collect();
    // The honest peer chats first, so its creation has a later Lamport time than all of them.
    let mut honest_log = SLog::default();
    let mut honest_ops = vec![
        honest_log
            .author(&honest, Timestamp(5), ShapePayload::Chat("hi".into()))
            .unwrap()
            .0,
    ];
    honest_ops.push(
        honest_log
            .author(&honest, Timestamp(6), ids.create(sphere_data(), None))
            .unwrap()
            .0,
    );
    for ops in [
        [member_ops.clone(), honest_ops.clone()].concat(),
        [honest_ops.clone(), member_ops.clone()].concat(),
    ] {
        let (log, scene) = deliver(&ops);
        let first_create = log
            .entries()
            .position(|e| matches!(e.op.payload(), ShapePayload::Create { .. }));
        assert_eq!(first_create, Some(0), "the member's creation sorts first");
        let object = object_data(&scene, target).expect("the honest creation makes it");
        assert_eq!(object.name, "ball");
        assert!(!matches!(object.geometry.unwrap().shape, Shape::Mesh(_)));
    }

    // Without the honest creation, none of the member's makes the object.
    let (_, scene) = deliver(&member_ops);
    assert!(object_data(&scene, target).is_none());

    // The member's own ids work: with its counter, or (as ops signed before ids were derived
    // do) without a counter outside the derived ids.
    let own = IdSource::first(member.peer_id());
    assert!(!may_create(member.peer_id(), target, Some(1)));
    assert!(!may_create(member.peer_id(), target, None));
    assert!(may_create(member.peer_id(), own.id(), Some(1)));
    assert!(may_create(member.peer_id(), 7, None));
    let (mine, _) = member_log
        .author(&member, Timestamp(9), own.create(stolen(), None))
        .unwrap();
    let (_, scene) = deliver(&[member_ops, vec![mine]].concat());
    assert_eq!(object_data(&scene, own.id()).unwrap().name, "stolen");
}

/// A member who predicts the ids an honest peer will use next cannot lease them first: an
/// acquire counts only once its object's creation (a `Create`, or the first part of one
/// authored in parts, that may make the id) is in its causal past, so the honest creations,
/// which saw the strong acquires, make their objects and edit them.
#[test]
fn strong_acquires_of_predicted_ids_do_not_reject_the_creations() {
    let (honest, member) = (key(0), key(1));
    let mut log = SLog::default();
    log.author(&honest, Timestamp(1), ShapePayload::Chat("hi".into()))
        .unwrap();
    let next = IdSource::next_in(&log, honest.peer_id());
    let predicted: Vec<u64> = (0..3).map(|n| next.skip(n).unwrap().id()).collect();
    for &object in &predicted {
        let hoard = ShapePayload::Lease(LeaseAction::Acquire {
            object,
            strong: true,
            ttl_micros: u64::MAX,
        });
        log.author(&member, Timestamp(2), hoard).unwrap();
    }
    // The first two whole, the third in parts (a mesh): every op sees every acquire.
    let mut ids = next;
    let mut honest_ops = Vec::new();
    for (i, &object) in predicted.iter().enumerate() {
        assert_eq!(ids.id(), object);
        let change = if i < 2 {
            vec![ids.create(sphere_data(), None)]
        } else {
            let ShapePayload::Create { data, .. } = mesh_ball(object) else {
                unreachable!()
            };
            parts::split(ShapePayload::Create {
                object,
                counter: Some(ids.counter),
                data,
                group: None,
            })
            .unwrap()
        };
        for payload in change {
            honest_ops.push(log.author(&honest, Timestamp(3), payload).unwrap().0);
        }
        honest_ops.push(
            log.author(&honest, Timestamp(4), carve_at(object, DVec3::ZERO))
                .unwrap()
                .0,
        );
        ids = ids.skip(1).unwrap();
    }
    assert!(honest_ops.iter().all(|op| log.is_active(&op.id())));
    let scene = SScene::fold(&log);
    for object in predicted.iter().copied() {
        assert!(object_data(&scene, object).is_some(), "object {object}");
    }
    // An acquire that saw a creation counts: the member takes the first object, and binds the
    // edits that see it.
    let take = ShapePayload::Lease(LeaseAction::Acquire {
        object: predicted[2],
        strong: true,
        ttl_micros: 60_000_000,
    });
    log.author(&member, Timestamp(5), take).unwrap();
    let (bound, _) = log
        .author(&honest, Timestamp(6), carve_at(predicted[2], DVec3::ZERO))
        .unwrap();
    assert!(!log.is_active(&bound.id()));
    // The first part creates for its author only, and the later parts for nobody.
    let mut parts =
        (honest_ops.iter()).filter(|op| matches!(op.payload(), ShapePayload::Part { .. }));
    let first_part = parts.next().unwrap();
    assert!(first_part.payload().creates(&honest.peer_id()));
    assert!(!first_part.payload().creates(&member.peer_id()));
    assert!(parts.all(|op| !op.payload().creates(&honest.peer_id())));
}

/// Derived ids: the derived bit set, the group bit clear, one per author and counter, and a
/// `Create` with a counter encodes after every older variant, so ops signed before still
/// decode to what they said.
#[test]
fn derived_ids_are_distinct_and_older_creations_decode_as_before() {
    let mut seen = std::collections::BTreeSet::new();
    for i in 0..8 {
        let author = key(i).peer_id();
        for counter in [0, 1, 2, 1000, u32::MAX] {
            let id = object_id(author, counter);
            assert_eq!(id & (DERIVED_ID_BIT | 1 << 63), DERIVED_ID_BIT);
            assert!(seen.insert(id), "{id:#x} twice");
        }
    }
    let older = ShapePayload::Create {
        object: 7,
        counter: None,
        data: std::sync::Arc::new(sphere_data()),
        group: None,
    };
    let mut bytes = Vec::new();
    older.encode(&mut bytes);
    assert_eq!(
        bytes[1], 0,
        "a counterless creation is variant 0, as before"
    );
    assert_eq!(ShapePayload::decode(&bytes).unwrap(), older);
    let derived = IdSource::first(key(0).peer_id()).create(sphere_data(), Some(3));
    bytes.clear();
    derived.encode(&mut bytes);
    assert_eq!(bytes[1], 13, "after every older variant");
    let back = ShapePayload::decode(&bytes).unwrap();
    assert!(back.is_canonical(&bytes));
    assert_eq!(back, derived);
}

/// Where an author's next ids start: past its highest counter, and past the ids its parts,
/// assemblies and groups use; counterless creations and another author's ops do not count.
#[test]
fn the_next_ids_skip_every_id_the_author_used() {
    let (me, other) = (key(0), key(1));
    let first = IdSource::first(me.peer_id());
    let mut log = SLog::default();
    assert_eq!(IdSource::next_in(&log, me.peer_id()), first);
    let at = |k: u64| first.skip(k).unwrap();
    let ShapePayload::Create { data: big, .. } = mesh_ball(0) else {
        unreachable!()
    };
    let mut payloads = vec![
        at(0).create(sphere_data(), None),
        ShapePayload::Create {
            object: 5,
            counter: None,
            data: std::sync::Arc::new(sphere_data()),
            group: None,
        },
    ];
    // An object in parts at counter 2, then a group at counter 3.
    payloads.extend(parts::split(at(1).create(ObjectData::clone(&big), None)).unwrap());
    payloads.push(ShapePayload::SetGroup {
        group: at(2).id(),
        value: None,
    });
    for p in payloads {
        log.author(&me, Timestamp(1), p).unwrap();
    }
    // Another author's creation under my next id (which makes nothing) does not move mine.
    log.author(&other, Timestamp(2), at(3).create(sphere_data(), None))
        .unwrap();
    assert_eq!(IdSource::next_in(&log, me.peer_id()), at(3));
}

/// Issue 17 item 6: a received sculpting edit is compiled once, at decode; folding it, and
/// folding its object again after a backdated op lands before it, compiles nothing more.
#[test]
fn a_received_edit_is_compiled_once_from_its_bytes_to_the_scene() {
    use model::object::compiled::n_edits_compiled_on_this_thread;
    let (a, b) = (key(0), key(1));
    let mut author = SLog::default();
    let ids = IdSource::first(a.peer_id());
    let (create, _) = author
        .author(&a, Timestamp(10), ids.create(sphere_data(), None))
        .unwrap();
    let object = ids.id();
    let stroke = Edit::stroke(
        EditOp::Subtract,
        ToolShape::Sphere { radius: 0.1 },
        (0..20)
            .map(|i| Pose::at(DVec3::new(0.05 * f64::from(i), 0.5, 0.0)))
            .collect(),
    );
    let (edit, _) = author
        .author(
            &a,
            Timestamp(20),
            ShapePayload::edit(object, stroke).unwrap(),
        )
        .unwrap();
    let bytes: Vec<Vec<u8>> = [&create, &edit]
        .iter()
        .map(|op| op.encoded().to_vec())
        .collect();
    // Another member's backdated colour, sorted before the edit: its object refolds.
    let mut other = SLog::default();
    let backdated = ShapePayload::Set {
        object,
        field: Box::new(Field::Diffuse(Some(ColorDef::Constant([1.0, 0.0, 0.0])))),
    };
    other
        .insert(Timestamp(10), create.clone(), Origin(1))
        .unwrap();
    let (late, _) = other.author(&b, Timestamp(15), backdated).unwrap();
    let before = n_edits_compiled_on_this_thread();
    let mut log = SLog::default();
    let mut scene = SScene::fold(&log);
    for bytes in &bytes {
        let op = replication::Op::<ShapePayload>::decode_verified(
            bytes,
            &replication::op::UNNAMED_SESSION,
        )
        .unwrap();
        let ins = log.insert(Timestamp(30), op, Origin(1)).unwrap();
        scene.apply_insertion(&log, &ins);
    }
    assert_eq!(
        n_edits_compiled_on_this_thread(),
        before + 1,
        "at decode only"
    );
    let ins = log.insert(Timestamp(30), late, Origin(2)).unwrap();
    scene.apply_insertion(&log, &ins);
    assert!(scene.stats().n_object_refolds >= 1, "{:?}", scene.stats());
    assert_eq!(
        n_edits_compiled_on_this_thread(),
        before + 1,
        "not at the refold"
    );
    let folded = scene.scene().scene().object(SceneObjectId(object)).unwrap();
    assert_eq!(folded.history().len(), 1);
}

/// A created object's description (about 0.5 KB before its formulas) is held once: the scene's
/// object shares the op's, through the fold and a refold, until a `Set` changes it, and then
/// still shares the parts the `Set` left alone.
#[test]
fn a_created_object_shares_its_description_with_the_op() {
    let a = key(0);
    let ids = IdSource::first(a.peer_id());
    let object = ids.id();
    let mut log = SLog::default();
    let mut scene = SScene::fold(&log);
    let (create, ins) = log
        .author(&a, Timestamp(10), ids.create(sphere_data(), None))
        .unwrap();
    scene.apply_insertion(&log, &ins);
    let ShapePayload::Create { data, .. } = create.op().payload() else {
        unreachable!("authored a creation")
    };
    let held = |scene: &SScene| {
        let o = scene.scene().scene().object(SceneObjectId(object)).unwrap();
        Arc::clone(o.shared_data())
    };
    assert!(Arc::ptr_eq(&held(&scene), data), "folded");
    let (_, ins) = log
        .author(
            &a,
            Timestamp(20),
            carve_at(object, DVec3::new(0.5, 0.0, 0.0)),
        )
        .unwrap();
    scene.apply_insertion(&log, &ins);
    assert!(Arc::ptr_eq(&held(&scene), data), "after an edit");
    assert!(
        Arc::ptr_eq(&held(&SScene::fold(&log)), data),
        "folded from scratch"
    );
    let colour = ShapePayload::Set {
        object,
        field: Box::new(Field::Diffuse(Some(ColorDef::Constant([1.0, 0.0, 0.0])))),
    };
    let (_, ins) = log.author(&a, Timestamp(30), colour).unwrap();
    scene.apply_insertion(&log, &ins);
    let changed = held(&scene);
    assert!(!Arc::ptr_eq(&changed, data), "a set makes its own");
    assert!(changed.appearance.diffuse.is_some());
    assert!(
        Shared::ptr_eq(&changed.physics, &data.physics),
        "a colour leaves the physics shared"
    );
    assert!(
        !Shared::ptr_eq(&changed.appearance, &data.appearance),
        "and copies the appearance it changes"
    );
    assert!(
        data.appearance.diffuse.is_none(),
        "the op's description is untouched"
    );
}
