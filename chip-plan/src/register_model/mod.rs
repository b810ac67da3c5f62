//! A register-level model of the part of the STM32F411 the chip engine drives: TIM2, TIM3,
//! TIM5 ([`timer`]), DMA1 ([`dma`]), their RCC clock enables and resets, SRAM, the NVIC enable
//! bits of TIM2's interrupt, the IWDG and DBGMCU's watchdog freeze bit. It is written from the
//! descriptions in RM0383, not from the firmware, and executes the same [`Plan`]s through the
//! same [`run`] the board does ([`Chip`] is a [`Bus`]).
//!
//! Time is counted in ticks of the 96 MHz timer clock. Every CPU access, DMA transfer and
//! interrupt entry takes a few ticks ([`Timing`]), so a chip boundary can land between two
//! steps of a plan: the halt race is a sweep over that instant ([`tests`]).
//!
//! What the outputs do is logged ([`LogEntry`]): every TIM2 update (chip boundary) and every
//! change of what a PWM bank plays. [`check`] turns that log into per-chip compare values and
//! compares them with the chip table. Anything a plan does that RM0383 forbids or the model does
//! not cover is a violation (a string in [`Chip::violations`]); the tests require none.

pub mod check;
pub mod dma;
mod legacy;
#[cfg(test)]
mod tests;
pub mod timer;

use std::ops::Range;

use crate::plan::{ChipInterrupt, ChipInterruptSlot};
use crate::regs::{SRAM, dbgmcu, iwdg, nvic, rcc, tim};
use crate::step::{Bus, run};

use self::dma::{Dma, RequestSource, request_source};
use self::timer::{BankOutputs, Outcome, Timer, TimerId};

/// How long things take, in timer-clock ticks (96 MHz: 10.4 ns each).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Timing {
    /// A CPU access to a peripheral register (through the APB1 bridge at 48 MHz).
    pub register_access: u64,
    /// A CPU access to SRAM.
    pub memory_access: u64,
    /// From a DMA request to the start of its transfer (arbitration).
    pub dma_latency: u64,
    /// One DMA item: SRAM read + APB write.
    pub dma_item: u64,
    /// From an interrupt flag to the handler's first access (entry, prologue).
    pub irq_latency: u64,
}

impl Default for Timing {
    fn default() -> Self {
        Self {
            register_access: 6,
            memory_access: 2,
            dma_latency: 4,
            dma_item: 8,
            irq_latency: 40,
        }
    }
}

/// One line of what the outputs did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogEntry {
    /// TIM2 had an update event: a chip boundary.
    ChipTimerUpdate {
        /// When.
        t: u64,
    },
    /// What a PWM bank plays changed.
    Outputs {
        /// When.
        t: u64,
        /// TIM3 or TIM5.
        timer: TimerId,
        /// The new state.
        outputs: BankOutputs,
    },
}

/// The independent watchdog's registers.
#[derive(Debug, Clone, Default)]
pub struct Iwdg {
    unlocked: bool,
    /// IWDG_PR.
    pub prescaler_code: u32,
    /// IWDG_RLR (reset value 0xFFF).
    pub reload: u32,
    /// Started (KR = 0xCCCC).
    pub running: bool,
    /// Number of feeds (KR = 0xAAAA).
    pub feeds: u32,
}

/// The modelled chip.
pub struct Chip {
    /// Current time in timer-clock ticks.
    pub now: u64,
    /// Access and transfer durations.
    pub timing: Timing,
    ahb1enr: u32,
    apb1enr: u32,
    apb1rstr: u32,
    timers: [Timer; 3],
    dma: Dma,
    /// When each timer's trigger DMA request was raised.
    request_raised: [u64; 3],
    sram: Vec<u8>,
    unmapped: Vec<Range<u32>>,
    /// The watchdog.
    pub iwdg: Iwdg,
    dbgmcu_apb1_fz: u32,
    nvic_enabled: u32,
    irq_at: Option<u64>,
    in_irq: bool,
    chip_interrupt: Option<ChipInterrupt>,
    last_outputs: [Option<BankOutputs>; 2],
    /// What the outputs did.
    pub log: Vec<LogEntry>,
    /// Every access RM0383 forbids or the model does not cover.
    pub violations: Vec<String>,
    /// For every write that switched a timer's trigger DMA requests off while one was latched:
    /// the burst index at that moment (0: the burst had not begun, NDTR a multiple of 4).
    pub requests_cut: Vec<u32>,
}

