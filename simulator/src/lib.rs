//! Deterministic multi-peer simulation of sculpt replication over a modelled network, driven by
//! one seeded RNG and a virtual clock.
//!
//! It is not a benchmark of real sockets: it runs the real sans-IO core
//! ([`replication::Peer`] over [`replication::shape::ShapePayload`]) over a simulated link.
//!
//! - [`config`]: a run (seed, peers, ops, [`config::Faults`] preset, hostile peer, planted bug)
//!   and the command line that replays it.
//! - [`sim`]: the event queue ordered by (virtual time, sequence number), the network model
//!   (per-link latency, jitter, loss, duplication, reordering, partitions including
//!   asymmetric ones, peers offline and back) and the hostile peer; then the checkers.
//! - [`workload`]: scripted users drawn from the RNG.
//! - [`report::Report`]: counters, convergence after healing, trace hash, failures.
//!
//! ```
//! use simulator::config::{Config, Faults};
//! let faults = Faults::named("lan").unwrap();
//! let report = simulator::sim::run(Config::new(1, 3, 40, faults)).unwrap();
//! assert!(report.passed(), "{report}");
//! ```
#![warn(missing_docs)]

pub mod config;
pub mod report;
pub mod rng;
pub mod sim;
pub mod trace;
pub mod workload;
