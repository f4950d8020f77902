//! LAN sessions by DNS-SD over multicast DNS (RFC 6763 over RFC 6762), the convention that
//! avahi, Bonjour and every other LAN browser understands, through the `mdns-sd` crate.
//!
//! Each peer announces one service instance of [`SERVICE_TYPE`] named after its short peer id,
//! at the port of its QUIC endpoint, with TXT records that say which session it is in (the
//! session's [`DiscoveryId`], a hash of the invite), the session's display name, its full peer
//! id and how many peers it is connected to. A [`DnsSd`] also browses the same service type and
//! keeps a bounded table of every [`LanSession`] announced on the link, from which the app lists
//! sessions and [`announce_and_dial`] dials the peers of its own session.
//!
//! What is announced is public by design: it is not the invite, the admission key or the sync
//! session id, and none of them can be computed from it (a listener who sees a discovery id can
//! still test guessed invites offline, which is why invites are long and random). Announcements prove
//! nothing: a listener learns an address to dial, and admission decides.
//!
//! It is **not** async and **not** part of the sans-IO core: `mdns-sd` runs its own named
//! thread (`mDNS_daemon`) with blocking sockets and hands results over bounded channels, which
//! [`DnsSd::poll`] drains without blocking, so it works on a current-thread tokio runtime.
//! TXT values from the network are untrusted: every length is bounded, malformed entries are
//! counted and dropped, and nothing here panics on them.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::io;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV6};
use std::time::Duration;

use mdns_sd::{
    IfKind, Receiver, ResolvedService, ScopedIp, ServiceDaemon, ServiceEvent, ServiceInfo,
    TryRecvError, TxtProperties,
};
use socket2::{Domain, InterfaceIndexOrAddress, Protocol, Socket, Type};
use tokio::sync::watch;
use tokio::time::Instant;

use crate::identity::{PEER_ID_BYTES, PeerId, hex};
use crate::net::clock::wall_clock_now;
use crate::net::discovery::message::DiscoveredPeer;
use crate::net::node::NodeHandle;
use crate::net::session::{DISCOVERY_ID_BYTES, DiscoveryId};
use crate::payload::Payload;
use crate::sync::message::PROTOCOL_VERSION;
use crate::sync::state::MIN_REDIAL_HANDSHAKE_MICROS;
use crate::time::Timestamp;

/// The DNS-SD service type of sculpt sessions (QUIC runs over UDP).
pub const SERVICE_TYPE: &str = "_sculpt._udp.local.";
/// The standard multicast DNS port.
pub const MDNS_PORT: u16 = 5353;
/// The IPv4 multicast DNS group.
pub const MDNS_GROUP_V4: Ipv4Addr = Ipv4Addr::new(224, 0, 0, 251);
/// The version of the TXT layout below (`txtvers`, RFC 6763 section 6.7).
pub const TXT_VERSION: u32 = 1;
/// TXT key: the layout version.
pub const TXT_KEY_VERSION: &str = "txtvers";
/// TXT key: the sync protocol version the peer speaks.
pub const TXT_KEY_PROTOCOL: &str = "proto";
/// TXT key: the session's discovery id, in hex.
pub const TXT_KEY_SESSION: &str = "session";
/// TXT key: the session's display name.
pub const TXT_KEY_NAME: &str = "name";
/// TXT key: the announcing peer's full id, in hex.
pub const TXT_KEY_PEER: &str = "peer";
/// TXT key: how many peers the announcing peer is connected to.
pub const TXT_KEY_PEERS: &str = "peers";
/// The longest session display name, in bytes of UTF-8.
pub const MAX_SESSION_NAME_BYTES: usize = 64;
/// The longest host name kept from the network (the DNS limit).
pub const MAX_HOST_BYTES: usize = 255;
/// How many announced instances the browser keeps. A new one beyond it takes the place of
/// the least recently announced instance that proved nothing (see [`DnsSd::note_admitted`]):
/// another session's first when it is of ours, never one of ours when it is another's.
pub const MAX_LAN_SESSIONS: usize = 256;
/// How many announced instances the browser keeps whose first address is one IP: a new one
/// beyond it takes the place of that address's least recently announced instance that proved
/// nothing, so one host cannot fill the table with made-up instances, while several peers on
/// one host (tests, a shared machine) are all kept.
pub const MAX_LAN_SESSIONS_PER_ADDRESS: usize = 16;
/// How many addresses the browser keeps per instance; more are dropped and counted.
pub const MAX_ADDRS_PER_SESSION: usize = 8;
/// How many peers one call of [`DnsSd::peers_to_dial`] returns at most.
pub const MAX_DIALS_PER_ROUND: usize = 16;
/// How many browse events one [`DnsSd::poll`] handles at most (the rest wait for the next).
pub const MAX_EVENTS_PER_POLL: usize = 1_024;
/// The shortest time between two announcements of a changed peer count.
pub const MIN_PEER_COUNT_UPDATE_MICROS: u64 = 2_000_000;
/// How often [`announce_and_dial`] drains browse events.
pub const POLL_INTERVAL_MILLIS: u64 = 250;
/// How often [`announce_and_dial`] updates the peer count and dials the session's peers.
pub const DIAL_INTERVAL_MILLIS: u64 = 1_000;

/// Where and how to run multicast DNS.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DnsSdConfig {
    /// The UDP port of multicast DNS: [`MDNS_PORT`] except in tests that want their own.
    pub port: u16,
    /// Whether to announce and browse on IPv6 interfaces too. Off by default: nodes listen on
    /// IPv4, so IPv6 addresses would be announced but not dialable.
    pub ipv6: bool,
}

impl Default for DnsSdConfig {
    fn default() -> Self {
        Self {
            port: MDNS_PORT,
            ipv6: false,
        }
    }
}

/// What this peer announces.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Announcement {
    /// The session, as discovery sees it.
    pub discovery_id: DiscoveryId,
    /// The session's display name, chosen by a person: at most [`MAX_SESSION_NAME_BYTES`]
    /// bytes, no control characters.
    pub session_name: String,
    /// This peer's id.
    pub peer: PeerId,
    /// The node's QUIC address (`NodeHandle::local_addr`): its port is announced, and so is its
    /// IP unless it is unspecified, in which case every interface's address is.
    pub quic_addr: SocketAddr,
    /// How many peers this peer is connected to.
    pub n_peers: u16,
}

/// One peer's announcement of a session, as the browser last saw it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LanSession {
    /// The DNS-SD instance's full name, e.g. `sculpt-1a2b3c4d._sculpt._udp.local.`: the key
    /// under which announcements are deduplicated.
    pub instance: String,
    /// The session, as discovery sees it.
    pub discovery_id: DiscoveryId,
    /// The session's display name (bounded, no control characters).
    pub name: String,
    /// The announcing host's mDNS name, e.g. `sculpt-1a2b3c4d.local.`.
    pub host: String,
    /// The addresses to dial, IPv4 first, at most [`MAX_ADDRS_PER_SESSION`].
    pub addrs: Vec<SocketAddr>,
    /// The announcing peer's claimed id (proven only at admission).
    pub peer: PeerId,
    /// How many peers the announcing peer said it is connected to.
    pub n_peers: u16,
    /// The sync protocol version the peer said it speaks.
    pub protocol_version: u64,
}