/// Which clock-enable/reset bit belongs to a timer.
fn rcc_bit(id: TimerId) -> u32 {
    match id {
        TimerId::Tim2 => rcc::TIM2,
        TimerId::Tim3 => rcc::TIM3,
        TimerId::Tim5 => rcc::TIM5,
    }
}

fn index(id: TimerId) -> usize {
    match id {
        TimerId::Tim2 => 0,
        TimerId::Tim3 => 1,
        TimerId::Tim5 => 2,
    }
}

const TIMERS: [(TimerId, u32); 3] = [
    (TimerId::Tim2, crate::regs::TIM2.base),
    (TimerId::Tim3, crate::regs::TIM3.base),
    (TimerId::Tim5, crate::regs::TIM5.base),
];

/// RM0383 table 54 (TIMx internal trigger connection): the timer behind ITR0..ITR3 of `slave`,
/// among the modelled ones (TIM1, TIM4 and TIM8 are not modelled: never a trigger).
pub(crate) fn itr_source(slave: TimerId, itr: u32) -> Option<TimerId> {
    match (slave, itr) {
        (TimerId::Tim2, 2) => Some(TimerId::Tim3),
        (TimerId::Tim3, 1) => Some(TimerId::Tim2),
        (TimerId::Tim3, 2) => Some(TimerId::Tim5),
        (TimerId::Tim5, 0) => Some(TimerId::Tim2),
        (TimerId::Tim5, 1) => Some(TimerId::Tim3),
        _ => None,
    }
}

/// What happens next.
#[derive(Debug, Clone, Copy)]
enum Event {
    Overflow(usize),
    DmaService(usize),
    Interrupt,
}

/// A bus error (unmapped address, or an address DMA1 cannot reach).
struct BusError;

impl Default for Chip {
    fn default() -> Self {
        Self::new()
    }
}

impl Chip {
    /// The chip as the firmware finds it after embassy's init: GPIO clocks on, TIM4 (the time
    /// driver) and PWR clocked, everything the engine uses in its reset state and unclocked.
    pub fn new() -> Self {
        Self {
            now: 0,
            timing: Timing::default(),
            ahb1enr: 0b111,
            apb1enr: rcc::TIM4 | (1 << 28),
            apb1rstr: 0,
            timers: [
                Timer::reset(TimerId::Tim2, 0),
                Timer::reset(TimerId::Tim3, 0),
                Timer::reset(TimerId::Tim5, 0),
            ],
            dma: Dma::default(),
            request_raised: [0; 3],
            sram: vec![0; (SRAM.end - SRAM.start) as usize],
            unmapped: Vec::new(),
            iwdg: Iwdg {
                reload: iwdg::RLR_MAX,
                ..Iwdg::default()
            },
            dbgmcu_apb1_fz: 0,
            nvic_enabled: 0,
            irq_at: None,
            in_irq: false,
            chip_interrupt: None,
            last_outputs: [None; 2],
            log: Vec::new(),
            violations: Vec::new(),
            requests_cut: Vec::new(),
        }
    }

    /// Makes `range` answer every access with a bus error from now on (a corrupted pointer).
    pub fn unmap(&mut self, range: Range<u32>) {
        self.unmapped.push(range);
    }

    /// Lets time pass without CPU activity.
    pub fn run_until(&mut self, t: u64) {
        self.advance_to(t);
    }

    /// Reads a register or memory word the way a debugger does: no time passes and nothing
    /// changes (DMAR, whose reads move the burst index, is refused).
    pub fn peek(&mut self, addr: u32) -> u32 {
        assert!(
            !TIMERS.iter().any(|&(_, base)| addr == base + tim::DMAR),
            "peeking DMAR would move the burst index"
        );
        let violations_before = self.violations.len();
        let value = self.access(addr, None);
        self.violations.truncate(violations_before);
        value
    }

    fn clocked(&self, id: TimerId) -> bool {
        self.apb1enr & rcc_bit(id) != 0 && self.apb1rstr & rcc_bit(id) == 0
    }

