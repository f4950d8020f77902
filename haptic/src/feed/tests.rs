//! The feed over a scripted source: an edit rebuilds its own object only, "everything changed"
//! drops what is gone, remote tools follow the objects and rebuild the snapshot when they
//! move, refused objects are reported, and the thread publishes through the handoff.

use std::collections::BTreeSet;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use glam::DVec3;

use model::object::{Domain, Formula, Geometry, Object, ObjectData, Physics, Property, Transform};
use model::scene::{GroupId, ObjectId, Scene};

use super::*;
use crate::container::Container as _;
use crate::container::object::ObjectContainerError;

/// A ball of `radius` at `at`, with tension when `tangible`.
fn ball(at: DVec3, radius: f64, tangible: bool) -> Object {
    let formula = |text: &str| Formula::new(text).unwrap();
    let data = ObjectData {
        geometry: Some(Geometry {
            transform: Transform::translate(at),
            ..Geometry::implicit_in(
                formula(&format!("{radius} - sqrt(x^2 + y^2 + z^2)")),
                Domain::new(DVec3::ZERO, DVec3::splat(2.2 * radius)),
            )
        }),
        physics: Physics {
            tension: tangible.then(|| Property::new(formula("0.8"))),
            ..Physics::default()
        }
        .into(),
        ..ObjectData::default()
    };
    Object::new(data).unwrap()
}

/// A remote tool: a tangible ball where it is.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Ball(DVec3);

impl RemoteTool for Ball {
    fn object(&self) -> Option<Object> {
        Some(ball(self.0, 0.1, true))
    }
}

/// A scene and its changes as an owner reports them: numbered from 1, `None` for "every
/// object", cursor 0 reading as everything.
#[derive(Default)]
struct Source {
    scene: Scene,
    changes: Vec<Option<ObjectId>>,
    tools: Vec<Ball>,
}

impl Source {
    fn insert(&mut self, id: u64, object: Object, group: Option<GroupId>) {
        self.scene.remove_object(ObjectId(id));
        self.scene
            .insert_object(ObjectId(id), object, group)
            .unwrap();
        self.changes.push(Some(ObjectId(id)));
    }
}

impl SceneSource for Source {
    type Tool = Ball;

    fn scene(&self) -> &Scene {
        &self.scene
    }

    fn changes_since(&self, cursor: u64) -> (Option<BTreeSet<ObjectId>>, u64) {
        let next = self.changes.len() as u64 + 1;
        if cursor == 0 {
            return (None, next);
        }
        let seen = usize::try_from(cursor - 1).unwrap();
        let ids = self.changes[seen..].iter().copied().collect();
        (ids, next)
    }

    fn remote_tools(&self) -> Vec<Ball> {
        self.tools.clone()
    }
}

fn ids(built: &Built) -> Vec<u64> {
    built.scene.iter().map(|c| c.id()).collect()
}

/// Two tangible balls (ids 1 and 3) and an intangible one (2).
fn three_balls() -> Mutex<Source> {
    let mut source = Source::default();
    source.insert(1, ball(DVec3::ZERO, 1.0, true), None);
    source.insert(2, ball(DVec3::X * 3.0, 1.0, false), None);
    source.insert(3, ball(DVec3::X * 6.0, 1.0, true), None);
    Mutex::new(source)
}

#[test]
fn an_edit_rebuilds_its_own_object_only() {
    let source = three_balls();
    let mut snapshotter = Snapshotter::new();
    let first = snapshotter.update(&source).unwrap();
    assert_eq!(ids(&first), [1, 3], "the intangible ball is seen, not felt");
    assert_eq!(first.n_rebuilt, 3);
    assert!(snapshotter.update(&source).is_none(), "nothing changed");
    source
        .lock()
        .unwrap()
        .insert(3, ball(DVec3::X * 7.0, 0.5, true), None);
    let second = snapshotter.update(&source).unwrap();
    assert_eq!((ids(&second), second.n_rebuilt), (vec![1, 3], 1));
    let bounds = second.scene[1].bounds();
    assert!(bounds.contains(DVec3::X * 7.4) && !bounds.contains(DVec3::X * 6.0));
}

#[test]
fn when_everything_may_have_changed_the_objects_gone_are_dropped() {
    let source = three_balls();
    let mut snapshotter = Snapshotter::new();
    snapshotter.update(&source).unwrap();
    {
        let mut s = source.lock().unwrap();
        s.scene.remove_object(ObjectId(1));
        s.changes.push(None);
    }
    let built = snapshotter.update(&source).unwrap();
    assert_eq!((ids(&built), built.n_rebuilt), (vec![3], 2));
}

