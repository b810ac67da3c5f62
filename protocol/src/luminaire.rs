//! The hardware-free luminaire state machine and the byte-level
//! [`Endpoint`] around it.
//!
//! [`Luminaire::handle`] maps a request to a response plus [`Effects`] the hardware layer must
//! carry out (load a chip table, persist, start/stop, blink). It owns the configuration, the
//! save state and the link counters, and never applies an invalid configuration. The firmware
//! and the host's virtual luminaire (`meb device emulate`) both run exactly this code through
//! [`Endpoint`], so the emulator answers byte for byte like the hardware.
//!
//! A state-changing request carrying the same sequence number and body as the previous one is
//! a retry: the cached response is returned and no effects are repeated. Read-only requests
//! (`Ping`, `GetInfo`, `GetConfig`, `GetStatus`) have no effects to repeat and are always
//! answered afresh, so a new session that happens to reuse a sequence number never reads a stale
//! status.

use heapless::{String, Vec};

use crate::carriers::{ChipTable, MAX_LEDS};
use crate::config::{ChipRate, ConfigError, LuminaireConfig};
use crate::flicker::{is_low_risk, limited_to_low_risk};
use crate::framing::{
    FrameError, FrameEvent, MAX_FRAME_LEN, WireFrameReader, decode_request, encode_response,
};
use crate::record::{RecordError, StoredConfig};
use crate::timing::LedLevels;
use crate::wire::{
    CommandError, ConfigSource, DeviceInfo, MAX_IDENTIFY_SECONDS, OutputFault, PROTOCOL_VERSION,
    ProtocolError, Request, Response, SEQ_UNKNOWN, SaveOutcome, SaveState, Status,
};

/// What the hardware must play: everything of a config except the running flag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OutputPlan {
    /// Number of LEDs N.
    pub led_count: u8,
    /// Chip rate.
    pub chip_rate: ChipRate,
    /// Per-LED on-brightness in per mille.
    pub brightness_permille: [u16; MAX_LEDS],
    /// Per-LED carrier delay in chips.
    pub phase_chips: [u16; MAX_LEDS],
    /// Per-LED off level in per mille of the on level.
    pub off_level_permille: [u16; MAX_LEDS],
}

impl OutputPlan {
    /// The plan of a (validated) configuration.
    pub fn of(config: &LuminaireConfig) -> Self {
        Self {
            led_count: config.led_count,
            chip_rate: config.chip_rate,
            brightness_permille: config.brightness_permille,
            phase_chips: config.phase_chips,
            off_level_permille: config.off_level_permille,
        }
    }

    /// The PWM compare values of each LED's on and off chips.
    pub fn levels(&self) -> LedLevels {
        LedLevels::new(&self.brightness_permille, &self.off_level_permille)
    }

    /// The chip table to load (phases applied).
    pub fn chip_table(&self) -> Result<ChipTable, ConfigError> {
        ChipTable::with_phases(self.led_count, &self.phase_chips).map_err(|_| {
            ConfigError::LedCount {
                got: self.led_count,
            }
        })
    }
}

/// One thing the hardware layer must do after a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Effect {
    /// Load the new chip table, rate and brightness.
    ApplyOutput(OutputPlan),
    /// Write this configuration to storage, then call [`Luminaire::notify_saved`].
    Persist(LuminaireConfig),
    /// Start playing the carriers.
    Start,
    /// Stop playing (LEDs off).
    Stop,
    /// Blink the identify indicator for `seconds` (0 = end a blink), then call
    /// [`Luminaire::notify_identify_finished`].
    Identify {
        /// Blink duration.
        seconds: u8,
    },
}

/// The effects of one request, in the order they must be carried out.
pub type Effects = Vec<Effect, 4>;

/// Static facts about the board the state machine runs on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BoardInfo {
    /// Firmware version string.
    pub firmware_version: String<16>,
    /// Board name.
    pub board: String<32>,
}

