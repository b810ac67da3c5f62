//! Rules about the workspace that no compiler checks: comments cite papers, equations and the
//! reference manual, never tracker issues (nor, on the host side, work sessions); the protocol
//! contract and the register plan contain no unsafe code; the firmware depends on nothing it
//! does not use; the host's Unix-only dependency is declared for Unix only; the simulator
//! depends on no part of the pipeline it is the oracle of.

use std::path::{Path, PathBuf};

use hil_tests::elf_budget::workspace_root;

/// Source trees whose comments these rules cover.
const DEVICE_SIDE: [&str; 9] = [
    "firmware/src",
    "protocol/src",
    "protocol/tests",
    "chip-plan/src",
    "host/device/src",
    "host/cli/src/cli/device.rs",
    "host/cli/tests/cli/device_cli.rs",
    "hil-tests/src",
    "hil-tests/tests",
];

fn rust_files(path: &Path, out: &mut Vec<PathBuf>) {
    if path.is_file() {
        if path.extension().is_some_and(|e| e == "rs") {
            out.push(path.to_path_buf());
        }
        return;
    }
    let mut entries: Vec<_> = std::fs::read_dir(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .map(|entry| entry.unwrap().path())
        .collect();
    entries.sort();
    for entry in entries {
        rust_files(&entry, out);
    }
}

/// Host trees whose comments must not cite tracker issues or work sessions either.
const HOST_SIDE: [&str; 6] = [
    "host/core",
    "host/sim",
    "host/pipeline",
    "host/device",
    "host/cli/src",
    "host/cli/tests",
];

/// Whether a comment line cites a work session by number ("session 27"): history belongs in
/// the commits, not in the code.
fn cites_a_session(comment: &str) -> bool {
    let lower = comment.to_lowercase();
    lower.match_indices("session").any(|(at, _)| {
        let rest = lower[at + "session".len()..].trim_start_matches(['s', ' ']);
        rest.starts_with(|c: char| c.is_ascii_digit())
    })
}

#[test]
fn host_comments_cite_no_tracker_issue_or_session() {
    assert!(cites_a_session("//! (used before session 27)"));
    assert!(!cites_a_session("/// a session of the virtual luminaire"));
    let root = workspace_root();
    let mut files = Vec::new();
    for tree in HOST_SIDE {
        rust_files(&root.join(tree), &mut files);
    }
    assert!(files.len() > 100, "found only {} files", files.len());
    let mut citations = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        for (n, line) in text.lines().enumerate() {
            let comment = line.trim_start();
            if comment.starts_with("//") && (cites_an_issue(comment) || cites_a_session(comment)) {
                citations.push(format!("{}:{}: {comment}", file.display(), n + 1));
            }
        }
    }
    assert!(citations.is_empty(), "{}", citations.join("\n"));
}

/// Whether a comment line cites a tracker issue: the word followed by a number, `#` or not.
fn cites_an_issue(comment: &str) -> bool {
    let lower = comment.to_lowercase();
    lower.match_indices("issue").any(|(at, _)| {
        let rest = lower[at + "issue".len()..].trim_start_matches(['s', ' ', '#']);
        rest.starts_with(|c: char| c.is_ascii_digit())
    })
}

#[test]
fn device_side_comments_cite_no_tracker_issue() {
    assert!(cites_an_issue("//! flash map (issue 6)."));
    assert!(cites_an_issue("/// see issue #12"));
    assert!(!cites_an_issue("/// a DMA issue with 6 streams"));
    let root = workspace_root();
    let mut files = Vec::new();
    for tree in DEVICE_SIDE {
        rust_files(&root.join(tree), &mut files);
    }
    assert!(files.len() > 30, "found only {} files", files.len());
    let mut citations = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        for (n, line) in text.lines().enumerate() {
            let comment = line.trim_start();
            if comment.starts_with("//") && cites_an_issue(comment) {
                citations.push(format!("{}:{}: {comment}", file.display(), n + 1));
            }
        }
    }
    assert!(citations.is_empty(), "{}", citations.join("\n"));
}

#[test]
fn contract_and_register_plan_forbid_unsafe_code() {
    for lib in ["protocol/src/lib.rs", "chip-plan/src/lib.rs"] {
        let text = std::fs::read_to_string(workspace_root().join(lib)).unwrap();
        assert!(text.contains("#![forbid(unsafe_code)]"), "{lib}");
    }
}

fn manifest(path: &str) -> toml::Table {
    let text = std::fs::read_to_string(workspace_root().join(path)).unwrap();
    text.parse::<toml::Table>()
        .unwrap_or_else(|e| panic!("{path}: {e}"))
}