#[test]
fn remote_tools_follow_the_objects_and_a_move_builds_again() {
    let source = three_balls();
    source.lock().unwrap().tools = vec![Ball(DVec3::Y * 5.0), Ball(DVec3::Y * 8.0)];
    let mut snapshotter = Snapshotter::new();
    let built = snapshotter.update(&source).unwrap();
    let tool_ids = [REMOTE_TOOL_ID_BASE, REMOTE_TOOL_ID_BASE + 1];
    assert_eq!(ids(&built), [1, 3, tool_ids[0], tool_ids[1]]);
    assert!(snapshotter.update(&source).is_none(), "the tools stayed");
    source.lock().unwrap().tools[1] = Ball(DVec3::Y * 9.0);
    let moved = snapshotter.update(&source).unwrap();
    assert_eq!((ids(&moved), moved.n_rebuilt), (ids(&built), 0));
    assert!(moved.scene[3].bounds().contains(DVec3::Y * 9.0));
    source.lock().unwrap().tools = vec![Ball(DVec3::ZERO); MAX_REMOTE_TOOLS + 3];
    let crowded = snapshotter.update(&source).unwrap();
    assert_eq!(crowded.scene.len(), 2 + MAX_REMOTE_TOOLS);
}

#[test]
fn an_object_that_cannot_be_felt_is_refused_with_why_and_the_rest_is_felt() {
    // A ball whose formula unrolls to more instructions than a tick may pay (padded so that
    // the text's own unrolling budget admits it).
    let mut text = String::from(
        "function frep(x,y,z,t) { s = 0; for (i = 0; i < 1000; i = i + 1) { \
         s = s + sin(x*i + y)*cos(z*i - x) + sqrt(abs(y*i + z)); } \
         return 1 - sqrt(x^2+y^2+z^2) + 1e-9*s; }",
    );
    text.push_str(&" ".repeat(2048 - text.len()));
    let costly = ObjectData {
        geometry: Some(Geometry::implicit_in(
            Formula::new(&text).unwrap(),
            Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
        )),
        physics: Physics {
            tension: Some(Property::new(Formula::new("1").unwrap())),
            ..Physics::default()
        }
        .into(),
        ..ObjectData::default()
    };
    let mut source = Source::default();
    source.insert(1, Object::new(costly).unwrap(), None);
    source.insert(2, ball(DVec3::X * 3.0, 1.0, true), None);
    let built = Snapshotter::new().update(&Mutex::new(source)).unwrap();
    assert_eq!(ids(&built), [2]);
    assert!(
        matches!(
            built.refused.as_slice(),
            [(ObjectId(1), ObjectContainerError::TooCostly { id: 1, .. })]
        ),
        "{:?}",
        built.refused
    );
}

#[test]
fn the_feed_thread_publishes_a_snapshot_per_change_through_the_handoff() {
    let source = Arc::new(three_balls());
    let (scenes, mut receiver) = crate::handoff::channel::<Snapshot>();
    let feed = Feed::spawn(Arc::clone(&source), scenes).unwrap();
    let take = |receiver: &mut crate::handoff::Receiver<Snapshot>| {
        let mut n_polls = 0;
        loop {
            if let Some(snapshot) = receiver.take() {
                return snapshot;
            }
            n_polls += 1;
            assert!(n_polls < 2_000, "no snapshot in 10 s");
            std::thread::sleep(Duration::from_millis(5));
        }
    };
    let first = take(&mut receiver);
    assert_eq!(first.len(), 2);
    source
        .lock()
        .unwrap()
        .insert(4, ball(DVec3::Z * 3.0, 1.0, true), None);
    feed.waker()();
    let second = take(&mut receiver);
    assert_eq!(second.iter().map(|c| c.id()).collect::<Vec<_>>(), [1, 3, 4]);
    // The servo's side retires what it took; the feed frees it on its own thread.
    receiver.retire(first).unwrap();
    receiver.retire(second).unwrap();
    // The counters follow each publication.
    let mut n_polls = 0;
    while feed.stats().n_snapshots < 2 {
        n_polls += 1;
        assert!(n_polls < 2_000, "{:?}", feed.stats());
        std::thread::sleep(Duration::from_millis(5));
    }
    let stats = feed.stats();
    assert_eq!(
        (stats.n_snapshots, stats.n_rebuilt, stats.n_objects),
        (2, 4, 3)
    );
    feed.stop();
}