impl BoardInfo {
    /// Board facts from plain strings, each cut at a character boundary to fit its capacity.
    pub fn new(firmware_version: &str, board: &str) -> Self {
        Self {
            firmware_version: truncated(firmware_version),
            board: truncated(board),
        }
    }
}

/// The longest prefix of `text` that fits `N` bytes, cut at a character boundary.
fn truncated<const N: usize>(text: &str) -> String<N> {
    let mut out = String::new();
    for c in text.chars() {
        if out.push(c).is_err() {
            break;
        }
    }
    out
}

/// Outcome of reading the stored configuration at boot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RestoredConfig {
    /// A valid record was read.
    Ok(LuminaireConfig),
    /// A valid record of the layout before off levels was read (off levels 0).
    WithoutDepth(LuminaireConfig),
    /// No record (erased flash, no file).
    Missing,
    /// A record was present but corrupt or invalid.
    Corrupt,
}

impl From<Result<StoredConfig, RecordError>> for RestoredConfig {
    /// Maps [`decode_record`](crate::record::decode_record)'s result: no magic (erased flash)
    /// is `Missing`, any other error (including an empty or truncated record) is `Corrupt`.
    fn from(result: Result<StoredConfig, RecordError>) -> Self {
        match result {
            Ok(stored) if stored.config.validate().is_err() => Self::Corrupt,
            Ok(stored) if stored.without_depth() => Self::WithoutDepth(stored.config),
            Ok(stored) => Self::Ok(stored.config),
            Err(RecordError::BadMagic) => Self::Missing,
            _ => Self::Corrupt,
        }
    }
}

/// Receive-side link counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LinkCounters {
    /// Frames that decoded into a request.
    pub frames_ok: u32,
    /// Frames with a CRC mismatch.
    pub bad_crc: u32,
    /// Frames that were not valid COBS or did not decode.
    pub malformed: u32,
    /// Frames that overflowed the reader.
    pub too_long: u32,
    /// Frames of another protocol version.
    pub unsupported_version: u32,
}

/// The luminaire's protocol state: configuration, save and identify state, counters.
#[derive(Debug, Clone)]
pub struct Luminaire {
    board: BoardInfo,
    config: LuminaireConfig,
    stored: Option<LuminaireConfig>,
    source: ConfigSource,
    flicker_limited: bool,
    save: SaveState,
    saving: Option<LuminaireConfig>,
    identify_active: bool,
    fault: Option<OutputFault>,
    counters: LinkCounters,
    last: Option<(u32, Request, Response)>,
}

impl Luminaire {
    /// A luminaire starting from the stored configuration, or the defaults if there is none.
    /// A stored configuration above IEEE 1789 low risk that was not saved with
    /// `allow_flicker` starts with its off levels raised to the largest low-risk depths
    /// ([`limited_to_low_risk`]), reported by [`Status::flicker_limited`].
    pub fn new(board: BoardInfo, restored: RestoredConfig) -> Self {
        let (config, stored, source) = match restored {
            RestoredConfig::Ok(config) if config.validate().is_ok() => {
                (config, Some(config), ConfigSource::Restored)
            }
            RestoredConfig::WithoutDepth(config) if config.validate().is_ok() => {
                (config, Some(config), ConfigSource::RestoredWithoutDepth)
            }
            RestoredConfig::Ok(_) | RestoredConfig::WithoutDepth(_) | RestoredConfig::Corrupt => (
                LuminaireConfig::DEFAULT,
                None,
                ConfigSource::CorruptRecordDefaults,
            ),
            RestoredConfig::Missing => (LuminaireConfig::DEFAULT, None, ConfigSource::Defaults),
        };
        let flicker_limited = !config.allow_flicker && !is_low_risk(&config);
        let config = if flicker_limited {
            limited_to_low_risk(&config)
        } else {
            config
        };
        Self {
            board,
            config,
            stored,
            source,
            flicker_limited,
            save: SaveState::Idle,
            saving: None,
            identify_active: false,
            fault: None,
            counters: LinkCounters::default(),
            last: None,
        }
    }

