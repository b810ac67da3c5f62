//! The virtual luminaire's "flash": one file holding a `protocol::record` configuration record.
//!
//! Writes go to a temporary file in the same directory, are synced, then renamed over the
//! record, so a crash mid-save leaves either the old or the new record, never half of one —
//! the same guarantee the firmware's flash page gives. Restarting the emulator on the same file
//! is a power cycle: the luminaire boots from what this store returns.

use std::io::{self, Write};
use std::path::{Path, PathBuf};

use protocol::config::LuminaireConfig;
use protocol::luminaire::RestoredConfig;
use protocol::record::{MAX_RECORD_LEN, RecordError, decode_record, encode_record};

/// Error writing the record.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StorageError {
    /// The configuration does not fit a record (cannot happen for a valid one).
    #[error("cannot encode the configuration record")]
    Encode(#[source] RecordError),
    /// The file could not be written or renamed.
    #[error("cannot write {path}")]
    Io {
        /// The record file.
        path: PathBuf,
        /// What failed.
        #[source]
        source: io::Error,
    },
}

/// A configuration record file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigStore {
    path: PathBuf,
}

impl ConfigStore {
    /// A store at `path` (the file need not exist yet).
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self { path: path.into() }
    }

    /// The record file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What the luminaire boots from: the stored config, `Missing`, or `Corrupt`.
    pub fn load(&self) -> RestoredConfig {
        match std::fs::read(&self.path) {
            Ok(bytes) => decode_record(&bytes).into(),
            Err(err) if err.kind() == io::ErrorKind::NotFound => RestoredConfig::Missing,
            Err(_) => RestoredConfig::Corrupt,
        }
    }

    /// Writes `config` atomically (temporary file, sync, rename).
    pub fn save(&self, config: &LuminaireConfig) -> Result<(), StorageError> {
        let mut buf = [0u8; MAX_RECORD_LEN];
        let record = encode_record(config, &mut buf).map_err(StorageError::Encode)?;
        let io_err = |source| StorageError::Io {
            path: self.path.clone(),
            source,
        };
        let mut temp_name = self.path.file_name().unwrap_or_default().to_os_string();
        temp_name.push(".tmp");
        let temp = self.path.with_file_name(temp_name);
        let mut file = std::fs::File::create(&temp).map_err(io_err)?;
        file.write_all(record).map_err(io_err)?;
        file.sync_all().map_err(io_err)?;
        drop(file);
        std::fs::rename(&temp, &self.path).map_err(io_err)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::config::ChipRate;

    #[test]
    fn save_then_load_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let store = ConfigStore::new(dir.path().join("luminaire.rec"));
        assert_eq!(store.load(), RestoredConfig::Missing);
        let mut config = LuminaireConfig::DEFAULT;
        config.led_count = 3;
        config.chip_rate = ChipRate(959_500);
        config.brightness_permille[1] = 800;
        store.save(&config).unwrap();
        assert_eq!(store.load(), RestoredConfig::Ok(config));
        assert!(!dir.path().join("luminaire.rec.tmp").exists());
    }

    #[test]
    fn damaged_file_is_corrupt_not_defaults() {
        let dir = tempfile::tempdir().unwrap();
        let store = ConfigStore::new(dir.path().join("luminaire.rec"));
        store.save(&LuminaireConfig::DEFAULT).unwrap();
        let mut bytes = std::fs::read(store.path()).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 0xff;
        std::fs::write(store.path(), &bytes).unwrap();
        assert_eq!(store.load(), RestoredConfig::Corrupt);
        std::fs::write(store.path(), &bytes[..5]).unwrap();
        assert_eq!(store.load(), RestoredConfig::Corrupt);
    }
}