/// Counters of what the browser saw.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DnsSdStats {
    /// Announcements (new or updated) accepted into the table.
    pub n_resolved: u64,
    /// Instances removed (goodbye, or their records expired).
    pub n_removed: u64,
    /// Announcements dropped for a missing, oversized or malformed TXT value, host or address.
    pub n_malformed: u64,
    /// Announcements of another TXT layout version (ignored).
    pub n_other_versions: u64,
    /// New instances dropped because the table (or their address's share of it) held
    /// [`MAX_LAN_SESSIONS`] ([`MAX_LAN_SESSIONS_PER_ADDRESS`]) and none they may displace.
    pub n_over_limit: u64,
    /// Instances displaced by a new one over [`MAX_LAN_SESSIONS`] or
    /// [`MAX_LAN_SESSIONS_PER_ADDRESS`].
    pub n_displaced: u64,
    /// Instances of our session proven by a connection admitted at their address.
    pub n_proven: u64,
    /// Addresses dropped beyond [`MAX_ADDRS_PER_SESSION`].
    pub n_addrs_dropped: u64,
    /// Times the browse subscription ended (the daemon drops one that falls behind) and was
    /// made again.
    pub n_resubscribed: u64,
    /// Times this peer's announcement was registered (first, renamed or a new peer count).
    pub n_announced: u64,
}

/// Why DNS-SD could not start, announce or browse.
#[derive(Debug, thiserror::Error)]
pub enum DnsSdError {
    /// The kernel will not join the multicast DNS group (no route for it, and on Linux no
    /// non-loopback interface that does IPv4 multicast: a host with loopback only), or its
    /// port cannot be shared.
    #[error(
        "multicast DNS is unavailable here: cannot join 224.0.0.251 ({0}), so LAN sessions can \
         be neither announced nor found"
    )]
    MulticastUnavailable(io::Error),
    /// The session name is longer than [`MAX_SESSION_NAME_BYTES`].
    #[error("the session name is {len} bytes long; at most {MAX_SESSION_NAME_BYTES} are announced")]
    NameTooLong {
        /// Its length in bytes.
        len: usize,
    },
    /// The session name holds a control character.
    #[error("the session name holds a control character")]
    NameHasControl,
    /// The mDNS daemon refused a command (its message).
    #[error("the mDNS daemon failed: {0}")]
    Daemon(String),
    /// The mDNS daemon thread has stopped.
    #[error("the mDNS daemon has stopped")]
    Stopped,
}

impl From<mdns_sd::Error> for DnsSdError {
    fn from(e: mdns_sd::Error) -> Self {
        match e {
            mdns_sd::Error::DaemonShutdown => Self::Stopped,
            other => Self::Daemon(other.to_string()),
        }
    }
}

/// What is registered for this peer.
#[derive(Debug)]
struct Announced {
    announcement: Announcement,
    fullname: String,
    /// When the current registration was made.
    at: Timestamp,
}

/// One peer's multicast DNS announcer and browser.
pub struct DnsSd {
    daemon: ServiceDaemon,
    events: Receiver<ServiceEvent>,
    announced: Option<Announced>,
    /// The peer count to announce once the rate limit allows.
    wanted_n_peers: Option<u16>,
    table: SessionTable,
    stats: DnsSdStats,
    dial_round: u64,
}

