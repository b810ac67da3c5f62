//! DMA1 as RM0383 chapter 9 (DMA controller) describes it, for memory-to-peripheral streams in
//! direct mode: the stream registers and which of them are locked while EN is 1 (DMA_SxCR,
//! SxNDTR, SxPAR, SxM0AR, SxFCR descriptions), enabling only with the stream's event flags
//! cleared (SxCR.EN note), the one-item preload of direct mode ("Direct mode"), NDTR counting
//! down one item per request and reloading in circular mode (SxNDTR: "If the value of this
//! register is zero, no transaction can be served even if the stream is enabled"), memory
//! increment, TCIF/HTIF, and a transfer error (TEIF) on a bus error, which also clears EN
//! ("Error management"). Disabling a stream takes effect once the item in flight is done: EN
//! reads 1 until then ("Stream disable").
//!
//! The request mapping is the part of RM0383 table 27 that reaches the modelled timers.
//! The FIFO, double buffering, bursts and peripheral-to-memory transfers are not modelled:
//! enabling a stream so configured is a violation.

use crate::regs::dma;

use super::timer::TimerId;

/// A request line into DMA1 from a modelled timer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RequestSource {
    /// TIMx_TRIG.
    Trigger(TimerId),
}

/// RM0383 table 27 (DMA1 request mapping), the entries carrying a modelled timer's trigger
/// request: (stream, channel) → source.
pub fn request_source(stream: usize, channel: u32) -> Option<RequestSource> {
    match (stream, channel) {
        (4, 5) => Some(RequestSource::Trigger(TimerId::Tim3)),
        (1, 6) | (3, 6) => Some(RequestSource::Trigger(TimerId::Tim5)),
        _ => None,
    }
}

/// SxCR bits outside the model: the interrupt enables DMEIE, TEIE, HTIE, TCIE (bits 1–4; the
/// model has no DMA interrupts), PFCTRL (5), PINCOS (15), CT (19).
const CR_UNMODELLED: u32 = 0b1_1111 << 1 | 1 << 15 | 1 << 19;
/// SxFCR.FEIE: FIFO error interrupt enable.
const FCR_FEIE: u32 = 1 << 7;

/// One stream's registers and internal state.
#[derive(Debug, Clone)]
pub struct Stream {
    /// SxCR as written (EN included while the stream runs).
    pub cr: u32,
    /// NDTR as programmed (the reload value).
    pub ndtr_programmed: u32,
    /// Items left in this cycle.
    pub ndtr: u32,
    /// SxPAR.
    pub par: u32,
    /// SxM0AR.
    pub m0ar: u32,
    /// SxFCR.
    pub fcr: u32,
    /// Address of the next memory item.
    pub memory_pointer: u32,
    /// The item fetched ahead in direct mode.
    pub preloaded: Option<u32>,
    /// EN was cleared while an item was in flight: EN reads 1 until this time.
    pub stopping_until: Option<u64>,
}

impl Default for Stream {
    fn default() -> Self {
        Self {
            cr: 0,
            ndtr_programmed: 0,
            ndtr: 0,
            par: 0,
            m0ar: 0,
            // Reset value 0x21: FS = 100 (FIFO empty), FTH = 01.
            fcr: 0x21,
            memory_pointer: 0,
            preloaded: None,
            stopping_until: None,
        }
    }
}

impl Stream {
    /// Whether the stream serves requests.
    pub fn enabled(&self) -> bool {
        self.cr & dma::CR_EN != 0 && self.stopping_until.is_none()
    }

    /// EN as software reads it at `now`.
    pub fn en_reads(&self, now: u64) -> bool {
        self.cr & dma::CR_EN != 0 || self.stopping_until.is_some_and(|until| now < until)
    }

    /// Item size in bytes (PSIZE: direct mode uses the peripheral size for both ports).
    pub fn item_bytes(&self) -> u32 {
        match (self.cr >> dma::CR_PSIZE_SHIFT) & 0b11 {
            0b00 => 1,
            0b01 => 2,
            _ => 4,
        }
    }

    /// The request channel (CHSEL).
    pub fn channel(&self) -> u32 {
        (self.cr >> dma::CR_CHSEL_SHIFT) & 0b111
    }

    /// Priority level (PL).
    pub fn priority(&self) -> u32 {
        (self.cr >> 16) & 0b11
    }

    /// Configuration problems that make enabling the stream leave the modelled ground.
    pub fn unmodelled_configuration(&self) -> Option<&'static str> {
        let size = |shift: u32| (self.cr >> shift) & 0b11;
        if self.fcr & dma::FCR_DMDIS != 0 {
            Some("FIFO mode (DMDIS = 1)")
        } else if self.cr & dma::CR_DIR_MASK != dma::CR_DIR_M2P {
            Some("a direction other than memory-to-peripheral")
        } else if size(dma::CR_MSIZE_SHIFT) != size(dma::CR_PSIZE_SHIFT) {
            Some("MSIZE different from PSIZE in direct mode")
        } else if size(dma::CR_PSIZE_SHIFT) == 0b11 {
            Some("a reserved data size")
        } else if self.cr & (dma::CR_DBM | dma::CR_BURST_MASK | dma::CR_PINC) != 0 {
            Some("double buffering, bursts or peripheral increment")
        } else if self.cr & CR_UNMODELLED != 0 || self.fcr & FCR_FEIE != 0 {
            Some("stream interrupts, the peripheral as flow controller, PINCOS or CT")
        } else {
            None
        }
    }
}

/// The controller: eight streams and their flags.
#[derive(Debug, Clone, Default)]
pub struct Dma {
    /// Streams 0..=7.
    pub streams: [Stream; 8],
    /// LISR, HISR.
    pub isr: [u32; 2],
    /// The controller is moving an item until this time.
    pub busy_until: u64,
    /// Stream of the item in flight.
    pub last_stream: Option<usize>,
}

impl Dma {
    /// Event flags of stream `s`, in its own bit positions (FEIF at bit 0 … TCIF at bit 5).
    pub fn flags(&self, s: usize) -> u32 {
        let shift = [0, 6, 16, 22][s % 4];
        (self.isr[s / 4] >> shift) & dma::ALL_FLAGS
    }

    /// Sets `flags` (own bit positions) of stream `s`.
    pub fn raise(&mut self, s: usize, flags: u32) {
        let shift = [0, 6, 16, 22][s % 4];
        self.isr[s / 4] |= flags << shift;
    }
}
