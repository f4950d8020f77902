//! LAN sessions by DNS-SD over multicast DNS, inside a private network namespace (loopback
//! only) so that no packet leaves this test: three nodes of two sessions announce themselves, a
//! browser lists all three with their names, hosts and peer counts, the two nodes of one session
//! find and dial each other and sync while the third is never dialed, and no announced byte
//! holds the invite or a key derived for admission or sync.
//!
//! avahi-browse is not run here: avahi ignores loopback interfaces and needs its daemon on
//! D-Bus, so in a loopback-only namespace it could see nothing.

#![allow(clippy::unwrap_used, reason = "test helpers")]

mod net_support;

use std::cell::RefCell;
use std::net::{Ipv4Addr, SocketAddr};
use std::process::Command;
use std::sync::{Arc, Mutex};

use mdns_sd::{ServiceDaemon, ServiceInfo};
use net_support::*;
use replication::Log;
use replication::net::Invite;
use replication::net::discovery::dnssd::{
    self, Announcement, DnsSd, DnsSdConfig, DnsSdError, LanSession, MAX_SESSION_NAME_BYTES,
    SERVICE_TYPE,
};
use tokio::sync::watch;

/// Set in the child process that runs inside the private network namespace.
const IN_NAMESPACE: &str = "SCULPT_DNSSD_TEST_IN_NAMESPACE";
/// The most datagrams the sniffer keeps.
const MAX_SNIFFED: usize = 10_000;

