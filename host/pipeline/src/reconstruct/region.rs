//! Reconstructions of part of the camera's frame: `meb video` decodes a window only around the
//! object ([`crate::video::focus`]) and reconstructs it there ([`super::Request::region`]). The
//! result keeps the region's arrays; what a caller needs of the whole frame (the depth, and
//! normals or albedo when they are saved) is pasted into it on request. Pasting every array
//! (≈ 40 MB at 1280×720) took 1.9–2.3 ms of each window's reconstruction in `meb video`.

use super::roi::Roi;
use super::{
    ReconstructConfig, ReconstructError, Reconstruction, Request, Source, WarmStart, reconstruct,
};
use meb_core::rig::{Projection, Rig};
use ndarray::{Array2, Array3};

/// A reconstruction on the camera cut to a region of its frame ([`super::Request::region`]).
#[derive(Debug, Clone)]
pub struct RegionReconstruction {
    roi: Roi,
    /// The reconstruction of the region: its arrays are the region's size, its pixel indices
    /// count from the region's corner.
    pub reconstruction: Reconstruction,
}

impl RegionReconstruction {
    /// `reconstruction` of the camera cut to `roi`.
    pub(super) fn new(roi: Roi, reconstruction: Reconstruction) -> Self {
        Self {
            roi,
            reconstruction,
        }
    }

    /// The region of the frame.
    pub fn region(&self) -> crate::demod::Roi {
        crate::demod::Roi {
            x: self.roi.cols.start,
            y: self.roi.rows.start,
            width: self.roi.cols.len(),
            height: self.roi.rows.len(),
        }
    }

    /// `array` (of the region's size) inside the region of a frame-sized array holding
    /// `outside` elsewhere.
    pub fn in_frame<T: Copy + Send + Sync>(&self, array: &Array2<T>, outside: T) -> Array2<T> {
        self.roi.paste2(array, outside)
    }

    /// Per-pixel vectors (rows, columns, channels; of the region's size) in a frame-sized
    /// array, NaN outside the region.
    pub fn vectors_in_frame(&self, array: &Array3<f32>) -> Array3<f32> {
        self.roi.paste3(array, f32::NAN)
    }

    /// The depth in mm over the whole frame, NaN outside the region.
    pub fn depth_in_frame(&self) -> Array2<f32> {
        self.in_frame(&self.reconstruction.integration.depth.depth_mm, f32::NAN)
    }

    /// Every result pasted into the frame: pixel indices moved by the region's corner and the
    /// depth's projection the frame's. Outside the region the results hold what a full-frame
    /// reconstruction leaves outside its object.
    pub fn into_frame(self, projection: &Projection) -> Reconstruction {
        let inner = self.reconstruction;
        let (photometric, integration) =
            self.roi
                .paste(inner.photometric, inner.integration, projection);
        Reconstruction {
            photometric,
            integration,
            ..inner
        }
    }
}

/// A reconstruction of the camera's whole frame, or of the region of interest its warm passes
/// ran in, kept there ([`super::reconstruct_extent`]). A warm window of `meb video` decoded
/// over the whole frame (its first windows, and one in [`crate::video::FULL_FRAME_EVERY`])
/// spent 11–12 ms of its reconstruction pasting every array of the region into the frame at
/// 1280×720.
#[derive(Debug, Clone)]
pub enum Extent {
    /// The whole frame.
    Frame(Reconstruction),
    /// A region of it.
    Region(RegionReconstruction),
}

impl Extent {
    /// The reconstruction of the whole frame, a region's pasted into it
    /// ([`RegionReconstruction::into_frame`]; timed as "full frame from the region, warm").
    pub fn into_frame(self, projection: &Projection) -> Reconstruction {
        match self {
            Self::Frame(reconstruction) => reconstruction,
            Self::Region(region) => {
                let started = std::time::Instant::now();
                let mut reconstruction = region.into_frame(projection);
                reconstruction.timings.push(super::StageTiming::since(
                    "full frame from the region, warm".to_string(),
                    started,
                ));
                reconstruction
            }
        }
    }
}

