//! The chip engine's register plans and the sequencing around them
//! (docs/maths/carriers.md#playing-the-table-on-a-luminaire: the luminaire plays
//! the on-mask table cyclically at the chip rate).
//!
//! ```text
//!  TIM2 (32-bit)   update every (PSC+1)(ARR+1) ticks = one chip       [timing::chip_timer_period]
//!    └─ TRGO = update ──┬──► TIM3 slave reset on ITR1 ─ trigger DMA ─► DMA1 S4 ch5 ─► TIM3_DMAR
//!                       └──► TIM5 slave reset on ITR0 ─ trigger DMA ─► DMA1 S1 ch6 ─► TIM5_DMAR
//!  TIM3/TIM5: PWM mode 1, 1000 steps at prescaler 0, CCR preload; DCR burst of 4 → CCR1..CCR4
//! ```
//!
//! Each chip boundary (TIM2 update) resets both PWM timers and raises their trigger DMA request;
//! the burst writes the chip's four compare values through DMAR into the preload registers, which
//! take effect at the next PWM period: every edge lags the chip clock by exactly one PWM period.
//!
//! The sequences, each a [`Plan`] of register writes:
//! * [`halt_plan`] (boot, stop, before a reload): TIM2 stopped, no DMA or interrupt requests,
//!   both streams disabled (bounded wait), then TIM2, TIM3 and TIM5 are put through their RCC
//!   reset and the PWM banks re-initialised with every compare value 0 (all LEDs off). The reset
//!   is what makes a halt race harmless: a chip trigger that lands while the plan stops the DMA
//!   may leave the timer's DMA burst index (RM0383 TIMx_DCR/DMAR) half-way through a burst, or
//!   leave a request pending, and no register can clear either except the peripheral reset.
//! * frames: the CPU writes the compare values of each bank's repeating prefix of the table
//!   ([`protocol::timing::slot_pattern_period`]) to the frame buffers, then a [`Step::Fence`].
//! * [`start_plan`]: stream registers, NDTR = the number of values written, enable, trigger
//!   DMA requests on, TIM2 period, update generation (chip 0 begins at once), counter on.
//!
//! [`Mode::ChipInterrupt`] is the fallback for a part whose timer DMA burst does not run from the
//! trigger request: TIM2's update interrupt copies the same frames into the compare registers
//! ([`ChipInterrupt`]). The register model runs both modes.

use protocol::carriers::ChipTable;
use protocol::timing::{
    LedLevels, PWM_STEPS, TimerPeriod, TimingError, chip_timer_period, slot_compare,
    slot_pattern_period,
};
use protocol::wire::OutputFault;

use crate::outputs::{BANKS, Bank, SLOTS, slots_of};
use crate::regs::{TIM2, dbgmcu, dma, iwdg, nvic, rcc, tim};
use crate::step::{Bus, Plan, Step, StepError, run};

/// Polls of a stream's EN bit before a halt gives up on it. A stream finishes the data item in
/// flight before EN reads 0 (well under a microsecond); 1000 polls are ~100 µs of CPU time.
pub const STREAM_STOP_POLLS: u32 = 1000;

/// How the compare values reach the PWM timers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Mode {
    /// Trigger DMA bursts, no CPU in the path (the design).
    Dma,
    /// TIM2 update interrupt copies the frames (the fallback).
    ChipInterrupt,
}

/// Bus addresses of the two frame buffers (TIM3: `u16` values, TIM5: `u32` values), each
/// `bank.frame_buffer_bytes()` long, in SRAM.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameMemory {
    /// Address of TIM3's frames.
    pub tim3: u32,
    /// Address of TIM5's frames.
    pub tim5: u32,
}

impl FrameMemory {
    /// Address of `bank`'s frames.
    pub const fn of(&self, bank: Bank) -> u32 {
        match bank {
            Bank::Tim3 => self.tim3,
            Bank::Tim5 => self.tim5,
        }
    }

    /// Address of the compare value of `slot` (0..4) in chip `chip` of `bank`'s frames.
    pub const fn value(&self, bank: Bank, chip: usize, slot: usize) -> u32 {
        self.of(bank) + ((chip * SLOTS + slot) as u32) * bank.item_bytes()
    }
}

/// What the engine is playing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Loaded {
    /// Chips per frame of the table.
    pub chips: usize,
    /// Chip timer (TIM2) registers.
    pub period: TimerPeriod,
    /// Achieved chip rate in microhertz.
    pub rate_microhertz: u64,
    /// Error against the requested rate in parts per billion.
    pub error_ppb: i64,
    /// Chips held in each bank's frame buffer (TIM3, TIM5): the repeating prefix of the table.
    pub bank_chips: [u16; 2],
}

