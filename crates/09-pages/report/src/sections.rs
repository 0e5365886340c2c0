//! The report's per-answer sections: the verdict card (level, reason, next action, figures,
//! further findings), "use it" (the export snippets with copy buttons), the transforms of each answer with their 1-sigma and every export form
//! ([`export_forms`]), the arm's own model when the solve estimated it, and the `<figure>` wrapper of a plot. Each writes HTML into the page that
//! [`render_html`](super::render_html) builds.
//!
//! Depends on `verdict` (the card's content), `solve` (through [`ReportAnswer`]), `geometry`
//! (the pose forms), `formats` (the exporters and the UR literal) and the HTML escaping of its parent
//! [`report`](super).

use std::fmt::Write;

use super::{escape, ReportAnswer};
use handeye_core::geometry::yaml::PoseRecord;
use handeye_core::geometry::{rotvec, to_matrix4_rows, Pose};
use handeye_core::setup::RobotFrames;
use handeye_formats::export::{ExportFormat, Exported, FrameIds};
use handeye_solve::cell_model::{CellModelSummary, GivenFile, MIN_EXPLAINED_PX};
use handeye_solve::verdict::{Level, Verdict};

/// The forms "use it" shows, with their headings: what `handeye export --format <name>` writes.
const USE_FORMS: [(ExportFormat, &str); 4] = [
    (
        ExportFormat::Ros2,
        "ROS 2: static_transform_publisher (commands and a launch snippet)",
    ),
    (ExportFormat::Urdf, "URDF: fixed joints"),
    (
        ExportFormat::Ur,
        "UR: TCP offset and base-frame pose (URScript)",
    ),
    (
        ExportFormat::Opencv,
        "OpenCV: FileStorage YAML (4x4 matrices)",
    ),
];

/// "Use it" of one camera's answer: [`use_section`] with the forms of [`USE_FORMS`], the
/// transforms as `result.yaml` holds them (quaternion w ≥ 0, read back), so the page shows the
/// very text `handeye export result.yaml` prints with the default frame ids.
pub(super) fn use_answer_section(
    html: &mut String,
    answer: &ReportAnswer,
    verdict: Option<&Verdict>,
    robot: &RobotFrames,
) {
    let ids = FrameIds::of_robot(robot);
    let mut mounts = answer.calibration.transforms();
    for pose in [&mut mounts.camera_mount, &mut mounts.target_mount] {
        if let Ok(read_back) = PoseRecord::from_pose(pose).to_pose("") {
            *pose = read_back;
        }
    }
    let intro = format!(
        "The transforms of <b>{}</b>, as <code>handeye export result.yaml --format …</code> writes them, with the frame ids <code>{}</code> (robot base), <code>{}</code> (flange), <code>{}</code> (camera optical frame: x right, y down, z forward) and <code>{}</code> (board). For other ids, or the UR ROS driver's <code>base_link</code> (<code>base</code> turned 180° about z), run <code>handeye export</code> with <code>--base-frame</code>, <code>--camera-frame</code>, …",
        escape(&answer.label),
        ids.base,
        ids.flange,
        ids.camera,
        ids.target
    );
    let redo = verdict.is_some_and(|v| v.level == Level::Redo);
    use_section(
        html,
        &intro,
        redo.then_some("The verdict is REDO"),
        &Exported::one(&mounts, &ids),
        &ids,
        &USE_FORMS,
    );
}

/// "Use it": `exported` in each of `forms` (with its heading), each the exact text `handeye
/// export` writes with `ids`, in a `<pre>` with a copy button, below `intro` (HTML). A
/// `caution` (a REDO verdict: "The verdict is REDO") goes above them; a form the exporter
/// refuses shows why instead. One camera's page and a several-camera cell's alike.
pub(super) fn use_section(
    html: &mut String,
    intro: &str,
    caution: Option<&str>,
    exported: &Exported,
    ids: &FrameIds,
    forms: &[(ExportFormat, &str)],
) {
    let _ = writeln!(html, "<section id=\"use\"><h2>Use it</h2>\n<p>{intro}</p>");
    if let Some(caution) = caution {
        let _ = writeln!(
            html,
            "<p class=\"caution\">{}: do not put these numbers on the cell; record again as the verdict says.</p>",
            escape(caution)
        );
    }
    html.push_str("<div class=\"snippets\">\n");
    for &(format, heading) in forms {
        let name = format.name();
        let body = match exported.check(ids).and_then(|()| exported.text(format)) {
            Ok(text) => format!(
                "<div class=\"snippet-head\"><h4>{heading}</h4><button type=\"button\" class=\"copy\" data-target=\"export-{name}\">Copy</button></div><pre id=\"export-{name}\">{}</pre>",
                escape(&text)
            ),
            Err(e) => format!(
                "<div class=\"snippet-head\"><h4>{heading}</h4></div><p class=\"error\">not exported: {}</p>",
                escape(&e.to_string())
            ),
        };
        let _ = writeln!(
            html,
            "<div class=\"snippet\" data-format=\"{name}\">{body}</div>"
        );
    }
    html.push_str("</div>\n</section>\n");
}

