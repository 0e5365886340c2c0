//! The calibration report of a simulated session: its structure (every section, one plot per
//! kind, a thumbnail per sample, numbers equal to result.yaml) and, when Debian's `chromium`
//! is installed, a real-browser check (no console messages, the screenshot shows the plots).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, OnceLock};

use handeye::cell;
use handeye::report::session::write_session_report;
use handeye::report::{PLOT_KINDS, SECTIONS};
use handeye::result::ResultFile;
use handeye::session::{self, SessionEvent, SessionFolder};

mod util;
use util::repo;

/// A 10-pose sim-cell session, solved and reported once for all tests of this file.
fn report() -> &'static (tempfile::TempDir, PathBuf) {
    static SESSION: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    SESSION.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let configs = repo().join("configs");
        let text = std::fs::read_to_string(configs.join("sim-cell.yaml"))
            .unwrap()
            .replace(
                "target: targets/",
                &format!("target: {}/targets/", configs.display()),
            )
            .replace(
                "intrinsics: cameras/",
                &format!("intrinsics: {}/cameras/", configs.display()),
            )
            .replace("generate: {count: 20,", "generate: {count: 10,");
        let config = dir.path().join("sim-cell.yaml");
        std::fs::write(&config, text).unwrap();
        let prepared = cell::prepare(&config).unwrap();
        let plan = prepared.report.validated().expect("plan passes its checks");
        let folder = SessionFolder::create(&dir.path().join("s")).unwrap();
        folder.write_manifest(&prepared.manifest(&plan)).unwrap();
        let mut hardware = prepared.open_hardware().unwrap();
        let setup = prepared.session_setup(folder.clone(), plan, Arc::new(AtomicBool::new(false)));
        session::run_session(
            setup,
            hardware.robot.as_mut(),
            hardware.camera.as_mut(),
            &mut |_e: SessionEvent| {},
        )
        .unwrap();
        let solved = session::solve_folder(&folder, &prepared.solve_inputs()).unwrap();
        let path = write_session_report(
            &folder,
            Some(&prepared.config),
            vec![("result".into(), solved.calibration)],
        )
        .unwrap();
        (dir, path)
    })
}

/// Issue #14: the page opens with the verdict card (before the warnings), and the simulated
/// cell's verdict is GOOD — the same verdict `verdict::assess_solved` gives the result.
#[test]
fn report_opens_with_the_verdict_card_before_the_warnings_and_the_sim_ends_good() {
    let (_dir, path) = report();
    let html = std::fs::read_to_string(path).unwrap();
    let card = html
        .find("<section id=\"verdict\"")
        .expect("a verdict card");
    let warnings = html
        .find("<section id=\"warnings\"")
        .expect("a warnings section");
    assert!(card < warnings, "the verdict card comes first");
    assert!(
        card < html.find("<section").unwrap() + 1,
        "nothing but the title before the verdict card"
    );
    let level_marker = "data-key=\"verdict.level\">";
    let at = html.find(level_marker).unwrap() + level_marker.len();
    let level = &html[at..at + html[at..].find('<').unwrap()];
    let card_html = &html[card..warnings];
    assert_eq!(level, "GOOD", "{card_html}");
    assert!(
        card_html.contains("held-out error (RMS over 10 poses"),
        "{card_html}"
    );
    assert!(card_html.contains("Next: use the result"), "{card_html}");
}

fn count(haystack: &str, needle: &str) -> usize {
    haystack.matches(needle).count()
}

/// The numbers inside `<tag data-key="key">...</tag>` (all of them, in order).
fn numbers_at(html: &str, key: &str) -> Vec<f64> {
    let marker = format!("data-key=\"{key}\">");
    let start = html
        .find(&marker)
        .unwrap_or_else(|| panic!("no data-key {key}"))
        + marker.len();
    let end = start + html[start..].find('<').unwrap();
    html[start..end]
        .split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == 'e'))
        .filter(|s| !s.is_empty() && *s != "-" && *s != "e")
        .map(|s| s.parse::<f64>().unwrap_or_else(|_| panic!("{key}: {s:?}")))
        .collect()
}

