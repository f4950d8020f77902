//! Unit tests of the engine: a store directory opened, reloaded and refused as it should be,
//! undo and redo targets, and two engines on loopback whose changes and presence travel.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::Duration;

use model::object::{Field, Formula, Geometry, Shape};
use rand_core::SeedableRng;
use replication::Timestamp;
use replication::sync::message::PROTOCOL_VERSION;

use super::*;

const T0: Timestamp = Timestamp(1_795_355_107_000_000);

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("sculpt-engine-{}-{name}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    dir
}

fn config(store: &Path) -> EngineConfig {
    EngineConfig {
        demo: crate::demos::find(crate::demos::DEFAULT_DEMO).ok(),
        memory_fallback: true,
        ..EngineConfig::on_loopback(store)
    }
}

fn set_shape(object: u64, formula: &str) -> ShapePayload {
    ShapePayload::Set {
        object,
        field: Box::new(Field::Geometry(Some(Box::new(Geometry::implicit(
            Formula::new(formula).unwrap(),
        ))))),
    }
}

fn only_object(engine: &Engine) -> u64 {
    let view = lock(engine.view());
    let ids: Vec<u64> = view.scene().objects().map(|(id, _)| id.0).collect();
    assert_eq!(ids.len(), 1, "{ids:?}");
    ids[0]
}

fn geometry_formula(engine: &Engine, object: u64) -> String {
    let view = lock(engine.view());
    let o = view.scene().object(model::scene::ObjectId(object)).unwrap();
    match &o.data().geometry.as_ref().unwrap().shape {
        Shape::Implicit(f) => f.as_str().to_string(),
        other => panic!("{other:?}"),
    }
}

fn author(engine: &Engine, payload: ShapePayload) -> OpId {
    engine.author(payload).unwrap().wait().unwrap()
}

/// A peer called `name`, stored in `dir`, that joins `a`'s session by dialing it (the demo it
/// would author only in a new session).
fn joiner(a: &Engine, dir: &Path, name: &str) -> EngineConfig {
    let addr = lock(a.view()).listen_addr().unwrap();
    EngineConfig {
        invite: Some(a.invite().clone()),
        network: Network {
            dial: vec![addr],
            ..config(dir).network
        },
        name: Some(name.into()),
        ..config(dir)
    }
}

/// Ops a new session holds before its demo: the founder's admission of itself.
const FOUNDED: usize = 1;

