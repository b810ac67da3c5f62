//! The chip engine executed on the register model: for N = 1..8 LEDs, the chip rates 30, 240,
//! 959.5, 960 and 4000 Hz and several brightness sets, the compare values each chip plays must
//! be the chip table's on-mask × brightness for two whole code periods, after the first start,
//! after stop → start and after a reload while running; and across the halt race.

use protocol::carriers::{ChipTable, MAX_LEDS};
use protocol::timing::chip_timer_period;

use super::Chip;
use super::check::{check_all_off, check_playback};
use super::legacy::LegacyEngine;
use crate::plan::{FrameMemory, Mode};
use crate::step::Bus;

/// Timer clock of TIM2/TIM3/TIM5 on the Black Pill.
const CLOCK: u32 = 96_000_000;
/// Where the tests put the frame buffers.
const FRAMES: FrameMemory = FrameMemory {
    tim3: 0x2000_4000,
    tim5: 0x2000_8000,
};
/// Chip rates of the issue, in millihertz.
const RATES: [u32; 5] = [30_000, 240_000, 959_500, 960_000, 4_000_000];
/// One PWM period in ticks.
const PWM_PERIOD: u64 = 1000;

/// What the tests drive: the engine under test.
trait UnderTest: Sized {
    fn boot(chip: &mut Chip, mode: Mode) -> Self;
    fn load(&mut self, chip: &mut Chip, table: &ChipTable, brightness: &[u16; MAX_LEDS], rate: u32);
    fn start(&mut self, chip: &mut Chip);
    fn stop(&mut self, chip: &mut Chip);
}

impl UnderTest for LegacyEngine {
    fn boot(chip: &mut Chip, _mode: Mode) -> Self {
        LegacyEngine::new(chip, FRAMES)
    }
    fn load(
        &mut self,
        chip: &mut Chip,
        table: &ChipTable,
        brightness: &[u16; MAX_LEDS],
        rate: u32,
    ) {
        LegacyEngine::load(self, chip, table, brightness, rate);
    }
    fn start(&mut self, chip: &mut Chip) {
        LegacyEngine::start(self, chip);
    }
    fn stop(&mut self, chip: &mut Chip) {
        LegacyEngine::halt(self, chip);
    }
}

/// The engine the playback tests run.
type Engine = LegacyEngine;

/// Brightness sets: full, graded, and a seeded pseudo-random one.
fn brightness_sets() -> [[u16; MAX_LEDS]; 3] {
    let mut random = [0u16; MAX_LEDS];
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    for value in &mut random {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        *value = (state % 1001) as u16;
    }
    [
        [1000; MAX_LEDS],
        [1000, 800, 650, 500, 350, 200, 100, 1],
        random,
    ]
}

fn chip_ticks(rate: u32) -> u64 {
    chip_timer_period(CLOCK, rate, 32).unwrap().ticks()
}

/// Start of the chip in progress at the model's current time.
fn last_boundary(chip: &Chip) -> u64 {
    super::check::chip_boundaries(&chip.log, 0)
        .last()
        .copied()
        .unwrap_or(chip.now)
}

/// Plays `table` from a start or reload at `from` and checks two code periods.
fn play_and_check(
    chip: &mut Chip,
    from: u64,
    table: &ChipTable,
    brightness: &[u16; MAX_LEDS],
    rate: u32,
    what: &str,
) -> Result<(), String> {
    let n = table.chips() as u64;
    chip.run_until(from + (2 * n + 2) * chip_ticks(rate) + 2 * PWM_PERIOD);
    check_playback(&chip.log, from, table, brightness, 2 * table.chips())
        .map_err(|e| format!("{what}: {e}"))
}

