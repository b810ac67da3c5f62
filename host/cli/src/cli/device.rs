//! `meb device`: list, query and configure luminaires over USB serial, or emulate one.

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Result, anyhow, bail};
use clap::{Args, Subcommand};
use meb_device::discovery::{self, DiscoveryError, PortEntry};
use meb_device::settings::{self, DepthRequest, SettingsRequest, Spelling};
use meb_device::{DeviceClient, Timeouts};
use protocol::carriers::MAX_LEDS;
use protocol::config::LuminaireConfig;
use protocol::flicker::{self, LOW_RISK, NO_OBSERVABLE_EFFECT};
use protocol::wire::{ConfigSource, SaveOutcome};
use serde::Serialize;

/// Arguments of `meb device`.
#[derive(Args)]
pub struct DeviceArgs {
    /// Serial port of the luminaire (default: the only attached luminaire).
    #[arg(long, global = true)]
    port: Option<PathBuf>,
    /// Reply timeout per attempt in milliseconds.
    #[arg(long, global = true, default_value_t = 500)]
    timeout_ms: u64,
    /// Attempts per command (retries reuse the sequence number).
    #[arg(long, global = true, default_value_t = 3)]
    attempts: u32,
    #[command(subcommand)]
    action: DeviceAction,
}

/// What to do with the luminaire.
#[derive(Subcommand)]
enum DeviceAction {
    /// List serial ports, marking meb luminaires.
    List(JsonFlag),
    /// Firmware, protocol version, board and limits.
    Info(JsonFlag),
    /// Running state, save state and link counters.
    Status(JsonFlag),
    /// The active configuration.
    Get(JsonFlag),
    /// Apply a configuration (takes effect at once; `save` persists it).
    Set(SetArgs),
    /// Persist the active configuration to the luminaire's flash (refused above IEEE 1789 low
    /// risk unless --allow-flicker).
    Save {
        /// Save a configuration that flickers above IEEE 1789 low risk; the luminaire then
        /// plays it at power-up instead of limiting it.
        #[arg(long)]
        allow_flicker: bool,
    },
    /// Start playing the carriers.
    Start,
    /// Stop playing the carriers (LEDs off).
    Stop,
    /// Blink to find the luminaire: the board LED (PC13) on a Black Pill, every output on the
    /// virtual luminaire (0 s ends a blink).
    Identify {
        /// Blink duration in seconds (≤ 60).
        #[arg(long, default_value_t = 5)]
        seconds: u8,
    },
    /// Wiring check without instruments: each LED alone for 1 s, then every carrier at 4 chips
    /// per second for 8 s, then the configuration back (nothing is saved). Exempt from the
    /// flicker check: it flickers visibly on purpose.
    Blink,
    /// Check the link and measure the round-trip time.
    Ping(PingArgs),
    /// Run a virtual luminaire on a pseudo-terminal until Ctrl-C / SIGTERM.
    #[cfg(unix)]
    Emulate(EmulateArgs),
}

