//! The luminaire's chip engine as data: every register value the firmware writes to play the
//! MEB-FDMA carriers (docs/maths/carriers.md#playing-the-table-on-a-luminaire) on an STM32F411,
//! computed here, host-tested, and only carried out
//! by the board.
//!
//! * [`regs`]: addresses and fields from the reference manual RM0383.
//! * [`outputs`]: which timer channel plays which LED; each bank's timer, DMA stream, trigger.
//! * [`step`]: a plan as plain data ([`step::Step`]) and its one interpreter over a [`step::Bus`].
//! * [`plan`]: the plans (clocks, halt, start, chip interrupt, watchdog) and the
//!   [`plan::ChipEngine`] that sequences them with the frame buffers.
//! * `register_model` (tests only): TIM2, TIM3, TIM5 and DMA1 modelled from RM0383's
//!   descriptions, executing the plans; `cargo test register_model` runs it.
//! * `vendor_check` (tests only): every address, field and value of [`regs`] and the pin and
//!   DMA tables of [`outputs`] against ST's register descriptions as stm32-metapac ships them;
//!   `cargo test vendor` runs it.
//!
//! `no_std`, no unsafe code, nothing of embassy: the firmware supplies a [`step::Bus`] that
//! reads and writes the addresses, the tests supply the model.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod outputs;
pub mod plan;
pub mod regs;
pub mod step;

#[cfg(test)]
mod register_model;
#[cfg(test)]
mod vendor_check;