#[test]
fn firmware_depends_on_nothing_it_does_not_use() {
    // Linked for what they provide, never named in the code (see firmware/Cargo.toml).
    const LINK_ONLY: [&str; 2] = ["cortex-m", "cortex-m-rt"];
    let firmware = manifest("firmware/Cargo.toml");
    let dependencies = firmware["dependencies"].as_table().unwrap();
    let mut sources = Vec::new();
    rust_files(&workspace_root().join("firmware/src"), &mut sources);
    let code: String = sources
        .iter()
        .map(|f| std::fs::read_to_string(f).unwrap())
        .collect();
    let unused: Vec<&String> = dependencies
        .keys()
        .filter(|name| !LINK_ONLY.contains(&name.as_str()))
        .filter(|name| {
            let ident = name.replace('-', "_");
            !code.contains(&format!("{ident}::")) && !code.contains(&format!("use {ident}"))
        })
        .collect();
    assert!(
        unused.is_empty(),
        "firmware dependencies never used: {unused:?}"
    );
}

#[test]
fn host_declares_nix_for_unix_only() {
    for path in [
        "host/core/Cargo.toml",
        "host/device/Cargo.toml",
        "host/cli/Cargo.toml",
    ] {
        let host = manifest(path);
        let everywhere = host["dependencies"].as_table().unwrap();
        assert!(!everywhere.contains_key("nix"), "{path}: nix is Unix-only");
        let unix = host["target"]["cfg(unix)"]["dependencies"]
            .as_table()
            .unwrap();
        assert!(unix.contains_key("nix"), "{path}");
    }
}

#[test]
fn the_simulator_depends_on_no_part_of_the_pipeline() {
    let sim = manifest("host/sim/Cargo.toml");
    let tables = ["dependencies", "dev-dependencies", "build-dependencies"];
    let names: Vec<&String> = tables
        .iter()
        .filter_map(|t| sim.get(*t).and_then(|d| d.as_table()))
        .flat_map(|d| d.keys())
        .collect();
    assert!(names.iter().any(|n| n.as_str() == "meb-core"), "{names:?}");
    for forbidden in ["meb-pipeline", "meb", "meb-device"] {
        assert!(
            !names.iter().any(|n| n.as_str() == forbidden),
            "the simulator depends on {forbidden}"
        );
    }
}

/// The GitHub anchor of a Markdown heading: lower case, spaces to hyphens, other punctuation
/// dropped.
fn anchor_of(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == ' ' || *c == '-' || *c == '_')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// Every `docs/….md#anchor` a source comment cites names a page of `docs/` and one of its
/// headings, so the code's citations of the maths cannot point into the void.
#[test]
fn docs_cited_by_the_code_exist() {
    assert_eq!(
        anchor_of("The subspace projection"),
        "the-subspace-projection"
    );
    assert_eq!(
        anchor_of("Duty, runs and half-period negation"),
        "duty-runs-and-half-period-negation"
    );
    let root = workspace_root();
    let mut files = Vec::new();
    for tree in HOST_SIDE.iter().chain(&DEVICE_SIDE) {
        rust_files(&root.join(tree), &mut files);
    }
    let mut cited = 0;
    let mut broken = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        for (at, _) in text.match_indices("docs/") {
            let rest = &text[at..];
            let Some(end) = rest.find(".md") else {
                continue;
            };
            let page = &rest[..end + 3];
            let is_path = |c: char| c.is_ascii_alphanumeric() || "/-_.".contains(c);
            if !page.chars().all(is_path) {
                continue;
            }
            cited += 1;
            let anchor: String = rest[end + 3..]
                .strip_prefix('#')
                .map(|a| {
                    a.chars()
                        .take_while(|c| c.is_alphanumeric() || *c == '-')
                        .collect()
                })
                .unwrap_or_default();
            let Ok(markdown) = std::fs::read_to_string(root.join(page)) else {
                broken.push(format!("{}: {page} does not exist", file.display()));
                continue;
            };
            let headings: Vec<String> = markdown
                .lines()
                .filter_map(|l| l.strip_prefix('#'))
                .map(|h| anchor_of(h.trim_start_matches('#')))
                .collect();
            if !anchor.is_empty() && !headings.contains(&anchor) {
                broken.push(format!(
                    "{}: {page} has no heading #{anchor}",
                    file.display()
                ));
            }
        }
    }
    assert!(cited > 50, "only {cited} citations of docs/ found");
    assert!(broken.is_empty(), "{}", broken.join("\n"));
}
