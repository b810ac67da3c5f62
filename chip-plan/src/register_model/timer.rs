//! A general-purpose timer (TIM2–TIM5) as RM0383 chapter 13 describes it, reduced to what the
//! chip engine can reach: the up-counting time base with prescaler and auto-reload ("Time-base
//! unit", "Counter modes"), the update event and its preloaded registers (ARR with ARPE, PSC
//! always, CCRx with OCxPE), UG and URS/UDIS, the master mode TRGO (TIMx_CR2.MMS: 000 reset/UG,
//! 010 update), one-pulse mode (CR1.OPM), the slave reset mode on an internal trigger (TIMx_SMCR.SMS = 100, "Slave mode:
//! Reset mode") with its trigger flag and trigger DMA request (TIMx_DIER.TDE), the DMA burst
//! through TIMx_DCR/TIMx_DMAR with its internal index ("DMA burst mode"), output compare in PWM
//! mode 1 ("PWM mode") and the channel enables (TIMx_CCER).
//!
//! Counters are advanced analytically between events, so a 30 Hz chip of 3.2 million ticks
//! costs the same as a 4 kHz one. Anything a plan could switch on that is not modelled (update
//! or compare DMA requests, other slave modes, input capture, centre-aligned counting) is
//! reported as a violation instead of being silently ignored.

use crate::regs::tim;

/// The timers the model contains.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum TimerId {
    /// TIM2, 32-bit.
    Tim2,
    /// TIM3, 16-bit.
    Tim3,
    /// TIM5, 32-bit.
    Tim5,
}

/// What caused an update event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UpdateSource {
    /// Counter overflow.
    Overflow,
    /// Software, EGR.UG.
    Software,
    /// Slave mode controller in reset mode.
    SlaveReset,
}

/// Side effects of an event the chip must route.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Outcome {
    /// A TRGO pulse was emitted.
    pub trgo: bool,
    /// An update event happened (UEV, not blocked by UDIS).
    pub update: bool,
}

/// The visible state of one PWM output: the compare value the pin plays (0 = low all the time,
/// ARR + 1 = high all the time), or `None` when the channel is configured in a way the chip
/// engine must never use (not PWM mode 1 active high, or an input).
pub type OutputLevel = Option<u32>;

/// Everything about a bank's outputs that changes what the LEDs see.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BankOutputs {
    /// Counter enabled.
    pub running: bool,
    /// Active prescaler.
    pub prescaler: u32,
    /// Active auto-reload.
    pub auto_reload: u32,
    /// Per channel 1..=4.
    pub levels: [OutputLevel; 4],
}

/// Register state and internal state of one timer.
#[derive(Debug, Clone)]
pub struct Timer {
    /// Which timer.
    pub id: TimerId,
    width_mask: u32,
    cr1: u32,
    cr2: u32,
    smcr: u32,
    dier: u32,
    sr: u32,
    ccmr: [u32; 2],
    ccer: u32,
    psc: u32,
    arr: u32,
    ccr: [u32; 4],
    dcr: u32,
    psc_active: u32,
    arr_active: u32,
    ccr_active: [u32; 4],
    cnt: u32,
    psc_cnt: u32,
    /// Time up to which `cnt`/`psc_cnt` are valid.
    synced: u64,
    /// DMA burst index (RM0383 TIMx_DMAR: "DMA index is automatically controlled by the DMA
    /// transfer, and ranges from 0 to DBL").
    dma_index: u32,
    /// The trigger DMA request is latched until its transfer (or whole burst) is done.
    trigger_request: bool,
}

impl Timer {
    /// A timer in its reset state (RM0383 13.4: all registers 0 except ARR = all ones).
    pub fn reset(id: TimerId, now: u64) -> Self {
        let width_mask = match id {
            TimerId::Tim3 => 0xFFFF,
            TimerId::Tim2 | TimerId::Tim5 => 0xFFFF_FFFF,
        };
        Self {
            id,
            width_mask,
            cr1: 0,
            cr2: 0,
            smcr: 0,
            dier: 0,
            sr: 0,
            ccmr: [0; 2],
            ccer: 0,
            psc: 0,
            arr: width_mask,
            ccr: [0; 4],
            dcr: 0,
            psc_active: 0,
            arr_active: width_mask,
            ccr_active: [0; 4],
            cnt: 0,
            psc_cnt: 0,
            synced: now,
            dma_index: 0,
            trigger_request: false,
        }
    }

    fn enabled(&self) -> bool {
        self.cr1 & tim::CR1_CEN != 0
    }

    fn preload_enabled(&self, channel: usize) -> bool {
        (self.ccmr[channel / 2] >> (8 * (channel % 2))) & tim::OCPE != 0
    }

