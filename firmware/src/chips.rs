//! The chip engine on the board: owns TIM2, TIM3, TIM5, their DMA streams, the LED pins and the
//! frame buffers, and carries out `chip_plan`'s register plans through [`Mmio`]. Every register
//! value and the order of the writes come from `chip_plan` (host-tested on a register model of
//! RM0383); nothing here computes one.
//!
//! Nothing on the carrier path touches flash or needs the CPU: each TIM2 update resets the PWM
//! timers and makes them pull the next chip's compare values from RAM by DMA, so the carriers
//! keep playing while a flash sector is erased and while USB is busy or gone. With the
//! `chip-interrupt-fallback` feature TIM2's update interrupt copies the values instead (for a
//! part whose timer DMA burst does not run from the trigger request; see `firmware/README.md`);
//! that path stalls with the CPU during a flash erase.

use core::cell::RefCell;

use chip_plan::outputs::{Bank, TIM3_MAX_CHIPS, channel_pin_is};
use chip_plan::plan::{
    ChipEngine, ChipError, ChipInterrupt, ChipInterruptSlot, FrameMemory, Loaded, Mode,
    WATCHDOG_FEED, WATCHDOG_MIN_TIMEOUT_MS, watchdog_plan, watchdog_setting,
};
use chip_plan::step::{Bus, run};
use embassy_stm32::Peri;
use embassy_stm32::gpio::OutputType;
use embassy_stm32::peripherals::{
    DMA1_CH1, DMA1_CH4, IWDG, PA0, PA1, PA2, PA3, PA6, PA7, PB0, PB1, TIM2, TIM3, TIM5,
};
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::{Ch1, Ch2, Ch3, Ch4};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::ThreadModeRawMutex;
use protocol::carriers::{ChipTable, MAX_CHIPS};
use protocol::timing::LedLevels;
use protocol::wire::OutputFault;
use static_cell::ConstStaticCell;

/// How the compare values reach the timers in this build.
const MODE: Mode = if cfg!(feature = "chip-interrupt-fallback") {
    Mode::ChipInterrupt
} else {
    Mode::Dma
};

static TIM3_FRAMES: ConstStaticCell<[u16; TIM3_MAX_CHIPS * 4]> =
    ConstStaticCell::new([0; TIM3_MAX_CHIPS * 4]);
static TIM5_FRAMES: ConstStaticCell<[u32; MAX_CHIPS * 4]> =
    ConstStaticCell::new([0; MAX_CHIPS * 4]);
const _: () = assert!(
    Bank::Tim3.frame_buffer_bytes() as usize == TIM3_MAX_CHIPS * 4 * 2
        && Bank::Tim5.frame_buffer_bytes() as usize == MAX_CHIPS * 4 * 4,
    "frame buffers and the plan's frame layout disagree"
);

/// The memory-mapped registers and SRAM, as the plan's bus.
///
/// The plan only names addresses from `chip_plan::regs` (RM0383's register map, cross-checked
/// against stm32-metapac) and the two frame buffers this module owns, so every access is to a
/// peripheral register or to memory nothing else uses.
pub struct Mmio;

impl Bus for Mmio {
    fn read(&mut self, addr: u32) -> u32 {
        // SAFETY: an aligned peripheral register or frame-buffer word (see `Mmio`).
        unsafe { core::ptr::read_volatile(addr as *const u32) }
    }

    fn write(&mut self, addr: u32, value: u32) {
        // SAFETY: as in `read`.
        unsafe { core::ptr::write_volatile(addr as *mut u32, value) }
    }

    fn read16(&mut self, addr: u32) -> u16 {
        // SAFETY: an aligned half-word of TIM3's frame buffer.
        unsafe { core::ptr::read_volatile(addr as *const u16) }
    }

    fn write16(&mut self, addr: u32, value: u16) {
        // SAFETY: as in `read16`.
        unsafe { core::ptr::write_volatile(addr as *mut u16, value) }
    }

    fn fence(&mut self) {
        // A real barrier (DMB), not just a compiler fence: the DMA reads the buffers.
        core::sync::atomic::fence(core::sync::atomic::Ordering::SeqCst);
    }
}

/// The chip interrupt's state while the fallback plays.
static CHIP_INTERRUPT: embassy_sync::blocking_mutex::CriticalSectionMutex<
    core::cell::Cell<Option<ChipInterrupt>>,
