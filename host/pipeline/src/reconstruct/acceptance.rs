//! Whether a result is kept, kept with a warning or refused: the rules every front end (the
//! `meb` command, the Python package) applies to a decode's verdict, a rig check and a
//! reconstruction's support check, so a result refused by one is refused by all.
//!
//! Each rule returns a [`Ruling`] whose messages name the front end's override (`--force`,
//! `force=True`); the front end prints the warning or raises the refusal.

use super::rig_check::{RigCheck, RigFit};
use crate::demod::{Verdict, VerdictStatus};

/// What a front end does with a result.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Ruling {
    /// Kept without a word.
    Keep,
    /// Kept, with this warning.
    Warn(String),
    /// Refused, with this message (what looks wrong and what to try).
    Refuse(String),
}

/// A decode whose verdict is not plausible is refused unless `force` (then a warning); `what`
/// names it (a folder, "the decode"), `force_name` the override (`--force`).
pub fn decode_verdict(verdict: &Verdict, what: &str, force: bool, force_name: &str) -> Ruling {
    let found = match verdict.status {
        VerdictStatus::Plausible => return Ruling::Keep,
        VerdictStatus::Unchecked => {
            "was decoded without a quality verdict (an older meb); decode it again".to_string()
        }
        VerdictStatus::Implausible | VerdictStatus::Overridden => format!(
            "holds a decode its quality verdict found implausible ({})",
            verdict.problems.join("; ")
        ),
    };
    if force {
        Ruling::Warn(format!("{what} {found}; using it anyway ({force_name})"))
    } else {
        Ruling::Refuse(format!(
            "{what} {found}; use {force_name} to reconstruct from it anyway"
        ))
    }
}

/// The ruling on a rig check, and a hint naming the rig when the reconstruction is
/// `implausible` anyway and the rig fits only roughly.
///
/// An inconsistent rig is refused unless `force`. A doubtful rig may be the cause of an
/// implausible reconstruction (a nominal rig 35 mm off per LED on the blobby shape: misfit
/// 2.35 times the noise's, and the offset search ran to its edge) or a victim (a surface lit
/// mostly by two LEDs is integrated at a wrong depth, where the right rig fits worse too): the
/// hint then joins the support refusal ([`support`]) instead of a second message, so the
/// refusal stays one line. A consistent rig is recorded in the report only.
pub fn rig(
    check: &RigCheck,
    rig_name: &str,
    force: bool,
    implausible: bool,
    force_name: &str,
) -> (Ruling, Option<String>) {
    let line = check.describe(rig_name);
    match check.fit {
        RigFit::Inconsistent if !force => (
            Ruling::Refuse(format!(
                "{line} (try: {}; {force_name} keeps the reconstruction anyway)",
                check.advice()
            )),
            None,
        ),
        RigFit::Inconsistent => (
            Ruling::Warn(format!("kept despite the rig check ({force_name}): {line}")),
            None,
        ),
        RigFit::Doubtful if implausible => (
            Ruling::Keep,
            Some(format!(
                "the rig may be the cause: {line} (if its LED positions or intensities are \
                 uncertain: {})",
                check.advice()
            )),
        ),
        RigFit::Doubtful => (Ruling::Warn(line), None),
        RigFit::Consistent | RigFit::Unjudged => (Ruling::Keep, None),
    }
}

/// A reconstruction whose support check found it implausible is refused unless `force`
/// (then a warning); `rig_hint` ([`rig`]) joins the refusal.
pub fn support(verdict: &Verdict, rig_hint: Option<&str>, force: bool, force_name: &str) -> Ruling {
    if verdict.is_plausible() {
        return Ruling::Keep;
    }
    let problems = verdict.problems.join("; ");
    if force {
        return Ruling::Warn(format!(
            "kept an implausible reconstruction ({force_name}): {problems}"
        ));
    }
    let refusal = format!(
        "the reconstruction looks implausible: {problems} (try: {}; {force_name} keeps it anyway)",
        verdict.advice.join("; ")
    );
    Ruling::Refuse(match rig_hint {
        Some(hint) => format!("{refusal}; {hint}"),
        None => refusal,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn implausible() -> Verdict {
        Verdict::from_findings(vec!["X looks wrong".into()], vec!["try Y".into()])
    }

    #[test]
    fn a_plausible_result_is_kept_and_an_implausible_one_refused_unless_forced() {
        let plausible = Verdict::from_findings(Vec::new(), Vec::new());
        assert_eq!(
            decode_verdict(&plausible, "d", false, "--force"),
            Ruling::Keep
        );
        assert_eq!(
            support(&plausible, Some("hint"), false, "--force"),
            Ruling::Keep
        );
        let bad = implausible();
        let Ruling::Refuse(message) = decode_verdict(&bad, "folder", false, "--force") else {
            panic!("an implausible decode must be refused");
        };
        assert!(message.contains("X looks wrong") && message.contains("use --force"));
        assert!(matches!(
            decode_verdict(&bad, "folder", true, "--force"),
            Ruling::Warn(m) if m.contains("using it anyway (--force)")
        ));
        let Ruling::Refuse(message) = support(&bad, Some("the rig may be the cause"), false, "f")
        else {
            panic!("an implausible reconstruction must be refused");
        };
        assert!(message.contains("try Y") && message.ends_with("; the rig may be the cause"));
        assert!(matches!(support(&bad, None, true, "f"), Ruling::Warn(_)));
    }
}
