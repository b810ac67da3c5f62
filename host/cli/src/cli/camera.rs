//! The camera a normal map was seen through, for `meb integrate` and `meb photometric`:
//! orthographic (`--pitch`) or a pinhole (`--intrinsics`, `--rig`), and what the written depth
//! then means (docs/maths/coordinates.md#what-depthnpy-holds).

use anyhow::{Context, Result, bail, ensure};
use clap::Args;
use meb_core::datasets::normal_maps::read_intrinsics_matrix;
use meb_core::rig::{Intrinsics, Projection, Rig};
use std::path::Path;

/// Camera arguments shared by the commands that integrate normals.
#[derive(Args, Debug, Clone, Default)]
pub struct CameraArgs {
    /// Orthographic camera: grid pitch in mm per pixel.
    #[arg(long, conflicts_with_all = ["intrinsics", "rig"])]
    pub pitch: Option<f64>,
    /// Pinhole camera: "fx,fy,cx,cy" or "fx,fy,cx,cy,k1,k2" in pixels (OpenCV convention: rows down, pixel
    /// centres at integer coordinates; k1, k2 radial distortion), or a 3×3 matrix file (K.txt).
    #[arg(long, conflicts_with = "rig")]
    pub intrinsics: Option<String>,
    /// The camera of a rig file or preset (perspective when it has intrinsics).
    #[arg(long)]
    pub rig: Option<String>,
    /// Pinhole camera: distance in mm from the camera centre, along the optical axis, to the
    /// object's outline (sets the scale of the depth, which normals cannot measure; --rig: the
    /// rig's camera distance).
    #[arg(long)]
    pub distance: Option<f64>,
}

/// The camera and what is known of the depth's scale and offset.
#[derive(Debug, Clone)]
pub struct CameraChoice {
    /// The projection handed to the integrator.
    pub projection: Projection,
    /// One line for the report: the camera.
    pub describe: String,
    /// One line for the report: what depth.npy holds and what is assumed about it.
    pub depth_convention: String,
}

impl CameraArgs {
    /// The camera of these arguments for an image of `shape` (rows, columns); `default_pitch`
    /// when none is given (None: one is required).
    pub fn choose(
        &self,
        shape: (usize, usize),
        default_pitch: Option<f64>,
    ) -> Result<CameraChoice> {
        let perspective = |intrinsics: Intrinsics, distance_mm: f64, source: &str| {
            ensure!(
                distance_mm.is_finite() && distance_mm > 0.0,
                "--distance must be a positive number of mm, got {distance_mm}"
            );
            Ok(CameraChoice {
                projection: Projection::Perspective {
                    intrinsics,
                    distance_mm,
                },
                describe: format!(
                    "perspective ({source}): fx {:.2}, fy {:.2}, cx {:.2}, cy {:.2}, k1 {}, k2 {} px; outline at {distance_mm} mm",
                    intrinsics.fx,
                    intrinsics.fy,
                    intrinsics.cx,
                    intrinsics.cy,
                    intrinsics.k1,
                    intrinsics.k2
                ),
                depth_convention: format!(
                    "scene z in mm (height towards the camera; distance along the optical axis = {distance_mm} − z); \
                     shape known up to scale about the camera centre: each piece's outline is put at {distance_mm} mm"
                ),
            })
        };
        let orthographic = |pitch_mm: f64, source: &str| {
            ensure!(
                pitch_mm.is_finite() && pitch_mm > 0.0,
                "--pitch must be a positive number of mm per pixel, got {pitch_mm}"
            );
            Ok(CameraChoice {
                projection: Projection::centred(pitch_mm, (shape.1, shape.0)),
                describe: format!("orthographic ({source}): {pitch_mm} mm per pixel"),
                depth_convention: "scene z in mm (height towards the camera); offset unknown: \
                                   each piece's outline is put at z = 0"
                    .into(),
            })
        };
        if let Some(spec) = &self.rig {
            let rig = Rig::load(spec).with_context(|| format!("cannot load rig {spec}"))?;
            let camera = &rig.camera;
            ensure!(
                (camera.height, camera.width) == shape,
                "rig {spec} has a {}x{} camera but the normals are {}x{} (rows x columns)",
                camera.height,
                camera.width,
                shape.0,
                shape.1
            );
            return match camera.projection() {
                Projection::Perspective {
                    intrinsics,
                    distance_mm,
                } => perspective(
                    intrinsics,
                    self.distance.unwrap_or(distance_mm),
                    &format!("rig {spec}"),
                ),
                Projection::Orthographic { .. } => {
                    ensure!(
                        self.distance.is_none(),
                        "--distance applies to a pinhole camera; rig {spec}'s camera is orthographic"
                    );
                    Ok(CameraChoice {
                        projection: camera.projection(),
                        ..orthographic(camera.pitch_mm(), &format!("rig {spec}"))?
                    })
                }
            };
        }
        if let Some(spec) = &self.intrinsics {
            let intrinsics = parse_intrinsics(spec)?;
            let distance = self.distance.context(
                "--intrinsics needs --distance: normals fix a perspective surface only up to its \
                 scale, so give the distance (mm) from the camera to the object's outline \
                 (any value gives the right shape up to scale)",
            )?;
            return perspective(intrinsics, distance, "intrinsics");
        }
        ensure!(
            self.distance.is_none(),
            "--distance applies to a pinhole camera (--intrinsics or --rig)"
        );
        match self.pitch.or(default_pitch) {
            Some(pitch) => orthographic(pitch, "pitch"),
            None => bail!(
                "no camera: give --pitch (orthographic, mm per pixel), --intrinsics (pinhole) or --rig"
            ),
        }
    }
}

/// Intrinsics from "fx,fy,cx,cy", "fx,fy,cx,cy,k1,k2" or a 3×3 matrix file.
pub fn parse_intrinsics(spec: &str) -> Result<Intrinsics> {
    let path = Path::new(spec);
    if path.exists() {
        return Ok(read_intrinsics_matrix(path)?);
    }
    let values: Vec<f64> = spec
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| {
            format!("--intrinsics {spec:?} is neither a file nor \"fx,fy,cx,cy[,k1,k2]\"")
        })?;
    ensure!(
        matches!(values.len(), 4 | 6) && values.iter().all(|v| v.is_finite()),
        "--intrinsics {spec:?}: expected 4 or 6 finite numbers \"fx,fy,cx,cy[,k1,k2]\""
    );
    ensure!(
        values[0] > 0.0 && values[1] > 0.0,
        "--intrinsics {spec:?}: focal lengths fx, fy must be positive"
    );
    Ok(Intrinsics {
        fx: values[0],
        fy: values[1],
        cx: values[2],
        cy: values[3],
        k1: values.get(4).copied().unwrap_or(0.0),
        k2: values.get(5).copied().unwrap_or(0.0),
    })
}
