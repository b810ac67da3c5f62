//! Persisted configuration record, used by the firmware's flash page and the host emulator's
//! storage file alike.
//!
//! Layout (little-endian): `b"MEBC"` magic, `u16` record version, `u16` payload length,
//! postcard([`LuminaireConfig`]), CRC-32/ISO-HDLC of everything before it. Bytes after the
//! record (erased flash) are ignored. Decoding yields either a valid configuration or an error,
//! never a half-valid configuration.
//!
//! Versions: 2 (written now) is the configuration with per-LED off levels and the flicker
//! acceptance; 1, written before the off level was a setting, holds the first five fields only
//! and is read as off level 0 (full on/off keying, what it played) without the acceptance, and
//! reported as such ([`StoredConfig::without_depth`]).

use crate::checksum::CRC32;
use crate::config::{ConfigError, LuminaireConfig};

/// Record magic.
pub const RECORD_MAGIC: [u8; 4] = *b"MEBC";
/// Current record layout version.
pub const RECORD_VERSION: u16 = 2;
/// The layout before off levels: LED count, rate, brightness, phases, running.
pub const RECORD_VERSION_WITHOUT_DEPTH: u16 = 1;
/// Bytes before the payload: magic, version, length.
pub const RECORD_HEADER_LEN: usize = 8;
/// Largest record in bytes (header, payload, CRC).
pub const MAX_RECORD_LEN: usize = 128;

/// Why a record could not be written or read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RecordError {
    /// The output buffer is too small.
    BufferFull,
    /// Shorter than its header or declared length.
    Truncated,
    /// The magic is wrong (e.g. erased flash).
    BadMagic,
    /// A record version this firmware does not know.
    UnknownVersion(u16),
    /// The CRC does not match.
    BadCrc,
    /// The payload does not decode as a configuration.
    Malformed,
    /// The decoded configuration fails validation.
    Invalid(ConfigError),
}

impl core::fmt::Display for RecordError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BufferFull => f.write_str("record buffer too small"),
            Self::Truncated => f.write_str("record truncated"),
            Self::BadMagic => f.write_str("no config record (bad magic)"),
            Self::UnknownVersion(v) => write!(f, "unknown record version {v}"),
            Self::BadCrc => f.write_str("record CRC mismatch"),
            Self::Malformed => f.write_str("record payload malformed"),
            Self::Invalid(e) => write!(f, "stored config invalid: {e}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for RecordError {}

/// The configuration of a version-1 record (the fields of [`LuminaireConfig`] before off
/// levels), in its postcard order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ConfigWithoutDepth {
    /// Number of LEDs.
    pub led_count: u8,
    /// Chip rate.
    pub chip_rate: crate::config::ChipRate,
    /// Per-LED brightness in per mille.
    pub brightness_permille: [u16; crate::carriers::MAX_LEDS],
    /// Per-LED phase in chips.
    pub phase_chips: [u16; crate::carriers::MAX_LEDS],
    /// Whether the carriers were playing.
    pub running: bool,
}

impl ConfigWithoutDepth {
    /// The configuration it played: off chips dark, flicker not accepted.
    pub fn upgraded(&self) -> LuminaireConfig {
        LuminaireConfig {
            led_count: self.led_count,
            chip_rate: self.chip_rate,
            brightness_permille: self.brightness_permille,
            phase_chips: self.phase_chips,
            running: self.running,
            off_level_permille: [0; crate::carriers::MAX_LEDS],
            allow_flicker: false,
        }
    }
}

/// A configuration read from a record and the record's layout version.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StoredConfig {
    /// The (valid) configuration.
    pub config: LuminaireConfig,
    /// [`RECORD_VERSION`] or [`RECORD_VERSION_WITHOUT_DEPTH`].
    pub version: u16,
}

impl StoredConfig {
    /// Whether the record predates off levels (read as off level 0).
    pub fn without_depth(&self) -> bool {
        self.version == RECORD_VERSION_WITHOUT_DEPTH
    }
}

