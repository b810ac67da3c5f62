//! `meb carriers`: print the chip table, and with `--rate` its spectrum and flicker class.

use anyhow::{Context, Result};
use clap::Args;
use meb_core::flicker::{self, LedFlicker};
use meb_core::mains;
use protocol::carriers::ChipTable;
use serde::Serialize;

/// Arguments of `meb carriers`.
#[derive(Args)]
pub struct CarriersArgs {
    /// Number of LEDs (1..=8).
    #[arg(long, default_value_t = 4)]
    leds: u8,
    /// Chip rate in Hz (= the camera's frame rate): adds each LED's spectrum below 200 Hz and
    /// its IEEE 1789 flicker-risk class.
    #[arg(long)]
    rate: Option<f64>,
    /// Camera frame rate in Hz (default: the chip rate): with --rate, adds where room-light
    /// flicker on 50 and 60 Hz mains falls among the carriers' lines, and chip rates that keep
    /// it clear.
    #[arg(long, requires = "rate")]
    fps: Option<f64>,
    /// Modulation depth (on − off)/(on + off) in (0, 1] of every LED (1: full on/off keying):
    /// with --rate, the IEEE 1789 class at that depth, each LED's largest low-risk and
    /// no-observable-effect depth and the noise cost 1/depth (docs/howto/flicker-safety.md).
    #[arg(long, default_value_t = 1.0, requires = "rate")]
    depth: f64,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

/// Frames of the decoding window the mains check assumes (the decoder's usual window).
const MAINS_WINDOW_FRAMES: usize = 128;
/// Chip rates within this fraction of the frame rate are suggested (the decoder's default
/// rate search).
const MAINS_SEARCH: f64 = 0.06;

/// Where mains flicker falls at this chip rate and camera rate.
#[derive(Serialize)]
struct MainsReport {
    fps: f64,
    window_frames: usize,
    clashes: Vec<mains::Clash>,
    clear_chip_rates_hz: Vec<f64>,
}

/// The mains-flicker section: clashes at `rate` on a camera at `fps`, and clear chip rates.
fn mains_report(leds: u8, rate: f64, fps: f64) -> MainsReport {
    MainsReport {
        fps,
        window_frames: MAINS_WINDOW_FRAMES,
        clashes: mains::clashes(leds, rate, fps, MAINS_WINDOW_FRAMES),
        clear_chip_rates_hz: mains::clear_chip_rates(
            leds,
            fps,
            MAINS_WINDOW_FRAMES,
            MAINS_SEARCH,
            5,
        ),
    }
}

/// Prints the mains-flicker section.
fn print_mains(report: &MainsReport, rate: f64) {
    println!(
        "\nRoom-light flicker (100 Hz family: 50 Hz mains, 120 Hz: 60 Hz mains) at {rate} Hz chip \
         rate, camera {} fps, {}-frame windows:",
        report.fps, report.window_frames
    );
    if report.clashes.is_empty() {
        println!("  clear: no flicker harmonic falls on a carrier line");
    }
    for c in &report.clashes {
        println!(
            "  {:.0} Hz family harmonic {} ({:.4} cycles/frame) falls on LED {}'s line ({:.4}): \
             that LED's gain is unreliable under such a lamp",
            c.family_hz, c.harmonic, c.flicker_cycles_per_frame, c.led, c.line_cycles_per_frame
        );
    }
    if !report.clashes.is_empty() {
        let rates: Vec<String> = report
            .clear_chip_rates_hz
            .iter()
            .map(|r| format!("{r:.1} Hz"))
            .collect();
        println!(
            "  chip rates that keep both families clear: {}",
            if rates.is_empty() {
                "none within 6 % of the frame rate".to_string()
            } else {
                rates.join(", ")
            }
        );
    }
}

#[derive(Serialize)]
struct CarriersReport {
    leds: u8,
    chips: usize,
    masks: Vec<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    rate_hz: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    flicker: Option<Vec<LedFlicker>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    mains: Option<MainsReport>,
}

/// Spectrum lines up to this frequency are listed (the flicker-sensitive band).
const REPORT_BELOW_HZ: f64 = 200.0;

/// Runs `meb carriers`.
pub fn run(args: &CarriersArgs) -> Result<()> {
    let table = ChipTable::new(args.leds).context("invalid --leds")?;
    if let Some(rate) = args.rate
        && !(rate.is_finite() && rate > 0.0)
    {
        anyhow::bail!("--rate must be a positive number of Hz, got {rate}");
    }
    if !(args.depth > 0.0 && args.depth <= 1.0) {
        anyhow::bail!("--depth must lie in (0, 1], got {}", args.depth);
    }
    let flicker = args
        .rate
        .map(|rate| flicker::analyse_at_depth(&table, rate, REPORT_BELOW_HZ, args.depth));
    if let Some(fps) = args.fps
        && !(fps.is_finite() && fps > 0.0)
    {
        anyhow::bail!("--fps must be a positive number of Hz, got {fps}");
    }
    let mains = args
        .rate
        .map(|rate| mains_report(args.leds, rate, args.fps.unwrap_or(rate)));
    let report = CarriersReport {
        leds: args.leds,
        chips: table.chips(),
        masks: table.masks().to_vec(),
        rate_hz: args.rate,
        flicker,
        mains,
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    println!(
        "{} LEDs, {} chips per frame (mask bit i = LED i+1 on)",
        report.leds, report.chips
    );
    println!(
        "{:>5}  {}",
        "chip",
        (1..=args.leds)
            .map(|i| format!("L{i}"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    for (chip, mask) in report.masks.iter().enumerate() {
        let cells: Vec<&str> = (0..args.leds)
            .map(|i| if mask & (1 << i) != 0 { "on" } else { " ." })
            .collect();
        println!("{chip:>5}  {}   mask {mask}", cells.join(" "));
    }
    if let (Some(rate), Some(flicker)) = (report.rate_hz, &report.flicker) {
        println!(
            "\nAt {rate} Hz chip rate (frame period {:.4} s), depth {}:",
            report.chips as f64 / rate,
            args.depth
        );
        for led in flicker {
            let lines: Vec<String> = led
                .components
                .iter()
                .map(|c| format!("{:.1} Hz {:.1} %", c.frequency_hz, c.modulation_percent))
                .collect();
            println!(
                "  LED {}: fundamental {:.1} Hz, IEEE 1789: {}; below {REPORT_BELOW_HZ} Hz: {}",
                led.led,
                led.fundamental_hz,
                led.class,
                if lines.is_empty() {
                    "none".to_string()
                } else {
                    lines.join(", ")
                }
            );
        }
        let min = |f: fn(&LedFlicker) -> f64| flicker.iter().map(f).fold(1.0, f64::min);
        let low_risk = min(|l| l.low_risk_depth);
        let noel = min(|l| l.no_observable_effect_depth);
        println!(
            "  largest depth for every LED: low risk {low_risk:.4} (decoding noise ×{:.1} of full depth), no observable effect {noel:.4} (×{:.1}); per LED: {}",
            1.0 / low_risk,
            1.0 / noel,
            flicker
                .iter()
                .map(|l| format!("{:.4}", l.low_risk_depth))
                .collect::<Vec<_>>()
                .join(", ")
        );
        println!(
            "  at depth {}: noise on LED images and normals ×{:.1} of full depth (same mean light)",
            args.depth,
            1.0 / args.depth
        );
    }
    if let (Some(rate), Some(mains)) = (report.rate_hz, &report.mains) {
        print_mains(mains, rate);
    }
    Ok(())
}
