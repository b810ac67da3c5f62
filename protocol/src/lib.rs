//! The contract between the meb luminaire firmware and the host.
//!
//! * [`carriers`]: MEB-FDMA chip tables (SPEC §2).
//!
//! `no_std` and allocation-free; the `std` feature adds `std::error::Error` impls for the host,
//! the `defmt` feature adds `defmt::Format` derives for the firmware's logs.
#![cfg_attr(not(feature = "std"), no_std)]
#![deny(missing_docs)]

pub mod carriers;
pub mod timing;