> = embassy_sync::blocking_mutex::CriticalSectionMutex::new(core::cell::Cell::new(None));

impl ChipInterruptSlot for Mmio {
    fn set_chip_interrupt(&mut self, interrupt: Option<ChipInterrupt>) {
        CHIP_INTERRUPT.lock(|cell| cell.set(interrupt));
    }
}

#[cfg(feature = "chip-interrupt-fallback")]
mod chip_interrupt {
    use chip_plan::plan::CHIP_INTERRUPT_ACK;
    use chip_plan::step::run;
    use embassy_stm32::pac::interrupt;

    use super::{CHIP_INTERRUPT, Mmio};

    /// TIM2 update: the next chip's compare values into TIM3/TIM5.
    #[interrupt]
    fn TIM2() {
        let plan = CHIP_INTERRUPT.lock(|cell| {
            cell.get().map(|mut state| {
                let plan = state.next_plan();
                cell.set(Some(state));
                plan
            })
        });
        let _ = match plan {
            Some(plan) => run(plan.steps(), &mut Mmio),
            None => run(&[CHIP_INTERRUPT_ACK], &mut Mmio),
        };
    }
}

// `install` hands TIM3's channels 1–4 PA6, PA7, PB0, PB1 and TIM5's PA0, PA1, PA2, PA3 (embassy's
// pin types enforce that each pin has that channel); the plan's pin table must say the same.
const _: () = assert!(
    channel_pin_is(Bank::Tim3, 1, "PA6")
        && channel_pin_is(Bank::Tim3, 2, "PA7")
        && channel_pin_is(Bank::Tim3, 3, "PB0")
        && channel_pin_is(Bank::Tim3, 4, "PB1")
        && channel_pin_is(Bank::Tim5, 1, "PA0")
        && channel_pin_is(Bank::Tim5, 2, "PA1")
        && channel_pin_is(Bank::Tim5, 3, "PA2")
        && channel_pin_is(Bank::Tim5, 4, "PA3"),
    "the pins install() hands the timers differ from chip_plan::outputs::LED_OUTPUTS"
);

/// The LED pins, in the order of `chip_plan::outputs::LED_OUTPUTS`.
pub struct LedPins {
    /// LED 1, TIM3 CH1.
    pub pa6: Peri<'static, PA6>,
    /// LED 2, TIM3 CH2.
    pub pa7: Peri<'static, PA7>,
    /// LED 3, TIM3 CH3.
    pub pb0: Peri<'static, PB0>,
    /// LED 4, TIM3 CH4.
    pub pb1: Peri<'static, PB1>,
    /// LED 5, TIM5 CH2.
    pub pa1: Peri<'static, PA1>,
    /// LED 6, TIM5 CH3.
    pub pa2: Peri<'static, PA2>,
    /// LED 7, TIM5 CH4.
    pub pa3: Peri<'static, PA3>,
    /// LED 8, TIM5 CH1.
    pub pa0: Peri<'static, PA0>,
}

/// The peripherals the engine drives, taken so that nothing else can.
pub struct ChipHardware {
    /// Chip clock.
    pub tim2: Peri<'static, TIM2>,
    /// PWM bank of LEDs 1–4.
    pub tim3: Peri<'static, TIM3>,
    /// PWM bank of LEDs 5–8.
    pub tim5: Peri<'static, TIM5>,
    /// TIM3's trigger stream (DMA1 stream 4).
    pub tim3_stream: Peri<'static, DMA1_CH4>,
    /// TIM5's trigger stream (DMA1 stream 1).
    pub tim5_stream: Peri<'static, DMA1_CH1>,
    /// The LED pins.
    pub pins: LedPins,
}

/// The four channel pins of one PWM timer, in alternate-function mode while they live.
type BankPins<T> = (
    PwmPin<'static, T, Ch1>,
    PwmPin<'static, T, Ch2>,
    PwmPin<'static, T, Ch3>,
    PwmPin<'static, T, Ch4>,
);

/// The timers and DMA streams, held so that nothing else can take them.
type OwnedPeripherals = (
    Peri<'static, TIM2>,
    Peri<'static, TIM3>,
    Peri<'static, TIM5>,
    Peri<'static, DMA1_CH4>,
    Peri<'static, DMA1_CH1>,
);

