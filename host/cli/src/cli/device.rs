//! `meb device`: list, query and configure luminaires over USB serial, or emulate one.

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Result, anyhow, bail};
use clap::{Args, Subcommand};
use meb_device::discovery::{self, DiscoveryError, PortEntry};
use meb_device::{DeviceClient, Timeouts};
use protocol::carriers::MAX_LEDS;
use protocol::config::{ChipRate, FULL_BRIGHTNESS_PERMILLE, LuminaireConfig};
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
    #[arg(long)]
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
    #[arg(long)]
    depth: Option<String>,
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

/// Refuses `config` above IEEE 1789 low risk unless `allowed`, naming the LED, the line that
/// sets the limit and the depth and rate that would be low-risk.
fn check_flicker(config: &LuminaireConfig, allowed: bool, command: &str) -> Result<()> {
    let Some(excess) = flicker::first_excess(config, &LOW_RISK) else {
        return Ok(());
    };
    if allowed {
        eprintln!(
            "warning: LED {} flickers above IEEE 1789 low risk (accepted with --allow-flicker)",
            excess.led + 1
        );
        return Ok(());
    }
    let f = excess.limit.frequency_hz;
    let band = if (flicker::SEIZURE_BAND_HZ.0..=flicker::SEIZURE_BAND_HZ.1).contains(&f) {
        ", inside the 3–60 Hz band where flicker can trigger seizures"
    } else {
        ""
    };
    let leds = usize::from(config.led_count);
    let auto: Vec<String> = (0..leds)
        .map(|led| {
            format!(
                "{:.3}",
                flicker::max_depth(led as u8, config.chip_rate, &LOW_RISK).depth
            )
        })
        .collect();
    let depth = excess.depth;
    let rate = lowest_low_risk_rate(config)
        .map(|hz| format!("a chip rate of at least {hz} Hz at this depth"))
        .unwrap_or_else(|| "no chip rate up to 4000 Hz at this depth".into());
    bail!(
        "refusing to {command}: LED {} plays its {f:.2} Hz line at {:.2} % modulation (depth {depth:.3}), above IEEE 1789 low risk ({:.2} % at {f:.2} Hz){band}.
         Low-risk: --depth auto (depths {}; decoding noise ×{:.1} of full depth), or {rate}; or pass --allow-flicker to {command} it anyway.",
        excess.led + 1,
        depth * excess.limit.full_depth_percent,
        LOW_RISK.percent_at(f).unwrap_or(f32::INFINITY),
        auto.join(","),
        1.0 / flicker::max_depth(excess.led, config.chip_rate, &LOW_RISK).depth,
    )
}

/// The lowest whole chip rate in hertz, from `config`'s up to 4000 Hz, at which its LEDs'
/// depths are low-risk.
fn lowest_low_risk_rate(config: &LuminaireConfig) -> Option<u32> {
    let start = config.chip_rate.hz().ceil() as u32;
    (start..=4000).find(|&hz| {
        let mut trial = *config;
        trial.chip_rate = ChipRate(hz * 1000);
        flicker::is_low_risk(&trial)
    })
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

/// Off levels for `--depth`: `auto`, one depth or one per LED.
fn off_levels_from_arg(
    arg: &str,
    n: usize,
    auto: &LuminaireConfig,
    out: &mut [u16; MAX_LEDS],
) -> Result<()> {
    if arg.trim() == "auto" {
        *out = auto.off_level_permille;
        return Ok(());
    }
    let depths: Vec<f32> = arg
        .split(',')
        .map(|v| {
            v.trim()
                .parse::<f32>()
                .ok()
                .filter(|d| *d > 0.0 && *d <= 1.0)
                .ok_or_else(|| anyhow!("--depth {v:?}: a depth in (0, 1] or `auto` expected"))
        })
        .collect::<Result<_>>()?;
    match depths.len() {
        1 => out[..n].fill(flicker::off_level_for_depth(depths[0])),
        len if len == n => {
            for (level, &d) in out.iter_mut().zip(&depths) {
                *level = flicker::off_level_for_depth(d);
            }
        }
        len => bail!("--depth needs 1 or {n} values (one per LED), got {len}"),
    }
    Ok(())
}

/// The full configuration `meb device set` sends: the flags given, the current off levels
/// for LEDs without `--depth`.
fn config_from_args(set: &SetArgs, current: &LuminaireConfig) -> Result<LuminaireConfig> {
    let running = current.running;
    let n = usize::from(set.leds);
    if n == 0 || n > MAX_LEDS {
        bail!("--leds {} is outside 1..={MAX_LEDS}", set.leds);
    }
    let (min, max) = (ChipRate::MIN.hz(), ChipRate::MAX.hz());
    // Checked in hertz: converting first would saturate 1e9 Hz to u32::MAX millihertz.
    if !(set.rate >= min && set.rate <= max) {
        bail!(
            "--rate {} Hz is outside the supported {min:.3}..={max:.3} Hz",
            set.rate
        );
    }
    let mut brightness = [FULL_BRIGHTNESS_PERMILLE; MAX_LEDS];
    if let Some(values) = &set.brightness {
        per_led("--brightness", values, n, &mut brightness)?;
    }
    let mut phases = [0u16; MAX_LEDS];
    if let Some(values) = &set.phase {
        per_led("--phase", values, n, &mut phases)?;
    }
    let mut config = LuminaireConfig {
        led_count: set.leds,
        chip_rate: ChipRate::from_hz(set.rate),
        brightness_permille: brightness,
        phase_chips: phases,
        running,
        off_level_permille: current.off_level_permille,
        allow_flicker: set.allow_flicker,
    };
    if let Some(arg) = &set.depth {
        let auto = flicker::at_largest_low_risk_depths(&config);
        off_levels_from_arg(arg, n, &auto, &mut config.off_level_permille)?;
    }
    Ok(config)
}

fn per_led(flag: &str, values: &[u16], n: usize, out: &mut [u16; MAX_LEDS]) -> Result<()> {
    if values.len() != n {
        bail!(
            "{flag} needs {n} values (one per LED), got {}",
            values.len()
        );
    }
    out[..n].copy_from_slice(values);
    Ok(())
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
