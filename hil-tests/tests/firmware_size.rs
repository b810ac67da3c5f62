//! The shipped firmware (`cargo firmware`) and its TIM2-interrupt fallback build
//! (`cargo firmware-fallback`) build for the board and fit the size budget.

use hil_tests::elf_budget::{
    CHIP_TABLE_ALLOWANCE, FALLBACK_FEATURE, FLASH_BUDGET, Footprint, RAM_BUDGET, build_firmware,
};

/// Builds with `features`, measures the ELF and checks the budget. Both variants write the same
/// ELF path, so they run one after the other in one test.
fn check(features: &[&str]) {
    let elf = match build_firmware(features) {
        Ok(path) => path,
        Err(log) => panic!("the firmware does not build:\n{log}"),
    };
    let bytes = std::fs::read(&elf).unwrap_or_else(|e| panic!("{}: {e}", elf.display()));
    let footprint = Footprint::of_elf(&bytes).unwrap_or_else(|e| panic!("{e}"));
    eprintln!(
        "firmware {features:?} footprint: flash {} / {FLASH_BUDGET} B, static RAM {} / {} B (incl. {CHIP_TABLE_ALLOWANCE} B chip tables)",
        footprint.flash,
        footprint.ram,
        RAM_BUDGET + CHIP_TABLE_ALLOWANCE
    );
    assert!(
        footprint.flash > 0,
        "no flash sections found in {}",
        elf.display()
    );
    assert!(footprint.fits(), "over budget: {footprint:?}");
}

#[test]
fn shipped_firmware_builds_fit_flash_and_ram_budget_with_and_without_the_fallback() {
    check(&[]);
    check(&[FALLBACK_FEATURE]);
}
