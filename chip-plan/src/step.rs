//! A register plan as plain data ([`Step`], [`Plan`]) and the one interpreter that carries it out
//! over a [`Bus`]: the board's memory-mapped registers, or the host's register model.
//!
//! A plan is a short list of register accesses with nothing computed at run time except what a
//! step says to read. Both the firmware and the tests run plans through [`run`], so what the
//! model executes is exactly what the board does.

/// One register access of a plan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Step {
    /// Write `value` to the 32-bit register at `addr`.
    Write {
        /// Register address.
        addr: u32,
        /// Value written.
        value: u32,
    },
    /// Read-modify-write: set `bits` in a register shared with code outside the plan (RCC).
    SetBits {
        /// Register address.
        addr: u32,
        /// Bits set.
        bits: u32,
    },
    /// Read-modify-write: clear `bits` in a register.
    ClearBits {
        /// Register address.
        addr: u32,
        /// Bits cleared.
        bits: u32,
    },
    /// Read `addr` until `value & mask == 0`, at most `polls` times; gives up with
    /// [`StepError::StillSet`] (the remaining steps still run).
    WaitClear {
        /// Register address.
        addr: u32,
        /// Bits that must read 0.
        mask: u32,
        /// Largest number of reads.
        polls: u32,
    },
    /// Copy a data item from memory (`src`, `bytes` = 2 or 4 wide) into the 32-bit register
    /// `dst` (the interrupt fallback's compare-value copy).
    Copy {
        /// Memory address of the item.
        src: u32,
        /// Register address.
        dst: u32,
        /// Item width in bytes (2 or 4).
        bytes: u8,
    },
    /// Full memory barrier (`fence(SeqCst)`, a DMB on Cortex-M): every memory access before it
    /// completes before any after it. Placed where a buffer changes hands between CPU and DMA.
    Fence,
}

/// Why a plan did not complete cleanly.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StepError {
    /// A [`Step::WaitClear`] gave up: the bits were still set after every poll.
    StillSet {
        /// Register polled.
        addr: u32,
        /// Bits that stayed set.
        mask: u32,
    },
}

/// Memory-mapped access as the plan needs it.
pub trait Bus {
    /// Reads the 32-bit word at `addr`.
    fn read(&mut self, addr: u32) -> u32;
    /// Writes the 32-bit word at `addr`.
    fn write(&mut self, addr: u32, value: u32);
    /// Reads the 16-bit half-word at `addr` (memory only).
    fn read16(&mut self, addr: u32) -> u16;
    /// Writes the 16-bit half-word at `addr` (memory only).
    fn write16(&mut self, addr: u32, value: u16);
    /// Memory barrier: see [`Step::Fence`].
    fn fence(&mut self);
}

/// Capacity of a [`Plan`]: the longest plan (halt with both banks re-initialised) has 42 steps.
pub const PLAN_CAPACITY: usize = 64;

/// An ordered list of [`Step`]s.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Plan {
    steps: [Step; PLAN_CAPACITY],
    len: usize,
}

impl Default for Plan {
    fn default() -> Self {
        Self::new()
    }
}

impl Plan {
    /// An empty plan.
    pub const fn new() -> Self {
        Self {
            steps: [Step::Fence; PLAN_CAPACITY],
            len: 0,
        }
    }

    /// Appends a step. Plans are built by this crate's functions whose lengths the tests pin,
    /// so running out of capacity is a bug, not a run-time condition.
    pub fn push(&mut self, step: Step) {
        assert!(self.len < PLAN_CAPACITY, "register plan over capacity");
        self.steps[self.len] = step;
        self.len += 1;
    }

    /// Appends `Write { addr, value }`.
    pub fn write(&mut self, addr: u32, value: u32) {
        self.push(Step::Write { addr, value });
    }

    /// Appends every step of `other`.
    pub fn extend(&mut self, other: &Plan) {
        for &step in other.steps() {
            self.push(step);
        }
    }

    /// The steps in order.
    pub fn steps(&self) -> &[Step] {
        &self.steps[..self.len]
    }
}

/// Carries out `steps` in order on `bus`. A [`Step::WaitClear`] that gives up does not stop the
/// plan (a halt must still switch the outputs off); the first such failure is returned.
pub fn run<B: Bus + ?Sized>(steps: &[Step], bus: &mut B) -> Result<(), StepError> {
    let mut first_error = None;
    for step in steps {
        match *step {
            Step::Write { addr, value } => bus.write(addr, value),
            Step::SetBits { addr, bits } => {
                let value = bus.read(addr);
                bus.write(addr, value | bits);
            }
            Step::ClearBits { addr, bits } => {
                let value = bus.read(addr);
                bus.write(addr, value & !bits);
            }
            Step::WaitClear { addr, mask, polls } => {
                let mut cleared = false;
                for _ in 0..polls.max(1) {
                    if bus.read(addr) & mask == 0 {
                        cleared = true;
                        break;
                    }
                }
                if !cleared && first_error.is_none() {
                    first_error = Some(StepError::StillSet { addr, mask });
                }
            }
            Step::Copy { src, dst, bytes } => {
                let value = if bytes == 2 {
                    u32::from(bus.read16(src))
                } else {
                    bus.read(src)
                };
                bus.write(dst, value);
            }
            Step::Fence => bus.fence(),
        }
    }
    first_error.map_or(Ok(()), Err)
}
