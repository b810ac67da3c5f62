//! The contract between the meb luminaire firmware and the host.
//!
//! * [`bringup`]: the wiring check without instruments (`meb device blink`).
//! * [`carriers`]: MEB-FDMA chip tables (docs/maths/carriers.md#the-carrier-table).
//! * [`config`]: the luminaire configuration and its validation.
//! * [`wire`]: header, request/response command table and payload types.
//! * [`framing`]: COBS + CRC-32 framing, the streaming [`framing::FrameReader`].
//! * [`record`]: the persisted configuration record (flash and emulator file).
//! * [`flicker`]: IEEE 1789 flicker limits of a configuration, the one acceptance function.
//! * [`flash`]: how long a save can stall the board; the watchdog and host waits derived from it.
//! * [`luminaire`]: the hardware-free state machine and [`luminaire::Endpoint`] that both the
//!   firmware and `meb device emulate` run.
//! * [`timing`]: the chip timer and brightness PWM arithmetic.
//! * [`usb`]: the USB identity the firmware enumerates with and the host looks for.
//!
//! `no_std` and allocation-free; the `std` feature adds `std::error::Error` impls for the host,
//! the `defmt` feature adds `defmt::Format` derives for the firmware's logs.
#![cfg_attr(not(any(feature = "std", test)), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod bringup;
pub mod carriers;
pub mod checksum;
pub mod config;
pub mod flash;
pub mod flicker;
pub mod framing;
pub mod luminaire;
pub mod record;
pub mod timing;
pub mod usb;
pub mod wire;
