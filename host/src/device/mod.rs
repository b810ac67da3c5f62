//! Device control: talking to meb luminaires over USB serial, and a virtual luminaire.
//!
//! * [`discovery`]: which serial ports are luminaires (USB IDs and product string).
//! * [`transport`]: the byte link, a `serialport` port with deadlines.
//! * [`pty`]: a raw pseudo-terminal pair the virtual luminaire serves on.
//!
//! The wire format, the configuration and the luminaire's behaviour all come from the
//! `protocol` crate (issue 2), so the host, the firmware and the emulator cannot disagree.

pub mod discovery;
pub mod pty;
pub mod transport;

pub use discovery::{USB_PID, USB_PRODUCT, USB_VID};
