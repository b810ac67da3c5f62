//! The reconstruction stage of [`super::process`]: the motion policy applied to a chosen try,
//! its warm-started reconstruction, and its score against the truth.

use super::decode_stage::{LeftOut, Try};
use super::*;

/// A finished window: its record and what was computed.
pub(super) struct Outcome {
    pub(super) record: FrameRecord,
    pub(super) decoded: Option<Decoded>,
    pub(super) reconstruction: Option<WindowReconstruction>,
}

/// Applies the motion policy to the chosen try, reconstructs it and scores it.
#[allow(clippy::too_many_arguments)]
pub(super) fn reconstruct_window(
    chosen: Try,
    scheduled: usize,
    index: usize,
    schedule: &WindowSchedule,
    format: &meb_core::capture::FrameFormat,
    rig: &Rig,
    config: &VideoConfig,
    truth: Option<TruthDepth>,
    mut timing: FrameTiming,
    warm: Option<&WarmStart>,
    pool: &rayon::ThreadPool,
) -> Result<Outcome, VideoError> {
    let decoded_range = chosen.decoded_frames(schedule);
    let time_s = (format.fps > 0.0)
        .then(|| (decoded_range.start + decoded_range.end) as f64 / (2.0 * format.fps));
    let mut record = FrameRecord {
        index,
        frames: (chosen.start, chosen.start + schedule.window),
        decoded: (decoded_range.start, decoded_range.end),
        time_s,
        status: FrameStatus::Failed,
        reason: None,
        placed_by: chosen.start - scheduled,
        decode_region: chosen.decode.region.map(|r| r.roi),
        widened: chosen.decode.widened,
        verdict: chosen.verdict,
        timing_source: chosen.decode.source,
        motion: chosen.motion,
        decode: None,
        reconstruction: None,
        accuracy: None,
        timing: FrameTiming::default(),
    };
    let (moving, left_out) = (chosen.moving(), chosen.left_out(config.motion.policy));
    let decoded = match chosen.decode.decoded {
        Ok(decoded) => decoded,
        Err(error) => {
            record.reason = Some(format!("decoding failed: {error}"));
            record.timing = timing;
            return Ok(Outcome {
                record,
                decoded: None,
                reconstruction: None,
            });
        }
    };
    let mut quality = DecodeQuality::of(&decoded);
    // The decoder kept every decode for the judgement; record what it came to.
    quality.verdict.status = match chosen.verdict {
        Some(WindowVerdict::Plausible) => VerdictStatus::Plausible,
        Some(WindowVerdict::Forced) => VerdictStatus::Overridden,
        _ => VerdictStatus::Implausible,
    };
    record.decode = Some(quality);
    let shape = decoded.leds.shape().unwrap_or((0, 0));
    let expected = chosen
        .decode
        .region
        .map_or((rig.camera.height, rig.camera.width), |r| {
            (r.roi.height, r.roi.width)
        });
    if shape != expected {
        return Err(VideoError::Rig(format!(
            "the rig's camera is {}x{} but the decoded images are {}x{} (use a rig of the \
             frames' or the region's size)",
            rig.camera.width, rig.camera.height, shape.1, shape.0
        )));
    }
    record.reason = match (moving, chosen.verdict) {
        (_, Some(WindowVerdict::Forced)) => Some(format!(
            "the decode is implausible ({}) and was kept on request (--force)",
            decoded.report.verdict.problems.join("; ")
        )),
        (true, Some(WindowVerdict::Motion)) => Some(
            "the object moved during the window (the modulation its decode leaves unexplained \
             is within the motion's energy)"
                .into(),
        ),
        (true, _) => Some("the object moved during the window".into()),
        (false, _) => None,
    };
    if let Some(left_out) = left_out {
        match left_out {
            LeftOut::Refused => {
                let verdict = &decoded.report.verdict;
                record.reason = Some(format!(
                    "the decode is implausible and the window's motion does not explain it: {} \
                     (try: {}; --force keeps such windows)",
                    verdict.problems.join("; "),
                    verdict.advice.join("; ")
                ));
            }
            LeftOut::Skipped => record.status = FrameStatus::Skipped,
        }
        record.timing = timing;
        return Ok(Outcome {
            record,
            decoded: Some(decoded),
            reconstruction: None,
        });
    }
    let time = Instant::now();
    let request = Request {
        warm,
        region: chosen.decode.region.map(|region| region.roi),
        ..Request::default()
    };
    let reconstruction = pool.install(|| {
        reconstruct_extent(Source::Decoded(&decoded), rig, &config.reconstruct, request)
            .map(WindowReconstruction::of_extent)
    });
    timing.reconstruct_ms = time.elapsed().as_secs_f64() * 1e3;
    let reconstruction = match reconstruction {
        Ok(r) => r,
        Err(error) => {
            record.reason = Some(format!("reconstruction failed: {error}"));
            record.timing = timing;
            return Ok(Outcome {
                record,
                decoded: Some(decoded),
                reconstruction: None,
            });
        }
    };
    record.reconstruction = Some(ReconstructionQuality::of(reconstruction.reconstruction()));
    timing.stages = reconstruction.reconstruction().timings.clone();
    let support = &reconstruction.reconstruction().support.verdict;
    if !support.is_plausible() {
        let problems = support.problems.join("; ");
        if config.decode.on_implausible != OnImplausible::Keep {
            record.reason = Some(format!(
                "the reconstruction is implausible: {problems} (try: {}; --force keeps such \
                 windows)",
                support.advice.join("; ")
            ));
            record.timing = timing;
            return Ok(Outcome {
                record,
                decoded: Some(decoded),
                reconstruction: None,
            });
        }
        let kept = format!(
            "the reconstruction is implausible ({problems}) and was kept on request (--force)"
        );
        record.reason = Some(match record.reason.take() {
            Some(reason) => format!("{reason}; {kept}"),
            None => kept,
        });
    }
    record.status = FrameStatus::Reconstructed;
    if let Some(truth) = truth {
        let time = Instant::now();
        record.accuracy = Some(score(&reconstruction, &truth, pool)?);
        timing.compare_ms += time.elapsed().as_secs_f64() * 1e3;
    }
    record.timing = timing;
    Ok(Outcome {
        record,
        decoded: Some(decoded),
        reconstruction: Some(reconstruction),
    })
}

/// The accuracy of a reconstruction against its window's `truth` (none where the two do not
/// overlap); its rows are summed in `pool`, the reconstruction's.
pub(super) fn score(
    reconstruction: &WindowReconstruction,
    truth: &TruthDepth,
    pool: &rayon::ThreadPool,
) -> Result<FrameAccuracy, VideoError> {
    match pool.install(|| score_depth(reconstruction.depth_mm(), &truth.depth_mm, None)) {
        Ok(score) => Ok(FrameAccuracy {
            rmse_mm: Some(score.rmse_mm),
            nrmse: score.nrmse,
            reconstructed_fraction: score.reconstructed_fraction,
            truth_frame: truth.frame,
        }),
        Err(MetricsError::NoOverlap) => Ok(FrameAccuracy {
            rmse_mm: None,
            nrmse: None,
            reconstructed_fraction: 0.0,
            truth_frame: truth.frame,
        }),
        Err(error) => Err(error.into()),
    }
}
