//! Where the 3-D frames of a video come from: windows of camera frames (thesis Ch. 5,
//! Fig. 5.5).
//!
//! The thesis recorded 40 camera frames per position of the object (1 kfps camera, 25
//! positions per second), dropped the first and last 4 so that a small misalignment between
//! the windows and the motor's steps does not mix two positions, and decoded the 32 in the
//! middle: `window 40, drop 4, hop 40`. A sliding window advances `hop` < `window` frames
//! instead (`hop 1` gives a 3-D frame per camera frame).
//!
//! Window k covers camera frames `[k·hop, k·hop + window)` and decodes
//! `[k·hop + drop, k·hop + window − drop)`.

use std::ops::Range;

/// Window length, dropped frames and hop of a video's 3-D frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct WindowSchedule {
    /// Camera frames per window.
    pub window: usize,
    /// Frames dropped at each end of a window.
    pub drop: usize,
    /// Camera frames from one window's start to the next's.
    pub hop: usize,
}

/// A schedule that cannot work.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("window {window}, drop {drop}, hop {hop}: {reason}")]
pub struct ScheduleError {
    /// Window length.
    pub window: usize,
    /// Dropped frames per end.
    pub drop: usize,
    /// Hop.
    pub hop: usize,
    /// What is wrong.
    pub reason: String,
}

impl WindowSchedule {
    /// The thesis' windows: 40 frames, 4 dropped at each end, back to back.
    pub const THESIS: Self = Self {
        window: 40,
        drop: 4,
        hop: 40,
    };

    /// A schedule that decodes at least `min_decoded` frames per window (2^(N+1) for N
    /// LEDs, docs/maths/demodulation.md#exposure-rate-ratio-and-rolling-shutter).
    pub fn new(
        window: usize,
        drop: usize,
        hop: usize,
        min_decoded: usize,
    ) -> Result<Self, ScheduleError> {
        let schedule = Self { window, drop, hop };
        let bad = |reason: String| ScheduleError {
            window,
            drop,
            hop,
            reason,
        };
        if hop == 0 {
            return Err(bad("the hop must be at least 1 frame".into()));
        }
        let Some(decoded) = window.checked_sub(drop.saturating_mul(2)) else {
            return Err(bad(format!(
                "dropping {drop} frames at each end leaves nothing of a {window}-frame window"
            )));
        };
        if decoded < min_decoded {
            return Err(bad(format!(
                "{decoded} frames are left to decode, but a 3-D frame needs at least \
                 {min_decoded} (2^(N+1) for N LEDs); lengthen the window or drop fewer frames"
            )));
        }
        Ok(schedule)
    }

    /// Frames decoded per window.
    pub fn decoded(&self) -> usize {
        self.window - 2 * self.drop
    }

    /// Camera frames of window `k`.
    pub fn frames(&self, k: usize) -> Range<usize> {
        k * self.hop..k * self.hop + self.window
    }

    /// Camera frames window `k` decodes.
    pub fn decoded_frames(&self, k: usize) -> Range<usize> {
        let start = k * self.hop + self.drop;
        start..start + self.decoded()
    }

    /// Whole windows in a clip of `frames` camera frames.
    pub fn windows_in(&self, frames: usize) -> usize {
        if frames < self.window {
            0
        } else {
            (frames - self.window) / self.hop + 1
        }
    }

    /// 3-D frames per second for a camera running at `fps`.
    pub fn rate(&self, fps: f64) -> f64 {
        fps / self.hop as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thesis_windows_decode_the_middle_32_of_every_40_frames() {
        let s = WindowSchedule::new(40, 4, 40, 32).unwrap();
        assert_eq!(s, WindowSchedule::THESIS);
        assert_eq!(s.decoded(), 32);
        assert_eq!(s.frames(0), 0..40);
        assert_eq!(s.decoded_frames(0), 4..36);
        assert_eq!(s.decoded_frames(2), 84..116);
        // 8 000 frames (8 s at 1 kfps) hold the thesis' 200 positions, 25 per second.
        assert_eq!(s.windows_in(8000), 200);
        assert_eq!(s.windows_in(8039), 200);
        assert_eq!(s.windows_in(8040), 201);
        assert_eq!(s.windows_in(39), 0);
        assert!((s.rate(1000.0) - 25.0).abs() < 1e-12);
    }

    #[test]
    fn sliding_windows_overlap_by_window_minus_hop() {
        let s = WindowSchedule::new(40, 4, 8, 32).unwrap();
        assert_eq!(s.decoded_frames(1), 12..44);
        assert_eq!(s.windows_in(2000), (2000 - 40) / 8 + 1);
        let every = WindowSchedule::new(32, 0, 1, 32).unwrap();
        assert_eq!(every.windows_in(100), 69);
        assert_eq!(every.decoded_frames(68), 68..100);
    }

    #[test]
    fn impossible_schedules_say_why() {
        let short = WindowSchedule::new(36, 4, 36, 32).unwrap_err();
        assert!(short.to_string().contains("28 frames are left"), "{short}");
        let gone = WindowSchedule::new(8, 4, 8, 1).unwrap_err();
        assert!(gone.reason.contains("0 frames are left"), "{gone}");
        let none = WindowSchedule::new(6, 4, 8, 1).unwrap_err();
        assert!(none.reason.contains("leaves nothing"), "{none}");
        let still = WindowSchedule::new(40, 4, 0, 32).unwrap_err();
        assert!(still.reason.contains("hop"), "{still}");
    }
}
