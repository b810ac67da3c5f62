//! `meb tof`: the time-of-flight side of the hybrid scanner (thesis Ch. 6) — range maps from
//! SPAD histograms, the ToF → camera calibration from chequerboard images, and object masks in
//! the camera's pixels from a range map.

use anyhow::{Context, Result, ensure};
use clap::{Args, Subcommand};
use meb_core::io::{FilesError, preview, read_float, write_mask, write_npy};
use meb_core::types::LedImages;
use meb_pipeline::demod::output::read_decode_dir;
use meb_pipeline::tof::calibration::{BoardView, Calibration};
use meb_pipeline::tof::chequerboard::{BoardSize, find_corners, require_corner_detector};
use meb_pipeline::tof::hybrid::{HybridConfig, object_masks};
use meb_pipeline::tof::mask::{Layer, MaskConfig, interval_mask};
use meb_pipeline::tof::{
    Histograms, RangeConfig, Reference, TimingMode, estimate_range, write_range_folder,
};
use ndarray::{Array2, Ix2};
use std::path::{Path, PathBuf};

/// Arguments of `meb tof`.
#[derive(Args, Debug)]
pub struct TofArgs {
    #[command(subcommand)]
    command: TofCommand,
}

#[derive(Subcommand, Debug)]
enum TofCommand {
    /// Range map from TCSPC histograms (H×W×bins .npy) and a reference histogram.
    Range(RangeArgs),
    /// ToF → camera homographies from chequerboard images seen by both cameras (corner
    /// finding needs meb built with `--features opencv`).
    Calibrate(CalibrateArgs),
    /// Object masks in camera pixels from a range map: a range interval, or every layer.
    Mask(MaskArgs),
}

/// Arguments of `meb tof range`.
#[derive(Args, Debug)]
pub struct RangeArgs {
    /// Photon counts, H×W×bins .npy (any integer or float type).
    histograms: PathBuf,
    /// Reference: one histogram (bins) of a white board at --reference-mm on the optical
    /// axis, or one per pixel (H×W×bins) of a board perpendicular to it.
    #[arg(long)]
    reference: PathBuf,
    /// Output folder (range.npy, sigma.npy, confidence.npy, signal.npy, background.npy,
    /// correlation.npy, samples.npy, raw_range.npy, raw_sigma.npy, range.png, range.json),
    /// replaced whole and atomically.
    #[arg(long)]
    out: PathBuf,
    #[arg(long, help = super::common::FORCE_HELP)]
    force: bool,
    /// TDC bin width, ps.
    #[arg(long, default_value_t = 33.0)]
    bin_ps: f64,
    /// Distance of the reference board, mm.
    #[arg(long, default_value_t = 600.0)]
    reference_mm: f64,
    /// Forward TCSPC (later photons in later bins) instead of the thesis' reverse mode.
    #[arg(long)]
    forward: bool,
    /// Horizontal field of view of the ToF camera, degrees (per-pixel ray angles; the
    /// range is then axial depth). Without it every ray is taken as paraxial.
    #[arg(long)]
    fov_deg: Option<f64>,
    /// Pixels with fewer signal photons get no range.
    #[arg(long, default_value_t = 50.0)]
    min_photons: f64,
    /// Largest distance from the reference searched, mm (either side).
    #[arg(long, default_value_t = 750.0)]
    max_shift_mm: f64,
}

/// Arguments of `meb tof calibrate`.
#[derive(Args, Debug)]
pub struct CalibrateArgs {
    /// Chequerboard images of the ToF camera (photon counts, .npy H×W or an image file), one
    /// per board position, comma-separated.
    #[arg(long, value_delimiter = ',', required = true)]
    tof: Vec<PathBuf>,
    /// The same board positions seen by the photometric-stereo camera, in the same order.
    #[arg(long, value_delimiter = ',', required = true)]
    camera: Vec<PathBuf>,
    /// Inner corners of the board, COLSxROWS (e.g. 8x5).
    #[arg(long, value_parser = super::parse::board)]
    board: BoardSize,
    /// Square size, mm (recorded in the calibration).
    #[arg(long)]
    square_mm: Option<f64>,
    /// ToF range of each board position, mm, comma-separated (needed with several boards:
    /// the homography is interpolated in range between them).
    #[arg(long, value_delimiter = ',')]
    range_mm: Vec<f64>,
    /// Output folder (calibration.toml), replaced whole and atomically.
    #[arg(long)]
    out: PathBuf,
    #[arg(long, help = super::common::FORCE_HELP)]
    force: bool,
}

