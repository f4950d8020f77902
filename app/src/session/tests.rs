//! Unit tests of the solo session: the demo authored once and reloaded, undo and redo
//! targets, and store failures that leave the files as they were.

use super::*;
use fdsl::object::{Formula, Geometry};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("sculpt-session-{}-{name}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    dir
}

const T0: Timestamp = Timestamp(1_795_355_107_000_000);

fn set_shape(object: u64, formula: &str) -> ShapePayload {
    ShapePayload::Set {
        object,
        field: Field::Geometry(Some(Geometry::implicit(Formula::new(formula).unwrap()))),
    }
}

fn only_object(session: &Session) -> u64 {
    let ids: Vec<u64> = session.scene().objects().map(|(id, _)| id.0).collect();
    assert_eq!(ids.len(), 1, "{ids:?}");
    ids[0]
}

fn geometry_formula(session: &Session, object: u64) -> String {
    let o = session
        .scene()
        .object(fdsl::scene::ObjectId(object))
        .unwrap();
    match &o.data().geometry.as_ref().unwrap().shape {
        Shape::Implicit(f) => f.as_str().to_string(),
        other => panic!("{other:?}"),
    }
}

#[test]
fn an_empty_store_gets_the_demo_once_and_a_reopened_one_shows_the_same_scene() {
    let dir = scratch("reopen");
    let first = Session::open(&dir, T0);
    assert_eq!(first.store_error(), None);
    assert_eq!(first.n_loaded(), 0);
    let melon = only_object(&first);
    assert_eq!(first.object_label(melon), "Watermelon");
    let (id, hash) = (first.peer_id(), first.scene_hash_hex());
    drop(first);

    let mut second = Session::open(&dir, Timestamp(T0.0 + 1));
    assert_eq!(second.store_error(), None);
    assert_eq!(second.n_loaded(), 1);
    assert_eq!(second.peer_id(), id, "the identity key is kept");
    assert_eq!(second.scene_hash_hex(), hash);
    second
        .author(Timestamp(T0.0 + 2), set_shape(melon, "1-x^2-y^2-z^2"))
        .unwrap();
    second
        .author(Timestamp(T0.0 + 3), ShapePayload::Chat("hello".into()))
        .unwrap();
    drop(second);

    let third = Session::open(&dir, Timestamp(T0.0 + 4));
    assert_eq!(third.n_loaded(), 3);
    assert_eq!(geometry_formula(&third, melon), "1-x^2-y^2-z^2");
    let chat = third.chat();
    assert_eq!(chat.len(), 1);
    assert_eq!(
        (chat[0].text.as_str(), chat[0].author.clone()),
        ("hello", id.short())
    );
    let history = third.history();
    assert_eq!(history.len(), 3);
    assert!(history[1].what.contains("1-x^2-y^2-z^2"), "{history:?}");
    assert!(
        history.iter().all(|h| h.status == "effective"),
        "{history:?}"
    );
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn undo_and_redo_pick_this_peers_latest_edit_of_the_object() {
    let dir = scratch("undo");
    let mut s = Session::open(&dir, T0);
    let melon = only_object(&s);
    let original = geometry_formula(&s, melon);
    let a = s
        .author(Timestamp(T0.0 + 1), set_shape(melon, "1-x^2-y^2-z^2"))
        .unwrap();
    let b = s
        .author(Timestamp(T0.0 + 2), set_shape(melon, "0.5-abs(x)"))
        .unwrap();
    assert_eq!(s.undo_target(melon), Some(b));
    assert_eq!(s.redo_target(melon), None);
    s.author(Timestamp(T0.0 + 3), ShapePayload::Undo(b))
        .unwrap();
    assert_eq!(geometry_formula(&s, melon), "1-x^2-y^2-z^2");
    assert_eq!(s.undo_target(melon), Some(a));
    assert_eq!(s.redo_target(melon), Some(b));
    s.author(Timestamp(T0.0 + 4), ShapePayload::Undo(a))
        .unwrap();
    assert_eq!(geometry_formula(&s, melon), original);
    assert_eq!(
        s.redo_target(melon),
        Some(a),
        "the latest undo is redone first"
    );
    s.author(Timestamp(T0.0 + 5), ShapePayload::Redo(a))
        .unwrap();
    assert_eq!(s.redo_target(melon), Some(b));
    assert_eq!(geometry_formula(&s, melon), "1-x^2-y^2-z^2");
    let statuses: Vec<String> = s.history().into_iter().map(|h| h.status).collect();
    assert_eq!(statuses[1], "effective");
    assert_eq!(statuses[2], "undone");
    assert!(s.next_object_id() > melon);
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn a_corrupt_store_is_reported_and_left_byte_for_byte() {
    let dir = scratch("corrupt");
    fs::create_dir_all(&dir).unwrap();
    let ops = dir.join(OPS_FILE);
    let garbage = b"this is not a sculpt op store at all".to_vec();
    fs::write(&ops, &garbage).unwrap();
    let s = Session::open(&dir, T0);
    let error = s.store_error().expect("a corrupt store is an error");
    assert!(error.contains("cannot be opened"), "{error}");
    assert!(error.contains(OPS_FILE), "{error}");
    // The session still shows the demo, in memory; the file is as it was.
    assert_eq!(s.scene().len(), 1);
    assert_eq!(fs::read(&ops).unwrap(), garbage);
    assert!(!dir.join(format!("{OPS_FILE}.opening")).exists());
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn a_torn_tail_is_cut_and_the_file_as_it_was_is_kept() {
    let dir = scratch("torn");
    drop(Session::open(&dir, T0));
    let ops = dir.join(OPS_FILE);
    let mut bytes = fs::read(&ops).unwrap();
    bytes.extend_from_slice(&[200, 0, 0, 0, 1, 2, 3]);
    fs::write(&ops, &bytes).unwrap();
    let s = Session::open(&dir, Timestamp(T0.0 + 1));
    assert_eq!(s.store_error(), None);
    assert_eq!(s.n_loaded(), 1);
    assert!(s.notices()[0].contains("7 bytes"), "{:?}", s.notices());
    let kept = dir.join(format!("ops.damaged-{}.sculpt", T0.0 + 1));
    assert_eq!(fs::read(kept).unwrap(), bytes);
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn a_bad_key_or_an_unusable_directory_is_reported_not_replaced() {
    let dir = scratch("badkey");
    fs::create_dir_all(&dir).unwrap();
    fs::write(dir.join(KEY_FILE), b"short").unwrap();
    let s = Session::open(&dir, T0);
    assert!(
        s.store_error().unwrap().contains("5 bytes"),
        "{:?}",
        s.store_error()
    );
    assert_eq!(fs::read(dir.join(KEY_FILE)).unwrap(), b"short");
    assert!(!dir.join(OPS_FILE).exists());

    let file = dir.join("plain-file");
    fs::write(&file, b"x").unwrap();
    let s = Session::open(&file.join("store"), T0);
    assert!(
        s.store_error().unwrap().contains("cannot create"),
        "{:?}",
        s.store_error()
    );
    assert_eq!(s.scene().len(), 1, "the demo still shows, in memory");
    let _ = fs::remove_dir_all(&dir);
}
