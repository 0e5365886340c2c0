//! The command line a person learns once (issue #30): one name per concept across subcommands
//! (`--board` for the board file, `-o/--output` for what a command writes, `--public`/`--wait`
//! for the console), the old names kept as hidden aliases so scripts keep working; shell
//! completions and man pages written from the same definition.

use crate::util::handeye;

fn help(args: &[&str]) -> String {
    let out = handeye().args(args).arg("--help").output().unwrap();
    assert!(out.status.success(), "{args:?} --help failed");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The options a help text lists (the first word of each option line).
fn options(help: &str) -> Vec<String> {
    help.lines()
        .filter_map(|line| {
            let line = line.trim_start();
            let line = line.strip_prefix("-o, ").unwrap_or(line);
            line.starts_with("--")
                .then(|| line.split([' ', '<']).next().unwrap().to_string())
        })
        .collect()
}

#[test]
fn one_name_per_concept_across_subcommands() {
    for args in [
        &["detect"][..],
        &["import", "visp"],
        &["import", "bag"],
        &["target", "render"],
    ] {
        let listed = options(&help(args));
        assert!(
            listed.contains(&"--board".to_string()),
            "{args:?}: {listed:?}"
        );
        assert!(
            !listed.contains(&"--target".to_string()),
            "{args:?}: {listed:?}"
        );
    }
    for args in [&["run"][..], &["console"], &["verify"]] {
        let text = help(args);
        assert!(text.contains("-o, --output <DIR>"), "{args:?}: {text}");
        assert!(!options(&text).contains(&"--out".to_string()), "{args:?}");
    }
    let run = options(&help(&["run"]));
    let console = options(&help(&["console"]));
    for name in ["--public", "--wait"] {
        assert!(run.contains(&name.to_string()) && console.contains(&name.to_string()));
    }
    assert!(!run.iter().any(|o| o.starts_with("--console-")), "{run:?}");
}

#[test]
fn the_old_names_still_parse() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.yaml");
    let missing = missing.to_str().unwrap();
    let out_dir = dir.path().join("session");
    let out_dir = out_dir.to_str().unwrap();
    let board_pdf = dir.path().join("board.pdf").to_str().unwrap().to_string();
    for args in [
        vec![
            "detect",
            "--target",
            missing,
            "--intrinsics",
            missing,
            missing,
        ],
        vec!["run", "--config", missing, "--out", out_dir],
        vec![
            "console",
            "--config",
            missing,
            "--out",
            out_dir,
            "--addr",
            "127.0.0.1:0",
        ],
        vec!["target", "render", "--target", missing, "-o", &board_pdf],
    ] {
        let out = handeye().args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}");
        // Parsed: the error is about the missing file, not the argument.
        assert!(
            !stderr.contains("unexpected argument"),
            "{args:?}: {stderr}"
        );
        assert!(stderr.contains("missing.yaml"), "{args:?}: {stderr}");
    }
    // `--console-public` is `--public`: it still needs `--console`.
    let out = handeye()
        .args(["run", "--config", missing, "--console-public"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("unexpected argument"), "{stderr}");
    assert!(stderr.contains("--console"), "{stderr}");
}

#[test]
fn completions_and_man_pages_come_from_the_command_line_definition() {
    let bash = handeye().args(["completions", "bash"]).output().unwrap();
    assert!(bash.status.success());
    let bash = String::from_utf8_lossy(&bash.stdout);
    for word in [
        "run", "replay", "verify", "console", "export", "--board", "--output",
    ] {
        assert!(bash.contains(word), "bash completions lack {word}");
    }
    for shell in ["zsh", "fish", "powershell"] {
        let out = handeye().args(["completions", shell]).output().unwrap();
        assert!(out.status.success() && out.stdout.len() > 1000, "{shell}");
    }
    let bad = handeye().args(["completions", "tcsh"]).output().unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("bash"));

    let dir = tempfile::tempdir().unwrap();
    let man = dir.path().join("man1");
    let out = handeye().args(["man", "-o"]).arg(&man).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let run = std::fs::read_to_string(man.join("handeye-run.1")).unwrap();
    assert!(
        run.starts_with(".ie") || run.contains(".TH"),
        "roff: {}",
        &run[..80]
    );
    // roff escapes the hyphens of option names.
    assert!(
        run.contains("\\-\\-output") && run.contains("\\-\\-resume"),
        "{run}"
    );
    for page in ["handeye.1", "handeye-detect.1", "handeye-import-bag.1"] {
        assert!(man.join(page).is_file(), "{page}");
    }
}
