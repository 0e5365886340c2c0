//! The layer rules of ARCHITECTURE.md. Between crates the compiler enforces them: a crate can
//! name only its dependencies. What is left to check here:
//!
//! - ARCHITECTURE.md's crate table is the workspace (`cargo metadata`): every member crate has
//!   its row, folder and layer, the folder is its layer's (`crates/<NN>-<layer>/`), its "may
//!   use" is exactly its dependencies, and no `Cargo.toml` adds a dependency that reaches up a
//!   layer;
//! - inside `handeye-session` (the pose loops below the cell run, the held-out check above it),
//!   every module names only the modules below it, whether through `crate::x`, `crate::{x, y}`
//!   or `super::…` paths that climb to the crate root. The plan, the config and the session's
//!   records were modules of it and are crates of their own now: the compiler keeps those.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// One row of ARCHITECTURE.md's crate table.
struct Row {
    layer: u32,
    name: String,
    folder: String,
    may_use: BTreeSet<String>,
}

/// The crate table of ARCHITECTURE.md (`| layer | crate | folder | owns | may use |`): the layer's
/// number, the crate, its folder and the crates it may use (short names: `core` is
/// `handeye-core`).
fn architecture_table() -> Vec<Row> {
    let text =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("ARCHITECTURE.md"))
            .expect("ARCHITECTURE.md reads");
    let full = |short: &str| match short {
        "mocks" => "mocks".to_string(),
        short => format!("handeye-{short}"),
    };
    text.lines()
        .filter(|line| line.starts_with("| ") && line.contains("| `"))
        .filter_map(|line| {
            let cells: Vec<&str> = line.trim_matches('|').split(" | ").map(str::trim).collect();
            let layer = cells.first()?.split(' ').next()?.parse().ok()?;
            let name = cells.get(1)?.trim_matches('`').to_string();
            let folder = cells
                .get(2)?
                .trim_matches('`')
                .trim_end_matches('/')
                .to_string();
            let may_use = cells
                .last()?
                .split(", ")
                .filter(|s| !s.is_empty() && *s != "—")
                .map(full)
                .collect();
            Some(Row {
                layer,
                name,
                folder,
                may_use,
            })
        })
        .collect()
}

