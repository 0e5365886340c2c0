//! Issue #40: lies a bag tells that the import tolerates — a metadata.yaml naming storage files
//! outside the bag folder, a compressed image's format label naming another codec than its
//! bytes, raw data past the last row, a big-endian flag on single bytes, one TF edge both static
//! and moving — each imported with a warning that names it, printed and recorded in
//! `import/bag-import.yaml`, and the calibration still made from the honest data.

use super::lies::{tf_row, S};
use super::*;

/// A small stop-and-go bag of `storage` and `image_kind` (`mono8` or `png`), edited.
fn tolerated_bag(
    dir: &Path,
    name: &str,
    image_kind: &str,
    edit: impl FnOnce(&mut serde_json::Value),
) -> Option<PathBuf> {
    let trajectory = StopAndGo::through_views(6, 0.6, 0.6);
    let standing = |t: f64| trajectory.standing(t);
    make_bag_edited(
        dir,
        name,
        &BagSpec {
            image_kind,
            ..BagSpec::of(&trajectory, &standing)
        },
        edit,
    )
}

/// Imports `bag` into `dir/NAME-session`, expecting success with every one of `warnings` (kind,
/// and what its message must say) printed as a warning naming the bag and recorded, and no
/// other; the log.
fn imported_with(dir: &Path, bag: &Path, warnings: &[(&str, &[&str])]) -> String {
    let out = dir.join(format!(
        "{}-session",
        bag.file_name().unwrap().to_string_lossy()
    ));
    let run = import(bag, &out, &["--camera-info", "/camera/camera_info"]);
    let log = text(&run);
    println!("{log}");
    assert!(run.status.success(), "{log}");
    for (_, said) in warnings {
        for part in *said {
            assert!(log.contains(part), "`{part}` missing: {log}");
        }
    }
    assert_eq!(
        log.matches(&format!("warning: {}: ", bag.display()))
            .count(),
        warnings.len(),
        "{log}"
    );
    let expected: Vec<&str> = warnings.iter().map(|(kind, _)| *kind).collect();
    assert_eq!(import_record_field(&out, "warnings", "kind"), expected);
    assert!(log.contains("6 samples accepted"), "{log}");
    bag_notices_in_result(&out, bag, warnings);
    solved_again_keeps_them(&out, warnings);
    log
}

/// A later `handeye solve` of the imported session, which reads the session and not the bag,
/// lists the same bag notices in the result it writes (they are the session's records, not a
/// patch of the import's result).
fn solved_again_keeps_them(session: &Path, warnings: &[(&str, &[&str])]) {
    use handeye_core::notice::NoticeKind;
    let again = session.join("result-again.yaml");
    let solve = handeye()
        .arg("solve")
        .arg(session)
        .arg("-o")
        .arg(&again)
        .output()
        .unwrap();
    assert!(solve.status.success(), "{}", text(&solve));
    let first = ResultFile::load(&session.join("result.yaml")).unwrap();
    let second = ResultFile::load(&again).unwrap();
    let bag_notices = |r: &ResultFile| -> Vec<String> {
        r.notices
            .iter()
            .filter(|n| n.kind == NoticeKind::BagWarning)
            .map(|n| n.message.clone())
            .collect()
    };
    assert_eq!(
        bag_notices(&second).len(),
        warnings.len(),
        "{:#?}",
        second.notices
    );
    assert_eq!(bag_notices(&second), bag_notices(&first));
}

/// The session's `result.yaml` holds each of `warnings` as a notice of kind `bag_warning` and
/// severity `warning` naming the bag and the lie (and no other bag notice), read back by the
/// result's own loader, and the report shows each among its findings.
fn bag_notices_in_result(session: &Path, bag: &Path, warnings: &[(&str, &[&str])]) {
    use handeye_core::notice::{NoticeKind, Severity};
    let path = session.join("result.yaml");
    let result = ResultFile::load(&path).unwrap();
    let bag_notices: Vec<_> = result
        .notices
        .iter()
        .filter(|n| n.kind == NoticeKind::BagWarning)
        .collect();
    assert_eq!(bag_notices.len(), warnings.len(), "{:#?}", result.notices);
    let bag = std::path::absolute(bag).unwrap();
    let page = std::fs::read_to_string(session.join("report.html")).unwrap();
    for ((kind, said), notice) in warnings.iter().zip(&bag_notices) {
        assert_eq!(notice.severity, Severity::Warning, "{notice:?}");
        let head = format!("ROS 2 bag {} ({kind}): ", bag.display());
        assert!(notice.message.starts_with(&head), "{notice:?}");
        for part in *said {
            assert!(
                notice.message.contains(part),
                "`{part}` missing: {notice:?}"
            );
        }
        // The page escapes HTML: look for the kind as it is written there.
        assert!(
            page.contains(&format!("({kind}): ")),
            "the report does not show the `{kind}` warning"
        );
    }
}

