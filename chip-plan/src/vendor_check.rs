//! Every encoding in [`crate::regs`] and [`crate::outputs`] against a second, independent source:
//! the STM32F411CE metadata of stm32-metapac (register blocks, fields and enumerations generated
//! from ST's SVD files, the memory map, RCC bits, interrupts, pins and DMA requests; the data
//! embassy-stm32 is generated from), at the version `Cargo.lock` pins for the firmware. The NVIC,
//! a Cortex-M core peripheral that the vendor metadata does not describe, is checked against the
//! `cortex-m` crate's register block.
//!
//! Names are looked up as the metadata spells them (register `cr1`, field `opm`, enumeration
//! variant `PWM_MODE1`); a name that is not found fails the test with the names that exist.

use stm32_metapac::metadata::ir::{Array, BitOffset, Block, BlockItemInner, FieldSet, IR};
use stm32_metapac::metadata::{METADATA, MemoryRegionKind, Peripheral};

use crate::outputs::{BANKS, Bank, LED_OUTPUTS, SLOTS};
use crate::regs::{self, DmaStream, GpTimer, dbgmcu, dma, iwdg, nvic, rcc, tim};

/// Case- and underscore-insensitive name comparison (the metadata names a block `TIM_GP32` in
/// one place and `TimGp32` in another).
fn same(a: &str, b: &str) -> bool {
    let key = |s: &str| {
        s.chars()
            .filter(|&c| c != '_')
            .map(|c| c.to_ascii_lowercase())
            .collect::<String>()
    };
    key(a) == key(b)
}

fn peripheral(name: &str) -> &'static Peripheral {
    METADATA
        .peripherals
        .iter()
        .find(|p| p.name == name)
        .unwrap_or_else(|| panic!("STM32F411CE has no peripheral {name}"))
}

/// Base address of a peripheral.
fn base(name: &str) -> u32 {
    u32::try_from(peripheral(name).address).expect("32-bit address")
}

fn ir_of(name: &str) -> (&'static IR, &'static str) {
    let registers = peripheral(name)
        .registers
        .as_ref()
        .unwrap_or_else(|| panic!("{name} has no register description"));
    (registers.ir, registers.block)
}

