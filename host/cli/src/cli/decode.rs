//! `meb decode`: demodulate a capture into one image per LED and write the output directory.

use super::parse;
use anyhow::{Context, Result, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use meb_core::capture::raw::RawLayout;
use meb_core::capture::{OpenOptions, open};
use meb_device::Timeline;
use meb_device::timeline::OutputMode;
use meb_pipeline::demod::output::write_decode_dir;
use meb_pipeline::demod::{
    DecodeConfig, DecodeReport, Decoded, DemodError, Estimator, LedCount, Linearize,
    ModulationDepths, OnImplausible, Roi, VerdictStatus, decode,
};
use meb_pipeline::reconstruct::acceptance;
use std::path::{Path, PathBuf};

/// Arguments of `meb decode`.
#[derive(Args)]
pub struct DecodeArgs {
    /// Input: a directory of PNG/TIFF frames, a multi-page TIFF, a .y4m file, a raw file
    /// (with --raw) or a video file (through FFmpeg).
    input: PathBuf,
    /// Output folder (led1.npy…, ledI.png, noise.npy, decode.json), replaced whole and
    /// atomically.
    #[arg(long)]
    out: PathBuf,
    #[arg(long, help = super::common::FORCE_HELP)]
    force: bool,
    /// Decoder settings.
    #[command(flatten)]
    options: DecodeOptions,
}

/// The decoder settings shared by `meb decode` and `meb reconstruct`.
#[derive(Args)]
pub struct DecodeOptions {
    /// Number of LEDs (1..=8) or `auto` [default: 4, or the rig's LED count in `reconstruct`].
    #[arg(long, value_parser = parse::leds)]
    leds: Option<LedCount>,
    /// Number of frames to use (≥ 2^(N+1)); default all.
    #[arg(long, value_parser = clap::value_parser!(u32).range(2..))]
    frames: Option<u32>,
    /// Frames to skip at the start.
    #[arg(long, default_value_t = 0)]
    start: usize,
    /// Amplitude estimator.
    #[arg(long, value_enum, default_value_t = EstimatorArg::Waveform)]
    estimator: EstimatorArg,
    /// Code-value linearisation: `none`, `srgb` or `gamma:G`.
    #[arg(long, default_value = "none", value_parser = parse::linearize)]
    linearize: Linearize,
    /// Region of interest WxH+X+Y.
    #[arg(long, value_parser = parse::roi)]
    roi: Option<Roi>,
    /// Camera frame rate override (phone containers may store the playback rate).
    #[arg(long, value_parser = parse::positive)]
    fps: Option<f64>,
    /// Known chips per frame (chip rate / frame rate) instead of estimating it.
    #[arg(long, value_parser = parse::positive)]
    rate_ratio: Option<f64>,
    /// Largest |chips per frame − 1| searched when the rate ratio is estimated.
    #[arg(long, default_value_t = 0.06, value_parser = parse::non_negative)]
    max_rate_mismatch: f64,
    /// Known exposure as a fraction of the frame period (0, 1] instead of estimating it.
    #[arg(long, value_parser = parse::fraction)]
    exposure: Option<f64>,
    /// Known rolling-shutter line time in microseconds (0 = global shutter); fitted from
    /// the video when absent.
    #[arg(long, value_parser = parse::non_negative)]
    line_time_us: Option<f64>,
    /// Raw input layout WxHxBITS (e.g. 1280x720x8).
    #[arg(long, value_parser = parse::raw)]
    raw: Option<RawLayout>,
    /// Decode even when the video shows a different LED count than --leds.
    #[arg(long)]
    no_led_check: bool,
    /// The luminaire's modulation depths, as `meb device set --depth` takes them: `auto`
    /// (each LED's largest IEEE 1789 low-risk depth at the decoded chip rate), one depth in
    /// (0, 1] for every LED or one per LED, or `factory` (the factory default's off levels).
    /// Each LED image is divided by 1 − its off chips' share of its on light, to the image
    /// full on/off keying gives [default: 1, off chips dark].
    #[arg(long, value_parser = parse::depth, allow_hyphen_values = true)]
    depth: Option<ModulationDepths>,
    /// Read the depths from a luminaire timeline (`meb device emulate --timeline`): the off
    /// levels and brightness its segment at --timeline-start plays.
    #[arg(long, conflicts_with = "depth")]
    timeline: Option<PathBuf>,
    /// Timeline time (s) whose segment gives the depths (default: the timeline's last output
    /// change, as `meb simulate --timeline`).
    #[arg(long, requires = "timeline")]
    timeline_start: Option<f64>,
}

/// The amplitude estimators `--estimator` accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum EstimatorArg {
    /// The matched filter on the waveform fitted from the whole image.
    Waveform,
    /// The thesis' projection and maximum (Eqs. 3.25–3.30).
    Thesis,
}