/// The engine with its hardware.
pub struct Carriers {
    engine: ChipEngine,
    _hardware: OwnedPeripherals,
    _pins: (BankPins<TIM3>, BankPins<TIM5>),
}

/// The engine, shared by the link (effects) and the fault watch (both thread mode).
static CARRIERS: Mutex<ThreadModeRawMutex, RefCell<Option<Carriers>>> =
    Mutex::new(RefCell::new(None));

/// Takes the hardware, enables the clocks and halts: every output 0, nothing plays.
/// `clock_hz` is the timer clock of TIM2/TIM3/TIM5.
pub fn install(hardware: ChipHardware, clock_hz: u32) -> Result<(), ChipError> {
    let push_pull = OutputType::PushPull;
    let p = hardware.pins;
    let pins = (
        (
            PwmPin::new(p.pa6, push_pull),
            PwmPin::new(p.pa7, push_pull),
            PwmPin::new(p.pb0, push_pull),
            PwmPin::new(p.pb1, push_pull),
        ),
        (
            PwmPin::new(p.pa0, push_pull),
            PwmPin::new(p.pa1, push_pull),
            PwmPin::new(p.pa2, push_pull),
            PwmPin::new(p.pa3, push_pull),
        ),
    );
    // Taken once (a second `install` panics), then only reached through their addresses: the
    // CPU writes them through `Mmio`, the DMA reads them.
    let frames = FrameMemory {
        tim3: TIM3_FRAMES.take().as_mut_ptr() as u32,
        tim5: TIM5_FRAMES.take().as_mut_ptr() as u32,
    };
    let engine = ChipEngine::new(&mut Mmio, clock_hz, frames, MODE)?;
    let carriers = Carriers {
        engine,
        _hardware: (
            hardware.tim2,
            hardware.tim3,
            hardware.tim5,
            hardware.tim3_stream,
            hardware.tim5_stream,
        ),
        _pins: pins,
    };
    CARRIERS.lock(|cell| *cell.borrow_mut() = Some(carriers));
    Ok(())
}

/// Runs `f` on the engine (`None` before [`install`]).
fn with_engine<R>(f: impl FnOnce(&mut ChipEngine) -> R) -> Option<R> {
    CARRIERS.lock(|cell| cell.borrow_mut().as_mut().map(|c| f(&mut c.engine)))
}

/// Loads a chip table, per-LED on and off levels and chip rate; keeps playing if it was.
pub fn load(
    table: &ChipTable,
    levels: &LedLevels,
    rate_millihertz: u32,
) -> Option<Result<Loaded, ChipError>> {
    with_engine(|e| e.load(&mut Mmio, table, levels, rate_millihertz))
}

/// Starts playing.
pub fn start() -> Option<Result<(), ChipError>> {
    with_engine(|e| e.start(&mut Mmio))
}

/// Stops playing (all outputs 0).
pub fn stop() -> Option<Result<(), ChipError>> {
    with_engine(|e| e.stop(&mut Mmio))
}

/// Whether the carriers are playing.
pub fn is_running() -> bool {
    with_engine(|e| e.is_running()).unwrap_or(false)
}

/// Checks the DMA streams; a fault has already stopped the carriers when it is returned.
pub fn poll_fault() -> Option<OutputFault> {
    with_engine(|e| e.poll_fault(&mut Mmio)).flatten()
}

/// The independent watchdog, started once; [`Watchdog::feed`] keeps the board from resetting.
pub struct Watchdog {
    _iwdg: Peri<'static, IWDG>,
}

impl Watchdog {
    /// Starts the IWDG with a timeout above the longest flash erase at any LSI frequency.
    pub fn start(iwdg: Peri<'static, IWDG>) -> Self {
        let setting = watchdog_setting(WATCHDOG_MIN_TIMEOUT_MS);
        // The watchdog plan has no waits: it cannot fail.
        let _ = run(watchdog_plan(setting).steps(), &mut Mmio);
        Self { _iwdg: iwdg }
    }

    /// Reloads the watchdog counter.
    pub fn feed(&mut self) {
        let _ = run(&[WATCHDOG_FEED], &mut Mmio);
    }
}
