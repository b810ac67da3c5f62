//! The host side of the luminaire protocol: one method per command over a [`Link`].
//!
//! Every request carries a fresh sequence number (counting up from a random start per client,
//! skipping 0, which is reserved for replies to unreadable frames, so that two sessions one
//! after the other do not reuse each other's numbers). A request whose reply does not arrive within [`Timeouts::reply`] is sent
//! again with the SAME sequence number, up to [`Timeouts::attempts`] times: the luminaire caches
//! its last reply per sequence number, so a retried `SetConfig` or `SaveConfig` is answered from
//! the cache and never executed twice. Every frame is preceded by a 0x00 delimiter so line
//! noise or a partial frame left by an earlier client can never corrupt it (see
//! `protocol::framing`).
//!
//! A save may stall the luminaire: erasing a 128 KiB flash sector stops the Black Pill's CPU
//! (and its USB) for up to 4 s. Requests around a save therefore keep retransmitting for at
//! least [`Timeouts::stall`] before giving up (`protocol::flash` derives both waits).

use std::path::Path;
use std::time::{Duration, Instant};

use protocol::config::{ConfigError, LuminaireConfig};
use protocol::framing::{
    FrameError, FrameEvent, MAX_FRAME_LEN, WireFrameReader, decode_response, encode_request,
};
use protocol::wire::{
    Command, CommandError, DeviceInfo, PROTOCOL_VERSION, ProtocolError, Request, Response,
    SEQ_UNKNOWN, SaveOutcome, SaveState, Status,
};

use super::transport::{Link, OpenError, SerialLink};

/// How long to wait for replies, and how often to try.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Timeouts {
    /// Time to wait for the reply to one transmission.
    pub reply: Duration,
    /// Transmissions per request (first try included), at least 1.
    pub attempts: u32,
    /// Longest wait for a deferred save to complete.
    pub save: Duration,
    /// Longest the luminaire may go silent around a save (a flash sector erase stalls its CPU
    /// for up to 4 s): requests during a save retransmit at least this long.
    pub stall: Duration,
}

impl Default for Timeouts {
    fn default() -> Self {
        Self {
            reply: Duration::from_millis(500),
            attempts: 3,
            save: Duration::from_millis(u64::from(protocol::flash::HOST_SAVE_TIMEOUT_MS)),
            stall: Duration::from_millis(u64::from(protocol::flash::HOST_STALL_MS)),
        }
    }
}

impl Timeouts {
    /// Transmissions per request: [`Self::attempts`], or enough to wait `patience` in all.
    fn attempts_for(&self, patience: Duration) -> u32 {
        let per_reply = self.reply.as_millis().max(1);
        let needed = patience.as_millis().div_ceil(per_reply);
        self.attempts
            .max(1)
            .max(u32::try_from(needed).unwrap_or(u32::MAX))
    }
}

