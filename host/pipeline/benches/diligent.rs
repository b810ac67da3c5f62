//! Normal integration on real normal maps: the DiLiGenT objects of the normal-integration
//! benchmark of Cao, Lin, Matsushita & Tao, "Bilateral Normal Integration" (BiNI, ECCV 2022),
//! integrated through their pinhole cameras (`K.txt`) and scored with that benchmark's protocol
//! (mean absolute depth error, MADE, after scaling by median(d_gt / d);
//! `meb_core::datasets::normal_maps`).
//!
//! The bench first prints one table (object × integrator: MADE in mm, pixels without depth, wall
//! time of one integration, the discontinuity edges `auto` cut), then times each integration
//! with criterion. Objects: every folder with a `normal_map.png` under `MEB_DILIGENT_DIR`
//! (default: the five in `shared/data/diligent-normals`; BiNI's repository has all nine under
//! `data/Fig7_diligent`). The camera distance is 1500 mm (DiLiGenT's set-up; the score is
//! scale-free, the distance only sets the artefact filter's 10 mm in real units).
//!
//! The table of the closing note (the same run, one after the other, shared 2-core machine at
//! a load average of 15–17, so every time is 5–10× a quiet machine's) is in
//! docs/maths/integration.md#benchmark-on-real-normal-maps, with the BiNI reference implementation's
//! figures run beside it.

use criterion::{Criterion, criterion_group, criterion_main};
use meb_core::datasets::normal_maps::{
    NormalIntegrationObject, load_normal_integration_object, mean_absolute_depth_error,
};
use meb_core::rig::Projection;
use meb_core::types::NormalField;
use meb_pipeline::integrate::{
    IntegrateConfig, Integration, Integrator, SurfaceEvidence, integrate_surface,
};
use ndarray::Array2;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Camera distance handed to the integrator, mm.
const DISTANCE_MM: f64 = 1500.0;

/// The integrators compared.
const INTEGRATORS: [(&str, Integrator); 3] = [
    ("auto", Integrator::Auto),
    ("least-squares", Integrator::LeastSquares),
    ("bilateral", Integrator::Bilateral),
];

/// The objects' folders, sorted by name.
fn objects() -> Vec<(String, NormalIntegrationObject)> {
    let dir = std::env::var_os("MEB_DILIGENT_DIR").map_or_else(
        || {
            PathBuf::from(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/../../../shared/data/diligent-normals"
            ))
        },
        PathBuf::from,
    );
    let mut found: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("normal_map.png").exists())
        .collect();
    found.sort();
    found
        .into_iter()
        .map(|p| {
            let name = p
                .file_name()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned();
            let object = load_normal_integration_object(&p)
                .unwrap_or_else(|e| panic!("cannot load {}: {e}", p.display()));
            (name, object)
        })
        .collect()
}

/// Integrates one object through its camera.
fn integrate(
    object: &NormalIntegrationObject,
    field: &NormalField,
    integrator: Integrator,
) -> Integration {
    let projection = Projection::Perspective {
        intrinsics: object.intrinsics,
        distance_mm: DISTANCE_MM,
    };
    let config = IntegrateConfig {
        integrator,
        ..IntegrateConfig::default()
    };
    let evidence = SurfaceEvidence {
        field,
        planes: &[],
        fill: None,
    };
    integrate_surface(&evidence, &projection, &config, None).expect("integration")
}

/// The object's normals as a field (albedo 1).
fn field_of(object: &NormalIntegrationObject) -> NormalField {
    NormalField {
        normals: object.normals.clone(),
        albedo: Array2::from_elem(object.mask.dim(), 1.0),
        mask: object.mask.clone(),
    }
}

fn bench(c: &mut Criterion) {
    let objects = objects();
    println!("object | integrator | MADE mm | missing px | time s | edges cut, bilateral pixels");
    let mut totals = vec![(0.0, Duration::ZERO); INTEGRATORS.len()];
    for (name, object) in &objects {
        let field = field_of(object);
        for (i, (label, integrator)) in INTEGRATORS.iter().enumerate() {
            let start = Instant::now();
            let out = integrate(object, &field, *integrator);
            let elapsed = start.elapsed();
            // Distance along the optical axis: D − z.
            let distance = out.depth.depth_mm.mapv(|z| DISTANCE_MM as f32 - z);
            let score = mean_absolute_depth_error(&distance, &object.depth_gt, &object.mask)
                .expect("some depth");
            totals[i].0 += score.made;
            totals[i].1 += elapsed;
            println!(
                "{name} | {label} | {:.3} | {} | {:.2} | {:?}, {:?}",
                score.made,
                score.missing,
                elapsed.as_secs_f64(),
                out.discontinuity_edges,
                out.bilateral_pixels
            );
        }
    }
    for ((label, _), (made, time)) in INTEGRATORS.iter().zip(&totals) {
        println!(
            "mean | {label} | {:.3} | | total {:.2} |",
            made / objects.len() as f64,
            time.as_secs_f64()
        );
    }
    let mut group = c.benchmark_group("diligent");
    group.sample_size(10);
    for (name, object) in &objects {
        let field = field_of(object);
        for (label, integrator) in INTEGRATORS {
            group.bench_function(format!("{name}/{label}"), |b| {
                b.iter(|| integrate(object, &field, integrator));
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
