//! The LED controller: host driver and emulator over a pseudo-terminal, the protocol
//! vectors shared with the firmware, and property tests of the protocol. One test
//! binary (`cargo test -p rollcam-hw --test led`).

mod led_pty;
mod led_vectors;
mod properties;
