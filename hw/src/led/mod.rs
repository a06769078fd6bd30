//! LED pulse controller: protocol, host driver, device emulator.
//!
//! The controller (an ATmega328P board running `hw/firmware/`, or the
//! [`emulator`]) drives up to four LEDs with square waves whose phase is
//! referenced to a trigger (software command or an input edge such as the
//! camera's exposure-active output). The wire protocol is specified in
//! `hw/firmware/PROTOCOL.md`.

pub mod driver;
pub mod emulator;
pub mod protocol;

pub use driver::{available_ports, ChannelSync, LedController, LedError, LedSync, LinkOptions, PortInfo, DEFAULT_BAUD};
pub use emulator::{Device, Emulator, Identity, LinkedEmulator};
pub use protocol::{ChannelConfig, ChannelConfigError, ChannelReadback, DeviceInfo, DeviceStatus, ErrorCode, RunState, TriggerMode};
