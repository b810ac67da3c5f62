//! `meb demo`: simulate the thesis' out-of-plane sphere (and cube), decode, reconstruct,
//! compare with ground truth, write the report and print a short summary.

use anyhow::Result;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use meb_cli::demo::{run as run_demo, thesis_capture_config, thesis_decode_config};
use meb_cli::export::report::Summary;
use meb_core::rig::Rig;
use meb_pipeline::reconstruct::ReconstructConfig;
use meb_sim::{Scene, SceneObject};
use std::path::PathBuf;

/// Arguments of `meb demo`.
#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Output folder (one sub-folder per object), replaced whole and atomically.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    #[arg(long, help = super::common::FORCE_HELP)]
    pub force: bool,
    /// Only the sphere (skip the cube).
    #[arg(long)]
    pub sphere_only: bool,
    /// Noise seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Runs `meb demo`.
pub fn run(args: &DemoArgs) -> Result<()> {
    let rig = Rig::preset("thesis-out-of-plane")
        .ok_or_else(|| anyhow::anyhow!("missing preset thesis-out-of-plane"))?;
    let mut objects = vec![("sphere", SceneObject::sphere(48.0))];
    if !args.sphere_only {
        objects.push(("cube", SceneObject::cube(75.0, false)));
    }
    let folder = super::common::output_folder(&args.out, "demo", args.force)?;
    let mut reports = Vec::new();
    println!(
        "meb demo: thesis out-of-plane rig, {}x{}, 128 frames, σ 1 %, background 0 dB SNR, exposure 0.8, gamma 2.2",
        rig.camera.width, rig.camera.height
    );
    for (name, object) in objects {
        let bar = ProgressBar::new(128);
        bar.set_style(
            ProgressStyle::with_template("{msg:8} decoding [{bar:30}] {pos}/{len} frames")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar.set_message(name);
        let out = run_demo(
            &rig,
            Scene::single(object),
            thesis_capture_config(args.seed),
            &thesis_decode_config(rig.leds.len()),
            &ReconstructConfig::decoded_capture(),
            &mut |done, total| {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            },
        )?;
        bar.finish_and_clear();
        super::common::check_support(&out.reconstruction, None, args.force)?;
        let e = &out.depth_errors;
        let config = ReconstructConfig::decoded_capture();
        let summary = Summary {
            rig: Some("thesis-out-of-plane".into()),
            object: Some(name.into()),
            lit_by_three_pixels: Some(out.lit_by_three.iter().filter(|&&m| m).count()),
            ..super::common::reconstruction_summary(&out.decoded, &config, &out.reconstruction)
        };
        let dir = folder.path().join(name);
        std::fs::create_dir(&dir).map_err(|e| meb_core::io::FilesError::write(&dir, e))?;
        super::common::write_outputs(
            &dir,
            &format!("meb demo: {name}"),
            "simulated capture (meb simulate), decoded with meb demod".into(),
            &out.reconstruction.photometric.field,
            &out.reconstruction.integration.depth,
            Some(e),
            Some(&out.angular_errors),
            Some(out.reconstruction.confidence()),
            &out.timings,
            summary,
            vec![],
        )?;
        let total_ms: f64 = out.timings.iter().map(|t| t.ms).sum();
        println!(
            "{name:7} depth RMSE {:.2} mm, NRMSE {}, surface {:.1} %, normals mean {:.2}° median {:.2}°, {:.1} s",
            e.rmse_mm,
            e.nrmse
                .map_or_else(|| "n/a".into(), |n| format!("{:.2} %", 100.0 * n)),
            100.0 * e.reconstructed_fraction,
            out.angular_errors.mean_deg,
            out.angular_errors.median_deg,
            total_ms / 1e3
        );
        reports.push(name);
    }
    let out = super::common::commit(folder)?;
    for name in reports {
        println!("report: {}", out.join(name).join("report.html").display());
    }
    Ok(())
}
