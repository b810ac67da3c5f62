//! Wire messages: header, one command table generating [`Request`] and [`Response`], and the
//! payload types (the command-table idea is postcard-rpc's).
//!
//! Every frame is `COBS(postcard(Header) ‖ postcard(body) ‖ crc32_le) 0x00` (see
//! [`crate::framing`]). The [`Header`] comes first so a peer speaking another protocol version
//! can still read the version and sequence number and be answered with
//! [`ProtocolError::UnsupportedVersion`]. [`Response::ProtocolError`] is variant 0 of
//! [`Response`] and must stay variant 0 in every future version for the same reason.
//!
//! Command variant `i` of [`Request`] is answered by variant `i + 1` of [`Response`]; every
//! command's own error is part of its response type, distinct from the frame-level
//! [`ProtocolError`].

use heapless::String;
use serde::{Deserialize, Serialize};

use crate::config::{ChipRate, ConfigError, LuminaireConfig};

/// Version of this wire protocol, carried in every [`Header`].
pub const PROTOCOL_VERSION: u16 = 3;

/// Sequence number meaning "unknown" in a [`Response::ProtocolError`] reply to an unreadable
/// frame; hosts number their requests from 1 and skip 0 on wrap-around.
pub const SEQ_UNKNOWN: u32 = 0;

/// Frame header, serialized before the body.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Header {
    /// Protocol version of the sender ([`PROTOCOL_VERSION`]).
    pub version: u16,
    /// Request sequence number; a response echoes the request's. A host numbers requests from
    /// 1 (skipping [`SEQ_UNKNOWN`]) and resends a timed-out request with the *same* number, so
    /// the device answers from its cache instead of applying it twice.
    pub seq: u32,
}

impl Header {
    /// Header of this protocol version with sequence number `seq`.
    pub const fn new(seq: u32) -> Self {
        Self {
            version: PROTOCOL_VERSION,
            seq,
        }
    }
}

/// Frame-level failure reported instead of a command's response.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ProtocolError {
    /// The frame exceeded [`crate::framing::MAX_FRAME_LEN`] and was discarded.
    FrameTooLong,
    /// The frame's CRC did not match.
    BadCrc,
    /// The frame was not valid COBS, or its header or body did not decode.
    Malformed,
    /// The header's protocol version is not the one this device speaks.
    UnsupportedVersion {
        /// The version this device speaks.
        supported: u16,
    },
}

/// A command's own failure (as opposed to a [`ProtocolError`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CommandError {
    /// Another operation (e.g. a save) is still in progress; retry later.
    Busy,
    /// Persistent storage reported a failure.
    StorageFailed,
    /// An argument is out of range (e.g. `Identify` for more than [`MAX_IDENTIFY_SECONDS`]).
    InvalidArgument,
}

/// Longest identify blink accepted.
pub const MAX_IDENTIFY_SECONDS: u8 = 60;

/// Result of `SaveConfig`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SaveOutcome {
    /// Storage already holds the active configuration; nothing written.
    AlreadySaved,
    /// The write was handed to storage; `GetStatus` reports its completion in `save`.
    Deferred,
}

/// Where the active configuration came from at boot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigSource {
    /// No stored record: factory defaults.
    Defaults,
    /// Restored from a valid stored record.
    Restored,
    /// A stored record existed but was corrupt or invalid: factory defaults.
    CorruptRecordDefaults,
    /// Restored from a record written before off levels were a setting: read as off level 0
    /// (full on/off keying); see [`Status::flicker_limited`] for what plays.
    RestoredWithoutDepth,
}

/// Progress of the last `SaveConfig`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SaveState {
    /// No save in progress; the last one (if any) succeeded.
    Idle,
    /// A save was handed to storage and has not completed.
    Pending,
    /// The last save failed.
    Failed,
}

/// Why the carriers stopped on their own: the luminaire switched every output off and reports
/// it in [`Status::output_fault`] until the next `Start` or `SetConfig`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum OutputFault {
    /// A DMA stream feeding the PWM compare registers reported a transfer error (TEIF) or
    /// stopped by itself.
    DmaTransferError,
    /// A DMA stream did not stop when the carriers were stopped or reloaded; the timers were
    /// reset, so the outputs are off, but the new configuration was not started.
    DmaStopTimeout,
}

impl core::fmt::Display for OutputFault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::DmaTransferError => "DMA transfer error: carriers stopped, outputs off",
            Self::DmaStopTimeout => {
                "DMA stream did not stop: outputs off, new settings not started"
            }
        })
    }
}

