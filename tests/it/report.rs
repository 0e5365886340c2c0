//! The calibration report of a simulated session: its structure (every section, one plot per
//! kind, a frame per sample, numbers equal to result.yaml, the "use it" snippets equal to
//! `handeye export`'s, the per-pose table, named axes and legends beside the data) and, when
//! Debian's `chromium` is installed, a real-browser check (the verdict card first, no console
//! messages, screenshots at desktop and laptop sizes that show the card and the plots).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use handeye_records::result::ResultFile;
use handeye_report::{CORNER_PLOT_KINDS, PLOT_KINDS, SECTIONS};

use crate::util;
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
        // A fixed plan: the report's samples are the plan's ten poses.
        let text = std::fs::read_to_string(&config)
            .unwrap()
            .replace("plan:\n", "plan:\n  adaptive: false\n");
        std::fs::write(&config, text).unwrap();
        let done = util::run_cell(&config, &dir.path().join("s"));
        let path = handeye_report::session::write_run_report(&done).unwrap();
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
    for kind in PLOT_KINDS.iter().chain(&CORNER_PLOT_KINDS) {
        assert_eq!(
            count(&html, &format!("data-kind=\"{kind}\"")),
            1,
            "plot {kind}"
        );
    }
    // Every plot is an inline SVG drawn by plotters; nothing is loaded from elsewhere: one
    // inline script (copy buttons, sorting, the frame overlay), no URL but the SVG namespace.
    // The corner section holds every corner of every sample (10 samples of the 6x6 grid).
    let visits = handeye_records::SessionFolder::open(path.parent().unwrap())
        .unwrap()
        .read_visits()
        .unwrap();
    let corners: usize = visits
        .iter()
        .filter(|v| v.camera_from_target.is_some())
        .map(|v| v.corners_px.len())
        .sum();
    assert_eq!(numbers_at(&html, "corners.count"), vec![corners as f64]);
    let rms = numbers_at(&html, "corners.rms_px")[0];
    assert!(
        rms > 0.0 && rms < 0.2,
        "sim corners reproject within 0.2 px: {rms}"
    );
    let plots = PLOT_KINDS.len() + CORNER_PLOT_KINDS.len();
    assert_eq!(count(&html, "<figure class=\"plot\""), plots);
    assert_eq!(
        count(&html, "<svg"),
        plots + count(&html, "<svg class=\"frame\"")
    );
    assert!(!html.contains("http://") || count(&html, "http://") == count(&html, "xmlns"));
    assert!(!html.contains("https://"));
    assert_eq!(count(&html, "<script"), 1);
    assert_eq!(count(&html, "<script>"), 1, "the script is inline, no src");
    assert!(!html.contains("<link") && !html.contains("@import"));
    // A frame for each of the 10 samples, as an inline JPEG that decodes, wider than the grid
    // shows it (a click shows it full size), under its marks: every detected corner a cross, the
    // 36 tags' outlines where the answer puts them.
    assert_eq!(count(&html, "<svg class=\"frame\""), 10);
    assert_eq!(count(&html, "href=\"data:image/jpeg;base64,"), 10);
    let first = &html[html.find("<svg class=\"frame\"").unwrap()..];
    let first = &first[..first.find("</svg>").unwrap()];
    let path_of = |class: &str| {
        let at = first.find(&format!("class=\"{class}\" d=\"")).unwrap();
        let d = &first[at..];
        d[..d.find("\"/>").unwrap()].to_string()
    };
    assert_eq!(path_of("board").matches('L').count(), 36 * 4);
    assert_eq!(
        path_of("corners").matches('h').count(),
        visits[0].corners_px.len()
    );
    let at = html.find("data:image/jpeg;base64,").unwrap() + "data:image/jpeg;base64,".len();
    let encoded = &html[at..at + html[at..].find('"').unwrap()];
    use base64::Engine as _;
    let frame = image::load_from_memory(
        &base64::engine::general_purpose::STANDARD
            .decode(encoded)
            .unwrap(),
    )
    .unwrap();
    assert!(frame.width() >= 640, "frame {} px wide", frame.width());

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

