//! The chip engine executed on the register model: for N = 1..8 LEDs, the chip rates 30, 240,
//! 959.5, 960 and 4000 Hz and several brightness sets, the compare values each chip plays must
//! be the chip table's on-mask × brightness for two whole code periods, after the first start,
//! after stop → start and after a reload while running; and across the halt race. The same for
//! the chip-interrupt fallback; then faults, the watchdog, and today's engine for comparison.

use protocol::carriers::{ChipTable, MAX_LEDS};
use protocol::timing::chip_timer_period;
use protocol::wire::OutputFault;

use super::check::{Lights, check_all_off, check_playback};
use super::legacy::LegacyEngine;
use super::{Chip, Timing};
use crate::outputs::Bank;
use crate::plan::{
    ChipEngine, ChipError, ChipInterrupt, ChipInterruptSlot, FrameMemory, Loaded, Mode,
    STREAM_STOP_POLLS, WATCHDOG_FEED, WATCHDOG_FEED_MS, WATCHDOG_MIN_TIMEOUT_MS, clock_plan,
    halt_plan, start_plan, watchdog_plan, watchdog_setting,
};
use crate::regs::dma;
use crate::step::{Bus, PLAN_CAPACITY, run};

/// Timer clock of TIM2/TIM3/TIM5 on the Black Pill.
const CLOCK: u32 = 96_000_000;
/// Where the tests put the frame buffers.
const FRAMES: FrameMemory = FrameMemory {
    tim3: 0x2000_4000,
    tim5: 0x2000_8000,
};
/// Chip rates under test (30 Hz to the 4 kHz maximum, a fractional rate), in millihertz.
const RATES: [u32; 5] = [30_000, 240_000, 959_500, 960_000, 4_000_000];
/// Full brightness, full on/off keying.
const FULL: Lights = Lights::full_depth([1000; MAX_LEDS]);
/// One PWM period in ticks.
const PWM_PERIOD: u64 = 1000;

/// What the tests drive: the engine under test.
trait UnderTest: Sized {
    fn boot(chip: &mut Chip, mode: Mode) -> Self;
    fn load(&mut self, chip: &mut Chip, table: &ChipTable, brightness: &Lights, rate: u32);
    fn start(&mut self, chip: &mut Chip);
    fn stop(&mut self, chip: &mut Chip);
}

/// This crate's chip engine.
struct Planned(ChipEngine);

impl UnderTest for Planned {
    fn boot(chip: &mut Chip, mode: Mode) -> Self {
        Planned(ChipEngine::new(chip, CLOCK, FRAMES, mode).expect("boot"))
    }
    fn load(&mut self, chip: &mut Chip, table: &ChipTable, brightness: &Lights, rate: u32) {
        self.0
            .load(chip, table, &brightness.levels(), rate)
            .expect("load");
    }
    fn start(&mut self, chip: &mut Chip) {
        self.0.start(chip).expect("start");
    }
    fn stop(&mut self, chip: &mut Chip) {
        self.0.stop(chip).expect("stop");
    }
}

/// The engine of today's main (see `legacy`); `NDTR_WRITTEN` repairs only its NDTR bug.
struct Todays<const NDTR_WRITTEN: bool>(LegacyEngine);

impl<const NDTR_WRITTEN: bool> UnderTest for Todays<NDTR_WRITTEN> {
    fn boot(chip: &mut Chip, _mode: Mode) -> Self {
        let mut engine = LegacyEngine::new(chip, FRAMES);
        engine.ndtr_written = NDTR_WRITTEN;
        Todays(engine)
    }
    fn load(&mut self, chip: &mut Chip, table: &ChipTable, brightness: &Lights, rate: u32) {
        self.0.load(chip, table, &brightness.levels(), rate);
    }
    fn start(&mut self, chip: &mut Chip) {
        self.0.start(chip);
    }
    fn stop(&mut self, chip: &mut Chip) {
        self.0.halt(chip);
    }
}

/// The engine the playback tests run.
type Engine = Planned;