/// Writes the record for `config` into `buf`; returns the record bytes.
pub fn encode_record<'a>(
    config: &LuminaireConfig,
    buf: &'a mut [u8],
) -> Result<&'a [u8], RecordError> {
    encode_versioned(RECORD_VERSION, config, buf)
}

fn encode_versioned<'a, T: serde::Serialize>(
    version: u16,
    config: &T,
    buf: &'a mut [u8],
) -> Result<&'a [u8], RecordError> {
    if buf.len() < RECORD_HEADER_LEN {
        return Err(RecordError::BufferFull);
    }
    let (head, tail) = buf.split_at_mut(RECORD_HEADER_LEN);
    let payload_len = postcard::to_slice(config, tail)
        .map_err(|_| RecordError::BufferFull)?
        .len();
    let length = u16::try_from(payload_len).map_err(|_| RecordError::BufferFull)?;
    head[..4].copy_from_slice(&RECORD_MAGIC);
    head[4..6].copy_from_slice(&version.to_le_bytes());
    head[6..8].copy_from_slice(&length.to_le_bytes());
    let body_end = RECORD_HEADER_LEN + payload_len;
    let end = body_end + 4;
    if buf.len() < end {
        return Err(RecordError::BufferFull);
    }
    let crc = CRC32.checksum(&buf[..body_end]);
    buf[body_end..end].copy_from_slice(&crc.to_le_bytes());
    Ok(&buf[..end])
}

/// Writes a version-1 record (the layout before off levels), for tests of old flash contents.
pub fn encode_record_without_depth<'a>(
    config: &ConfigWithoutDepth,
    buf: &'a mut [u8],
) -> Result<&'a [u8], RecordError> {
    encode_versioned(RECORD_VERSION_WITHOUT_DEPTH, config, buf)
}

