//! The library calls the Python package makes, timed in Rust on the same inputs, for
//! `bench/compare.py` (which times the Python calls and prints both):
//!
//! * `decode REPEATS`: [`meb_pipeline::demod::decode`] of the 32-frame 1280×720 capture that
//!   `meb.simulate("thesis-out-of-plane", "sphere", frames=32, camera_size=(1280, 720))`
//!   renders, from an in-memory source, as the decode benchmark (`host/pipeline/benches/
//!   decode.rs`) times it;
//! * `integrate REPEATS DIR NORMALS.npy …`: [`meb_pipeline::integrate::integrate_surface`] of
//!   each DiLiGenT object's normals (the H×W×3 float32 array the Python side passes, so that
//!   both integrate the same bits) in its mask through its camera (`K.txt`, 1500 mm,
//!   automatic integrator), as `meb.integrate(normals, mask, K=K, distance=1500)` calls it.
//!
//! Prints one JSON object per case: `{"case": …, "ms": [one time per repeat]}`.

use meb_core::capture::memory::MemorySource;
use meb_core::datasets::normal_maps::load_normal_integration_object;
use meb_core::rig::{Projection, Rig};
use meb_core::types::NormalField;
use meb_pipeline::demod::{DecodeConfig, LedCount, OnImplausible, decode};
use meb_pipeline::integrate::{IntegrateConfig, Integrator, SurfaceEvidence, integrate_surface};
use meb_sim::{Scene, SceneObject, SimConfig, SimulatedCapture};
use ndarray::Array2;
use std::error::Error;
use std::path::Path;
use std::time::Instant;

/// Times `decode` on the simulated 1280×720 capture.
fn time_decode(repeats: usize) -> Result<Vec<f64>, Box<dyn Error>> {
    let mut rig = Rig::load("thesis-out-of-plane")?;
    if let Some(pitch) = rig.camera.pixel_pitch_mm {
        rig.camera.pixel_pitch_mm = Some(pitch * rig.camera.width as f64 / 1280.0);
    }
    (rig.camera.width, rig.camera.height) = (1280, 720);
    let config = SimConfig {
        frames: 32,
        peak: 0.4,
        ..SimConfig::default()
    };
    let capture = SimulatedCapture::new(rig, Scene::single(SceneObject::sphere(48.0)), config)?;
    let format = meb_core::capture::FrameFormat::full_range(1280, 720, 8, capture.rig().camera.fps);
    let frames: Vec<_> = (0..32).map(|i| capture.render_frame(i)).collect();
    let config = DecodeConfig {
        leds: LedCount::Fixed(4),
        on_implausible: OnImplausible::Keep,
        ..DecodeConfig::default()
    };
    let mut times = Vec::new();
    for _ in 0..repeats {
        let mut source = MemorySource::new(format.clone(), frames.clone())?;
        let started = Instant::now();
        decode(&mut source, &config, &mut |_, _| {})?;
        times.push(started.elapsed().as_secs_f64() * 1e3);
    }
    Ok(times)
}

/// Times `integrate_surface` on one benchmark object.
fn time_integrate(dir: &Path, normals: &Path, repeats: usize) -> Result<Vec<f64>, Box<dyn Error>> {
    let object = load_normal_integration_object(dir)?;
    let (rows, cols) = object.mask.dim();
    let field = NormalField {
        normals: meb_core::io::read_float::<ndarray::Ix3>(
            normals,
            &[Some(rows), Some(cols), Some(3)],
        )?,
        albedo: Array2::from_elem((rows, cols), 1.0),
        mask: object.mask,
    };
    let projection = Projection::Perspective {
        intrinsics: object.intrinsics,
        distance_mm: 1500.0,
    };
    let config = IntegrateConfig {
        integrator: Integrator::Auto,
        ..IntegrateConfig::default()
    };
    let mut times = Vec::new();
    for _ in 0..repeats {
        let started = Instant::now();
        let evidence = SurfaceEvidence {
            field: &field,
            planes: &[],
            fill: None,
        };
        integrate_surface(&evidence, &projection, &config, None)?;
        times.push(started.elapsed().as_secs_f64() * 1e3);
    }
    Ok(times)
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let repeats = |i: usize| -> Result<usize, Box<dyn Error>> {
        Ok(args.get(i).ok_or("missing REPEATS")?.parse()?)
    };
    match args.first().map(String::as_str) {
        Some("decode") => {
            let ms = time_decode(repeats(1)?)?;
            println!("{}", serde_json::json!({"case": "decode", "ms": ms}));
        }
        Some("integrate") => {
            let n = repeats(1)?;
            for pair in args[2..].chunks_exact(2) {
                let (dir, normals) = (&pair[0], &pair[1]);
                let ms = time_integrate(Path::new(dir), Path::new(normals), n)?;
                let name = Path::new(dir)
                    .file_name()
                    .map(|s| s.to_string_lossy().into_owned());
                println!("{}", serde_json::json!({"case": name, "ms": ms}));
            }
        }
        _ => {
            return Err(
                "usage: timing decode REPEATS | timing integrate REPEATS (DIR NORMALS.npy)…".into(),
            );
        }
    }
    Ok(())
}