/// The page reads in the order a person needs it: the verdict card as the first thing in
/// `<main>`, then the answer in plain words, "use it", the evidence, the details (SECTIONS is that
/// order).
#[test]
fn report_reads_verdict_then_use_then_evidence_then_details() {
    let (_dir, path) = report();
    let html = std::fs::read_to_string(path).unwrap();
    let main = html.find("<main>").expect("a <main>") + "<main>".len();
    assert!(
        html[main..]
            .trim_start()
            .starts_with("<section id=\"verdict\""),
        "{}",
        &html[main..main + 200]
    );
    let at = |needle: &str| {
        html.find(needle)
            .unwrap_or_else(|| panic!("no {needle} in the page"))
    };
    let positions: Vec<usize> = SECTIONS
        .iter()
        .map(|id| at(&format!("<section id=\"{id}\"")))
        .collect();
    assert!(
        positions.windows(2).all(|w| w[0] < w[1]),
        "sections out of order: {SECTIONS:?} at {positions:?}"
    );
    let (evidence, details) = (at(">Evidence</h2>"), at(">Details</h2>"));
    // verdict, plain, use | the evidence | ... | the details: transforms, convergence.
    assert!(positions[2] < evidence && evidence < positions[3]);
    let transforms = SECTIONS.iter().position(|s| *s == "transforms").unwrap();
    assert!(positions[transforms - 1] < details && details < positions[transforms]);
}

/// HTML text unescaping (the inverse of `report::escape`).
fn unescape(text: &str) -> String {
    text.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&#39;", "'")
        .replace("&amp;", "&")
}

/// "Use it" shows, for ROS 2, URDF, UR and OpenCV, exactly what `handeye export` prints for
/// the session's result.yaml, each with a copy button that copies that block.
#[test]
fn use_it_snippets_are_what_handeye_export_prints() {
    let (_dir, path) = report();
    let html = std::fs::read_to_string(path).unwrap();
    let result = path.parent().unwrap().join("result.yaml");
    let section = &html[html.find("<section id=\"use\"").unwrap()..];
    let section = &section[..section.find("</section>").unwrap()];
    for format in ["ros2", "urdf", "ur", "opencv"] {
        let out = util::handeye()
            .arg("export")
            .arg(&result)
            .args(["--format", format])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let printed = String::from_utf8(out.stdout).unwrap();
        let open = format!("<pre id=\"export-{format}\">");
        let start = section
            .find(&open)
            .unwrap_or_else(|| panic!("no {format} snippet"))
            + open.len();
        let shown = unescape(&section[start..start + section[start..].find("</pre>").unwrap()]);
        assert_eq!(shown, printed, "{format}");
        assert_eq!(
            count(
                section,
                &format!("<button type=\"button\" class=\"copy\" data-target=\"export-{format}\">")
            ),
            1,
            "{format} copy button"
        );
    }
}

/// The per-pose table: one row per sample, the primary answer's residuals (result.yaml's), worst
/// translation first; the headings the script sorts by carry their type.
#[test]
fn per_pose_table_lists_every_sample_worst_translation_first() {
    let (_dir, path) = report();
    let html = std::fs::read_to_string(path).unwrap();
    let result_path = path.parent().unwrap().join("result.yaml");
    let residuals = ResultFile::load(&result_path)
        .unwrap()
        .to_calibration(&result_path)
        .unwrap()
        .residuals;
    let table = &html[html
        .find("<table class=\"sortable\" id=\"pose-table\">")
        .unwrap()..];
    let table = &table[..table.find("</table>").unwrap()];
    assert_eq!(count(table, "<th data-type=\"number\""), 5, "{table}");
    let mut samples = Vec::new();
    let mut translations = Vec::new();
    for row in table.split("<tr class=\"").skip(1) {
        let values: Vec<&str> = row
            .split("data-value=\"")
            .skip(1)
            .map(|v| &v[..v.find('"').unwrap()])
            .collect();
        // sample, rotation, translation, normalised, reprojection
        assert_eq!(values.len(), 5, "{row}");
        let sample: usize = values[0].parse().unwrap();
        let translation: f64 = values[2].parse().unwrap();
        let expected = residuals.translation_mm[sample];
        assert!(
            (translation - expected).abs() < 1e-9,
            "sample {sample}: {translation} vs result.yaml {expected}"
        );
        let rotation: f64 = values[1].parse().unwrap();
        assert!((rotation - residuals.rotation_deg[sample]).abs() < 1e-9);
        let reprojection: f64 = values[4].parse().unwrap();
        assert!(
            reprojection > 0.0 && reprojection < 5.0,
            "{reprojection} px"
        );
        samples.push(sample);
        translations.push(translation);
    }
    let mut sorted = samples.clone();
    sorted.sort();
    assert_eq!(sorted, (0..10).collect::<Vec<_>>());
    assert!(
        translations.windows(2).all(|w| w[0] >= w[1]),
        "{translations:?}"
    );
}

