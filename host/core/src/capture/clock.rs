//! The camera's frame clock as a container's timestamps show it.
//!
//! A video container stamps each frame with its presentation time. At a constant frame rate
//! the stamps are one frame period p apart; a camera that dropped frames leaves an interval of
//! m·p (m − 1 frames missing); a variable frame rate leaves intervals that are no whole
//! number of periods. The decoder samples every carrier at frame times j·p, so a gap is a
//! timing break it re-aligns (it finds breaks from the data as well), and irregular intervals
//! are a clock it cannot model.
//!
//! p is the median interval. An interval counts as m periods when it lies within
//! [`TOLERANCE`]·p of m·p, widened to 1.5 ticks of the container's time base when that is
//! coarser; when the tolerance reaches half a period the stamps cannot tell a gap from jitter
//! and nothing is judged.

use serde::{Deserialize, Serialize};

/// An interval within this fraction of a period of a whole number of periods counts as one.
pub const TOLERANCE: f64 = 0.25;

/// Frames a container's timestamps show missing before one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TimestampGap {
    /// The frame after the gap, counted from the file's first frame.
    pub frame: usize,
    /// Frame periods missing before it.
    pub missing: usize,
}

/// What a container's timestamps say about the camera's frame clock.
#[derive(Debug, Clone, PartialEq)]
pub enum FrameClock {
    /// Every interval is one period (or the stamps are too coarse or too few to tell).
    Regular,
    /// Whole frame periods are missing at these frames; every other interval is one period.
    Gaps(Vec<TimestampGap>),
    /// An interval is no whole number of periods: a variable frame rate.
    Irregular {
        /// The frame after the first such interval, counted from the file's first frame.
        frame: usize,
        /// That interval in frame periods.
        periods: f64,
        /// The median frame period, seconds.
        period_s: f64,
    },
}

impl FrameClock {
    /// Judges presentation `times` (seconds, in presentation order) stamped with a time base
    /// of `tick` seconds (0 when unknown).
    pub fn judge(times: &[f64], tick: f64) -> Self {
        let intervals: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
        let mut sorted: Vec<f64> = intervals
            .iter()
            .copied()
            .filter(|d| d.is_finite())
            .collect();
        if sorted.len() < 2 || sorted.len() != intervals.len() {
            return Self::Regular;
        }
        sorted.sort_by(f64::total_cmp);
        let period = sorted[sorted.len() / 2];
        let tolerance = (TOLERANCE * period).max(1.5 * tick.max(0.0));
        if period <= 0.0 || tolerance >= 0.5 * period {
            return Self::Regular;
        }
        let mut gaps = Vec::new();
        for (j, &d) in intervals.iter().enumerate() {
            let periods = d / period;
            let whole = periods.round();
            if whole < 1.0 || (d - whole * period).abs() > tolerance {
                return Self::Irregular {
                    frame: j + 1,
                    periods,
                    period_s: period,
                };
            }
            if whole >= 2.0 {
                gaps.push(TimestampGap {
                    frame: j + 1,
                    missing: whole as usize - 1,
                });
            }
        }
        if gaps.is_empty() {
            Self::Regular
        } else {
            Self::Gaps(gaps)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stamps(period: f64, offsets: &[(usize, f64)], n: usize) -> Vec<f64> {
        (0..n)
            .map(|j| {
                let shift: f64 = offsets
                    .iter()
                    .filter(|(at, _)| j >= *at)
                    .map(|(_, by)| by)
                    .sum();
                (j as f64 + shift) * period
            })
            .collect()
    }

    #[test]
    fn a_constant_rate_is_regular_and_a_missing_frame_is_a_gap() {
        let p = 1.0 / 960.0;
        assert_eq!(
            FrameClock::judge(&stamps(p, &[], 100), 1e-6),
            FrameClock::Regular
        );
        assert_eq!(
            FrameClock::judge(&stamps(p, &[(60, 1.0), (80, 2.0)], 100), 1e-6),
            FrameClock::Gaps(vec![
                TimestampGap {
                    frame: 60,
                    missing: 1
                },
                TimestampGap {
                    frame: 80,
                    missing: 2
                }
            ])
        );
    }

    #[test]
    fn an_interval_of_no_whole_number_of_periods_is_irregular() {
        let p = 1.0 / 960.0;
        match FrameClock::judge(&stamps(p, &[(40, 0.5)], 100), 1e-6) {
            FrameClock::Irregular { frame, periods, .. } => {
                assert_eq!(frame, 40);
                assert!((periods - 1.5).abs() < 1e-9, "{periods}");
            }
            other => panic!("{other:?}"),
        }
        // Two frames stamped at one time.
        assert!(matches!(
            FrameClock::judge(&stamps(p, &[(30, -1.0)], 100), 1e-6),
            FrameClock::Irregular { frame: 30, .. }
        ));
    }

    #[test]
    fn stamps_too_coarse_or_too_few_to_tell_are_not_judged() {
        // A 1 ms time base cannot show a 960 fps clock's gaps from its rounding.
        let p = 1.0 / 960.0;
        let rounded: Vec<f64> = stamps(p, &[(40, 0.5)], 100)
            .iter()
            .map(|t| (t * 1000.0).round() / 1000.0)
            .collect();
        assert_eq!(FrameClock::judge(&rounded, 1e-3), FrameClock::Regular);
        assert_eq!(FrameClock::judge(&[0.0, 0.1], 0.0), FrameClock::Regular);
        assert_eq!(
            FrameClock::judge(&[0.0, f64::NAN, 0.2, 0.3], 0.0),
            FrameClock::Regular
        );
    }
}