impl Loaded {
    /// Chips held for `bank`.
    pub const fn chips_of(&self, bank: Bank) -> u16 {
        match bank {
            Bank::Tim3 => self.bank_chips[0],
            Bank::Tim5 => self.bank_chips[1],
        }
    }

    /// DMA items of one cycle through `bank`'s frames: four compare values per chip (NDTR).
    pub const fn items_of(&self, bank: Bank) -> u16 {
        self.chips_of(bank) * SLOTS as u16
    }
}

/// Why the engine could not do what was asked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ChipError {
    /// No chip timer setting for the requested rate.
    Timing(TimingError),
    /// A DMA stream did not stop; the timers were reset and the outputs are off, but the frames
    /// were not reloaded and nothing was started.
    StreamStuck(StepError),
}

impl ChipError {
    /// The fault `GetStatus` reports for this error, if it stopped the carriers.
    pub const fn fault(&self) -> Option<OutputFault> {
        match self {
            ChipError::Timing(_) => None,
            ChipError::StreamStuck(_) => Some(OutputFault::DmaStopTimeout),
        }
    }
}

/// Clock enables the engine needs (shared RCC registers: read-modify-write).
pub fn clock_plan() -> Plan {
    let mut plan = Plan::new();
    plan.push(Step::SetBits {
        addr: rcc::AHB1ENR,
        bits: rcc::DMA1EN,
    });
    plan.push(Step::SetBits {
        addr: rcc::APB1ENR,
        bits: rcc::TIM2 | rcc::TIM3 | rcc::TIM5,
    });
    plan
}

/// Stops everything and leaves both PWM banks initialised with all outputs at 0 (see the
/// module docs); also the boot state after [`clock_plan`].
pub fn halt_plan() -> Plan {
    let mut plan = Plan::new();
    // No new chip triggers and no chip interrupt.
    plan.write(TIM2.reg(tim::CR1), 0);
    plan.write(TIM2.reg(tim::DIER), 0);
    plan.write(nvic::ICER0, 1 << nvic::TIM2_IRQ);
    // No new DMA requests from the banks, then stop both streams.
    for bank in BANKS {
        plan.write(bank.timer().reg(tim::DIER), 0);
    }
    for bank in BANKS {
        plan.push(Step::ClearBits {
            addr: bank.stream().cr(),
            bits: dma::CR_EN,
        });
    }
    for bank in BANKS {
        plan.push(Step::WaitClear {
            addr: bank.stream().cr(),
            mask: dma::CR_EN,
            polls: STREAM_STOP_POLLS,
        });
    }
    // The DMA is done with the frame buffers before the CPU rewrites them.
    plan.push(Step::Fence);
    for bank in BANKS {
        let stream = bank.stream();
        plan.write(stream.ifcr(), stream.flags(dma::ALL_FLAGS));
    }
    // Reset state: counters, burst indices and pending requests of all three timers.
    let timers = rcc::TIM2 | rcc::TIM3 | rcc::TIM5;
    plan.push(Step::SetBits {
        addr: rcc::APB1RSTR,
        bits: timers,
    });
    plan.push(Step::ClearBits {
        addr: rcc::APB1RSTR,
        bits: timers,
    });
    for bank in BANKS {
        plan.extend(&pwm_bank_plan(bank));
    }
    plan
}

/// A PWM bank from its reset state: PWM mode 1 with preload on all four channels at compare 0,
/// [`PWM_STEPS`] steps at prescaler 0, slave reset on TIM2's TRGO, DMA burst CCR1..CCR4 through
/// DMAR, counter running.
fn pwm_bank_plan(bank: Bank) -> Plan {
    let timer = bank.timer();
    let mut plan = Plan::new();
    plan.write(timer.reg(tim::PSC), 0);
    plan.write(timer.reg(tim::ARR), u32::from(PWM_STEPS) - 1);
    plan.write(timer.reg(tim::CCMR1), tim::ccmr_pwm1_preload_pair());
    plan.write(timer.reg(tim::CCMR2), tim::ccmr_pwm1_preload_pair());
    for channel in 1..=SLOTS as u8 {
        plan.write(timer.ccr(channel), 0);
    }
    plan.write(timer.reg(tim::CCER), tim::ccer_all_enabled());
    plan.write(timer.reg(tim::CR1), tim::CR1_ARPE);
    // Loads PSC, ARR and the compare shadows, counter 0.
    plan.write(timer.reg(tim::EGR), tim::EGR_UG);
    plan.write(
        timer.reg(tim::SMCR),
        (bank.tim2_trigger() << tim::SMCR_TS_SHIFT) | tim::SMCR_SMS_RESET,
    );
    plan.write(timer.reg(tim::DCR), tim::dcr(tim::CCR1, SLOTS as u32));
    plan.write(timer.reg(tim::CR1), tim::CR1_ARPE | tim::CR1_CEN);
    plan
}

