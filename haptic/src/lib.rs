//! Haptic rendering of fdsl scenes: force computation from compiled shape snapshots, the 1 kHz
//! servo loop, and haptic devices behind one trait.
//!
//! It never sees the op log; it reads immutable scene snapshots handed over by the app.
#![warn(missing_docs)]
