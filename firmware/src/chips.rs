//! The chip engine: plays a [`ChipTable`] on the PWM outputs at an exact chip rate, without the
//! CPU (issue 6, SPEC §2 "the firmware plays the on-mask table cyclically at the chip rate").
//!
//! ```text
//!  TIM2 (32-bit, 96 MHz)      update every (PSC+1)(ARR+1) ticks = one chip   [timing::chip_timer_period]
//!    └─ TRGO = update ──┬──► TIM3 slave "reset" on ITR1 ─ trigger DMA ─► DMA1 S4 ch5 ─► TIM3_DMAR
//!                       └──► TIM5 slave "reset" on ITR0 ─ trigger DMA ─► DMA1 S1 ch6 ─► TIM5_DMAR
//!  TIM3/TIM5: PWM mode 1, 1000 steps at 96 kHz, CCR preload; DCR burst of 4 → CCR1..CCR4
//! ```
//!
//! At every chip boundary TIM2's update event resets both PWM timers (their 96 kHz periods start
//! in phase with the chip) and makes each request a 4-word DMA burst through its DMAR, which
//! writes the next chip's four compare values (from a RAM frame buffer, circular) into the
//! preload registers. They take effect at the next PWM period, so every edge of every chip is
//! late by exactly one PWM period (10.4 µs): a constant offset, no jitter and no drift, and
//! irrelevant to the phase-invariant carriers. Nothing on the path touches flash or needs an
//! interrupt, so the carriers keep running while a flash sector is erased (the CPU stalls, the
//! DMA and timers do not) and while USB is busy or gone.
//!
//! Frame buffers: TIM5 (LEDs 5–8) holds the whole frame, up to 512 chips; TIM3 (LEDs 1–4) only
//! the first 32 chips, because those carriers repeat every ≤ 32 chips whatever N and the phases;
//! both streams are paced by the same trigger, so they stay in step.
//!
//! TIM5's registers are 32 bits wide, so its frames are `u32` (a 16-bit APB write would be
//! replicated into the upper half of the compare register); TIM3's are `u16`.
//!
//! Not verified on a board: that the F411's timer DMA burst runs from the *trigger* request
//! (RM0383 describes the burst for any timer DMA request). If it does not, `Hardware test` in
//! `firmware/README.md` says how to see it; the fallback is a TIM2 update interrupt writing the
//! same frames.

use embassy_stm32::Peri;
use embassy_stm32::gpio::OutputType;
use embassy_stm32::pac;
use embassy_stm32::pac::dma::vals::{Dir, Pl, Size};
use embassy_stm32::peripherals::{
    DMA1_CH1, DMA1_CH4, PA0, PA1, PA2, PA3, PA6, PA7, PB0, PB1, TIM2, TIM3, TIM5,
};
use embassy_stm32::timer::low_level::{
    MasterMode, OutputCompareMode, SlaveMode, Timer, TriggerSource,
};
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::{Ch1, Ch2, Ch3, Ch4, Channel, GeneralInstance4Channel};
use protocol::carriers::{ChipTable, MAX_CHIPS, MAX_LEDS};
use protocol::timing::{
    PWM_STEPS, TimerPeriod, TimingError, brightness_pwm_period, chip_timer_period,
    fill_compare_frames,
};
use static_cell::ConstStaticCell;

use crate::board::{Bank, slots_of};

/// Compare values per chip and bank (CCR1..CCR4).
const SLOTS: usize = 4;
/// DMA stream and request channel of TIM3_TRIG (RM0383 table 27).
const TIM3_STREAM: (usize, u8) = (4, 5);
/// DMA stream and request channel of TIM5_TRIG.
const TIM5_STREAM: (usize, u8) = (1, 6);
/// Polls of NDTR to wait for a burst in flight (a burst is 4 APB writes, ~100 CPU cycles).
const BURST_SPIN_LIMIT: u32 = 10_000;
/// DCR base address of the burst: CCR1 is register 13 (offset 0x34) of a general-purpose timer.
const DCR_BASE_CCR1: u8 = 13;

/// LEDs 1–4 repeat within 32 chips whatever N and the phases (`protocol::timing::slot_pattern_period`), so
/// TIM3 needs 32 frames; TIM5 (LEDs 5–8) needs the full 512.
const TIM3_MAX_CHIPS: usize = 32;