#[test]
fn report_has_every_section_one_plot_per_kind_and_the_result_numbers() {
    let (_dir, path) = report();
    let html = std::fs::read_to_string(path).unwrap();
    for id in SECTIONS {
        assert_eq!(
            count(&html, &format!("<section id=\"{id}\"")),
            1,
            "section {id}"
        );
    }
    for kind in PLOT_KINDS {
        assert_eq!(
            count(&html, &format!("data-kind=\"{kind}\"")),
            1,
            "plot {kind}"
        );
    }
    // Every plot is an inline SVG drawn by plotters; nothing is loaded from elsewhere.
    assert_eq!(count(&html, "<figure class=\"plot\""), PLOT_KINDS.len());
    assert_eq!(count(&html, "<svg"), PLOT_KINDS.len());
    assert!(!html.contains("http://") || count(&html, "http://") == count(&html, "xmlns"));
    assert!(!html.contains("https://") && !html.contains("<script"));
    // A thumbnail for each of the 10 samples.
    assert_eq!(count(&html, "src=\"data:image/png;base64,"), 10);

    // The numbers equal result.yaml's (printed with 9 decimals for poses, 3–4 for sigmas).
    let result_path = path.parent().unwrap().join("result.yaml");
    let result = ResultFile::load(&result_path).unwrap();
    let record = result.T_flange_camera.as_ref().unwrap();
    let close = |a: &[f64], b: &[f64], tol: f64, what: &str| {
        assert_eq!(a.len(), b.len(), "{what}: {a:?} vs {b:?}");
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() <= tol, "{what}: page {x} vs result.yaml {y}");
        }
    };
    for (key, record) in [
        ("T_flange_camera", record),
        ("T_base_target", result.T_base_target.as_ref().unwrap()),
    ] {
        close(
            &numbers_at(&html, &format!("{key}.translation")),
            &record.translation,
            1e-9,
            key,
        );
        close(
            &numbers_at(&html, &format!("{key}.rotation_vector"))[..3],
            &record.rotation_vector,
            1e-9,
            key,
        );
        let q = &record.quaternion;
        close(
            &numbers_at(&html, &format!("{key}.quaternion")),
            &[q.w, q.x, q.y, q.z],
            1e-9,
            key,
        );
    }
    let u = result.uncertainty.as_ref().unwrap();
    let sigma = u.T_flange_camera.unwrap();
    close(
        &numbers_at(&html, "uncertainty.T_flange_camera.translation_mm"),
        &[sigma.translation_mm],
        5e-4,
        "sigma",
    );
    close(
        &numbers_at(&html, "uncertainty.T_flange_camera.rotation_deg"),
        &[sigma.rotation_deg],
        5e-5,
        "sigma",
    );
    close(
        &numbers_at(&html, "residuals.translation_rms_mm"),
        &[result.residuals.translation_rms_mm],
        5e-4,
        "residuals",
    );
}

fn chromium() -> Option<PathBuf> {
    ["chromium", "chromium-browser"].iter().find_map(|name| {
        let found = Command::new("which").arg(name).output().ok()?;
        found
            .status
            .success()
            .then(|| PathBuf::from(String::from_utf8_lossy(&found.stdout).trim()))
    })
}

fn headless(browser: &Path, args: &[&str], page: &Path) -> std::process::Output {
    Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
            "--enable-logging=stderr",
            "--v=0",
        ])
        .args(args)
        .arg(format!("file://{}", page.display()))
        .output()
        .expect("chromium runs")
}