/// The verdict card: level, reason, next action, the accuracy asked for, the figures, and any
/// further findings.
pub(super) fn verdict_card(html: &mut String, v: &Verdict) {
    let level = v.level.word();
    let class = level.to_ascii_lowercase();
    let _ = writeln!(
        html,
        "<section id=\"verdict\" class=\"verdict {class}\"><h2>Verdict: <span data-key=\"verdict.level\">{level}</span></h2>\n<p class=\"reason\">{}</p>\n<p class=\"next\">Next: {}</p>",
        escape(&v.reason),
        escape(&v.next_action)
    );
    let f = &v.figures;
    let mut rows = vec![format!(
        "accuracy asked for: {} mm, {}°",
        v.accuracy.translation_mm, v.accuracy.rotation_deg
    )];
    if let Some(h) = f.held_out {
        rows.push(format!(
            "held-out error (RMS over {} poses, target at ~{:.0} mm): {:.3} mm, {:.4}°",
            h.poses, h.working_distance_mm, h.translation_rms_mm, h.rotation_rms_deg
        ));
    }
    if let (Some(t), Some(r)) = (f.sigma_translation_mm, f.sigma_rotation_deg) {
        rows.push(format!(
            "largest 1-sigma of the two transforms: {t:.3} mm, {r:.4}°"
        ));
    }
    if let (Some(r), Some(t)) = (f.residual_rotation_rms_deg, f.residual_translation_rms_mm) {
        rows.push(format!("residual RMS: {r:.4}°, {t:.3} mm"));
    }
    if let Some(off) = f.rotation_off_axis_deg {
        rows.push(format!(
            "{} poses; largest rotation off the main axis {off:.1}°",
            f.poses
        ));
    }
    html.push_str("<ul class=\"figures\">\n");
    for row in rows {
        let _ = writeln!(html, "<li>{}</li>", escape(&row));
    }
    html.push_str("</ul>\n");
    if let Some(model) = &f.cell_model {
        cell_model_table(html, model);
    }
    if !v.also.is_empty() {
        html.push_str("<h3>Also</h3>\n<ul>\n");
        for finding in &v.also {
            let _ = writeln!(
                html,
                "<li class=\"{}\">{}: {}<br><span class=\"next\">Next: {}</span></li>",
                finding.level.word().to_ascii_lowercase(),
                finding.level.word(),
                escape(&finding.reason),
                escape(&finding.next_action)
            );
        }
        html.push_str("</ul>\n");
    }
    html.push_str("</section>\n");
}