/// Why a device command failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DeviceError {
    /// The port could not be opened (no device, busy, permissions).
    #[error(transparent)]
    Open(#[from] OpenError),
    /// The link failed mid-command (device unplugged, emulator stopped).
    #[error("link to the luminaire failed")]
    Link(#[from] std::io::Error),
    /// No valid reply after every attempt.
    #[error(
        "no reply to {command:?} after {attempts} attempt(s) of {reply_ms} ms each \
         (is this a meb luminaire, and is it running?)"
    )]
    Timeout {
        /// The command that went unanswered.
        command: Command,
        /// Transmissions made.
        attempts: u32,
        /// Reply timeout per transmission in milliseconds.
        reply_ms: u128,
    },
    /// The device speaks another protocol version.
    #[error(
        "protocol version mismatch: device speaks {device}, this host speaks {host}; \
         update the firmware or meb"
    )]
    ProtocolVersion {
        /// The device's version.
        device: u16,
        /// This host's version ([`PROTOCOL_VERSION`]).
        host: u16,
    },
    /// The device rejected a configuration; names the offending field.
    #[error("the luminaire rejected the configuration: {0}")]
    InvalidConfig(ConfigError),
    /// The device is busy (e.g. a save still in progress).
    #[error("the luminaire is busy ({command:?}): a save is still in progress; try again")]
    Busy {
        /// The refused command.
        command: Command,
    },
    /// A command's own failure other than busy.
    #[error("{command:?} failed on the luminaire: {error}")]
    Command {
        /// The failed command.
        command: Command,
        /// The device's error.
        error: CommandError,
    },
    /// The device answered every attempt with a frame-level protocol error.
    #[error("the luminaire reported a protocol error for {command:?}: {error}")]
    Protocol {
        /// The command being sent.
        command: Command,
        /// The device's error.
        error: ProtocolError,
    },
    /// The reply answered another command (a protocol bug on one side).
    #[error("the luminaire answered {command:?} with a reply to {got:?}")]
    UnexpectedReply {
        /// The command sent.
        command: Command,
        /// The command answered, `None` for a protocol error.
        got: Option<Command>,
    },
    /// The request could not be encoded (a host bug).
    #[error("cannot encode {command:?}: {error}")]
    Encode {
        /// The command.
        command: Command,
        /// The encoder's error.
        error: protocol::framing::EncodeError,
    },
    /// A deferred save completed with a storage failure.
    #[error("the luminaire could not write its configuration to storage")]
    SaveFailed,
    /// A deferred save did not complete in time.
    #[error("the luminaire's save did not complete within {0:?}")]
    SaveTimeout(Duration),
}

/// Host-side client of one luminaire.
#[derive(Debug)]
pub struct DeviceClient<L: Link = SerialLink> {
    link: L,
    timeouts: Timeouts,
    next_seq: u32,
    reader: WireFrameReader,
    noise: Option<ProtocolError>,
}

impl DeviceClient<SerialLink> {
    /// Opens the serial port at `port_path` (a `/dev/ttyACM*` or the emulator's pty).
    pub fn open(port_path: &Path, timeouts: Timeouts) -> Result<Self, DeviceError> {
        Ok(Self::new(SerialLink::open(port_path)?, timeouts))
    }
}

/// What one received frame means for the request in flight.
enum Reply {
    /// The answer.
    Answer(Response),
    /// Our frame arrived damaged: send it again.
    Resend(ProtocolError),
    /// A frame-level error reply without sequence number: maybe line noise, maybe our frame;
    /// noted, and the timeout decides.
    Noise(ProtocolError),
    /// Nothing for us (stale reply, damaged reply, empty).
    Ignore,
}

impl<L: Link> DeviceClient<L> {
    /// A client over an already open link.
    pub fn new(link: L, timeouts: Timeouts) -> Self {
        Self {
            link,
            timeouts,
            next_seq: first_sequence_number(),
            reader: WireFrameReader::new(),
            noise: None,
        }
    }

    /// The underlying link.
    pub fn link_mut(&mut self) -> &mut L {
        &mut self.link
    }

    /// Checks the link: the device echoes `nonce`; returns the round-trip time.
    pub fn ping(&mut self, nonce: u32) -> Result<Duration, DeviceError> {
        let started = Instant::now();
        match self.request(&Request::Ping(nonce))? {
            Response::Ping(echo) if echo == nonce => Ok(started.elapsed()),
            other => Err(unexpected(Command::Ping, &other)),
        }
    }

    /// Identity and limits (`GetInfo`).
    pub fn info(&mut self) -> Result<DeviceInfo, DeviceError> {
        match self.request(&Request::GetInfo(()))? {
            Response::GetInfo(info) => Ok(info),
            other => Err(unexpected(Command::GetInfo, &other)),
        }
    }

    /// The active configuration (`GetConfig`).
    pub fn config(&mut self) -> Result<LuminaireConfig, DeviceError> {
        match self.request(&Request::GetConfig(()))? {
            Response::GetConfig(config) => Ok(config),
            other => Err(unexpected(Command::GetConfig, &other)),
        }
    }