    /// Brings the counter forward to `now` (no overflow processing: the chip processes every
    /// overflow that matters at its own time; others only set UIF).
    pub fn sync(&mut self, now: u64) {
        if now <= self.synced {
            return;
        }
        let elapsed = now - self.synced;
        self.synced = now;
        if !self.enabled() {
            return;
        }
        let divider = u64::from(self.psc_active) + 1;
        let phase = u64::from(self.psc_cnt) + elapsed;
        self.psc_cnt = (phase % divider) as u32;
        let mut steps = phase / divider;
        // Count up, wrapping at ARR (or at the counter width when CNT is above ARR).
        while steps > 0 {
            let limit = if self.cnt <= self.arr_active {
                u64::from(self.arr_active)
            } else {
                u64::from(self.width_mask)
            };
            let to_wrap = limit - u64::from(self.cnt) + 1;
            if steps < to_wrap {
                self.cnt += steps as u32;
                break;
            }
            steps -= to_wrap;
            self.cnt = 0;
            if self.cr1 & tim::CR1_UDIS == 0 {
                self.sr |= tim::SR_UIF;
            }
            if steps > 0 && self.arr_active > 0 {
                // Whole further periods: only the flag changes.
                steps %= u64::from(self.arr_active) + 1;
            }
        }
    }

    /// Time of the next overflow, if the counter runs.
    pub fn next_overflow(&self) -> Option<u64> {
        if !self.enabled() {
            return None;
        }
        let divider = u64::from(self.psc_active) + 1;
        let limit = if self.cnt <= self.arr_active {
            u64::from(self.arr_active)
        } else {
            u64::from(self.width_mask)
        };
        let to_next_tick = divider - u64::from(self.psc_cnt);
        Some(self.synced + to_next_tick + (limit - u64::from(self.cnt)) * divider)
    }

    /// Whether an overflow changes anything beyond UIF: a preloaded value waits for it, or an
    /// update is routed somewhere (TRGO, interrupt, DMA).
    pub fn overflow_matters(&self) -> bool {
        if self.cr1 & tim::CR1_OPM != 0 {
            // The overflow stops the counter.
            return true;
        }
        let waiting_ccr =
            (0..4).any(|c| self.preload_enabled(c) && self.ccr[c] != self.ccr_active[c]);
        let waiting = self.psc != self.psc_active || self.arr != self.arr_active || waiting_ccr;
        let mms = (self.cr2 >> tim::CR2_MMS_SHIFT) & 0b111;
        waiting || mms == 0b010 || self.dier & (tim::DIER_UIE | tim::DIER_UDE) != 0
    }

    /// Processes the overflow at `now` (= [`Self::next_overflow`]).
    pub fn overflow(&mut self, now: u64, violations: &mut Vec<String>) -> Outcome {
        // At the overflow instant the counter goes from its limit to 0 and the prescaler
        // counter restarts.
        self.cnt = 0;
        self.psc_cnt = 0;
        self.synced = now;
        let outcome = self.update_event(UpdateSource::Overflow, violations);
        // One-pulse mode: the counter stops at the update event (RM0383 "One-pulse mode").
        if self.cr1 & tim::CR1_OPM != 0 {
            self.cr1 &= !tim::CR1_CEN;
        }
        outcome
    }

    /// The update event (RM0383 13.3.2): shadow registers loaded, UIF, TRGO.
    fn update_event(&mut self, source: UpdateSource, violations: &mut Vec<String>) -> Outcome {
        if self.cr1 & tim::CR1_UDIS != 0 {
            return Outcome::default();
        }
        self.psc_active = self.psc;
        self.arr_active = self.arr;
        for c in 0..4 {
            if self.preload_enabled(c) {
                self.ccr_active[c] = self.ccr[c];
            }
        }
        if source == UpdateSource::Overflow || self.cr1 & tim::CR1_URS == 0 {
            self.sr |= tim::SR_UIF;
        }
        if self.dier & tim::DIER_UDE != 0 {
            violations.push(format!(
                "{:?}: update DMA requests are not modelled",
                self.id
            ));
        }
        let mms = (self.cr2 >> tim::CR2_MMS_SHIFT) & 0b111;
        let trgo = match mms {
            0b010 => true,
            0b000 => source != UpdateSource::Overflow,
            _ => false,
        };
        Outcome { trgo, update: true }
    }

    /// Whether the update interrupt is asserted (UIF with UIE).
    pub fn update_interrupt(&self) -> bool {
        self.sr & tim::SR_UIF != 0 && self.dier & tim::DIER_UIE != 0
    }