    fn next_event(&self) -> Option<(u64, Event)> {
        let mut best: Option<(u64, Event)> = None;
        let mut consider = |t: u64, event: Event| {
            if best.is_none_or(|(b, _)| t < b) {
                best = Some((t, event));
            }
        };
        for (i, timer) in self.timers.iter().enumerate() {
            if timer.overflow_matters()
                && let Some(t) = timer.next_overflow()
            {
                consider(t.max(self.now), Event::Overflow(i));
            }
        }
        if let Some((t, s)) = self.next_dma_service() {
            consider(t, Event::DmaService(s));
        }
        if !self.in_irq
            && let Some(t) = self.irq_at
        {
            consider(t.max(self.now), Event::Interrupt);
        }
        best
    }

    /// The stream served next and when: enabled, items left, its request line up; the highest
    /// priority wins, then the lowest stream number (RM0383 "DMA arbiter").
    fn next_dma_service(&self) -> Option<(u64, usize)> {
        if self.ahb1enr & rcc::DMA1EN == 0 {
            return None;
        }
        let mut best: Option<(u64, u32, usize)> = None;
        for (s, stream) in self.dma.streams.iter().enumerate() {
            if !stream.enabled() || stream.ndtr == 0 {
                continue;
            }
            let Some(RequestSource::Trigger(id)) = request_source(s, stream.channel()) else {
                continue;
            };
            if !self.timers[index(id)].trigger_dma_request() {
                continue;
            }
            let ready = (self.request_raised[index(id)] + self.timing.dma_latency)
                .max(self.dma.busy_until)
                .max(self.now);
            let better = match best {
                None => true,
                Some((t, pl, _)) => ready < t || (ready == t && stream.priority() > pl),
            };
            if better {
                best = Some((ready, stream.priority(), s));
            }
        }
        best.map(|(t, _, s)| (t, s))
    }

    fn advance_to(&mut self, target: u64) {
        while let Some((t, event)) = self.next_event() {
            if t > target {
                break;
            }
            self.now = t;
            match event {
                Event::Overflow(i) => {
                    let mut violations = Vec::new();
                    let outcome = self.timers[i].overflow(t, &mut violations);
                    self.violations.extend(violations);
                    self.after_timer_event(self.timers[i].id, outcome);
                }
                Event::DmaService(s) => self.serve(s),
                Event::Interrupt => self.interrupt(),
            }
        }
        self.now = self.now.max(target);
    }

    /// Routes a timer event's effects: chip boundary log, TRGO to slaves, TIM2's interrupt.
    fn after_timer_event(&mut self, id: TimerId, outcome: Outcome) {
        if id == TimerId::Tim2 {
            if outcome.update {
                self.log.push(LogEntry::ChipTimerUpdate { t: self.now });
            }
            if self.timers[0].update_interrupt()
                && self.nvic_enabled & (1 << nvic::TIM2_IRQ) != 0
                && self.irq_at.is_none()
            {
                self.irq_at = Some(self.now + self.timing.irq_latency);
            }
        }
        if outcome.trgo {
            self.trgo(id, 0);
        }
        self.log_outputs();
    }

    fn trgo(&mut self, master: TimerId, depth: u32) {
        if depth > 3 {
            self.violations.push("trigger loop between timers".into());
            return;
        }
        for (slave, _) in TIMERS {
            for itr in 0..4 {
                if itr_source(slave, itr) != Some(master) || !self.clocked(slave) {
                    continue;
                }
                let i = index(slave);
                let before = self.timers[i].trigger_dma_request();
                let mut violations = Vec::new();
                let outcome = self.timers[i].trigger_input(itr, self.now, &mut violations);
                self.violations.extend(violations);
                if !before && self.timers[i].trigger_dma_request() {
                    self.request_raised[i] = self.now;
                }
                if outcome.trgo {
                    self.trgo(slave, depth + 1);
                }
            }
        }
    }

    fn log_outputs(&mut self) {
        for (k, id) in [TimerId::Tim3, TimerId::Tim5].into_iter().enumerate() {
            let outputs = self.timers[index(id)].outputs();
            if self.last_outputs[k] != Some(outputs) {
                self.last_outputs[k] = Some(outputs);
                self.log.push(LogEntry::Outputs {
                    t: self.now,
                    timer: id,
                    outputs,
                });
            }
        }
    }

