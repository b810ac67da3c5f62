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

#[cfg(test)]
mod tests {
    use super::*;

    /// Word and half-word memory that logs every access in order.
    #[derive(Default)]
    struct Memory {
        words: std::collections::BTreeMap<u32, u32>,
        log: std::vec::Vec<(&'static str, u32, u32)>,
        /// Reads of this address return the value with these bits set, `sticky` times.
        sticky: Option<(u32, u32, u32)>,
    }

    impl Bus for Memory {
        fn read(&mut self, addr: u32) -> u32 {
            let mut value = self.words.get(&addr).copied().unwrap_or(0);
            if let Some((at, bits, left)) = self.sticky
                && at == addr
                && left > 0
            {
                value |= bits;
                self.sticky = Some((at, bits, left - 1));
            }
            self.log.push(("read", addr, value));
            value
        }
        fn write(&mut self, addr: u32, value: u32) {
            self.log.push(("write", addr, value));
            self.words.insert(addr, value);
        }
        fn read16(&mut self, addr: u32) -> u16 {
            let word = self.words.get(&(addr & !3)).copied().unwrap_or(0);
            let value = (word >> (8 * (addr & 2))) as u16;
            self.log.push(("read16", addr, u32::from(value)));
            value
        }
        fn write16(&mut self, addr: u32, value: u16) {
            self.log.push(("write16", addr, u32::from(value)));
        }
        fn fence(&mut self) {
            self.log.push(("fence", 0, 0));
        }
    }

    #[test]
    fn read_modify_write_steps_keep_the_other_bits() {
        let mut bus = Memory::default();
        bus.words.insert(0x10, 0b1010);
        let steps = [
            Step::SetBits {
                addr: 0x10,
                bits: 0b0101,
            },
            Step::ClearBits {
                addr: 0x10,
                bits: 0b0011,
            },
            Step::Write {
                addr: 0x20,
                value: 7,
            },
            Step::Fence,
        ];
        assert_eq!(run(&steps, &mut bus), Ok(()));
        assert_eq!(bus.words[&0x10], 0b1100);
        assert_eq!(bus.words[&0x20], 7);
        assert_eq!(bus.log.last(), Some(&("fence", 0, 0)));
    }

    #[test]
    fn wait_clear_polls_until_clear_or_gives_up_and_goes_on() {
        // Clears after 3 reads: 4 polls suffice.
        let mut bus = Memory {
            sticky: Some((0x30, 1, 3)),
            ..Memory::default()
        };
        let wait = |polls| Step::WaitClear {
            addr: 0x30,
            mask: 1,
            polls,
        };
        assert_eq!(run(&[wait(4)], &mut bus), Ok(()));
        assert_eq!(bus.log.len(), 4);
        // Never clears within 5 polls: an error, and the later steps still run.
        let mut bus = Memory {
            sticky: Some((0x30, 1, 100)),
            ..Memory::default()
        };
        let steps = [
            wait(5),
            Step::Write {
                addr: 0x40,
                value: 1,
            },
            wait(2),
        ];
        assert_eq!(
            run(&steps, &mut bus),
            Err(StepError::StillSet {
                addr: 0x30,
                mask: 1
            })
        );
        assert_eq!(bus.log.iter().filter(|e| e.0 == "read").count(), 7);
        assert_eq!(bus.words[&0x40], 1);
        // Bits outside the mask do not count; 0 polls still reads once.
        let mut bus = Memory::default();
        bus.words.insert(0x30, 0b10);
        assert_eq!(run(&[wait(0)], &mut bus), Ok(()));
        assert_eq!(bus.log.len(), 1);
    }

    #[test]
    fn copy_reads_at_the_item_width() {
        let mut bus = Memory::default();
        bus.words.insert(0x100, 0x0002_0001);
        let steps = [
            Step::Copy {
                src: 0x102,
                dst: 0x200,
                bytes: 2,
            },
            Step::Copy {
                src: 0x100,
                dst: 0x204,
                bytes: 4,
            },
        ];
        assert_eq!(run(&steps, &mut bus), Ok(()));
        assert_eq!(bus.words[&0x200], 2);
        assert_eq!(bus.words[&0x204], 0x0002_0001);
        assert_eq!(bus.log[0].0, "read16");
        assert_eq!(bus.log[2].0, "read");
    }

    #[test]
    fn plans_hold_their_steps_in_order() {
        let mut plan = Plan::default();
        assert!(plan.steps().is_empty());
        plan.write(1, 2);
        let mut other = Plan::new();
        other.push(Step::Fence);
        other.write(3, 4);
        plan.extend(&other);
        assert_eq!(
            plan.steps(),
            [
                Step::Write { addr: 1, value: 2 },
                Step::Fence,
                Step::Write { addr: 3, value: 4 }
            ]
        );
    }
}
