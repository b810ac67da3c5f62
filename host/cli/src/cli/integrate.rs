//! `meb integrate`: integrate a normal map (H×W×3 .npy) inside a mask into depth.

use anyhow::Result;
use clap::Args;
use meb_cli::export::report::Summary;
use meb_core::io::read_float;
use meb_core::timing::StageTiming;
use meb_core::types::NormalField;
use meb_pipeline::integrate::{IntegrateConfig, Integrator, integrate_normals};
use ndarray::{Array2, Ix3};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `meb integrate`.
#[derive(Args, Debug)]
pub struct IntegrateArgs {
    /// Normals as an H×W×3 float32/float64 .npy (x right, y up, z towards the camera).
    pub normals: PathBuf,
    /// Mask image (non-zero = integrate here).
    #[arg(long)]
    pub mask: PathBuf,
    /// Grid pitch in mm per pixel.
    #[arg(long)]
    pub pitch: f64,
    /// Output folder, replaced whole and atomically.
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, help = super::common::FORCE_HELP)]
    pub force: bool,
    /// Also write the surface in these formats (comma-separated): obj, stl.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub mesh: Vec<super::common::MeshFormat>,
    /// Integrator.
    #[arg(long, value_enum, default_value = "least-squares")]
    pub integrator: IntegratorArg,
    /// Fast Marching λ per pixel².
    #[arg(long, default_value_t = 0.06)]
    pub lambda: f64,
}

/// Integrator choice on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum IntegratorArg {
    /// Masked least squares (default).
    LeastSquares,
    /// Bilateral normal integration: keeps depth discontinuities.
    Bilateral,
    /// The thesis' Fast Marching.
    FastMarching,
}

impl From<IntegratorArg> for Integrator {
    fn from(a: IntegratorArg) -> Self {
        match a {
            IntegratorArg::Bilateral => Integrator::Bilateral,
            IntegratorArg::LeastSquares => Integrator::LeastSquares,
            IntegratorArg::FastMarching => Integrator::FastMarching,
        }
    }
}

/// Runs `meb integrate`.
pub fn run(args: &IntegrateArgs) -> Result<()> {
    let folder = super::common::output_folder(&args.out, "integrate", args.force)?;
    let normals = read_float::<Ix3>(&args.normals, &[None, None, Some(3)])?;
    let (rows, cols, _) = normals.dim();
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
    let out = integrate_normals(&field, args.pitch, &config, None)?;
    let timings = vec![StageTiming::since("integration", start)];
    let summary = Summary {
        input: Some(args.normals.display().to_string()),
        integrator: Some(super::common::integrator_name(config.integrator)),
        object_pixels: Some(field.mask.iter().filter(|&&m| m).count()),
        kept_fraction: Some(out.kept_fraction),
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