    fn mapped(&self, addr: u32, bytes: u32) -> bool {
        SRAM.contains(&addr)
            && SRAM.contains(&(addr + bytes - 1))
            && !self.unmapped.iter().any(|r| r.contains(&addr))
    }

    fn memory_read(&self, addr: u32, bytes: u32) -> Result<u32, BusError> {
        if !self.mapped(addr, bytes) {
            return Err(BusError);
        }
        let at = (addr - SRAM.start) as usize;
        let mut word = [0u8; 4];
        word[..bytes as usize].copy_from_slice(&self.sram[at..at + bytes as usize]);
        Ok(u32::from_le_bytes(word))
    }

    fn memory_write(&mut self, addr: u32, value: u32, bytes: u32) -> Result<(), BusError> {
        if !self.mapped(addr, bytes) {
            return Err(BusError);
        }
        let at = (addr - SRAM.start) as usize;
        self.sram[at..at + bytes as usize].copy_from_slice(&value.to_le_bytes()[..bytes as usize]);
        Ok(())
    }

    /// The timer whose register block holds `addr`, and the offset.
    fn timer_at(addr: u32) -> Option<(TimerId, u32)> {
        TIMERS
            .iter()
            .find(|&&(_, base)| (base..base + tim::BLOCK).contains(&addr))
            .map(|&(id, base)| (id, addr - base))
    }

    /// One DMA transfer of stream `s` at `self.now`.
    fn serve(&mut self, s: usize) {
        let now = self.now;
        let stream = &self.dma.streams[s];
        let bytes = stream.item_bytes();
        let par = stream.par;
        let requester = match request_source(s, stream.channel()) {
            Some(RequestSource::Trigger(id)) => id,
            None => return,
        };
        let value = match stream.preloaded {
            Some(value) => value,
            None => match self.memory_read(stream.memory_pointer, bytes) {
                Ok(value) => value,
                Err(BusError) => return self.transfer_error(s),
            },
        };
        self.dma.busy_until = now + self.timing.dma_item;
        self.dma.last_stream = Some(s);
        // APB bridge: a 16-bit (8-bit) write reaches a 32-bit register copied into both halves
        // (all four bytes) (RM0383 section 2.1, AHB/APB bridges).
        let replicated = match bytes {
            1 => (value & 0xFF) * 0x0101_0101,
            2 => (value & 0xFFFF) * 0x0001_0001,
            _ => value,
        };
        let Some((target, offset)) = Self::timer_at(par) else {
            return self.transfer_error(s);
        };
        if !self.clocked(target) {
            self.violations.push(format!(
                "DMA wrote {target:?} while it was unclocked or in reset"
            ));
            return self.transfer_error(s);
        }
        let mut violations = Vec::new();
        let (outcome, burst) =
            self.timers[index(target)].write(offset, replicated, now, &mut violations);
        self.violations.extend(violations);
        let continues = target == requester && burst == Some(true);
        self.timers[index(requester)].acknowledge_trigger(continues);
        if continues {
            // The next item of the burst is requested as soon as this one is done.
            self.request_raised[index(requester)] = now + self.timing.dma_item;
        }
        let stream = &mut self.dma.streams[s];
        stream.preloaded = None;
        stream.ndtr -= 1;
        if stream.cr & crate::regs::dma::CR_MINC != 0 {
            stream.memory_pointer += bytes;
        }
        let mut flags = 0;
        if stream.ndtr == stream.ndtr_programmed / 2 {
            flags |= crate::regs::dma::HTIF;
        }
        if stream.ndtr == 0 {
            flags |= crate::regs::dma::TCIF;
            if stream.cr & crate::regs::dma::CR_CIRC != 0 {
                stream.ndtr = stream.ndtr_programmed;
                stream.memory_pointer = stream.m0ar;
            } else {
                stream.cr &= !crate::regs::dma::CR_EN;
            }
        }
        self.dma.raise(s, flags);
        self.preload(s);
        self.after_timer_event(target, outcome);
    }

    /// Direct mode keeps one memory item fetched ahead (RM0383 "Direct mode").
    fn preload(&mut self, s: usize) {
        let stream = &self.dma.streams[s];
        if !stream.enabled() || stream.ndtr == 0 {
            return;
        }
        match self.memory_read(stream.memory_pointer, stream.item_bytes()) {
            Ok(value) => self.dma.streams[s].preloaded = Some(value),
            Err(BusError) => self.transfer_error(s),
        }
    }

