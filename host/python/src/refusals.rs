//! The refusals of a reconstruction, with the rules and messages of `meb reconstruct`: a
//! decode whose verdict is not plausible, a rig the capture contradicts, a depth its support
//! check finds implausible. Each raises `ImplausibleError` carrying the verdict unless
//! `force`, which turns it into a warning.

use crate::errors::implausible;
use crate::json::to_python;
use meb_pipeline::demod::{DecodeReport, Verdict, VerdictStatus};
use meb_pipeline::reconstruct::Reconstruction;
use meb_pipeline::reconstruct::rig_check::{RigCheck, RigFit};
use pyo3::prelude::*;

/// Issues a Python `UserWarning` with `message`.
pub fn warn(py: Python<'_>, message: &str) -> PyResult<()> {
    py.import("warnings")?.call_method1("warn", (message,))?;
    Ok(())
}

/// Refuses a decode whose verdict is not plausible unless `force` (then warns); `what`
/// names it (a folder or "the decode").
pub fn check_decode_verdict(
    py: Python<'_>,
    report: &DecodeReport,
    what: &str,
    force: bool,
) -> PyResult<()> {
    let verdict = &report.verdict;
    if verdict.status == VerdictStatus::Plausible {
        return Ok(());
    }
    let found = match verdict.status {
        VerdictStatus::Unchecked => {
            "was decoded without a quality verdict (an older meb); decode it again".to_string()
        }
        _ => format!(
            "holds a decode its quality verdict found implausible ({})",
            verdict.problems.join("; ")
        ),
    };
    if force {
        return warn(py, &format!("{what} {found}; using it anyway (force=True)"));
    }
    Err(implausible(
        py,
        format!("{what} {found}; use force=True to reconstruct from it anyway"),
        to_python(py, verdict)?,
        Some(to_python(py, report)?),
    ))
}

/// Reports a doubtful or inconsistent rig and refuses an inconsistent one unless `force`;
/// returns the hint that names the rig when the reconstruction is implausible anyway and the
/// rig fits only roughly (it may be the cause).
pub fn check_rig(
    py: Python<'_>,
    check: &RigCheck,
    rig_name: &str,
    force: bool,
    implausible_result: bool,
) -> PyResult<Option<String>> {
    let line = check.describe(rig_name);
    match check.fit {
        RigFit::Inconsistent if !force => Err(implausible(
            py,
            format!(
                "{line} (try: {}; force=True keeps the reconstruction anyway)",
                check.advice()
            ),
            to_python(py, &check.verdict(rig_name))?,
            Some(to_python(py, check)?),
        )),
        RigFit::Inconsistent => {
            warn(
                py,
                &format!("kept despite the rig check (force=True): {line}"),
            )?;
            Ok(None)
        }
        RigFit::Doubtful if implausible_result => Ok(Some(format!(
            "the rig may be the cause: {line} (if its LED positions or intensities are \
             uncertain: {})",
            check.advice()
        ))),
        RigFit::Doubtful => {
            warn(py, &line)?;
            Ok(None)
        }
        RigFit::Consistent | RigFit::Unjudged => Ok(None),
    }
}

/// Refuses a reconstruction whose support verdict is implausible unless `force` (then warns);
/// `rig_hint` joins the refusal when the rig may be the cause.
pub fn check_support(
    py: Python<'_>,
    reconstruction: &Reconstruction,
    rig_hint: Option<String>,
    force: bool,
) -> PyResult<()> {
    let verdict: &Verdict = &reconstruction.support.verdict;
    if verdict.is_plausible() {
        return Ok(());
    }
    let problems = verdict.problems.join("; ");
    if force {
        return warn(
            py,
            &format!("kept an implausible reconstruction (force=True): {problems}"),
        );
    }
    let advice = verdict.advice.join("; ");
    let refusal = format!(
        "the reconstruction looks implausible: {problems} (try: {advice}; force=True keeps it anyway)"
    );
    let message = match rig_hint {
        Some(hint) => format!("{refusal}; {hint}"),
        None => refusal,
    };
    Err(implausible(py, message, to_python(py, verdict)?, None))
}
