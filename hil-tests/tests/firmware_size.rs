//! The shipped firmware (`cargo firmware`) builds for the board and fits its size budget.

use hil_tests::elf_budget::{
    CHIP_TABLE_ALLOWANCE, FLASH_BUDGET, Footprint, RAM_BUDGET, build_firmware,
};

#[test]
fn shipped_firmware_build_fits_flash_and_ram_budget() {
    let elf = match build_firmware() {
        Ok(path) => path,
        Err(log) => panic!("the firmware does not build:\n{log}"),
    };
    let bytes = std::fs::read(&elf).unwrap_or_else(|e| panic!("{}: {e}", elf.display()));
    let footprint = Footprint::of_elf(&bytes).unwrap_or_else(|e| panic!("{e}"));
    eprintln!(
        "firmware footprint: flash {} / {FLASH_BUDGET} B, static RAM {} / {} B (incl. {CHIP_TABLE_ALLOWANCE} B chip tables)",
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
