//! The layer rules of DESIGN.md, checked in code: every module of `src/` may name (`crate::…`)
//! only the modules its layer allows. Data flows top to bottom; nothing reaches back up.
//!
//! The check reads the sources (comments skipped), so it fails the moment someone adds an
//! upward `use` — no build trick can hide one, since a path into another module has to name it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The ground floor: everything may use it, it uses nothing above it.
const FLOOR: &[&str] = &[
    "geometry",
    "camera_model",
    "setup",
    "notice",
    "atomic_file",
    "yaml_file",
];

/// Top-level module → the modules (besides the ground floor and itself) it may name.
fn allowed() -> BTreeMap<&'static str, &'static [&'static str]> {
    BTreeMap::from([
        // Ground floor: nothing above it.
        ("geometry", &[][..]),
        ("camera_model", &[][..]),
        ("setup", &[][..]),
        ("notice", &[][..]),
        ("atomic_file", &[][..]),
        ("yaml_file", &[][..]),
        // Pure maths: the floor only.
        ("solve", &[][..]),
        // The verdict on an answer: judged from the solver's figures (and held-out solves).
        ("verdict", &["solve"][..]),
        // Hardware and vision: the floor; the camera simulator renders boards.
        ("vision", &[][..]),
        ("robot", &[][..]),
        ("camera", &["vision"][..]),
        // Data and plans.
        ("dataset", &[][..]),
        ("result", &["solve", "verdict"][..]),
        ("plan", &["solve", "robot", "camera", "vision"][..]),
        (
            "config",
            &["plan", "robot", "solve", "vision", "verdict"][..],
        ),
        // The run.
        (
            "session",
            &[
                "solve", "vision", "camera", "robot", "plan", "dataset", "result", "config",
                "verdict",
            ][..],
        ),
        (
            "cell",
            &[
                "solve", "vision", "camera", "robot", "plan", "dataset", "result", "config",
                "verdict", "session",
            ][..],
        ),
        (
            "verify",
            &[
                "solve", "vision", "camera", "robot", "plan", "dataset", "result", "config",
                "verdict", "session", "cell",
            ][..],
        ),
        // Outputs and file formats.
        ("formats", &["solve", "dataset", "vision", "camera"][..]),
        (
            "report",
            &[
                "solve", "vision", "camera", "robot", "plan", "dataset", "result", "config",
                "verdict", "session", "cell", "verify", "formats",
            ][..],
        ),
        // The live browser console: renders a run's events; runs manual sessions of a cell.
        (
            "console",
            &[
                "solve", "vision", "camera", "robot", "plan", "dataset", "result", "config",
                "verdict", "session", "cell", "report",
            ][..],
        ),
    ])
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("src/ is readable") {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The top-level module a source file belongs to (`src/solve/refine.rs` → `solve`).
fn module_of(src: &Path, file: &Path) -> String {
    let rel = file.strip_prefix(src).expect("file under src/");
    let first = rel.components().next().expect("non-empty path");
    let name = first.as_os_str().to_string_lossy();
    name.trim_end_matches(".rs").to_string()
}

/// Every top-level module a file names through `crate::x` or `crate::{x, y::…}`.
fn named_modules(text: &str) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    let code: String = text
        .lines()
        .filter(|line| !line.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n");
    let mut rest = code.as_str();
    while let Some(at) = rest.find("crate::") {
        rest = &rest[at + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            // `crate::{a, b::c, d::{e, f}}`: the first segment of each top-level item.
            let mut depth = 0usize;
            let mut item = String::new();
            for ch in group.chars() {
                match ch {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        names.insert(first_segment(&item));
                        item.clear();
                        continue;
                    }
                    _ => {}
                }
                if depth == 0 {
                    item.push(ch);
                }
            }
            names.insert(first_segment(&item));
        } else {
            names.insert(first_segment(rest));
        }
    }
    names.remove("");
    names
}

fn first_segment(s: &str) -> String {
    s.trim()
        .chars()
        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
        .collect()
}

#[test]
fn every_module_names_only_what_its_layer_allows() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let rules = allowed();
    let mut violations = Vec::new();
    let mut checked = 0;
    for file in &files {
        let module = module_of(&src, file);
        // The binary (main.rs, cli/) is the top: it may use anything; lib.rs declares modules.
        if matches!(module.as_str(), "main" | "cli" | "lib") {
            continue;
        }
        let Some(allowed) = rules.get(module.as_str()) else {
            violations.push(format!(
                "{}: module `{module}` has no layer in tests/layers.rs; add it to the table",
                file.display()
            ));
            continue;
        };
        checked += 1;
        let text = std::fs::read_to_string(file).expect("readable source");
        for named in named_modules(&text) {
            let ok = named == module
                || FLOOR.contains(&named.as_str())
                || allowed.contains(&named.as_str());
            if !ok {
                violations.push(format!(
                    "{}: `{module}` names `crate::{named}`, which sits above it",
                    file.display()
                ));
            }
        }
    }
    assert!(checked > 40, "only {checked} source files checked");
    assert!(
        violations.is_empty(),
        "layer rules broken:\n{}",
        violations.join("\n")
    );
}

#[test]
fn the_checker_sees_grouped_and_plain_paths() {
    let text = "use crate::{geometry::Pose, session::{a, b}};\n// crate::cli in a comment\nlet x = crate::solve::solve();";
    let names = named_modules(text);
    assert_eq!(
        names,
        BTreeSet::from(["geometry".into(), "session".into(), "solve".into()])
    );
}
