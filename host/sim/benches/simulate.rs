//! Simulator speed: one 1280×720 frame of the default sphere (target: 128 frames well under a
//! minute), and the per-geometry shading a spinning scene pays every frame.

use criterion::{Criterion, criterion_group, criterion_main};
use meb_core::rig::Rig;
use meb_sim::{Scene, SceneObject, SimConfig, SimulatedCapture, Spin};
use nalgebra::Vector3;

fn capture(spinning: bool) -> Option<SimulatedCapture> {
    let rig = Rig::preset("thesis-out-of-plane")?;
    let mut object = SceneObject::ellipsoid([100.0, 60.0, 60.0]);
    if spinning {
        object.spin = Some(Spin {
            axis: Vector3::y_axis(),
            rpm: 7.5,
        });
    }
    SimulatedCapture::new(rig, Scene::single(object), SimConfig::default()).ok()
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("simulate_1280x720");
    group.sample_size(10);
    if let Some(still) = capture(false) {
        group.bench_function("frame_static", |b| b.iter(|| still.render_frame(7)));
    }
    if let Some(moving) = capture(true) {
        group.bench_function("frame_spinning", |b| b.iter(|| moving.render_frame(7)));
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