impl fmt::Debug for DnsSd {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("DnsSd")
            .field("announced", &self.announced)
            .field("n_sessions", &self.table.by_instance.len())
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl DnsSd {
    /// Checks that this host can join the multicast DNS group, starts the `mdns-sd` daemon
    /// thread and starts browsing [`SERVICE_TYPE`].
    ///
    /// Fails with [`DnsSdError::MulticastUnavailable`] where the kernel can join
    /// [`MDNS_GROUP_V4`] neither by route nor (on Linux) on a non-loopback interface that does
    /// IPv4 multicast (a host or namespace with loopback only), or the port cannot be shared,
    /// rather than running a daemon that can reach no one. It does not promise the opposite:
    /// an interface that is up without an IPv4 address passes, and finds no one.
    pub fn start(config: DnsSdConfig) -> Result<Self, DnsSdError> {
        check_multicast(config.port).map_err(DnsSdError::MulticastUnavailable)?;
        let daemon = ServiceDaemon::new_with_port(config.port)?;
        if !config.ipv6 {
            daemon.disable_interface(IfKind::IPv6)?;
        }
        let events = daemon.browse(SERVICE_TYPE)?;
        Ok(Self {
            daemon,
            events,
            announced: None,
            wanted_n_peers: None,
            table: SessionTable::default(),
            stats: DnsSdStats::default(),
            dial_round: 0,
        })
    }

    /// Announces this peer (or changes what it announces): a new registration replaces the
    /// previous one of the same instance, which browsers see as an update.
    pub fn announce(
        &mut self,
        announcement: Announcement,
        now: Timestamp,
    ) -> Result<(), DnsSdError> {
        check_session_name(&announcement.session_name)?;
        let info = service_info(&announcement)?;
        let fullname = info.get_fullname().to_owned();
        if let Some(old) = &self.announced
            && old.fullname != fullname
        {
            let _ = self.daemon.unregister(&old.fullname)?;
        }
        self.daemon.register(info)?;
        self.stats.n_announced += 1;
        self.wanted_n_peers = None;
        self.announced = Some(Announced {
            announcement,
            fullname,
            at: now,
        });
        Ok(())
    }

    /// Sets the announced peer count. The TXT record is registered again at most once per
    /// [`MIN_PEER_COUNT_UPDATE_MICROS`]: a change within that time waits for a later call
    /// (call this periodically, as [`announce_and_dial`] does). Returns whether it announced.
    pub fn update_n_peers(&mut self, n_peers: u16, now: Timestamp) -> Result<bool, DnsSdError> {
        let Some(announced) = &self.announced else {
            return Ok(false);
        };
        if announced.announcement.n_peers == n_peers {
            self.wanted_n_peers = None;
            return Ok(false);
        }
        self.wanted_n_peers = Some(n_peers);
        if !update_allowed(announced.at, now) {
            return Ok(false);
        }
        let mut announcement = announced.announcement.clone();
        announcement.n_peers = n_peers;
        self.announce(announcement, now)?;
        Ok(true)
    }

    /// The peer count that waits for the rate limit, if any.
    pub fn pending_n_peers(&self) -> Option<u16> {
        self.wanted_n_peers
    }

    /// What this peer announces, if anything.
    pub fn announcement(&self) -> Option<&Announcement> {
        self.announced.as_ref().map(|a| &a.announcement)
    }

    /// Withdraws this peer's announcement (browsers see a goodbye).
    pub fn withdraw(&mut self) -> Result<(), DnsSdError> {
        if let Some(old) = self.announced.take() {
            let _ = self.daemon.unregister(&old.fullname)?;
        }
        self.wanted_n_peers = None;
        Ok(())
    }

    /// Handles the browse events that have arrived, without blocking; returns whether the
    /// table of sessions changed. A subscription the daemon ended is made again.
    pub fn poll(&mut self) -> Result<bool, DnsSdError> {
        let mut changed = false;
        for _ in 0..MAX_EVENTS_PER_POLL {
            match self.events.try_recv() {
                Ok(event) => changed |= self.handle_event(event),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => {
                    self.events = self.daemon.browse(SERVICE_TYPE)?;
                    self.stats.n_resubscribed += 1;
                    break;
                }
            }
        }
        Ok(changed)
    }

    /// Every announced instance on the link, this peer's own included, in instance-name order.
    pub fn sessions(&self) -> impl Iterator<Item = &LanSession> {
        self.table.by_instance.values().map(|held| &held.session)
    }

    /// A dial of `dialed` (from [`DnsSd::peers_to_dial`]) was admitted: whoever answered at the
    /// instance's address holds the invite. Such an instance is never displaced by unproven
    /// ones while it stays announced.
    pub fn note_admitted(&mut self, dialed: &DiscoveredPeer) {
        self.table.note_admitted(dialed, &mut self.stats);
    }

    /// The counters.
    pub fn stats(&self) -> &DnsSdStats {
        &self.stats
    }

    /// The other peers of session `discovery_id` that speak this build's sync protocol, with
    /// one address each of `local`'s family (rotating through an instance's addresses from one
    /// call to the next, so an unreachable first address does not hide the others), at most
    /// [`MAX_DIALS_PER_ROUND`], none of them in `skip` (the peers connected or being dialed,
    /// so that a round's places go to peers that need a dial, however many the session has).
    /// This peer's own announcement is skipped.
    pub fn peers_to_dial(
        &mut self,
        discovery_id: DiscoveryId,
        local: SocketAddr,
        skip: &BTreeSet<PeerId>,
    ) -> Vec<DiscoveredPeer> {
        let own = self.announced.as_ref().map(|a| a.announcement.peer);
        let round = self.dial_round;
        self.dial_round = self.dial_round.wrapping_add(1);
        self.table
            .peers_to_dial(discovery_id, own, local, round, skip)
    }

    fn handle_event(&mut self, event: ServiceEvent) -> bool {
        match event {
            ServiceEvent::ServiceResolved(resolved) => match parse_resolved(&resolved) {
                Ok((session, n_addrs_dropped)) => {
                    self.stats.n_addrs_dropped += n_addrs_dropped;
                    let ours = self.announced.as_ref().map(|a| a.announcement.discovery_id);
                    self.table.insert(session, ours, &mut self.stats)
                }
                Err(Malformed::OtherVersion) => {
                    self.stats.n_other_versions += 1;
                    false
                }
                Err(Malformed::Bad) => {
                    self.stats.n_malformed += 1;
                    false
                }
            },
            ServiceEvent::ServiceRemoved(_, fullname) => {
                let removed = (self.table.by_instance)
                    .remove(&fullname.to_lowercase())
                    .is_some();
                self.stats.n_removed += u64::from(removed);
                removed
            }
            _ => false,
        }
    }
}

/// The browser's bounded table of announced instances.
#[derive(Debug, Default)]
struct SessionTable {
    /// Keyed by the lower-case instance name (DNS names are case-insensitive).
    by_instance: BTreeMap<String, Held>,
    /// Counts announcements taken: what `Held::seen` is measured in.
    n_seen: u64,
}

/// One instance in the table.
#[derive(Debug)]
struct Held {
    session: LanSession,
    /// When it was last announced (in `SessionTable::n_seen`).
    seen: u64,
    /// A connection dialed at its address was admitted ([`DnsSd::note_admitted`]).
    proven: bool,
}

impl Held {
    fn ip(&self) -> Option<std::net::IpAddr> {
        self.session.addrs.first().map(SocketAddr::ip)
    }
}

impl SessionTable {
    /// Adds or updates an instance; returns whether the table changed. A new instance beyond
    /// [`MAX_LAN_SESSIONS_PER_ADDRESS`] or [`MAX_LAN_SESSIONS`] takes the place of the least
    /// recently announced instance that proved nothing (at its address, or anywhere): one of
    /// another session first when the new one is of `ours`, and never one of `ours` when it is
    /// not, so neither strangers nor made-up instances of our own session crowd out a real
    /// peer of ours, and the new one is never refused while one it may displace is unproven.
    fn insert(
        &mut self,
        session: LanSession,
        ours: Option<DiscoveryId>,
        stats: &mut DnsSdStats,
    ) -> bool {
        let key = session.instance.to_lowercase();
        self.n_seen += 1;
        if let Some(held) = self.by_instance.get_mut(&key) {
            stats.n_resolved += 1;
            held.seen = self.n_seen;
            let changed = held.session != session;
            held.session = session;
            return changed;
        }
        let is_ours = |s: &LanSession| ours == Some(s.discovery_id);
        let new_is_ours = is_ours(&session);
        // The least recently announced unproven instance among `candidates` the new one may
        // displace (another session's first, when the new one is of ours).
        let victim = |candidates: &mut dyn Iterator<Item = (&String, &Held)>| {
            candidates
                .filter(|(_, h)| !h.proven && (new_is_ours || !is_ours(&h.session)))
                .min_by_key(|(_, h)| (is_ours(&h.session), h.seen))
                .map(|(k, _)| k.clone())
        };
        let ip = session.addrs.first().map(SocketAddr::ip);
        let at_address = |h: &&Held| ip.is_some() && h.ip() == ip;
        let n_at_address = self.by_instance.values().filter(at_address).count();
        let displaced = if n_at_address >= MAX_LAN_SESSIONS_PER_ADDRESS {
            let mut candidates = self.by_instance.iter().filter(|(_, h)| at_address(h));
            Some(victim(&mut candidates))
        } else if self.by_instance.len() >= MAX_LAN_SESSIONS {
            Some(victim(&mut self.by_instance.iter()))
        } else {
            None
        };
        match displaced {
            Some(None) => {
                stats.n_over_limit += 1;
                return false;
            }
            Some(Some(victim)) => {
                self.by_instance.remove(&victim);
                stats.n_displaced += 1;
            }
            None => {}
        }
        stats.n_resolved += 1;
        let held = Held {
            session,
            seen: self.n_seen,
            proven: false,
        };
        self.by_instance.insert(key, held);
        assert!(
            self.by_instance.len() <= MAX_LAN_SESSIONS,
            "the session table is bounded"
        );
        true
    }

