//! `meb carriers`: print the chip table, and with `--rate` its spectrum and flicker class.

use anyhow::{Context, Result};
use clap::Args;
use meb_core::flicker::{self, LedFlicker};
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
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
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
    let flicker = args
        .rate
        .map(|rate| flicker::analyse(&table, rate, REPORT_BELOW_HZ));
    let report = CarriersReport {
        leds: args.leds,
        chips: table.chips(),
        masks: table.masks().to_vec(),
        rate_hz: args.rate,
        flicker,
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
            "\nAt {rate} Hz chip rate (frame period {:.4} s):",
            report.chips as f64 / rate
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
    }
    Ok(())
}