/// The cell model's choice as the verdict holds it (issue #38): every explanation fitted with
/// its BIC above the chosen one's and its corner RMS, each estimated parameter against the
/// file's value with its 1-sigma, and the corrected files written. It renders; it judges nothing.
pub(super) fn cell_model_table(html: &mut String, model: &CellModelSummary) {
    let best = model
        .candidates
        .iter()
        .find(|c| c.explanation == model.chosen)
        .map_or(0.0, |c| c.bic);
    let _ = writeln!(
        html,
        "<div class=\"cell-model\"><h3>Cell model: the data choose <span data-key=\"cell_model.chosen\">{}</span></h3>",
        escape(model.chosen.label())
    );
    if let Some(e) = model.immaterial {
        let why = match model.explained_px(e) {
            Some(px) if px < MIN_EXPLAINED_PX => format!(
                "explains only {px:.3} px of the corners' fit (less than the {MIN_EXPLAINED_PX} px a detector and a lens model miss a true lens by)"
            ),
            _ => "moves neither transform by half the accuracy asked".to_string(),
        };
        let _ = writeln!(
            html,
            "<p>The corners prefer \"{}\", but it {why}: the files as given stand.</p>",
            escape(e.label()),
        );
    }
    html.push_str("<table><tr><th>explanation</th><th>free parameters</th><th>corner RMS (px)</th><th>BIC above the chosen</th></tr>\n");
    for c in &model.candidates {
        let mark = if c.explanation == model.chosen {
            " class=\"chosen\""
        } else {
            ""
        };
        let _ = writeln!(
            html,
            "<tr{mark}><td>{}</td><td>{}</td><td>{:.3}</td><td>{:.1}</td></tr>",
            escape(c.explanation.label()),
            c.parameters,
            c.rms_px,
            c.bic - best
        );
    }
    html.push_str("</table>\n");
    if !model.estimates.is_empty() {
        html.push_str("<table><tr><th>file</th><th>parameter</th><th>in the file</th><th>estimated (± 1σ)</th><th>off by</th></tr>\n");
        for e in &model.estimates {
            let file = match e.file {
                GivenFile::Intrinsics => "intrinsics",
                GivenFile::Board => "board",
            };
            let _ = writeln!(
                html,
                "<tr><td>{file}</td><td>{}</td><td>{:.4}</td><td>{:.4} ± {:.4}</td><td>{:.1} σ</td></tr>",
                escape(&e.parameter),
                e.file_value,
                e.estimate,
                e.sigma,
                e.sigmas()
            );
        }
        html.push_str("</table>\n");
    }
    for path in &model.written {
        let _ = writeln!(
            html,
            "<p>Corrected file written: <code>{}</code></p>",
            escape(path)
        );
    }
    html.push_str("</div>\n");
}

/// The answer in plain words, beside the config's nominal values when there are some: where
/// each transform puts its frame (mm, and roll / pitch / yaw in degrees about x, y, z), and how
/// far that is from the nominal.
pub(super) fn plain_summary(
    html: &mut String,
    answer: &ReportAnswer,
    nominal: Option<&handeye_core::setup::CellTransforms>,
    id: &str,
) {
    let ids = FrameIds::default();
    let frame = |name: &str| match name {
        "flange" => format!("the flange ({})", ids.flange),
        "base" => format!("the robot base ({})", ids.base),
        "camera" => "the camera".to_string(),
        "target" => "the board".to_string(),
        other => other.to_string(),
    };
    let place = |pose: &Pose| {
        // Rounded to the tenth shown, and `+ 0.0`, so a -0.04 prints as 0.0, not -0.0.
        let tenth = |v: f64| (v * 10.0).round() / 10.0 + 0.0;
        let t = pose.translation.vector * 1e3;
        let (roll, pitch, yaw) = pose.rotation.euler_angles();
        format!(
            "x {:.1}, y {:.1}, z {:.1} mm, roll {:.1}°, pitch {:.1}°, yaw {:.1}°",
            tenth(t.x),
            tenth(t.y),
            tenth(t.z),
            tenth(roll.to_degrees()),
            tenth(pitch.to_degrees()),
            tenth(yaw.to_degrees())
        )
    };
    let _ = writeln!(html, "<section id=\"{id}\"><h3>In plain words</h3>\n<ul>");
    let nominal = nominal.map(|n| n.unknowns());
    let frames = answer.calibration.setup.unknown_frames();
    for (k, ((key, pose), (parent, child))) in
        answer.calibration.unknowns().iter().zip(frames).enumerate()
    {
        // `T_parent_child`: the child frame's place in the parent frame.
        let mut line = format!(
            "<b>{}</b> is at {} in the frame of {} (<code>{key}</code>)",
            escape(&capitalised(&frame(child))),
            place(pose),
            escape(&frame(parent))
        );
        if let Some((_, nominal)) = nominal.as_ref().map(|n| n[k]) {
            let apart_mm = (pose.translation.vector - nominal.translation.vector).norm() * 1e3;
            let apart_deg = pose.rotation.angle_to(&nominal.rotation).to_degrees();
            let _ = write!(
                line,
                "; the config's nominal: {} ({apart_mm:.1} mm and {apart_deg:.1}° apart)",
                place(&nominal)
            );
        }
        let _ = writeln!(html, "<li>{line}.</li>");
    }
    html.push_str("</ul>\n</section>\n");
}

fn capitalised(text: &str) -> String {
    let mut chars = text.chars();
    match chars.next() {
        Some(first) => first.to_uppercase().chain(chars).collect(),
        None => String::new(),
    }
}

pub(super) fn figure(html: &mut String, kind: &str, svg: &str) {
    let _ = writeln!(
        html,
        "<figure class=\"plot\" data-kind=\"{kind}\">{svg}</figure>"
    );
}