    /// A rising edge on internal trigger `itr` (0..=3) at `now`.
    pub fn trigger_input(&mut self, itr: u32, now: u64, violations: &mut Vec<String>) -> Outcome {
        let ts = (self.smcr >> tim::SMCR_TS_SHIFT) & 0b111;
        let sms = self.smcr & tim::SMCR_SMS_MASK;
        if ts != itr || sms == 0 {
            return Outcome::default();
        }
        if sms != tim::SMCR_SMS_RESET {
            violations.push(format!(
                "{:?}: slave mode {sms:03b} is not modelled",
                self.id
            ));
            return Outcome::default();
        }
        self.sync(now);
        self.cnt = 0;
        self.psc_cnt = 0;
        let outcome = self.update_event(UpdateSource::SlaveReset, violations);
        self.sr |= tim::SR_TIF;
        if self.dier & tim::DIER_TDE != 0 {
            self.trigger_request = true;
        }
        outcome
    }

    /// The burst index while a trigger DMA request is latched (0: nothing transferred yet).
    pub fn pending_burst(&self) -> Option<u32> {
        self.trigger_request.then_some(self.dma_index)
    }

    /// Whether the timer asserts its trigger DMA request line.
    pub fn trigger_dma_request(&self) -> bool {
        self.trigger_request && self.dier & tim::DIER_TDE != 0
    }

    /// The DMA served one transfer of the trigger request. A transfer through this timer's DMAR
    /// that leaves its burst going keeps the request up (`burst_continues`); any other transfer
    /// ends it.
    pub fn acknowledge_trigger(&mut self, burst_continues: bool) {
        if !burst_continues {
            self.trigger_request = false;
        }
    }

    /// Register offset a DMAR access reaches, advancing the burst index; the second value says
    /// whether the burst goes on after this access.
    fn dmar_target(&mut self) -> (u32, bool) {
        let dba = self.dcr & 0x1F;
        let dbl = (self.dcr >> tim::DCR_DBL_SHIFT) & 0x1F;
        let offset = 4 * (dba + self.dma_index);
        self.dma_index += 1;
        if self.dma_index > dbl {
            self.dma_index = 0;
            self.trigger_request = false;
            (offset, false)
        } else {
            (offset, true)
        }
    }

    /// Reads the register at `offset` (counter synced to `now`).
    pub fn read(&mut self, offset: u32, now: u64, violations: &mut Vec<String>) -> u32 {
        self.sync(now);
        match offset {
            tim::CR1 => self.cr1,
            tim::CR2 => self.cr2,
            tim::SMCR => self.smcr,
            tim::DIER => self.dier,
            tim::SR => self.sr,
            tim::CCMR1 => self.ccmr[0],
            tim::CCMR2 => self.ccmr[1],
            tim::CCER => self.ccer,
            tim::CNT => self.cnt,
            tim::PSC => self.psc,
            tim::ARR => self.arr,
            o if (tim::CCR1..tim::CCR1 + 16).contains(&o) => {
                self.ccr[((o - tim::CCR1) / 4) as usize]
            }
            tim::DCR => self.dcr,
            tim::DMAR => {
                let (target, _) = self.dmar_target();
                self.read(target, now, violations)
            }
            tim::EGR => 0,
            other => {
                violations.push(format!(
                    "{:?}: read of unmodelled offset {other:#x}",
                    self.id
                ));
                0
            }
        }
    }