/// `--json` flag of a read command.
#[derive(Args)]
struct JsonFlag {
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// Arguments of `meb device set`.
#[derive(Args)]
struct SetArgs {
    /// Number of LEDs N (1..=8).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=8))]
    leds: u8,
    /// Chip rate in Hz (= the camera frame rate), e.g. 960 or 959.5; 1 to 4000 Hz.
    #[arg(long)]
    rate: f64,
    /// Per-LED brightness in per mille, N comma-separated values (default all 1000).
    #[arg(long, value_delimiter = ',')]
    brightness: Option<Vec<u16>>,
    /// Per-LED carrier delay in chips, N comma-separated values (default all 0).
    #[arg(long, value_delimiter = ',')]
    phase: Option<Vec<u16>>,
    /// Modulation depth (on − off)/(on + off) in (0, 1]: one value for every LED, N
    /// comma-separated values, or `auto` for each LED's largest IEEE 1789 low-risk depth at
    /// this rate (default: the luminaire's current off levels).
    #[arg(long, value_parser = super::parse::device_depth)]
    depth: Option<DepthRequest>,
    /// Apply a configuration that flickers above IEEE 1789 low risk (people in the room may
    /// see flicker, and below 60 Hz it can trigger seizures).
    #[arg(long)]
    allow_flicker: bool,
}

/// Arguments of `meb device ping`.
#[derive(Args)]
struct PingArgs {
    /// Number of pings (at least 1).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    count: u32,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// Arguments of `meb device emulate`.
#[cfg(unix)]
#[derive(Args)]
struct EmulateArgs {
    /// Record file standing in for flash (restart on the same file = power cycle).
    #[arg(long)]
    storage: Option<PathBuf>,
    /// Crystal error of the virtual board in ppm (chips play at rate × (1 + ppm·1e-6)).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    rate_error_ppm: f64,
    /// JSON file receiving the LED timeline (for `meb simulate --timeline`).
    #[arg(long)]
    timeline: Option<PathBuf>,
}

/// Runs `meb device`.
pub fn run(args: &DeviceArgs) -> Result<()> {
    match &args.action {
        DeviceAction::List(flag) => list(flag.json),
        #[cfg(unix)]
        DeviceAction::Emulate(emulate_args) => emulate::run(emulate_args),
        action => {
            let mut client = connect(args)?;
            talk(&mut client, action)
        }
    }
}

fn connect(args: &DeviceArgs) -> Result<DeviceClient> {
    let path = discovery::select_port(args.port.as_deref()).map_err(|err| match err {
        DiscoveryError::NoLuminaire | DiscoveryError::SeveralLuminaires(_) => {
            anyhow!("{err}; pass --port PATH (e.g. the path `meb device emulate` prints)")
        }
        other => other.into(),
    })?;
    let timeouts = Timeouts {
        reply: Duration::from_millis(args.timeout_ms),
        attempts: args.attempts.max(1),
        ..Timeouts::default()
    };
    Ok(DeviceClient::open(&path, timeouts)?)
}

fn talk(client: &mut DeviceClient, action: &DeviceAction) -> Result<()> {
    match action {
        DeviceAction::Info(flag) => {
            let info = client.info()?;
            if flag.json {
                return print_json(&info);
            }
            println!("board             {}", info.board);
            println!("firmware          {}", info.firmware_version);
            println!("protocol version  {}", info.protocol_version);
            println!("max LEDs          {}", info.max_leds);
            println!(
                "chip rate range   {:.3} .. {:.3} Hz",
                info.min_chip_rate.hz(),
                info.max_chip_rate.hz()
            );
            println!("carrier table     {:08x}", info.carrier_fingerprint);
        }
        DeviceAction::Status(flag) => {
            let s = client.status()?;
            if flag.json {
                return print_json(&s);
            }
            println!("running           {}", yes_no(s.running));
            match s.output_fault {
                Some(fault) => println!("output fault      {fault}"),
                None => println!("output fault      none"),
            }
            println!("config source     {}", source_text(s.config_source));
            if s.flicker_limited {
                println!(
                    "flicker limited   yes: the saved configuration flickers above IEEE 1789 low risk and was not saved with --allow-flicker; power-up raised its off levels (see `meb device get`)"
                );
            }
            println!("unsaved changes   {}", yes_no(s.unsaved_changes));
            println!("save              {:?}", s.save);
            println!("identify active   {}", yes_no(s.identify_active));
            println!(
                "frames received   {} ok, {} bad CRC, {} malformed, {} too long, {} wrong version",
                s.rx_frames_ok,
                s.rx_bad_crc,
                s.rx_malformed,
                s.rx_too_long,
                s.rx_unsupported_version
            );
        }
        DeviceAction::Get(flag) => {
            let view = ConfigView::of(&client.config()?);
            if flag.json {
                return print_json(&view);
            }
            view.print();
        }
        DeviceAction::Set(set) => {
            let current = client.config()?;
            let config = config_from_args(set, &current)?;
            check_flicker(&config, set.allow_flicker, "set")?;
            client.set_config(&config)?;
            println!("configuration applied (not yet saved; run `meb device save`)");
            ConfigView::of(&config).print();
        }
        DeviceAction::Save { allow_flicker } => {
            check_flicker(&client.config()?, *allow_flicker, "save")?;
            match client.save_and_wait()? {
                SaveOutcome::AlreadySaved => println!("already saved"),
                SaveOutcome::Deferred => println!("saved"),
            }
        }
        DeviceAction::Start => {
            client.start()?;
            println!("started");
        }
        DeviceAction::Stop => {
            client.stop()?;
            println!("stopped");
        }
        DeviceAction::Identify { seconds } => {
            client.identify(*seconds)?;
            println!("identifying for {seconds} s");
        }
        DeviceAction::Blink => return blink(client),
        DeviceAction::Ping(ping) => return ping_repeatedly(client, ping),
        DeviceAction::List(_) => {}
        #[cfg(unix)]
        DeviceAction::Emulate(_) => {}
    }
    Ok(())
}

/// Plays `protocol::bringup::blink_sequence`, naming each step as it starts; if a step fails,
/// tries to put the configuration from before the check back.
fn blink(client: &mut DeviceClient) -> Result<()> {
    let active = client.config()?;
    let leds = usize::from(active.led_count);
    println!(
        "bring-up blink: full on/off keying and a 4 Hz walk, visible flicker on purpose (exempt from the IEEE 1789 check; avoid it with people sensitive to flicker in the room)"
    );
    for (i, step) in protocol::bringup::blink_sequence(&active)
        .iter()
        .enumerate()
    {
        match i {
            i if i < leds => println!("LED {} alone", i + 1),
            i if i == leds => println!("all {leds} carriers at 4 chips per second"),
            _ => println!("configuration restored"),
        }
        std::io::stdout().flush()?;
        if let Err(err) = client.set_config(&step.config) {
            let restored = client.set_config(&active).is_ok();
            return Err(anyhow::Error::new(err).context(if restored {
                "blink step failed; configuration restored"
            } else {
                "blink step failed; restore with `meb device set` or a power cycle"
            }));
        }
        std::thread::sleep(Duration::from_millis(u64::from(step.hold_ms)));
    }
    Ok(())
}

/// Pings `ping.count` times, printing each round trip as it arrives (text) so that a link
/// that breaks keeps what it measured; JSON prints the measured list, also on failure.
fn ping_repeatedly(client: &mut DeviceClient, ping: &PingArgs) -> Result<()> {
    let mut rtts_ms = Vec::new();
    let mut failure = None;
    for nonce in 0..ping.count {
        match client.ping(nonce) {
            Ok(rtt) => {
                let ms = rtt.as_secs_f64() * 1e3;
                if !ping.json {
                    println!("pong in {ms:.2} ms");
                    std::io::stdout().flush()?;
                }
                rtts_ms.push(ms);
            }
            Err(err) => {
                failure = Some(err);
                break;
            }
        }
    }
    if ping.json {
        print_json(&serde_json::json!({ "round_trip_ms": rtts_ms }))?;
    }
    match failure {
        None => Ok(()),
        Some(err) => Err(anyhow::Error::new(err).context(format!(
            "ping {} of {} failed",
            rtts_ms.len() + 1,
            ping.count
        ))),
    }
}

/// Refuses `config` above IEEE 1789 low risk unless `allowed` (then warns), naming the LED,
/// the line that sets the limit and the depth and rate that would be low-risk.
fn check_flicker(config: &LuminaireConfig, allowed: bool, command: &str) -> Result<()> {
    let Some(excess) = settings::flicker_excess(config) else {
        return Ok(());
    };
    if allowed {
        eprintln!(
            "warning: LED {} flickers above IEEE 1789 low risk (accepted with --allow-flicker)",
            excess.led + 1
        );
        return Ok(());
    }
    bail!("{}", excess.refusal(command, &Spelling::CLI))
}

/// Readable boot source.
fn source_text(source: ConfigSource) -> &'static str {
    match source {
        ConfigSource::Defaults => "factory defaults (no saved configuration)",
        ConfigSource::Restored => "restored from flash",
        ConfigSource::CorruptRecordDefaults => "factory defaults (saved configuration corrupt)",
        ConfigSource::RestoredWithoutDepth => {
            "restored from flash, an old record without a depth: read as depth 1 (full on/off keying); set a depth and save again"
        }
    }
}

/// The full configuration `meb device set` sends: the flags given, the current off levels
/// for LEDs without `--depth`.
fn config_from_args(set: &SetArgs, current: &LuminaireConfig) -> Result<LuminaireConfig> {
    let request = SettingsRequest {
        leds: set.leds,
        rate_hz: set.rate,
        brightness: set.brightness.as_deref(),
        phase: set.phase.as_deref(),
        depth: set.depth.as_ref(),
        allow_flicker: set.allow_flicker,
    };
    Ok(settings::configure(&request, current, &Spelling::CLI)?)
}

/// A configuration as printed: only the N LEDs in use, the rate in Hz.
#[derive(Serialize)]
struct ConfigView {
    led_count: u8,
    chip_rate_hz: f64,
    chip_rate_millihertz: u32,
    brightness_permille: Vec<u16>,
    phase_chips: Vec<u16>,
    running: bool,
    off_level_permille: Vec<u16>,
    /// Modulation depth each LED plays, (on − off)/(on + off).
    depth: Vec<f32>,
    /// Largest IEEE 1789 low-risk and no-observable-effect depth of each LED at this rate.
    low_risk_depth: Vec<f32>,
    no_observable_effect_depth: Vec<f32>,
    allow_flicker: bool,
}

impl ConfigView {
    fn of(config: &LuminaireConfig) -> Self {
        let n = usize::from(config.led_count).min(MAX_LEDS);
        Self {
            led_count: config.led_count,
            chip_rate_hz: config.chip_rate.hz(),
            chip_rate_millihertz: config.chip_rate.millihertz(),
            brightness_permille: config.brightness_permille[..n].to_vec(),
            phase_chips: config.phase_chips[..n].to_vec(),
            running: config.running,
            off_level_permille: config.off_level_permille[..n].to_vec(),
            depth: (0..n)
                .map(|led| flicker::played_depth(config, led))
                .collect(),
            low_risk_depth: (0..n)
                .map(|led| flicker::max_depth(led as u8, config.chip_rate, &LOW_RISK).depth)
                .collect(),
            no_observable_effect_depth: (0..n)
                .map(|led| {
                    flicker::max_depth(led as u8, config.chip_rate, &NO_OBSERVABLE_EFFECT).depth
                })
                .collect(),
            allow_flicker: config.allow_flicker,
        }
    }