/// The `x` of the SVG `<text>` whose content is `label`, in the figure of `kind`.
fn text_x(html: &str, kind: &str, label: &str) -> f64 {
    let figure = &html[html.find(&format!("data-kind=\"{kind}\"")).unwrap()..];
    // plotters writes each text on its own line.
    let figure = figure[..figure.find("</figure>").unwrap()]
        .replace(">\n", ">")
        .replace("\n</text>", "</text>");
    let end = figure
        .find(&format!(">{label}</text>"))
        .unwrap_or_else(|| panic!("{kind}: no text {label:?}"));
    let open = figure[..end].rfind("<text").unwrap();
    let x = &figure[open..end];
    let x = &x[x.find("x=\"").unwrap() + 3..];
    x[..x.find('"').unwrap()].parse().unwrap()
}

/// Issue #14: the residual charts had no y-axis names and the legend hid bars. Every axis is
/// named, and every legend sits in a column right of the plot area (x beyond the data).
#[test]
fn plot_axes_are_named_and_legends_sit_beside_the_data() {
    let (_dir, path) = report();
    let html = std::fs::read_to_string(path).unwrap();
    for (kind, axis) in [
        ("residual-rotation", "rotation residual (deg)"),
        ("residual-translation", "translation residual (mm)"),
        ("residual-reprojection", "reprojection RMS (px)"),
    ] {
        assert!(text_x(&html, kind, "sample") > 0.0);
        assert!(text_x(&html, kind, axis).is_finite());
        // The plot is 900 px wide, its legend column the last 190.
        assert!(text_x(&html, kind, "flagged outlier") > 710.0, "{kind}");
        for answer in ["reprojection space", "pose space"] {
            assert!(text_x(&html, kind, answer) > 710.0, "{kind}: {answer}");
        }
    }
    for label in [
        "flange at each sample",
        "x axis of a frame",
        "camera at each sample",
    ] {
        assert!(text_x(&html, "poses-3d", label) > 670.0, "{label}");
    }
    for name in ["base x (m)", "base y (m)", "base z (m), up"] {
        text_x(&html, "poses-3d", name);
    }
    assert!(text_x(&html, "convergence", "refine cost ½Σr²") > 650.0);
    assert!(text_x(&html, "convergence", "step within each phase") > 0.0);
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

/// The console lines chromium logged for the page (`--enable-logging=stderr`).
fn console_lines(out: &std::process::Output) -> Vec<String> {
    String::from_utf8_lossy(&out.stderr)
        .lines()
        .filter(|l| l.contains("CONSOLE"))
        .map(str::to_string)
        .collect()
}

/// Pixels of the GOOD card's background (#e8f5ec) in the top `rows` of a screenshot.
fn good_card_pixels(shot: &image::RgbImage, rows: u32) -> usize {
    shot.enumerate_pixels()
        .filter(|(_, y, p)| *y < rows && p.0 == [232, 245, 236])
        .count()
}

#[test]
fn report_renders_in_headless_chromium_without_console_messages() {
    let Some(browser) = chromium() else {
        util::skip("chromium is not installed (`apt-get install chromium`; .ci/run does it)");
        return;
    };
    let (dir, path) = report();

    // The check can fail: a page whose script logs an error shows a console line.
    let control = dir.path().join("control.html");
    std::fs::write(
        &control,
        "<!DOCTYPE html><html><body><script>console.error('control message')</script></body></html>",
    )
    .unwrap();
    let out = headless(&browser, &["--dump-dom"], &control);
    assert!(
        console_lines(&out)
            .iter()
            .any(|l| l.contains("control message")),
        "chromium's console logging did not show the control page's error:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );

    // The DOM after the script ran: the verdict card is still the first thing in <main>, the
    // overlay is hidden, and the script threw nothing (no console line).
    let out = headless(&browser, &["--dump-dom"], path);
    let console = console_lines(&out);
    assert!(console.is_empty(), "console messages: {console:#?}");
    assert!(out.status.success());
    let dom = String::from_utf8_lossy(&out.stdout);
    let main = dom.find("<main>").expect("a <main> in the DOM") + "<main>".len();
    assert!(
        dom[main..]
            .trim_start()
            .starts_with("<section id=\"verdict\""),
        "{}",
        &dom[main..main + 200]
    );
    assert!(dom.contains("<div id=\"overlay\" hidden=\"\""));

    // A desktop and a laptop screen: the GOOD verdict card is on screen without scrolling.
    // HANDEYE_UPDATE_SCREENSHOTS=1 keeps them as docs/report-desktop.png and
    // docs/report-laptop.png (the README shows them).
    for (name, width, height) in [("desktop", 1440u32, 900u32), ("laptop", 1366, 768)] {
        let shot = dir.path().join(format!("report-{name}.png"));
        let out = headless(
            &browser,
            &[
                &format!("--window-size={width},{height}"),
                &format!("--screenshot={}", shot.display()),
            ],
            path,
        );
        let console = console_lines(&out);
        assert!(console.is_empty(), "{name}: console messages: {console:#?}");
        let image = image::open(&shot).unwrap().to_rgb8();
        assert_eq!((image.width(), image.height()), (width, height), "{name}");
        let card = good_card_pixels(&image, height / 2);
        assert!(
            card > 100_000,
            "{name}: only {card} px of the GOOD card in the top half of the screen"
        );
        if std::env::var_os("HANDEYE_UPDATE_SCREENSHOTS").is_some() {
            let keep = repo().join("docs").join(format!("report-{name}.png"));
            std::fs::copy(&shot, &keep).unwrap();
            eprintln!("kept {}", keep.display());
        }
    }

    // The whole page: the plots are drawn (count pixels of the plots' bar/marker blue).
    let shot = dir.path().join("report.png");
    let out = headless(
        &browser,
        &[
            "--window-size=1280,9000",
            &format!("--screenshot={}", shot.display()),
        ],
        path,
    );
    let console = console_lines(&out);
    assert!(console.is_empty(), "console messages: {console:#?}");
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

/// Drives the page's script in Chromium: clicks the rotation heading twice, a frame, the
/// overlay and a copy button, and records what happened in the DOM (`data-driven`).
const DRIVER: &str = r#"<script>
(function () {
  var table = document.getElementById('pose-table');
  var order = function () {
    return Array.prototype.map.call(table.tBodies[0].rows, function (r) { return Number(r.dataset.sample); });
  };
  var out = {};
  var heading = table.tHead.rows[0].cells[3];
  heading.click();
  out.first = order();
  out.firstSort = heading.getAttribute('aria-sort');
  heading.click();
  out.second = order();
  out.secondSort = heading.getAttribute('aria-sort');
  var thumb = document.querySelector('figure.thumb svg.frame');
  thumb.dispatchEvent(new MouseEvent('click', {bubbles: true}));
  var overlay = document.getElementById('overlay');
  out.overlayShown = !overlay.hidden;
  out.overlaySameImage = overlay.querySelector('svg.frame image').getAttribute('href') === thumb.querySelector('image').getAttribute('href');
  overlay.click();
  out.overlayClosed = overlay.hidden;
  var button = document.querySelector('button.copy');
  button.click();
  setTimeout(function () {
    out.copyButton = button.textContent;
    document.body.setAttribute('data-driven', JSON.stringify(out));
  }, 300);
})();
</script>"#;

/// The script works in a real browser: a click on "rotation" sorts the table by it, worst
/// first, a second click reverses it; a frame opens full size in the overlay and closes on a
/// click; a copy button copies (says "Copied"); no console message.
#[test]
fn report_script_sorts_opens_frames_and_copies_in_chromium() {
    let Some(browser) = chromium() else {
        util::skip("chromium is not installed (`apt-get install chromium`; .ci/run does it)");
        return;
    };
    let (dir, path) = report();
    let html = std::fs::read_to_string(path).unwrap();
    let driven = dir.path().join("driven.html");
    std::fs::write(
        &driven,
        html.replace("</body>", &format!("{DRIVER}</body>")),
    )
    .unwrap();
    let out = headless(
        &browser,
        &["--virtual-time-budget=3000", "--dump-dom"],
        &driven,
    );
    let console = console_lines(&out);
    assert!(console.is_empty(), "console messages: {console:#?}");
    let dom = String::from_utf8_lossy(&out.stdout);
    let marker = "data-driven=\"";
    let start = dom.find(marker).expect("the driver ran") + marker.len();
    let json = unescape(&dom[start..start + dom[start..].find('"').unwrap()]);
    let driven: serde_json::Value = serde_json::from_str(&json).unwrap();

    // The rotation residual per sample, from the page's table.
    let table = &html[html.find("id=\"pose-table\"").unwrap()..];
    let table = &table[..table.find("</table>").unwrap()];
    let mut rotation = std::collections::HashMap::new();
    for row in table.split("<tr class=\"").skip(1) {
        let values: Vec<f64> = row
            .split("data-value=\"")
            .skip(1)
            .take(2)
            .map(|v| v[..v.find('"').unwrap()].parse().unwrap())
            .collect();
        rotation.insert(values[0] as u64, values[1]);
    }
    let order = |key: &str| -> Vec<u64> {
        driven[key]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect()
    };
    let (first, second) = (order("first"), order("second"));
    assert_eq!(first.len(), 10);
    let values = |order: &[u64]| order.iter().map(|s| rotation[s]).collect::<Vec<f64>>();
    assert!(
        values(&first).windows(2).all(|w| w[0] >= w[1]),
        "first click: worst rotation first: {first:?}"
    );
    assert!(
        values(&second).windows(2).all(|w| w[0] <= w[1]),
        "second click: reversed: {second:?}"
    );
    assert_eq!(driven["firstSort"], "descending");
    assert_eq!(driven["secondSort"], "ascending");
    assert_eq!(driven["overlayShown"], true);
    assert_eq!(driven["overlaySameImage"], true);
    assert_eq!(driven["overlayClosed"], true);
    assert_eq!(driven["copyButton"], "Copied");
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
    let pairs = handeye_records::dataset::Dataset::load(&folder.join("samples.yaml"))
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

/// A copy of the shared session (`report`) in a folder of its own, for a test that writes into
/// it.
fn session_copy() -> (tempfile::TempDir, PathBuf) {
    let (_dir, path) = report();
    let scratch = tempfile::tempdir().unwrap();
    let session = scratch.path().join("s");
    util::copy_folder(path.parent().unwrap(), &session);
    (scratch, session)
}

/// The JPEG of each frame on a page, in page order.
fn page_jpegs(html: &str) -> Vec<Vec<u8>> {
    use base64::Engine as _;
    let marker = "href=\"data:image/jpeg;base64,";
    html.match_indices(marker)
        .map(|(at, _)| {
            let encoded = &html[at + marker.len()..];
            base64::engine::general_purpose::STANDARD
                .decode(&encoded[..encoded.find('"').unwrap()])
                .unwrap()
        })
        .collect()
}

/// The page shows each frame from the preview its run made while it decoded the frame for
/// detection (`previews/NNN.jpg`): the report decodes no frame. A session without previews
/// (recorded before them) gets the same pictures, made from its frames.
#[test]
fn frames_are_shown_from_the_runs_previews_or_made_from_the_frames_without_them() {
    use handeye_report::session::write_folder_report;
    let (_dir, path) = report();
    let session = path.parent().unwrap();
    let shown = page_jpegs(&std::fs::read_to_string(path).unwrap());
    assert_eq!(shown.len(), 10);
    for (k, jpeg) in shown.iter().enumerate() {
        let preview = session.join(format!("previews/{k:03}.jpg"));
        assert_eq!(
            jpeg,
            &std::fs::read(&preview).unwrap(),
            "{}",
            preview.display()
        );
    }
    let (_scratch, copy) = &session_copy();
    std::fs::remove_dir_all(copy.join("previews")).unwrap();
    write_folder_report(copy, None).unwrap();
    let made = page_jpegs(&std::fs::read_to_string(copy.join("report.html")).unwrap());
    assert!(
        made == shown,
        "the pictures made from the frames differ from the previews"
    );
}

/// The page is written as its frames are drawn, a few at a time: a frame that cannot be read
/// halfway through fails the report naming the frame, and leaves the page the session had
/// byte for byte, with no partial file beside it.
#[test]
fn a_frame_that_cannot_be_read_leaves_the_previous_page_as_it_was() {
    use handeye_report::session::write_folder_report;
    let (_scratch, session) = &session_copy();
    write_folder_report(session, None).unwrap();
    let page = session.join("report.html");
    let before = std::fs::read(&page).unwrap();
    // The seventh of ten frames: six are drawn and written before it.
    let frame = session.join("frames/006.png");
    let bytes = std::fs::read(&frame).unwrap();
    std::fs::write(&frame, &bytes[..bytes.len() / 3]).unwrap();
    let error = format!(
        "{:#}",
        anyhow::Error::new(write_folder_report(session, None).unwrap_err())
    );
    assert!(error.contains("frames/006.png"), "{error}");
    assert_eq!(std::fs::read(&page).unwrap(), before, "the page changed");
    let names: Vec<String> = std::fs::read_dir(session)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        names
            .iter()
            .all(|n| !n.contains("report.html") || n == "report.html"),
        "a partial page is left: {names:?}"
    );
}

/// One loader reads a session's result.yaml whichever cell wrote it, and `handeye report`'s
/// library call writes the page of either: a one-camera session and the three-camera one
/// give their own layout with the verdict the file holds; a file that is neither is refused
/// naming the file and the key; a folder not solved yet is refused saying to solve it.
#[test]
fn both_result_layouts_read_through_one_loader_and_report_through_one_call() {
    use handeye_records::result::CellResult;
    use handeye_report::session::write_folder_report;
    // A copy: the page written here has only the file's answer, and the other tests read the
    // run's page with both.
    let (scratch, one) = &session_copy();
    let result_path = one.join("result.yaml");
    let read = CellResult::load(&result_path).unwrap();
    let file = ResultFile::load(&result_path).unwrap();
    // One camera's answer is the cell's only camera, its two unknowns the cell's transforms.
    assert_eq!(read.only_camera(), Some(&file), "{read:?}");
    let mounts = file.mounts(&result_path).unwrap();
    assert_eq!(read.mounts(), vec![("camera".to_string(), mounts)]);
    assert_eq!(read.verdict, file.verdict);
    let written = write_folder_report(one, None).unwrap();
    assert_eq!(written.path, one.join("report.html"));
    // `handeye verify --session` gives the held-out figure the verdict holds (its samples, the
    // answer's own outlier flags).
    let held = file.verdict.as_ref().unwrap().figures.held_out.unwrap();
    let verify = util::handeye()
        .args(["verify", "--session"])
        .arg(one)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&verify.stdout);
    let expected = format!(
        "error {:.2} mm, {:.3}° (RMS over {} poses)",
        held.translation_rms_mm, held.rotation_rms_deg, held.poses
    );
    assert!(stdout.contains(&expected), "{stdout} vs {expected}");
    assert!(written.lacking.is_empty(), "{:?}", written.lacking);
    assert!(written.provisional.is_none());

    let (_, cameras, _) = crate::cameras::shipped_run();
    let read = CellResult::load(&cameras.join("result.yaml")).unwrap();
    // The several-camera layout is the cell's list: every camera with its joint mount and no
    // one camera's whole answer, the robot's frames recorded.
    assert!(read.only_camera().is_none());
    let named: Vec<String> = read.mounts().into_iter().map(|(name, _)| name).collect();
    assert_eq!(named, ["wrist", "left", "right"]);
    assert!(read.robot_frames.is_some());
    let written = write_folder_report(cameras, None).unwrap();
    assert_eq!(written.path, cameras.join("report.html"));

    // A one-camera file with a stray key and a several-camera one missing its verdict: each
    // refused by its own layout's rules, naming the file and the key.
    let stray = scratch.path().join("stray.yaml");
    let text = std::fs::read_to_string(&result_path).unwrap();
    std::fs::write(&stray, format!("{text}stray_key: 1\n")).unwrap();
    let e = CellResult::load(&stray).unwrap_err().to_string();
    assert!(e.contains("stray.yaml") && e.contains("stray_key"), "{e}");
    let unjudged = scratch.path().join("unjudged.yaml");
    let mut value: serde_yaml_ng::Value =
        serde_yaml_ng::from_str(&std::fs::read_to_string(cameras.join("result.yaml")).unwrap())
            .unwrap();
    value.as_mapping_mut().unwrap().remove("verdict");
    std::fs::write(&unjudged, serde_yaml_ng::to_string(&value).unwrap()).unwrap();
    let e = CellResult::load(&unjudged).unwrap_err().to_string();
    assert!(e.contains("unjudged.yaml") && e.contains("verdict"), "{e}");
    // What only a one-camera answer may lack, a several-camera one may not: a camera's verdict,
    // a transform's 1-sigma.
    let whole: serde_yaml_ng::Value =
        serde_yaml_ng::from_str(&std::fs::read_to_string(cameras.join("result.yaml")).unwrap())
            .unwrap();
    let mut value = whole.clone();
    value["cameras"][1]
        .as_mapping_mut()
        .unwrap()
        .remove("verdict");
    std::fs::write(&unjudged, serde_yaml_ng::to_string(&value).unwrap()).unwrap();
    let e = CellResult::load(&unjudged).unwrap_err().to_string();
    assert!(
        e.contains("unjudged.yaml") && e.contains("cameras[1].verdict"),
        "{e}"
    );
    let mut value = whole;
    let board = &mut value["boards"][0];
    let name = board["name"].as_str().unwrap().to_string();
    board.as_mapping_mut().unwrap().remove("sigma");
    std::fs::write(&unjudged, serde_yaml_ng::to_string(&value).unwrap()).unwrap();
    let e = CellResult::load(&unjudged).unwrap_err().to_string();
    assert!(
        e.contains("unjudged.yaml") && e.contains(&name) && e.contains("sigma"),
        "{e}"
    );

    // A session folder with records but no answer yet.
    let unsolved = scratch.path().join("unsolved");
    std::fs::create_dir(&unsolved).unwrap();
    for file in ["session.yaml", "samples.yaml"] {
        std::fs::copy(one.join(file), unsolved.join(file)).unwrap();
    }
    let e = write_folder_report(&unsolved, None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("result.yaml") && e.contains("handeye replay"),
        "{e}"
    );
}

/// Two answers side by side (here the refined and the iterative method on pose-space data with
/// no frames): both in the transforms section and in the bar legends, each plot still once.
#[test]
fn two_answers_are_shown_side_by_side() {
    use handeye_core::geometry::pose_from_rotvec;
    use handeye_core::setup::{PosePair, Setup};
    use handeye_report::{render_html, ReportAnswer, ReportInput};
    use handeye_solve::{Method, SolveOptions};
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
            calibration: handeye_solve::solve(Setup::EyeInHand, &pairs, &options).unwrap(),
            reprojection_px: vec![None; pairs.len()],
            joint: None,
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
        frames: None,
        holdout: None,
        verdict: None,
        arm_time: None,
        nominal: None,
        corners: Vec::new(),
        image_size: None,
        robot_frames: Default::default(),
        arm: None,
    };
    let html = render_html(&input).unwrap();
    // Without a config's nominal values the plain summary says where the answer puts each frame.
    let plain = &html[html.find("<section id=\"plain\"").unwrap()..];
    let plain = &plain[..plain.find("</section>").unwrap()];
    assert!(
        plain.contains("<code>T_flange_camera</code>") && !plain.contains("nominal"),
        "{plain}"
    );
    // With them, both values and how far apart they are (here 10 mm along x, 2° about z).
    let mut nominal = input.answers[0].calibration.transforms();
    nominal.camera_mount *= handeye_core::geometry::Pose::from_parts(
        nalgebra::Translation3::new(0.01, 0.0, 0.0),
        nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, 2f64.to_radians()),
    );
    let with_nominal = render_html(&ReportInput {
        nominal: Some(nominal),
        ..input.clone()
    })
    .unwrap();
    assert!(
        with_nominal.contains("(10.0 mm and 2.0° apart)")
            && with_nominal.contains("(0.0 mm and 0.0° apart)"),
        "the camera 10 mm and 2° off its nominal, the board on it"
    );
    // A GOOD page has no caution above the snippets.
    assert!(!html.contains("class=\"caution\""));
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
    // Pose pairs alone have no corners: the corner section says so instead of empty plots.
    for kind in CORNER_PLOT_KINDS {
        assert_eq!(count(&html, &format!("data-kind=\"{kind}\"")), 0, "{kind}");
    }
    assert!(html.contains("No detected corners in this input"));
    // Only the refined answer has a covariance; the iterative one says so instead of a number.
    assert_eq!(
        count(
            &html,
            "data-key=\"uncertainty.T_flange_camera.translation_mm\""
        ),
        1
    );
    assert!(html.contains("no uncertainty"));

    // A REDO verdict (here: a solve refused for too few poses) opens the page and puts a
    // caution above the snippets; the snippets are still there to inspect.
    let refused = handeye_solve::solve(Setup::EyeInHand, &pairs[..2], &SolveOptions::default())
        .expect_err("two poses are too few");
    let redo = ReportInput {
        verdict: Some(handeye_solve::verdict::Verdict::refused(
            &refused,
            2,
            handeye_solve::verdict::Accuracy::default(),
        )),
        ..input
    };
    let html = render_html(&redo).unwrap();
    let level = "data-key=\"verdict.level\">";
    let at = html.find(level).unwrap() + level.len();
    assert!(html[at..].starts_with("REDO<"), "{}", &html[at..at + 20]);
    assert!(html.contains("<section id=\"verdict\" class=\"verdict redo\">"));
    let use_it = &html[html.find("<section id=\"use\"").unwrap()..];
    let caution = use_it.find("class=\"caution\"").expect("a caution");
    assert!(caution < use_it.find("<div class=\"snippets\">").unwrap());
    assert_eq!(count(use_it, "<pre id=\"export-"), 4);
}

/// Issue #30: the convergence plot's rotation line was invisible (the rotation phase often
/// takes one step, and one point draws no line): every step of every phase has a marker.
#[test]
fn every_solver_step_shows_in_the_convergence_plot() {
    let (_dir, path) = report();
    let html = std::fs::read_to_string(path).unwrap();
    let at = html.find("data-kind=\"convergence\"").unwrap();
    let figure = &html[at..at + html[at..].find("</figure>").unwrap()];
    let caption = figure
        .split("iterations: ")
        .nth(1)
        .and_then(|rest| rest.split(" refine steps").next())
        .expect("the caption counts the steps");
    // "1 rotation, 141 translation, 17" -> 1 + 141 + 17
    let steps: usize = caption
        .split(", ")
        .filter_map(|part| part.split(' ').next()?.parse::<usize>().ok())
        .sum();
    assert!(steps > 0, "{caption}");
    assert_eq!(figure.matches("<circle").count(), steps, "{caption}");
}