/// Brightness and off-level sets: full brightness at full depth; graded brightness at the
/// factory default's low-risk off levels and a few others; a seeded pseudo-random set of both.
fn brightness_sets() -> [Lights; 3] {
    let mut random = Lights::full_depth([0; MAX_LEDS]);
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    for (value, off) in random.brightness.iter_mut().zip(&mut random.off_level) {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        *value = (state % 1001) as u16;
        *off = ((state >> 20) % 1001) as u16;
    }
    [
        Lights::full_depth([1000; MAX_LEDS]),
        Lights {
            brightness: [1000, 800, 650, 500, 350, 200, 100, 1],
            off_level: [738, 693, 889, 888, 1000, 500, 999, 1],
        },
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
    brightness: &Lights,
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
    brightness: &Lights,
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
    let other_brightness = brightness.reversed();
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

/// Fails, listing the first of `failures`, unless there are none.
fn assert_no_failures(failures: &[String], what: &str) {
    for failure in failures.iter().take(12) {
        println!("{failure}");
    }
    assert!(failures.is_empty(), "{} {what}", failures.len());
}

/// Runs [`sweep`] in `mode`: all 120 configurations must play right.
fn assert_every_configuration_plays(mode: Mode) {
    let failures = sweep::<Engine>(mode);
    assert_no_failures(
        &failures,
        "of 120 configurations play the wrong compare values",
    );
}

#[test]
fn dma_chain_plays_the_chip_table_for_every_led_count_rate_and_brightness() {
    assert_every_configuration_plays(Mode::Dma);
}

/// Stops the engine `offset` ticks after a chip boundary (negative: before it), starts it
/// again and checks two code periods; returns the failure (if any) and the burst index of every
/// trigger request the halt cut (see `Chip::requests_cut`).
fn halt_race<E: UnderTest>(
    mode: Mode,
    timing: Timing,
    leds: u8,
    offset: i64,
) -> (Option<String>, Vec<u32>) {
    let rate = 4_000_000;
    let mut chip = Chip::new();
    chip.timing = timing;
    let mut engine = E::boot(&mut chip, mode);
    let table = ChipTable::new(leds).unwrap();
    let brightness = brightness_sets()[1];
    let ticks = chip_ticks(rate);
    engine.load(&mut chip, &table, &brightness, rate);
    engine.start(&mut chip);
    chip.run_until(chip.now + 3 * ticks + ticks / 2);
    let boundary = last_boundary(&chip) + ticks;
    chip.run_until(boundary.saturating_add_signed(offset));
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
    let failure = match (result, chip.violations.is_empty()) {
        (Ok(()), true) => None,
        (Err(e), _) => Some(format!("offset {offset}: {e}")),
        (Ok(()), false) => Some(format!("offset {offset}: violations {:?}", chip.violations)),
    };
    (failure, chip.requests_cut)
}

/// Bus timings the halt race is swept under: the defaults, and a DMA slowed by bus contention
/// (a request waits 48 ticks, an item takes 12), where a trigger can still be pending, nothing
/// transferred, when the halt switches the requests off.
fn race_timings() -> [Timing; 2] {
    [
        Timing::default(),
        Timing {
            dma_latency: 48,
            dma_item: 12,
            ..Timing::default()
        },
    ]
}

/// Halt instants swept: every 2 ticks from 400 ticks before a chip boundary to 200 after it,
/// which covers the whole halt plan (42 steps of ~6 ticks) meeting the trigger and its 4-item
/// burst, from either side.
fn halt_race_sweep<E: UnderTest>(mode: Mode) -> (Vec<String>, Vec<u32>) {
    let mut failures = Vec::new();
    let mut cut = Vec::new();
    for timing in race_timings() {
        for leds in [4, 8] {
            for offset in (-400..200).step_by(2) {
                let (failure, requests_cut) = halt_race::<E>(mode, timing, leds, offset);
                cut.extend(requests_cut);
                if let Some(e) = failure {
                    failures.push(format!(
                        "N = {leds}, DMA latency {}, {e}",
                        timing.dma_latency
                    ));
                }
            }
        }
    }
    (failures, cut)
}

#[test]
fn halt_race_never_moves_the_channels() {
    let (failures, cut) = halt_race_sweep::<Engine>(Mode::Dma);
    assert_no_failures(&failures, "halt instants break the next start");
    // The sweep met both sides of the race: a trigger pending with nothing transferred yet
    // (NDTR a multiple of 4) and a burst cut half-way.
    assert!(
        cut.contains(&0),
        "no halt met a pending trigger at NDTR % 4 == 0: {cut:?}"
    );
    assert!(
        cut.iter().any(|&i| i > 0),
        "no halt met a burst half-way: {cut:?}"
    );
}

#[test]
fn chip_interrupt_fallback_plays_the_chip_table_for_every_led_count_rate_and_brightness() {
    assert_every_configuration_plays(Mode::ChipInterrupt);
    let (failures, _) = halt_race_sweep::<Engine>(Mode::ChipInterrupt);
    assert_no_failures(&failures, "halt instants break the next start");
}

#[test]
fn todays_main_plays_nothing() {
    // Today's engine gives both streams NDTR = 0: no request is ever served.
    let error = scenario::<Todays<false>>(Mode::Dma, 4, 960_000, &FULL).unwrap_err();
    println!("{error}");
    assert!(
        error.contains("chip 0 of 32")
            && error.contains("plays [Some(0), Some(0), Some(0), Some(0)]"),
        "{error}"
    );
}

#[test]
fn todays_halt_moves_the_channels_even_with_ndtr_written() {
    // Repairing only the NDTR bug leaves the halt race: stopping the DMA mid-burst (or with a
    // trigger pending) leaves the timers' DMA burst state where it was, and the next start
    // plays the frames shifted.
    scenario::<Todays<true>>(Mode::Dma, 4, 960_000, &FULL)
        .expect("with NDTR written, today's engine plays away from the race");
    let (failures, _) = halt_race_sweep::<Todays<true>>(Mode::Dma);
    println!(
        "{} halt instants break the next start, e.g. {:?}",
        failures.len(),
        failures.first()
    );
    assert!(
        !failures.is_empty(),
        "the model does not show the halt race"
    );
}

/// A chip with the engine playing `leds` LEDs at 960 Hz, full brightness, `chips` chips in.
fn playing(leds: u8, chips: u64) -> (Chip, ChipEngine, ChipTable) {
    let mut chip = Chip::new();
    let mut engine = ChipEngine::new(&mut chip, CLOCK, FRAMES, Mode::Dma).unwrap();
    let table = ChipTable::new(leds).unwrap();
    engine
        .load(&mut chip, &table, &FULL.levels(), 960_000)
        .unwrap();
    engine.start(&mut chip).unwrap();
    chip.run_until(chip.now + chips * chip_ticks(960_000));
    (chip, engine, table)
}

#[test]
fn transfer_error_stops_the_carriers_and_is_reported() {
    let (mut chip, mut engine, _) = playing(8, 5);
    assert_eq!(
        engine.poll_fault(&mut chip),
        None,
        "a healthy chain has no fault"
    );
    // A corrupted pointer: TIM5's frames now answer with a bus error.
    chip.unmap(FRAMES.tim5..FRAMES.tim5 + Bank::Tim5.frame_buffer_bytes());
    chip.run_until(chip.now + 3 * chip_ticks(960_000));
    let stream = Bank::Tim5.stream();
    assert_ne!(
        chip.peek(stream.isr()) & stream.flags(dma::TEIF),
        0,
        "TEIF of stream 1"
    );
    assert_eq!(
        chip.peek(stream.cr()) & dma::CR_EN,
        0,
        "the error disabled the stream"
    );
    assert_eq!(
        engine.poll_fault(&mut chip),
        Some(OutputFault::DmaTransferError)
    );
    assert!(!engine.is_running());
    chip.run_until(chip.now + PWM_PERIOD);
    check_all_off(&chip.log, chip.now).unwrap();
    assert_eq!(engine.poll_fault(&mut chip), None, "reported once");
    assert!(chip.violations.is_empty(), "{:?}", chip.violations);
}

/// The model with one stream whose EN never reads 0 (a hung transfer).
struct HungStream<'a>(&'a mut Chip, u32);

impl Bus for HungStream<'_> {
    fn read(&mut self, addr: u32) -> u32 {
        let value = self.0.read(addr);
        if addr == self.1 {
            value | dma::CR_EN
        } else {
            value
        }
    }
    fn write(&mut self, addr: u32, value: u32) {
        self.0.write(addr, value);
    }
    fn read16(&mut self, addr: u32) -> u16 {
        self.0.read16(addr)
    }
    fn write16(&mut self, addr: u32, value: u16) {
        self.0.write16(addr, value);
    }
    fn fence(&mut self) {
        self.0.fence();
    }
}