    fn print(&self) {
        let join = |v: &[u16]| v.iter().map(u16::to_string).collect::<Vec<_>>().join(",");
        println!("leds        {}", self.led_count);
        println!("chip rate   {:.3} Hz", self.chip_rate_hz);
        println!("brightness  {} per mille", join(&self.brightness_permille));
        println!("phase       {} chips", join(&self.phase_chips));
        println!(
            "off level   {} per mille of on",
            join(&self.off_level_permille)
        );
        let fmt = |v: &[f32]| {
            v.iter()
                .map(|d| format!("{d:.3}"))
                .collect::<Vec<_>>()
                .join(",")
        };
        println!(
            "depth       {} (low-risk up to {}; no observable effect up to {})",
            fmt(&self.depth),
            fmt(&self.low_risk_depth),
            fmt(&self.no_observable_effect_depth)
        );
        println!("running     {}", yes_no(self.running));
        if self.allow_flicker {
            println!("flicker     accepted above IEEE 1789 low risk (--allow-flicker)");
        }
    }
}

fn list(json: bool) -> Result<()> {
    let ports = discovery::list_ports()?;
    if json {
        return print_json(&ports);
    }
    if ports.is_empty() {
        println!("no serial ports");
    }
    for PortEntry {
        path,
        vid,
        pid,
        manufacturer,
        product,
        serial_number,
        is_luminaire,
    } in &ports
    {
        let ids = match (vid, pid) {
            (Some(v), Some(p)) => format!("{v:04x}:{p:04x}"),
            _ => "-".into(),
        };
        println!(
            "{}{}  {ids}  {} / {}  {}",
            if *is_luminaire { "* " } else { "  " },
            path.display(),
            manufacturer.as_deref().unwrap_or("-"),
            product.as_deref().unwrap_or("-"),
            serial_number.as_deref().unwrap_or("")
        );
    }
    if ports.iter().any(|p| p.is_luminaire) {
        println!("(* = meb luminaire)");
    }
    Ok(())
}

/// `meb device emulate` (pseudo-terminals and signals: Unix only).
#[cfg(unix)]
mod emulate {
    use std::io::Write;
    use std::path::Path;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::Duration;

