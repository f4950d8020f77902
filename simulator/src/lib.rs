//! Deterministic multi-peer simulation of sculpt replication over a modelled network, driven by
//! one seeded RNG and a virtual clock.
//!
//! It is not a benchmark of real sockets: it runs the real sans-IO core
//! ([`replication::Peer`] over [`replication::shape::ShapePayload`]) over a simulated link
//! and disk.
//!
//! - [`config`]: a run (seed, peers, ops, [`config::Faults`] preset less the switched-off
//!   [`config::FaultKind`]s, hostile peer, planted bug, kept actions) and the command line
//!   that replays it.
//! - [`sim`]: the event queue ordered by (virtual time, sequence number), the network model
//!   (per-link latency, jitter, loss, duplication, bandwidth, partitions including asymmetric
//!   ones, peers offline and back), crashes, late joins (empty, or from a snapshot: `join.rs`),
//!   and the hostile member's traffic; it drives the modules below, which never name it.
//!   Each honest peer is an `honest::Honest` (the real core, its scene, user and disk);
//!   [`session`]: the session they join; [`store`]: the disk (fsync delays, crash images
//!   recovered by the real store); [`hostile`]: garbage, replays, forged and member-authored
//!   ops, floods; [`byzantine`]: a hostile member running the real core and crafting attacks.
//! - [`workload`]: scripted users as a list of [`workload::Action`]s drawn up front.
//! - Checkers (`check.rs`, run on what a run ended with): convergence, causal delivery, scene
//!   folds, the [`reference`](mod@reference) lease rules, durable and lost ops, forged ops, rate
//!   limits, and [`memory`] per peer (a counting allocator).
//! - [`report::Report`]: counters, convergence after healing, memory, op sizes, samples;
//!   [`plots`]: PNG plots; [`shrink`]: failing runs cut down to small reproducers.
//!
//! ```
//! use simulator::config::{Config, Faults};
//! let faults = Faults::named("lan").unwrap();
//! let report = simulator::sim::run(Config::new(1, 3, 40, faults)).unwrap();
//! assert!(report.passed(), "{report}");
//! ```
#![warn(missing_docs)]

pub mod byzantine;
mod check;
pub mod config;
mod honest;
pub mod hostile;
mod join;
pub mod memory;
pub mod plots;
pub mod reference;
pub mod report;
pub mod rng;
pub mod session;
pub mod shrink;
pub mod sim;
pub mod store;
pub mod trace;
pub mod workload;