/// ARCHITECTURE.md's crate table against `cargo metadata`: every member crate has a row and its
/// folder; its "may use" is exactly its workspace dependencies (normal and build; tests may use
/// anything, the top crate's tests drive the mock controller), so the table's claims stay true;
/// and each of those sits in a lower layer, so no `Cargo.toml` adds a dependency that reaches up.
#[test]
fn the_architecture_table_is_the_workspace_and_no_crate_depends_on_a_crate_above_it() {
    let output = std::process::Command::new(env!("CARGO"))
        .args([
            "metadata",
            "--no-deps",
            "--format-version",
            "1",
            "--offline",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("cargo metadata runs");
    assert!(
        output.status.success(),
        "cargo metadata: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let metadata: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let packages = metadata["packages"].as_array().expect("packages");
    let members: BTreeSet<&str> = packages
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    let table = architecture_table();
    let rows: BTreeMap<&str, &Row> = table.iter().map(|r| (r.name.as_str(), r)).collect();
    assert_eq!(rows.len(), table.len(), "a crate has two rows");
    let mut violations = Vec::new();
    for row in &table {
        if !members.contains(row.name.as_str()) {
            violations.push(format!(
                "ARCHITECTURE.md names `{}`, which is not a workspace member",
                row.name
            ));
        }
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for package in packages {
        let name = package["name"].as_str().unwrap();
        let Some(row) = rows.get(name) else {
            violations.push(format!(
                "crate `{name}` has no row in ARCHITECTURE.md's crate table: add it with its layer"
            ));
            continue;
        };
        let manifest = Path::new(package["manifest_path"].as_str().unwrap());
        let folder = manifest
            .parent()
            .unwrap()
            .strip_prefix(root)
            .unwrap_or(manifest);
        let folder = match folder.to_str().unwrap() {
            "" => "src".to_string(),
            other => other.to_string(),
        };
        if folder != row.folder {
            violations.push(format!(
                "`{name}`: ARCHITECTURE.md says folder `{}`, it is `{folder}`",
                row.folder
            ));
        }
        // A library crate sits in its layer's folder (`crates/07-run/session`), so the list of
        // `crates/` is the layer map; the binary (`src`) and the test stand-ins (`mocks`) are
        // the top level the project promises.
        let layer_folder = format!("crates/{:02}-", row.layer);
        if !(folder == "src" || folder == "mocks" || folder.starts_with(&layer_folder)) {
            violations.push(format!(
                "`{name}` (layer {}) is in `{folder}`: a crate of layer {} belongs in `{layer_folder}<layer>/`",
                row.layer, row.layer
            ));
        }
        let uses: BTreeSet<String> = package["dependencies"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|d| d["kind"] != "dev")
            .map(|d| d["name"].as_str().unwrap())
            .filter(|d| members.contains(d))
            .map(str::to_string)
            .collect();
        if uses != row.may_use {
            violations.push(format!(
                "`{name}`: ARCHITECTURE.md says it may use {:?}, its Cargo.toml uses {uses:?}",
                row.may_use
            ));
        }
        for dep in &uses {
            if let Some(below) = rows.get(dep.as_str()) {
                if below.layer >= row.layer {
                    violations.push(format!(
                        "`{name}` (layer {}) depends on `{dep}` (layer {}): a crate uses only crates of lower layers",
                        row.layer, below.layer
                    ));
                }
            }
        }
    }
    assert!(members.len() >= 10, "only {members:?} in the workspace");
    assert!(
        violations.is_empty(),
        "ARCHITECTURE.md and the workspace disagree:\n{}",
        violations.join("\n")
    );
}

/// A crate that holds several layers: its folder, the names that come from the crates below it
/// (always allowed), and each of its top-level modules with the modules of the same crate it
/// may name.
struct Ladder {
    src: &'static str,
    below: &'static [&'static str],
    modules: &'static [(&'static str, &'static [&'static str])],
    /// Files that only declare modules or hold the binary's top.
    skip: &'static [&'static str],
}

