//! Deterministic multi-peer simulation of sculpt replication over a modelled network, driven by
//! one seeded RNG and a virtual clock.
//!
//! It is not a benchmark of real sockets: it runs the real sans-IO core over a simulated link.
#![warn(missing_docs)]