    /// TEIF set and the stream disabled by hardware.
    fn transfer_error(&mut self, s: usize) {
        self.dma.raise(s, crate::regs::dma::TEIF);
        let stream = &mut self.dma.streams[s];
        stream.cr &= !crate::regs::dma::CR_EN;
        stream.preloaded = None;
    }

    /// TIM2's interrupt: the installed chip interrupt's steps, run as CPU accesses.
    fn interrupt(&mut self) {
        self.irq_at = None;
        let asserted =
            self.timers[0].update_interrupt() && self.nvic_enabled & (1 << nvic::TIM2_IRQ) != 0;
        if !asserted {
            return;
        }
        let Some(mut state) = self.chip_interrupt.take() else {
            self.violations
                .push("TIM2 interrupt with no chip interrupt installed".into());
            self.nvic_enabled &= !(1 << nvic::TIM2_IRQ);
            return;
        };
        let plan = state.next_plan();
        self.chip_interrupt = Some(state);
        self.in_irq = true;
        let result = run(plan.steps(), self);
        self.in_irq = false;
        if result.is_err() {
            self.violations
                .push("chip interrupt plan did not complete".into());
        }
        if self.timers[0].update_interrupt() && self.irq_at.is_none() {
            self.irq_at = Some(self.now);
        }
    }

    /// A CPU access of `cost` ticks: time passes (events included), then the access happens.
    fn cpu(&mut self, addr: u32) {
        let cost = if SRAM.contains(&addr) {
            self.timing.memory_access
        } else {
            self.timing.register_access
        };
        let target = self.now + cost;
        self.advance_to(target);
    }

    /// Reads (`write == None`) or writes the 32-bit register or memory word at `addr`.
    fn access(&mut self, addr: u32, write: Option<u32>) -> u32 {
        if SRAM.contains(&addr) {
            return match write {
                Some(value) => {
                    if self.memory_write(addr, value, 4).is_err() {
                        self.violations
                            .push(format!("CPU write to unmapped memory {addr:#010x}"));
                    }
                    0
                }
                None => self.memory_read(addr, 4).unwrap_or_else(|BusError| {
                    self.violations
                        .push(format!("CPU read of unmapped memory {addr:#010x}"));
                    0
                }),
            };
        }
        if let Some((id, offset)) = Self::timer_at(addr) {
            return self.timer_access(id, offset, write);
        }
        if (crate::regs::dma::DMA1..crate::regs::dma::DMA1 + 0x400).contains(&addr) {
            return self.dma_access(addr - crate::regs::dma::DMA1, write);
        }
        match (addr, write) {
            (rcc::AHB1ENR, None) => self.ahb1enr,
            (rcc::APB1ENR, None) => self.apb1enr,
            (rcc::APB1RSTR, None) => self.apb1rstr,
            (rcc::AHB1ENR, Some(value)) => {
                if value & self.ahb1enr != self.ahb1enr {
                    self.violations
                        .push("AHB1ENR write turns off a clock the plan does not own".into());
                }
                self.ahb1enr = value;
                0
            }
            (rcc::APB1ENR, Some(value)) => {
                if value & self.apb1enr != self.apb1enr {
                    self.violations
                        .push("APB1ENR write turns off a clock".into());
                }
                self.apb1enr = value;
                0
            }
            (rcc::APB1RSTR, Some(value)) => {
                let ours = rcc::TIM2 | rcc::TIM3 | rcc::TIM5;
                if value & !ours != 0 {
                    self.violations.push(format!(
                        "APB1RSTR resets peripherals the engine does not own: {:#x}",
                        value & !ours
                    ));
                }
                self.apb1rstr = value & ours;
                for (id, _) in TIMERS {
                    if self.apb1rstr & rcc_bit(id) != 0 {
                        self.timers[index(id)] = Timer::reset(id, self.now);
                    }
                }
                self.log_outputs();
                0
            }
            (iwdg::KR, Some(key)) => {
                match key & 0xFFFF {
                    iwdg::KEY_UNLOCK => self.iwdg.unlocked = true,
                    iwdg::KEY_START => {
                        self.iwdg.running = true;
                        self.iwdg.unlocked = false;
                    }
                    iwdg::KEY_FEED => {
                        self.iwdg.feeds += 1;
                        self.iwdg.unlocked = false;
                    }
                    other => self.violations.push(format!("IWDG_KR key {other:#x}")),
                }
                0
            }
            (iwdg::PR | iwdg::RLR, Some(value)) => {
                if !self.iwdg.unlocked {
                    self.violations
                        .push("IWDG_PR/RLR written while write-protected".into());
                } else if addr == iwdg::PR {
                    self.iwdg.prescaler_code = value & 0b111;
                } else {
                    self.iwdg.reload = value & iwdg::RLR_MAX;
                }
                0
            }
            (iwdg::SR, None) => 0,
            (iwdg::PR, None) => self.iwdg.prescaler_code,
            (iwdg::RLR, None) => self.iwdg.reload,
            (dbgmcu::APB1_FZ, None) => self.dbgmcu_apb1_fz,
            (dbgmcu::APB1_FZ, Some(value)) => {
                self.dbgmcu_apb1_fz = value;
                0
            }
            (nvic::ISER0 | nvic::ICER0, None) => self.nvic_enabled,
            (nvic::ISER0, Some(bits)) => {
                self.nvic_enabled |= bits;
                if self.timers[0].update_interrupt() && self.irq_at.is_none() {
                    self.irq_at = Some(self.now + self.timing.irq_latency);
                }
                0
            }
            (nvic::ICER0, Some(bits)) => {
                self.nvic_enabled &= !bits;
                0
            }
            _ => {
                self.violations
                    .push(format!("access to unmodelled address {addr:#010x}"));
                0
            }
        }
    }