    /// Effects that bring freshly booted hardware into the active configuration.
    pub fn startup_effects(&self) -> Effects {
        let mut effects = Effects::new();
        push(
            &mut effects,
            Effect::ApplyOutput(OutputPlan::of(&self.config)),
        );
        push(&mut effects, self.run_effect());
        effects
    }

    /// The active configuration.
    pub fn config(&self) -> &LuminaireConfig {
        &self.config
    }

    /// The receive counters.
    pub fn counters(&self) -> &LinkCounters {
        &self.counters
    }

    /// The `GetInfo` answer.
    pub fn info(&self) -> DeviceInfo {
        DeviceInfo {
            firmware_version: self.board.firmware_version.clone(),
            protocol_version: PROTOCOL_VERSION,
            board: self.board.board.clone(),
            max_leds: MAX_LEDS as u8,
            min_chip_rate: ChipRate::MIN,
            max_chip_rate: ChipRate::MAX,
            carrier_fingerprint: self
                .config
                .chip_table()
                .map(|table| table.fingerprint())
                .unwrap_or(0),
        }
    }

    /// The `GetStatus` answer.
    pub fn status(&self) -> Status {
        Status {
            running: self.config.running && self.fault.is_none(),
            output_fault: self.fault,
            config_source: self.source,
            unsaved_changes: self.stored != Some(self.config),
            flicker_limited: self.flicker_limited,
            save: self.save,
            identify_active: self.identify_active,
            rx_frames_ok: self.counters.frames_ok,
            rx_bad_crc: self.counters.bad_crc,
            rx_malformed: self.counters.malformed,
            rx_too_long: self.counters.too_long,
            rx_unsupported_version: self.counters.unsupported_version,
        }
    }

    /// Handles one decoded request with sequence number `seq`.
    pub fn handle(&mut self, seq: u32, request: &Request) -> (Response, Effects) {
        self.counters.frames_ok = self.counters.frames_ok.wrapping_add(1);
        let read_only = matches!(
            request,
            Request::Ping(_)
                | Request::GetInfo(())
                | Request::GetConfig(())
                | Request::GetStatus(())
        );
        if read_only {
            return self.execute(request);
        }
        if let Some((last_seq, last_request, last_response)) = &self.last
            && *last_seq == seq
            && last_request == request
        {
            return (last_response.clone(), Effects::new());
        }
        let (response, effects) = self.execute(request);
        self.last = Some((seq, request.clone(), response.clone()));
        (response, effects)
    }

    fn execute(&mut self, request: &Request) -> (Response, Effects) {
        let mut effects = Effects::new();
        let response = match request {
            Request::Ping(nonce) => Response::Ping(*nonce),
            Request::GetInfo(()) => Response::GetInfo(self.info()),
            Request::GetConfig(()) => Response::GetConfig(self.config),
            Request::SetConfig(new) => Response::SetConfig(match new.validate_for_people() {
                Ok(()) => {
                    self.config = *new;
                    self.fault = None;
                    self.flicker_limited = false;
                    push(&mut effects, Effect::ApplyOutput(OutputPlan::of(new)));
                    push(&mut effects, self.run_effect());
                    Ok(())
                }
                Err(e) => Err(e),
            }),
            Request::SaveConfig(()) => Response::SaveConfig(if self.save == SaveState::Pending {
                Err(CommandError::Busy)
            } else if self.stored == Some(self.config) {
                self.save = SaveState::Idle;
                Ok(SaveOutcome::AlreadySaved)
            } else {
                self.save = SaveState::Pending;
                self.saving = Some(self.config);
                push(&mut effects, Effect::Persist(self.config));
                Ok(SaveOutcome::Deferred)
            }),
            Request::Start(()) => {
                self.config.running = true;
                self.fault = None;
                push(&mut effects, Effect::Start);
                Response::Start(Ok(()))
            }
            Request::Stop(()) => {
                self.config.running = false;
                push(&mut effects, Effect::Stop);
                Response::Stop(Ok(()))
            }
            Request::GetStatus(()) => Response::GetStatus(self.status()),
            Request::Identify(seconds) => Response::Identify(if *seconds > MAX_IDENTIFY_SECONDS {
                Err(CommandError::InvalidArgument)
            } else {
                self.identify_active = *seconds > 0;
                push(&mut effects, Effect::Identify { seconds: *seconds });
                Ok(())
            }),
        };
        (response, effects)
    }

