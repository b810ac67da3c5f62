//! The thesis' artefact filter: drop grid points whose depth jumps more than a threshold
//! (10 mm) from a 4-neighbour, and report the fraction of the surface kept
//! (docs/maths/integration.md#the-artefact-filter).

use ndarray::Array2;

/// Settings of the artefact filter.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ArtefactFilter {
    /// Largest depth step between neighbours in mm; `None` disables the filter.
    pub max_jump_mm: Option<f64>,
}

impl Default for ArtefactFilter {
    fn default() -> Self {
        Self {
            max_jump_mm: Some(10.0),
        }
    }
}

/// Returns the kept pixels of `valid` and the fraction kept: both ends of every step larger than
/// the threshold are dropped.
pub fn filter_artefacts(
    depth: &Array2<f64>,
    valid: &Array2<bool>,
    filter: &ArtefactFilter,
) -> (Array2<bool>, f64) {
    let mut kept = valid.clone();
    if let Some(limit) = filter.max_jump_mm {
        let (rows, cols) = depth.dim();
        for r in 0..rows {
            for c in 0..cols {
                if !valid[(r, c)] {
                    continue;
                }
                for (rr, cc) in [(r + 1, c), (r, c + 1)] {
                    if rr < rows
                        && cc < cols
                        && valid[(rr, cc)]
                        && (depth[(r, c)] - depth[(rr, cc)]).abs() > limit
                    {
                        kept[(r, c)] = false;
                        kept[(rr, cc)] = false;
                    }
                }
            }
        }
    }
    let total = valid.iter().filter(|&&v| v).count();
    let n_kept = kept.iter().filter(|&&v| v).count();
    let fraction = if total == 0 {
        0.0
    } else {
        n_kept as f64 / total as f64
    };
    (kept, fraction)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drops_both_sides_of_a_cliff() {
        let depth = Array2::from_shape_fn((4, 4), |(_, c)| if c < 2 { 0.0 } else { 20.0 });
        let valid = Array2::from_elem((4, 4), true);
        let (kept, frac) = filter_artefacts(&depth, &valid, &ArtefactFilter::default());
        assert!(kept[(0, 0)] && !kept[(0, 1)] && !kept[(0, 2)] && kept[(0, 3)]);
        assert!((frac - 0.5).abs() < 1e-12);
        let (_, all) = filter_artefacts(&depth, &valid, &ArtefactFilter { max_jump_mm: None });
        assert_eq!(all, 1.0);
    }
}
