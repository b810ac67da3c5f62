//! A window's reconstruction as `meb video` keeps it: of the whole frame, or of the region
//! around the object the window was decoded in ([`super::focus`]), whose arrays stay the
//! region's. The depth over the whole frame (the warm start of the next window, the accuracy
//! against the truth, the depth file and pictures) is pasted once; normals and albedo only when
//! they are asked for (`--save`).

use crate::reconstruct::{Extent, Reconstruction, RegionReconstruction, StageTiming};
use ndarray::{Array2, Array3};
use std::borrow::Cow;
use std::time::Instant;

/// A window's reconstruction (module docs).
#[derive(Debug, Clone)]
pub enum WindowReconstruction {
    /// Of the whole frame.
    Frame(Reconstruction),
    /// Of the window's decode region.
    Region {
        /// The region's reconstruction.
        region: RegionReconstruction,
        /// Its depth in mm over the whole frame (NaN outside the region).
        depth_mm: Array2<f32>,
    },
}

impl WindowReconstruction {
    /// A reconstruction of a region, its depth pasted into the frame (timed as a stage of its
    /// reconstruction).
    pub fn of_region(mut region: RegionReconstruction) -> Self {
        let started = Instant::now();
        let depth_mm = region.depth_in_frame();
        region.reconstruction.timings.push(StageTiming::since(
            "depth into the frame".to_string(),
            started,
        ));
        Self::Region { region, depth_mm }
    }

    /// A reconstruction of the whole frame, or of a region ([`Self::of_region`]).
    pub fn of_extent(extent: Extent) -> Self {
        match extent {
            Extent::Frame(reconstruction) => Self::Frame(reconstruction),
            Extent::Region(region) => Self::of_region(region),
        }
    }

    /// The reconstruction itself: its arrays are the region's for [`Self::Region`].
    pub fn reconstruction(&self) -> &Reconstruction {
        match self {
            Self::Frame(reconstruction) => reconstruction,
            Self::Region { region, .. } => &region.reconstruction,
        }
    }

    /// Depth in mm over the whole frame (NaN where nothing was reconstructed).
    pub fn depth_mm(&self) -> &Array2<f32> {
        match self {
            Self::Frame(reconstruction) => &reconstruction.integration.depth.depth_mm,
            Self::Region { depth_mm, .. } => depth_mm,
        }
    }

    /// Its depth over the whole frame, moved out (the next window's warm start).
    pub fn into_depth_mm(self) -> Array2<f32> {
        match self {
            Self::Frame(reconstruction) => reconstruction.integration.depth.depth_mm,
            Self::Region { depth_mm, .. } => depth_mm,
        }
    }

    /// Measured normals over the whole frame (rows, columns, xyz; NaN where none).
    pub fn normals(&self) -> Cow<'_, Array3<f32>> {
        match self {
            Self::Frame(reconstruction) => Cow::Borrowed(&reconstruction.photometric.field.normals),
            Self::Region { region, .. } => Cow::Owned(
                region.vectors_in_frame(&region.reconstruction.photometric.field.normals),
            ),
        }
    }

    /// Albedo over the whole frame (NaN where none).
    pub fn albedo(&self) -> Cow<'_, Array2<f32>> {
        match self {
            Self::Frame(reconstruction) => Cow::Borrowed(&reconstruction.photometric.field.albedo),
            Self::Region { region, .. } => Cow::Owned(
                region.in_frame(&region.reconstruction.photometric.field.albedo, f32::NAN),
            ),
        }
    }
}