fn block(ir: &'static IR, name: &str) -> &'static Block {
    ir.blocks
        .iter()
        .find(|b| same(b.name, name))
        .unwrap_or_else(|| panic!("no register block {name}"))
}

/// Byte offset (of element `index` when the item is an array), the register's field set and
/// the block it leads to, for item `path[0]` of `block`, then `path[1]` inside it, and so on.
fn locate(ir: &'static IR, block_name: &str, path: &[(&str, u32)]) -> (u32, Option<&'static str>) {
    let mut current = block(ir, block_name);
    let mut offset = 0;
    let mut fieldset = None;
    for &(name, index) in path {
        let item = current
            .items
            .iter()
            .find(|i| same(i.name, name))
            .unwrap_or_else(|| {
                let names: Vec<_> = current.items.iter().map(|i| i.name).collect();
                panic!("block {} has no {name}; it has {names:?}", current.name)
            });
        offset += item.byte_offset
            + match item.array {
                None => {
                    assert_eq!(index, 0, "{name} is not an array");
                    0
                }
                Some(Array::Regular(ref a)) => {
                    assert!(index < a.len, "{name}[{index}] out of range");
                    index * a.stride
                }
                Some(Array::Cursed(ref a)) => a.offsets[index as usize],
            };
        match item.inner {
            BlockItemInner::Block(ref b) => current = block(ir, b.block),
            BlockItemInner::Register(ref r) => fieldset = r.fieldset,
        }
    }
    (offset, fieldset)
}

/// Address of register `path` of peripheral `name`.
fn address(name: &str, path: &[(&str, u32)]) -> u32 {
    let (ir, block_name) = ir_of(name);
    base(name) + locate(ir, block_name, path).0
}

/// Offset of register `reg` (not an array) within peripheral `name`.
fn offset(name: &str, reg: &str) -> u32 {
    address(name, &[(reg, 0)]) - base(name)
}

fn fieldset(ir: &'static IR, name: &str) -> &'static FieldSet {
    ir.fieldsets
        .iter()
        .find(|f| same(f.name, name))
        .unwrap_or_else(|| panic!("no field set {name}"))
}

/// Position, width and enumeration of field `field` (element `index`) of register `path`.
/// A field whose bits are split keeps its lowest run: the only one the F411 implements.
fn field_of(name: &str, path: &[(&str, u32)], field: &str, index: u32) -> (u32, u32, &'static str) {
    let (ir, block_name) = ir_of(name);
    let set_name = locate(ir, block_name, path)
        .1
        .unwrap_or_else(|| panic!("{name} {path:?} has no fields"));
    let set = fieldset(ir, set_name);
    let f = set
        .fields
        .iter()
        .find(|f| same(f.name, field))
        .unwrap_or_else(|| {
            let names: Vec<_> = set.fields.iter().map(|f| f.name).collect();
            panic!("{name} {path:?} has no field {field}; it has {names:?}")
        });
    let (low, width) = match f.bit_offset {
        BitOffset::Regular(ref r) => (r.offset, f.bit_size),
        BitOffset::Cursed(ref c) => (
            *c.ranges[0].start(),
            c.ranges[0].end() - c.ranges[0].start() + 1,
        ),
    };
    let element = match f.array {
        None => {
            assert_eq!(index, 0, "{field} is not an array");
            0
        }
        Some(Array::Regular(ref a)) => {
            assert!(index < a.len, "{field}[{index}] out of range");
            index * a.stride
        }
        Some(Array::Cursed(ref a)) => a.offsets[index as usize],
    };
    (low + element, width, f.enumm.unwrap_or(""))
}

/// The bits of field `field` (element `index`) of register `reg` of peripheral `name`.
fn mask(name: &str, reg: &str, field: &str, index: u32) -> u32 {
    let (shift, width, _) = field_of(name, &[(reg, 0)], field, index);
    (((1u64 << width) - 1) << shift) as u32
}

/// Bit position of field `field` (element `index`).
fn shift(name: &str, reg: &str, field: &str, index: u32) -> u32 {
    field_of(name, &[(reg, 0)], field, index).0
}

/// The value of enumeration variant `variant` of the field, unshifted.
fn variant(name: &str, reg: &str, field: &str, variant: &str) -> u32 {
    let (ir, _) = ir_of(name);
    let enum_name = field_of(name, &[(reg, 0)], field, 0).2;
    let e = ir
        .enums
        .iter()
        .find(|e| same(e.name, enum_name))
        .unwrap_or_else(|| panic!("{name}.{reg}.{field} has no enumeration"));
    let v = e
        .variants
        .iter()
        .find(|v| v.name == variant)
        .unwrap_or_else(|| {
            let names: Vec<_> = e.variants.iter().map(|v| v.name).collect();
            panic!("{} has no {variant}; it has {names:?}", e.name)
        });
    u32::try_from(v.value).expect("small value")
}

/// The field `field` of `reg` set to enumeration variant `name`, shifted into place.
fn field_value(periph: &str, reg: &str, field: &str, index: u32, name: &str) -> u32 {
    variant(periph, reg, field, name) << shift(periph, reg, field, index)
}

/// The metadata's name of a bank's timer.
fn timer_name(bank: Bank) -> &'static str {
    match bank {
        Bank::Tim3 => "TIM3",
        Bank::Tim5 => "TIM5",
    }
}

#[test]
fn vendor_base_addresses_and_memory_map() {
    let timers = [
        ("TIM2", regs::TIM2),
        ("TIM3", regs::TIM3),
        ("TIM5", regs::TIM5),
    ];
    for (name, timer) in timers {
        assert_eq!(timer.base, base(name), "{name} base");
    }
    for bank in BANKS {
        assert_eq!(bank.timer().base, base(timer_name(bank)), "{bank:?} timer");
    }
    assert_eq!(dma::DMA1, base("DMA1"), "DMA1 base");
    assert_eq!(iwdg::KR, base("IWDG") + offset("IWDG", "kr"), "IWDG_KR");
    assert_eq!(iwdg::PR, base("IWDG") + offset("IWDG", "pr"), "IWDG_PR");
    assert_eq!(iwdg::RLR, base("IWDG") + offset("IWDG", "rlr"), "IWDG_RLR");
    assert_eq!(iwdg::SR, base("IWDG") + offset("IWDG", "sr"), "IWDG_SR");
    assert_eq!(
        rcc::APB1RSTR,
        address("RCC", &[("apb1rstr", 0)]),
        "RCC_APB1RSTR"
    );
    assert_eq!(
        rcc::AHB1ENR,
        address("RCC", &[("ahb1enr", 0)]),
        "RCC_AHB1ENR"
    );
    assert_eq!(
        rcc::APB1ENR,
        address("RCC", &[("apb1enr", 0)]),
        "RCC_APB1ENR"
    );
    assert_eq!(
        dbgmcu::APB1_FZ,
        address("DBGMCU", &[("apb1fzr", 0)]),
        "DBGMCU_APB1_FZ"
    );
    let sram = METADATA.memory[0]
        .iter()
        .find(|m| m.kind == MemoryRegionKind::Ram && m.name == "SRAM")
        .expect("SRAM region");
    assert_eq!(regs::SRAM, sram.address..sram.address + sram.size, "SRAM");
    // Neighbouring timers are one register block apart; the block holds every register.
    assert_eq!(base("TIM3") - base("TIM2"), tim::BLOCK);
    assert_eq!(base("TIM5") - base("TIM4"), tim::BLOCK);
    assert!(offset("TIM5", "dmar") < tim::BLOCK);
}

#[test]
fn vendor_rcc_bits_of_every_peripheral_the_plan_clocks_or_resets() {
    let rcc_bit = |periph: &str, reset: bool| {
        let info = peripheral(periph).rcc.as_ref().expect("RCC entry");
        let reg = if reset { &info.reset } else { &info.enable };
        let reg = reg.as_ref().expect("RCC bit");
        let expected = if reset { "APB1RSTR" } else { "APB1ENR" };
        if periph != "DMA1" {
            assert_eq!(reg.register, expected, "{periph}");
        }
        mask("RCC", reg.register, reg.field, 0)
    };
    for (periph, bit) in [
        ("TIM2", rcc::TIM2),
        ("TIM3", rcc::TIM3),
        ("TIM4", rcc::TIM4),
        ("TIM5", rcc::TIM5),
    ] {
        assert_eq!(bit, rcc_bit(periph, false), "{periph} enable bit");
        assert_eq!(bit, rcc_bit(periph, true), "{periph} reset bit");
    }
    let dma1 = peripheral("DMA1")
        .rcc
        .as_ref()
        .unwrap()
        .enable
        .as_ref()
        .unwrap();
    assert_eq!(dma1.register, "AHB1ENR");
    assert_eq!(rcc::DMA1EN, mask("RCC", "ahb1enr", dma1.field, 0), "DMA1EN");
}

#[test]
fn vendor_timer_offsets_fields_and_values() {
    for timer in ["TIM2", "TIM3", "TIM5"] {
        for (name, ours) in [
            ("cr1", tim::CR1),
            ("cr2", tim::CR2),
            ("smcr", tim::SMCR),
            ("dier", tim::DIER),
            ("sr", tim::SR),
            ("egr", tim::EGR),
            ("ccer", tim::CCER),
            ("cnt", tim::CNT),
            ("psc", tim::PSC),
            ("arr", tim::ARR),
            ("dcr", tim::DCR),
            ("dmar", tim::DMAR),
        ] {
            assert_eq!(ours, offset(timer, name), "{timer} {name} offset");
        }
        let ccmr = |i: u32| address(timer, &[("ccmr_output", i)]) - base(timer);
        assert_eq!(tim::CCMR1, ccmr(0), "{timer} CCMR1");
        assert_eq!(tim::CCMR2, ccmr(1), "{timer} CCMR2");
        let t = GpTimer { base: base(timer) };
        for channel in 1..=4u8 {
            let ccr = address(timer, &[("ccr", u32::from(channel) - 1)]);
            assert_eq!(t.ccr(channel), ccr, "{timer} CCR{channel}");
        }
    }
    let t = "TIM2";
    assert_eq!(tim::CR1_CEN, mask(t, "cr1", "cen", 0));
    assert_eq!(tim::CR1_UDIS, mask(t, "cr1", "udis", 0));
    assert_eq!(tim::CR1_URS, mask(t, "cr1", "urs", 0));
    assert_eq!(tim::CR1_OPM, mask(t, "cr1", "opm", 0));
    assert_eq!(
        tim::CR1_DIR_CMS_MASK,
        mask(t, "cr1", "dir", 0) | mask(t, "cr1", "cms", 0)
    );
    assert_eq!(tim::CR1_ARPE, mask(t, "cr1", "arpe", 0));
    assert_eq!(tim::CR1_CKD_MASK, mask(t, "cr1", "ckd", 0));
    assert_eq!(tim::CR2_MMS_SHIFT, shift(t, "cr2", "mms", 0));
    assert_eq!(tim::CR2_MMS_MASK, mask(t, "cr2", "mms", 0));
    assert_eq!(
        tim::CR2_MMS_UPDATE,
        field_value(t, "cr2", "mms", 0, "UPDATE")
    );
    assert_eq!(tim::SMCR_SMS_MASK, mask(t, "smcr", "sms", 0));
    assert_eq!(
        tim::SMCR_SMS_RESET,
        field_value(t, "smcr", "sms", 0, "RESET_MODE")
    );
    assert_eq!(tim::SMCR_TS_SHIFT, shift(t, "smcr", "ts", 0));
    assert_eq!(tim::SMCR_TS_MASK, mask(t, "smcr", "ts", 0));
    assert_eq!(tim::DIER_UIE, mask(t, "dier", "uie", 0));
    assert_eq!(tim::DIER_UDE, mask(t, "dier", "ude", 0));
    let ccde = (0..4).fold(0, |m, i| m | mask(t, "dier", "ccde", i));
    assert_eq!(tim::DIER_CCDE_MASK, ccde);
    assert_eq!(tim::DIER_TDE, mask(t, "dier", "tde", 0));
    assert_eq!(tim::SR_UIF, mask(t, "sr", "uif", 0));
    assert_eq!(tim::SR_TIF, mask(t, "sr", "tif", 0));
    assert_eq!(tim::EGR_UG, mask(t, "egr", "ug", 0));
    // CCMRx in output mode: channel fields one byte apart.
    let ccmr = |field: &str, i: u32| field_of(t, &[("ccmr_output", 0)], field, i);
    assert_eq!(tim::OCM_SHIFT, ccmr("ocm", 0).0);
    assert_eq!(ccmr("ocm", 0).1, 3, "OCxM width");
    assert_eq!(
        tim::CCMR_CHANNEL_STRIDE,
        ccmr("ocm", 1).0 - ccmr("ocm", 0).0
    );
    assert_eq!(tim::OCPE, 1 << ccmr("ocpe", 0).0);
    let (ir, _) = ir_of(t);
    let ocm = ir
        .enums
        .iter()
        .find(|e| same(e.name, ccmr("ocm", 0).2))
        .unwrap();
    let pwm1 = ocm.variants.iter().find(|v| v.name == "PWM_MODE1").unwrap();
    assert_eq!(u64::from(tim::OCM_PWM1), pwm1.value, "PWM mode 1");
    // The plan's composite values, built field by field from the vendor's positions.
    let pair = (0..2).fold(0, |v, i| {
        v | (pwm1.value as u32) << ccmr("ocm", i).0 | 1 << ccmr("ocpe", i).0
    });
    assert_eq!(tim::ccmr_pwm1_preload_pair(), pair);
    assert_eq!(tim::CCE, mask(t, "ccer", "cce", 0));
    assert_eq!(tim::CCP, mask(t, "ccer", "ccp", 0));
    assert_eq!(tim::CCER_CHANNEL_STRIDE, shift(t, "ccer", "cce", 1));
    let enabled = (0..4).fold(0, |v, i| v | mask(t, "ccer", "cce", i));
    assert_eq!(tim::ccer_all_enabled(), enabled);
    assert_eq!(tim::DCR_DBL_SHIFT, shift(t, "dcr", "dbl", 0));
    assert_eq!(mask(t, "dcr", "dba", 0), 0x1F);
    assert_eq!(mask(t, "dcr", "dbl", 0), 0x1F << tim::DCR_DBL_SHIFT);
    let burst = (tim::CCR1 / 4) << shift(t, "dcr", "dba", 0)
        | (SLOTS as u32 - 1) << shift(t, "dcr", "dbl", 0);
    assert_eq!(tim::dcr(tim::CCR1, SLOTS as u32), burst);
}

#[test]
fn vendor_internal_trigger_selection_values() {
    // The trigger selection codes the plan writes are ITRn's codes (n = the code).
    for bank in BANKS {
        let itr = bank.tim2_trigger();
        let name = format!("ITR{itr}");
        let code = match itr {
            // ITR0 is the field's zero value, named after the field in the metadata.
            0 => 0,
            _ => variant("TIM2", "smcr", "ts", &name),
        };
        assert_eq!(itr, code, "{bank:?} trigger {name}");
    }
}

#[test]
fn vendor_dma_offsets_fields_and_values() {
    let d = "DMA1";
    assert_eq!(dma::LISR, offset(d, "isr"));
    assert_eq!(dma::LIFCR, offset(d, "ifcr"));
    assert_eq!(dma::HISR, address(d, &[("isr", 1)]) - base(d), "HISR");
    assert_eq!(dma::HIFCR, address(d, &[("ifcr", 1)]) - base(d), "HIFCR");
    for number in 0..8u8 {
        let stream = DmaStream { number };
        let n = u32::from(number);
        let at = |reg: &str| address(d, &[("st", n), (reg, 0)]);
        assert_eq!(stream.cr(), at("cr"), "S{number}CR");
        assert_eq!(stream.ndtr(), at("ndtr"), "S{number}NDTR");
        assert_eq!(stream.par(), at("par"), "S{number}PAR");
        assert_eq!(stream.m0ar(), at("m0ar"), "S{number}M0AR");
        assert_eq!(stream.fcr(), at("fcr"), "S{number}FCR");
        assert_eq!(
            stream.isr(),
            address(d, &[("isr", n / 4)]),
            "stream {number} ISR"
        );
        assert_eq!(
            stream.ifcr(),
            address(d, &[("ifcr", n / 4)]),
            "stream {number} IFCR"
        );
        let isr_bits = |field: &str| field_of(d, &[("isr", n / 4)], field, n % 4).0;
        for (flag, field) in [
            (dma::FEIF, "feif"),
            (dma::DMEIF, "dmeif"),
            (dma::TEIF, "teif"),
            (dma::HTIF, "htif"),
            (dma::TCIF, "tcif"),
        ] {
            assert_eq!(
                stream.flags(flag),
                1 << isr_bits(field),
                "stream {number} {field}"
            );
            let clear = field_of(d, &[("ifcr", n / 4)], field, n % 4).0;
            assert_eq!(
                stream.flags(flag),
                1 << clear,
                "stream {number} clear {field}"
            );
        }
    }
    assert_eq!(dma::S0CR, offset(d, "st"));
    assert_eq!(
        dma::STREAM_STRIDE,
        address(d, &[("st", 1)]) - address(d, &[("st", 0)]),
        "stream stride"
    );
    let cr = |field: &str| field_of(d, &[("st", 0), ("cr", 0)], field, 0);
    let bits = |field: &str| {
        let (s, w, _) = cr(field);
        (((1u64 << w) - 1) << s) as u32
    };
    let (ir, _) = ir_of(d);
    let value = |field: &str, name: &str| {
        let (s, _, enum_name) = cr(field);
        let e = ir.enums.iter().find(|e| same(e.name, enum_name)).unwrap();
        let v = e
            .variants
            .iter()
            .find(|v| v.name == name)
            .unwrap_or_else(|| {
                let names: Vec<_> = e.variants.iter().map(|v| v.name).collect();
                panic!("{} has no {name}: {names:?}", e.name)
            });
        (v.value as u32) << s
    };
    assert_eq!(dma::CR_EN, bits("en"));
    assert_eq!(dma::CR_TEIE, bits("teie"));
    assert_eq!(dma::CR_DIR_MASK, bits("dir"));
    assert_eq!(dma::CR_DIR_M2P, value("dir", "MEMORY_TO_PERIPHERAL"));
    assert_eq!(dma::CR_CIRC, bits("circ"));
    assert_eq!(dma::CR_PINC, bits("pinc"));
    assert_eq!(dma::CR_MINC, bits("minc"));
    assert_eq!(dma::CR_PSIZE_SHIFT, cr("psize").0);
    assert_eq!(dma::CR_MSIZE_SHIFT, cr("msize").0);
    for (bytes, name) in [(1, "BITS8"), (2, "BITS16"), (4, "BITS32")] {
        assert_eq!(
            dma::size_code(bytes) << dma::CR_PSIZE_SHIFT,
            value("psize", name),
            "{bytes}-byte items"
        );
    }
    assert_eq!(dma::CR_PL_SHIFT, cr("pl").0);
    assert_eq!(dma::CR_PL_VERY_HIGH, value("pl", "VERY_HIGH"));
    assert_eq!(dma::CR_DBM, bits("dbm"));
    assert_eq!(dma::CR_BURST_MASK, bits("pburst") | bits("mburst"));
    assert_eq!(dma::CR_CHSEL_SHIFT, cr("chsel").0);
    assert!(cr("chsel").1 >= 3, "CHSEL holds channels 0–7");
    let fcr = field_of(d, &[("st", 0), ("fcr", 0)], "dmdis", 0);
    assert_eq!(dma::FCR_DMDIS, 1 << fcr.0);
    let every_flag = ["feif", "dmeif", "teif", "htif", "tcif"]
        .iter()
        .fold(0, |m, f| m | 1 << field_of(d, &[("isr", 0)], f, 0).0);
    assert_eq!(dma::ALL_FLAGS, every_flag, "a stream's five event flags");
    let shifts: Vec<u32> = (0..4)
        .map(|i| field_of(d, &[("isr", 0)], "feif", i).0)
        .collect();
    assert_eq!(dma::FLAG_SHIFTS.to_vec(), shifts);
}

#[test]
fn vendor_iwdg_dbgmcu_and_interrupt_encodings() {
    let key = |name: &str| variant("IWDG", "kr", "key", name);
    assert_eq!(iwdg::KEY_UNLOCK, key("ENABLE"), "IWDG unlock key");
    assert_eq!(iwdg::KEY_START, key("START"), "IWDG start key");
    assert_eq!(iwdg::KEY_FEED, key("RESET"), "IWDG reload key");
    assert_eq!(iwdg::RLR_MAX, mask("IWDG", "rlr", "rl", 0), "RLR width");
    assert_eq!(
        iwdg::PR_MAX,
        variant("IWDG", "pr", "pr", "DIVIDE_BY256"),
        "divider 256"
    );
    assert_eq!(
        dbgmcu::IWDG_STOP,
        mask("DBGMCU", "apb1fzr", "iwdg", 0),
        "DBG_IWDG_STOP"
    );
    let tim2_irq = METADATA
        .interrupts
        .iter()
        .find(|i| i.name == "TIM2")
        .expect("TIM2 interrupt");
    assert_eq!(nvic::TIM2_IRQ, tim2_irq.number, "TIM2 interrupt number");
    // The NVIC is the core's, not ST's: from the Cortex-M register block.
    use cortex_m::peripheral::{NVIC, nvic::RegisterBlock};
    let nvic_base = NVIC::PTR as usize;
    let iser0 = nvic_base + core::mem::offset_of!(RegisterBlock, iser);
    let icer0 = nvic_base + core::mem::offset_of!(RegisterBlock, icer);
    assert_eq!(nvic::ISER0 as usize, iser0, "NVIC_ISER0");
    assert_eq!(nvic::ICER0 as usize, icer0, "NVIC_ICER0");
}

#[test]
fn vendor_led_pins_channels_and_alternate_functions() {
    for (i, led) in LED_OUTPUTS.iter().enumerate() {
        let timer = peripheral(timer_name(led.bank));
        let signal = format!("CH{}", led.channel);
        let pin = timer
            .pins
            .iter()
            .find(|p| p.pin == led.pin && p.signal == signal)
            .unwrap_or_else(|| {
                let pins: Vec<_> = timer.pins.iter().map(|p| (p.pin, p.signal)).collect();
                panic!(
                    "LED {}: {} is not {} {signal}; its pins are {pins:?}",
                    i + 1,
                    led.pin,
                    timer.name
                )
            });
        assert_eq!(Some(led.af), pin.af, "LED {} alternate function", i + 1);
    }
}

#[test]
fn vendor_dma_request_map_of_the_chip_triggers() {
    for bank in BANKS {
        let timer = peripheral(timer_name(bank));
        let channel = format!("DMA1_CH{}", bank.stream().number);
        let found = timer.dma_channels.iter().any(|c| {
            c.signal == "TRIG"
                && c.channel == Some(channel.as_str())
                && c.request == Some(bank.request_channel())
        });
        assert!(
            found,
            "{bank:?}: {} TRIG is not on {channel} request {}",
            timer.name,
            bank.request_channel()
        );
    }
    // The register model's request map: exactly the modelled timers' TRIG requests on DMA1.
    use crate::register_model::dma::{RequestSource, request_source};
    use crate::register_model::timer::TimerId;
    for stream in 0..8usize {
        for request in 0..8u32 {
            let channel = format!("DMA1_CH{stream}");
            let vendor = [
                ("TIM3", TimerId::Tim3),
                ("TIM5", TimerId::Tim5),
                ("TIM2", TimerId::Tim2),
            ]
            .into_iter()
            .find(|(name, _)| {
                peripheral(name).dma_channels.iter().any(|c| {
                    c.signal == "TRIG"
                        && c.channel == Some(channel.as_str())
                        && c.request == Some(request)
                })
            })
            .map(|(_, id)| RequestSource::Trigger(id));
            assert_eq!(
                request_source(stream, request),
                vendor,
                "DMA1 stream {stream} request {request}"
            );
        }
    }
}

/// PA0 is also the Black Pill's KEY button: whatever the pin table says, the timer channel the
/// vendor wires to PA0 must play nothing unless the user configures all 8 LEDs.
#[test]
fn pa0_is_driven_only_with_eight_leds() {
    use protocol::carriers::{ChipTable, MAX_LEDS};

    use crate::plan::{ChipEngine, FrameMemory, Mode};
    use crate::register_model::Chip;
    use crate::register_model::LogEntry;
    use crate::register_model::timer::TimerId;

    let (timer, channel) = ["TIM3", "TIM5"]
        .into_iter()
        .find_map(|t| {
            let pin = peripheral(t).pins.iter().find(|p| p.pin == "PA0")?;
            let channel: usize = pin.signal.strip_prefix("CH")?.parse().ok()?;
            Some((t, channel))
        })
        .expect("PA0 is a PWM bank's channel");
    let timer = if timer == "TIM3" {
        TimerId::Tim3
    } else {
        TimerId::Tim5
    };
    let frames = FrameMemory {
        tim3: 0x2000_4000,
        tim5: 0x2000_8000,
    };
    for leds in 1..=MAX_LEDS as u8 {
        let mut chip = Chip::new();
        let mut engine = ChipEngine::new(&mut chip, 96_000_000, frames, Mode::Dma).unwrap();
        let table = ChipTable::new(leds).unwrap();
        engine
            .load(
                &mut chip,
                &table,
                &protocol::timing::LedLevels::full_depth(&[1000; MAX_LEDS]),
                4_000_000,
            )
            .unwrap();
        engine.start(&mut chip).unwrap();
        chip.run_until(chip.now + 2 * table.chips() as u64 * 24_000);
        let driven = chip.log.iter().any(|entry| {
            matches!(entry, LogEntry::Outputs { timer: t, outputs, .. }
                if *t == timer && outputs.levels[channel - 1] != Some(0))
        });
        assert_eq!(driven, leds == 8, "N = {leds}: PA0 driven = {driven}");
    }
}
