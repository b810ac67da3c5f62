//! Scenes shared by the benches: the thesis' dynamic test object (Ch. 5), simulated once here
//! for `video.rs` (a whole window through `meb video`) and `integrate.rs` (its integration).

use meb_core::capture::{Frame, FrameFormat, FrameSource};
use meb_core::rig::Rig;
use meb_sim::{Scene, SceneObject, SimConfig, SimulatedCapture, Spin};
use nalgebra::Vector3;

/// `frames` camera frames of the 100×60×60 mm ellipsoid turning at 7.5 rpm about the y axis,
/// seen by `rig` (the thesis-dynamic rig in both benches); `None` when the simulator refuses.
pub fn turning_ellipsoid(rig: &Rig, frames: usize) -> Option<(FrameFormat, Vec<Frame>)> {
    let mut object = SceneObject::ellipsoid([100.0, 60.0, 60.0]);
    object.spin = Some(Spin {
        axis: Vector3::y_axis(),
        rpm: 7.5,
    });
    let config = SimConfig {
        frames,
        ..SimConfig::default()
    };
    let mut capture = SimulatedCapture::new(rig.clone(), Scene::single(object), config).ok()?;
    let format = capture.format().clone();
    let mut clip = Vec::new();
    while let Ok(Some(frame)) = capture.next_frame() {
        clip.push(frame);
    }
    Some((format, clip))
}