    fn timer_access(&mut self, id: TimerId, offset: u32, write: Option<u32>) -> u32 {
        if !self.clocked(id) {
            self.violations
                .push(format!("{id:?} accessed while unclocked or in reset"));
            return 0;
        }
        let i = index(id);
        let mut violations = Vec::new();
        let value = match write {
            None => self.timers[i].read(offset, self.now, &mut violations),
            Some(value) => {
                if offset == tim::DIER
                    && value & tim::DIER_TDE == 0
                    && let Some(index) = self.timers[i].pending_burst()
                {
                    self.requests_cut.push(index);
                }
                let before = self.timers[i].trigger_dma_request();
                let (outcome, _) = self.timers[i].write(offset, value, self.now, &mut violations);
                if !before && self.timers[i].trigger_dma_request() {
                    self.request_raised[i] = self.now;
                }
                self.violations.extend(std::mem::take(&mut violations));
                self.after_timer_event(id, outcome);
                0
            }
        };
        self.violations.extend(violations);
        value
    }

    fn dma_access(&mut self, offset: u32, write: Option<u32>) -> u32 {
        use crate::regs::dma as d;
        if self.ahb1enr & rcc::DMA1EN == 0 {
            self.violations.push("DMA1 accessed while unclocked".into());
            return 0;
        }
        if offset < d::S0CR {
            return match (offset, write) {
                (0x00 | 0x04, None) => self.dma.isr[(offset / 4) as usize],
                (0x08 | 0x0C, Some(bits)) => {
                    self.dma.isr[((offset - 8) / 4) as usize] &= !bits;
                    0
                }
                (0x08 | 0x0C, None) => 0,
                _ => {
                    self.violations
                        .push(format!("DMA1 interrupt register {offset:#x} misused"));
                    0
                }
            };
        }
        let s = ((offset - d::S0CR) / d::STREAM_STRIDE) as usize;
        let reg = (offset - d::S0CR) % d::STREAM_STRIDE;
        if s >= 8 {
            self.violations
                .push(format!("DMA1 offset {offset:#x} is not a stream register"));
            return 0;
        }
        let now = self.now;
        let locked = self.dma.streams[s].en_reads(now);
        let Some(value) = write else {
            let stream = &self.dma.streams[s];
            return match reg {
                0 => (stream.cr & !d::CR_EN) | if locked { d::CR_EN } else { 0 },
                d::NDTR => stream.ndtr,
                d::PAR => stream.par,
                d::M0AR => stream.m0ar,
                d::FCR => stream.fcr,
                _ => 0,
            };
        };
        if reg != 0 && locked {
            self.violations.push(format!(
                "DMA1 stream {s} register {reg:#x} written while EN = 1"
            ));
            return 0;
        }
        match reg {
            0 => self.write_stream_cr(s, value),
            d::NDTR => {
                self.dma.streams[s].ndtr_programmed = value & 0xFFFF;
                self.dma.streams[s].ndtr = value & 0xFFFF;
            }
            d::PAR => self.dma.streams[s].par = value,
            d::M0AR => self.dma.streams[s].m0ar = value,
            d::FCR => {
                self.dma.streams[s].fcr =
                    (self.dma.streams[s].fcr & 0b11_1000) | (value & 0b1000_0111)
            }
            _ => self
                .violations
                .push(format!("DMA1 stream {s} register {reg:#x} is not modelled")),
        }
        0
    }