/// Identity and limits of a luminaire (`GetInfo`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeviceInfo {
    /// Firmware version string (e.g. "0.1.0").
    pub firmware_version: String<16>,
    /// Wire protocol version ([`PROTOCOL_VERSION`]).
    pub protocol_version: u16,
    /// Board name (e.g. "nucleo-g474re" or "emulator").
    pub board: String<32>,
    /// Highest LED count supported.
    pub max_leds: u8,
    /// Lowest chip rate supported.
    pub min_chip_rate: ChipRate,
    /// Highest chip rate supported.
    pub max_chip_rate: ChipRate,
    /// [`crate::carriers::ChipTable::fingerprint`] of the table being played.
    pub carrier_fingerprint: u32,
}

/// Runtime state and link counters (`GetStatus`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    /// Whether the carriers are playing (false after an [`OutputFault`]).
    pub running: bool,
    /// Why the carriers stopped on their own, if they did.
    pub output_fault: Option<OutputFault>,
    /// Where the configuration came from at boot.
    pub config_source: ConfigSource,
    /// Whether the active configuration differs from the stored one.
    pub unsaved_changes: bool,
    /// Whether the stored configuration flickers above IEEE 1789 low risk without
    /// `allow_flicker`, so that power-up raised its off levels to the largest low-risk depths
    /// (the stored record is unchanged).
    pub flicker_limited: bool,
    /// Progress of the last save.
    pub save: SaveState,
    /// Whether an identify blink is in progress.
    pub identify_active: bool,
    /// Frames that decoded into a request.
    pub rx_frames_ok: u32,
    /// Frames with a CRC mismatch.
    pub rx_bad_crc: u32,
    /// Frames that were not valid COBS or did not decode.
    pub rx_malformed: u32,
    /// Frames longer than the maximum frame length.
    pub rx_too_long: u32,
    /// Frames with another protocol version.
    pub rx_unsupported_version: u32,
}

/// Generates [`Request`], [`Response`] and [`Command`] from one table of
/// `Name(request type) -> response type` lines.
macro_rules! command_table {
    ($( $(#[$doc:meta])* $name:ident ( $req:ty ) -> $resp:ty ; )+) => {
        /// A request from host to luminaire: one variant per command.
        #[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub enum Request {
            $( $(#[$doc])* $name($req), )+
        }

        /// A response from luminaire to host: the reserved protocol error, then one variant
        /// per command in the same order as [`Request`].
        #[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub enum Response {
            /// The request frame could not be handled (always variant 0).
            ProtocolError(ProtocolError),
            $( $(#[$doc])* $name($resp), )+
        }

        /// The command named by a request or response, without payload.
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub enum Command {
            $( $(#[$doc])* $name, )+
        }

        impl Command {
            /// Every command in table order.
            pub const ALL: &'static [Command] = &[ $( Command::$name, )+ ];
        }

        impl Request {
            /// The command this request invokes.
            pub fn command(&self) -> Command {
                match self { $( Request::$name(_) => Command::$name, )+ }
            }
        }

        impl Response {
            /// The command this response answers, `None` for a protocol error.
            pub fn command(&self) -> Option<Command> {
                match self {
                    Response::ProtocolError(_) => None,
                    $( Response::$name(_) => Some(Command::$name), )+
                }
            }
        }
    };
}

command_table! {
    /// Echo a nonce.
    Ping(u32) -> u32;
    /// Identity and limits.
    GetInfo(()) -> DeviceInfo;
    /// The active configuration.
    GetConfig(()) -> LuminaireConfig;
    /// Validate and apply a configuration (not persisted until `SaveConfig`).
    SetConfig(LuminaireConfig) -> Result<(), ConfigError>;
    /// Persist the active configuration.
    SaveConfig(()) -> Result<SaveOutcome, CommandError>;
    /// Start playing the carriers.
    Start(()) -> Result<(), CommandError>;
    /// Stop playing the carriers (LEDs off).
    Stop(()) -> Result<(), CommandError>;
    /// Runtime state and link counters.
    GetStatus(()) -> Status;
    /// Blink the identify indicator for the given number of seconds (0 ends a blink early); the
    /// Black Pill firmware blinks its board LED (PC13), the virtual luminaire every output.
    Identify(u8) -> Result<(), CommandError>;
}

impl core::fmt::Display for ProtocolError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::FrameTooLong => f.write_str("frame too long"),
            Self::BadCrc => f.write_str("bad CRC"),
            Self::Malformed => f.write_str("malformed frame"),
            Self::UnsupportedVersion { supported } => {
                write!(
                    f,
                    "unsupported protocol version (device speaks {supported})"
                )
            }
        }
    }
}

impl core::fmt::Display for CommandError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Busy => f.write_str("busy"),
            Self::StorageFailed => f.write_str("storage failed"),
            Self::InvalidArgument => f.write_str("invalid argument"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for ProtocolError {}
#[cfg(feature = "std")]
impl std::error::Error for CommandError {}