const LADDERS: &[Ladder] = &[Ladder {
    src: "crates/07-run/session/src",
    below: &[],
    modules: &[
        ("driver", &[]),
        ("adaptive", &["driver"]),
        ("manual", &["driver", "adaptive"]),
        ("replay", &["driver"]),
        ("cell", &["driver", "adaptive", "manual", "replay"]),
        (
            "verify",
            &["driver", "adaptive", "manual", "replay", "cell"],
        ),
    ],
    // The crate root re-exports the pose loops' entry points for `cell`.
    skip: &["lib"],
}];

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("the source folder is readable") {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The module path of a source file (`src/report/plots.rs` → `[report, plots]`,
/// `src/report/mod.rs` → `[report]`).
fn module_path(src: &Path, file: &Path) -> Vec<String> {
    let rel = file
        .strip_prefix(src)
        .expect("file under its source folder");
    let mut path: Vec<String> = rel
        .components()
        .map(|c| {
            c.as_os_str()
                .to_string_lossy()
                .trim_end_matches(".rs")
                .to_string()
        })
        .collect();
    if path.last().is_some_and(|last| last == "mod") {
        path.pop();
    }
    path
}

/// The top-level items a group or path names: `{a, b::c, d::{e}}` → a, b, d; `x::y` → x.
fn first_segments(rest: &str) -> Vec<String> {
    let Some(group) = rest.strip_prefix('{') else {
        return vec![first_segment(rest)];
    };
    let mut names = Vec::new();
    let mut depth = 0usize;
    let mut item = String::new();
    for ch in group.chars() {
        match ch {
            '{' => depth += 1,
            '}' if depth == 0 => break,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                names.push(first_segment(&item));
                item.clear();
                continue;
            }
            _ => {}
        }
        if depth == 0 {
            item.push(ch);
        }
    }
    names.push(first_segment(&item));
    names
}

fn first_segment(s: &str) -> String {
    s.trim()
        .chars()
        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
        .collect()
}

/// Every top-level module of its crate a file at `module` names: through `crate::…`, or through
/// `super::` chains that climb to the crate root (`super::super::x` from `a::b`).
fn named_modules(text: &str, module: &[String]) -> BTreeSet<String> {
    let code: String = text
        .lines()
        .filter(|line| !line.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n");
    let mut names = BTreeSet::new();
    let mut rest = code.as_str();
    while let Some(at) = rest.find("crate::") {
        rest = &rest[at + "crate::".len()..];
        names.extend(first_segments(rest));
    }
    let mut rest = code.as_str();
    while let Some(at) = rest.find("super::") {
        // Only a path's first `super`: the start of the text or after a non-path character.
        let starts_path = at == 0
            || !rest[..at]
                .chars()
                .next_back()
                .is_some_and(|c| c.is_ascii_alphanumeric() || c == '_' || c == ':');
        rest = &rest[at..];
        let mut ups = 0;
        while let Some(after) = rest.strip_prefix("super::") {
            ups += 1;
            rest = after;
        }
        if starts_path && ups >= module.len() {
            // At the crate root: the next segment is a top-level module.
            let segments = first_segments(rest);
            if ups == module.len() {
                names.extend(segments);
            }
        }
    }
    names.remove("");
    names
}

#[test]
fn modules_inside_a_crate_name_only_the_modules_below_them() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut violations = Vec::new();
    let mut checked = 0;
    for ladder in LADDERS {
        let src = root.join(ladder.src);
        let rules: BTreeMap<&str, &[&str]> = ladder.modules.iter().copied().collect();
        let own: BTreeSet<&str> = rules
            .keys()
            .copied()
            .chain(ladder.skip.iter().copied())
            .collect();
        let mut files = Vec::new();
        rust_files(&src, &mut files);
        files.sort();
        for file in &files {
            let module = module_path(&src, file);
            let top = module[0].as_str();
            if ladder.skip.contains(&top) {
                continue;
            }
            let Some(allowed) = rules.get(top) else {
                violations.push(format!(
                    "{}: module `{top}` has no layer in tests/it/layers.rs; add it to the table",
                    file.display()
                ));
                continue;
            };
            checked += 1;
            let text = std::fs::read_to_string(file).expect("readable source");
            for named in named_modules(&text, &module) {
                let ok = named == top
                    || ladder.below.contains(&named.as_str())
                    || allowed.contains(&named.as_str())
                    // Not a module of this crate (an item of the root, a glob).
                    || !own.contains(named.as_str());
                if !ok {
                    violations.push(format!(
                        "{}: `{top}` names `{named}`, which sits above it",
                        file.display()
                    ));
                }
            }
        }
    }
    // Every file of the run crate but its root.
    assert!(checked > 15, "only {checked} source files checked");
    assert!(
        violations.is_empty(),
        "layer rules broken:\n{}",
        violations.join("\n")
    );
}

#[test]
fn the_checker_sees_grouped_plain_and_super_paths() {
    let text = "use crate::{geometry::Pose, session::{a, b}};\n// crate::cli in a comment\nlet x = crate::solve::solve();\nuse super::super::report::Thing;\nuse super::sibling;";
    let names = named_modules(text, &["console".into(), "server".into()]);
    assert_eq!(
        names,
        BTreeSet::from([
            "geometry".into(),
            "session".into(),
            "solve".into(),
            "report".into()
        ])
    );
    // From a top-level module's own file, one `super` is the root.
    let names = named_modules("use super::report::X;", &["console".into()]);
    assert_eq!(names, BTreeSet::from(["report".into()]));
}
