//! Device control: talking to meb luminaires over USB serial, and a virtual luminaire.
//!
//! * [`discovery`]: which serial ports are luminaires (USB IDs and strings).
//! * [`transport`]: the byte link, a `serialport` port with deadlines.
//! * [`pty`]: a raw pseudo-terminal pair the virtual luminaire serves on (Unix).
//! * [`client`]: [`DeviceClient`], one method per protocol command, retries and typed errors.
//! * [`settings`]: a configuration from what a user asks for, and the IEEE 1789 check.
//! * [`storage`]: the emulator's record file standing in for flash.
//! * [`timeline`]: the light a luminaire emits, recorded, as a waveform for the simulator.
//! * [`emulator`]: [`VirtualLuminaire`], the protocol's state machine served on a pty (Unix).
//!
//! The wire format, the configuration, the USB identity and the luminaire's behaviour all come
//! from the `protocol` crate, so the host, the firmware and the emulator cannot disagree.

#![deny(missing_docs)]

pub mod client;
pub mod discovery;
#[cfg(unix)]
pub mod emulator;
#[cfg(unix)]
pub mod pty;
pub mod settings;
pub mod storage;
pub mod timeline;
pub mod transport;

pub use client::{DeviceClient, DeviceError, Timeouts};
pub use discovery::{USB_MANUFACTURER, USB_PID, USB_PRODUCT, USB_VID};
#[cfg(unix)]
pub use emulator::{EmulatorOptions, VirtualLuminaire};
pub use timeline::{Timeline, TimelineWaveform};
