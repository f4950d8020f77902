//! The collaboration core of sculpt: a replicated log of signed operations, their causal order,
//! per-object leases and a sans-IO sync protocol, plus storage and transport adapters.
//!
//! It is not a network server and not a scene editor: the core takes time and randomness as
//! arguments and never touches sockets, files, clocks or threads.
#![warn(missing_docs)]