static TIM3_FRAMES: ConstStaticCell<[u16; TIM3_MAX_CHIPS * SLOTS]> =
    ConstStaticCell::new([0; TIM3_MAX_CHIPS * SLOTS]);
static TIM5_FRAMES: ConstStaticCell<[u32; MAX_CHIPS * SLOTS]> =
    ConstStaticCell::new([0; MAX_CHIPS * SLOTS]);

/// The LED pins, in board-table order (see [`crate::board::LED_OUTPUTS`]).
pub struct LedPins<'d> {
    /// LED 1, TIM3 CH1.
    pub pa6: Peri<'d, PA6>,
    /// LED 2, TIM3 CH2.
    pub pa7: Peri<'d, PA7>,
    /// LED 3, TIM3 CH3.
    pub pb0: Peri<'d, PB0>,
    /// LED 4, TIM3 CH4.
    pub pb1: Peri<'d, PB1>,
    /// LED 5, TIM5 CH2.
    pub pa1: Peri<'d, PA1>,
    /// LED 6, TIM5 CH3.
    pub pa2: Peri<'d, PA2>,
    /// LED 7, TIM5 CH4.
    pub pa3: Peri<'d, PA3>,
    /// LED 8, TIM5 CH1.
    pub pa0: Peri<'d, PA0>,
}

/// The four channel pins of one PWM timer.
type BankPins<'d, T> = (
    PwmPin<'d, T, Ch1>,
    PwmPin<'d, T, Ch2>,
    PwmPin<'d, T, Ch3>,
    PwmPin<'d, T, Ch4>,
);

/// The pins in alternate-function mode; kept alive so they stay timer outputs.
#[allow(dead_code)]
struct PwmPins<'d> {
    tim3: BankPins<'d, TIM3>,
    tim5: BankPins<'d, TIM5>,
}

/// Why an output plan could not be loaded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum ChipError {
    /// No timer setting for the requested rate.
    Timing(TimingError),
}

/// What the engine is playing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub struct Loaded {
    /// Chips per frame.
    pub chips: usize,
    /// Chip timer registers.
    pub period: TimerPeriod,
    /// Achieved chip rate in microhertz.
    pub rate_microhertz: u64,
    /// Error against the requested rate in parts per billion.
    pub error_ppb: i64,
}

/// Owner of the chip timer, both PWM banks, their DMA streams and frame buffers.
pub struct ChipEngine<'d> {
    chip_clock: Timer<'d, TIM2>,
    tim3: Timer<'d, TIM3>,
    tim5: Timer<'d, TIM5>,
    _pins: PwmPins<'d>,
    _dma: (Peri<'d, DMA1_CH4>, Peri<'d, DMA1_CH1>),
    tim3_frames: &'static mut [u16; TIM3_MAX_CHIPS * SLOTS],
    tim5_frames: &'static mut [u32; MAX_CHIPS * SLOTS],
    loaded: Option<Loaded>,
    /// DMA transfers of one cycle of each bank's frames (TIM3, TIM5).
    transfers: (u16, u16),
    running: bool,
}

impl<'d> ChipEngine<'d> {
    /// Takes the timers, DMA streams and pins; all outputs start off, nothing plays.
    ///
    /// Panics if called twice (the frame buffers are singletons).
    pub fn new(
        tim2: Peri<'d, TIM2>,
        tim3: Peri<'d, TIM3>,
        tim5: Peri<'d, TIM5>,
        dma: (Peri<'d, DMA1_CH4>, Peri<'d, DMA1_CH1>),
        pins: LedPins<'d>,
    ) -> Self {
        let push_pull = OutputType::PushPull;
        let pins = PwmPins {
            tim3: (
                PwmPin::new(pins.pa6, push_pull),
                PwmPin::new(pins.pa7, push_pull),
                PwmPin::new(pins.pb0, push_pull),
                PwmPin::new(pins.pb1, push_pull),
            ),
            tim5: (
                PwmPin::new(pins.pa0, push_pull),
                PwmPin::new(pins.pa1, push_pull),
                PwmPin::new(pins.pa2, push_pull),
                PwmPin::new(pins.pa3, push_pull),
            ),
        };
        // DMA1 carries the frames; embassy enables its clock only for its own transfers.
        pac::RCC.ahb1enr().modify(|w| w.set_dma1en(true));
        let engine = Self {
            chip_clock: Timer::new(tim2),
            tim3: Timer::new(tim3),
            tim5: Timer::new(tim5),
            _pins: pins,
            _dma: dma,
            tim3_frames: TIM3_FRAMES.take(),
            tim5_frames: TIM5_FRAMES.take(),
            loaded: None,
            transfers: (0, 0),
            running: false,
        };
        // TIM3 is triggered by ITR1 = TIM2, TIM5 by ITR0 = TIM2 (RM0383 table 54).
        setup_pwm_bank(&engine.tim3, TriggerSource::ITR1);
        setup_pwm_bank(&engine.tim5, TriggerSource::ITR0);
        engine
    }