/// Reads a record (trailing bytes ignored); the configuration is returned only if valid.
pub fn decode_record(bytes: &[u8]) -> Result<StoredConfig, RecordError> {
    if bytes.len() >= RECORD_MAGIC.len() && bytes[..RECORD_MAGIC.len()] != RECORD_MAGIC {
        return Err(RecordError::BadMagic);
    }
    if bytes.len() < RECORD_HEADER_LEN {
        return Err(RecordError::Truncated);
    }
    let version = u16::from_le_bytes([bytes[4], bytes[5]]);
    if version != RECORD_VERSION && version != RECORD_VERSION_WITHOUT_DEPTH {
        return Err(RecordError::UnknownVersion(version));
    }
    let length = usize::from(u16::from_le_bytes([bytes[6], bytes[7]]));
    let body_end = RECORD_HEADER_LEN + length;
    let end = body_end + 4;
    let (Some(body), Some(trailer)) = (bytes.get(..body_end), bytes.get(body_end..end)) else {
        return Err(RecordError::Truncated);
    };
    let expected = u32::from_le_bytes([trailer[0], trailer[1], trailer[2], trailer[3]]);
    if CRC32.checksum(body) != expected {
        return Err(RecordError::BadCrc);
    }
    let payload = &body[RECORD_HEADER_LEN..];
    let config = if version == RECORD_VERSION {
        match postcard::take_from_bytes::<LuminaireConfig>(payload) {
            Ok((config, [])) => config,
            _ => return Err(RecordError::Malformed),
        }
    } else {
        match postcard::take_from_bytes::<ConfigWithoutDepth>(payload) {
            Ok((old, [])) => old.upgraded(),
            _ => return Err(RecordError::Malformed),
        }
    };
    config.validate().map_err(RecordError::Invalid)?;
    Ok(StoredConfig { config, version })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ChipRate;

    fn sample() -> LuminaireConfig {
        LuminaireConfig {
            led_count: 6,
            chip_rate: ChipRate(959_500),
            brightness_permille: [1000, 900, 800, 700, 600, 500, 0, 0],
            phase_chips: [0, 1, 2, 3, 127, 5, 0, 0],
            running: false,
            off_level_permille: [0, 100, 900, 1000, 0, 0, 0, 7],
            allow_flicker: true,
        }
    }

    fn stored(config: LuminaireConfig) -> StoredConfig {
        StoredConfig {
            config,
            version: RECORD_VERSION,
        }
    }

    #[test]
    fn round_trip_ignores_trailing_erased_flash() {
        let mut buf = [0xFFu8; MAX_RECORD_LEN];
        let len = encode_record(&sample(), &mut buf).unwrap().len();
        assert!(len < MAX_RECORD_LEN);
        assert_eq!(decode_record(&buf), Ok(stored(sample())));
        assert_eq!(decode_record(&buf[..len]), Ok(stored(sample())));
        assert_eq!(decode_record(&buf[..len - 1]), Err(RecordError::Truncated));
    }

    #[test]
    fn every_corrupted_byte_is_rejected() {
        let mut buf = [0u8; MAX_RECORD_LEN];
        let record = encode_record(&sample(), &mut buf).unwrap().to_vec();
        for index in 0..record.len() {
            for flip in [0x01u8, 0x80, 0xFF] {
                let mut bad = record.clone();
                bad[index] ^= flip;
                assert!(decode_record(&bad).is_err(), "byte {index} ^ {flip:#x}");
            }
        }
        assert_eq!(decode_record(&[0xFF; 64]), Err(RecordError::BadMagic));
        assert_eq!(decode_record(&[]), Err(RecordError::Truncated));
        let mut bad = record.clone();
        bad[4] = 3;
        assert_eq!(decode_record(&bad), Err(RecordError::UnknownVersion(3)));
    }

    #[test]
    fn invalid_config_with_valid_crc_is_rejected() {
        let mut config = sample();
        config.phase_chips[0] = 128;
        let mut buf = [0u8; MAX_RECORD_LEN];
        encode_record(&config, &mut buf).unwrap();
        assert_eq!(
            decode_record(&buf),
            Err(RecordError::Invalid(ConfigError::Phase {
                led: 0,
                got: 128
            }))
        );
        assert_eq!(
            encode_record(&config, &mut [0u8; 12]),
            Err(RecordError::BufferFull)
        );
    }

    /// A version-1 record, byte for byte as the firmware before off levels wrote it (6 LEDs,
    /// 959.5 Hz, stopped), reads as that configuration with dark off chips, flagged.
    #[test]
    fn a_record_without_depth_reads_as_full_on_off_keying() {
        // Computed independently: postcard varints of the fields, CRC-32/ISO-HDLC (zlib's).
        let old: [u8; 47] = [
            0x4D, 0x45, 0x42, 0x43, 0x01, 0x00, 0x1B, 0x00, 0x06, 0x8C, 0xC8, 0x3A, 0xE8, 0x07,
            0x84, 0x07, 0xA0, 0x06, 0xBC, 0x05, 0xD8, 0x04, 0xF4, 0x03, 0x00, 0x00, 0x00, 0x01,
            0x02, 0x03, 0x7F, 0x05, 0x00, 0x00, 0x00, 0x4A, 0x1B, 0x02, 0xBE, 0xFF, 0xFF, 0xFF,
            0xFF, 0xFF, 0xFF, 0xFF, 0xFF,
        ];
        let mut expected = sample();
        expected.off_level_permille = [0; 8];
        expected.allow_flicker = false;
        let read = decode_record(&old).unwrap();
        assert_eq!(read.config, expected);
        assert!(read.without_depth());
        // The same bytes from the encoder of the old layout.
        let mut buf = [0xFFu8; 47];
        let old_config = ConfigWithoutDepth {
            led_count: 6,
            chip_rate: ChipRate(959_500),
            brightness_permille: [1000, 900, 800, 700, 600, 500, 0, 0],
            phase_chips: [0, 1, 2, 3, 127, 5, 0, 0],
            running: false,
        };
        let len = encode_record_without_depth(&old_config, &mut buf)
            .unwrap()
            .len();
        assert_eq!(&buf[..len], &old[..len]);
        assert!(
            !decode_record(encode_record(&sample(), &mut [0u8; 128]).unwrap())
                .unwrap()
                .without_depth()
        );
    }
}
