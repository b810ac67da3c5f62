//! The firmware's size budget: ≤ 72 KiB of flash and ≤ 16 KiB of static RAM beyond
//! the chip table, measured from the shipped (`firmware` profile) ELF's section headers.
//!
//! Flash holds `.vector_table`, `.text`, `.rodata` and the load image of `.data`; static RAM is
//! `.data`, `.bss` and `.uninit` (cortex-m-rt's section names). The chip-table allowance is two
//! [`ChipTable`]s: the one playing and the one being loaded for a glitch-free swap.

use std::path::{Path, PathBuf};
use std::process::Command;

use object::{Object, ObjectSection};
use protocol::carriers::ChipTable;

/// Flash budget in bytes.
/// 72 KiB of the 256 KiB code region (memory.x): room for the IEEE 1789 flicker check
/// (`protocol::flicker`, ~3 KiB with the larger configuration) above the 64 KiB of sectors 0–3.
pub const FLASH_BUDGET: u64 = 72 * 1024;
/// Static RAM budget in bytes, not counting the chip tables.
pub const RAM_BUDGET: u64 = 16 * 1024;
/// RAM the chip tables may take on top of [`RAM_BUDGET`].
pub const CHIP_TABLE_ALLOWANCE: u64 = 2 * std::mem::size_of::<ChipTable>() as u64;
/// The firmware's target triple.
pub const FIRMWARE_TARGET: &str = "thumbv7em-none-eabihf";

const FLASH_SECTIONS: [&str; 4] = [".vector_table", ".text", ".rodata", ".data"];
const RAM_SECTIONS: [&str; 3] = [".data", ".bss", ".uninit"];

/// Flash and static RAM taken by an ELF image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Footprint {
    /// Bytes in flash.
    pub flash: u64,
    /// Bytes of static RAM.
    pub ram: u64,
}

impl Footprint {
    /// Measures an ELF file's sections.
    pub fn of_elf(bytes: &[u8]) -> Result<Self, String> {
        let file = object::File::parse(bytes).map_err(|e| format!("not an ELF file: {e}"))?;
        let size_of = |names: &[&str]| -> u64 {
            file.sections()
                .filter(|s| s.name().is_ok_and(|n| names.contains(&n)))
                .map(|s| s.size())
                .sum()
        };
        Ok(Self {
            flash: size_of(&FLASH_SECTIONS),
            ram: size_of(&RAM_SECTIONS),
        })
    }

    /// Whether it fits the flash and RAM budgets.
    pub fn fits(&self) -> bool {
        self.flash <= FLASH_BUDGET && self.ram <= RAM_BUDGET + CHIP_TABLE_ALLOWANCE
    }
}

/// The workspace root (parent of this crate).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// Cargo profile of the shipped firmware (`cargo firmware`): release + fat LTO + `opt-level = "z"`.
pub const FIRMWARE_PROFILE: &str = "firmware";

/// Cargo feature of the TIM2-update-interrupt fallback build (`cargo firmware-fallback`).
pub const FALLBACK_FEATURE: &str = "chip-interrupt-fallback";

/// Builds the shipped firmware (the `firmware` profile, as `cargo firmware` does, with
/// `features` on) in the workspace target dir; returns the ELF path or cargo's output on
/// failure. Builds run one at a time: both variants write the same ELF path.
pub fn build_firmware(features: &[&str]) -> Result<PathBuf, String> {
    static ONE_BUILD: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _turn = ONE_BUILD
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let root = workspace_root();
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut args = vec![
        "build",
        "-p",
        "firmware",
        "--profile",
        FIRMWARE_PROFILE,
        "--target",
        FIRMWARE_TARGET,
    ];
    let feature_list = features.join(",");
    if !features.is_empty() {
        args.extend(["--features", &feature_list]);
    }
    let output = Command::new(cargo)
        .current_dir(&root)
        .args(&args)
        .output()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    if !output.status.success() {
        return Err(format!(
            "`cargo {}` failed ({}):\n{}",
            args.join(" "),
            output.status,
            String::from_utf8_lossy(&output.stderr)
        ));
    }
    let target_dir =
        std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| root.join("target"), PathBuf::from);
    Ok(target_dir
        .join(FIRMWARE_TARGET)
        .join(FIRMWARE_PROFILE)
        .join("firmware"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn measures_a_real_elf() {
        let exe = std::env::current_exe().unwrap();
        let footprint = Footprint::of_elf(&std::fs::read(exe).unwrap()).unwrap();
        assert!(footprint.flash > 0);
        assert!(Footprint::of_elf(b"not an elf").is_err());
    }

    #[test]
    fn budget_edges() {
        let fits = Footprint {
            flash: FLASH_BUDGET,
            ram: RAM_BUDGET + CHIP_TABLE_ALLOWANCE,
        };
        assert!(fits.fits());
        assert!(
            !Footprint {
                flash: FLASH_BUDGET + 1,
                ..fits
            }
            .fits()
        );
        assert!(
            !Footprint {
                ram: fits.ram + 1,
                ..fits
            }
            .fits()
        );
    }
}