    /// Timer clock of the chip timer (TIM2), from the RCC state.
    pub fn chip_clock_hz(&self) -> u32 {
        self.chip_clock.get_clock_frequency().0
    }

    /// Whether the carriers are playing.
    pub fn is_running(&self) -> bool {
        self.running
    }

    /// Loads a chip table, per-LED brightness and chip rate; keeps playing if it was.
    pub fn load(
        &mut self,
        table: &ChipTable,
        brightness_permille: &[u16; MAX_LEDS],
        rate_millihertz: u32,
    ) -> Result<Loaded, ChipError> {
        let clock = self.chip_clock_hz();
        let period = chip_timer_period(clock, rate_millihertz, 32).map_err(ChipError::Timing)?;
        let was_running = self.running;
        self.halt();
        let tim3_slots = slots_of(Bank::Tim3);
        let tim5_slots = slots_of(Bank::Tim5);
        fill_compare_frames(
            table,
            brightness_permille,
            &tim3_slots,
            &mut self.tim3_frames[..],
        )
        .map_err(ChipError::Timing)?;
        fill_compare_frames(
            table,
            brightness_permille,
            &tim5_slots,
            &mut self.tim5_frames[..],
        )
        .map_err(ChipError::Timing)?;
        let regs = self.chip_clock.regs_gp32();
        regs.psc().write_value(period.prescaler);
        regs.arr().write_value(period.auto_reload);
        let loaded = Loaded {
            chips: table.chips(),
            period,
            rate_microhertz: period.rate_microhertz(clock),
            error_ppb: period.error_ppb(clock, rate_millihertz),
        };
        self.loaded = Some(loaded);
        if was_running {
            self.start();
        }
        Ok(loaded)
    }

    /// Starts playing the loaded table from chip 0 (no-op if nothing is loaded or running).
    pub fn start(&mut self) {
        let Some(loaded) = self.loaded else {
            return;
        };
        if self.running {
            return;
        }
        if loaded.chips == 0 {
            return;
        }
        let tim3 = self.tim3.regs_gp16();
        let tim5 = self.tim5.regs_gp16();
        start_stream(
            TIM3_STREAM,
            tim3.dmar().as_ptr() as u32,
            self.tim3_frames.as_ptr() as u32,
            self.transfers.0,
            Size::BITS16,
        );
        start_stream(
            TIM5_STREAM,
            tim5.dmar().as_ptr() as u32,
            self.tim5_frames.as_ptr() as u32,
            self.transfers.1,
            Size::BITS32,
        );
        for regs in [tim3, tim5] {
            set_burst(regs);
            regs.sr().write(|w| w.0 = 0);
            regs.dier().modify(|w| w.set_tde(true));
        }
        // Chip timer: load PSC/ARR with a silent update, then every update drives TRGO.
        self.chip_clock.stop();
        self.chip_clock.regs_core().cnt().write(|w| w.set_cnt(0));
        self.chip_clock.generate_update_event();
        self.chip_clock.set_master_mode(MasterMode::UPDATE);
        self.chip_clock.start();
        self.running = true;
    }

    /// Stops playing; every output goes to 0 (LEDs off) within one PWM period.
    pub fn stop(&mut self) {
        self.halt();
    }