/// First start, stop → start, and a reload while running (other phases and brightness).
fn scenario<E: UnderTest>(
    mode: Mode,
    leds: u8,
    rate: u32,
    brightness: &[u16; MAX_LEDS],
) -> Result<(), String> {
    let mut chip = Chip::new();
    let mut engine = E::boot(&mut chip, mode);
    let table = ChipTable::new(leds).unwrap();
    let ticks = chip_ticks(rate);
    engine.load(&mut chip, &table, brightness, rate);
    let from = chip.now;
    engine.start(&mut chip);
    play_and_check(&mut chip, from, &table, brightness, rate, "first start")?;

    // Stop in the middle of a chip: everything off within a PWM period, then start again.
    chip.run_until(last_boundary(&chip) + ticks / 2 + 1);
    engine.stop(&mut chip);
    chip.run_until(chip.now + PWM_PERIOD);
    check_all_off(&chip.log, chip.now).map_err(|e| format!("after stop: {e}"))?;
    chip.run_until(chip.now + ticks / 3 + 17);
    let from = chip.now;
    engine.start(&mut chip);
    play_and_check(&mut chip, from, &table, brightness, rate, "stop → start")?;

    // Reload while running, mid-chip: other phases and brightness, playing from chip 0.
    let mut phases = [0u16; MAX_LEDS];
    for (i, phase) in phases.iter_mut().enumerate() {
        *phase = ((i * 37 + 11) % table.chips()) as u16;
    }
    let other = ChipTable::with_phases(leds, &phases).unwrap();
    let mut other_brightness = *brightness;
    other_brightness.reverse();
    chip.run_until(last_boundary(&chip) + ticks / 2 + 3);
    let from = chip.now;
    engine.load(&mut chip, &other, &other_brightness, rate);
    play_and_check(
        &mut chip,
        from,
        &other,
        &other_brightness,
        rate,
        "reload while running",
    )?;

    if chip.violations.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "violations: {:?}",
            &chip.violations[..chip.violations.len().min(5)]
        ))
    }
}

/// Every LED count, rate and brightness set in `mode`; returns the failures.
fn sweep<E: UnderTest>(mode: Mode) -> Vec<String> {
    let mut failures = Vec::new();
    for leds in 1..=MAX_LEDS as u8 {
        for rate in RATES {
            for (set, brightness) in brightness_sets().iter().enumerate() {
                if let Err(e) = scenario::<E>(mode, leds, rate, brightness) {
                    failures.push(format!(
                        "N = {leds}, {} Hz, brightness set {set}: {e}",
                        f64::from(rate) / 1000.0
                    ));
                }
            }
        }
    }
    failures
}

#[test]
fn dma_chain_plays_the_chip_table_for_every_led_count_rate_and_brightness() {
    let failures = sweep::<Engine>(Mode::Dma);
    for failure in failures.iter().take(12) {
        println!("{failure}");
    }
    assert!(
        failures.is_empty(),
        "{} of 120 configurations play the wrong compare values",
        failures.len()
    );
}

/// Stops the engine `offset` ticks before a chip boundary, starts it again and checks two code
/// periods; `None` when it played right.
fn halt_race<E: UnderTest>(mode: Mode, leds: u8, offset: u64) -> Option<String> {
    let rate = 4_000_000;
    let mut chip = Chip::new();
    let mut engine = E::boot(&mut chip, mode);
    let table = ChipTable::new(leds).unwrap();
    let brightness = brightness_sets()[1];
    let ticks = chip_ticks(rate);
    engine.load(&mut chip, &table, &brightness, rate);
    engine.start(&mut chip);
    chip.run_until(chip.now + 3 * ticks + ticks / 2);
    let boundary = last_boundary(&chip) + ticks;
    chip.run_until(boundary - offset);
    engine.stop(&mut chip);
    chip.run_until(chip.now + ticks / 4);
    let from = chip.now;
    engine.start(&mut chip);
    let result = play_and_check(
        &mut chip,
        from,
        &table,
        &brightness,
        rate,
        "start after the halt race",
    );
    match (result, chip.violations.is_empty()) {
        (Ok(()), true) => None,
        (Err(e), _) => Some(format!("offset {offset}: {e}")),
        (Ok(()), false) => Some(format!("offset {offset}: violations {:?}", chip.violations)),
    }
}

#[test]
fn halt_race_never_moves_the_channels() {
    let mut failures = Vec::new();
    for leds in [4, 8] {
        for offset in (0..400).step_by(2) {
            if let Some(e) = halt_race::<Engine>(Mode::Dma, leds, offset) {
                failures.push(format!("N = {leds}, {e}"));
            }
        }
    }
    for failure in failures.iter().take(8) {
        println!("{failure}");
    }
    assert!(
        failures.is_empty(),
        "{} halt instants break the next start",
        failures.len()
    );
}

/// Keeps `Bus` in use for the legacy engine's helper calls.
#[allow(dead_code)]
fn bus_is_object_safe(_: &mut dyn Bus) {}