/// SxCR of `bank`'s stream without EN: its request channel, memory → peripheral, circular,
/// memory increment, data size = the bank's compare width, very high priority, direct mode.
pub fn stream_config(bank: Bank) -> u32 {
    let size = dma::size_code(bank.item_bytes());
    (bank.request_channel() << dma::CR_CHSEL_SHIFT)
        | dma::CR_PL_VERY_HIGH
        | (size << dma::CR_MSIZE_SHIFT)
        | (size << dma::CR_PSIZE_SHIFT)
        | dma::CR_MINC
        | dma::CR_CIRC
        | dma::CR_DIR_M2P
}

/// Starts playing `loaded` from chip 0 (after [`halt_plan`] and the frames).
pub fn start_plan(loaded: &Loaded, frames: &FrameMemory, mode: Mode) -> Plan {
    let mut plan = Plan::new();
    if mode == Mode::Dma {
        for bank in BANKS {
            let stream = bank.stream();
            plan.write(stream.cr(), stream_config(bank));
            plan.write(stream.par(), bank.timer().reg(tim::DMAR));
            plan.write(stream.m0ar(), frames.of(bank));
            plan.write(stream.ndtr(), u32::from(loaded.items_of(bank)));
            plan.write(stream.fcr(), 0);
            plan.write(stream.ifcr(), stream.flags(dma::ALL_FLAGS));
        }
    }
    // The frames the CPU wrote are in SRAM before a stream preloads its first item.
    plan.push(Step::Fence);
    match mode {
        Mode::Dma => {
            for bank in BANKS {
                plan.write(bank.stream().cr(), stream_config(bank) | dma::CR_EN);
            }
            for bank in BANKS {
                plan.write(bank.timer().reg(tim::SR), 0);
                plan.write(bank.timer().reg(tim::DIER), tim::DIER_TDE);
            }
        }
        Mode::ChipInterrupt => {
            plan.write(TIM2.reg(tim::SR), 0);
            plan.write(TIM2.reg(tim::DIER), tim::DIER_UIE);
            plan.write(nvic::ISER0, 1 << nvic::TIM2_IRQ);
        }
    }
    plan.write(TIM2.reg(tim::PSC), u32::from(loaded.period.prescaler));
    plan.write(TIM2.reg(tim::ARR), loaded.period.auto_reload);
    plan.write(TIM2.reg(tim::CR2), tim::CR2_MMS_UPDATE);
    // Chip 0 begins now: the update event is TRGO, which resets both banks and requests frame 0.
    plan.write(TIM2.reg(tim::EGR), tim::EGR_UG);
    plan.write(TIM2.reg(tim::CR1), tim::CR1_CEN);
    plan
}

/// The TIM2 update interrupt of [`Mode::ChipInterrupt`]: which chip comes next and where its
/// frames are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ChipInterrupt {
    next_chip: u32,
    bank_chips: [u16; 2],
    frames: FrameMemory,
}

impl ChipInterrupt {
    /// The interrupt state for playing `loaded` from chip 0.
    pub const fn new(loaded: &Loaded, frames: FrameMemory) -> Self {
        Self {
            next_chip: 0,
            bank_chips: loaded.bank_chips,
            frames,
        }
    }

    /// The steps of one interrupt (clear UIF, copy the chip's eight compare values), advancing
    /// to the next chip.
    pub fn next_plan(&mut self) -> Plan {
        let mut plan = Plan::new();
        plan.push(CHIP_INTERRUPT_ACK);
        for (i, bank) in BANKS.into_iter().enumerate() {
            let chips = u32::from(self.bank_chips[i].max(1));
            let chip = (self.next_chip % chips) as usize;
            for slot in 0..SLOTS {
                plan.push(Step::Copy {
                    src: self.frames.value(bank, chip, slot),
                    dst: bank.timer().ccr(slot as u8 + 1),
                    bytes: bank.item_bytes() as u8,
                });
            }
        }
        self.next_chip = self.next_chip.wrapping_add(1);
        plan
    }
}

