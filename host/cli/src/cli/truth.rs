//! What `meb reconstruct` works from — the rig, the decoded capture, an optional mask and
//! ground truth — and the comparison of a result with that truth. Shared by the plain command
//! ([`super::reconstruct`]) and its per-object ToF mode ([`super::hybrid`]).

use anyhow::{Context, Result, bail, ensure};
use meb_core::io::read_float;
use meb_core::metrics::{
    AngularErrors, DepthErrors, compare_depth, compare_normals, load_mesh_triangles,
    normals_from_depth, render_mesh_depth,
};
use meb_core::rig::Rig;
use meb_pipeline::demod::Decoded;
use ndarray::{Array2, Array3, Ix2};
use std::path::Path;

/// Ground-truth depth and normals on the camera grid.
pub struct Truth {
    /// Depth, mm (NaN = background).
    pub depth: Array2<f32>,
    /// Unit normals, H×W×3.
    pub normals: Array3<f32>,
}

/// What `meb reconstruct` reads: the rig, the decoded capture and the optional mask and truth.
pub struct Inputs {
    /// The rig.
    pub rig: Rig,
    /// The decoded capture.
    pub decoded: Decoded,
    /// Whether INPUT was a `meb decode` folder (else a capture decoded here).
    pub from_folder: bool,
    /// The object mask given with --mask.
    pub mask: Option<Array2<bool>>,
    /// The ground truth on the camera grid.
    pub truth: Option<Truth>,
}

/// Loads ground truth from a depth `.npy` or renders a mesh in the rig's camera.
pub fn load_truth(path: &Path, rig: &Rig, shape: (usize, usize)) -> Result<Truth> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let truth = match ext.as_str() {
        "npy" => {
            let depth = read_float::<Ix2>(path, &[Some(shape.0), Some(shape.1)])
                .context("expected a ground-truth depth map in mm (NaN = background)")?;
            let normals = normals_from_depth(&depth, rig.camera.pitch_mm());
            Truth { depth, normals }
        }
        "stl" | "obj" => {
            let triangles = load_mesh_triangles(path)
                .with_context(|| format!("reading ground-truth mesh {}", path.display()))?;
            let rendered = render_mesh_depth(&triangles, &rig.camera);
            Truth {
                depth: rendered.depth_mm,
                normals: rendered.normals,
            }
        }
        _ => bail!(
            "ground truth {} must be a depth .npy or an .stl/.obj mesh",
            path.display()
        ),
    };
    ensure!(
        truth.depth.dim() == shape,
        "ground truth {} is {}x{} but the images are {}x{}",
        path.display(),
        truth.depth.dim().1,
        truth.depth.dim().0,
        shape.1,
        shape.0
    );
    ensure!(
        truth.depth.iter().any(|z| z.is_finite()),
        "ground truth {} has no finite depth",
        path.display()
    );
    Ok(truth)
}

/// Depth and normal errors against the truth, over the truth's surface.
pub fn compare(
    truth: &Truth,
    field: &meb_core::types::NormalField,
    depth: &Array2<f32>,
) -> Result<(Option<DepthErrors>, Option<AngularErrors>)> {
    let depth_errors =
        compare_depth(depth, &truth.depth, None).context("comparing depth with ground truth")?;
    let both = Array2::from_shape_fn(truth.depth.dim(), |(r, c)| {
        field.mask[(r, c)] && (0..3).all(|j| truth.normals[(r, c, j)].is_finite())
    });
    let angular = if both.iter().any(|&m| m) {
        Some(
            compare_normals(&field.normals, &truth.normals, &both)
                .context("comparing normals with ground truth")?,
        )
    } else {
        None
    };
    Ok((Some(depth_errors), angular))
}
