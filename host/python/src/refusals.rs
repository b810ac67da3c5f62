//! The refusals of a reconstruction, by the rules `meb reconstruct` applies
//! ([`meb_pipeline::reconstruct::acceptance`]): a decode whose verdict is not plausible, a rig
//! the capture contradicts, a depth its support check finds implausible. Each raises
//! `ImplausibleError` carrying the verdict unless `force`, which turns it into a warning.

use crate::errors::implausible;
use crate::json::to_python;
use meb_pipeline::demod::DecodeReport;
use meb_pipeline::reconstruct::Reconstruction;
use meb_pipeline::reconstruct::acceptance::{self, Ruling};
use meb_pipeline::reconstruct::rig_check::RigCheck;
use pyo3::prelude::*;

/// The override's name in messages.
const FORCE: &str = "force=True";

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
    match acceptance::decode_verdict(&report.verdict, what, force, FORCE) {
        Ruling::Keep => Ok(()),
        Ruling::Warn(warning) => warn(py, &warning),
        Ruling::Refuse(refusal) => Err(implausible(
            py,
            refusal,
            to_python(py, &report.verdict)?,
            Some(to_python(py, report)?),
        )),
    }
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
    let (ruling, hint) = acceptance::rig(check, rig_name, force, implausible_result, FORCE);
    match ruling {
        Ruling::Keep => {}
        Ruling::Warn(warning) => warn(py, &warning)?,
        Ruling::Refuse(refusal) => {
            return Err(implausible(
                py,
                refusal,
                to_python(py, &check.verdict(rig_name))?,
                Some(to_python(py, check)?),
            ));
        }
    }
    Ok(hint)
}

/// Refuses a reconstruction whose support verdict is implausible unless `force` (then warns);
/// `rig_hint` joins the refusal when the rig may be the cause.
pub fn check_support(
    py: Python<'_>,
    reconstruction: &Reconstruction,
    rig_hint: Option<String>,
    force: bool,
) -> PyResult<()> {
    let verdict = &reconstruction.support.verdict;
    match acceptance::support(verdict, rig_hint.as_deref(), force, FORCE) {
        Ruling::Keep => Ok(()),
        Ruling::Warn(warning) => warn(py, &warning),
        Ruling::Refuse(refusal) => Err(implausible(py, refusal, to_python(py, verdict)?, None)),
    }
}