pub(super) fn transforms_section(html: &mut String, k: usize, answer: &ReportAnswer) {
    let c = &answer.calibration;
    let _ = write!(
        html,
        "<div class=\"answer\" data-answer=\"{k}\"><h3>{}</h3>",
        escape(&answer.label)
    );
    let sigmas = match &answer.joint {
        Some(joint) => {
            // Its run and variance factor are the cell's, in the cameras' section.
            html.push_str("<p>the joint solve of every camera and the boards</p>\n");
            joint.sigmas
        }
        None => {
            let _ = writeln!(
                html,
                "<p>method {}, {} iterations, {}converged</p>",
                c.solver.method.name(),
                c.solver.iterations,
                if c.solver.converged { "" } else { "NOT " }
            );
            let sigmas = c.uncertainty.as_ref();
            [
                sigmas.map(|u| u.camera_mount),
                sigmas.map(|u| u.target_mount),
            ]
        }
    };
    for (i, (name, pose)) in c.unknowns().iter().enumerate() {
        let _ = writeln!(html, "<h4>{name}</h4>");
        match sigmas[i] {
            Some(s) => {
                let _ = writeln!(
                    html,
                    "<p class=\"sigma\">1-sigma: <span data-key=\"uncertainty.{name}.rotation_deg\">{:.4}</span>° (x {:.4}, y {:.4}, z {:.4}), <span data-key=\"uncertainty.{name}.translation_mm\">{:.3}</span> mm (x {:.3}, y {:.3}, z {:.3})</p>",
                    s.rotation_deg,
                    s.rotation_axes_deg[0],
                    s.rotation_axes_deg[1],
                    s.rotation_axes_deg[2],
                    s.translation_mm,
                    s.translation_axes_mm[0],
                    s.translation_axes_mm[1],
                    s.translation_axes_mm[2]
                );
            }
            None => {
                html.push_str("<p class=\"sigma\">no uncertainty (only the refined method computes one)</p>\n");
            }
        }
        html.push_str("<div class=\"forms-wrap\"><table class=\"forms\">\n");
        for (form, value, key) in export_forms(pose) {
            let key_attr = key
                .map(|key| format!(" data-key=\"{name}.{key}\""))
                .unwrap_or_default();
            let _ = writeln!(
                html,
                "<tr><th>{form}</th><td><code{key_attr}>{}</code></td></tr>",
                escape(&value)
            );
        }
        html.push_str("</table></div>\n");
    }
    let r = &c.residuals;
    let _ = writeln!(
        html,
        "<p>residuals: rotation RMS <span data-key=\"residuals.rotation_rms_deg\">{:.4}</span>°, translation RMS <span data-key=\"residuals.translation_rms_mm\">{:.3}</span> mm; outliers {:?}</p></div>",
        r.rotation_rms_deg, r.translation_rms_mm, c.outliers
    );
}

/// Every export form of a pose `T_a_b`, as (name, text, key of the `result.yaml` field it shows).
///
/// Translation and quaternion are printed with 9 decimals so they read back exactly enough to
/// be compared with the file. The UR form is the one `handeye export --format ur` writes
/// (`p[x, y, z, rx, ry, rz]`, metres and radians), the matrix row-major.
pub fn export_forms(pose: &Pose) -> Vec<(&'static str, String, Option<&'static str>)> {
    let t = pose.translation.vector;
    // w ≥ 0, as the YAML writes it.
    let q = handeye_core::geometry::yaml::QuaternionYaml::from(&pose.rotation);
    let rv = rotvec(&pose.rotation);
    let m = to_matrix4_rows(pose);
    let (roll, pitch, yaw) = pose.rotation.euler_angles();
    let matrix = m
        .iter()
        .map(|r| format!("[{:.9}, {:.9}, {:.9}, {:.9}]", r[0], r[1], r[2], r[3]))
        .collect::<Vec<_>>()
        .join("\n");
    vec![
        (
            "translation (m)",
            format!("[{:.9}, {:.9}, {:.9}]", t.x, t.y, t.z),
            Some("translation"),
        ),
        (
            "quaternion (w, x, y, z)",
            format!(
                "{{w: {:.9}, x: {:.9}, y: {:.9}, z: {:.9}}}",
                q.w, q.x, q.y, q.z
            ),
            Some("quaternion"),
        ),
        (
            "rotation vector (rad)",
            format!(
                "[{:.9}, {:.9}, {:.9}] ({:.4}°)",
                rv.x,
                rv.y,
                rv.z,
                rv.norm().to_degrees()
            ),
            Some("rotation_vector"),
        ),
        (
            "roll-pitch-yaw (fixed x-y-z, deg)",
            format!(
                "[{:.5}, {:.5}, {:.5}]",
                roll.to_degrees(),
                pitch.to_degrees(),
                yaw.to_degrees()
            ),
            None,
        ),
        ("4x4 matrix", matrix, None),
        (
            "UR pose (URScript)",
            handeye_formats::export::ur_pose_literal(pose),
            None,
        ),
    ]
}