/// Clears TIM2's update flag: the first step of every chip interrupt, and all a handler does
/// when no [`ChipInterrupt`] is installed.
pub const CHIP_INTERRUPT_ACK: Step = Step::Write {
    addr: TIM2.base + tim::SR,
    value: 0,
};

/// Where the chip interrupt's state lives while the carriers play in [`Mode::ChipInterrupt`]:
/// the board's interrupt handler, or the host model.
pub trait ChipInterruptSlot {
    /// Installs (`Some`) the state before the interrupt is enabled, removes it (`None`) after.
    fn set_chip_interrupt(&mut self, interrupt: Option<ChipInterrupt>);
}

/// Writes `bank`'s compare values for the repeating prefix of `table` to its frame buffer;
/// returns the number of chips written.
fn write_frames<B: Bus + ?Sized>(
    bus: &mut B,
    frames: &FrameMemory,
    bank: Bank,
    table: &ChipTable,
    levels: &LedLevels,
) -> u16 {
    let slots = slots_of(bank);
    // At most 32 chips for TIM3 and 512 for TIM5 whatever the table (see `outputs`).
    let chips = slot_pattern_period(table, &slots).min(bank.max_chips());
    for (chip, &mask) in table.masks()[..chips].iter().enumerate() {
        for (slot, &led) in slots.iter().enumerate() {
            let value = slot_compare(table, levels, led, mask);
            let addr = frames.value(bank, chip, slot);
            if bank.item_bytes() == 2 {
                bus.write16(addr, value);
            } else {
                bus.write(addr, u32::from(value));
            }
        }
    }
    chips as u16
}

/// The chip engine: which plan runs when. Owns no hardware; every access goes through the
/// [`Bus`] passed in, so the board and the register model run this same code.
#[derive(Debug, Clone)]
pub struct ChipEngine {
    clock_hz: u32,
    frames: FrameMemory,
    mode: Mode,
    loaded: Option<Loaded>,
    running: bool,
}

impl ChipEngine {
    /// Enables the clocks and halts (all outputs 0); nothing plays. `clock_hz` is the timer
    /// clock of TIM2/TIM3/TIM5.
    pub fn new<B: Bus + ChipInterruptSlot + ?Sized>(
        bus: &mut B,
        clock_hz: u32,
        frames: FrameMemory,
        mode: Mode,
    ) -> Result<Self, ChipError> {
        run(clock_plan().steps(), bus).map_err(ChipError::StreamStuck)?;
        let mut engine = Self {
            clock_hz,
            frames,
            mode,
            loaded: None,
            running: false,
        };
        engine.halt(bus)?;
        Ok(engine)
    }

    /// Timer clock the periods are computed for.
    pub fn clock_hz(&self) -> u32 {
        self.clock_hz
    }

    /// What is loaded, if anything.
    pub fn loaded(&self) -> Option<Loaded> {
        self.loaded
    }

    /// Whether the carriers are playing.
    pub fn is_running(&self) -> bool {
        self.running
    }

    /// Loads a chip table, per-LED on and off levels and chip rate; keeps playing (from chip 0)
    /// if it was. A rate with no timer setting changes nothing.
    pub fn load<B: Bus + ChipInterruptSlot + ?Sized>(
        &mut self,
        bus: &mut B,
        table: &ChipTable,
        levels: &LedLevels,
        rate_millihertz: u32,
    ) -> Result<Loaded, ChipError> {
        let period =
            chip_timer_period(self.clock_hz, rate_millihertz, 32).map_err(ChipError::Timing)?;
        let was_running = self.running;
        self.halt(bus)?;
        let mut bank_chips = [0u16; 2];
        for (chips, bank) in bank_chips.iter_mut().zip(BANKS) {
            *chips = write_frames(bus, &self.frames, bank, table, levels);
        }
        let loaded = Loaded {
            chips: table.chips(),
            period,
            rate_microhertz: period.rate_microhertz(self.clock_hz),
            error_ppb: period.error_ppb(self.clock_hz, rate_millihertz),
            bank_chips,
        };
        self.loaded = Some(loaded);
        if was_running {
            self.start(bus)?;
        }
        Ok(loaded)
    }

    /// Starts playing the loaded table from chip 0 (no-op if nothing is loaded or it plays).
    pub fn start<B: Bus + ChipInterruptSlot + ?Sized>(
        &mut self,
        bus: &mut B,
    ) -> Result<(), ChipError> {
        let Some(loaded) = self.loaded else {
            return Ok(());
        };
        if self.running {
            return Ok(());
        }
        if self.mode == Mode::ChipInterrupt {
            bus.set_chip_interrupt(Some(ChipInterrupt::new(&loaded, self.frames)));
        }
        let result = run(start_plan(&loaded, &self.frames, self.mode).steps(), bus);
        self.running = true;
        result.map_err(ChipError::StreamStuck)
    }

