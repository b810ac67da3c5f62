//! How long saving a configuration can stall the luminaire, and the waits derived from it: the
//! watchdog period (`chip_plan::plan::WATCHDOG_MIN_TIMEOUT_MS`) and the host's patience around a
//! save ([`HOST_STALL_MS`], [`HOST_SAVE_TIMEOUT_MS`]). One place, so the firmware and the host
//! cannot drift apart.
//!
//! The firmware keeps its configuration in a sequential-storage map on two 128 KiB sectors of
//! the F411's single-bank flash. A save programs one record and, once every several hundred
//! saves, first erases one sector. The CPU runs from the same flash, so it stalls (no USB, no
//! watchdog feeding) while the erase runs.
//!
//! The erase time depends on the program/erase parallelism, FLASH_CR.PSIZE at the moment STRT is
//! set. embassy-stm32 0.6.0's F4 driver (`src/flash/f4.rs`, the version in `Cargo.lock`) sets
//! PSIZE = x32 only for word programming (`enable_write` writes FLASH_CR whole with PG and
//! PSIZE32) and clears it again afterwards (`disable_write` writes FLASH_CR whole, PSIZE = 00,
//! as after reset); its sector erase (`erase_sector`) modifies SER/SNB/STRT and leaves PSIZE
//! alone. Every erase therefore runs at x8.
//!
//! STM32F411xC/E datasheet (DS10314 Rev 8), §6.3.12, Table 45 "Flash memory programming"
//! (T_A = −40 to 125 °C; maxima evaluated by characterisation, not tested in production):
//!
//! ```text
//! t_ERASE128KB   PSIZE x8: typ 2 s, max 4 s;  x16: 1.3 s, 2.6 s;  x32: 1 s, 2 s
//! t_prog (word)  PSIZE x8/16/32: typ 16 µs, max 100 µs (max measured after 100 k erases)
//! ```

use crate::record::MAX_RECORD_LEN;

/// Program/erase parallelism (bits) of the firmware's sector erases: x8, see the module docs.
pub const ERASE_PARALLELISM_BITS: u32 = 8;

/// Longest erase of one 128 KiB sector at [`ERASE_PARALLELISM_BITS`] (DS10314 Table 45,
/// maximum of t_ERASE128KB at x8; typical 2 s).
pub const SECTOR_ERASE_MAX_MS: u32 = 4_000;

/// Longest programming of one 32-bit word (DS10314 Table 45, maximum of t_prog; typical 16 µs).
pub const WORD_PROGRAM_MAX_US: u32 = 100;

/// Bytes programmed by one save at most: the item (key, record, sequential-storage's item
/// header and CRC, padding; the firmware's item buffer) and 64 bytes of page and item state
/// markers.
pub const SAVE_PROGRAM_BYTES_MAX: u32 = SAVE_ITEM_BYTES as u32 + 64;

/// Scratch the firmware needs for one stored item: the record and 32 bytes for
/// sequential-storage's key, header, CRC and word padding.
pub const SAVE_ITEM_BYTES: usize = MAX_RECORD_LEN + 32;

/// Sector erases one save can trigger at most (the map erases the next page when the current
/// one is full).
pub const ERASES_PER_SAVE_MAX: u32 = 1;

/// Longest the CPU can stall in one save: the erases plus programming every word.
pub const SAVE_STALL_MAX_MS: u32 = ERASES_PER_SAVE_MAX * SECTOR_ERASE_MAX_MS
    + (SAVE_PROGRAM_BYTES_MAX / 4 * WORD_PROGRAM_MAX_US).div_ceil(1000);

/// Margin on [`SAVE_STALL_MAX_MS`] for every wait derived from it, in percent: covers what the
/// datasheet maximum does not (flash wear beyond its cycling figure, interrupt and USB
/// re-enumeration latency after the stall).
pub const STALL_MARGIN_PERCENT: u32 = 50;

/// The stall budget every derived wait starts from: [`SAVE_STALL_MAX_MS`] plus
/// [`STALL_MARGIN_PERCENT`].
pub const STALL_BUDGET_MS: u32 = SAVE_STALL_MAX_MS * (100 + STALL_MARGIN_PERCENT) / 100;

/// How long the host keeps retransmitting a request around a save before it gives up: the
/// luminaire may be silent for the whole stall.
pub const HOST_STALL_MS: u32 = STALL_BUDGET_MS;

/// How long the host waits for a deferred save to complete: the stall budget plus 2 s for the
/// status requests around it.
pub const HOST_SAVE_TIMEOUT_MS: u32 = STALL_BUDGET_MS + 2_000;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stall_budget_numbers() {
        // One 4 s erase at x8 plus (128 + 32 + 64) / 4 = 56 words at 100 µs (5.6 ms).
        assert_eq!(SAVE_ITEM_BYTES, 160);
        assert_eq!(SAVE_PROGRAM_BYTES_MAX, 224);
        assert_eq!(SAVE_STALL_MAX_MS, 4_006);
        // 50 % margin: 6 s of silence the host and the watchdog must outlast.
        assert_eq!(STALL_BUDGET_MS, 6_009);
        assert_eq!(HOST_STALL_MS, 6_009);
        assert_eq!(HOST_SAVE_TIMEOUT_MS, 8_009);
        // x8 is the slowest parallelism: twice the x32 maximum of 2 s.
        assert_eq!((ERASE_PARALLELISM_BITS, SECTOR_ERASE_MAX_MS), (8, 4_000));
    }
}