    /// See [`DnsSd::note_admitted`]: marks the instances of `dialed`'s peer that list its
    /// address.
    fn note_admitted(&mut self, dialed: &DiscoveredPeer, stats: &mut DnsSdStats) {
        for held in self.by_instance.values_mut() {
            let listed =
                held.session.peer == dialed.peer && held.session.addrs.contains(&dialed.addr);
            if listed && !held.proven {
                held.proven = true;
                stats.n_proven += 1;
            }
        }
    }

    /// See [`DnsSd::peers_to_dial`]; `round` picks the address.
    fn peers_to_dial(
        &self,
        discovery_id: DiscoveryId,
        own: Option<PeerId>,
        local: SocketAddr,
        round: u64,
        skip: &BTreeSet<PeerId>,
    ) -> Vec<DiscoveredPeer> {
        let mut found: Vec<DiscoveredPeer> = Vec::new();
        for session in self.by_instance.values().map(|held| &held.session) {
            if session.discovery_id != discovery_id
                || session.protocol_version != PROTOCOL_VERSION
                || Some(session.peer) == own
                || skip.contains(&session.peer)
                || found.iter().any(|d| d.peer == session.peer)
            {
                continue;
            }
            let addrs: Vec<SocketAddr> = session
                .addrs
                .iter()
                .copied()
                .filter(|a| a.is_ipv4() == local.is_ipv4())
                .collect();
            let Some(n_addrs) = u64::try_from(addrs.len()).ok().filter(|&n| n > 0) else {
                continue;
            };
            let addr_idx = usize::try_from(round % n_addrs).unwrap_or(0);
            found.push(DiscoveredPeer {
                peer: session.peer,
                addr: addrs[addr_idx],
            });
            if found.len() == MAX_DIALS_PER_ROUND {
                break;
            }
        }
        found
    }
}

impl Drop for DnsSd {
    fn drop(&mut self) {
        // Say goodbye first (the daemon handles commands in order), then stop its thread,
        // which would otherwise outlive us.
        let _ = self.withdraw();
        let _ = self.daemon.shutdown();
    }
}

/// Lists the LAN's sessions while `node` runs, and once `shared` says so, announces
/// `announcement` and keeps it true: every [`DIAL_INTERVAL_MILLIS`], and at once when the node
/// hears a remote after a silence ([`NodeHandle::resumed`]), it announces the node's peer
/// count (rate-limited) and dials the peers of its session that it found; every
/// [`POLL_INTERVAL_MILLIS`] it reads the LAN and publishes every announced instance on
/// `sessions` when that changed. A session not shared yet (a solo window) browses only: it
/// is neither announced nor does it dial. Returns the counters when the node stops, and
/// withdraws the announcement (dropping `dnssd`).
pub async fn announce_and_dial<P: Payload + Send + 'static>(
    mut dnssd: DnsSd,
    node: NodeHandle<P>,
    announcement: Announcement,
    shared: watch::Receiver<bool>,
    sessions: watch::Sender<Vec<LanSession>>,
) -> Result<DnsSdStats, DnsSdError> {
    let discovery_id = announcement.discovery_id;
    let mut announcement = Some(announcement);
    let mut poll_tick = tokio::time::interval(Duration::from_millis(POLL_INTERVAL_MILLIS));
    let mut dial_tick = tokio::time::interval(Duration::from_millis(DIAL_INTERVAL_MILLIS));
    let mut dialing = DialsUnderWay::new();
    let mut resumed = node.resumed();
    loop {
        let fresh = tokio::select! {
            _ = poll_tick.tick() => {
                if dnssd.poll()? {
                    sessions.send_replace(dnssd.sessions().cloned().collect());
                }
                continue;
            }
            _ = dial_tick.tick() => false,
            Ok(()) = resumed.changed() => true,
        };
        let Ok(connected) = node.connected_peers().await else {
            return Ok(dnssd.stats().clone());
        };
        if *shared.borrow()
            && let Some(a) = announcement.take()
        {
            dnssd.announce(a, wall_clock_now())?;
        }
        if announcement.is_some() {
            continue;
        }
        let peers: BTreeSet<PeerId> = connected.into_iter().map(|(_, p)| p).collect();
        let n_peers = u16::try_from(peers.len()).unwrap_or(u16::MAX);
        dnssd.update_n_peers(n_peers, wall_clock_now())?;
        if fresh {
            drop_waiting_dials(&mut dialing, Instant::now());
        }
        dial_round(&mut dnssd, &node, discovery_id, &peers, &mut dialing).await;
    }
}

/// The finder's dials under way, one task per peer, each with when it began and answering
/// with the address that admitted it.
type DialsUnderWay = BTreeMap<PeerId, (Instant, tokio::task::JoinHandle<Option<DiscoveredPeer>>)>;

/// A round of dials: the instances whose address admitted a finished dial are proven, and
/// every peer of the session neither `connected` nor being dialed is dialed on a task of its
/// own, so a dial waiting out its handshake (an instance gone without a goodbye) holds up no
/// other. Failures are the node's to count (admission refusals, timeouts); a later round
/// dials again, at the instance's next address.
async fn dial_round<P: Payload + Send + 'static>(
    dnssd: &mut DnsSd,
    node: &NodeHandle<P>,
    discovery_id: DiscoveryId,
    connected: &BTreeSet<PeerId>,
    dialing: &mut DialsUnderWay,
) {
    let finished: Vec<PeerId> = (dialing.iter())
        .filter(|(_, (_, dial))| dial.is_finished())
        .map(|(peer, _)| *peer)
        .collect();
    for peer in finished {
        if let Some((_, dial)) = dialing.remove(&peer)
            && let Ok(Some(dialed)) = dial.await
        {
            dnssd.note_admitted(&dialed);
        }
    }
    let busy: BTreeSet<PeerId> = connected.iter().chain(dialing.keys()).copied().collect();
    for found in dnssd.peers_to_dial(discovery_id, node.local_addr(), &busy) {
        let node = node.clone();
        let dial = tokio::spawn(async move {
            let outcomes = node.dial_discovered(&[found]).await;
            (outcomes.into_iter()).find_map(|(dialed, outcome)| outcome.is_ok().then_some(dialed))
        });
        dialing.insert(found.peer, (Instant::now(), dial));
    }
}

/// On a sign that the network is back ([`NodeHandle::resumed`]): aborts and forgets the dials
/// begun at least [`MIN_REDIAL_HANDSHAKE_MICROS`] before `now` and still waiting, so that the
/// next round dials those peers afresh (the dial under way in the node goes on until its own
/// timeout; one admitted late only duplicates the connection a fresh dial made, which the
/// node settles). Finished dials stay for the round to read their outcome.
fn drop_waiting_dials(dialing: &mut DialsUnderWay, now: Instant) {
    let waited = Duration::from_micros(MIN_REDIAL_HANDSHAKE_MICROS);
    dialing.retain(|_, (began, dial)| {
        let replace = now.saturating_duration_since(*began) >= waited && !dial.is_finished();
        if replace {
            dial.abort();
        }
        !replace
    });
}

