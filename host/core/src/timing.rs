//! Wall-clock timing of pipeline stages, reported by the reconstruction, the demo and every
//! command's report (a neutral module: the stages produce timings, `export` prints them).

use std::time::Instant;

/// Wall-clock time of one stage.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StageTiming {
    /// Stage name.
    pub stage: String,
    /// Milliseconds.
    pub ms: f64,
}

impl StageTiming {
    /// The time elapsed since `start` under the name `stage`.
    pub fn since(stage: impl Into<String>, start: Instant) -> Self {
        Self {
            stage: stage.into(),
            ms: start.elapsed().as_secs_f64() * 1e3,
        }
    }
}