    fn halt(&mut self) {
        // No new chip triggers; then let a burst in flight finish (4 transfers, well under a
        // microsecond) so the timer's DMAR index is back at CCR1 for the next start.
        self.chip_clock.stop();
        for (regs, stream) in [
            (self.tim3.regs_gp16(), TIM3_STREAM),
            (self.tim5.regs_gp16(), TIM5_STREAM),
        ] {
            let st = pac::DMA1.st(stream.0);
            let mut spins = 0u32;
            while st.cr().read().en()
                && !usize::from(st.ndtr().read().ndt()).is_multiple_of(SLOTS)
                && spins < BURST_SPIN_LIMIT
            {
                spins += 1;
            }
            regs.dier().modify(|w| w.set_tde(false));
            stop_stream(stream.0);
        }
        for channel in [Channel::Ch1, Channel::Ch2, Channel::Ch3, Channel::Ch4] {
            self.tim3.set_compare_value(channel, 0);
            self.tim5.set_compare_value(channel, 0);
        }
        self.running = false;
    }
}

/// PWM mode 1 with CCR preload on all four channels, 1000 steps at prescaler 0, slave reset on
/// `trigger`, DMA burst of CCR1..CCR4 through DMAR on each trigger request; counter running.
fn setup_pwm_bank<T: GeneralInstance4Channel>(timer: &Timer<'_, T>, trigger: TriggerSource) {
    let pwm = match brightness_pwm_period(timer.get_clock_frequency().0) {
        Ok(period) => period,
        Err(_) => TimerPeriod {
            prescaler: 0,
            auto_reload: u32::from(PWM_STEPS) - 1,
        },
    };
    let regs = timer.regs_gp16();
    timer.stop();
    regs.psc().write_value(pwm.prescaler);
    timer.set_autoreload_preload(true);
    regs.arr().write(|w| w.set_arr(pwm.auto_reload as u16));
    for channel in [Channel::Ch1, Channel::Ch2, Channel::Ch3, Channel::Ch4] {
        timer.set_output_compare_mode(channel, OutputCompareMode::PwmMode1);
        timer.set_output_compare_preload(channel, true);
        timer.enable_channel(channel, true);
    }
    set_burst(regs);
    timer.set_trigger_source(trigger);
    timer.set_slave_mode(SlaveMode::RESET_MODE);
    timer.generate_update_event();
    timer.start();
}

/// DMA burst through DMAR: CCR1..CCR4, one burst per DMA request of the timer.
fn set_burst(regs: pac::timer::TimGp16) {
    regs.dcr().write(|w| {
        w.set_dba(DCR_BASE_CCR1);
        w.set_dbl(SLOTS as u8 - 1);
    });
}

/// Programs and enables a DMA1 stream: circular, memory → peripheral, memory increment, one
/// item per request (direct mode), highest priority, no interrupts.
fn start_stream(
    (stream, request): (usize, u8),
    peripheral: u32,
    memory: u32,
    items: u16,
    size: Size,
) {
    stop_stream(stream);
    let st = pac::DMA1.st(stream);
    st.par().write_value(peripheral);
    st.m0ar().write_value(memory);
    st.ndtr().write(|w| w.set_ndt(items));
    st.fcr()
        .write(|w| w.set_dmdis(pac::dma::vals::Dmdis::ENABLED));
    st.cr().write(|w| {
        w.set_chsel(request);
        w.set_dir(Dir::MEMORY_TO_PERIPHERAL);
        w.set_circ(true);
        w.set_minc(true);
        w.set_pinc(false);
        w.set_psize(size);
        w.set_msize(size);
        w.set_pl(Pl::VERY_HIGH);
    });
    // The frame buffer must be written before the DMA may read it.
    core::sync::atomic::compiler_fence(core::sync::atomic::Ordering::SeqCst);
    st.cr().modify(|w| w.set_en(true));
}

/// Disables a DMA1 stream, waits until it has stopped and clears its flags.
fn stop_stream(stream: usize) {
    let st = pac::DMA1.st(stream);
    st.cr().modify(|w| w.set_en(false));
    while st.cr().read().en() {}
    pac::DMA1.ifcr(stream / 4).write(|w| {
        let n = stream % 4;
        w.set_tcif(n, true);
        w.set_htif(n, true);
        w.set_teif(n, true);
        w.set_dmeif(n, true);
        w.set_feif(n, true);
    });
    core::sync::atomic::compiler_fence(core::sync::atomic::Ordering::SeqCst);
}