impl ChipInterruptSlot for HungStream<'_> {
    fn set_chip_interrupt(&mut self, interrupt: Option<ChipInterrupt>) {
        self.0.set_chip_interrupt(interrupt);
    }
}

#[test]
fn a_stream_that_never_stops_is_an_error_and_the_outputs_still_go_off() {
    let (mut chip, mut engine, table) = playing(4, 3);
    let started = chip.now;
    let hung_cr = Bank::Tim3.stream().cr();
    let error = engine
        .stop(&mut HungStream(&mut chip, hung_cr))
        .unwrap_err();
    assert_eq!(error.fault(), Some(OutputFault::DmaStopTimeout));
    // Bounded: STREAM_STOP_POLLS reads of a few ticks each, not forever.
    let spent = chip.now - started;
    assert!(spent < 10 * u64::from(STREAM_STOP_POLLS), "{spent} ticks");
    chip.run_until(chip.now + PWM_PERIOD);
    check_all_off(&chip.log, chip.now).unwrap();
    // A reload over the hung stream reports it and starts nothing.
    engine.start(&mut chip).unwrap();
    let reload = engine.load(
        &mut HungStream(&mut chip, hung_cr),
        &table,
        &Lights::full_depth([500; MAX_LEDS]).levels(),
        960_000,
    );
    assert!(
        matches!(reload, Err(ChipError::StreamStuck(_))),
        "{reload:?}"
    );
    assert!(!engine.is_running());
    chip.run_until(chip.now + PWM_PERIOD);
    check_all_off(&chip.log, chip.now).unwrap();
}