    /// Validates and applies `config` on the device (`SetConfig`, not persisted).
    pub fn set_config(&mut self, config: &LuminaireConfig) -> Result<(), DeviceError> {
        match self.request(&Request::SetConfig(*config))? {
            Response::SetConfig(Ok(())) => Ok(()),
            Response::SetConfig(Err(error)) => Err(DeviceError::InvalidConfig(error)),
            other => Err(unexpected(Command::SetConfig, &other)),
        }
    }

    /// Asks the device to persist its configuration (`SaveConfig`); may complete later. The
    /// device may stall while it erases flash: this waits up to [`Timeouts::stall`] for the reply.
    pub fn save(&mut self) -> Result<SaveOutcome, DeviceError> {
        let patience = self.timeouts.stall;
        match self.request_within(&Request::SaveConfig(()), patience)? {
            Response::SaveConfig(result) => {
                result.map_err(|e| command_error(Command::SaveConfig, e))
            }
            other => Err(unexpected(Command::SaveConfig, &other)),
        }
    }

    /// Persists the configuration and waits (polling `GetStatus`) until storage has it.
    pub fn save_and_wait(&mut self) -> Result<SaveOutcome, DeviceError> {
        let outcome = self.save()?;
        if outcome == SaveOutcome::AlreadySaved {
            return Ok(outcome);
        }
        let started = Instant::now();
        loop {
            let status = match self.request_within(&Request::GetStatus(()), self.timeouts.stall)? {
                Response::GetStatus(status) => status,
                other => return Err(unexpected(Command::GetStatus, &other)),
            };
            match status.save {
                SaveState::Idle => return Ok(outcome),
                SaveState::Failed => return Err(DeviceError::SaveFailed),
                SaveState::Pending if started.elapsed() > self.timeouts.save => {
                    return Err(DeviceError::SaveTimeout(self.timeouts.save));
                }
                SaveState::Pending => std::thread::sleep(Duration::from_millis(10)),
            }
        }
    }

    /// Starts the carriers.
    pub fn start(&mut self) -> Result<(), DeviceError> {
        match self.request(&Request::Start(()))? {
            Response::Start(result) => result.map_err(|e| command_error(Command::Start, e)),
            other => Err(unexpected(Command::Start, &other)),
        }
    }

    /// Stops the carriers (LEDs off).
    pub fn stop(&mut self) -> Result<(), DeviceError> {
        match self.request(&Request::Stop(()))? {
            Response::Stop(result) => result.map_err(|e| command_error(Command::Stop, e)),
            other => Err(unexpected(Command::Stop, &other)),
        }
    }

    /// Runtime state and link counters (`GetStatus`).
    pub fn status(&mut self) -> Result<Status, DeviceError> {
        match self.request(&Request::GetStatus(()))? {
            Response::GetStatus(status) => Ok(status),
            other => Err(unexpected(Command::GetStatus, &other)),
        }
    }

    /// Blinks all LEDs for `seconds` (0 ends a blink).
    pub fn identify(&mut self, seconds: u8) -> Result<(), DeviceError> {
        match self.request(&Request::Identify(seconds))? {
            Response::Identify(result) => result.map_err(|e| command_error(Command::Identify, e)),
            other => Err(unexpected(Command::Identify, &other)),
        }
    }

    /// Sends `request` and returns the device's answer, retrying with the same sequence number.
    pub fn request(&mut self, request: &Request) -> Result<Response, DeviceError> {
        self.request_within(request, Duration::ZERO)
    }

    /// [`Self::request`], retransmitting until at least `patience` has passed without a reply.
    fn request_within(
        &mut self,
        request: &Request,
        patience: Duration,
    ) -> Result<Response, DeviceError> {
        let command = request.command();
        let seq = self.take_seq();
        // Leading 0x00: ends whatever partial frame the device may hold.
        let mut frame = [0u8; MAX_FRAME_LEN + 1];
        let len = encode_request(seq, request, &mut frame[1..])
            .map_err(|error| DeviceError::Encode { command, error })?
            .len();
        let frame = &frame[..len + 1];
        let attempts = self.timeouts.attempts_for(patience);
        let mut last_protocol_error = None;
        self.noise = None;
        for _ in 0..attempts {
            self.link.send(frame)?;
            match self.await_reply(seq)? {
                Some(Ok(response)) => return check_command(command, response),
                Some(Err(error)) => last_protocol_error = Some(error),
                None => {}
            }
        }
        Err(match last_protocol_error.or(self.noise) {
            Some(error) => DeviceError::Protocol { command, error },
            None => DeviceError::Timeout {
                command,
                attempts,
                reply_ms: self.timeouts.reply.as_millis(),
            },
        })
    }

