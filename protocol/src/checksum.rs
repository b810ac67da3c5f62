//! The one checksum of the protocol: CRC-32/ISO-HDLC over wire frames, flash records and the
//! carrier-table fingerprint.

/// CRC-32/ISO-HDLC, computed bit by bit (frames are at most 256 bytes; a lookup table would
/// cost the firmware 1 KiB of flash).
pub static CRC32: crc::Crc<u32, crc::NoTable> =
    crc::Crc::<u32, crc::NoTable>::new(&crc::CRC_32_ISO_HDLC);
