//! Decodes and reconstructs a capture: `cargo run --release -p meb-pipeline --example
//! reconstruct_capture -- CAPTURE RIG` (a video file, a y4m, or a folder of frames; a rig TOML
//! file or a preset name such as `thesis-out-of-plane`). Without arguments it renders a small
//! capture of a sphere under the thesis' out-of-plane rig with the simulator first.

use meb_core::capture::{FrameSource, OpenOptions, open};
use meb_core::rig::Rig;
use meb_pipeline::demod::{DecodeConfig, decode};
use meb_pipeline::reconstruct::{ReconstructConfig, Request, Source, reconstruct};
use meb_sim::{Scene, SceneObject, SimConfig, SimulatedCapture};
use std::error::Error;
use std::path::Path;

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (mut frames, rig): (Box<dyn FrameSource>, Rig) = match args.as_slice() {
        [capture, rig] => (
            open(Path::new(capture), &OpenOptions::default())?,
            Rig::load(rig)?,
        ),
        _ => {
            let mut rig = Rig::preset("thesis-out-of-plane").ok_or("no such preset")?;
            (rig.camera.width, rig.camera.height) = (320, 180);
            let scene = Scene::single(SceneObject::sphere(48.0));
            let config = SimConfig {
                frames: 64,
                ..SimConfig::default()
            };
            (
                Box::new(SimulatedCapture::new(rig.clone(), scene, config)?),
                rig,
            )
        }
    };
    let decoded = decode(frames.as_mut(), &DecodeConfig::default(), &mut |_, _| {})?;
    let verdict = &decoded.report.verdict;
    println!("decode: {:?} {:?}", verdict.status, verdict.problems);
    let config = ReconstructConfig::decoded_capture();
    let result = reconstruct(Source::Decoded(&decoded), &rig, &config, Request::default())?;
    let depth = &result.integration.depth.depth_mm;
    let known = depth.iter().filter(|z| z.is_finite()).count();
    let verdict = &result.support.verdict;
    println!(
        "{known} pixels of depth: {:?} {:?}",
        verdict.status, verdict.problems
    );
    Ok(())
}