    fn run_effect(&self) -> Effect {
        if self.config.running {
            Effect::Start
        } else {
            Effect::Stop
        }
    }

    /// Reports the outcome of the last [`Effect::Persist`].
    pub fn notify_saved(&mut self, result: Result<(), CommandError>) {
        let saving = self.saving.take();
        match result {
            Ok(()) => {
                self.save = SaveState::Idle;
                if saving.is_some() {
                    self.stored = saving;
                }
            }
            Err(_) => self.save = SaveState::Failed,
        }
    }

    /// Reports that the hardware stopped the carriers on its own (see [`OutputFault`]); the
    /// configuration is kept, `GetStatus` shows the fault until the next `Start` or `SetConfig`.
    pub fn notify_output_fault(&mut self, fault: OutputFault) {
        self.fault = Some(fault);
    }

    /// Reports that an identify blink ended.
    pub fn notify_identify_finished(&mut self) {
        self.identify_active = false;
    }

    /// Counts a frame that failed to decode and returns the reply to send.
    pub fn frame_error(&mut self, error: &FrameError) -> (u32, Response) {
        let c = &mut self.counters;
        let counter = match error {
            FrameError::Cobs | FrameError::Malformed { .. } => &mut c.malformed,
            FrameError::BadCrc => &mut c.bad_crc,
            FrameError::UnsupportedVersion { .. } => &mut c.unsupported_version,
        };
        *counter = counter.wrapping_add(1);
        (
            error.seq().unwrap_or(SEQ_UNKNOWN),
            Response::ProtocolError(error.protocol_error()),
        )
    }

    /// Counts an overflowing frame and returns the reply to send.
    pub fn frame_too_long(&mut self) -> (u32, Response) {
        self.counters.too_long = self.counters.too_long.wrapping_add(1);
        (
            SEQ_UNKNOWN,
            Response::ProtocolError(ProtocolError::FrameTooLong),
        )
    }
}

fn push(effects: &mut Effects, effect: Effect) {
    // Capacity 4 exceeds the 2 effects any request produces.
    let _ = effects.push(effect);
}

/// A [`Luminaire`] behind a [`WireFrameReader`]: bytes in, reply frames and effects out.
#[derive(Debug, Clone)]
pub struct Endpoint {
    /// The state machine.
    pub luminaire: Luminaire,
    reader: WireFrameReader,
    reply: [u8; MAX_FRAME_LEN],
}

impl Endpoint {
    /// An endpoint around `luminaire` with an empty reader.
    pub fn new(luminaire: Luminaire) -> Self {
        Self {
            luminaire,
            reader: WireFrameReader::new(),
            reply: [0; MAX_FRAME_LEN],
        }
    }

    /// Feeds received bytes; for every complete or overflowing frame calls `sink` with the
    /// encoded reply frame and the effects to carry out.
    pub fn on_bytes(&mut self, chunk: &[u8], mut sink: impl FnMut(&[u8], Effects)) {
        let Self {
            luminaire,
            reader,
            reply,
        } = self;
        reader.feed(chunk, |event| {
            let (bytes, effects) = match event {
                FrameEvent::Frame(raw) => respond(luminaire, raw, reply),
                FrameEvent::TooLong => {
                    let (seq, response) = luminaire.frame_too_long();
                    (encode_reply(seq, &response, reply), Effects::new())
                }
            };
            if let Some(bytes) = bytes {
                sink(bytes, effects);
            }
        });
    }