#[test]
fn issue40_compressed_images_labelled_as_another_codec_are_named() {
    let dir = tempfile::tempdir().unwrap();
    for label in ["jpeg", "webp"] {
        let Some(bag) = tolerated_bag(dir.path(), &format!("label-{label}"), "png", |spec| {
            spec["image_format"] = label.into();
        }) else {
            return;
        };
        imported_with(
            dir.path(),
            &bag,
            &[(
                "format label of other data",
                &[
                    "topic `/camera/image_raw`: ",
                    "image(s) decoded say what their data is not",
                    &format!("format `{label}` but PNG data (decoded as PNG)"),
                ],
            )],
        );
    }
}

#[test]
fn issue40_raw_data_past_the_last_row_and_a_big_endian_flag_on_mono8_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let Some(bag) = tolerated_bag(dir.path(), "raw-lies", "mono8", |spec| {
        spec["extra_bytes"] = 100.into();
        spec["is_bigendian"] = 1.into();
    }) else {
        return;
    };
    let rows = camera().width as usize * camera().height as usize;
    let log = imported_with(
        dir.path(),
        &bag,
        &[
            (
                "big-endian flag on bytes",
                &["is_bigendian set on `mono8`, whose channels are single bytes"],
            ),
            (
                "data past the last row",
                &[&format!(
                    "{} bytes of data, longer than height × step = {rows} (the 100 bytes past the last row are ignored)",
                    rows + 100
                )],
            ),
        ],
    );
    // Every frame tells both: each warning counts every image decoded ("N of the N").
    for line in log
        .lines()
        .filter(|l| l.contains("say what their data is not"))
    {
        let counts = line.split("`/camera/image_raw`: ").nth(1).unwrap();
        let words: Vec<&str> = counts.split_whitespace().collect();
        assert_eq!(words[1..3], ["of", "the"], "{line}");
        assert_eq!(words[0], words[3], "{line}");
        assert!(words[0].parse::<usize>().unwrap() >= 6, "{line}");
    }
}

#[test]
fn issue40_metadata_naming_files_outside_the_bag_folder_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let Some(bag) = tolerated_bag(dir.path(), "outside", "mono8", |_| {}) else {
        return;
    };
    let metadata = bag.join("metadata.yaml");
    let text = std::fs::read_to_string(&metadata).unwrap();
    let mut yaml: serde_yaml_ng::Value = serde_yaml_ng::from_str(&text).unwrap();
    let paths = yaml["rosbag2_bagfile_information"]["relative_file_paths"]
        .as_sequence_mut()
        .unwrap();
    paths.push("../elsewhere/other.mcap".into());
    paths.push("/etc/passwd".into());
    // Inside after all: not named.
    paths.push("sub/../outside_0.mcap".into());
    std::fs::write(&metadata, serde_yaml_ng::to_string(&yaml).unwrap()).unwrap();
    imported_with(
        dir.path(),
        &bag,
        &[(
            "files outside the bag",
            &["relative_file_paths names `../elsewhere/other.mcap`, `/etc/passwd` outside the bag folder; not read"],
        )],
    );
}

#[test]
fn issue40_a_tf_edge_both_static_and_moving_is_named_and_the_moving_one_used() {
    let dir = tempfile::tempdir().unwrap();
    // The moving edge shoulder_link → wrist_3_link also given a static value 30 cm off, first
    // at the start (before the moving ones) and, in a second bag, received mid-bag.
    for (name, receive) in [("static-first", None), ("static-later", Some(2 * S))] {
        let Some(bag) = tolerated_bag(dir.path(), name, "mono8", |spec| {
            spec["tf_static"].as_array_mut().unwrap().push(tf_row(
                ROBOT_START_NS.into(),
                "shoulder_link",
                "wrist_3_link",
                [0.3, 0.0, 0.0],
                receive.map(|r| ROBOT_START_NS + r),
            ));
        }) else {
            return;
        };
        let log = imported_with(
            dir.path(),
            &bag,
            &[(
                "edge both static and moving",
                &[
                    "`shoulder_link` → `wrist_3_link` is both static (`/tf_static` message",
                    "and moving (`/tf` message",
                    "the moving transforms are used, the static value ignored",
                    "on the chain `base_link` → `tool0`",
                ],
            )],
        );
        // The poses are the moving ones: the calibration is the truth, not 30 cm off.
        assert_calibrated(&dir.path().join(format!("{name}-session")));
        assert!(!log.contains("REDO"), "{log}");
    }
}
