//! Order statistics shared by several stages: quantiles and medians of image values.
//!
//! Quantiles use the nearest-rank rule on the finite values, index round((n − 1)·q) of the
//! sorted values (Hyndman & Fan, "Sample quantiles in statistical packages", 1996, definition 3
//! up to the rounding convention), found by selection (`select_nth_unstable`, O(n)) instead of
//! a full sort. Non-finite values (NaN marks "no data" throughout the pipeline) are ignored.

/// The `q`-quantile (`q` clamped to [0, 1]) of the finite `values`, or `None` when there are
/// none.
pub fn quantile(values: impl IntoIterator<Item = f32>, q: f64) -> Option<f32> {
    let mut finite: Vec<f32> = values.into_iter().filter(|v| v.is_finite()).collect();
    quantile_in_place(&mut finite, q)
}

/// The `q`-quantile of `values`, which must all be finite; reorders `values`. `None` when empty.
pub fn quantile_in_place(values: &mut [f32], q: f64) -> Option<f32> {
    if values.is_empty() {
        return None;
    }
    let index = ((values.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    let (_, value, _) = values.select_nth_unstable_by(index, f32::total_cmp);
    Some(*value)
}

/// The median of the finite `values` (the upper one of the middle two for an even count), or
/// `None` when there are none.
pub fn median(values: impl IntoIterator<Item = f32>) -> Option<f32> {
    quantile(values, 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_ignore_non_finite_values() {
        let values = [5.0, f32::NAN, 1.0, 3.0, f32::INFINITY, 2.0, 4.0];
        assert_eq!(quantile(values, 0.0), Some(1.0));
        assert_eq!(quantile(values, 1.0), Some(5.0));
        assert_eq!(median(values), Some(3.0));
        assert_eq!(quantile(values, 0.75), Some(4.0));
        assert_eq!(quantile([f32::NAN], 0.5), None);
        assert_eq!(median([2.0, 1.0]), Some(2.0));
    }

    #[test]
    fn quantile_matches_a_sort_on_random_values() {
        let values: Vec<f32> = (0..1001).map(|i| ((i * 7919) % 1001) as f32).collect();
        for q in [0.01f64, 0.5, 0.99, 0.995] {
            let expected = (1000.0 * q).round() as f32;
            assert_eq!(
                quantile(values.iter().copied(), q),
                Some(expected),
                "q = {q}"
            );
        }
    }
}