    fn take_seq(&mut self) -> u32 {
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        if self.next_seq == SEQ_UNKNOWN {
            self.next_seq = 1;
        }
        seq
    }

    /// Waits one reply timeout: `Some(Ok)` answer, `Some(Err)` resend, `None` nothing.
    fn await_reply(
        &mut self,
        seq: u32,
    ) -> Result<Option<Result<Response, ProtocolError>>, DeviceError> {
        let deadline = Instant::now() + self.timeouts.reply;
        let mut chunk = [0u8; 256];
        loop {
            let remaining = deadline.saturating_duration_since(Instant::now());
            if remaining.is_zero() {
                return Ok(None);
            }
            let n = self.link.receive(&mut chunk, remaining)?;
            let mut resend = None;
            for &byte in &chunk[..n] {
                let Some(FrameEvent::Frame(raw)) = self.reader.push(byte) else {
                    continue;
                };
                match classify(raw, seq)? {
                    Reply::Answer(response) => {
                        self.reader.reset();
                        return Ok(Some(Ok(response)));
                    }
                    Reply::Resend(error) => resend = Some(error),
                    Reply::Noise(error) => self.noise = Some(error),
                    Reply::Ignore => {}
                }
            }
            if let Some(error) = resend {
                return Ok(Some(Err(error)));
            }
        }
    }
}

/// A random sequence number to start a session at (never [`SEQ_UNKNOWN`]): std's per-process
/// random hashing keys are the randomness.
fn first_sequence_number() -> u32 {
    use std::hash::{BuildHasher, RandomState};
    let seq = RandomState::new().hash_one(std::process::id()) as u32;
    if seq == SEQ_UNKNOWN { 1 } else { seq }
}

/// Interprets one received frame while waiting for the reply to `seq`.
fn classify(raw: &mut [u8], seq: u32) -> Result<Reply, DeviceError> {
    match decode_response(raw) {
        Ok((header, Response::ProtocolError(ProtocolError::UnsupportedVersion { supported })))
            if header.seq == seq || header.seq == SEQ_UNKNOWN =>
        {
            Err(DeviceError::ProtocolVersion {
                device: supported,
                host: PROTOCOL_VERSION,
            })
        }
        Ok((header, Response::ProtocolError(error))) if header.seq == seq => {
            Ok(Reply::Resend(error))
        }
        Ok((header, Response::ProtocolError(error))) if header.seq == SEQ_UNKNOWN => {
            Ok(Reply::Noise(error))
        }
        Ok((header, response)) if header.seq == seq => Ok(Reply::Answer(response)),
        Ok(_) => Ok(Reply::Ignore),
        Err(FrameError::UnsupportedVersion { version, .. }) => Err(DeviceError::ProtocolVersion {
            device: version,
            host: PROTOCOL_VERSION,
        }),
        Err(_) => Ok(Reply::Ignore),
    }
}

fn check_command(command: Command, response: Response) -> Result<Response, DeviceError> {
    if response.command() == Some(command) {
        Ok(response)
    } else {
        Err(unexpected(command, &response))
    }
}

fn unexpected(command: Command, response: &Response) -> DeviceError {
    DeviceError::UnexpectedReply {
        command,
        got: response.command(),
    }
}

fn command_error(command: Command, error: CommandError) -> DeviceError {
    match error {
        CommandError::Busy => DeviceError::Busy { command },
        error => DeviceError::Command { command, error },
    }
}
