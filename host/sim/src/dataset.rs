//! The thesis' Ch. 7 synthetic data set (docs/formats/simulated-folders.md#the-synthetic-data-set):
//! per random blobby object, one image per
//! LED of the top-down in-plane rig (orthographic, 480×270 by default), a binary mask, the
//! light vectors and the ground-truth depth map (plus normals and albedo).
//!
//! Layout: `DIR/rig.toml`, `DIR/dataset.json`, and per object `DIR/object_0000/` holding
//! `led1.npy … ledN.npy` (float32, fraction of full scale, noise-free, no background),
//! `mask.png`, `depth.npy` (mm, NaN outside), `normals.npy`, `albedo.npy` and
//! `light_vectors.json` (the distant-light vectors g·L_i(0) of
//! docs/maths/photometric-stereo.md#light-vectors, so that
//! A_i ≈ ρ·max(0, n·L_i), and the LED positions for near-field use).

use super::SimulateError;
use super::capture::{SimConfig, SimulatedCapture};
use super::scene::{Scene, SceneObject, Shape};
use super::sensor::NoiseModel;
use meb_core::io::{FilesError, write_mask, write_npy};
use meb_core::rig::Rig;
use nalgebra::UnitQuaternion;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use std::path::Path;
use std::sync::Arc;

/// Settings of the data set.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetConfig {
    /// Number of objects (≥ 1).
    pub count: usize,
    /// The rig (default: `thesis-in-plane` at 480×270, same field of view).
    pub rig: Rig,
    /// Largest extent of each object in mm.
    pub size_mm: f64,
    /// Seed of the shapes and poses.
    pub seed: u64,
}

impl DatasetConfig {
    /// The thesis defaults: in-plane rig at 480×270, 120 mm objects.
    pub fn thesis(count: usize, seed: u64) -> Self {
        let mut rig = Rig::preset("thesis-in-plane").unwrap_or_else(|| Rig {
            camera: meb_core::rig::Camera {
                width: 480,
                height: 270,
                fps: 960.0,
                distance_mm: 460.0,
                fov_deg: Some(43.0),
                pixel_pitch_mm: None,
                intrinsics: None,
                axis_px: None,
            },
            leds: Vec::new(),
            tof_camera: None,
        });
        rig.camera.width = 480;
        rig.camera.height = 270;
        Self {
            count,
            rig,
            size_mm: 120.0,
            seed,
        }
    }
}

#[derive(Serialize)]
struct LightVectors {
    /// g·L_i(0), one per LED (docs/maths/photometric-stereo.md#light-vectors distant-light model
    /// with the simulator's gain).
    light_vectors: Vec<[f64; 3]>,
    /// LED positions in mm.
    positions_mm: Vec<[f64; 3]>,
    /// The gain g.
    gain: f64,
}

#[derive(Serialize)]
struct DatasetIndex {
    count: usize,
    seed: u64,
    size_mm: f64,
    width: usize,
    height: usize,
    pitch_mm: f64,
    objects: Vec<String>,
}

/// Writes the data set into the existing folder `dir` (one the caller replaces atomically);
/// `progress(done, total)` after each object.
pub fn write_dataset(
    config: &DatasetConfig,
    dir: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), SimulateError> {
    if config.count == 0 {
        return Err(SimulateError::Invalid {
            field: "count".into(),
            reason: "must be at least 1".into(),
        });
    }
    if !(config.size_mm.is_finite() && config.size_mm > 0.0) {
        return Err(SimulateError::Invalid {
            field: "size-mm".into(),
            reason: "must be a positive number".into(),
        });
    }
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let mut names = Vec::with_capacity(config.count);
    let sim = SimConfig {
        frames: 1,
        noise: NoiseModel::NONE,
        phases_chips: Some(vec![0.0; config.rig.leds.len()]),
        ..SimConfig::default()
    };
    for k in 0..config.count {
        let mesh = crate::mesh::blobby(rng.random(), config.size_mm);
        let mut object = SceneObject::new(Shape::Mesh(Arc::new(mesh)));
        object.rotation = UnitQuaternion::from_euler_angles(
            rng.random_range(-0.6..0.6),
            rng.random_range(-0.6..0.6),
            rng.random_range(0.0..std::f64::consts::TAU),
        );
        let capture =
            SimulatedCapture::new(config.rig.clone(), Scene::single(object), sim.clone())?;
        let truth = capture.truth_at(0.0);
        let name = format!("object_{k:04}");
        let odir = dir.join(&name);
        std::fs::create_dir(&odir).map_err(|e| FilesError::write(&odir, e))?;
        for (i, image) in truth.led_true.images.iter().enumerate() {
            write_npy(&odir.join(format!("led{}.npy", i + 1)), image)?;
        }
        write_npy(&odir.join("depth.npy"), &truth.depth_mm)?;
        write_npy(&odir.join("normals.npy"), &truth.normals)?;
        write_npy(&odir.join("albedo.npy"), &truth.albedo)?;
        write_mask(&odir.join("mask.png"), &truth.mask)?;
        let gain = capture.info().gain;
        let lights = LightVectors {
            light_vectors: config
                .rig
                .distant_light_vectors()
                .iter()
                .map(|l| (l * gain).into())
                .collect(),
            positions_mm: config.rig.leds.iter().map(|l| l.position_mm).collect(),
            gain,
        };
        write_json(&odir.join("light_vectors.json"), &lights)?;
        names.push(name);
        progress(k + 1, config.count);
    }
    let rig_path = dir.join("rig.toml");
    std::fs::write(&rig_path, config.rig.to_toml_string())
        .map_err(|e| FilesError::write(&rig_path, e))?;
    let index = DatasetIndex {
        count: config.count,
        seed: config.seed,
        size_mm: config.size_mm,
        width: config.rig.camera.width,
        height: config.rig.camera.height,
        pitch_mm: config.rig.camera.pitch_mm(),
        objects: names,
    };
    write_json(&dir.join("dataset.json"), &index)
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<(), SimulateError> {
    let text = serde_json::to_string_pretty(value).map_err(|e| FilesError::Encode {
        path: path.to_path_buf(),
        source: Box::new(e),
    })?;
    std::fs::write(path, text).map_err(|e| FilesError::write(path, e).into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dataset_objects_fit_the_frame_and_are_lit() {
        let mut config = DatasetConfig::thesis(2, 5);
        config.rig.camera.width = 96;
        config.rig.camera.height = 54;
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path();
        write_dataset(&config, out, &mut |_, _| {}).unwrap();
        for name in ["object_0000", "object_0001"] {
            let mask = image::open(out.join(name).join("mask.png"))
                .unwrap()
                .to_luma8();
            let inside = mask.pixels().filter(|p| p.0[0] == 255).count();
            assert!(inside > 300, "{name}: {inside} mask pixels");
            let border = (0..96).any(|c| mask.get_pixel(c, 0).0[0] == 255);
            assert!(!border, "{name} touches the top edge");
            let led: ndarray::Array2<f32> =
                ndarray_npy::read_npy(out.join(name).join("led1.npy")).unwrap();
            assert!(led.iter().any(|&v| v > 0.1));
        }
        assert!(out.join("dataset.json").exists());
    }
}