    /// Stops playing; every output is 0 (LED off) when this returns.
    pub fn stop<B: Bus + ChipInterruptSlot + ?Sized>(
        &mut self,
        bus: &mut B,
    ) -> Result<(), ChipError> {
        self.halt(bus)
    }

    fn halt<B: Bus + ChipInterruptSlot + ?Sized>(&mut self, bus: &mut B) -> Result<(), ChipError> {
        let result = run(halt_plan().steps(), bus);
        bus.set_chip_interrupt(None);
        self.running = false;
        result.map_err(ChipError::StreamStuck)
    }

    /// Checks the DMA streams of a playing engine (call it from a slow task): a transfer error
    /// (TEIF) or a stream that stopped by itself halts the engine (outputs 0) and is returned.
    pub fn poll_fault<B: Bus + ChipInterruptSlot + ?Sized>(
        &mut self,
        bus: &mut B,
    ) -> Option<OutputFault> {
        if !self.running || self.mode != Mode::Dma {
            return None;
        }
        let failed = BANKS.into_iter().any(|bank| {
            let stream = bank.stream();
            let flags = bus.read(stream.isr());
            let enabled = bus.read(stream.cr()) & dma::CR_EN != 0;
            flags & stream.flags(dma::TEIF) != 0 || !enabled
        });
        if !failed {
            return None;
        }
        Some(match self.halt(bus) {
            Ok(()) => OutputFault::DmaTransferError,
            Err(error) => error.fault().unwrap_or(OutputFault::DmaTransferError),
        })
    }
}

/// Shortest watchdog timeout: the stall budget of a save (`protocol::flash::STALL_BUDGET_MS`:
/// the worst x8 sector erase and the record's programming, plus 50 %) plus one feeding period
/// ([`WATCHDOG_FEED_MS`]).
pub const WATCHDOG_MIN_TIMEOUT_MS: u32 = protocol::flash::STALL_BUDGET_MS + WATCHDOG_FEED_MS;
/// How often the firmware feeds the watchdog.
pub const WATCHDOG_FEED_MS: u32 = 500;

/// IWDG prescaler code and reload value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WatchdogSetting {
    /// IWDG_PR: divider 4 · 2^code.
    pub prescaler_code: u32,
    /// IWDG_RLR.
    pub reload: u32,
}

impl WatchdogSetting {
    /// Timeout in milliseconds with the LSI at `lsi_hz`: (RLR + 1) · divider / f_LSI.
    pub const fn timeout_ms(&self, lsi_hz: u32) -> u64 {
        (self.reload as u64 + 1) * (4u64 << self.prescaler_code) * 1000 / lsi_hz as u64
    }
}

/// The setting whose timeout is at least `min_timeout_ms` even with the fastest LSI
/// ([`iwdg::LSI_HZ`]): the smallest divider that reaches it, the smallest reload that does.
pub const fn watchdog_setting(min_timeout_ms: u32) -> WatchdogSetting {
    let lsi_max = iwdg::LSI_HZ.2 as u64;
    let needed_ticks = (min_timeout_ms as u64 * lsi_max).div_ceil(1000);
    let mut code = 0;
    while code < iwdg::PR_MAX && needed_ticks > (iwdg::RLR_MAX as u64 + 1) * (4 << code) {
        code += 1;
    }
    let divider = 4u64 << code;
    let mut reload = needed_ticks.div_ceil(divider);
    if reload > iwdg::RLR_MAX as u64 + 1 {
        reload = iwdg::RLR_MAX as u64 + 1;
    }
    WatchdogSetting {
        prescaler_code: code,
        reload: reload as u32 - 1,
    }
}

/// Starts the independent watchdog with `setting`; it also stops while a debugger halts the core.
pub fn watchdog_plan(setting: WatchdogSetting) -> Plan {
    let mut plan = Plan::new();
    plan.push(Step::SetBits {
        addr: dbgmcu::APB1_FZ,
        bits: dbgmcu::IWDG_STOP,
    });
    plan.write(iwdg::KR, iwdg::KEY_UNLOCK);
    plan.write(iwdg::PR, setting.prescaler_code);
    plan.write(iwdg::RLR, setting.reload);
    plan.write(iwdg::KR, iwdg::KEY_START);
    plan
}

/// Feeds the watchdog.
pub const WATCHDOG_FEED: Step = Step::Write {
    addr: iwdg::KR,
    value: iwdg::KEY_FEED,
};
