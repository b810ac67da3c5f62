//! Framing: `COBS(postcard(Header) ‖ postcard(body) ‖ crc32_le(…)) 0x00`.
//!
//! Encoding serializes with postcard, appends the CRC-32 (ISO-HDLC, the `crc` crate) and COBS-
//! encodes (the `cobs` crate postcard itself uses); decoding undoes COBS in place, checks the
//! CRC, then reads the header and the body with postcard. A frame on the wire is
//! at most [`MAX_FRAME_LEN`] bytes including its 0x00 terminator.
//!
//! [`FrameReader`] splits a byte stream at 0x00 delimiters. Resynchronisation rules:
//! * Bytes between two delimiters form one candidate frame; garbage that is separated from the
//!   next frame by a 0x00 therefore costs nothing but a rejected candidate.
//! * Garbage glued to the front of a frame with no 0x00 in between corrupts exactly that frame
//!   (CRC or COBS error); the frame after the next 0x00 is read intact. Senders may put a 0x00
//!   *before* a frame too (the reader ignores empty frames), which makes every frame immune to
//!   preceding line noise; the host does so after a timeout.
//! * A candidate longer than the capacity is reported once as [`FrameEvent::TooLong`] and the
//!   rest is discarded up to the next 0x00; the frame after that is read intact.

use serde::{Deserialize, Serialize};

use crate::wire::{Header, PROTOCOL_VERSION, Request, Response};

/// Largest frame on the wire in bytes, including the 0x00 terminator.
pub const MAX_FRAME_LEN: usize = 256;

/// Largest COBS-encoded frame body (without terminator) a reader must hold.
pub const MAX_COBS_LEN: usize = MAX_FRAME_LEN - 1;

/// Length of the CRC-32 trailer inside a decoded frame.
pub const CRC_LEN: usize = 4;

/// The frame CRC ([`crate::checksum::CRC32`]), re-exported where the frame layout is defined.
pub use crate::checksum::CRC32;

/// A [`FrameReader`] sized for this protocol's frames.
pub type WireFrameReader = FrameReader<MAX_COBS_LEN>;

/// Why a message could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The output buffer (capped at [`MAX_FRAME_LEN`]) is too small for the frame.
    BufferFull,
    /// postcard failed to serialize the message.
    Serialize,
}

/// Why a received frame could not be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// Not valid COBS (or empty).
    Cobs,
    /// Shorter than a CRC or CRC mismatch.
    BadCrc,
    /// CRC fine but header or body did not decode, or bytes were left over; `seq` is known
    /// when the header decoded.
    Malformed {
        /// Sequence number from the header, if it decoded.
        seq: Option<u32>,
    },
    /// The header carries another protocol version.
    UnsupportedVersion {
        /// The sender's version.
        version: u16,
        /// The sender's sequence number.
        seq: u32,
    },
}

impl FrameError {
    /// Sequence number of the offending frame, if known.
    pub fn seq(&self) -> Option<u32> {
        match self {
            Self::Cobs | Self::BadCrc => None,
            Self::Malformed { seq } => *seq,
            Self::UnsupportedVersion { seq, .. } => Some(*seq),
        }
    }

    /// The [`crate::wire::ProtocolError`] a device answers this error with.
    pub fn protocol_error(&self) -> crate::wire::ProtocolError {
        use crate::wire::ProtocolError;
        match self {
            Self::Cobs | Self::Malformed { .. } => ProtocolError::Malformed,
            Self::BadCrc => ProtocolError::BadCrc,
            Self::UnsupportedVersion { .. } => ProtocolError::UnsupportedVersion {
                supported: PROTOCOL_VERSION,
            },
        }
    }
}

impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BufferFull => write!(f, "frame does not fit the buffer ({MAX_FRAME_LEN} B max)"),
            Self::Serialize => f.write_str("message could not be serialized"),
        }
    }
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Cobs => f.write_str("invalid COBS frame"),
            Self::BadCrc => f.write_str("CRC mismatch"),
            Self::Malformed { seq: Some(seq) } => write!(f, "malformed frame (seq {seq})"),
            Self::Malformed { seq: None } => f.write_str("malformed frame"),
            Self::UnsupportedVersion { version, seq } => {
                write!(f, "protocol version {version} unsupported (seq {seq})")
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for EncodeError {}
#[cfg(feature = "std")]
impl std::error::Error for FrameError {}

/// Encodes `(header, body)` as one complete frame (terminator included) into `buf`:
/// postcard into a scratch payload, the CRC-32 appended, COBS-encoded into `buf`, 0x00.
fn encode<'a, T: Serialize>(
    header: Header,
    body: &T,
    buf: &'a mut [u8],
) -> Result<&'a [u8], EncodeError> {
    let limit = buf.len().min(MAX_FRAME_LEN);
    let mut payload = [0u8; MAX_FRAME_LEN];
    let used = match postcard::to_slice(&(header, body), &mut payload[..MAX_FRAME_LEN - CRC_LEN]) {
        Ok(serialized) => serialized.len(),
        Err(postcard::Error::SerializeBufferFull) => return Err(EncodeError::BufferFull),
        Err(_) => return Err(EncodeError::Serialize),
    };
    let crc = CRC32.checksum(&payload[..used]);
    payload[used..used + CRC_LEN].copy_from_slice(&crc.to_le_bytes());
    let out = &mut buf[..limit];
    let encoded =
        cobs::try_encode(&payload[..used + CRC_LEN], out).map_err(|_| EncodeError::BufferFull)?;
    match out.get_mut(encoded) {
        Some(terminator) => *terminator = 0,
        None => return Err(EncodeError::BufferFull),
    }
    Ok(&out[..=encoded])
}

/// Encodes a request frame with sequence number `seq`; returns the bytes to send.
pub fn encode_request<'a>(
    seq: u32,
    request: &Request,
    buf: &'a mut [u8],
) -> Result<&'a [u8], EncodeError> {
    encode(Header::new(seq), request, buf)
}

/// Encodes a response frame echoing sequence number `seq`; returns the bytes to send.
pub fn encode_response<'a>(
    seq: u32,
    response: &Response,
    buf: &'a mut [u8],
) -> Result<&'a [u8], EncodeError> {
    encode(Header::new(seq), response, buf)
}

/// Undoes COBS in place and checks the CRC; returns the payload (header ‖ body).
fn unframe(raw: &mut [u8]) -> Result<&[u8], FrameError> {
    let len = cobs::decode_in_place(raw).map_err(|_| FrameError::Cobs)?;
    let decoded = &raw[..len];
    if decoded.len() < CRC_LEN {
        return Err(FrameError::BadCrc);
    }
    let (payload, trailer) = decoded.split_at(decoded.len() - CRC_LEN);
    let expected = u32::from_le_bytes([trailer[0], trailer[1], trailer[2], trailer[3]]);
    if CRC32.checksum(payload) != expected {
        return Err(FrameError::BadCrc);
    }
    Ok(payload)
}

/// Decodes one frame's header and body; the body must use every remaining byte.
fn decode<'de, T: Deserialize<'de>>(raw: &'de mut [u8]) -> Result<(Header, T), FrameError> {
    let payload = unframe(raw)?;
    let (header, rest) = postcard::take_from_bytes::<Header>(payload)
        .map_err(|_| FrameError::Malformed { seq: None })?;
    if header.version != PROTOCOL_VERSION {
        return Err(FrameError::UnsupportedVersion {
            version: header.version,
            seq: header.seq,
        });
    }
    let malformed = FrameError::Malformed {
        seq: Some(header.seq),
    };
    match postcard::take_from_bytes::<T>(rest) {
        Ok((body, [])) => Ok((header, body)),
        _ => Err(malformed),
    }
}

/// Decodes a request from one raw COBS frame (terminator optional), in place.
pub fn decode_request(raw: &mut [u8]) -> Result<(Header, Request), FrameError> {
    decode(raw)
}

