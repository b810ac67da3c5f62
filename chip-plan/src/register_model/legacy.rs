//! The chip engine as `firmware/src/chips.rs` programmed it before the register plan (commit
//! b7059a9), access for access: embassy's `Timer` helpers are the read-modify-writes they
//! perform, `start_stream`/`stop_stream`/`halt` are transcribed, and `transfers` is the
//! `(0, 0)` it was initialised to and never written again, so both streams get NDTR = 0.
//!
//! It exists to show that the model sees what review found: run through [`super::check`] it
//! plays nothing at all, and with NDTR repaired its halt still loses the DMA burst position in
//! the halt race. `ndtr_written` repairs only the NDTR bug.

use protocol::carriers::ChipTable;
use protocol::timing::{LedLevels, chip_timer_period, fill_compare_frames};

use crate::outputs::{Bank, slots_of};
use crate::plan::FrameMemory;
use crate::regs::{DmaStream, GpTimer, TIM2, TIM3, TIM5, dma, rcc, tim};
use crate::step::Bus;

use super::Chip;

/// Polls of NDTR while waiting for a burst in flight (`BURST_SPIN_LIMIT`).
const BURST_SPIN_LIMIT: u32 = 10_000;

/// Today's engine state.
pub struct LegacyEngine {
    frames: FrameMemory,
    loaded: Option<(usize, [u16; 2])>,
    running: bool,
    /// Repair the NDTR bug (write the frame item counts that `load` used to throw away).
    pub ndtr_written: bool,
}

fn modify(chip: &mut Chip, addr: u32, clear: u32, set: u32) {
    let value = chip.read(addr);
    chip.write(addr, (value & !clear) | set);
}

/// `setup_pwm_bank`.
fn setup_pwm_bank(chip: &mut Chip, timer: GpTimer, trigger: u32) {
    modify(chip, timer.reg(tim::CR1), tim::CR1_CEN, 0); // timer.stop()
    chip.write(timer.reg(tim::PSC), 0);
    modify(chip, timer.reg(tim::CR1), 0, tim::CR1_ARPE); // set_autoreload_preload(true)
    chip.write(timer.reg(tim::ARR), 999);
    for channel in 0..4u32 {
        let ccmr = timer.reg(tim::CCMR1 + 4 * (channel / 2));
        let shift = 8 * (channel % 2);
        modify(
            chip,
            ccmr,
            0b111 << (shift + 4),
            tim::OCM_PWM1 << (shift + 4),
        );
        modify(chip, ccmr, 0, tim::OCPE << shift);
        modify(chip, timer.reg(tim::CCER), 0, tim::CCE << (4 * channel));
    }
    set_burst(chip, timer);
    modify(chip, timer.reg(tim::SMCR), 0b111 << 4, trigger << 4);
    modify(chip, timer.reg(tim::SMCR), 0b111, tim::SMCR_SMS_RESET);
    chip.write(timer.reg(tim::EGR), tim::EGR_UG);
    modify(chip, timer.reg(tim::CR1), 0, tim::CR1_CEN);
}

fn set_burst(chip: &mut Chip, timer: GpTimer) {
    chip.write(timer.reg(tim::DCR), 13 | (3 << 8));
}

fn stop_stream(chip: &mut Chip, stream: DmaStream) {
    modify(chip, stream.cr(), dma::CR_EN, 0);
    while chip.read(stream.cr()) & dma::CR_EN != 0 {}
    chip.write(stream.ifcr(), stream.flags(dma::ALL_FLAGS));
}

fn start_stream(
    chip: &mut Chip,
    stream: DmaStream,
    request: u32,
    peripheral: u32,
    memory: u32,
    items: u16,
    bytes: u32,
) {
    stop_stream(chip, stream);
    chip.write(stream.par(), peripheral);
    chip.write(stream.m0ar(), memory);
    chip.write(stream.ndtr(), u32::from(items));
    chip.write(stream.fcr(), 0);
    let size = dma::size_code(bytes);
    chip.write(
        stream.cr(),
        (request << dma::CR_CHSEL_SHIFT)
            | dma::CR_DIR_M2P
            | dma::CR_CIRC
            | dma::CR_MINC
            | (size << dma::CR_PSIZE_SHIFT)
            | (size << dma::CR_MSIZE_SHIFT)
            | dma::CR_PL_VERY_HIGH,
    );
    chip.fence();
    modify(chip, stream.cr(), 0, dma::CR_EN);
}