#[test]
fn report_renders_in_headless_chromium_without_console_messages() {
    let Some(browser) = chromium() else {
        eprintln!("SKIP: chromium is not installed (`apt-get install chromium`; .ci/run does it)");
        return;
    };
    let (dir, path) = report();
    let shot = dir.path().join("report.png");
    let out = headless(
        &browser,
        &[
            "--window-size=1280,6000",
            &format!("--screenshot={}", shot.display()),
        ],
        path,
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    // The page has no script: any console line is a broken resource or markup the browser rejected.
    let console: Vec<&str> = stderr.lines().filter(|l| l.contains("CONSOLE")).collect();
    assert!(console.is_empty(), "console messages: {console:#?}");
    assert!(out.status.success(), "chromium failed: {stderr}");

    // The screenshot shows the plots: count pixels of the plots' bar/marker blue.
    let image = image::open(&shot).unwrap().to_rgb8();
    assert_eq!(image.width(), 1280);
    let blue = image
        .pixels()
        .filter(|p| {
            (p[0] as i32 - 31).abs() < 12
                && (p[1] as i32 - 119).abs() < 12
                && (p[2] as i32 - 180).abs() < 12
        })
        .count();
    // The three bar charts alone cover far more than 20 000 px at this size.
    assert!(
        blue > 20_000,
        "only {blue} plot-blue pixels in the screenshot"
    );
    // Keep a copy for people to look at.
    let keep = std::env::temp_dir().join("handeye-report-screenshot.png");
    let _ = std::fs::copy(&shot, &keep);
    eprintln!("screenshot: {}", keep.display());
}

/// result.yaml read back as a calibration writes the same file again (what `handeye report`
/// shows is what the solve wrote).
#[test]
fn result_file_round_trips_through_a_calibration() {
    let (_dir, path) = report();
    let folder = path.parent().unwrap();
    let result_path = folder.join("result.yaml");
    let result = ResultFile::load(&result_path).unwrap();
    let calibration = result.to_calibration(&result_path).unwrap();
    let pairs = handeye::dataset::Dataset::load(&folder.join("samples.yaml"))
        .unwrap()
        .pairs;
    let again = ResultFile::from_calibration(&calibration, &pairs);
    assert_eq!(again.residuals, result.residuals);
    assert_eq!(again.uncertainty, result.uncertainty);
    assert_eq!(again.solver, result.solver);
    assert_eq!(again.outliers, result.outliers);
    let (a, b) = (
        again.T_flange_camera.unwrap().translation,
        result.T_flange_camera.unwrap().translation,
    );
    for k in 0..3 {
        assert!((a[k] - b[k]).abs() < 1e-12);
    }
}

/// Two answers side by side (here the refined and the iterative method on pose-space data with
/// no frames): both in the transforms section and in the bar legends, each plot still once.
#[test]
fn two_answers_are_shown_side_by_side() {
    use handeye::geometry::pose_from_rotvec;
    use handeye::report::{render_html, ReportAnswer, ReportInput};
    use handeye::setup::{PosePair, Setup};
    use handeye::solve::{Method, NoiseModel, SolveOptions};
    use nalgebra::Vector3;

    let camera_mount =
        pose_from_rotvec(Vector3::new(0.03, -0.07, 0.04), Vector3::new(0.0, 0.0, 1.5));
    let target_mount = pose_from_rotvec(Vector3::new(0.5, -0.15, 0.0), Vector3::new(0.0, 0.0, 0.3));
    let pairs: Vec<PosePair> = (0..12)
        .map(|k| {
            let a = k as f64;
            let view = pose_from_rotvec(
                Vector3::new(0.05 * (a * 0.7).sin(), 0.05 * (a * 1.3).cos(), 0.6),
                Vector3::new(
                    std::f64::consts::PI + 0.4 * (a * 0.9).sin(),
                    0.4 * (a * 1.7).cos(),
                    0.5 * (a * 0.5).sin(),
                ),
            );
            let noise = pose_from_rotvec(
                Vector3::new(1e-4 * (a * 3.1).sin(), 1e-4 * (a * 2.3).cos(), 0.0),
                Vector3::new(1e-4 * (a * 1.9).sin(), 0.0, 1e-4 * (a * 0.3).cos()),
            );
            PosePair::new(
                target_mount * view.inverse() * camera_mount.inverse(),
                noise * view,
            )
        })
        .collect();
    let answer = |method: Method, label: &str| {
        let options = SolveOptions {
            method,
            ..SolveOptions::default()
        };
        ReportAnswer {
            label: label.into(),
            calibration: handeye::solve::solve(Setup::EyeInHand, &pairs, &options).unwrap(),
            reprojection_px: vec![None; pairs.len()],
        }
    };
    let input = ReportInput {
        title: "two answers".into(),
        setup: Setup::EyeInHand,
        pairs: pairs.clone(),
        answers: vec![
            answer(Method::Refined, "answer-one"),
            answer(Method::Iterative, "answer-two"),
        ],
        thumbnails: Vec::new(),
        noise: NoiseModel::default(),
        holdout: None,
        verdict: None,
        arm_time: None,
    };
    let html = render_html(&input).unwrap();
    assert_eq!(count(&html, "class=\"answer\" data-answer="), 2);
    for label in ["answer-one", "answer-two"] {
        assert!(
            count(&html, label) >= 4,
            "{label} in headings and the three bar legends"
        );
    }
    for kind in PLOT_KINDS {
        assert_eq!(count(&html, &format!("data-kind=\"{kind}\"")), 1, "{kind}");
    }
    // Only the refined answer has a covariance; the iterative one says so instead of a number.
    assert_eq!(
        count(
            &html,
            "data-key=\"uncertainty.T_flange_camera.translation_mm\""
        ),
        1
    );
    assert!(html.contains("no uncertainty"));
}