#[test]
fn dnssd_lists_lan_sessions_and_dials_only_its_own() {
    if std::env::var_os(IN_NAMESPACE).is_some() {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        return runtime.block_on(in_namespace());
    }
    // Multicast DNS is sent only inside a network namespace of our own (loopback only), never
    // on the machine's real interfaces: the test re-runs itself there.
    let usable = Command::new("unshare")
        .args(["-rn", "ip", "link", "set", "lo", "up"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !usable {
        eprintln!("skipped: `unshare -rn` or `ip` is not available, so DNS-SD is untested here");
        return;
    }
    let exe = std::env::current_exe().unwrap();
    let output = Command::new("unshare")
        .args(["-rn", "sh", "-c", "ip link set lo up && exec \"$0\" \"$@\""])
        .arg(exe)
        .args([
            "dnssd_lists_lan_sessions_and_dials_only_its_own",
            "--exact",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(IN_NAMESPACE, "1")
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        output.status.success(),
        "the namespaced run failed:\n{text}"
    );
    assert!(
        text.contains("1 passed"),
        "the namespaced run ran no test:\n{text}"
    );
    println!("{text}");
}

async fn in_namespace() {
    // Loopback is up but has no multicast route: starting must fail with a clear error.
    let refused = DnsSd::start(DnsSdConfig::default());
    assert!(
        matches!(refused, Err(DnsSdError::MulticastUnavailable(_))),
        "{refused:?}"
    );
    println!("without a multicast route: {}", refused.unwrap_err());
    for args in [
        &["link", "set", "lo", "multicast", "on"][..],
        &["route", "add", "224.0.0.0/4", "dev", "lo"][..],
    ] {
        let status = Command::new("ip").args(args).status().unwrap();
        assert!(status.success(), "ip {args:?}");
    }
    let sniffed = sniff();

    let keys = session_keys(INVITE);
    let other = session_keys(OTHER_INVITE);
    let a = node(1);
    let b = node(2);
    let c = node_with(3, OTHER_INVITE, Log::default());
    author_some(&a.handle, 1, "alice").await;
    author_some(&b.handle, 2, "bob").await;
    author_some(&c.handle, 3, "carol").await;

    // A browser of its own, announcing nothing: what the window would list.
    let observer = RefCell::new(DnsSd::start(DnsSdConfig::default()).unwrap());
    let mut drivers = Vec::new();
    for (handle, discovery_id, name) in [
        (&a.handle, keys.discovery_id(), "melon"),
        (&b.handle, keys.discovery_id(), "melon"),
        (&c.handle, other.discovery_id(), "carol's cube"),
    ] {
        let announcement = Announcement {
            discovery_id,
            session_name: name.into(),
            peer: handle.peer_id(),
            quic_addr: handle.local_addr(),
            n_peers: 0,
        };
        let (sessions, listed) = watch::channel(Vec::new());
        let dnssd = DnsSd::start(DnsSdConfig::default()).unwrap();
        let (_share, shared) = tokio::sync::watch::channel(true);
        let driving =
            dnssd::announce_and_dial(dnssd, handle.clone(), announcement, shared, sessions);
        drivers.push((tokio::spawn(driving), listed));
    }
    let hostile = announce_hostile();

    // A and B find and dial each other; their ops meet, C's do not.
    converge(&[&a.handle, &b.handle], 8).await;
    eventually(
        "A and B are each other's only peer, and they say so",
        || async {
            let listed = listed_by(&observer);
            listed.len() == 3
                && a.handle.connected_peers().await.unwrap().len() == 1
                && b.handle.connected_peers().await.unwrap().len() == 1
                && [&a.handle, &b.handle].iter().all(|h| {
                    listed
                        .iter()
                        .any(|s| s.peer == h.peer_id() && s.n_peers == 1)
                })
        },
    )
    .await;
    let listed = listed_by(&observer);
    for s in &listed {
        println!(
            "listed: {:?} {} at {} {:?}, {} peers",
            s.name, s.peer, s.host, s.addrs, s.n_peers
        );
    }
    assert_eq!(listed.len(), 3, "A, B and C, not the hostile ones");
    for (handle, discovery_id, name, n_peers) in [
        (&a.handle, keys.discovery_id(), "melon", 1),
        (&b.handle, keys.discovery_id(), "melon", 1),
        (&c.handle, other.discovery_id(), "carol's cube", 0),
    ] {
        let short = handle.peer_id().short();
        let session = listed.iter().find(|s| s.peer == handle.peer_id()).unwrap();
        assert_eq!(session.discovery_id, discovery_id);
        assert_eq!(session.name, name);
        assert_eq!(session.host, format!("sculpt-{short}.local."));
        assert_eq!(session.instance, format!("sculpt-{short}.{SERVICE_TYPE}"));
        assert_eq!(session.addrs, vec![handle.local_addr()]);
        assert_eq!(session.n_peers, n_peers);
    }
    // Each driver publishes the same table.
    for (_, published) in &drivers {
        eventually("every driver lists the three", || async {
            published.borrow().len() == 3
        })
        .await;
    }
    // Nobody dialed C, and C dialed nobody.
    let stats_c = c.handle.stats().await.unwrap();
    assert_eq!(stats_c.n_admitted, 0, "{stats_c:?}");
    assert_eq!(stats_c.n_failed_admissions(), 0, "{stats_c:?}");
    assert!(c.handle.connected_peers().await.unwrap().is_empty());
    assert_eq!(n_ops(&c.handle).await, 4);
    for h in [&a.handle, &b.handle] {
        let stats = h.stats().await.unwrap();
        assert_eq!(stats.n_failed_admissions(), 0, "{stats:?}");
    }

    // C stops: its driver withdraws the announcement, and the browser drops it at once.
    c.handle.shutdown().await.unwrap();
    eventually("C's goodbye removes it from the list", || async {
        let listed = listed_by(&observer);
        listed.len() == 2 && listed.iter().all(|s| s.discovery_id == keys.discovery_id())
    })
    .await;
    let stats = observer.borrow().stats().clone();
    println!("observer: {stats:?}");
    assert!(stats.n_malformed >= 1, "{stats:?}");
    assert!(stats.n_other_versions >= 1, "{stats:?}");
    assert!(stats.n_removed >= 1, "{stats:?}");
    assert_eq!(stats.n_over_limit, 0, "{stats:?}");
    hostile.shutdown().unwrap();
    a.handle.shutdown().await.unwrap();
    b.handle.shutdown().await.unwrap();
    for (driving, _) in drivers {
        let stats = tokio::time::timeout(PATIENCE, driving)
            .await
            .unwrap()
            .unwrap()
            .unwrap();
        assert!(stats.n_announced >= 1, "{stats:?}");
    }

    check_nothing_secret_was_announced(&sniffed.lock().unwrap(), &[INVITE, OTHER_INVITE]);
}

/// The observer's table after handling what has arrived.
fn listed_by(observer: &RefCell<DnsSd>) -> Vec<LanSession> {
    let mut observer = observer.borrow_mut();
    observer.poll().unwrap();
    observer.sessions().cloned().collect()
}

/// Records every multicast DNS datagram on loopback, as any listener on the link could.
fn sniff() -> Arc<Mutex<Vec<Vec<u8>>>> {
    let socket = socket2::Socket::new(
        socket2::Domain::IPV4,
        socket2::Type::DGRAM,
        Some(socket2::Protocol::UDP),
    )
    .unwrap();
    socket.set_reuse_address(true).unwrap();
    socket
        .bind(&SocketAddr::from((Ipv4Addr::UNSPECIFIED, dnssd::MDNS_PORT)).into())
        .unwrap();
    socket
        .join_multicast_v4(&dnssd::MDNS_GROUP_V4, &Ipv4Addr::LOCALHOST)
        .unwrap();
    socket.set_nonblocking(true).unwrap();
    let socket = tokio::net::UdpSocket::from_std(socket.into()).unwrap();
    let sniffed = Arc::new(Mutex::new(Vec::new()));
    let keep = sniffed.clone();
    tokio::spawn(async move {
        let mut buf = vec![0; 9_000];
        while let Ok((n, _)) = socket.recv_from(&mut buf).await {
            let mut kept = keep.lock().unwrap();
            if kept.len() < MAX_SNIFFED {
                kept.push(buf[..n].to_vec());
            }
        }
    });
    sniffed
}

/// Announces, from a daemon of its own, instances of our service type that a browser must
/// count and drop: bad TXT values, and a future TXT layout.
fn announce_hostile() -> ServiceDaemon {
    let daemon = ServiceDaemon::new().unwrap();
    let long_name = "x".repeat(MAX_SESSION_NAME_BYTES + 1);
    let hostile: [&[(&str, &str)]; 3] = [
        &[
            ("txtvers", "1"),
            ("proto", "2"),
            ("session", "not hex"),
            ("name", "bad"),
            ("peer", "00"),
            ("peers", "1"),
        ],
        &[
            ("txtvers", "1"),
            ("proto", "2"),
            ("session", "00000000000000000000000000000000"),
            ("name", &long_name),
            (
                "peer",
                "0000000000000000000000000000000000000000000000000000000000000000",
            ),
            ("peers", "99999999"),
        ],
        &[("txtvers", "2"), ("anything", "new")],
    ];
    for (idx, txt) in hostile.into_iter().enumerate() {
        let info = ServiceInfo::new(
            SERVICE_TYPE,
            &format!("hostile-{idx}"),
            &format!("hostile-{idx}.local."),
            Ipv4Addr::LOCALHOST.to_string().as_str(),
            9,
            txt,
        )
        .unwrap();
        daemon.register(info).unwrap();
    }
    daemon
}

/// No captured datagram holds an invite (in any spelling) or a key derived for admission or
/// sync; they do hold what is meant to be public.
fn check_nothing_secret_was_announced(datagrams: &[Vec<u8>], invites: &[&str]) {
    let all: Vec<u8> = datagrams.concat();
    println!("sniffed {} datagrams, {} bytes", datagrams.len(), all.len());
    let holds = |needle: &[u8]| all.windows(needle.len()).any(|w| w == needle);
    for text in invites {
        let invite = Invite::parse(text).unwrap();
        let canonical = invite.to_string();
        let keys = session_keys(text);
        // The derivation as session.rs does it, checked against the public derived values, so
        // that the admission key computed below is the real one.
        let derive = |context: &str| blake3::derive_key(context, canonical.as_bytes());
        assert_eq!(
            derive("sculpt 2026 replication session id v1")[..16],
            keys.session_id()[..]
        );
        // The announced discovery id is stretched (argon2id), not a fast hash of the invite.
        assert_ne!(
            derive("sculpt 2026 replication discovery id v1")[..16],
            keys.discovery_id()[..]
        );
        let admission_key = derive("sculpt 2026 replication admission key v1");
        assert!(
            holds(hex(&keys.discovery_id()).as_bytes()),
            "the sniffer heard the announcements"
        );
        let secrets: Vec<Vec<u8>> = vec![
            canonical.clone().into_bytes(),
            canonical.to_uppercase().into_bytes(),
            canonical.replace('-', "").into_bytes(),
            admission_key.to_vec(),
            hex(&admission_key).into_bytes(),
            hex(&admission_key[..8]).into_bytes(),
            keys.session_id().to_vec(),
            hex(&keys.session_id()).into_bytes(),
        ];
        for secret in secrets {
            assert!(
                !holds(&secret),
                "an announcement holds {}",
                String::from_utf8_lossy(&secret)
            );
        }
    }
    assert!(holds(b"name=melon"));
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}