/// Whether a registration made at `at` may be replaced at `now` ([`MIN_PEER_COUNT_UPDATE_MICROS`];
/// a clock that went back allows it, rather than freezing the count).
fn update_allowed(at: Timestamp, now: Timestamp) -> bool {
    now.0 < at.0 || now.0 - at.0 >= MIN_PEER_COUNT_UPDATE_MICROS
}

/// Joins the group once on a throwaway socket that shares the port the daemon will bind: the
/// daemon itself skips interfaces it cannot join and would run deaf and mute. The kernel joins
/// by route; without one (a LAN without a default gateway), on Linux, by each non-loopback
/// interface that does IPv4 multicast, as the daemon will.
fn check_multicast(port: u16) -> io::Result<()> {
    let socket = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))?;
    socket.set_reuse_address(true)?;
    socket.bind(&SocketAddr::from((Ipv4Addr::UNSPECIFIED, port)).into())?;
    let Err(routed) = socket.join_multicast_v4(&MDNS_GROUP_V4, &Ipv4Addr::UNSPECIFIED) else {
        return Ok(());
    };
    let joined_one = multicast_interface_indexes().into_iter().any(|if_index| {
        let interface = InterfaceIndexOrAddress::Index(if_index);
        socket
            .join_multicast_v4_n(&MDNS_GROUP_V4, &interface)
            .is_ok()
    });
    if joined_one { Ok(()) } else { Err(routed) }
}

/// The most bytes read from `/proc/net/igmp`.
#[cfg(target_os = "linux")]
const MAX_IGMP_TABLE_BYTES: u64 = 64 * 1024;

/// The indexes of the non-loopback interfaces where the kernel does IPv4 multicast: those
/// `/proc/net/igmp` lists (each has joined the all-hosts group).
#[cfg(target_os = "linux")]
fn multicast_interface_indexes() -> Vec<u32> {
    use std::io::Read;
    let mut table = String::new();
    let read = std::fs::File::open("/proc/net/igmp")
        .and_then(|f| f.take(MAX_IGMP_TABLE_BYTES).read_to_string(&mut table));
    if read.is_err() {
        return Vec::new();
    }
    // Interface lines are "<index>\t<name> : <count> <querier>"; group lines start blank.
    table
        .lines()
        .filter_map(|line| {
            let mut fields = line.split_whitespace();
            let if_index: u32 = fields.next()?.parse().ok()?;
            let name = fields.next().filter(|name| !name.contains('/'))?;
            let flags = std::fs::read_to_string(format!("/sys/class/net/{name}/flags")).ok();
            let flags =
                flags.and_then(|f| u32::from_str_radix(f.trim().trim_start_matches("0x"), 16).ok());
            let loopback = flags.map_or(name == "lo", |f| f & IFF_LOOPBACK != 0);
            (!loopback).then_some(if_index)
        })
        .collect()
}

/// Linux's `IFF_LOOPBACK` interface flag.
#[cfg(target_os = "linux")]
const IFF_LOOPBACK: u32 = 0x8;

#[cfg(not(target_os = "linux"))]
fn multicast_interface_indexes() -> Vec<u32> {
    Vec::new()
}

fn check_session_name(name: &str) -> Result<(), DnsSdError> {
    if name.len() > MAX_SESSION_NAME_BYTES {
        return Err(DnsSdError::NameTooLong { len: name.len() });
    }
    if name.chars().any(char::is_control) {
        return Err(DnsSdError::NameHasControl);
    }
    Ok(())
}

/// The instance (and host) label of a peer: `sculpt-` and its short id.
pub fn instance_name(peer: &PeerId) -> String {
    format!("sculpt-{}", peer.short())
}

/// The TXT records of an announcement, in the order they are sent.
pub fn txt_records(announcement: &Announcement) -> Vec<(&'static str, String)> {
    vec![
        (TXT_KEY_VERSION, TXT_VERSION.to_string()),
        (TXT_KEY_PROTOCOL, PROTOCOL_VERSION.to_string()),
        (TXT_KEY_SESSION, hex(&announcement.discovery_id)),
        (TXT_KEY_NAME, announcement.session_name.clone()),
        (TXT_KEY_PEER, hex(&announcement.peer.0)),
        (TXT_KEY_PEERS, announcement.n_peers.to_string()),
    ]
}

fn service_info(announcement: &Announcement) -> Result<ServiceInfo, DnsSdError> {
    let label = instance_name(&announcement.peer);
    // The host name is ours alone: announcing the machine's own name would contend with the
    // system's responder (avahi) for its address records.
    let host = format!("{label}.local.");
    let txt = txt_records(announcement);
    let ip = announcement.quic_addr.ip();
    let port = announcement.quic_addr.port();
    let info = if ip.is_unspecified() {
        ServiceInfo::new(SERVICE_TYPE, &label, &host, (), port, txt.as_slice())?.enable_addr_auto()
    } else {
        ServiceInfo::new(SERVICE_TYPE, &label, &host, ip, port, txt.as_slice())?
    };
    Ok(info)
}

/// Why an announcement was not taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Malformed {
    /// Another TXT layout version: not ours to read.
    OtherVersion,
    /// Missing, oversized or malformed.
    Bad,
}

/// Reads a resolved instance: the session and the number of addresses dropped.
fn parse_resolved(resolved: &ResolvedService) -> Result<(LanSession, u64), Malformed> {
    let addrs = resolved
        .get_addresses()
        .iter()
        .map(|ip| scoped_addr(ip, resolved.get_port()));
    parse_parts(
        resolved.get_fullname(),
        resolved.get_hostname(),
        resolved.get_port(),
        addrs,
        resolved.get_properties(),
    )
}

fn scoped_addr(ip: &ScopedIp, port: u16) -> SocketAddr {
    match ip {
        ScopedIp::V6(v6) if v6.addr().segments()[0] & 0xffc0 == 0xfe80 => {
            SocketAddr::V6(SocketAddrV6::new(*v6.addr(), port, 0, v6.scope_id().index))
        }
        other => SocketAddr::new(other.to_ip_addr(), port),
    }
}

