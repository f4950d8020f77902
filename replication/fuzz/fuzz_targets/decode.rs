//! Fuzzes every decoder of untrusted replication input and the sync state machine: any bytes
//! must decode or be refused (op, sync message, snapshot, test scene), and fed to a
//! `SyncState` after a valid hello, as a sequence of messages, must be handled or counted as
//! rejections, never panic, hang or allocate without bound. Each input runs on a thread with
//! a 256 KiB stack, so that a recursion as deep as the input is a crash the fuzzer finds.
#![no_main]

use libfuzzer_sys::fuzz_target;
use replication::materialize::Materialize;
use replication::materialize::test_scene::TestScene;
use replication::payload::test_payload::TestPayload;
use replication::pending::Origin;
use replication::op::UNNAMED_SESSION;
use replication::snapshot::{Snapshot, verify};
use replication::sync::message::{Message, PROTOCOL_VERSION};
use replication::{Keypair, Log, Op, SyncConfig, SyncState, Timestamp};
use testkit::stack::on_small_stack;

const SESSION: [u8; 16] = [5; 16];

fuzz_target!(|data: &[u8]| on_small_stack(|| decode(data)));

fn decode(data: &[u8]) {
    if let Ok(op) = Op::<TestPayload>::decode(data) {
        assert_eq!(op.encoded(), data, "a decoded op is canonical");
        let _ = op.verify(&UNNAMED_SESSION);
    }
    if let Ok(message) = Message::decode(data) {
        assert_eq!(message.encode(), data, "a decoded message is canonical");
    }
    if let Ok(snapshot) = Snapshot::<TestPayload>::decode(data) {
        let _ = snapshot.encode();
        let joined = snapshot.join::<TestScene>(Default::default(), Timestamp(0));
        if let Ok((log, _)) = joined {
            let _ = verify(&log, &UNNAMED_SESSION, |_| {});
        }
    }
    sync(data);
}

/// Feeds `data`, split into messages by a one-byte length prefix, to a connection whose
/// remote has said hello, with time advancing between messages.
fn sync(data: &[u8]) {
    let me = Keypair::from_seed([1; 32]);
    let remote = Keypair::from_seed([2; 32]).peer_id();
    let mut log = Log::<TestPayload>::default();
    let config = SyncConfig {
        session_id: SESSION,
        local: me.peer_id(),
        origin: Origin(1),
    };
    let mut state = SyncState::new(Timestamp(0), config);
    let hello = Message::Hello {
        protocol_version: PROTOCOL_VERSION,
        session_id: SESSION,
        peer: remote,
        hello_seen: true,
        have: None,
    };
    state.handle_input(Timestamp(0), &hello.encode(), &mut log);
    let mut rest = data;
    let mut now = 0;
    while let Some((&len, tail)) = rest.split_first() {
        let len = usize::from(len).min(tail.len());
        let (message, tail) = tail.split_at(len);
        now += 700_000;
        state.handle_input(Timestamp(now), message, &mut log);
        state.handle_timeout(Timestamp(now), &mut log);
        while state.poll_event().is_some() {}
        while state.poll_transmit(Timestamp(now), &log).is_some() {}
        let _ = state.poll_timeout(&log);
        rest = tail;
    }
}
