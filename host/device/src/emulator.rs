//! The virtual luminaire: the `protocol` crate's own state machine ([`Endpoint`]) served on a
//! pseudo-terminal, with a file for flash and a recorded light timeline instead of LEDs.
//!
//! It answers byte for byte like the firmware, because it runs the same code; only the
//! hardware effects differ: `ApplyOutput`/`Start`/`Stop`/`Identify` append to a [`Timeline`]
//! (optionally mirrored to a JSON file), `Persist` writes the [`ConfigStore`] file (pausing for
//! [`EmulatorOptions::save_stall`] as the board's CPU stalls during a flash erase) and reports
//! back with `notify_saved`. [`VirtualLuminaire::inject_output_fault`] plays a DMA fault the way
//! the firmware's carrier watch reports one. Restarting on the same storage file is a power
//! cycle.

use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use protocol::luminaire::{BoardInfo, Effect, Endpoint, Luminaire, OutputPlan, RestoredConfig};
use protocol::wire::{CommandError, OutputFault};

use super::pty::{PseudoTerminal, PtyError};
use super::storage::ConfigStore;
use super::timeline::{OutputMode, Timeline, TimelineError, TimelineSegment};

/// Board name the emulator reports in `GetInfo`.
pub const EMULATOR_BOARD: &str = "emulator";

/// How the virtual luminaire is set up.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EmulatorOptions {
    /// Record file standing in for flash; `None` keeps saves in memory only.
    pub storage: Option<PathBuf>,
    /// Crystal error: the chips play at nominal × (1 + ppm·10⁻⁶).
    pub rate_error_ppm: f64,
    /// File the light timeline is written to after every change.
    pub timeline: Option<PathBuf>,
    /// How long serving pauses on every save, like the board whose CPU stalls while a flash
    /// sector is erased (up to 4 s); zero by default.
    pub save_stall: Duration,
}