fn parse_parts(
    fullname: &str,
    host: &str,
    port: u16,
    addrs: impl Iterator<Item = SocketAddr>,
    txt: &TxtProperties,
) -> Result<(LanSession, u64), Malformed> {
    let version: u32 = parse_decimal(txt_value(txt, TXT_KEY_VERSION)?, 10)?;
    if version != TXT_VERSION {
        return Err(Malformed::OtherVersion);
    }
    if !fullname.to_lowercase().ends_with(SERVICE_TYPE) || fullname.len() > MAX_HOST_BYTES {
        return Err(Malformed::Bad);
    }
    if host.is_empty() || host.len() > MAX_HOST_BYTES || port == 0 {
        return Err(Malformed::Bad);
    }
    let protocol_version: u64 = parse_decimal(txt_value(txt, TXT_KEY_PROTOCOL)?, 20)?;
    let discovery_id: [u8; DISCOVERY_ID_BYTES] = parse_hex(txt_value(txt, TXT_KEY_SESSION)?)?;
    let peer = PeerId(parse_hex::<PEER_ID_BYTES>(txt_value(txt, TXT_KEY_PEER)?)?);
    let n_peers: u16 = parse_decimal(txt_value(txt, TXT_KEY_PEERS)?, 5)?;
    let name = txt_value(txt, TXT_KEY_NAME)?;
    if name.len() > MAX_SESSION_NAME_BYTES {
        return Err(Malformed::Bad);
    }
    let name = std::str::from_utf8(name).map_err(|_| Malformed::Bad)?;
    if name.chars().any(char::is_control) {
        return Err(Malformed::Bad);
    }
    let mut addrs: Vec<SocketAddr> = addrs.collect();
    // IPv4 before IPv6, then by address, so that the choice of address is deterministic.
    addrs.sort_unstable_by_key(|a| (a.is_ipv6(), *a));
    addrs.dedup();
    let n_dropped = addrs.len().saturating_sub(MAX_ADDRS_PER_SESSION);
    addrs.truncate(MAX_ADDRS_PER_SESSION);
    if addrs.is_empty() {
        return Err(Malformed::Bad);
    }
    let session = LanSession {
        instance: fullname.to_owned(),
        discovery_id,
        name: name.to_owned(),
        host: host.to_owned(),
        addrs,
        peer,
        n_peers,
        protocol_version,
    };
    Ok((session, u64::try_from(n_dropped).unwrap_or(u64::MAX)))
}

/// The value of `key`, which must be present with a value.
fn txt_value<'t>(txt: &'t TxtProperties, key: &str) -> Result<&'t [u8], Malformed> {
    txt.get(key).and_then(|p| p.val()).ok_or(Malformed::Bad)
}

/// A decimal of at most `max_digits` ASCII digits that fits `T`.
fn parse_decimal<T: std::str::FromStr>(value: &[u8], max_digits: usize) -> Result<T, Malformed> {
    if value.is_empty() || value.len() > max_digits || !value.iter().all(u8::is_ascii_digit) {
        return Err(Malformed::Bad);
    }
    std::str::from_utf8(value)
        .ok()
        .and_then(|s| s.parse().ok())
        .ok_or(Malformed::Bad)
}