impl From<EstimatorArg> for Estimator {
    fn from(arg: EstimatorArg) -> Self {
        match arg {
            EstimatorArg::Waveform => Estimator::Waveform,
            EstimatorArg::Thesis => Estimator::Thesis,
        }
    }
}

/// Builds the decoder settings; `default_leds` applies when --leds is absent, `force` keeps
/// a result the quality verdict finds implausible (recorded as overridden).
pub fn config(args: &DecodeOptions, default_leds: usize, force: bool) -> Result<DecodeConfig> {
    let leds = args.leds.unwrap_or(LedCount::Fixed(default_leds));
    let depths = match (&args.depth, &args.timeline) {
        (_, Some(path)) => timeline_depths(path, args.timeline_start)?,
        (Some(depths), None) => depths.clone(),
        (None, None) => ModulationDepths::Full,
    };
    Ok(DecodeConfig {
        depths,
        leds,
        frames: args.frames.map(|f| f as usize),
        start: args.start,
        estimator: args.estimator.into(),
        linearize: args.linearize,
        roi: args.roi,
        fps: args.fps,
        rate_ratio: args.rate_ratio,
        max_rate_mismatch: args.max_rate_mismatch,
        exposure: args.exposure,
        line_time_s: args.line_time_us.map(|us| us * 1e-6),
        check_led_count: !args.no_led_check,
        on_implausible: if force {
            OnImplausible::Keep
        } else {
            OnImplausible::Refuse
        },
        ..DecodeConfig::default()
    })
}

/// The off fractions a luminaire timeline's segment at `start` (the last for `None`) plays.
fn timeline_depths(path: &Path, start: Option<f64>) -> Result<ModulationDepths> {
    let timeline = Timeline::read(path)?;
    let segment = timeline
        .segment_at(start)
        .with_context(|| format!("no depths in {}", path.display()))?;
    if segment.mode != OutputMode::Playing {
        bail!(
            "the luminaire of {} is not playing its carriers at that time ({:?}): give \
             --timeline-start inside a playing segment",
            path.display(),
            segment.mode
        );
    }
    Ok(ModulationDepths::OffFractions(segment.off_fractions()))
}

/// How to open the input: frame rate override and raw layout.
pub fn open_options(options: &DecodeOptions) -> Result<OpenOptions> {
    Ok(OpenOptions {
        fps: options.fps,
        raw: options.raw,
    })
}