    use anyhow::{Context, Result};
    use meb_device::{EmulatorOptions, VirtualLuminaire};
    use nix::sys::signal::{SigSet, Signal};

    use super::EmulateArgs;

    pub fn run(args: &EmulateArgs) -> Result<()> {
        // Block SIGINT/SIGTERM in every thread; one watcher thread receives them with sigwait.
        let mut signals = SigSet::empty();
        signals.add(Signal::SIGINT);
        signals.add(Signal::SIGTERM);
        signals
            .thread_block()
            .context("cannot block SIGINT/SIGTERM")?;
        let stop = Arc::new(AtomicBool::new(false));
        let stop_flag = Arc::clone(&stop);
        std::thread::spawn(move || {
            let _ = signals.wait();
            stop_flag.store(true, Ordering::Relaxed);
        });

        let emulator = VirtualLuminaire::spawn(EmulatorOptions {
            storage: args.storage.clone(),
            rate_error_ppm: args.rate_error_ppm,
            timeline: args.timeline.clone(),
            ..EmulatorOptions::default()
        })?;
        println!("{}", emulator.port_path().display());
        std::io::stdout().flush()?;
        eprintln!(
            "virtual luminaire on {} (booted from {:?}); Ctrl-C to stop",
            emulator.port_path().display(),
            emulator.restored()
        );
        while !stop.load(Ordering::Relaxed) && emulator.is_running() {
            std::thread::sleep(Duration::from_millis(50));
        }
        let timeline = emulator.shutdown()?;
        eprintln!(
            "virtual luminaire stopped after {} output change(s){}",
            timeline.segments.len(),
            args.timeline
                .as_deref()
                .map(|p: &Path| format!("; timeline in {}", p.display()))
                .unwrap_or_default()
        );
        Ok(())
    }
}

fn print_json<T: Serialize>(value: &T) -> Result<()> {
    println!("{}", serde_json::to_string_pretty(value)?);
    Ok(())
}

fn yes_no(flag: bool) -> &'static str {
    if flag { "yes" } else { "no" }
}