/// Error starting or running the virtual luminaire.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EmulatorError {
    /// The pseudo-terminal could not be set up or failed.
    #[error(transparent)]
    Pty(#[from] PtyError),
    /// The timeline file could not be written.
    #[error(transparent)]
    Timeline(#[from] TimelineError),
    /// The rate error is not a finite number above −10⁶ ppm.
    #[error("rate error {0} ppm is not a usable crystal error")]
    RateError(f64),
    /// The serving thread could not be started.
    #[error("cannot start the emulator thread")]
    Spawn(#[source] io::Error),
    /// The serving thread panicked.
    #[error("the emulator thread panicked")]
    Panicked,
}

/// Where the luminaire booted from and what it plays, shared with the serving thread.
#[derive(Debug)]
struct Shared {
    timeline: Mutex<Timeline>,
    stop: AtomicBool,
    fault: Mutex<Option<OutputFault>>,
}

/// A running virtual luminaire; stops when shut down or dropped.
#[derive(Debug)]
pub struct VirtualLuminaire {
    port_path: PathBuf,
    restored: RestoredConfig,
    shared: Arc<Shared>,
    thread: Option<JoinHandle<Result<(), EmulatorError>>>,
}

impl VirtualLuminaire {
    /// Boots a luminaire from `options.storage` and serves it on a new pseudo-terminal.
    pub fn spawn(options: EmulatorOptions) -> Result<Self, EmulatorError> {
        let ppm = options.rate_error_ppm;
        if !ppm.is_finite() || ppm <= -1e6 {
            return Err(EmulatorError::RateError(ppm));
        }
        let store = options.storage.clone().map(ConfigStore::new);
        let restored = store
            .as_ref()
            .map_or(RestoredConfig::Missing, ConfigStore::load);
        let pty = PseudoTerminal::open()?;
        let port_path = pty.slave_path().to_path_buf();
        let board = BoardInfo {
            firmware_version: env!("CARGO_PKG_VERSION").try_into().unwrap_or_default(),
            board: EMULATOR_BOARD.try_into().unwrap_or_default(),
        };
        let mut server = Server {
            pty,
            endpoint: Endpoint::new(Luminaire::new(board, restored)),
            store,
            ram_copy: None,
            started: Instant::now(),
            identify_until: None,
            running: false,
            plan: None,
            options,
            shared: Arc::new(Shared {
                timeline: Mutex::new(Timeline::new(ppm)),
                stop: AtomicBool::new(false),
                fault: Mutex::new(None),
            }),
        };
        let shared = Arc::clone(&server.shared);
        server.boot()?;
        let thread = std::thread::Builder::new()
            .name("virtual-luminaire".into())
            .spawn(move || server.serve())
            .map_err(EmulatorError::Spawn)?;
        Ok(Self {
            port_path,
            restored,
            shared,
            thread: Some(thread),
        })
    }

    /// The serial port clients open (the pseudo-terminal's slave, e.g. `/dev/pts/7`).
    pub fn port_path(&self) -> &Path {
        &self.port_path
    }

    /// What the luminaire booted from (stored config, missing, corrupt).
    pub fn restored(&self) -> RestoredConfig {
        self.restored
    }

    /// A copy of the light timeline recorded so far.
    pub fn timeline(&self) -> Timeline {
        self.shared
            .timeline
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// Makes the virtual hardware stop its carriers with `fault`, as the firmware does when a
    /// DMA stream fails: the outputs go off and `GetStatus` reports the fault until the next
    /// `Start` or `SetConfig`.
    pub fn inject_output_fault(&self, fault: OutputFault) {
        *self
            .shared
            .fault
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = Some(fault);
    }

    /// Whether the serving thread is still running.
    pub fn is_running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Stops serving ("power off") and returns the recorded timeline.
    pub fn shutdown(mut self) -> Result<Timeline, EmulatorError> {
        self.stop_and_join()?;
        Ok(self.timeline())
    }

    fn stop_and_join(&mut self) -> Result<(), EmulatorError> {
        self.shared.stop.store(true, Ordering::Relaxed);
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(_)) => Err(EmulatorError::Panicked),
            None => Ok(()),
        }
    }
}

impl Drop for VirtualLuminaire {
    fn drop(&mut self) {
        let _ = self.stop_and_join();
    }
}

/// The serving thread's state.
struct Server {
    pty: PseudoTerminal,
    endpoint: Endpoint,
    store: Option<ConfigStore>,
    ram_copy: Option<protocol::config::LuminaireConfig>,
    started: Instant,
    identify_until: Option<Instant>,
    running: bool,
    plan: Option<OutputPlan>,
    options: EmulatorOptions,
    shared: Arc<Shared>,
}

impl Server {
    fn boot(&mut self) -> Result<(), EmulatorError> {
        let effects = self.endpoint.luminaire.startup_effects();
        self.carry_out(effects.iter().copied())
    }

    fn serve(mut self) -> Result<(), EmulatorError> {
        let mut chunk = [0u8; 512];
        let mut effects = Vec::new();
        while !self.shared.stop.load(Ordering::Relaxed) {
            if let Some(until) = self.identify_until
                && Instant::now() >= until
            {
                self.identify_until = None;
                self.endpoint.luminaire.notify_identify_finished();
                self.record()?;
            }
            self.watch_carriers()?;
            if !self.pty.wait_readable(Duration::from_millis(20))? {
                continue;
            }
            let n = match self.pty.master().read(&mut chunk) {
                Ok(n) => n,
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
                    ) =>
                {
                    continue;
                }
                // EIO: no client has the line open; wait for one.
                Err(e) if e.raw_os_error() == Some(nix::libc::EIO) => {
                    std::thread::sleep(Duration::from_millis(20));
                    continue;
                }
                Err(e) => return Err(PtyError::Io(e).into()),
            };
            let Self { pty, endpoint, .. } = &mut self;
            endpoint.on_bytes(&chunk[..n], |reply, reply_effects| {
                // A client that stopped reading loses replies, as with a full USB endpoint.
                let _ = pty.master().write_all(reply);
                effects.extend(reply_effects.iter().copied());
            });
            self.carry_out(effects.drain(..))?;
        }
        Ok(())
    }

    /// The firmware's carrier watch: an injected fault stops the carriers and is reported.
    fn watch_carriers(&mut self) -> Result<(), EmulatorError> {
        let fault = self
            .shared
            .fault
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take();
        if let Some(fault) = fault
            && self.running
        {
            self.running = false;
            self.endpoint.luminaire.notify_output_fault(fault);
            self.record()?;
        }
        Ok(())
    }

    /// Plays effects on the "hardware", then records the resulting output once.
    fn carry_out(&mut self, effects: impl Iterator<Item = Effect>) -> Result<(), EmulatorError> {
        for effect in effects {
            match effect {
                Effect::ApplyOutput(plan) => self.plan = Some(plan),
                Effect::Start => self.running = true,
                Effect::Stop => self.running = false,
                Effect::Identify { seconds } => {
                    self.identify_until = (seconds > 0)
                        .then(|| Instant::now() + Duration::from_secs(u64::from(seconds)));
                    if seconds == 0 {
                        self.endpoint.luminaire.notify_identify_finished();
                    }
                }
                Effect::Persist(config) => {
                    // The board's CPU (and its USB) stalls while flash is erased.
                    std::thread::sleep(self.options.save_stall);
                    let result = match &self.store {
                        Some(store) => store.save(&config).map_err(|_| CommandError::StorageFailed),
                        None => {
                            self.ram_copy = Some(config);
                            Ok(())
                        }
                    };
                    self.endpoint.luminaire.notify_saved(result);
                }
            }
        }
        self.record()
    }

    /// Appends a timeline segment if the light output changed.
    fn record(&mut self) -> Result<(), EmulatorError> {
        let Some(plan) = self.plan else {
            return Ok(());
        };
        let mode = if self.identify_until.is_some() {
            OutputMode::Identify
        } else if self.running {
            OutputMode::Playing
        } else {
            OutputMode::Off
        };
        let t = self.started.elapsed().as_secs_f64();
        let segment = TimelineSegment::new(t, mode, &plan, self.options.rate_error_ppm);
        let mut timeline = self
            .shared
            .timeline
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        let unchanged = timeline
            .segments
            .last()
            .is_some_and(|last| TimelineSegment { t, ..last.clone() } == segment);
        if unchanged {
            return Ok(());
        }
        timeline.segments.push(segment);
        if let Some(path) = &self.options.timeline {
            timeline.write(path)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::{DeviceClient, DeviceError, Timeouts};
    use crate::transport::{Link, SerialLink};
    use protocol::config::{ChipRate, ConfigError, LuminaireConfig};
    use protocol::wire::{ConfigSource, SaveOutcome};

    fn quick() -> Timeouts {
        Timeouts {
            reply: Duration::from_millis(300),
            attempts: 3,
            save: Duration::from_secs(5),
            stall: Duration::from_secs(3),
        }
    }

    #[test]
    fn configure_save_power_cycle_restores() {
        let dir = tempfile::tempdir().unwrap();
        let options = EmulatorOptions {
            storage: Some(dir.path().join("flash.rec")),
            rate_error_ppm: 50.0,
            timeline: Some(dir.path().join("timeline.json")),
            ..EmulatorOptions::default()
        };
        let emulator = VirtualLuminaire::spawn(options.clone()).unwrap();
        assert_eq!(emulator.restored(), RestoredConfig::Missing);
        let mut client = DeviceClient::open(emulator.port_path(), quick()).unwrap();
        let mut config = LuminaireConfig::DEFAULT;
        config.led_count = 3;
        config.chip_rate = ChipRate(959_500);
        config.phase_chips[2] = 7;
        config.off_level_permille[..3].copy_from_slice(&[750, 700, 900]);
        client.set_config(&config).unwrap();
        assert_eq!(client.config().unwrap(), config);
        assert_eq!(client.save_and_wait().unwrap(), SaveOutcome::Deferred);
        assert_eq!(client.save_and_wait().unwrap(), SaveOutcome::AlreadySaved);
        drop(client);
        let timeline = emulator.shutdown().unwrap();
        let last = timeline.segments.last().unwrap();
        assert_eq!(last.led_count, 3);
        assert!((last.effective_chip_rate_hz - 959.5 * (1.0 + 50e-6)).abs() < 1e-9);
        assert!(
            Timeline::read(options.timeline.as_ref().unwrap())
                .unwrap()
                .approx_eq(&timeline)
        );

        let emulator = VirtualLuminaire::spawn(options).unwrap();
        assert_eq!(emulator.restored(), RestoredConfig::Ok(config));
        let mut client = DeviceClient::open(emulator.port_path(), quick()).unwrap();
        assert_eq!(client.config().unwrap(), config);
        assert_eq!(
            client.status().unwrap().config_source,
            ConfigSource::Restored
        );
    }

    #[test]
    fn a_save_that_stalls_the_luminaire_for_two_seconds_still_completes() {
        let emulator = VirtualLuminaire::spawn(EmulatorOptions {
            save_stall: Duration::from_secs(2),
            ..EmulatorOptions::default()
        })
        .unwrap();
        // Three replies of 500 ms each (1.5 s) would give up during the stall; the client
        // keeps trying for `stall` (3 s by default) around a save.
        let timeouts = Timeouts::default();
        assert!(timeouts.stall >= Duration::from_secs(3));
        let mut client = DeviceClient::open(emulator.port_path(), timeouts).unwrap();
        let started = Instant::now();
        assert_eq!(client.save_and_wait().unwrap(), SaveOutcome::Deferred);
        assert!(started.elapsed() >= Duration::from_secs(2));
        assert!(!client.status().unwrap().unsaved_changes);
        // Without that patience the same save fails.
        drop(client);
        let impatient = Timeouts {
            stall: Duration::ZERO,
            ..Timeouts::default()
        };
        let mut client = DeviceClient::open(emulator.port_path(), impatient).unwrap();
        client
            .set_config(&LuminaireConfig {
                led_count: 2,
                ..LuminaireConfig::DEFAULT
            })
            .unwrap();
        assert!(matches!(
            client.save_and_wait(),
            Err(DeviceError::Timeout { .. })
        ));
    }

    #[test]
    fn an_output_fault_stops_the_light_and_shows_in_status_until_start() {
        let emulator = VirtualLuminaire::spawn(EmulatorOptions::default()).unwrap();
        let mut client = DeviceClient::open(emulator.port_path(), quick()).unwrap();
        assert_eq!(client.status().unwrap().output_fault, None);
        emulator.inject_output_fault(OutputFault::DmaTransferError);
        let deadline = Instant::now() + Duration::from_secs(5);
        let status = loop {
            let status = client.status().unwrap();
            if status.output_fault.is_some() || Instant::now() > deadline {
                break status;
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        assert_eq!(status.output_fault, Some(OutputFault::DmaTransferError));
        assert!(!status.running);
        let last = emulator.timeline().segments.last().cloned().unwrap();
        assert_eq!(last.mode, OutputMode::Off, "the light went off");
        client.start().unwrap();
        let status = client.status().unwrap();
        assert_eq!(status.output_fault, None);
        assert!(status.running);
        let last = emulator.timeline().segments.last().cloned().unwrap();
        assert_eq!(last.mode, OutputMode::Playing);
    }

    #[test]
    fn invalid_config_names_the_field_and_changes_nothing() {
        let emulator = VirtualLuminaire::spawn(EmulatorOptions::default()).unwrap();
        let mut client = DeviceClient::open(emulator.port_path(), quick()).unwrap();
        let before = client.config().unwrap();
        let mut bad = before;
        bad.phase_chips[1] = 32;
        match client.set_config(&bad) {
            Err(DeviceError::InvalidConfig(ConfigError::Phase { led: 1, got: 32 })) => {}
            other => panic!("{other:?}"),
        }
        assert_eq!(client.config().unwrap(), before);
    }

    /// Drops the first `drop_replies` chunks the device sends back.
    struct LossyLink {
        inner: SerialLink,
        drop_replies: usize,
        sent: usize,
    }

    impl Link for LossyLink {
        fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
            self.sent += 1;
            self.inner.send(bytes)
        }
        fn receive(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
            let n = self.inner.receive(buf, timeout)?;
            if n > 0 && self.drop_replies > 0 {
                self.drop_replies -= 1;
                // Swallow the rest of this reply too.
                std::thread::sleep(Duration::from_millis(50));
                let mut rest = [0u8; 256];
                while self.inner.receive(&mut rest, Duration::from_millis(10))? > 0 {}
                return Ok(0);
            }
            Ok(n)
        }
        fn discard_input(&mut self) -> io::Result<()> {
            self.inner.discard_input()
        }
    }

    #[test]
    fn lost_reply_is_retried_with_the_same_sequence_number() {
        let emulator = VirtualLuminaire::spawn(EmulatorOptions::default()).unwrap();
        let link = LossyLink {
            inner: SerialLink::open(emulator.port_path()).unwrap(),
            drop_replies: 1,
            sent: 0,
        };
        let mut client = DeviceClient::new(link, quick());
        let segments_before = emulator.timeline().segments.len();
        let mut config = LuminaireConfig::DEFAULT;
        config.led_count = 2;
        client.set_config(&config).unwrap();
        assert_eq!(client.link_mut().sent, 2, "one retransmission");
        // The device answered the retry from its cache: applied once, one frame counted twice.
        assert_eq!(emulator.timeline().segments.len(), segments_before + 1);
        let status = client.status().unwrap();
        assert_eq!(status.rx_frames_ok, 3);
        assert_eq!(client.config().unwrap(), config);
    }

    #[test]
    fn no_reply_is_a_timeout() {
        let pty = PseudoTerminal::open().unwrap();
        let mut client = DeviceClient::open(
            pty.slave_path(),
            Timeouts {
                reply: Duration::from_millis(30),
                attempts: 2,
                save: Duration::from_secs(1),
                stall: Duration::ZERO,
            },
        )
        .unwrap();
        match client.ping(7) {
            Err(DeviceError::Timeout { attempts: 2, .. }) => {}
            other => panic!("{other:?}"),
        }
    }
}