/// Waits (at most 20 s) until `done` holds for the view.
fn wait_view(engine: &Engine, what: &str, done: impl Fn(&mut View) -> bool) {
    let deadline = crate::clock::now().instant + Duration::from_secs(20);
    while !done(&mut lock(engine.view())) {
        assert!(
            crate::clock::now().instant < deadline,
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn a_new_store_gets_the_demo_once_and_a_reopened_one_shows_the_same_scene() {
    let dir = scratch("reopen");
    let first = Engine::start(config(&dir), T0).unwrap();
    assert_eq!(lock(first.view()).store_error(), None);
    assert_eq!(lock(first.view()).n_loaded(), 0);
    wait_view(&first, "the demo", |v| v.n_ops() == FOUNDED + 1);
    let melon = only_object(&first);
    assert_eq!(lock(first.view()).object_label(melon), "Watermelon");
    let (id, hash, invite) = (
        first.peer_id(),
        lock(first.view()).scene_hash_hex(),
        first.invite().clone(),
    );
    first.shutdown();

    let second = Engine::start(config(&dir), T0).unwrap();
    assert_eq!(lock(second.view()).n_loaded(), FOUNDED + 1);
    assert_eq!(second.peer_id(), id, "the identity key is kept");
    assert_eq!(second.invite(), &invite, "the session is kept");
    assert_eq!(lock(second.view()).scene_hash_hex(), hash);
    author(&second, set_shape(melon, "1-x^2-y^2-z^2"));
    author(&second, ShapePayload::Chat("hello".into()));
    // A payload that does not validate is answered at once and authors nothing.
    let long = ShapePayload::Chat("x".repeat(1 << 20));
    assert!(second.author(long).unwrap().wait().is_err());
    second.shutdown();

    let third = Engine::start(config(&dir), T0).unwrap();
    let view = lock(third.view());
    assert_eq!(view.n_loaded(), FOUNDED + 3);
    assert_eq!(view.chat().len(), 1);
    assert_eq!(view.chat()[0].text, "hello");
    assert_eq!(view.chat()[0].author, id.short());
    let history = view.history();
    assert_eq!(history.len(), FOUNDED + 3);
    assert_eq!(history[0].what, "founded the session");
    assert!(
        history[FOUNDED + 1].what.contains("1-x^2-y^2-z^2"),
        "{history:?}"
    );
    assert!(history.iter().all(|h| h.status == "effective" && h.mine));
    drop(view);
    assert_eq!(geometry_formula(&third, melon), "1-x^2-y^2-z^2");
    drop(third);
    let _ = fs::remove_dir_all(&dir);
}

/// The view's objects hold their edits indexed after every batch it folds, on start and as
/// ops arrive: the mesher's, the servo's and picking's copies share that index, where each
/// would otherwise index the whole history again.
#[test]
fn the_views_objects_keep_their_edits_indexed() {
    use model::object::history::MAX_TAIL;
    use model::object::{Edit, EditOp, Pose, ToolShape};
    let dir = scratch("indexed");
    let tail = |s: &Engine, melon: u64| {
        let view = lock(s.view());
        let o = view.scene().object(model::scene::ObjectId(melon)).unwrap();
        (o.history().len(), o.history().tail_len())
    };
    let n_edits = 2 * MAX_TAIL + 3;
    let first = Engine::start(config(&dir), T0).unwrap();
    wait_view(&first, "the demo", |v| v.n_ops() == FOUNDED + 1);
    let melon = only_object(&first);
    for k in 0..n_edits {
        let at = glam::DVec3::new(0.01 * k as f64, 0.0, 1.0);
        let carve = Edit::stamp(
            EditOp::Subtract,
            ToolShape::Sphere { radius: 0.1 },
            Pose::at(at),
        );
        author(&first, ShapePayload::edit(melon, carve).unwrap());
    }
    let (len, unindexed) = tail(&first, melon);
    assert!(
        len >= n_edits && unindexed <= MAX_TAIL,
        "{unindexed} of {len}"
    );
    first.shutdown();
    let second = Engine::start(config(&dir), T0).unwrap();
    let (len, unindexed) = tail(&second, melon);
    assert!(
        len >= n_edits && unindexed == 0,
        "reopened: {unindexed} of {len}"
    );
    drop(second);
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn undo_and_redo_pick_this_peers_latest_edit_of_the_object() {
    let dir = scratch("undo");
    let s = Engine::start(config(&dir), T0).unwrap();
    wait_view(&s, "the demo", |v| v.n_ops() == FOUNDED + 1);
    let melon = only_object(&s);
    let original = geometry_formula(&s, melon);
    let a = author(&s, set_shape(melon, "1-x^2-y^2-z^2"));
    let b = author(&s, set_shape(melon, "0.5-abs(x)"));
    let targets = |s: &Engine| {
        let v = lock(s.view());
        (v.undo_target(melon), v.redo_target(melon))
    };
    assert_eq!(targets(&s), (Some(b), None));
    author(&s, ShapePayload::Undo(b));
    assert_eq!(geometry_formula(&s, melon), "1-x^2-y^2-z^2");
    assert_eq!(targets(&s), (Some(a), Some(b)));
    author(&s, ShapePayload::Undo(a));
    assert_eq!(geometry_formula(&s, melon), original);
    assert_eq!(targets(&s).1, Some(a), "the latest undo is redone first");
    author(&s, ShapePayload::Redo(a));
    assert_eq!(targets(&s).1, Some(b));
    assert_eq!(geometry_formula(&s, melon), "1-x^2-y^2-z^2");
    let view = lock(s.view());
    let statuses: Vec<&str> = view.history().iter().map(|h| h.status.as_str()).collect();
    assert_eq!(statuses[FOUNDED + 1], "effective");
    assert_eq!(statuses[FOUNDED + 2], "undone");
    let fresh = view.next_object().id();
    assert!(fresh != melon && view.scene().object(model::scene::ObjectId(fresh)).is_none());
    drop(view);
    drop(s);
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn a_corrupt_store_is_reported_and_left_byte_for_byte() {
    let dir = scratch("corrupt");
    fs::create_dir_all(&dir).unwrap();
    let ops = dir.join(store::OPS_FILE);
    let garbage = b"this is not a sculpt op store at all".to_vec();
    fs::write(&ops, &garbage).unwrap();
    let s = Engine::start(config(&dir), T0).unwrap();
    let error = lock(s.view()).store_error().unwrap().to_string();
    assert!(error.contains("cannot be opened"), "{error}");
    assert!(error.contains(store::OPS_FILE), "{error}");
    // The window still shows the demo, in memory; the file is as it was.
    wait_view(&s, "the demo in memory", |v| v.scene().len() == 1);
    drop(s);
    assert_eq!(fs::read(&ops).unwrap(), garbage);
    // A headless peer refuses to run on it instead.
    let strict = EngineConfig {
        memory_fallback: false,
        ..config(&dir)
    };
    assert!(matches!(
        Engine::start(strict, T0),
        Err(StartError::Store(store::StoreError::Open(_)))
    ));
    assert_eq!(fs::read(&ops).unwrap(), garbage);
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn a_torn_tail_is_cut_and_its_bytes_are_kept_aside() {
    let dir = scratch("torn");
    let first = Engine::start(config(&dir), T0).unwrap();
    wait_view(&first, "the demo", |v| v.n_ops() == FOUNDED + 1);
    first.shutdown();
    let ops = dir.join(store::OPS_FILE);
    let mut bytes = fs::read(&ops).unwrap();
    let tail = [200, 0, 0, 0, 1, 2, 3];
    bytes.extend_from_slice(&tail);
    fs::write(&ops, &bytes).unwrap();
    let s = Engine::start(config(&dir), T0).unwrap();
    let view = lock(s.view());
    assert_eq!(view.store_error(), None);
    assert_eq!(view.n_loaded(), FOUNDED + 1);
    let notice = view.notices()[0].clone();
    drop(view);
    assert!(notice.contains("7 bytes"), "{notice}");
    let kept: Vec<PathBuf> = fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.to_string_lossy().contains(".torn-"))
        .collect();
    assert_eq!(kept.len(), 1, "{kept:?}");
    assert_eq!(fs::read(&kept[0]).unwrap(), tail);
    assert!(notice.contains(&kept[0].display().to_string()), "{notice}");
    drop(s);
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn a_bad_key_another_sessions_store_or_an_unusable_directory_is_refused_not_replaced() {
    let dir = scratch("badkey");
    fs::create_dir_all(&dir).unwrap();
    fs::write(dir.join(store::KEY_FILE), b"short").unwrap();
    let s = Engine::start(config(&dir), T0).unwrap();
    let error = lock(s.view()).store_error().unwrap().to_string();
    assert!(error.contains("5 bytes"), "{error}");
    drop(s);
    assert_eq!(fs::read(dir.join(store::KEY_FILE)).unwrap(), b"short");

    let file = dir.join("plain-file");
    fs::write(&file, b"x").unwrap();
    let s = Engine::start(config(&file.join("store")), T0).unwrap();
    let error = lock(s.view()).store_error().unwrap().to_string();
    assert!(error.contains("cannot create"), "{error}");
    wait_view(&s, "the demo in memory", |v| v.scene().len() == 1);
    drop(s);

    let mine = scratch("session-a");
    let a = Engine::start(config(&mine), T0).unwrap();
    let stored = a.invite().clone();
    a.shutdown();
    let other = replication::net::invite::Invite::generate(&mut store::entropy_rng().unwrap());
    let join = EngineConfig {
        invite: Some(other),
        memory_fallback: false,
        ..config(&mine)
    };
    let refused = Engine::start(join, T0).err().unwrap().to_string();
    assert!(refused.contains("another session"), "{refused}");
    let text = fs::read_to_string(mine.join(store::INVITE_FILE)).unwrap();
    assert_eq!(text.trim(), stored.to_string());
    let _ = fs::remove_dir_all(&dir);
    let _ = fs::remove_dir_all(&mine);
}

#[cfg(unix)]
#[test]
fn secrets_are_private_and_a_second_engine_on_a_store_is_refused() {
    use std::os::unix::fs::PermissionsExt as _;
    let dir = scratch("private");
    let first = Engine::start(config(&dir), T0).unwrap();
    let mode = |p: &Path| fs::metadata(p).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode(&dir), 0o700);
    assert_eq!(mode(&dir.join(store::KEY_FILE)), 0o600);
    assert_eq!(mode(&dir.join(store::INVITE_FILE)), 0o600);
    let strict = EngineConfig {
        memory_fallback: false,
        ..config(&dir)
    };
    let refused = Engine::start(strict, T0).err().unwrap().to_string();
    assert!(
        refused.contains(&std::process::id().to_string()),
        "{refused}"
    );
    drop(first);
    let _ = fs::remove_dir_all(&dir);
}

/// A locked store's refusal names the store and its holder once, however it is shown (the
/// CLI prints the error with its causes), and the window's fallback in memory says so.
#[test]
fn a_locked_store_says_so_once_and_the_fallback_works_in_memory() {
    let dir = scratch("locked");
    let first = Engine::start(config(&dir), T0).unwrap();
    let strict = EngineConfig {
        memory_fallback: false,
        ..config(&dir)
    };
    let refused = Engine::start(strict, T0).err().unwrap();
    let shown = format!("{:#}", anyhow::Error::from(refused));
    assert_eq!(
        shown.matches("in use by another sculpt process").count(),
        1,
        "{shown}"
    );
    assert_eq!(shown.matches(store::OPS_FILE).count(), 1, "{shown}");
    let holder = format!("pid {}", std::process::id());
    assert_eq!(shown.matches(&holder).count(), 1, "{shown}");
    let fallback = Engine::start(config(&dir), T0).unwrap();
    let view = lock(fallback.view());
    let error = view.store_error().unwrap();
    assert_eq!(
        error.matches("in use by another sculpt process").count(),
        1,
        "{error}"
    );
    assert_eq!(
        error.matches("store").count(),
        2,
        "the store's path and `stored`: {error}"
    );
    assert_eq!(
        view.opening_status(),
        "in memory, the store cannot be used: the demo scene was authored"
    );
    drop(view);
    drop(fallback);
    drop(first);
    let _ = fs::remove_dir_all(&dir);
}

/// The window's first status line says what starting did: the demo authored in a new
/// session, a session joined by invite (no demo of ours authored into it, in memory too),
/// or the ops loaded.
#[test]
fn the_opening_status_says_whether_the_demo_was_authored_or_a_session_joined() {
    let dir = scratch("opening");
    let first = Engine::start(config(&dir), T0).unwrap();
    assert_eq!(
        lock(first.view()).opening_status(),
        "new store: the demo scene was authored"
    );
    wait_view(&first, "the demo", |v| v.n_ops() == FOUNDED + 1);
    let invite = first.invite().clone();
    first.shutdown();
    let again = Engine::start(config(&dir), T0).unwrap();
    assert_eq!(
        lock(again.view()).opening_status(),
        format!("loaded {} ops from the store", FOUNDED + 1)
    );

    // Joining: a new store of its own, then the same store while `again` holds it.
    let joined_dir = scratch("opening-joined");
    for store in [&joined_dir, &dir] {
        let joining = EngineConfig {
            invite: Some(invite.clone()),
            ..config(store)
        };
        let joined = Engine::start(joining, T0).unwrap();
        std::thread::sleep(Duration::from_millis(300));
        let view = lock(joined.view());
        let status = view.opening_status();
        assert!(
            status.ends_with("joined the session; its objects come from its peers"),
            "{status}"
        );
        assert!(!status.contains("demo"), "{status}");
        assert_eq!(view.n_ops(), 0, "no demo was authored into the session");
        drop(view);
        joined.shutdown();
    }
    drop(again);
    let _ = fs::remove_dir_all(&dir);
    let _ = fs::remove_dir_all(&joined_dir);
}

#[test]
fn a_new_session_is_founded_by_its_maker_and_a_joiner_is_not_its_founder() {
    use std::os::unix::fs::PermissionsExt as _;
    let (dir, joiner) = (scratch("founder"), scratch("founder-joiner"));
    let made = store::open(&dir, None, T0).unwrap();
    let nonce = made
        .founder_nonce
        .expect("the maker of a session is its founder");
    let mode = fs::metadata(dir.join(store::FOUNDER_NONCE_FILE))
        .unwrap()
        .permissions()
        .mode();
    assert_eq!(mode & 0o777, 0o600);
    let commitment = made.invite.founder_commitment();
    assert!(commitment.is_founder(&made.keypair.peer_id(), &nonce));
    assert_eq!(made.log.founder(), Some(commitment));
    let invite = made.invite.clone();
    drop(made);
    let reopened = store::open(&dir, None, T0).unwrap();
    assert_eq!(reopened.founder_nonce, Some(nonce));
    drop(reopened);
    let joined = store::open(&joiner, Some(&invite), T0).unwrap();
    assert_eq!(joined.founder_nonce, None);
    assert_eq!(
        joined.log.founder(),
        Some(commitment),
        "a joiner judges expels the same way"
    );
    // A nonce copied into another peer's store does not make that peer the founder.
    drop(joined);
    fs::copy(
        dir.join(store::FOUNDER_NONCE_FILE),
        joiner.join(store::FOUNDER_NONCE_FILE),
    )
    .unwrap();
    assert_eq!(
        store::open(&joiner, Some(&invite), T0)
            .unwrap()
            .founder_nonce,
        None
    );
    let _ = fs::remove_dir_all(&dir);
    let _ = fs::remove_dir_all(&joiner);
}

#[test]
fn an_edit_on_one_engine_reaches_the_other_as_a_change_of_that_object_with_presence() {
    let (da, db) = (scratch("pair-a"), scratch("pair-b"));
    let a = Engine::start(config(&da), T0).unwrap();
    wait_view(&a, "the demo", |v| v.n_ops() == FOUNDED + 1);
    let melon = only_object(&a);
    let b = Engine::start(joiner(&a, &db, "Bea"), T0).unwrap();
    // A admits B (the session binds its authors): the demo from A, then B's admission.
    wait_view(&b, "the demo from a and b's admission", |v| {
        v.n_ops() == FOUNDED + 2 && v.admitted()
    });
    assert_eq!(
        lock(b.view()).n_loaded(),
        0,
        "a joining peer authors no demo"
    );
    let (_, cursor) = lock(b.view()).changes_since(0);
    author(&a, set_shape(melon, "0.5-x^2-y^2-z^2"));
    wait_view(&b, "a's edit", |v| v.n_ops() == FOUNDED + 3);
    let (changes, _) = lock(b.view()).changes_since(cursor);
    assert_eq!(
        changes,
        Some([model::scene::ObjectId(melon)].into_iter().collect()),
        "the change names the edited object only"
    );
    assert_eq!(geometry_formula(&b, melon), "0.5-x^2-y^2-z^2");
    assert_eq!(
        lock(a.view()).scene_hash_hex(),
        lock(b.view()).scene_hash_hex()
    );
    // B names the newest stamp of A's ops that changed its scene (for timing them to the
    // screen); a carve is newer, and A names none of its own.
    let shaped = lock(b.view()).last_remote_edit();
    assert!(shaped.is_some());
    let carve = model::object::Edit::stamp(
        model::object::EditOp::Subtract,
        model::object::ToolShape::Sphere { radius: 0.1 },
        model::object::Pose::at(glam::DVec3::Z),
    );
    author(&a, ShapePayload::edit(melon, carve).unwrap());
    wait_view(&b, "a's carve", |v| v.n_ops() == FOUNDED + 4);
    assert!(lock(b.view()).last_remote_edit() > shaped);
    assert_eq!(lock(a.view()).last_remote_edit(), None);
    // B's presence (its name, then a pointer) reaches A.
    let mut presence = b.presence();
    presence.pointer = Some([0.1, 0.2, 0.3]);
    b.set_presence(presence).unwrap();
    wait_view(&a, "b's presence", |v| {
        v.presence()
            .values()
            .any(|p| p.name == "Bea" && p.pointer == Some([0.1, 0.2, 0.3]))
    });
    let rows = lock(a.view()).peers().to_vec();
    assert_eq!(rows.len(), 1);
    assert!(rows[0].online && rows[0].name == "Bea", "{rows:?}");
    assert_eq!(rows[0].how, "it dialed us");
    assert_eq!(lock(b.view()).peers()[0].how, "direct");
    b.shutdown();
    wait_view(&a, "b to be offline", |v| v.n_online() == 0);
    assert!(lock(a.view()).presence().is_empty());
    drop(a);
    let _ = fs::remove_dir_all(&da);
    let _ = fs::remove_dir_all(&db);
}

#[test]
fn the_founder_expels_a_peer_over_quic_and_hears_from_it_no_more() {
    let (da, db) = (scratch("expel-a"), scratch("expel-b"));
    let a = Engine::start(config(&da), T0).unwrap();
    wait_view(&a, "the demo", |v| v.n_ops() == FOUNDED + 1);
    let b = Engine::start(joiner(&a, &db, "Bea"), T0).unwrap();
    wait_view(&b, "the demo from a and b's admission", |v| {
        v.n_ops() == FOUNDED + 2 && v.admitted()
    });
    wait_view(&a, "b's name", |v| {
        v.n_online() == 1 && v.peers().iter().any(|p| p.name == "Bea")
    });
    let (founder, member) = (lock(a.view()).peer_id(), lock(b.view()).peer_id());
    // B joined with A's invite: it is not the founder and cannot expel A.
    let refused = lock(b.view()).membership_change(&founder.to_hex()[..8], true);
    assert!(refused.unwrap_err().contains("founder"));
    // A, who made the session, expels B by its name.
    let expel = lock(a.view()).membership_change("bea", true).unwrap();
    author(&a, ShapePayload::Member(Box::new(expel)));
    wait_view(&a, "b expelled and cut off", |v| {
        v.expelled().contains(&member) && v.n_online() == 0
    });
    // B goes on writing, and its engine dials A again every 2 s: A refuses it at
    // admission, so it hears none of it and never sees it connect again.
    let (_, seen) = a.news_since(0);
    author(&b, ShapePayload::Chat("still here".into()));
    std::thread::sleep(Duration::from_millis(2 * DIAL_RETRY_MILLIS + 500));
    let (lines, _) = a.news_since(seen);
    assert!(!lines.iter().any(|l| l.contains("connected")), "{lines:?}");
    assert_eq!(
        lock(a.view()).n_ops(),
        FOUNDED + 3,
        "the demo, b's admission and the expel only"
    );
    drop((a, b));
    let _ = fs::remove_dir_all(&da);
    let _ = fs::remove_dir_all(&db);
}

#[test]
fn news_keeps_the_latest_lines_and_disconnections_read_as_actions() {
    let mut news = News::default();
    for i in 0..MAX_NEWS_LINES + 5 {
        news.push(format!("line {i}"));
    }
    let (lines, next) = news.since(0);
    assert_eq!(lines.len(), MAX_NEWS_LINES);
    assert_eq!(lines[0], "line 5");
    assert_eq!(next, MAX_NEWS_LINES as u64 + 5);
    assert!(news.since(next).0.is_empty());
    let text = disconnect_text(&DisconnectReason::Sync(CloseReason::WrongProtocol {
        remote: PROTOCOL_VERSION + 1,
    }));
    let expected = format!(
        "protocol {}, this build speaks {PROTOCOL_VERSION}",
        PROTOCOL_VERSION + 1
    );
    assert!(text.contains(&expected), "{text}");
}

#[test]
fn a_joined_sessions_directory_is_named_by_its_invite_without_revealing_it() {
    let a = replication::net::invite::Invite::generate(&mut rand_chacha::ChaCha20Rng::from_seed(
        [1; 32],
    ));
    let b = replication::net::invite::Invite::generate(&mut rand_chacha::ChaCha20Rng::from_seed(
        [2; 32],
    ));
    let name = store::joined_dir_name(&a);
    assert_eq!(
        name,
        store::joined_dir_name(&a),
        "the same invite, the same directory"
    );
    assert_ne!(name, store::joined_dir_name(&b));
    assert!(name.starts_with("joined-") && name.len() == "joined-".len() + 12);
    let code = a.to_string().replace('-', "");
    assert!(
        !code.contains(&name["joined-".len()..]),
        "the name is not part of the code"
    );
    // Not the discovery id (which is public on the LAN, and slow to derive).
    let discovery = replication::net::SessionKeys::from_invite(&a).discovery_id();
    let discovery_hex: String = discovery[..6].iter().map(|b| format!("{b:02x}")).collect();
    assert_ne!(&name["joined-".len()..], discovery_hex);
}

#[test]
fn a_large_import_is_one_history_row_not_undone_and_its_id_not_reused() {
    let dir = scratch("parts");
    let s = Engine::start(config(&dir), T0).unwrap();
    wait_view(&s, "the demo", |v| v.n_ops() == FOUNDED + 1);
    let first = lock(s.view()).next_object();
    let first_id = first.id();
    let mesh = model::mesh::shapes::icosphere(1.0, 4);
    let data = model::object::ObjectData {
        name: "ball".into(),
        geometry: Some(Geometry {
            shape: Shape::Mesh(std::sync::Arc::new(mesh)),
            ..Geometry::implicit(Formula::new("0").unwrap())
        }),
        ..Default::default()
    };
    let ops = replication::shape::parts::split(first.create(data, None)).unwrap();
    let n_ops = ops.len();
    assert!(n_ops > 2, "{n_ops}");
    for op in ops {
        author(&s, op);
    }
    let view = lock(s.view());
    assert_eq!(view.object_label(first_id), "ball");
    assert_eq!(view.n_ops(), FOUNDED + 1 + n_ops);
    let rows: Vec<&str> = view.history().iter().map(|h| h.what.as_str()).collect();
    assert_eq!(rows.len(), FOUNDED + 2, "the parts are not rows: {rows:?}");
    assert_eq!(
        rows[FOUNDED + 1],
        format!("put together a change to ball from {} parts", n_ops - 1)
    );
    assert!(!view.history()[FOUNDED + 1].undoable);
    assert_eq!(view.undo_target(first_id), None, "a creation is not undone");
    let next = view.next_object();
    assert!(
        next.counter > first.counter && next.id() != first_id,
        "the id is taken"
    );
    drop(view);
    drop(s);
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn a_planted_scene_difference_is_found_over_quic_shown_and_repaired() {
    let (da, db) = (scratch("check-a"), scratch("check-b"));
    let a = Engine::start(config(&da), T0).unwrap();
    wait_view(&a, "the demo", |v| v.n_ops() == FOUNDED + 1);
    let melon = only_object(&a);
    let b = Engine::start(joiner(&a, &db, "Bea"), T0).unwrap();
    let same_scene = |a: &Engine, b: &mut View| {
        b.scene_hash_hex() == lock(a.view()).scene_hash_hex()
            && b.scene_check().agrees == Some(true)
            && lock(a.view()).scene_check().agrees == Some(true)
    };
    wait_view(&b, "the two scenes compared and equal", |v| {
        v.n_ops() == FOUNDED + 2 && same_scene(&a, v)
    });
    for engine in [&a, &b] {
        let view = lock(engine.view());
        assert_eq!(
            view.scene_check().n_mismatches,
            0,
            "equal scenes never differ"
        );
        assert_eq!(view.peers()[0].scene_agrees, Some(true));
    }
    // B's fold loses the melon behind its log's back: found, shown, refolded.
    let planted_at = crate::clock::now().instant;
    lock(b.view()).plant_scene_difference(melon);
    assert_ne!(
        lock(b.view()).scene_hash_hex(),
        lock(a.view()).scene_hash_hex()
    );
    wait_view(&b, "the difference found and repaired", |v| {
        v.scene_check().n_mismatches >= 1 && same_scene(&a, v)
    });
    let took = planted_at.elapsed();
    // A slow repair says what each side's check did, so that a rare one can be read.
    let checks = |e: &Engine| {
        let view = lock(e.view());
        format!("{:?}; {:?}", view.scene_check(), view.peers())
    };
    assert!(
        took < Duration::from_secs(10),
        "repaired in {took:?}; A: {}; B: {}",
        checks(&a),
        checks(&b)
    );
    assert_eq!(geometry_formula(&b, melon), geometry_formula(&a, melon));
    for engine in [&a, &b] {
        let view = lock(engine.view());
        let check = view.scene_check();
        assert!(check.n_mismatches >= 1, "{check:?}");
        let last = check.last_mismatch.as_deref().unwrap();
        assert!(last.contains("ours") && last.contains("theirs") && last.contains("cut"));
        let row = &view.peers()[0];
        assert!(
            row.scene_mismatches >= 1 && row.last_mismatch.is_some(),
            "{row:?}"
        );
        assert_eq!(row.scene_agrees, Some(true));
    }
    assert!(lock(b.view()).scene_check().n_objects_refolded >= 1);
    drop(b);
    drop(a);
    let _ = fs::remove_dir_all(&da);
    let _ = fs::remove_dir_all(&db);
}

/// Ops in the session [`a_joiner_takes_a_snapshot_checks_it_and_stores_the_whole_log`] joins.
const JOINED_EDITS: usize = 3_000;

#[test]
fn a_joiner_takes_a_snapshot_checks_it_and_stores_the_whole_log() {
    let (da, db) = (scratch("snap-a"), scratch("snap-b"));
    let n = crate::workload::carved_session(&da, JOINED_EDITS, T0)
        .unwrap()
        .0;
    let a = Engine::start(config(&da), T0).unwrap();
    assert_eq!(lock(a.view()).n_ops(), n);
    let b = Engine::start(joiner(&a, &db, "Bea"), T0).unwrap();
    wait_view(&b, "the snapshot joined and checked", |v| {
        v.snapshot().is_some_and(|s| s.verified)
    });
    let row = lock(b.view()).snapshot().cloned().unwrap();
    assert_eq!(row.n_ops, n, "{row:?}");
    assert!(row.refused.is_empty() && !row.busy, "{row:?}");
    assert!(row.join_micros.is_some() && row.bytes > 0, "{row:?}");
    assert!(row.text().contains("checked"), "{}", row.text());
    wait_view(&b, "the same scene as the founder's", |v| {
        v.n_ops() == n && v.scene_hash_hex() == lock(a.view()).scene_hash_hex()
    });
    // The history came with the snapshot: every row of the founder's is there.
    let rows = |e: &Engine| -> Vec<(String, String, String, OpId)> {
        (lock(e.view()).history().iter())
            .map(|h| (h.author.clone(), h.what.clone(), h.status.clone(), h.op))
            .collect()
    };
    assert_eq!(rows(&b), rows(&a));
    // An edit of the joiner's travels both ways as after any join.
    drop(b);
    // Restarted, the joiner loads the whole log from its store, without a snapshot.
    let b = Engine::start(joiner(&a, &db, "Bea"), T0).unwrap();
    {
        let mut view = lock(b.view());
        assert_eq!(view.n_loaded(), n);
        assert_eq!(view.scene_hash_hex(), lock(a.view()).scene_hash_hex());
    }
    let stats = lock(b.view()).snapshot().cloned();
    assert_eq!(stats, None, "a peer with a stored log joins no snapshot");
    drop(b);
    drop(a);
    let _ = fs::remove_dir_all(&da);
    let _ = fs::remove_dir_all(&db);
}

#[test]
fn a_snapshot_whose_scene_is_not_its_ops_fold_is_refused_and_the_joiner_syncs_op_by_op() {
    let (da, db) = (scratch("planted-a"), scratch("planted-b"));
    let n = crate::workload::carved_session(&da, 200, T0).unwrap().0;
    let a = Engine::start(config(&da), T0).unwrap();
    let ball = only_object(&a);
    let fold = lock(a.view()).scene_hash_hex();
    // The founder's fold loses the ball behind its log's back, so its snapshot names a scene
    // that is not its ops' fold.
    lock(a.view()).plant_scene_difference(ball);
    let b = Engine::start(joiner(&a, &db, "Bea"), T0).unwrap();
    wait_view(&b, "the ops synced one by one", |v| {
        v.n_ops() >= n && v.scene_hash_hex() == fold
    });
    let row = lock(b.view()).snapshot().cloned().unwrap();
    assert!(!row.verified && row.join_micros.is_none(), "{row:?}");
    assert!(row.refused[0].contains("not the scene"), "{row:?}");
    assert!(row.text().contains("op by op"), "{}", row.text());
    // The founder's own difference is found by the scene check with the joiner, and repaired.
    wait_view(&a, "the founder repaired", |v| {
        v.scene_check().n_mismatches >= 1 && v.scene_hash_hex() == fold
    });
    drop(b);
    drop(a);
    let _ = fs::remove_dir_all(&da);
    let _ = fs::remove_dir_all(&db);
}