/// Opens and decodes `input` with `options`, showing a progress bar; `default_leds` applies
/// when --leds is absent, `force` keeps a result the verdict finds implausible.
pub fn decode_capture(
    input: &Path,
    options: &DecodeOptions,
    default_leds: usize,
    force: bool,
) -> Result<Decoded> {
    let config = config(options, default_leds, force)?;
    let mut source = open(input, &open_options(options)?)
        .with_context(|| format!("cannot open {}", input.display()))?;
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("decoding {bar:40} {pos}/{len} frames {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let decoded = decode(source.as_mut(), &config, &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    });
    bar.finish_and_clear();
    let decoded = decoded.map_err(|e| match flag_hint(&e) {
        // These errors carry no source: the message with the flags to try is all there is.
        Some(hint) => anyhow::anyhow!("cannot decode {}: {e} {hint}", input.display()),
        None => anyhow::Error::new(e).context(format!("cannot decode {}", input.display())),
    })?;
    warn_if_overridden(&decoded.report);
    Ok(decoded)
}

/// The command-line flags that address a decode error (for errors without a source).
fn flag_hint(error: &DemodError) -> Option<String> {
    Some(match error {
        DemodError::LedCountMismatch { detected, .. } => {
            format!("(use --leds {detected} or --leds auto; --no-led-check skips the check)")
        }
        DemodError::LedsHiddenByClipping { .. } => "(--no-led-check decodes the pixels that \
             do not clip anyway; the clipped ones are flagged in saturated.npy)"
            .into(),
        DemodError::Implausible { .. } => "(flags: --rate-ratio, --exposure, --line-time-us, \
             --linearize, --frames, --max-rate-mismatch; --force keeps the result with the \
             verdict recorded)"
            .into(),
        DemodError::NoModulation => "(check --leds, --fps and --max-rate-mismatch)".into(),
        DemodError::DepthCount { .. } => "(--depth takes one depth for every LED or one per \
             LED)"
            .into(),
        DemodError::DepthNeedsChipRate { .. } => "(give --fps, or --depth with the depths \
             `meb device get` shows)"
            .into(),
        DemodError::StartBeyondEnd { .. } => "(lower --start)".into(),
        _ => return None,
    })
}

/// Says how a decode without a frame rate looked for room-light flicker.
fn note_if_rate_unknown(report: &DecodeReport) {
    if report.fps <= 0.0 {
        eprintln!(
            "note: the frame rate is unknown (image files carry none), so flicker of room lights \
             was looked for at any frequency in frames rather than at the mains harmonics; give \
             --fps to have it placed and named as mains flicker"
        );
    }
}

/// Prints the verdict's problems when an implausible result was kept on request.
fn warn_if_overridden(report: &DecodeReport) {
    if report.verdict.status == VerdictStatus::Overridden {
        eprintln!(
            "warning: kept an implausible decode (--force): {}",
            report.verdict.problems.join("; ")
        );
    }
}

/// Refuses a decode folder whose verdict is not plausible unless `force` (then warns).
pub fn check_folder_verdict(report: &DecodeReport, folder: &Path, force: bool) -> Result<()> {
    let what = folder.display().to_string();
    super::common::apply(acceptance::decode_verdict(
        &report.verdict,
        &what,
        force,
        "--force",
    ))
}

/// Runs `meb decode`.
pub fn run(args: &DecodeArgs) -> Result<()> {
    let folder = super::common::output_folder(&args.out, "decode", args.force)?;
    let decoded = decode_capture(&args.input, &args.options, 4, args.force)?;
    // The exposure advice for clipped pixels (`meb reconstruct` gives it with a result and keeps
    // it in report.json, so its refusals stay one line).
    if let Some(clipping) = &decoded.report.clipping {
        eprintln!("note: {}", clipping.message);
    }
    write_decode_dir(folder.path(), &decoded)?;
    let out = super::common::commit(folder)?;
    let report = &decoded.report;
    println!(
        "decoded {} LEDs from {} frames ({}x{}), rate ratio {:.5}, exposure {:.2}, \
         line time {:.2} µs, median noise {:.4}, verdict {:?}",
        report.leds,
        report.frames_used,
        report.width,
        report.height,
        report.rate_ratio,
        report.exposure,
        report.line_time_us,
        report.median_noise,
        report.verdict.status
    );
    let modulation = &report.modulation;
    for led in &report.per_led {
        let depth = match modulation.depths.get(led.led - 1) {
            Some(&m) if m < 1.0 => format!(
                ", depth {m:.3} (image ×{:.2})",
                modulation.scale(led.led - 1)
            ),
            _ => String::new(),
        };
        println!(
            "  LED {}: phase {:.3} chips, mean level {:.4}, SNR {:.1} dB, gain ±{:.2} %{depth}",
            led.led,
            led.phase_chips,
            led.mean_level,
            led.snr_db,
            100.0 * led.quality.gain_uncertainty
        );
    }
    println!("wrote {}", out.display());
    // After the folder is in place: a command that fails later keeps its one-line error.
    note_if_rate_unknown(report);
    Ok(())
}