/// Decodes a response from one raw COBS frame (terminator optional), in place.
pub fn decode_response(raw: &mut [u8]) -> Result<(Header, Response), FrameError> {
    decode(raw)
}

/// What [`FrameReader`] found in the stream.
#[derive(Debug, PartialEq, Eq)]
pub enum FrameEvent<'a> {
    /// A complete candidate frame (COBS bytes, terminator stripped), ready for decoding.
    Frame(&'a mut [u8]),
    /// A candidate exceeded the capacity; it is discarded up to the next 0x00.
    TooLong,
}

/// Streaming splitter of a byte stream into frames at 0x00 delimiters, holding up to `N`
/// bytes per frame (see the module docs for the resynchronisation rules).
#[derive(Debug, Clone)]
pub struct FrameReader<const N: usize> {
    buf: [u8; N],
    len: usize,
    discarding: bool,
}

impl<const N: usize> Default for FrameReader<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameReader<N> {
    /// An empty reader.
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            discarding: false,
        }
    }

    /// Forgets any partial frame (e.g. after a link reset).
    pub fn reset(&mut self) {
        self.len = 0;
        self.discarding = false;
    }

    /// Number of bytes of the partial frame held.
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Takes one byte; returns an event when it completes a frame or overflows one.
    pub fn push(&mut self, byte: u8) -> Option<FrameEvent<'_>> {
        if byte == 0 {
            let len = core::mem::take(&mut self.len);
            if core::mem::take(&mut self.discarding) || len == 0 {
                return None;
            }
            return Some(FrameEvent::Frame(&mut self.buf[..len]));
        }
        if self.discarding {
            return None;
        }
        if self.len == N {
            self.len = 0;
            self.discarding = true;
            return Some(FrameEvent::TooLong);
        }
        self.buf[self.len] = byte;
        self.len += 1;
        None
    }

    /// Takes a chunk of any length, calling `on_event` for every event in stream order.
    pub fn feed(&mut self, chunk: &[u8], mut on_event: impl FnMut(FrameEvent<'_>)) {
        for &byte in chunk {
            if let Some(event) = self.push(byte) {
                on_event(event);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{ChipRate, ConfigError, LuminaireConfig};
    use crate::wire::{
        CommandError, ConfigSource, DeviceInfo, OutputFault, ProtocolError, SaveState, Status,
    };

    fn frame(seq: u32, request: &Request) -> ([u8; MAX_FRAME_LEN], usize) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let len = encode_request(seq, request, &mut buf).unwrap().len();
        (buf, len)
    }

    fn frames_of(
        reader: &mut WireFrameReader,
        chunk: &[u8],
        out: &mut std::vec::Vec<Result<(u32, Request), &'static str>>,
    ) {
        reader.feed(chunk, |event| match event {
            FrameEvent::Frame(raw) => out.push(
                decode_request(raw)
                    .map(|(h, r)| (h.seq, r))
                    .map_err(|_| "bad"),
            ),
            FrameEvent::TooLong => out.push(Err("too long")),
        });
    }

    fn worst_config() -> LuminaireConfig {
        LuminaireConfig {
            led_count: u8::MAX,
            chip_rate: ChipRate(u32::MAX),
            brightness_permille: [u16::MAX; 8],
            phase_chips: [u16::MAX; 8],
            running: true,
            off_level_permille: [u16::MAX; 8],
            allow_flicker: true,
        }
    }

    #[test]
    fn largest_messages_fit_a_frame() {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let s16 = heapless::String::<16>::try_from("0123456789abcdef").unwrap();
        let s32 = heapless::String::<32>::try_from("0123456789abcdef0123456789abcdef").unwrap();
        let info = DeviceInfo {
            firmware_version: s16,
            protocol_version: u16::MAX,
            board: s32,
            max_leds: u8::MAX,
            min_chip_rate: ChipRate(u32::MAX),
            max_chip_rate: ChipRate(u32::MAX),
            carrier_fingerprint: u32::MAX,
        };
        let status = Status {
            running: true,
            output_fault: Some(OutputFault::DmaStopTimeout),
            config_source: ConfigSource::CorruptRecordDefaults,
            unsaved_changes: true,
            flicker_limited: true,
            save: SaveState::Failed,
            identify_active: true,
            rx_frames_ok: u32::MAX,
            rx_bad_crc: u32::MAX,
            rx_malformed: u32::MAX,
            rx_too_long: u32::MAX,
            rx_unsupported_version: u32::MAX,
        };
        let responses = [
            Response::GetInfo(info),
            Response::GetConfig(worst_config()),
            Response::GetStatus(status),
            Response::SetConfig(Err(ConfigError::ChipRate {
                got_millihertz: u32::MAX,
            })),
            Response::SetConfig(Err(ConfigError::Flicker {
                led: u8::MAX,
                depth_permille: u16::MAX,
                max_depth_permille: u16::MAX,
                frequency_millihertz: u32::MAX,
            })),
            Response::SaveConfig(Err(CommandError::StorageFailed)),
        ];
        for response in &responses {
            let len = encode_response(u32::MAX, response, &mut buf).unwrap().len();
            assert!(len <= MAX_FRAME_LEN / 2, "{response:?}: {len} B");
        }
        let len = encode_request(u32::MAX, &Request::SetConfig(worst_config()), &mut buf)
            .unwrap()
            .len();
        assert!(len <= MAX_FRAME_LEN / 2, "{len}");
    }

    #[test]
    fn small_buffer_is_an_error() {
        let mut buf = [0u8; 8];
        assert_eq!(
            encode_request(1, &Request::SetConfig(worst_config()), &mut buf),
            Err(EncodeError::BufferFull)
        );
        assert_eq!(
            encode_request(1, &Request::Ping(1), &mut []),
            Err(EncodeError::BufferFull)
        );
    }

    #[test]
    fn decode_errors_are_classified() {
        let (buf, len) = frame(7, &Request::Ping(9));
        // Flip a payload byte: COBS stays valid (non-zero), CRC fails.
        let mut raw = buf[..len].to_vec();
        raw[4] ^= 0x01;
        assert_eq!(decode_request(&mut raw), Err(FrameError::BadCrc));
        // Not COBS: a code byte pointing past the end.
        assert_eq!(decode_request(&mut [9, 1, 1]), Err(FrameError::Cobs));
        assert_eq!(decode_request(&mut []), Err(FrameError::Cobs));
        // Too short for a CRC.
        assert_eq!(decode_request(&mut [3, 1, 1]), Err(FrameError::BadCrc));
    }

    /// Builds a frame from an arbitrary payload with a valid CRC.
    fn raw_frame(payload: &[u8]) -> std::vec::Vec<u8> {
        let mut data = payload.to_vec();
        data.extend_from_slice(&CRC32.checksum(payload).to_le_bytes());
        let mut out = std::vec![0u8; data.len() * 2 + 2];
        let n = cobs::encode(&data, &mut out);
        out.truncate(n);
        out
    }

    #[test]
    fn version_and_body_errors_carry_the_seq() {
        // The next version, seq 5, Ping(1).
        let next = (PROTOCOL_VERSION + 1) as u8;
        let mut raw = raw_frame(&[next, 5, 0, 1]);
        assert_eq!(
            decode_request(&mut raw),
            Err(FrameError::UnsupportedVersion {
                version: u16::from(next),
                seq: 5
            })
        );
        // This version, seq 5, unknown command 99.
        let mut raw = raw_frame(&[PROTOCOL_VERSION as u8, 5, 99]);
        assert_eq!(
            decode_request(&mut raw),
            Err(FrameError::Malformed { seq: Some(5) })
        );
        // Trailing byte after a complete Ping.
        let mut raw = raw_frame(&[PROTOCOL_VERSION as u8, 5, 0, 1, 0]);
        assert_eq!(
            decode_request(&mut raw),
            Err(FrameError::Malformed { seq: Some(5) })
        );
        // Header truncated.
        let mut raw = raw_frame(&[PROTOCOL_VERSION as u8]);
        assert_eq!(
            decode_request(&mut raw),
            Err(FrameError::Malformed { seq: None })
        );
        assert_eq!(
            FrameError::UnsupportedVersion { version: 2, seq: 5 }.protocol_error(),
            ProtocolError::UnsupportedVersion {
                supported: PROTOCOL_VERSION
            }
        );
    }

    #[test]
    fn every_split_point_yields_the_frame() {
        let request = Request::SetConfig(LuminaireConfig::DEFAULT);
        let (buf, len) = frame(42, &request);
        let bytes = &buf[..len];
        for split in 0..=len {
            let mut reader = WireFrameReader::new();
            let mut out = std::vec::Vec::new();
            frames_of(&mut reader, &bytes[..split], &mut out);
            frames_of(&mut reader, &bytes[split..], &mut out);
            assert_eq!(out, [Ok((42, request.clone()))], "split at {split}");
            assert_eq!(reader.pending(), 0);
        }
    }

    #[test]
    fn one_byte_chunks_and_back_to_back_frames() {
        let requests = [
            Request::Ping(1),
            Request::GetStatus(()),
            Request::Identify(3),
        ];
        let mut stream = std::vec::Vec::new();
        for (seq, request) in (10..).zip(&requests) {
            let (buf, len) = frame(seq, request);
            stream.extend_from_slice(&buf[..len]);
        }
        let expected: std::vec::Vec<_> = (10..).zip(requests.iter().cloned()).map(Ok).collect();
        let mut reader = WireFrameReader::new();
        let mut out = std::vec::Vec::new();
        for byte in &stream {
            frames_of(&mut reader, core::slice::from_ref(byte), &mut out);
        }
        assert_eq!(out, expected);
        let mut out = std::vec::Vec::new();
        frames_of(&mut reader, &stream, &mut out);
        assert_eq!(out, expected);
    }

    #[test]
    fn garbage_costs_only_what_it_touches() {
        let (buf, len) = frame(3, &Request::Ping(77));
        let good = &buf[..len];
        let mut reader = WireFrameReader::new();
        let mut out = std::vec::Vec::new();
        // Garbage, delimiter, frame: garbage rejected, frame intact.
        let mut stream = std::vec![0x55, 0xAA, 0x13, 0x00];
        stream.extend_from_slice(good);
        // Garbage glued to a frame: that frame lost, the next one intact.
        stream.extend_from_slice(&[0x42, 0x42]);
        stream.extend_from_slice(good);
        // Leading delimiters and empty frames are ignored; the next frame is intact.
        stream.extend_from_slice(&[0, 0, 0]);
        stream.extend_from_slice(good);
        frames_of(&mut reader, &stream, &mut out);
        let ping = Ok((3, Request::Ping(77)));
        assert_eq!(out, [Err("bad"), ping.clone(), Err("bad"), ping]);
    }

    #[test]
    fn oversize_is_reported_once_and_the_next_frame_survives() {
        let (buf, len) = frame(4, &Request::Ping(5));
        let mut stream = std::vec![0x11; 3 * MAX_FRAME_LEN];
        stream.push(0);
        stream.extend_from_slice(&buf[..len]);
        for chunk in [1, 7, 64, stream.len()] {
            let mut reader = WireFrameReader::new();
            let mut out = std::vec::Vec::new();
            for piece in stream.chunks(chunk) {
                frames_of(&mut reader, piece, &mut out);
            }
            assert_eq!(
                out,
                [Err("too long"), Ok((4, Request::Ping(5)))],
                "chunk {chunk}"
            );
        }
        // A frame of exactly the capacity is accepted.
        let mut reader = FrameReader::<4>::new();
        let mut got = std::vec::Vec::new();
        reader.feed(&[1, 2, 3, 4, 0, 1, 2, 3, 4, 5, 0], |e| {
            got.push(match e {
                FrameEvent::Frame(f) => f.len(),
                FrameEvent::TooLong => 0,
            })
        });
        assert_eq!(got, [4, 0]);
    }
}