    /// Handles one raw COBS frame (terminator optional): decode → handle → encode.
    /// Returns the reply (`None` only if it could not be encoded) and the effects.
    pub fn handle_frame<'a>(
        &mut self,
        raw: &mut [u8],
        reply_buf: &'a mut [u8],
    ) -> (Option<&'a [u8]>, Effects) {
        respond(&mut self.luminaire, raw, reply_buf)
    }
}

fn respond<'a>(
    luminaire: &mut Luminaire,
    raw: &mut [u8],
    reply_buf: &'a mut [u8],
) -> (Option<&'a [u8]>, Effects) {
    let (seq, response, effects) = match decode_request(raw) {
        Ok((header, request)) => {
            let (response, effects) = luminaire.handle(header.seq, &request);
            (header.seq, response, effects)
        }
        Err(error) => {
            let (seq, response) = luminaire.frame_error(&error);
            (seq, response, Effects::new())
        }
    };
    (encode_reply(seq, &response, reply_buf), effects)
}

fn encode_reply<'a>(seq: u32, response: &Response, buf: &'a mut [u8]) -> Option<&'a [u8]> {
    encode_response(seq, response, buf).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::framing::{decode_response, encode_request};

    fn board() -> BoardInfo {
        BoardInfo {
            firmware_version: String::try_from("0.1.0").unwrap(),
            board: String::try_from("test").unwrap(),
        }
    }

    fn other_config() -> LuminaireConfig {
        LuminaireConfig {
            led_count: 3,
            chip_rate: ChipRate(959_500),
            phase_chips: [1, 2, 3, 0, 0, 0, 0, 0],
            off_level_permille: [750, 700, 900, 900, 900, 900, 900, 900],
            ..LuminaireConfig::DEFAULT
        }
    }

    #[test]
    fn board_info_truncates_at_char_boundaries() {
        let info = BoardInfo::new("0.1.0-very-long-version", "ü".repeat(20).as_str());
        assert_eq!(info.firmware_version.as_str(), "0.1.0-very-long-");
        assert_eq!(info.board.as_str(), "ü".repeat(16));
    }

    #[test]
    fn restored_from_record_results() {
        use crate::record::{MAX_RECORD_LEN, decode_record, encode_record};
        assert_eq!(
            RestoredConfig::from(decode_record(&[0xFF; 64])),
            RestoredConfig::Missing
        );
        assert_eq!(
            RestoredConfig::from(decode_record(&[])),
            RestoredConfig::Corrupt
        );
        let mut buf = [0u8; MAX_RECORD_LEN];
        let len = encode_record(&other_config(), &mut buf).unwrap().len();
        assert_eq!(
            RestoredConfig::from(decode_record(&buf)),
            RestoredConfig::Ok(other_config())
        );
        buf[len - 1] ^= 1;
        assert_eq!(
            RestoredConfig::from(decode_record(&buf)),
            RestoredConfig::Corrupt
        );
    }

    #[test]
    fn boot_sources() {
        let missing = Luminaire::new(board(), RestoredConfig::Missing);
        assert_eq!(missing.status().config_source, ConfigSource::Defaults);
        assert_eq!(*missing.config(), LuminaireConfig::DEFAULT);
        assert!(missing.status().unsaved_changes);
        let corrupt = Luminaire::new(board(), RestoredConfig::Corrupt);
        assert_eq!(
            corrupt.status().config_source,
            ConfigSource::CorruptRecordDefaults
        );
        let restored = Luminaire::new(board(), RestoredConfig::Ok(other_config()));
        assert_eq!(restored.status().config_source, ConfigSource::Restored);
        assert_eq!(*restored.config(), other_config());
        assert!(!restored.status().unsaved_changes);
        let mut bad = other_config();
        bad.led_count = 0;
        let invalid = Luminaire::new(board(), RestoredConfig::Ok(bad));
        assert_eq!(
            invalid.status().config_source,
            ConfigSource::CorruptRecordDefaults
        );
        assert_eq!(
            restored.startup_effects().as_slice(),
            [
                Effect::ApplyOutput(OutputPlan::of(&other_config())),
                Effect::Start
            ]
        );
    }

    #[test]
    fn set_config_applies_only_valid_configs() {
        let mut lum = Luminaire::new(board(), RestoredConfig::Missing);
        let mut bad = other_config();
        bad.brightness_permille[5] = 2000;
        let (response, effects) = lum.handle(1, &Request::SetConfig(bad));
        assert_eq!(
            response,
            Response::SetConfig(Err(ConfigError::Brightness { led: 5, got: 2000 }))
        );
        assert!(effects.is_empty());
        assert_eq!(*lum.config(), LuminaireConfig::DEFAULT);
        let (response, effects) = lum.handle(2, &Request::SetConfig(other_config()));
        assert_eq!(response, Response::SetConfig(Ok(())));
        assert_eq!(
            effects.as_slice(),
            [
                Effect::ApplyOutput(OutputPlan::of(&other_config())),
                Effect::Start
            ]
        );
        assert_eq!(
            lum.handle(3, &Request::GetConfig(())).0,
            Response::GetConfig(other_config())
        );
        let Response::GetInfo(info) = lum.handle(4, &Request::GetInfo(())).0 else {
            panic!("not an info response");
        };
        assert_eq!(
            info.carrier_fingerprint,
            other_config().chip_table().unwrap().fingerprint()
        );
        assert_eq!(
            (info.min_chip_rate, info.max_chip_rate),
            (ChipRate::MIN, ChipRate::MAX)
        );
    }

    #[test]
    fn retry_returns_cached_response_without_effects() {
        let mut lum = Luminaire::new(board(), RestoredConfig::Missing);
        let request = Request::SetConfig(other_config());
        let first = lum.handle(9, &request);
        assert!(!first.1.is_empty());
        let retry = lum.handle(9, &request);
        assert_eq!(retry.0, first.0);
        assert!(retry.1.is_empty());
        // Same seq, different body: a new request.
        let (_, effects) = lum.handle(9, &Request::Stop(()));
        assert_eq!(effects.as_slice(), [Effect::Stop]);
        assert!(!lum.config().running);
    }

    #[test]
    fn read_only_requests_are_answered_afresh_even_with_a_repeated_sequence_number() {
        let mut lum = Luminaire::new(board(), RestoredConfig::Missing);
        let (first, _) = lum.handle(1, &Request::GetStatus(()));
        lum.notify_output_fault(OutputFault::DmaTransferError);
        // Another session starting at sequence number 1 again.
        let (second, _) = lum.handle(1, &Request::GetStatus(()));
        assert_ne!(first, second, "a stale status from the retry cache");
        let Response::GetStatus(status) = second else {
            panic!("not a status");
        };
        assert_eq!(status.output_fault, Some(OutputFault::DmaTransferError));
        // A state-changing retry is still answered from the cache, effects not repeated,
        // even with read-only requests in between.
        let (_, effects) = lum.handle(7, &Request::Stop(()));
        assert_eq!(effects.as_slice(), [Effect::Stop]);
        lum.handle(8, &Request::GetConfig(()));
        let (_, effects) = lum.handle(7, &Request::Stop(()));
        assert!(effects.is_empty());
    }

    #[test]
    fn save_flow() {
        let mut lum = Luminaire::new(board(), RestoredConfig::Missing);
        let (response, effects) = lum.handle(1, &Request::SaveConfig(()));
        assert_eq!(response, Response::SaveConfig(Ok(SaveOutcome::Deferred)));
        assert_eq!(
            effects.as_slice(),
            [Effect::Persist(LuminaireConfig::DEFAULT)]
        );
        assert_eq!(lum.status().save, SaveState::Pending);
        assert_eq!(
            lum.handle(2, &Request::SaveConfig(())).0,
            Response::SaveConfig(Err(CommandError::Busy))
        );
        // A change while saving stays unsaved after the save completes.
        lum.handle(3, &Request::Stop(()));
        lum.notify_saved(Ok(()));
        let status = lum.status();
        assert_eq!(status.save, SaveState::Idle);
        assert!(status.unsaved_changes);
        lum.handle(4, &Request::Start(()));
        assert!(!lum.status().unsaved_changes);
        assert_eq!(
            lum.handle(5, &Request::SaveConfig(())).0,
            Response::SaveConfig(Ok(SaveOutcome::AlreadySaved))
        );
        lum.handle(6, &Request::SetConfig(other_config()));
        lum.handle(7, &Request::SaveConfig(()));
        lum.notify_saved(Err(CommandError::StorageFailed));
        assert_eq!(lum.status().save, SaveState::Failed);
        assert!(lum.status().unsaved_changes);
    }

    #[test]
    fn output_fault_is_reported_until_start_or_set_config() {
        let mut lum = Luminaire::new(board(), RestoredConfig::Missing);
        let before = lum.status();
        assert_eq!(before.output_fault, None);
        assert!(before.running);
        lum.notify_output_fault(OutputFault::DmaTransferError);
        let status = lum.status();
        assert!(!status.running, "a faulted luminaire does not play");
        assert_eq!(status.output_fault, Some(OutputFault::DmaTransferError));
        assert_eq!(
            status.unsaved_changes, before.unsaved_changes,
            "a fault is not a configuration change"
        );
        assert!(lum.config().running, "the configuration still asks to play");
        lum.handle(1, &Request::Stop(()));
        assert_eq!(
            lum.status().output_fault,
            Some(OutputFault::DmaTransferError)
        );
        let (_, effects) = lum.handle(2, &Request::Start(()));
        assert_eq!(effects.as_slice(), [Effect::Start]);
        assert_eq!(lum.status().output_fault, None);
        assert!(lum.status().running);
        lum.notify_output_fault(OutputFault::DmaStopTimeout);
        lum.handle(3, &Request::SetConfig(other_config()));
        assert_eq!(lum.status().output_fault, None);
    }

    #[test]
    fn identify_and_ping() {
        let mut lum = Luminaire::new(board(), RestoredConfig::Missing);
        assert_eq!(lum.handle(1, &Request::Ping(77)).0, Response::Ping(77));
        let (response, effects) = lum.handle(2, &Request::Identify(5));
        assert_eq!(response, Response::Identify(Ok(())));
        assert_eq!(effects.as_slice(), [Effect::Identify { seconds: 5 }]);
        assert!(lum.status().identify_active);
        lum.notify_identify_finished();
        assert!(!lum.status().identify_active);
        assert_eq!(
            lum.handle(3, &Request::Identify(MAX_IDENTIFY_SECONDS + 1))
                .0,
            Response::Identify(Err(CommandError::InvalidArgument))
        );
    }

    #[test]
    fn endpoint_replies_and_counts() {
        let mut endpoint = Endpoint::new(Luminaire::new(board(), RestoredConfig::Missing));
        let mut buf = [0u8; MAX_FRAME_LEN];
        let mut stream = std::vec::Vec::new();
        stream.extend_from_slice(encode_request(5, &Request::Ping(1), &mut buf).unwrap());
        stream.extend_from_slice(&[0x33, 0x01, 0x02, 0x00]);
        stream.extend_from_slice(&[0x44; 2 * MAX_FRAME_LEN]);
        stream.push(0);
        stream.extend_from_slice(encode_request(6, &Request::Stop(()), &mut buf).unwrap());
        let mut replies = std::vec::Vec::new();
        for chunk in stream.chunks(5) {
            endpoint.on_bytes(chunk, |bytes, effects| {
                let mut raw = bytes.to_vec();
                let (header, response) = decode_response(&mut raw).unwrap();
                replies.push((header.seq, response, effects));
            });
        }
        let seqs: std::vec::Vec<_> = replies.iter().map(|r| r.0).collect();
        assert_eq!(seqs, [5, SEQ_UNKNOWN, SEQ_UNKNOWN, 6]);
        assert_eq!(replies[0].1, Response::Ping(1));
        assert_eq!(
            replies[1].1,
            Response::ProtocolError(ProtocolError::Malformed)
        );
        assert_eq!(
            replies[2].1,
            Response::ProtocolError(ProtocolError::FrameTooLong)
        );
        assert_eq!(replies[3].1, Response::Stop(Ok(())));
        assert_eq!(replies[3].2.as_slice(), [Effect::Stop]);
        let status = endpoint.luminaire.status();
        assert_eq!(
            (
                status.rx_frames_ok,
                status.rx_malformed,
                status.rx_too_long,
                status.rx_bad_crc
            ),
            (2, 1, 1, 0)
        );
        // handle_frame: a bad CRC is answered as such.
        let mut raw = encode_request(8, &Request::Ping(2), &mut buf)
            .unwrap()
            .to_vec();
        raw[4] ^= 0x01;
        let mut reply = [0u8; MAX_FRAME_LEN];
        let (bytes, effects) = endpoint.handle_frame(&mut raw, &mut reply);
        let mut bytes = bytes.unwrap().to_vec();
        assert!(effects.is_empty());
        assert_eq!(
            decode_response(&mut bytes).unwrap().1,
            Response::ProtocolError(ProtocolError::BadCrc)
        );
        assert_eq!(endpoint.luminaire.counters().bad_crc, 1);
    }

    #[test]
    fn set_config_refuses_flicker_above_low_risk_unless_accepted() {
        let mut luminaire = Luminaire::new(board(), RestoredConfig::Missing);
        let mut full = LuminaireConfig::FULL_DEPTH;
        full.allow_flicker = false;
        let (response, effects) = luminaire.handle(1, &Request::SetConfig(full));
        assert!(
            matches!(
                response,
                Response::SetConfig(Err(ConfigError::Flicker {
                    led: 0,
                    depth_permille: 1000,
                    ..
                }))
            ),
            "{response:?}"
        );
        assert!(effects.is_empty());
        assert_eq!(*luminaire.config(), LuminaireConfig::DEFAULT);
        full.allow_flicker = true;
        let (response, effects) = luminaire.handle(2, &Request::SetConfig(full));
        assert_eq!(response, Response::SetConfig(Ok(())));
        assert_eq!(
            effects.first(),
            Some(&Effect::ApplyOutput(OutputPlan::of(&full)))
        );
    }

    #[test]
    fn power_up_limits_a_stored_flicker_that_was_not_accepted() {
        let mut full = LuminaireConfig::FULL_DEPTH;
        full.allow_flicker = false;
        for restored in [RestoredConfig::Ok(full), RestoredConfig::WithoutDepth(full)] {
            let luminaire = Luminaire::new(board(), restored);
            let status = luminaire.status();
            assert!(status.flicker_limited, "{restored:?}");
            assert!(crate::flicker::is_low_risk(luminaire.config()));
            assert_eq!(
                luminaire.config().off_level_permille[..4],
                [738, 693, 889, 888]
            );
            let Effect::ApplyOutput(plan) = luminaire.startup_effects()[0] else {
                panic!("no output first");
            };
            assert_eq!(
                plan.off_level_permille,
                luminaire.config().off_level_permille
            );
        }
        let old = Luminaire::new(board(), RestoredConfig::WithoutDepth(full));
        assert_eq!(
            old.status().config_source,
            ConfigSource::RestoredWithoutDepth
        );
        // Saved on purpose: played as saved.
        let accepted = Luminaire::new(board(), RestoredConfig::Ok(LuminaireConfig::FULL_DEPTH));
        assert!(!accepted.status().flicker_limited);
        assert_eq!(*accepted.config(), LuminaireConfig::FULL_DEPTH);
        let default = Luminaire::new(board(), RestoredConfig::Missing);
        assert!(!default.status().flicker_limited);
    }
}