    /// Writes `value` to the register at `offset` at time `now`; `burst` receives whether a
    /// DMAR access leaves the burst going.
    pub fn write(
        &mut self,
        offset: u32,
        value: u32,
        now: u64,
        violations: &mut Vec<String>,
    ) -> (Outcome, Option<bool>) {
        self.sync(now);
        let mut outcome = Outcome::default();
        let mut burst = None;
        match offset {
            tim::CR1 => {
                if value & tim::CR1_DIR_CMS_MASK != 0 {
                    violations.push(format!(
                        "{:?}: down or centre-aligned counting is not modelled",
                        self.id
                    ));
                }
                if value & tim::CR1_CKD_MASK != 0 {
                    violations.push(format!(
                        "{:?}: clock division (CKD) is not modelled",
                        self.id
                    ));
                }
                self.cr1 = value & 0x3FF;
            }
            tim::CR2 => {
                let mms = value & tim::CR2_MMS_MASK;
                if mms != 0 && mms != tim::CR2_MMS_UPDATE {
                    violations.push(format!(
                        "{:?}: master mode {:03b} is not modelled",
                        self.id,
                        mms >> tim::CR2_MMS_SHIFT
                    ));
                }
                if value & !tim::CR2_MMS_MASK != 0 {
                    violations.push(format!(
                        "{:?}: CR2 bits {:#x} (CCDS, TI1S) are not modelled",
                        self.id,
                        value & !tim::CR2_MMS_MASK
                    ));
                }
                self.cr2 = value & 0xF8;
            }
            tim::SMCR => {
                let known = tim::SMCR_SMS_MASK | tim::SMCR_TS_MASK;
                if value & !known != 0 {
                    violations.push(format!(
                        "{:?}: SMCR bits {:#x} (MSM, external trigger) are not modelled",
                        self.id,
                        value & !known
                    ));
                }
                let ts = (value & tim::SMCR_TS_MASK) >> tim::SMCR_TS_SHIFT;
                if value & tim::SMCR_SMS_MASK != 0 && ts > 3 {
                    violations.push(format!(
                        "{:?}: trigger input {ts:03b} (TI1/TI2/ETR) is not modelled",
                        self.id
                    ));
                }
                self.smcr = value & 0xFFF7;
            }
            tim::DIER => {
                if value & tim::DIER_CCDE_MASK != 0 {
                    violations.push(format!(
                        "{:?}: compare DMA requests are not modelled",
                        self.id
                    ));
                }
                if self.id != TimerId::Tim2 && value & tim::DIER_UIE != 0 {
                    violations.push(format!("{:?}: only TIM2's interrupt is modelled", self.id));
                }
                let other_interrupts = value
                    & 0x5F5F
                    & !(tim::DIER_UIE | tim::DIER_UDE)
                    & !(tim::DIER_CCDE_MASK | tim::DIER_TDE);
                if other_interrupts != 0 {
                    violations.push(format!(
                        "{:?}: compare and trigger interrupts ({other_interrupts:#x}) are not \
                         modelled",
                        self.id
                    ));
                }
                self.dier = value & 0x5F5F;
            }
            // rc_w0: writing 0 clears a flag, 1 leaves it.
            tim::SR => self.sr &= value,
            tim::EGR => {
                if value & tim::EGR_UG != 0 {
                    self.cnt = 0;
                    self.psc_cnt = 0;
                    outcome = self.update_event(UpdateSource::Software, violations);
                }
                if value & !tim::EGR_UG != 0 {
                    violations.push(format!(
                        "{:?}: EGR events other than UG are not modelled",
                        self.id
                    ));
                }
            }
            tim::CCMR1 | tim::CCMR2 => {
                let i = ((offset - tim::CCMR1) / 4) as usize;
                // CCxS = 00 (output) is the only modelled channel direction.
                if value & 0b11 != 0 || (value >> 8) & 0b11 != 0 {
                    violations.push(format!("{:?}: input capture is not modelled", self.id));
                }
                // OCxFE (bit 2) and OCxCE (bit 7) of either channel.
                if value & 0x8484 != 0 {
                    violations.push(format!(
                        "{:?}: output compare fast or clear enable is not modelled",
                        self.id
                    ));
                }
                self.ccmr[i] = value & 0xFFFF;
            }
            tim::CCER => {
                if value & 0x8888 != 0 {
                    violations.push(format!(
                        "{:?}: CCxNP must stay 0 for an output channel",
                        self.id
                    ));
                }
                self.ccer = value & 0xBBBB;
            }
            tim::CNT => self.cnt = value & self.width_mask,
            tim::PSC => self.psc = value & 0xFFFF,
            tim::ARR => {
                self.arr = value & self.width_mask;
                if self.cr1 & tim::CR1_ARPE == 0 {
                    self.arr_active = self.arr;
                }
            }
            o if (tim::CCR1..tim::CCR1 + 16).contains(&o) => {
                let c = ((o - tim::CCR1) / 4) as usize;
                self.ccr[c] = value & self.width_mask;
                if !self.preload_enabled(c) {
                    self.ccr_active[c] = self.ccr[c];
                }
            }
            tim::DCR => self.dcr = value & 0x1F1F,
            tim::DMAR => {
                let (target, goes_on) = self.dmar_target();
                if target == tim::DMAR {
                    violations.push(format!("{:?}: DMA burst aimed at DMAR itself", self.id));
                } else {
                    outcome = self.write(target, value, now, violations).0;
                }
                burst = Some(goes_on);
            }
            other => violations.push(format!(
                "{:?}: write to unmodelled offset {other:#x}",
                self.id
            )),
        }
        (outcome, burst)
    }

    /// What the outputs look like now.
    pub fn outputs(&self) -> BankOutputs {
        let mut levels = [None; 4];
        for (c, level) in levels.iter_mut().enumerate() {
            let mode = (self.ccmr[c / 2] >> (8 * (c % 2) as u32 + tim::OCM_SHIFT)) & 0b111;
            let ccer = (self.ccer >> (4 * c)) & 0xF;
            *level = if ccer & tim::CCE == 0 {
                // Channel output disabled: the pin is not driven high.
                Some(0)
            } else if mode == tim::OCM_PWM1 && ccer & tim::CCP == 0 {
                Some(self.ccr_active[c].min(self.arr_active.saturating_add(1)))
            } else {
                None
            };
        }
        BankOutputs {
            running: self.enabled(),
            prescaler: self.psc_active,
            auto_reload: self.arr_active,
            levels,
        }
    }
}