#[test]
fn watchdog_outlasts_the_longest_flash_erase_at_any_lsi_frequency() {
    let mut chip = Chip::new();
    let setting = watchdog_setting(WATCHDOG_MIN_TIMEOUT_MS);
    run(watchdog_plan(setting).steps(), &mut chip).unwrap();
    run(&[WATCHDOG_FEED], &mut chip).unwrap();
    assert!(chip.iwdg.running && chip.iwdg.feeds == 1);
    assert!(chip.watchdog_frozen_in_debug());
    let (slowest, typical, fastest) = crate::regs::iwdg::LSI_HZ;
    let shortest = chip.watchdog_timeout_ms(fastest);
    println!(
        "IWDG PR {} RLR {}: {} ms at 47 kHz, {} ms at 32 kHz, {} ms at 17 kHz",
        setting.prescaler_code,
        setting.reload,
        shortest,
        chip.watchdog_timeout_ms(typical),
        chip.watchdog_timeout_ms(slowest)
    );
    // The worst save stall (a 4 s sector erase at x8) with its margin plus a feeding period,
    // with the LSI at its fastest.
    let stall = u64::from(protocol::flash::SAVE_STALL_MAX_MS);
    assert!(stall >= 4_000);
    assert!(
        shortest >= stall * 3 / 2 + u64::from(WATCHDOG_FEED_MS),
        "{shortest} ms"
    );
    assert!(shortest < stall * 3 / 2 + 2 * u64::from(WATCHDOG_FEED_MS));
    assert_eq!(shortest, setting.timeout_ms(fastest));
    assert_eq!(
        (setting.prescaler_code, setting.reload),
        (5, 2390),
        "6.5 s at 47 kHz"
    );
    // Still a reset within 20 s at the slowest LSI, not minutes.
    assert!(chip.watchdog_timeout_ms(slowest) <= 20_000);
    assert!(chip.violations.is_empty(), "{:?}", chip.violations);
}

