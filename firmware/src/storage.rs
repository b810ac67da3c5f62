//! Configuration persistence: the protocol's config record ([`protocol::record`]) stored under one
//! key of a sequential-storage map on flash sectors 6–7 ([`crate::board::CONFIG_FLASH`]).
//!
//! sequential-storage appends every save and only erases a 128 KiB sector when a page is full
//! (hundreds of saves apart), CRC-checks its items and repairs a half-written page after a power
//! loss. On top of that the record carries its own magic, version and CRC, and is validated on
//! load: a missing record boots the factory defaults ([`RestoredConfig::Missing`]), an unreadable
//! or invalid one the defaults as well, reported as [`RestoredConfig::Corrupt`] in `GetStatus`.
//!
//! A save that erases stalls the CPU for 2 s typically, 4 s at most (single-bank flash, x8
//! erase parallelism: `protocol::flash`); the carriers keep playing
//! from DMA meanwhile (see [`crate::chips`]), and the state machine has already answered
//! `SaveConfig` with `Deferred`: the outcome shows up in `GetStatus.save`.

use embassy_stm32::flash::{Async, Flash};
use protocol::config::LuminaireConfig;
use protocol::luminaire::RestoredConfig;
use protocol::record::{MAX_RECORD_LEN, decode_record, encode_record};

const _: () = assert!(
    ITEM_BUFFER > MAX_RECORD_LEN,
    "the item buffer holds a record"
);
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};

use crate::board::CONFIG_FLASH;

/// The map key of the configuration record.
const CONFIG_KEY: u8 = 0;
/// Scratch for one map item: key, record, padding to the flash word (the size
/// `protocol::flash` budgets a save's programming time for).
const ITEM_BUFFER: usize = protocol::flash::SAVE_ITEM_BYTES;

type ConfigMap = MapStorage<u8, Flash<'static, Async>, Cache<Uncached, Uncached, Uncached, u8>>;

/// Why a save failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum SaveError {
    /// The record did not encode.
    Encode,
    /// sequential-storage or the flash reported an error.
    Flash,
}

/// The configuration store on the MCU's own flash.
pub struct ConfigStore {
    map: ConfigMap,
    buffer: [u8; ITEM_BUFFER],
}

impl ConfigStore {
    /// A store over `flash`, using [`CONFIG_FLASH`].
    pub fn new(flash: Flash<'static, Async>) -> Self {
        Self {
            map: MapStorage::new(flash, MapConfig::new(CONFIG_FLASH), Cache::new_uncached()),
            buffer: [0; ITEM_BUFFER],
        }
    }

    /// Reads the stored configuration: valid record, none, or corrupt.
    pub async fn restore(&mut self) -> RestoredConfig {
        match self
            .map
            .fetch_item::<&[u8]>(&mut self.buffer, &CONFIG_KEY)
            .await
        {
            // An item under our key that does not decode is corruption, even without the magic
            // (the protocol maps a bare BadMagic to Missing for files and raw flash).
            Ok(Some(bytes)) => match decode_record(bytes) {
                Ok(stored) if stored.without_depth() => RestoredConfig::WithoutDepth(stored.config),
                Ok(stored) => RestoredConfig::Ok(stored.config),
                Err(error) => {
                    defmt::warn!("stored config unusable: {}", error);
                    RestoredConfig::Corrupt
                }
            },
            Ok(None) => RestoredConfig::Missing,
            Err(error) => {
                defmt::warn!("config storage unreadable: {}", error);
                RestoredConfig::Corrupt
            }
        }
    }

    /// Writes `config` as the new record.
    pub async fn save(&mut self, config: &LuminaireConfig) -> Result<(), SaveError> {
        let mut record = [0u8; MAX_RECORD_LEN];
        let bytes = encode_record(config, &mut record).map_err(|_| SaveError::Encode)?;
        self.map
            .store_item(&mut self.buffer, &CONFIG_KEY, &bytes)
            .await
            .map_err(|error| {
                defmt::warn!("config save failed: {}", error);
                SaveError::Flash
            })
    }
}
