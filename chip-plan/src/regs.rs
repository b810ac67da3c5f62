//! Addresses and bit fields of every STM32F411 register the chip engine touches, from the
//! reference manual RM0383 (STM32F411xC/E, rev 3): the memory map (section 2.3), RCC (section 6.3),
//! the DMA controller (section 9.5), the general-purpose timers TIM2–TIM5 (section 13.4), the
//! independent watchdog (IWDG, section 15.4) and the debug support's DBGMCU_APB1_FZ (chapter 23);
//! the NVIC set/clear-enable registers come from the Cortex-M4 programming manual PM0214
//! (section 4.3).
//!
//! `cargo test vendor` checks every value here against the STM32F411CE metadata of stm32-metapac
//! (the register descriptions generated from ST's SVD files that embassy-stm32 builds on, at the
//! version `Cargo.lock` pins): base addresses, register offsets, field positions and widths,
//! enumerated values, RCC enable and reset bits, interrupt numbers, the LED pins' alternate
//! functions and the DMA request map; the NVIC registers are checked against the `cortex-m`
//! crate. Addresses are plain `u32`s: the plan is data, and the host model decodes the same
//! numbers the board writes.

/// SRAM of the F411: 128 KiB from 0x2000_0000 (RM0383 section 2.3, memory map).
pub const SRAM: core::ops::Range<u32> = 0x2000_0000..0x2002_0000;

/// Reset and clock control (RM0383 section 6.3), base 0x4002_3800.
pub mod rcc {
    /// RCC_APB1RSTR: holding a bit at 1 keeps that APB1 peripheral in reset.
    pub const APB1RSTR: u32 = 0x4002_3820;
    /// RCC_AHB1ENR: AHB1 peripheral clock enables.
    pub const AHB1ENR: u32 = 0x4002_3830;
    /// RCC_APB1ENR: APB1 peripheral clock enables.
    pub const APB1ENR: u32 = 0x4002_3840;
    /// AHB1ENR.DMA1EN.
    pub const DMA1EN: u32 = 1 << 21;
    /// TIM2 bit in APB1ENR (TIM2EN) and APB1RSTR (TIM2RST).
    pub const TIM2: u32 = 1; // bit 0
    /// TIM3 bit in APB1ENR and APB1RSTR.
    pub const TIM3: u32 = 1 << 1;
    /// TIM4 bit (the embassy time driver's timer: never touched by the plan).
    pub const TIM4: u32 = 1 << 2;
    /// TIM5 bit in APB1ENR and APB1RSTR.
    pub const TIM5: u32 = 1 << 3;
}

/// Register offsets and fields of the general-purpose timers TIM2–TIM5 (RM0383 section 13.4).
pub mod tim {
    /// TIMx_CR1 offset.
    pub const CR1: u32 = 0x00;
    /// TIMx_CR2 offset.
    pub const CR2: u32 = 0x04;
    /// TIMx_SMCR offset.
    pub const SMCR: u32 = 0x08;
    /// TIMx_DIER offset.
    pub const DIER: u32 = 0x0C;
    /// TIMx_SR offset.
    pub const SR: u32 = 0x10;
    /// TIMx_EGR offset.
    pub const EGR: u32 = 0x14;
    /// TIMx_CCMR1 offset (channels 1 and 2).
    pub const CCMR1: u32 = 0x18;
    /// TIMx_CCMR2 offset (channels 3 and 4).
    pub const CCMR2: u32 = 0x1C;
    /// TIMx_CCER offset.
    pub const CCER: u32 = 0x20;
    /// TIMx_CNT offset.
    pub const CNT: u32 = 0x24;
    /// TIMx_PSC offset.
    pub const PSC: u32 = 0x28;
    /// TIMx_ARR offset.
    pub const ARR: u32 = 0x2C;
    /// TIMx_CCR1 offset; CCRn is at `CCR1 + 4 (n − 1)`.
    pub const CCR1: u32 = 0x34;
    /// TIMx_DCR offset.
    pub const DCR: u32 = 0x48;
    /// TIMx_DMAR offset.
    pub const DMAR: u32 = 0x4C;
    /// Size of one timer's register block.
    pub const BLOCK: u32 = 0x400;