/// Exactly `N` bytes written as `2 N` hex digits, either case.
fn parse_hex<const N: usize>(value: &[u8]) -> Result<[u8; N], Malformed> {
    if value.len() != 2 * N {
        return Err(Malformed::Bad);
    }
    let digit = |c: u8| char::from(c).to_digit(16).ok_or(Malformed::Bad);
    let mut out = [0; N];
    for (byte, pair) in out.iter_mut().zip(value.chunks_exact(2)) {
        let (hi, lo) = (digit(pair[0])?, digit(pair[1])?);
        *byte = u8::try_from(hi * 16 + lo).map_err(|_| Malformed::Bad)?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use mdns_sd::{IntoTxtProperties, TxtProperty};

    use super::*;

    const ID: DiscoveryId = [7; DISCOVERY_ID_BYTES];

    fn announcement(name: &str) -> Announcement {
        Announcement {
            discovery_id: ID,
            session_name: name.into(),
            peer: PeerId([0xab; PEER_ID_BYTES]),
            quic_addr: "127.0.0.1:4433".parse().unwrap(),
            n_peers: 3,
        }
    }

    fn txt(pairs: &[(&str, &[u8])]) -> TxtProperties {
        pairs
            .iter()
            .map(|(k, v)| TxtProperty::from((*k, *v)))
            .collect::<Vec<_>>()
            .into_txt_properties()
    }

    fn good_txt() -> Vec<(&'static str, Vec<u8>)> {
        txt_records(&announcement("melon"))
            .into_iter()
            .map(|(k, v)| (k, v.into_bytes()))
            .collect()
    }

    fn parse_with(pairs: &[(&'static str, Vec<u8>)]) -> Result<(LanSession, u64), Malformed> {
        let pairs: Vec<(&str, &[u8])> = pairs.iter().map(|(k, v)| (*k, v.as_slice())).collect();
        parse_parts(
            "sculpt-abababab._sculpt._udp.local.",
            "sculpt-abababab.local.",
            4433,
            ["127.0.0.1:4433".parse().unwrap()].into_iter(),
            &txt(&pairs),
        )
    }

    fn with(key: &'static str, value: &[u8]) -> Vec<(&'static str, Vec<u8>)> {
        let mut pairs = good_txt();
        for (k, v) in &mut pairs {
            if *k == key {
                *v = value.to_vec();
            }
        }
        pairs
    }

    #[test]
    fn announced_txt_round_trips() {
        let (session, n_dropped) = parse_with(&good_txt()).unwrap();
        assert_eq!(n_dropped, 0);
        assert_eq!(session.discovery_id, ID);
        assert_eq!(session.name, "melon");
        assert_eq!(session.peer, PeerId([0xab; PEER_ID_BYTES]));
        assert_eq!(session.n_peers, 3);
        assert_eq!(session.protocol_version, PROTOCOL_VERSION);
        assert_eq!(session.host, "sculpt-abababab.local.");
    }

    #[test]
    fn malformed_txt_values_are_refused_without_panicking() {
        let long_name = vec![b'x'; MAX_SESSION_NAME_BYTES + 1];
        let cases: Vec<Vec<(&'static str, Vec<u8>)>> = vec![
            with(TXT_KEY_SESSION, b"zz"),
            with(TXT_KEY_SESSION, &[b'0'; 2 * DISCOVERY_ID_BYTES + 2]),
            with(TXT_KEY_SESSION, "é".repeat(DISCOVERY_ID_BYTES).as_bytes()),
            with(TXT_KEY_PEER, &[b'g'; 2 * PEER_ID_BYTES]),
            with(TXT_KEY_PEERS, b"70000"),
            with(TXT_KEY_PEERS, b"-1"),
            with(TXT_KEY_PEERS, b"00000000000000000001"),
            with(TXT_KEY_PROTOCOL, b""),
            with(TXT_KEY_NAME, &long_name),
            with(TXT_KEY_NAME, &[0xff, 0xfe]),
            with(TXT_KEY_NAME, b"bell\x07"),
            good_txt()
                .into_iter()
                .filter(|(k, _)| *k != TXT_KEY_PEER)
                .collect(),
        ];
        for pairs in cases {
            assert_eq!(parse_with(&pairs).err(), Some(Malformed::Bad), "{pairs:?}");
        }
        assert_eq!(
            parse_with(&with(TXT_KEY_VERSION, b"2")).err(),
            Some(Malformed::OtherVersion)
        );
        let (session, _) = parse_with(&with(TXT_KEY_PEERS, b"65535")).unwrap();
        assert_eq!(session.n_peers, u16::MAX);
    }

    #[test]
    fn names_are_bounded_before_they_are_announced() {
        let long = "é".repeat(MAX_SESSION_NAME_BYTES / 2 + 1);
        assert!(matches!(
            check_session_name(&long),
            Err(DnsSdError::NameTooLong { len }) if len == MAX_SESSION_NAME_BYTES + 2
        ));
        assert!(matches!(
            check_session_name("a\nb"),
            Err(DnsSdError::NameHasControl)
        ));
        assert!(check_session_name("Alice's melon 🍉").is_ok());
        // Every TXT string of the longest name fits the 255-byte limit of one string.
        let mut longest = announcement(&"x".repeat(MAX_SESSION_NAME_BYTES));
        longest.n_peers = u16::MAX;
        for (key, value) in txt_records(&longest) {
            assert!(key.len() + 1 + value.len() <= 255, "{key}");
        }
        assert!(service_info(&longest).is_ok());
    }

    #[test]
    fn addresses_are_sorted_deduplicated_and_bounded() {
        let addrs: Vec<SocketAddr> = (0..20u8)
            .rev()
            .map(|i| SocketAddr::from(([10, 0, 0, i], 4433)))
            .chain([
                "[fe80::1%2]:4433".parse().unwrap(),
                "10.0.0.3:4433".parse().unwrap(),
            ])
            .collect();
        let pairs = good_txt();
        let pairs: Vec<(&str, &[u8])> = pairs.iter().map(|(k, v)| (*k, v.as_slice())).collect();
        let (session, n_dropped) = parse_parts(
            "a._sculpt._udp.local.",
            "a.local.",
            4433,
            addrs.into_iter(),
            &txt(&pairs),
        )
        .unwrap();
        assert_eq!(session.addrs.len(), MAX_ADDRS_PER_SESSION);
        assert_eq!(session.addrs[0], "10.0.0.0:4433".parse().unwrap());
        assert_eq!(
            n_dropped,
            21 - u64::try_from(MAX_ADDRS_PER_SESSION).unwrap()
        );
    }

    fn lan_session(instance_idx: usize, discovery_id: DiscoveryId, peer: u8) -> LanSession {
        LanSession {
            instance: format!("sculpt-{instance_idx:04}.{SERVICE_TYPE}"),
            discovery_id,
            name: "melon".into(),
            host: format!("sculpt-{instance_idx:04}.local."),
            addrs: vec![
                SocketAddr::from(([10, 0, 0, peer], 4433)),
                SocketAddr::from(([10, 0, 1, peer], 4433)),
                "[fe80::1%2]:4433".parse().unwrap(),
            ],
            peer: PeerId([peer; PEER_ID_BYTES]),
            n_peers: 0,
            protocol_version: PROTOCOL_VERSION,
        }
    }

    #[test]
    fn the_table_is_bounded_and_strangers_cannot_crowd_out_our_session() {
        let (mut table, mut stats) = (SessionTable::default(), DnsSdStats::default());
        let stranger = [9; DISCOVERY_ID_BYTES];
        for idx in 0..MAX_LAN_SESSIONS {
            assert!(table.insert(lan_session_at(idx, stranger, 9), Some(ID), &mut stats));
        }
        // An update of a known instance is taken; an unchanged one changes nothing.
        let mut updated = lan_session_at(0, stranger, 9);
        updated.n_peers = 5;
        assert!(table.insert(updated.clone(), Some(ID), &mut stats));
        assert!(!table.insert(updated, Some(ID), &mut stats));
        // One more stranger displaces the stranger announced least recently; so does one of
        // ours.
        assert!(table.insert(lan_session_at(9_000, stranger, 9), Some(ID), &mut stats));
        assert!(
            !table
                .by_instance
                .contains_key(&lan_session(1, stranger, 9).instance)
        );
        assert!(table.insert(lan_session(9_001, ID, 1), Some(ID), &mut stats));
        assert_eq!(stats.n_displaced, 2);
        assert_eq!(table.by_instance.len(), MAX_LAN_SESSIONS);
        assert_eq!(n_of(&table, ID), 1);
        // Strangers never displace one of ours.
        for idx in 0..2 * MAX_LAN_SESSIONS {
            table.insert(
                lan_session_at(10_000 + idx, stranger, 9),
                Some(ID),
                &mut stats,
            );
        }
        assert_eq!(n_of(&table, ID), 1);
    }

    /// Instance `instance_idx` of `discovery_id` with an address of its own.
    fn lan_session_at(instance_idx: usize, discovery_id: DiscoveryId, peer: u8) -> LanSession {
        let [_, _, hi, lo] = u32::try_from(instance_idx).unwrap().to_be_bytes();
        LanSession {
            addrs: vec![SocketAddr::from(([10, 9, hi, lo], 4433))],
            ..lan_session(instance_idx, discovery_id, peer)
        }
    }

    /// How many instances of `discovery_id` the table holds.
    fn n_of(table: &SessionTable, discovery_id: DiscoveryId) -> usize {
        (table.by_instance.values())
            .filter(|h| h.session.discovery_id == discovery_id)
            .count()
    }

    /// Issue 49: made-up instances claiming our own discovery id filled the table (256 of
    /// them), and a real peer of ours announced next was dropped: there was no stranger to
    /// displace. A new instance now displaces the least recently announced one that proved
    /// nothing, and one whose address admitted a dial is never displaced.
    #[test]
    fn made_up_instances_of_our_session_cannot_crowd_out_a_real_peer_of_ours() {
        let (mut table, mut stats) = (SessionTable::default(), DnsSdStats::default());
        for idx in 0..MAX_LAN_SESSIONS {
            assert!(table.insert(lan_session_at(idx, ID, 7), Some(ID), &mut stats));
        }
        let real = lan_session(5_000, ID, 1);
        assert!(table.insert(real.clone(), Some(ID), &mut stats));
        assert!(table.by_instance.contains_key(&real.instance));
        assert_eq!(stats.n_displaced, 1);
        // It is dialed and admits; made-up instances keep coming, and it stays.
        let dialed =
            table.peers_to_dial(ID, None, "0.0.0.0:1".parse().unwrap(), 0, &BTreeSet::new());
        let real_dialed = dialed.iter().find(|d| d.peer == real.peer).unwrap();
        table.note_admitted(real_dialed, &mut stats);
        assert_eq!(stats.n_proven, 1);
        for idx in 0..2 * MAX_LAN_SESSIONS {
            table.insert(lan_session_at(1_000 + idx, ID, 7), Some(ID), &mut stats);
        }
        assert!(table.by_instance.contains_key(&real.instance));
        assert_eq!(table.by_instance.len(), MAX_LAN_SESSIONS);
        // A second real peer announced now still gets in.
        let second = lan_session(6_000, ID, 2);
        assert!(table.insert(second.clone(), Some(ID), &mut stats));
        assert!(table.by_instance.contains_key(&second.instance));
    }

    /// One host's made-up instances hold at most its address's share of the table, whichever
    /// session they claim, so a peer on another host is never displaced by them.
    #[test]
    fn one_address_holds_at_most_its_share_of_the_table() {
        let (mut table, mut stats) = (SessionTable::default(), DnsSdStats::default());
        let real = lan_session(5_000, ID, 1);
        assert!(table.insert(real.clone(), Some(ID), &mut stats));
        for idx in 0..2 * MAX_LAN_SESSIONS {
            assert!(table.insert(lan_session(idx, ID, 7), Some(ID), &mut stats));
        }
        assert_eq!(table.by_instance.len(), 1 + MAX_LAN_SESSIONS_PER_ADDRESS);
        assert!(
            table.by_instance.contains_key(&real.instance),
            "never proven, still kept"
        );
    }

    #[test]
    fn dialing_picks_our_session_one_address_of_our_family_at_a_time() {
        let (mut table, mut stats) = (SessionTable::default(), DnsSdStats::default());
        let mut old = lan_session(3, ID, 3);
        old.protocol_version = PROTOCOL_VERSION + 1;
        for session in [
            lan_session(0, ID, 0xab),
            lan_session(1, ID, 1),
            lan_session(2, [9; DISCOVERY_ID_BYTES], 2),
            old,
        ] {
            table.insert(session, Some(ID), &mut stats);
        }
        let local: SocketAddr = "0.0.0.0:1".parse().unwrap();
        let own = Some(PeerId([0xab; PEER_ID_BYTES]));
        let none = BTreeSet::new();
        let first = table.peers_to_dial(ID, own, local, 0, &none);
        let second = table.peers_to_dial(ID, own, local, 1, &none);
        let peer_1 = PeerId([1; PEER_ID_BYTES]);
        assert_eq!(
            first,
            vec![DiscoveredPeer {
                peer: peer_1,
                addr: "10.0.0.1:4433".parse().unwrap()
            }]
        );
        assert_eq!(second[0].addr, "10.0.1.1:4433".parse().unwrap());
        let v6 = table.peers_to_dial(ID, own, "[::]:1".parse().unwrap(), 0, &none);
        assert_eq!(v6[0].addr, "[fe80::1%2]:4433".parse().unwrap());
    }

    /// A round dials at most `MAX_DIALS_PER_ROUND` peers. It used to pick them among every
    /// peer of the session, connected or not, always in the table's order, so in a session of
    /// more than that many other peers the ones after them were never dialed by anyone whose
    /// table put them there. The peers connected or being dialed are now skipped.
    #[test]
    fn rounds_reach_every_peer_of_a_large_session() {
        let (mut table, mut stats) = (SessionTable::default(), DnsSdStats::default());
        let n = 2 * MAX_DIALS_PER_ROUND + 3;
        for idx in 0..n {
            let peer = u8::try_from(idx + 1).unwrap();
            assert!(table.insert(lan_session_at(idx, ID, peer), Some(ID), &mut stats));
        }
        let local: SocketAddr = "0.0.0.0:1".parse().unwrap();
        let mut busy = BTreeSet::new();
        for round in 0..3 {
            let found = table.peers_to_dial(ID, None, local, round, &busy);
            assert!(!found.is_empty() && found.len() <= MAX_DIALS_PER_ROUND);
            assert!(found.iter().all(|d| !busy.contains(&d.peer)), "{found:?}");
            // Each round's dials are under way (or admitted) at the next.
            busy.extend(found.iter().map(|d| d.peer));
        }
        assert_eq!(busy.len(), n, "every peer of the session was dialed");
    }

    #[test]
    fn peer_count_updates_are_rate_limited() {
        let at = Timestamp(10_000_000);
        assert!(!update_allowed(at, at));
        assert!(!update_allowed(
            at,
            Timestamp(at.0 + MIN_PEER_COUNT_UPDATE_MICROS - 1)
        ));
        assert!(update_allowed(
            at,
            Timestamp(at.0 + MIN_PEER_COUNT_UPDATE_MICROS)
        ));
        assert!(update_allowed(at, Timestamp(at.0 - 1)));
    }

    /// A round the node's sign of the network's return brought replaces the finder's dials
    /// that have waited for a handshake since before the shortest handshake allowance, and
    /// leaves younger ones, which may still be getting through, to finish.
    #[test]
    fn a_fresh_round_replaces_only_the_dials_that_waited() {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_time()
            .build()
            .unwrap();
        runtime.block_on(async {
            let now = Instant::now();
            let waited = Duration::from_micros(MIN_REDIAL_HANDSHAKE_MICROS);
            let mut dialing = DialsUnderWay::new();
            for (seed, began) in [(1, now - waited), (2, now - waited / 2), (3, now)] {
                let dial = tokio::spawn(std::future::pending::<Option<DiscoveredPeer>>());
                dialing.insert(PeerId([seed; PEER_ID_BYTES]), (began, dial));
            }
            // An old dial that has finished keeps its outcome for the round to read.
            let done = tokio::spawn(async { None::<DiscoveredPeer> });
            tokio::task::yield_now().await;
            assert!(done.is_finished());
            dialing.insert(PeerId([4; PEER_ID_BYTES]), (now - waited, done));
            let old = dialing[&PeerId([1; PEER_ID_BYTES])].1.abort_handle();
            drop_waiting_dials(&mut dialing, now);
            let kept: Vec<u8> = dialing.keys().map(|p| p.0[0]).collect();
            assert_eq!(kept, vec![2, 3, 4]);
            tokio::task::yield_now().await;
            assert!(old.is_finished(), "the replaced dial's task is aborted");
            let waiting = |p: u8| !dialing[&PeerId([p; PEER_ID_BYTES])].1.is_finished();
            assert!(waiting(2) && waiting(3));
        });
    }

    #[test]
    fn hex_decoding_is_exact() {
        assert_eq!(parse_hex::<2>(b"0aFf"), Ok([0x0a, 0xff]));
        assert_eq!(parse_hex::<2>(b"0aF"), Err(Malformed::Bad));
        assert_eq!(parse_hex::<1>(b"+1"), Err(Malformed::Bad));
        assert_eq!(
            hex(&parse_hex::<16>(hex(&ID).as_bytes()).unwrap()),
            hex(&ID)
        );
    }
}