/// Arguments of `meb tof mask`.
#[derive(Args, Debug)]
pub struct MaskArgs {
    /// Range map: a `meb tof range` folder or an H×W .npy of ranges in mm (NaN = none).
    range: PathBuf,
    /// Calibration: a `meb tof calibrate` folder or its calibration.toml.
    #[arg(long)]
    calibration: PathBuf,
    /// Keep the ToF pixels with range in A..B mm (the thesis' selection).
    #[arg(
        long,
        value_name = "A..B",
        conflicts_with = "segment",
        required_unless_present = "segment",
        value_parser = super::parse::interval
    )]
    interval: Option<(f64, f64)>,
    /// Split the range map at range jumps and write one mask per object.
    #[arg(long)]
    segment: bool,
    /// With --segment: neighbouring ToF pixels whose ranges differ by more belong to
    /// different objects, mm.
    #[arg(long, default_value_t = 30.0)]
    jump_mm: f64,
    /// With --segment: also keep layers touching the image border (usually the background).
    #[arg(long)]
    include_border: bool,
    /// With --segment: the camera's images, whose edges the masks' boundaries snap to (within
    /// ±1 ToF pixel, as `meb reconstruct --tof` does): a `meb decode` folder (every LED
    /// image) or comma-separated H×W .npy images of the camera's size (e.g. the total
    /// intensity).
    #[arg(long, requires = "segment", value_name = "DECODE_DIR|A.npy,B.npy")]
    image: Option<String>,
    /// Output folder (mask.png, or mask_1.png… and labels.npy with --segment; masks.json),
    /// replaced whole and atomically.
    #[arg(long)]
    out: PathBuf,
    #[arg(long, help = super::common::FORCE_HELP)]
    force: bool,
}

/// Runs `meb tof`.
pub fn run(args: &TofArgs) -> Result<()> {
    match &args.command {
        TofCommand::Range(a) => range(a),
        TofCommand::Calibrate(a) => calibrate(a),
        TofCommand::Mask(a) => mask(a),
    }
}

/// Summary of a range map (`range.json`).
#[derive(serde::Serialize)]
struct RangeSummary<'a> {
    histograms: String,
    reference: String,
    width: usize,
    height: usize,
    bins: usize,
    reliable_pixels: usize,
    rejected: &'a meb_pipeline::tof::range::Rejections,
    median_sigma_mm: Option<f64>,
    range_mm: Option<[f64; 2]>,
    settings: &'a RangeConfig,
}

fn range(args: &RangeArgs) -> Result<()> {
    let folder = super::common::output_folder(&args.out, "tof range", args.force)?;
    let histograms = Histograms::read(&args.histograms)?;
    let reference = Reference::read(&args.reference)?;
    let config = RangeConfig {
        bin_ps: args.bin_ps,
        reference_distance_mm: args.reference_mm,
        mode: if args.forward {
            TimingMode::Forward
        } else {
            TimingMode::Reverse
        },
        fov_deg: args.fov_deg,
        min_signal_photons: args.min_photons,
        max_shift_mm: args.max_shift_mm,
        ..RangeConfig::default()
    };
    let map = estimate_range(&histograms, &reference, &config)?;
    let dir = folder.path();
    write_range_folder(dir, &map)?;
    preview::write_png(&dir.join("range.png"), &preview::depth_map(&map.range_mm))?;
    let finite = |a: &Array2<f32>| -> Vec<f64> {
        let mut v: Vec<f64> = a
            .iter()
            .filter(|x| x.is_finite())
            .map(|&x| f64::from(x))
            .collect();
        v.sort_by(f64::total_cmp);
        v
    };
    let sigmas = finite(&map.sigma_mm);
    let ranges = finite(&map.range_mm);
    let (height, width) = histograms.shape();
    let summary = RangeSummary {
        histograms: args.histograms.display().to_string(),
        reference: args.reference.display().to_string(),
        width,
        height,
        bins: histograms.bins(),
        reliable_pixels: map.reliable_pixels(),
        rejected: &map.rejected,
        median_sigma_mm: sigmas.get(sigmas.len() / 2).copied(),
        range_mm: ranges.first().zip(ranges.last()).map(|(a, b)| [*a, *b]),
        settings: &config,
    };
    write_json(&dir.join("range.json"), &summary)?;
    let written = super::common::commit(folder)?;
    println!(
        "range map {width}x{height}: {} of {} pixels reliable, median σ {:.1} mm → {}",
        summary.reliable_pixels,
        width * height,
        summary.median_sigma_mm.unwrap_or(f64::NAN),
        written.display()
    );
    Ok(())
}