    /// CR1.CEN: counter enable.
    pub const CR1_CEN: u32 = 1; // bit 0
    /// CR1.UDIS: update disable.
    pub const CR1_UDIS: u32 = 1 << 1;
    /// CR1.URS: only counter overflow raises UIF / update requests.
    pub const CR1_URS: u32 = 1 << 2;
    /// CR1.OPM: one-pulse mode, the counter stops (CEN cleared) at the next update event.
    pub const CR1_OPM: u32 = 1 << 3;
    /// CR1.DIR (bit 4) and CR1.CMS (bits 5–6): down-counting and centre-aligned modes.
    pub const CR1_DIR_CMS_MASK: u32 = 0b111 << 4;
    /// CR1.CKD (bits 8–9): clock division for the digital filters and dead-time.
    pub const CR1_CKD_MASK: u32 = 0b11 << 8;
    /// CR1.ARPE: TIMx_ARR is buffered (preloaded).
    pub const CR1_ARPE: u32 = 1 << 7;
    /// CR2.MMS field position (master mode selection, 3 bits).
    pub const CR2_MMS_SHIFT: u32 = 4;
    /// CR2.MMS field mask.
    pub const CR2_MMS_MASK: u32 = 0b111 << CR2_MMS_SHIFT;
    /// CR2.MMS = 010: the update event is TRGO.
    pub const CR2_MMS_UPDATE: u32 = 0b010 << CR2_MMS_SHIFT;
    /// SMCR.SMS field mask (slave mode selection).
    pub const SMCR_SMS_MASK: u32 = 0b111;
    /// SMCR.SMS = 100: reset mode, a rising TRGI edge reinitialises the counter and updates.
    pub const SMCR_SMS_RESET: u32 = 0b100;
    /// SMCR.TS field position (trigger selection, 3 bits; 000–011 = ITR0–ITR3).
    pub const SMCR_TS_SHIFT: u32 = 4;
    /// SMCR.TS field mask.
    pub const SMCR_TS_MASK: u32 = 0b111 << SMCR_TS_SHIFT;
    /// DIER.UIE: update interrupt enable.
    pub const DIER_UIE: u32 = 1; // bit 0
    /// DIER.UDE: update DMA request enable.
    pub const DIER_UDE: u32 = 1 << 8;
    /// DIER.CC1DE..CC4DE: capture/compare DMA request enables (bits 9–12).
    pub const DIER_CCDE_MASK: u32 = 0b1111 << 9;
    /// DIER.TDE: trigger DMA request enable.
    pub const DIER_TDE: u32 = 1 << 14;
    /// SR.UIF: update interrupt flag.
    pub const SR_UIF: u32 = 1; // bit 0
    /// SR.TIF: trigger interrupt flag.
    pub const SR_TIF: u32 = 1 << 6;
    /// EGR.UG: re-initialise the counter and generate an update event.
    pub const EGR_UG: u32 = 1; // bit 0
    /// CCMRx output compare mode = 110 (PWM mode 1: active while CNT < CCR), per channel slot.
    pub const OCM_PWM1: u32 = 0b110;
    /// CCMRx.OCxM position within a channel's byte.
    pub const OCM_SHIFT: u32 = 4;
    /// CCMRx.OCxPE (preload enable) within a channel's byte.
    pub const OCPE: u32 = 1 << 3;
    /// Distance in bits between the two channels' fields of one CCMRx register.
    pub const CCMR_CHANNEL_STRIDE: u32 = 8;
    /// Distance in bits between two channels' fields in CCER.
    pub const CCER_CHANNEL_STRIDE: u32 = 4;
    /// CCER.CCxE (output enable) within a channel's nibble.
    pub const CCE: u32 = 1; // bit 0
    /// CCER.CCxP (output polarity: active low) within a channel's nibble.
    pub const CCP: u32 = 1 << 1;
    /// DCR.DBL field position (burst length − 1, 5 bits); DBA is bits 0–4.
    pub const DCR_DBL_SHIFT: u32 = 8;

    /// CCMR1/CCMR2 value with both of its channels in PWM mode 1 with preload.
    pub const fn ccmr_pwm1_preload_pair() -> u32 {
        let one = (OCM_PWM1 << OCM_SHIFT) | OCPE;
        one | (one << CCMR_CHANNEL_STRIDE)
    }

    /// CCER value with channels 1–4 enabled, active high.
    pub const fn ccer_all_enabled() -> u32 {
        let s = CCER_CHANNEL_STRIDE;
        CCE | (CCE << s) | (CCE << (2 * s)) | (CCE << (3 * s))
    }

    /// DCR value for a burst of `transfers` registers starting at offset `first` (a multiple
    /// of 4): DBA = first / 4, DBL = transfers − 1.
    pub const fn dcr(first: u32, transfers: u32) -> u32 {
        (first / 4) | ((transfers - 1) << DCR_DBL_SHIFT)
    }
}

/// One of the general-purpose timers TIM2–TIM5, by base address.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GpTimer {
    /// Base address of its register block.
    pub base: u32,
}

