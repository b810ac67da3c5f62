//! `meb rig check`: how consistent a rig is with a capture (the rig check every
//! reconstruction runs, [`meb_pipeline::reconstruct::rig_check`]; with `--sphere-mm`, the
//! radius and normals recovered for a sphere of known size, [`meb_pipeline::calibrate::
//! sphere_check`]), and the refusal of an inconsistent rig that `meb reconstruct` shares.

use super::decode::{DecodeOptions, check_folder_verdict, decode_capture};
use anyhow::{Context, Result, bail, ensure};
use clap::{Args, Subcommand};
use meb_core::rig::Rig;
use meb_pipeline::calibrate::sphere_check::{
    MAX_NORMAL_ERROR_DEG, MAX_RADIUS_ERROR, SphereCheck, check_sphere,
};
use meb_pipeline::demod::Decoded;
use meb_pipeline::demod::output::read_decode_dir;
use meb_pipeline::reconstruct::acceptance;
use meb_pipeline::reconstruct::rig_check::{RigCheck, RigFit};
use meb_pipeline::reconstruct::{
    ReconstructConfig, Request, Source, check_decoded_rig, level_noise, reconstruct,
    usable_led_images,
};
use std::path::PathBuf;

/// Arguments of `meb rig`.
#[derive(Args)]
pub struct RigArgs {
    #[command(subcommand)]
    command: RigCommand,
}

#[derive(Subcommand)]
enum RigCommand {
    /// How well a rig explains a capture: the Lambertian fit's residuals per LED over the
    /// reconstructed surface, each LED's apparent intensity, and a verdict (exit status 1
    /// when the rig does not fit).
    Check(CheckArgs),
}

/// Arguments of `meb rig check`.
#[derive(Args)]
struct CheckArgs {
    /// A capture (decoded first) or a `meb decode` output folder.
    input: PathBuf,
    /// Rig: a TOML file or a preset.
    #[arg(long)]
    rig: String,
    /// The capture shows a matte sphere of this diameter, mm (wholly in view): also check the
    /// radius and normals the rig recovers for it.
    #[arg(long)]
    sphere_mm: Option<f64>,
    /// Decoder settings (only used when INPUT is a capture).
    #[command(flatten)]
    decode: DecodeOptions,
}

/// Runs `meb rig`.
pub fn run(args: &RigArgs) -> Result<()> {
    match &args.command {
        RigCommand::Check(check) => run_check(check),
    }
}

fn run_check(args: &CheckArgs) -> Result<()> {
    let rig = Rig::load(&args.rig).with_context(|| format!("cannot load rig {}", args.rig))?;
    let decoded = read_capture(&args.input, &rig, &args.decode)?;
    let config = ReconstructConfig::decoded_capture();
    let reconstruction = reconstruct(Source::Decoded(&decoded), &rig, &config, Request::default())
        .with_context(|| {
            format!(
                "rig {} could not reconstruct {} at all, so it cannot be checked (is it the rig of \
             this capture, with the LEDs in their order?)",
                args.rig,
                args.input.display()
            )
        })?;
    let check = check_decoded_rig(&decoded, &rig, &reconstruction, &config);
    print_table(&check);
    println!("{}", check.describe(&args.rig));
    if let Some(diameter) = args.sphere_mm {
        let images = usable_led_images(&decoded);
        let sphere = check_sphere(
            &images.images,
            &level_noise(&decoded),
            &rig,
            &reconstruction.photometric.field,
            &reconstruction.integration.depth,
            diameter,
        )
        .context("the sphere check could not run")?;
        println!("{}", describe_sphere(&sphere));
        if !sphere.consistent {
            bail!(
                "verdict: inconsistent; the rig does not give back the Ø{diameter} mm sphere \
                 (a consistent rig: radius within {:.0} %, mean normal error at most {:.0}°); \
                 try: {}",
                100.0 * MAX_RADIUS_ERROR,
                MAX_NORMAL_ERROR_DEG,
                check.advice()
            );
        }
    }
    match check.fit {
        RigFit::Consistent => println!("verdict: consistent"),
        RigFit::Doubtful => println!("verdict: doubtful (reported, not refused)"),
        RigFit::Unjudged => bail!(
            "{} (light the object with every LED, or use a larger object)",
            check.describe(&args.rig)
        ),
        RigFit::Inconsistent => bail!("verdict: inconsistent; try: {}", check.advice()),
    }
    Ok(())
}

/// Decodes `input` (or reads its decode folder) for `rig`, checking that the LED count and
/// image size agree.
fn read_capture(input: &std::path::Path, rig: &Rig, options: &DecodeOptions) -> Result<Decoded> {
    let decoded = if input.join("decode.json").is_file() {
        let decoded = read_decode_dir(input)?;
        check_folder_verdict(&decoded.report, input, false)?;
        decoded
    } else {
        decode_capture(input, options, rig.leds.len(), false)?
    };
    ensure!(
        decoded.leds.images.len() == rig.leds.len(),
        "the rig has {} LEDs but {} has {} LED images",
        rig.leds.len(),
        input.display(),
        decoded.leds.images.len()
    );
    let shape = decoded
        .leds
        .shape()
        .context("the capture holds no LED image")?;
    ensure!(
        shape == (rig.camera.height, rig.camera.width),
        "the rig's camera is {}x{} but the images are {}x{}",
        rig.camera.width,
        rig.camera.height,
        shape.1,
        shape.0
    );
    Ok(decoded)
}

/// One line on the sphere `check`.
fn describe_sphere(check: &SphereCheck) -> String {
    format!(
        "sphere: radius {:.2} mm recovered for {:.2} mm ({:+.1} %), normal error mean {:.2}°, \
         95 % below {:.2}°, over {} pixels ({})",
        check.recovered_radius_mm,
        check.radius_mm,
        100.0 * check.radius_error(),
        check.mean_normal_error_deg,
        check.p95_normal_error_deg,
        check.pixels,
        if check.consistent {
            "as a consistent rig gives"
        } else {
            "not what a consistent rig gives"
        }
    )
}

/// Prints the per-LED figures of `check`.
fn print_table(check: &RigCheck) {
    if check.leds.is_empty() {
        return;
    }
    println!("LED  apparent intensity  median |residual|  median residual (σ)");
    for led in &check.leds {
        println!(
            "{:>3}  {:>18.4}  {:>16.2} %  {:>19.2}",
            led.led,
            led.gain,
            100.0 * led.residual,
            led.residual_sigmas
        );
    }
}

/// Reports a doubtful or inconsistent rig on stderr and refuses an inconsistent one unless
/// `force`; returns the hint that names the rig when the reconstruction is `implausible` anyway
/// and the rig fits only roughly ([`acceptance::rig`]).
pub fn enforce(
    check: &RigCheck,
    rig_name: &str,
    force: bool,
    implausible: bool,
) -> Result<Option<String>> {
    let (ruling, hint) = acceptance::rig(check, rig_name, force, implausible, "--force");
    super::common::apply(ruling)?;
    Ok(hint)
}