fn calibrate(args: &CalibrateArgs) -> Result<()> {
    ensure!(
        args.tof.len() == args.camera.len(),
        "{} ToF images but {} camera images: give one of each per board position",
        args.tof.len(),
        args.camera.len()
    );
    ensure!(
        args.range_mm.is_empty() || args.range_mm.len() == args.tof.len(),
        "{} ranges for {} board positions: give one --range-mm per board",
        args.range_mm.len(),
        args.tof.len()
    );
    let board = args.board;
    require_corner_detector()?;
    let folder = super::common::output_folder(&args.out, "tof calibrate", args.force)?;
    let mut views = Vec::with_capacity(args.tof.len());
    let (mut tof_size, mut camera_size) = (None, None);
    for (k, (tof_path, camera_path)) in args.tof.iter().zip(&args.camera).enumerate() {
        let tof = read_grey(tof_path)?;
        let camera = read_grey(camera_path)?;
        for (size, image, path) in [
            (&mut tof_size, &tof, tof_path),
            (&mut camera_size, &camera, camera_path),
        ] {
            let found = [image.ncols(), image.nrows()];
            let first = *size.get_or_insert(found);
            ensure!(
                first == found,
                "{} is {}x{} but the first image of that camera is {}x{}",
                path.display(),
                found[0],
                found[1],
                first[0],
                first[1]
            );
        }
        let which = |name: &str, path: &Path| format!("{name} ({})", path.display());
        views.push(BoardView {
            tof_corners: find_corners(&tof, board, &which("ToF", tof_path))?,
            camera_corners: find_corners(&camera, board, &which("camera", camera_path))?,
            range_mm: args.range_mm.get(k).copied(),
        });
    }
    let (Some(tof_size), Some(camera_size)) = (tof_size, camera_size) else {
        anyhow::bail!("no board images given");
    };
    let calibration = Calibration::fit(&views, tof_size, camera_size, board, args.square_mm)?;
    let path = folder.path().join("calibration.toml");
    std::fs::write(&path, calibration.to_toml_string()).map_err(|e| FilesError::write(&path, e))?;
    let written = super::common::commit(folder)?;
    for (k, plane) in calibration.planes.iter().enumerate() {
        println!(
            "board {}: {} corners, reprojection RMS {:.3} camera px (max {:.3}){}",
            k + 1,
            plane.corners,
            plane.rms_px,
            plane.max_px,
            plane
                .range_mm
                .map(|r| format!(" at {r:.0} mm"))
                .unwrap_or_default()
        );
    }
    println!(
        "calibration → {}",
        written.join("calibration.toml").display()
    );
    Ok(())
}

/// One mask of `masks.json`.
#[derive(serde::Serialize)]
struct MaskSummary {
    file: String,
    median_range_mm: f64,
    range_mm: [f64; 2],
    tof_pixels: usize,
    camera_pixels: usize,
}