/// TIM2 (32-bit counter, APB1): the chip clock.
pub const TIM2: GpTimer = GpTimer { base: 0x4000_0000 };
/// TIM3 (16-bit counter, APB1): PWM bank of LEDs 1–4.
pub const TIM3: GpTimer = GpTimer { base: 0x4000_0400 };
/// TIM5 (32-bit counter, APB1): PWM bank of LEDs 5–8.
pub const TIM5: GpTimer = GpTimer { base: 0x4000_0C00 };

impl GpTimer {
    /// Address of the register at `offset` (one of the [`tim`] offsets).
    pub const fn reg(self, offset: u32) -> u32 {
        self.base + offset
    }

    /// Address of TIMx_CCRn for channel `channel` (1..=4).
    pub const fn ccr(self, channel: u8) -> u32 {
        self.base + tim::CCR1 + 4 * (channel as u32 - 1)
    }
}

/// DMA controller registers and stream fields (RM0383 section 9.5).
pub mod dma {
    /// DMA1 base address.
    pub const DMA1: u32 = 0x4002_6000;
    /// DMA_LISR offset (streams 0–3).
    pub const LISR: u32 = 0x00;
    /// DMA_HISR offset (streams 4–7).
    pub const HISR: u32 = 0x04;
    /// DMA_LIFCR offset (streams 0–3).
    pub const LIFCR: u32 = 0x08;
    /// DMA_HIFCR offset (streams 4–7).
    pub const HIFCR: u32 = 0x0C;
    /// DMA_S0CR offset; stream x's registers are `0x18 · x` further on.
    pub const S0CR: u32 = 0x10;
    /// Distance between two streams' register sets.
    pub const STREAM_STRIDE: u32 = 0x18;
    /// SxNDTR offset from SxCR.
    pub const NDTR: u32 = 0x04;
    /// SxPAR offset from SxCR.
    pub const PAR: u32 = 0x08;
    /// SxM0AR offset from SxCR.
    pub const M0AR: u32 = 0x0C;
    /// SxFCR offset from SxCR.
    pub const FCR: u32 = 0x14;

    /// SxCR.EN: stream enable (cleared by hardware at a transfer error or end of transfer).
    pub const CR_EN: u32 = 1; // bit 0
    /// SxCR.TEIE: transfer error interrupt enable.
    pub const CR_TEIE: u32 = 1 << 2;
    /// SxCR.DIR = 01: memory to peripheral.
    pub const CR_DIR_M2P: u32 = 0b01 << 6;
    /// SxCR.DIR field mask.
    pub const CR_DIR_MASK: u32 = 0b11 << 6;
    /// SxCR.CIRC: circular mode (NDTR and the addresses reload at the end).
    pub const CR_CIRC: u32 = 1 << 8;
    /// SxCR.PINC: peripheral address increment.
    pub const CR_PINC: u32 = 1 << 9;
    /// SxCR.MINC: memory address increment.
    pub const CR_MINC: u32 = 1 << 10;
    /// SxCR.PSIZE position (00 byte, 01 half-word, 10 word).
    pub const CR_PSIZE_SHIFT: u32 = 11;
    /// SxCR.MSIZE position.
    pub const CR_MSIZE_SHIFT: u32 = 13;
    /// SxCR.PL position (priority level, 2 bits).
    pub const CR_PL_SHIFT: u32 = 16;
    /// SxCR.PL = 11: very high priority.
    pub const CR_PL_VERY_HIGH: u32 = 0b11 << CR_PL_SHIFT;
    /// SxCR.DBM: double-buffer mode.
    pub const CR_DBM: u32 = 1 << 18;
    /// SxCR.PBURST/MBURST field mask (bits 21–24).
    pub const CR_BURST_MASK: u32 = 0b1111 << 21;
    /// SxCR.CHSEL position (request channel 0–7).
    pub const CR_CHSEL_SHIFT: u32 = 25;
    /// SxFCR.DMDIS: direct mode disabled (FIFO used); 0 = direct mode.
    pub const FCR_DMDIS: u32 = 1 << 2;

    /// FEIFx: FIFO error flag (per-stream flag bit, before shifting).
    pub const FEIF: u32 = 1; // bit 0
    /// DMEIFx: direct mode error flag.
    pub const DMEIF: u32 = 1 << 2;
    /// TEIFx: transfer error flag.
    pub const TEIF: u32 = 1 << 3;
    /// HTIFx: half transfer flag.
    pub const HTIF: u32 = 1 << 4;
    /// TCIFx: transfer complete flag.
    pub const TCIF: u32 = 1 << 5;
    /// Every event flag of one stream.
    pub const ALL_FLAGS: u32 = FEIF | DMEIF | TEIF | HTIF | TCIF;
    /// Bit position of the flags of streams 0–3 (4–7) in LISR/LIFCR (HISR/HIFCR).
    pub const FLAG_SHIFTS: [u32; 4] = [0, 6, 16, 22];