#[test]
fn plans_fit_their_capacity() {
    let loaded = Loaded {
        chips: 512,
        period: chip_timer_period(CLOCK, 30_000, 32).unwrap(),
        rate_microhertz: 0,
        error_ppb: 0,
        bank_chips: [32, 512],
    };
    let lengths = [
        clock_plan().steps().len(),
        halt_plan().steps().len(),
        start_plan(&loaded, &FRAMES, Mode::Dma).steps().len(),
        start_plan(&loaded, &FRAMES, Mode::ChipInterrupt)
            .steps()
            .len(),
        watchdog_plan(watchdog_setting(WATCHDOG_MIN_TIMEOUT_MS))
            .steps()
            .len(),
    ];
    println!("plan lengths: {lengths:?}");
    assert_eq!(
        lengths[1], 42,
        "the halt plan, the longest, as documented at PLAN_CAPACITY"
    );
    assert!(
        lengths
            .iter()
            .all(|&n| n > 0 && n <= lengths[1] && n <= PLAN_CAPACITY)
    );
}

/// The register values the first-flash bring-up (firmware/README.md) tells a user to expect
/// with the factory default (4 LEDs, 960 Hz, full brightness), read from the model the way
/// `probe-rs read` reads the board: mid-chip, a few chips apart. The README must carry exactly
/// this table.
#[test]
fn bring_up_values_in_the_firmware_readme_are_the_models() {
    use crate::regs::{TIM3, TIM5, tim};
    let mut chip = Chip::new();
    let mut engine = ChipEngine::new(&mut chip, CLOCK, FRAMES, Mode::Dma).unwrap();
    let table = ChipTable::new(4).unwrap();
    engine
        .load(&mut chip, &table, &FULL.levels(), 960_000)
        .unwrap();
    engine.start(&mut chip).unwrap();
    let ticks = chip_ticks(960_000);
    let start = last_boundary(&chip);
    let (s4, s1) = (Bank::Tim3.stream(), Bank::Tim5.stream());
    let mut rows = vec![
        "| chip | S4 NDTR | S1 NDTR | TIM3 SR.TIF | TIM3 CCR1–4 | TIM5 CCR1–4 |".to_string(),
        "|------|---------|---------|-------------|-------------|-------------|".to_string(),
    ];
    for k in [1u64, 2, 3, 4, 8] {
        chip.run_until(start + 6 + k * ticks + ticks / 2);
        let ccrs = |chip: &mut Chip, timer: crate::regs::GpTimer| {
            (1..=4)
                .map(|c| chip.peek(timer.ccr(c)).to_string())
                .collect::<Vec<_>>()
                .join(" ")
        };
        let tif = chip.peek(TIM3.reg(tim::SR)) & tim::SR_TIF != 0;
        let row = format!(
            "| {k} | {} | {} | {} | {} | {} |",
            chip.peek(s4.ndtr()),
            chip.peek(s1.ndtr()),
            u8::from(tif),
            ccrs(&mut chip, TIM3),
            ccrs(&mut chip, TIM5)
        );
        rows.push(row);
    }
    let expected_static = [
        format!("S4CR = {:#010x}", chip.peek(s4.cr())),
        format!("S1CR = {:#010x}", chip.peek(s1.cr())),
        format!("TIM3 DCR = {:#06x}", chip.peek(TIM3.reg(tim::DCR))),
        format!("TIM3 SMCR = {:#06x}", chip.peek(TIM3.reg(tim::SMCR))),
        format!("TIM5 SMCR = {:#06x}", chip.peek(TIM5.reg(tim::SMCR))),
    ];
    let table_text = rows.join("\n");
    println!("{table_text}\n{}", expected_static.join("\n"));
    let readme = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../firmware/README.md"
    ))
    .unwrap();
    for line in rows.iter().chain(&expected_static) {
        assert!(
            readme.contains(line.as_str()),
            "firmware/README.md lacks `{line}`"
        );
    }
}