/// [`super::reconstruct`] of a source covering only `region` of `rig`'s camera
/// ([`super::Request::region`]): the camera and the warm start cut to the region, the object
/// refused when it reaches an edge of the region inside the frame.
pub(super) fn in_region(
    source: Source<'_>,
    region: crate::demod::Roi,
    rig: &Rig,
    config: &ReconstructConfig,
    request: Request<'_>,
) -> Result<RegionReconstruction, ReconstructError> {
    let frame = (rig.camera.height, rig.camera.width);
    let Some(roi) = Roi::of_rect(region, frame) else {
        return Err(ReconstructError::Region(format!(
            "{}x{}+{}+{} does not lie inside the camera's {}x{} frame",
            region.width, region.height, region.x, region.y, frame.1, frame.0
        )));
    };
    let region_rig = roi.cut_rig(rig);
    let region_warm = request
        .warm
        .filter(|w| w.depth_mm.dim() == frame)
        .map(|w| WarmStart {
            depth_mm: roi.cut(&w.depth_mm),
            glossy: w.glossy,
        });
    let region_request = Request {
        warm: region_warm.as_ref(),
        region: None,
        ..request
    };
    let reconstruction = reconstruct(source, &region_rig, config, region_request)?;
    if roi.reached_edge(&reconstruction.photometric.object_mask) {
        return Err(ReconstructError::Region(format!(
            "the object reaches an edge of the decoded region {}x{}+{}+{} inside the frame and \
             may go on beyond it (decode the whole frame)",
            region.width, region.height, region.x, region.y
        )));
    }
    Ok(RegionReconstruction {
        roi,
        reconstruction,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demod::Decoded;
    use crate::reconstruct::tests::{
        StillSphere, largest_depth_difference, still_sphere, synthetic_decode,
    };

    /// The still sphere (320×180) decoded whole, and the same decode cut to `rect`.
    fn sphere_decodes(rect: crate::demod::Roi) -> (Decoded, Decoded, StillSphere) {
        let sphere = still_sphere();
        let mut whole = synthetic_decode();
        whole.leds = sphere.images.clone();
        whole.noise = sphere.noise.clone();
        whole.saturated = Array2::from_elem(sphere.noise.dim(), false);
        whole.underexposed = whole.saturated.clone();
        let roi = Roi::of_rect(rect, sphere.noise.dim()).expect("inside the frame");
        let mut cut = whole.clone();
        cut.leds = roi.cut_images(&whole.leds);
        cut.noise = roi.cut(&whole.noise);
        cut.saturated = roi.cut(&whole.saturated);
        cut.underexposed = roi.cut(&whole.underexposed);
        (whole, cut, sphere)
    }

    /// A region's reconstruction keeps the region's arrays; pasted into the frame (all of it,
    /// or the depth, normals and albedo one by one) it is the whole frame's reconstruction.
    #[test]
    fn a_region_pasted_into_the_frame_is_the_whole_frames_reconstruction() {
        let rect = crate::demod::Roi {
            x: 60,
            y: 20,
            width: 200,
            height: 140,
        };
        let (whole, cut, sphere) = sphere_decodes(rect);
        let warm = Some(&sphere.warm);
        let request = Request {
            warm,
            ..Request::default()
        };
        let region = in_region(
            Source::Decoded(&cut),
            rect,
            &sphere.rig,
            &sphere.config,
            request,
        )
        .expect("the sphere lies inside the region");
        assert_eq!(region.region(), rect);
        let depth = &region.reconstruction.integration.depth.depth_mm;
        assert_eq!(depth.dim(), (140, 200));
        let framed = region.depth_in_frame();
        let normals = &region.reconstruction.photometric.field.normals;
        let framed_normals = region.vectors_in_frame(normals);
        let albedo = &region.reconstruction.photometric.field.albedo;
        let framed_albedo = region.in_frame(albedo, f32::NAN);
        let full = region.clone().into_frame(&sphere.rig.camera.projection());
        let bits2 = |a: &Array2<f32>| a.mapv(f32::to_bits);
        assert_eq!(bits2(&framed), bits2(&full.integration.depth.depth_mm));
        assert_eq!(
            framed_normals.mapv(f32::to_bits),
            full.photometric.field.normals.mapv(f32::to_bits)
        );
        assert_eq!(bits2(&framed_albedo), bits2(&full.photometric.field.albedo));
        // Outside the region: nothing; inside: the region's own values.
        assert!(framed[(10, 10)].is_nan() && framed[(170, 300)].is_nan());
        assert_eq!(framed[(90, 160)].to_bits(), depth[(70, 100)].to_bits());
        let from_whole = reconstruct(
            Source::Decoded(&whole),
            &sphere.rig,
            &sphere.config,
            Request {
                warm,
                ..Request::default()
            },
        )
        .expect("the whole frame");
        let worst = largest_depth_difference(&framed, &from_whole.integration.depth.depth_mm);
        assert!(worst < 1e-3, "region vs whole frame: {worst} mm");
    }

    /// A whole-frame decode's warm window runs in its region of interest and stays there
    /// ([`Extent::Region`]); pasted into the frame it is what [`reconstruct`] returns, bit
    /// for bit, while a cold window is the whole frame's.
    #[test]
    fn a_warm_window_of_a_whole_decode_keeps_its_region() {
        let rect = crate::demod::Roi {
            x: 0,
            y: 0,
            width: 320,
            height: 180,
        };
        let (whole, _, sphere) = sphere_decodes(rect);
        let warm = Some(&sphere.warm);
        let extent = super::super::reconstruct_extent(
            Source::Decoded(&whole),
            &sphere.rig,
            &sphere.config,
            Request {
                warm,
                ..Request::default()
            },
        )
        .expect("warm");
        let Extent::Region(region) = extent.clone() else {
            panic!("the warm window was not kept in its region");
        };
        let r = region.region();
        assert!(r.width < 320 && r.height < 180, "{r:?}");
        let depth = &region.reconstruction.integration.depth.depth_mm;
        assert_eq!(depth.dim(), (r.height, r.width));
        let pasted = extent.into_frame(&sphere.rig.camera.projection());
        let framed = reconstruct(
            Source::Decoded(&whole),
            &sphere.rig,
            &sphere.config,
            Request {
                warm,
                ..Request::default()
            },
        )
        .expect("warm, in the frame");
        let bits2 = |a: &Array2<f32>| a.mapv(f32::to_bits);
        assert_eq!(
            bits2(&pasted.integration.depth.depth_mm),
            bits2(&framed.integration.depth.depth_mm)
        );
        assert_eq!(
            pasted.photometric.field.normals.mapv(f32::to_bits),
            framed.photometric.field.normals.mapv(f32::to_bits)
        );
        assert_eq!(
            pasted.photometric.object_mask,
            framed.photometric.object_mask
        );
        assert_eq!(pasted.integration.confidence, framed.integration.confidence);
        assert!(
            pasted
                .timings
                .iter()
                .any(|t| t.stage == "full frame from the region, warm")
        );
        let cold = super::super::reconstruct_extent(
            Source::Decoded(&whole),
            &sphere.rig,
            &sphere.config,
            Request::default(),
        )
        .expect("cold");
        assert!(
            matches!(cold, Extent::Frame(_)),
            "a cold window is the frame's"
        );
    }
}