fn mask(args: &MaskArgs) -> Result<()> {
    let folder = super::common::output_folder(&args.out, "tof mask", args.force)?;
    let range_path = if args.range.is_dir() {
        args.range.join("range.npy")
    } else {
        args.range.clone()
    };
    let range: Array2<f32> = read_float::<Ix2>(&range_path, &[None, None])?;
    let calibration = load_calibration(&args.calibration)?;
    let masks: Vec<(Layer, Array2<bool>)> = match &args.interval {
        Some((lo, hi)) => {
            vec![interval_mask(&range, *lo, *hi, &calibration, true)?]
        }
        None => {
            let config = HybridConfig {
                mask: MaskConfig {
                    jump_mm: args.jump_mm,
                    ..MaskConfig::default()
                },
                include_border_layers: args.include_border,
                ..HybridConfig::default()
            };
            let images = args
                .image
                .as_deref()
                .map(|spec| read_edge_images(spec, calibration.camera_size))
                .transpose()?;
            object_masks(
                images.as_ref(),
                calibration.camera_size,
                &range,
                &calibration,
                &config,
            )?
        }
    };
    let dir = folder.path();
    let mut summaries = Vec::with_capacity(masks.len());
    let mut labels = Array2::from_elem(masks[0].1.dim(), -1i32);
    for (k, (layer, m)) in masks.iter().enumerate() {
        let file = if args.segment {
            format!("mask_{}.png", k + 1)
        } else {
            "mask.png".to_string()
        };
        write_mask(&dir.join(&file), m)?;
        labels.zip_mut_with(m, |l, &inside| {
            if inside {
                *l = k as i32;
            }
        });
        summaries.push(MaskSummary {
            file,
            median_range_mm: layer.median_mm,
            range_mm: layer.range_mm,
            tof_pixels: layer.tof_pixels,
            camera_pixels: m.iter().filter(|&&v| v).count(),
        });
    }
    if args.segment {
        write_npy(&dir.join("labels.npy"), &labels)?;
    }
    write_json(&dir.join("masks.json"), &summaries)?;
    let written = super::common::commit(folder)?;
    for s in &summaries {
        println!(
            "{}: {} camera pixels from {} ToF pixels at {:.0} mm (range {:.0}..{:.0} mm)",
            s.file, s.camera_pixels, s.tof_pixels, s.median_range_mm, s.range_mm[0], s.range_mm[1]
        );
    }
    println!("masks → {}", written.display());
    Ok(())
}

/// The camera images of `--image`: a `meb decode` folder or comma-separated .npy files, each
/// checked against the calibration's camera size [width, height].
fn read_edge_images(spec: &str, camera_size: [usize; 2]) -> Result<LedImages> {
    let [width, height] = camera_size;
    let folder = Path::new(spec);
    let images = if folder.is_dir() {
        read_decode_dir(folder)
            .with_context(|| format!("--image {spec}: reading the `meb decode` folder"))?
            .leds
    } else {
        let images = spec
            .split(',')
            .map(|file| {
                read_float::<Ix2>(Path::new(file.trim()), &[None, None])
                    .with_context(|| format!("--image {file}"))
            })
            .collect::<Result<Vec<_>>>()?;
        LedImages { images }
    };
    for (k, image) in images.images.iter().enumerate() {
        let (rows, cols) = image.dim();
        ensure!(
            (cols, rows) == (width, height),
            "--image {spec}: image {} is {cols}x{rows} but the calibration is for {width}x{height} camera images (give the camera images the calibration was made for)",
            k + 1
        );
    }
    Ok(images)
}

/// Loads a calibration: a `meb tof calibrate` folder or its calibration.toml.
pub fn load_calibration(path: &Path) -> Result<Calibration> {
    let file = if path.is_dir() {
        path.join("calibration.toml")
    } else {
        path.to_path_buf()
    };
    Ok(Calibration::load(&file)?)
}

/// A grey image: a 2-D float .npy, or an image file converted to luminance in [0, 1].
pub(super) fn read_grey(path: &Path) -> Result<Array2<f32>> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npy"))
    {
        return Ok(read_float::<Ix2>(path, &[None, None])?);
    }
    let image = image::open(path)
        .map_err(|source| FilesError::Image {
            path: path.to_path_buf(),
            source,
        })?
        .to_luma32f();
    let (w, h) = image.dimensions();
    Ok(Array2::from_shape_vec(
        (h as usize, w as usize),
        image.into_raw(),
    )?)
}

/// Writes `value` as pretty JSON to `path`.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text).map_err(|e| FilesError::write(path, e))?;
    Ok(())
}