/// The chip clock the plan sets up, measured on the model as the spacing of TIM2's update
/// events, is the requested rate rounded to a whole number of timer-clock ticks; the error the
/// engine reports ([`Loaded::error_ppb`]) is that rounding, at most half a tick per chip.
#[test]
fn chip_period_is_the_requested_rate_to_the_timers_resolution() {
    let rates = [
        1_000, 29_970, 30_000, 240_000, 959_500, 960_000, 1_000_000, 4_000_000,
    ];
    println!("requested Hz | ticks per chip | achieved Hz | error ppm | bound ppm");
    for rate in rates {
        let mut chip = Chip::new();
        let mut engine = ChipEngine::new(&mut chip, CLOCK, FRAMES, Mode::Dma).unwrap();
        let table = ChipTable::new(4).unwrap();
        let loaded = engine
            .load(&mut chip, &table, &FULL.levels(), rate)
            .unwrap();
        engine.start(&mut chip).unwrap();
        // Independent of the timer arithmetic: the nearest whole number of ticks.
        let exact = u64::from(CLOCK) * 1000;
        let ticks = (exact + u64::from(rate) / 2) / u64::from(rate);
        let from = chip.now;
        chip.run_until(from + 5 * ticks + 10);
        let boundaries = super::check::chip_boundaries(&chip.log, from);
        assert!(boundaries.len() >= 5, "{rate} mHz: {boundaries:?}");
        for pair in boundaries.windows(2) {
            assert_eq!(pair[1] - pair[0], ticks, "{rate} mHz: chip length in ticks");
        }
        let error_ppb = (exact as f64 / (ticks as f64 * f64::from(rate)) - 1.0) * 1e9;
        let bound_ppb = 0.5e9 / ticks as f64;
        println!(
            "{:>12} | {ticks:>14} | {:>11.5} | {:>9.3} | {:>9.3}",
            f64::from(rate) / 1000.0,
            f64::from(CLOCK) / ticks as f64,
            error_ppb / 1000.0,
            bound_ppb / 1000.0
        );
        assert!(
            (loaded.error_ppb as f64 - error_ppb).abs() <= 1.0,
            "{rate} mHz: reported {} ppb, measured {error_ppb:.1} ppb",
            loaded.error_ppb
        );
        assert!(
            error_ppb.abs() <= bound_ppb + 1.0,
            "{rate} mHz: {error_ppb} ppb"
        );
        assert_eq!(
            loaded.rate_microhertz,
            (exact * 1000 + ticks / 2) / ticks,
            "{rate} mHz: reported rate"
        );
        assert!(chip.violations.is_empty(), "{:?}", chip.violations);
    }
}

/// One-pulse mode as RM0383 describes it: the counter stops at its first update event.
#[test]
fn one_pulse_mode_stops_the_counter_at_the_update_event() {
    use crate::regs::{TIM2, tim};
    let mut chip = Chip::new();
    run(clock_plan().steps(), &mut chip).unwrap();
    for (opm, expected) in [(0, 4), (tim::CR1_OPM, 1)] {
        chip.write(TIM2.reg(tim::CR1), 0);
        chip.write(TIM2.reg(tim::ARR), 999);
        chip.write(TIM2.reg(tim::CR2), tim::CR2_MMS_UPDATE);
        let from = chip.now;
        chip.write(TIM2.reg(tim::CR1), tim::CR1_CEN | opm);
        chip.run_until(from + 4_500);
        let updates = super::check::chip_boundaries(&chip.log, from + 1).len();
        assert_eq!(updates, expected, "CR1.OPM = {}", opm != 0);
    }
    assert_eq!(
        chip.peek(TIM2.reg(tim::CR1)) & tim::CR1_CEN,
        0,
        "OPM cleared CEN"
    );
}