    /// SxCR.PSIZE/MSIZE code of a data item of `bytes` bytes (1, 2 or 4).
    pub const fn size_code(bytes: u32) -> u32 {
        match bytes {
            1 => 0b00,
            2 => 0b01,
            _ => 0b10,
        }
    }
}

/// One DMA1 stream (0..=7).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DmaStream {
    /// Stream number.
    pub number: u8,
}

impl DmaStream {
    /// Address of SxCR.
    pub const fn cr(self) -> u32 {
        dma::DMA1 + dma::S0CR + dma::STREAM_STRIDE * self.number as u32
    }

    /// Address of SxNDTR.
    pub const fn ndtr(self) -> u32 {
        self.cr() + dma::NDTR
    }

    /// Address of SxPAR.
    pub const fn par(self) -> u32 {
        self.cr() + dma::PAR
    }

    /// Address of SxM0AR.
    pub const fn m0ar(self) -> u32 {
        self.cr() + dma::M0AR
    }

    /// Address of SxFCR.
    pub const fn fcr(self) -> u32 {
        self.cr() + dma::FCR
    }

    /// Address of the interrupt status register holding this stream's flags (LISR or HISR).
    pub const fn isr(self) -> u32 {
        dma::DMA1
            + if self.number < 4 {
                dma::LISR
            } else {
                dma::HISR
            }
    }

    /// Address of the flag clear register for this stream (LIFCR or HIFCR).
    pub const fn ifcr(self) -> u32 {
        dma::DMA1
            + if self.number < 4 {
                dma::LIFCR
            } else {
                dma::HIFCR
            }
    }

    /// `flags` (per-stream flag bits such as [`dma::TEIF`]) moved to this stream's position in
    /// its ISR/IFCR: streams 0/4 at bit 0, 1/5 at 6, 2/6 at 16, 3/7 at 22.
    pub const fn flags(self, flags: u32) -> u32 {
        flags << dma::FLAG_SHIFTS[(self.number % 4) as usize]
    }
}

/// Independent watchdog (RM0383 section 15.4), clocked by the LSI RC oscillator.
pub mod iwdg {
    /// IWDG_KR.
    pub const KR: u32 = 0x4000_3000;
    /// IWDG_PR: prescaler divider 4 · 2^PR (PR = 0..=6).
    pub const PR: u32 = 0x4000_3004;
    /// IWDG_RLR: 12-bit reload value.
    pub const RLR: u32 = 0x4000_3008;
    /// IWDG_SR.
    pub const SR: u32 = 0x4000_300C;
    /// KR key that unlocks PR and RLR.
    pub const KEY_UNLOCK: u32 = 0x5555;
    /// KR key that starts the watchdog.
    pub const KEY_START: u32 = 0xCCCC;
    /// KR key that reloads the counter ("feeds" the watchdog).
    pub const KEY_FEED: u32 = 0xAAAA;
    /// Largest reload value.
    pub const RLR_MAX: u32 = 0xFFF;
    /// Largest prescaler code (divider 256).
    pub const PR_MAX: u32 = 6;
    /// LSI frequency range over voltage and temperature (F411 datasheet DS10314, table
    /// "LSI oscillator characteristics"): 17 kHz min, 32 kHz typ, 47 kHz max.
    pub const LSI_HZ: (u32, u32, u32) = (17_000, 32_000, 47_000);
}

/// Debug MCU freeze register (RM0383 chapter 23, debug support).
pub mod dbgmcu {
    /// DBGMCU_APB1_FZ.
    pub const APB1_FZ: u32 = 0xE004_2008;
    /// DBG_IWDG_STOP: the watchdog stops while the core is halted by a debugger.
    pub const IWDG_STOP: u32 = 1 << 12;
}

/// Nested vectored interrupt controller (PM0214 section 4.3).
pub mod nvic {
    /// NVIC_ISER0: writing 1 to bit n enables interrupt n (zeros have no effect).
    pub const ISER0: u32 = 0xE000_E100;
    /// NVIC_ICER0: writing 1 to bit n disables interrupt n.
    pub const ICER0: u32 = 0xE000_E180;
    /// TIM2 global interrupt number (position 28 of the vector table, RM0383 chapter 10).
    pub const TIM2_IRQ: u32 = 28;
}