/// The arm's own model the solve estimated (`solver.kinematics`; the result's `kinematics:`):
/// what was estimated, the residuals with and without it, how far it moves the flange over the
/// recorded poses, and each joint offset and link correction with its 1σ or why it was held.
pub(super) fn arm_section(html: &mut String, arm: &handeye_records::result::KinematicsYaml) {
    let estimated = match arm.estimated.as_str() {
        "dh" => "joint zero offsets and DH link corrections",
        _ => "joint zero offsets",
    };
    let _ = write!(
        html,
        "<section id=\"arm-model\"><h3>The arm's own model</h3>\n<p>The {} against the {}'s published model, estimated with the two transforms: pose-space residual RMS <span data-key=\"kinematics.translation_rms_mm.with\">{:.3}</span> mm / {:.4}° with it, {:.3} mm / {:.4}° with the published model.",
        estimated,
        escape(&arm.model),
        arm.translation_rms_mm.with,
        arm.rotation_rms_deg.with,
        arm.translation_rms_mm.without,
        arm.rotation_rms_deg.without
    );
    if let Some(moved) = &arm.flange_correction_mm {
        let _ = write!(
            html,
            " The flange where it puts it is <span data-key=\"kinematics.flange_correction_mm.mean\">{:.3}</span> mm from the published model's on average over the recorded poses ({:.3} mm at most).",
            moved.mean, moved.max
        );
    }
    html.push_str("</p>\n<table class=\"arm\"><thead><tr><th>joint</th><th>parameter</th><th>correction</th><th>1σ</th></tr></thead><tbody>\n");
    let held = |absorbed_by: &Option<String>, undetermined: bool| match absorbed_by {
        Some(by) => format!("held: absorbed by {}", escape(by)),
        None if undetermined => "held: not determined by these poses".to_string(),
        None => "-".to_string(),
    };
    for o in &arm.joint_offsets {
        let sigma = o.sigma_deg.map_or_else(
            || held(&o.absorbed_by, o.undetermined),
            |s| format!("{s:.4}°"),
        );
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td>zero offset</td><td>{:+.4}°</td><td>{sigma}</td></tr>",
            escape(&o.joint),
            o.offset_deg
        );
    }
    for l in &arm.links {
        let unit = if l.unit == "deg" { "°" } else { " mm" };
        let sigma = l.sigma.map_or_else(
            || held(&l.absorbed_by, l.undetermined),
            |s| format!("{s:.4}{unit}"),
        );
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td>{}</td><td>{:+.4}{unit}</td><td>{sigma}</td></tr>",
            escape(&l.joint),
            escape(&l.parameter),
            l.correction
        );
    }
    html.push_str("</tbody></table>\n</section>\n");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ur_form_is_translation_then_rotation_vector() {
        let pose = handeye_core::geometry::pose_from_rotvec(
            nalgebra::Vector3::new(0.1, -0.2, 0.3),
            nalgebra::Vector3::new(0.0, 0.0, 0.5),
        );
        let forms = export_forms(&pose);
        let ur = forms.iter().find(|f| f.0.starts_with("UR")).unwrap();
        // Full precision (the export's literal): the numbers read back to the pose within 1e-12.
        let values: Vec<f64> =
            ur.1.strip_prefix("p[")
                .and_then(|s| s.strip_suffix(']'))
                .unwrap_or_else(|| panic!("not a UR pose literal: {}", ur.1))
                .split(", ")
                .map(|v| v.parse().unwrap())
                .collect();
        let expected = [0.1, -0.2, 0.3, 0.0, 0.0, 0.5];
        assert_eq!(values.len(), 6, "{}", ur.1);
        for (v, e) in values.iter().zip(expected) {
            assert!((v - e).abs() < 1e-12, "{} vs {expected:?}", ur.1);
        }
    }
}