/// Every control bit the model does not implement is refused, not ignored.
#[test]
fn unmodelled_control_bits_are_violations() {
    use crate::regs::{TIM3, tim};
    let cases: [(u32, u32); 12] = [
        (tim::CR1, tim::CR1_CKD_MASK),
        (tim::CR1, 1 << 4),
        (tim::CR2, 0b001 << tim::CR2_MMS_SHIFT),
        (tim::CR2, 1 << 3),
        (tim::CR2, 1 << 7),
        (tim::SMCR, 1 << 7),
        (tim::SMCR, 1 << 14),
        (tim::SMCR, tim::SMCR_SMS_RESET | 5 << tim::SMCR_TS_SHIFT),
        (tim::DIER, 1 << 1),
        (tim::DIER, 1 << 6),
        (tim::CCMR1, 1 << 2),
        (tim::CCER, 1 << 3),
    ];
    for (offset, value) in cases {
        let mut chip = Chip::new();
        run(clock_plan().steps(), &mut chip).unwrap();
        chip.write(TIM3.reg(offset), value);
        assert!(
            !chip.violations.is_empty(),
            "offset {offset:#x} value {value:#x} accepted"
        );
    }
    // A stream enabled with an interrupt enable or the peripheral as flow controller.
    for extra in [dma::CR_TEIE, 1 << 5, 1 << 15, 1 << 19] {
        let mut chip = Chip::new();
        run(clock_plan().steps(), &mut chip).unwrap();
        let stream = Bank::Tim3.stream();
        chip.write(stream.par(), crate::regs::TIM3.reg(tim::DMAR));
        chip.write(stream.m0ar(), FRAMES.tim3);
        chip.write(stream.ndtr(), 4);
        chip.write(stream.fcr(), 0);
        let config = crate::plan::stream_config(Bank::Tim3);
        chip.write(stream.cr(), config | extra | dma::CR_EN);
        assert!(!chip.violations.is_empty(), "SxCR bit {extra:#x} accepted");
    }
}

/// The firmware README's wiring table is the pin table the plan plays.
#[test]
fn firmware_readme_wiring_is_the_pin_table() {
    let readme = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../firmware/README.md"
    ))
    .unwrap();
    for (i, led) in crate::outputs::LED_OUTPUTS.iter().enumerate() {
        let timer = match led.bank {
            Bank::Tim3 => "TIM3",
            Bank::Tim5 => "TIM5",
        };
        let cell = format!("| {} | {} ({timer} CH{})", i + 1, led.pin, led.channel);
        assert!(readme.contains(&cell), "firmware/README.md lacks `{cell}`");
    }
}

/// A halt leaves TIM2's interrupt disabled in the NVIC, whichever mode played.
#[test]
fn halt_disables_the_chip_interrupt_in_the_nvic() {
    use crate::regs::nvic;
    for mode in [Mode::ChipInterrupt, Mode::Dma] {
        let mut chip = Chip::new();
        let mut engine = ChipEngine::new(&mut chip, CLOCK, FRAMES, mode).unwrap();
        let table = ChipTable::new(4).unwrap();
        engine
            .load(&mut chip, &table, &FULL.levels(), 960_000)
            .unwrap();
        engine.start(&mut chip).unwrap();
        let enabled = chip.peek(nvic::ISER0) & (1 << nvic::TIM2_IRQ) != 0;
        assert_eq!(
            enabled,
            mode == Mode::ChipInterrupt,
            "{mode:?} while playing"
        );
        chip.run_until(chip.now + 3 * chip_ticks(960_000));
        engine.stop(&mut chip).unwrap();
        assert_eq!(
            chip.peek(nvic::ISER0) & (1 << nvic::TIM2_IRQ),
            0,
            "{mode:?}"
        );
    }
}

/// A stream that stopped without a transfer error (EN cleared, TEIF clear) is a fault too.
#[test]
fn a_stream_that_stopped_by_itself_is_reported() {
    for bank in [Bank::Tim3, Bank::Tim5] {
        let (mut chip, mut engine, _) = playing(8, 3);
        assert_eq!(engine.poll_fault(&mut chip), None, "healthy");
        let stream = bank.stream();
        let cr = chip.peek(stream.cr());
        chip.write(stream.cr(), cr & !dma::CR_EN);
        chip.run_until(chip.now + 100);
        assert_eq!(chip.peek(stream.isr()) & stream.flags(dma::TEIF), 0);
        assert_eq!(
            engine.poll_fault(&mut chip),
            Some(OutputFault::DmaTransferError),
            "{bank:?}"
        );
        assert!(!engine.is_running());
    }
}

/// The engine's accessors say what it was given and what it plays.
#[test]
fn engine_reports_its_clock_load_and_running_state() {
    let mut chip = Chip::new();
    let mut engine = ChipEngine::new(&mut chip, CLOCK, FRAMES, Mode::Dma).unwrap();
    assert_eq!(engine.clock_hz(), CLOCK);
    assert_eq!(engine.loaded(), None);
    assert!(!engine.is_running());
    let table = ChipTable::new(5).unwrap();
    let loaded = engine
        .load(&mut chip, &table, &FULL.levels(), 960_000)
        .unwrap();
    assert_eq!(engine.loaded(), Some(loaded));
    assert_eq!(loaded.chips, 64);
    assert_eq!(loaded.bank_chips, [32, 64]);
    assert!(!engine.is_running());
    engine.start(&mut chip).unwrap();
    assert!(engine.is_running());
    engine.stop(&mut chip).unwrap();
    assert!(!engine.is_running());
}