impl LegacyEngine {
    /// `ChipEngine::new`: clocks (embassy `Timer::new` enables and resets each timer), DMA1
    /// clock, both PWM banks.
    pub fn new(chip: &mut Chip, frames: FrameMemory) -> Self {
        for bit in [rcc::TIM2, rcc::TIM3, rcc::TIM5] {
            modify(chip, rcc::APB1ENR, 0, bit);
            modify(chip, rcc::APB1RSTR, 0, bit);
            modify(chip, rcc::APB1RSTR, bit, 0);
        }
        modify(chip, rcc::AHB1ENR, 0, rcc::DMA1EN);
        setup_pwm_bank(chip, TIM3, 1);
        setup_pwm_bank(chip, TIM5, 0);
        Self {
            frames,
            loaded: None,
            running: false,
            ndtr_written: false,
        }
    }

    /// `load`.
    pub fn load(
        &mut self,
        chip: &mut Chip,
        table: &ChipTable,
        levels: &LedLevels,
        rate_millihertz: u32,
    ) {
        let period = chip_timer_period(96_000_000, rate_millihertz, 32).expect("rate");
        let was_running = self.running;
        self.halt(chip);
        let mut tim3 = [0u16; 32 * 4];
        let mut tim5 = [0u32; 512 * 4];
        let n3 =
            fill_compare_frames(table, levels, &slots_of(Bank::Tim3), &mut tim3).expect("frames");
        let n5 =
            fill_compare_frames(table, levels, &slots_of(Bank::Tim5), &mut tim5).expect("frames");
        for (i, &value) in tim3[..n3].iter().enumerate() {
            chip.write16(self.frames.tim3 + 2 * i as u32, value);
        }
        for (i, &value) in tim5[..n5].iter().enumerate() {
            chip.write(self.frames.tim5 + 4 * i as u32, value);
        }
        chip.write(TIM2.reg(tim::PSC), u32::from(period.prescaler));
        chip.write(TIM2.reg(tim::ARR), period.auto_reload);
        // `transfers` stays (0, 0): the counts n3, n5 are dropped here.
        let transfers = if self.ndtr_written {
            [n3 as u16, n5 as u16]
        } else {
            [0, 0]
        };
        self.loaded = Some((table.chips(), transfers));
        if was_running {
            self.start(chip);
        }
    }

    /// `start`.
    pub fn start(&mut self, chip: &mut Chip) {
        let Some((chips, transfers)) = self.loaded else {
            return;
        };
        if self.running || chips == 0 {
            return;
        }
        start_stream(
            chip,
            Bank::Tim3.stream(),
            5,
            TIM3.reg(tim::DMAR),
            self.frames.tim3,
            transfers[0],
            2,
        );
        start_stream(
            chip,
            Bank::Tim5.stream(),
            6,
            TIM5.reg(tim::DMAR),
            self.frames.tim5,
            transfers[1],
            4,
        );
        for timer in [TIM3, TIM5] {
            set_burst(chip, timer);
            chip.write(timer.reg(tim::SR), 0);
            modify(chip, timer.reg(tim::DIER), 0, tim::DIER_TDE);
        }
        modify(chip, TIM2.reg(tim::CR1), tim::CR1_CEN, 0);
        chip.write(TIM2.reg(tim::CNT), 0);
        chip.write(TIM2.reg(tim::EGR), tim::EGR_UG);
        modify(chip, TIM2.reg(tim::CR2), 0b111 << 4, tim::CR2_MMS_UPDATE);
        modify(chip, TIM2.reg(tim::CR1), 0, tim::CR1_CEN);
        self.running = true;
    }

    /// `stop` = `halt`.
    pub fn halt(&mut self, chip: &mut Chip) {
        modify(chip, TIM2.reg(tim::CR1), tim::CR1_CEN, 0);
        for bank in [Bank::Tim3, Bank::Tim5] {
            let stream = bank.stream();
            let mut spins = 0;
            while chip.read(stream.cr()) & dma::CR_EN != 0
                && chip.read(stream.ndtr()) % 4 != 0
                && spins < BURST_SPIN_LIMIT
            {
                spins += 1;
            }
            modify(chip, bank.timer().reg(tim::DIER), tim::DIER_TDE, 0);
            stop_stream(chip, stream);
        }
        for timer in [TIM3, TIM5] {
            for channel in 1..=4 {
                chip.write(timer.ccr(channel), 0);
            }
        }
        self.running = false;
    }
}