    fn write_stream_cr(&mut self, s: usize, value: u32) {
        use crate::regs::dma as d;
        let now = self.now;
        let stream = &mut self.dma.streams[s];
        let running = stream.en_reads(now);
        if running {
            if value & !d::CR_EN != stream.cr & !d::CR_EN {
                self.violations.push(format!(
                    "DMA1 stream {s} configuration changed while EN = 1"
                ));
            }
            if value & d::CR_EN == 0 && stream.cr & d::CR_EN != 0 {
                stream.cr &= !d::CR_EN;
                stream.preloaded = None;
                if self.dma.last_stream == Some(s) && self.dma.busy_until > now {
                    stream.stopping_until = Some(self.dma.busy_until);
                }
            }
            return;
        }
        stream.stopping_until = None;
        stream.cr = value;
        if value & d::CR_EN == 0 {
            return;
        }
        if self.dma.flags(s) != 0 {
            self.violations
                .push(format!("DMA1 stream {s} enabled with event flags set"));
        }
        if let Some(what) = self.dma.streams[s].unmodelled_configuration() {
            self.violations
                .push(format!("DMA1 stream {s} enabled with {what}"));
        }
        let stream = &mut self.dma.streams[s];
        let bytes = stream.item_bytes();
        if !stream.par.is_multiple_of(bytes) || !stream.m0ar.is_multiple_of(bytes) {
            self.violations.push(format!(
                "DMA1 stream {s} addresses not aligned to the item size"
            ));
        }
        stream.ndtr = stream.ndtr_programmed;
        stream.memory_pointer = stream.m0ar;
        stream.preloaded = None;
        self.preload(s);
    }

    /// The watchdog timeout in milliseconds with the LSI at `lsi_hz`.
    pub fn watchdog_timeout_ms(&self, lsi_hz: u32) -> u64 {
        (u64::from(self.iwdg.reload) + 1) * (4u64 << self.iwdg.prescaler_code) * 1000
            / u64::from(lsi_hz)
    }

    /// Whether debug halts freeze the watchdog.
    pub fn watchdog_frozen_in_debug(&self) -> bool {
        self.dbgmcu_apb1_fz & dbgmcu::IWDG_STOP != 0
    }
}

impl Bus for Chip {
    fn read(&mut self, addr: u32) -> u32 {
        self.cpu(addr);
        self.access(addr, None)
    }

    fn write(&mut self, addr: u32, value: u32) {
        self.cpu(addr);
        self.access(addr, Some(value));
    }

    fn read16(&mut self, addr: u32) -> u16 {
        self.cpu(addr);
        match self.memory_read(addr, 2) {
            Ok(value) => value as u16,
            Err(BusError) => {
                self.violations.push(format!(
                    "CPU half-word read of unmapped memory {addr:#010x}"
                ));
                0
            }
        }
    }

    fn write16(&mut self, addr: u32, value: u16) {
        self.cpu(addr);
        if self.memory_write(addr, u32::from(value), 2).is_err() {
            self.violations.push(format!(
                "CPU half-word write to unmapped memory {addr:#010x}"
            ));
        }
    }

    fn fence(&mut self) {
        let target = self.now + 1;
        self.advance_to(target);
    }
}

impl ChipInterruptSlot for Chip {
    fn set_chip_interrupt(&mut self, interrupt: Option<ChipInterrupt>) {
        self.chip_interrupt = interrupt;
    }
}