/// Loading writes each bank's compare values at its own width and nothing outside its buffer,
/// whatever the memory held before.
#[test]
fn frames_are_written_at_their_width_inside_their_buffers() {
    let mut chip = Chip::new();
    let mut engine = ChipEngine::new(&mut chip, CLOCK, FRAMES, Mode::Dma).unwrap();
    let guard = |bank: Bank| FRAMES.of(bank) + bank.frame_buffer_bytes();
    for bank in [Bank::Tim3, Bank::Tim5] {
        for offset in (0..bank.frame_buffer_bytes() + 16).step_by(4) {
            chip.write(FRAMES.of(bank) + offset, 0xDEAD_BEEF);
        }
    }
    let table = ChipTable::new(8).unwrap();
    let brightness = brightness_sets()[1];
    let loaded = engine
        .load(&mut chip, &table, &brightness.levels(), 960_000)
        .unwrap();
    for bank in [Bank::Tim3, Bank::Tim5] {
        assert_eq!(
            chip.peek(guard(bank)),
            0xDEAD_BEEF,
            "{bank:?}: past the buffer"
        );
        for chip_index in 0..usize::from(loaded.chips_of(bank)) {
            let expected = super::check::expected_levels(&table, &brightness, bank, chip_index);
            for (slot, level) in expected.iter().enumerate() {
                let addr = FRAMES.value(bank, chip_index, slot);
                let word = chip.peek(addr & !3);
                let value = if bank.item_bytes() == 2 {
                    (word >> (8 * (addr & 3))) & 0xFFFF
                } else {
                    word
                };
                assert_eq!(
                    Some(value),
                    *level,
                    "{bank:?} chip {chip_index} slot {slot}"
                );
            }
        }
    }
}

/// For any requested timeout the watchdog setting reaches it at the fastest LSI with the
/// smallest divider that can and, for that divider, the smallest reload; past the longest
/// timeout the IWDG has, the longest.
#[test]
fn watchdog_setting_is_the_smallest_that_reaches_the_timeout() {
    use crate::plan::WatchdogSetting;
    let fastest = crate::regs::iwdg::LSI_HZ.2;
    let longest = WatchdogSetting {
        prescaler_code: 6,
        reload: 0xFFF,
    };
    // Every 7 ms, and at each divider's longest timeout (4096 reloads) and 1 ms past it.
    let edges = (0..=6u32).flat_map(|code| {
        let t = (4096u64 * (4 << code) * 1000 / u64::from(fastest)) as u32;
        [t, t + 1]
    });
    for t in (1..=longest.timeout_ms(fastest) as u32)
        .step_by(7)
        .chain(edges)
    {
        let s = watchdog_setting(t);
        if u64::from(t) > longest.timeout_ms(fastest) {
            assert_eq!(s, longest, "{t} ms");
            continue;
        }
        assert!(s.prescaler_code <= 6 && s.reload <= 0xFFF, "{t} ms: {s:?}");
        assert!(s.timeout_ms(fastest) >= u64::from(t), "{t} ms: {s:?}");
        if s.reload > 0 {
            let shorter = WatchdogSetting {
                reload: s.reload - 1,
                ..s
            };
            assert!(shorter.timeout_ms(fastest) < u64::from(t), "{t} ms: {s:?}");
        }
        if s.prescaler_code > 0 {
            let finer = WatchdogSetting {
                prescaler_code: s.prescaler_code - 1,
                reload: 0xFFF,
            };
            assert!(finer.timeout_ms(fastest) < u64::from(t), "{t} ms: {s:?}");
        }
    }
    assert_eq!(watchdog_setting(100_000), longest);
    assert_eq!(watchdog_setting(u32::MAX / 1000), longest);
}
