//! `meb integrate`: integrate a normal map (H×W×3 .npy, or an 8/16-bit RGB normal-map image)
//! inside a mask into depth, through an orthographic or a pinhole camera.

use anyhow::Result;
use clap::Args;
use meb_cli::export::report::Summary;
use meb_core::datasets::normal_maps::read_normal_map;
use meb_core::io::read_float;
use meb_core::timing::StageTiming;
use meb_core::types::NormalField;
use meb_pipeline::integrate::{IntegrateConfig, Integrator, SurfaceEvidence, integrate_surface};
use ndarray::{Array2, Ix3};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `meb integrate`.
#[derive(Args, Debug)]
pub struct IntegrateArgs {
    /// Normals (x right, y up, z towards the camera): an H×W×3 float32/float64 .npy, or an RGB
    /// normal-map image (PNG/TIFF, n = rgb·2 − 1 with rgb in 0..1).
    pub normals: PathBuf,
    /// Mask image (non-zero = integrate here).
    #[arg(long)]
    pub mask: PathBuf,
    /// The camera: --pitch (orthographic), --intrinsics with --distance, or --rig.
    #[command(flatten)]
    pub camera: super::camera::CameraArgs,
    /// Output folder, replaced whole and atomically.
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, help = super::common::FORCE_HELP)]
    pub force: bool,
    /// Also write the surface in these formats (comma-separated): obj, stl.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub mesh: Vec<super::common::MeshFormat>,
    /// Integrator.
    #[arg(long, value_enum, default_value = "auto")]
    pub integrator: IntegratorArg,
    /// Fast Marching λ per pixel².
    #[arg(long, default_value_t = 0.06)]
    pub lambda: f64,
}

/// Integrator choice on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum IntegratorArg {
    /// Least squares with the depth discontinuities that bilateral reweighting finds cut
    /// (default): least squares on smooth surfaces, bilateral across jumps.
    Auto,
    /// Masked least squares.
    LeastSquares,
    /// Bilateral normal integration: keeps depth discontinuities.
    Bilateral,
    /// The thesis' Fast Marching.
    FastMarching,
}

impl From<IntegratorArg> for Integrator {
    fn from(a: IntegratorArg) -> Self {
        match a {
            IntegratorArg::Auto => Integrator::Auto,
            IntegratorArg::Bilateral => Integrator::Bilateral,
            IntegratorArg::LeastSquares => Integrator::LeastSquares,
            IntegratorArg::FastMarching => Integrator::FastMarching,
        }
    }
}

/// Runs `meb integrate`.
pub fn run(args: &IntegrateArgs) -> Result<()> {
    let folder = super::common::output_folder(&args.out, "integrate", args.force)?;
    let normals = read_normals(&args.normals)?;
    let (rows, cols, _) = normals.dim();
    let camera = args.camera.choose((rows, cols), None)?;
    let mask = super::common::load_mask(&args.mask)?;
    anyhow::ensure!(
        mask.dim() == (rows, cols),
        "mask is {:?} but normals are {rows}x{cols}",
        mask.dim()
    );
    let field = NormalField {
        normals,
        albedo: Array2::from_elem((rows, cols), 1.0),
        mask,
    };
    let config = IntegrateConfig {
        integrator: args.integrator.into(),
        lambda: args.lambda,
        ..Default::default()
    };
    let start = Instant::now();
    let evidence = SurfaceEvidence {
        field: &field,
        planes: &[],
        fill: None,
    };
    let out = integrate_surface(&evidence, &camera.projection, &config, None)?;
    let timings = vec![StageTiming::since("integration", start)];
    let summary = Summary {
        input: Some(args.normals.display().to_string()),
        integrator: Some(super::common::integrator_name(config.integrator)),
        object_pixels: Some(field.mask.iter().filter(|&&m| m).count()),
        kept_fraction: Some(out.kept_fraction),
        camera: Some(camera.describe),
        integrator_choice: integrator_choice(&out),
        depth_convention: Some(camera.depth_convention),
        ..Summary::default()
    };
    super::common::write_outputs(
        folder.path(),
        "meb integrate",
        args.normals.display().to_string(),
        &field,
        &out.depth,
        None,
        None,
        Some(&out.confidence),
        &timings,
        summary,
        super::common::mesh_extensions(&args.mesh),
    )?;
    let written = super::common::commit(folder)?;
    println!(
        "integrated {} pixels ({:.1} % kept) in {:.1} ms → {}",
        out.kept.iter().filter(|&&k| k).count(),
        100.0 * out.kept_fraction,
        timings[0].ms,
        written.join("report.html").display()
    );
    Ok(())
}

/// Reads normals from a .npy array or a normal-map image (by the file's extension).
fn read_normals(path: &std::path::Path) -> Result<ndarray::Array3<f32>> {
    let image = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| ["png", "tif", "tiff"].contains(&e.to_ascii_lowercase().as_str()));
    if image {
        Ok(read_normal_map(path)?)
    } else {
        Ok(read_float::<Ix3>(path, &[None, None, Some(3)])?)
    }
}

/// The report's line on what the automatic integrator found, `None` for the others.
pub fn integrator_choice(out: &meb_pipeline::integrate::Integration) -> Option<String> {
    let edges = out.discontinuity_edges?;
    let pixels = out.bilateral_pixels.unwrap_or(0);
    Some(if pixels == 0 {
        "no depth discontinuity found: plain least squares".to_string()
    } else {
        format!(
            "least squares, with bilateral weights on {pixels} pixels near depth discontinuities \
             and {edges} grid edges cut"
        )
    })
}
