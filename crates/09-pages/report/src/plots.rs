//! The report's plots, drawn with `plotters`' SVG backend into strings that are inlined in the
//! page. Each function returns one `<svg>` element. Units as in the axis captions (deg, mm, px;
//! the cell sketch in metres, base frame).

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::{ReportError, ReportInput};
use handeye_core::evenly_spaced;
use handeye_core::geometry::{relative_rotation_axis, Pose};
use handeye_core::setup::{PosePair, Setup};
use handeye_solve::Phase;

const WIDTH: u32 = 900;
const HEIGHT: u32 = 300;
/// Colours of the answers, in order (blue, orange, teal, purple).
const ANSWER_COLOURS: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
    RGBColor(148, 103, 189),
];
const OUTLIER: RGBColor = RGBColor(214, 39, 40);

fn plot_error<E: std::fmt::Display>(kind: &'static str) -> impl Fn(E) -> ReportError {
    move |e| ReportError::Plot {
        kind,
        message: e.to_string(),
    }
}

/// Which per-sample residual a bar chart shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResidualKind {
    /// Rotation residual, degrees.
    Rotation,
    /// Translation residual, mm.
    Translation,
    /// Board reprojection RMS at the predicted `T_camera_target`, px.
    Reprojection,
}

impl ResidualKind {
    /// The plot's `data-kind` in the page.
    pub fn kind(self) -> &'static str {
        match self {
            ResidualKind::Rotation => "residual-rotation",
            ResidualKind::Translation => "residual-translation",
            ResidualKind::Reprojection => "residual-reprojection",
        }
    }
    fn caption(self) -> &'static str {
        match self {
            ResidualKind::Rotation => "rotation residual per sample (deg)",
            ResidualKind::Translation => "translation residual per sample (mm)",
            ResidualKind::Reprojection => {
                "board reprojection RMS at the predicted T_camera_target (px)"
            }
        }
    }
    fn y_desc(self) -> &'static str {
        match self {
            ResidualKind::Rotation => "rotation residual (deg)",
            ResidualKind::Translation => "translation residual (mm)",
            ResidualKind::Reprojection => "reprojection RMS (px)",
        }
    }
}

/// Width of the legend column right of a plot, px: legends never cover data.
const LEGEND_WIDTH: u32 = 190;
const GREY: RGBColor = RGBColor(150, 150, 150);

/// A legend entry's mark.
enum Mark {
    /// A filled square.
    Square(RGBColor),
    /// A line.
    Line(RGBColor, u32),
    /// A filled dot.
    Dot(RGBColor),
}

/// Draws a legend (mark and label per entry) into `area`, the column beside a plot.
fn legend(area: &Area<'_>, title: &str, entries: &[(Mark, String)]) -> PlotResult {
    // (plotters' SVG text comes out at about 0.8 of the size asked for.)
    let font = ("sans-serif", 16).into_font().color(&BLACK);
    let mut y = 34;
    area.draw(&Text::new(
        title.to_string(),
        (8, y - 14),
        ("sans-serif", 16)
            .into_font()
            .style(FontStyle::Bold)
            .color(&BLACK),
    ))?;
    for (mark, label) in entries {
        match mark {
            Mark::Square(c) => area.draw(&Rectangle::new([(8, y), (20, y + 12)], c.filled()))?,
            Mark::Line(c, w) => area.draw(&PathElement::new(
                [(6, y + 6), (22, y + 6)],
                c.stroke_width(*w),
            ))?,
            Mark::Dot(c) => area.draw(&Circle::new((14, y + 6), 3, c.filled()))?,
        }
        area.draw(&Text::new(label.clone(), (28, y), font.clone()))?;
        y += 22;
    }
    Ok(())
}

/// One series of a grouped bar chart: a bar per sample where it has a value.
pub struct BarSeries<'a> {
    /// Its legend label (an answer's, a camera's).
    pub label: &'a str,
    /// Per sample (the x axis, from 0), its value.
    pub values: Vec<Option<f64>>,
    /// Samples it flagged as outliers (red).
    pub outliers: &'a [usize],
    /// Samples it dropped from its fit (a grey stub).
    pub dropped: &'a [usize],
}

/// Grouped bars: one group per sample, one bar per answer; outliers red.
pub fn residual_bars(input: &ReportInput, which: ResidualKind) -> Result<String, ReportError> {
    let n = input.pairs.len();
    let series: Vec<BarSeries<'_>> = input
        .answers
        .iter()
        .map(|a| BarSeries {
            label: &a.label,
            values: (0..n)
                .map(|i| match which {
                    ResidualKind::Rotation => a.calibration.residuals.rotation_deg.get(i).copied(),
                    ResidualKind::Translation => {
                        a.calibration.residuals.translation_mm.get(i).copied()
                    }
                    ResidualKind::Reprojection => a.reprojection_px.get(i).copied().flatten(),
                })
                .collect(),
            outliers: &a.calibration.outliers,
            dropped: &a.calibration.dropped,
        })
        .collect();
    bars(which, "sample", "answer", &series)
}

/// Grouped bars of `series` over `x_desc` (one group per index, one bar per series; outliers
/// red, dropped samples a grey stub), the legend titled `legend_title`.
pub fn bars(
    which: ResidualKind,
    x_desc: &str,
    legend_title: &str,
    series: &[BarSeries<'_>],
) -> Result<String, ReportError> {
    let kind = which.kind();
    let err = plot_error(kind);
    let n = series.iter().map(|s| s.values.len()).max().unwrap_or(0);
    let values: Vec<Vec<Option<f64>>> = series
        .iter()
        .map(|s| {
            s.values
                .iter()
                .map(|v| v.filter(|v| v.is_finite()))
                .collect()
        })
        .collect();
    let top = values
        .iter()
        .flatten()
        .flatten()
        .fold(0.0f64, |m, &v| m.max(v));
    let top = if top > 0.0 { top * 1.1 } else { 1.0 };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE).map_err(&err)?;
        let (root, key) = root.split_horizontally(WIDTH - LEGEND_WIDTH);
        let mut chart = ChartBuilder::on(&root)
            .caption(which.caption(), ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(-0.5f64..(n as f64 - 0.5), 0f64..top)
            .map_err(&err)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_desc(x_desc)
            .y_desc(which.y_desc())
            .label_style(("sans-serif", 16))
            .axis_desc_style(("sans-serif", 17))
            .x_labels(n.min(25))
            .x_label_formatter(&|x| format!("{:.0}", x))
            .draw()
            .map_err(&err)?;
        let width = 0.8 / series.len().max(1) as f64;
        for (k, one) in series.iter().enumerate() {
            let colour = ANSWER_COLOURS[k % ANSWER_COLOURS.len()];
            let bars = values[k].iter().enumerate().filter_map(|(i, v)| {
                let v = (*v)?;
                let x0 = i as f64 - 0.4 + k as f64 * width;
                let fill = if one.outliers.contains(&i) {
                    OUTLIER
                } else {
                    colour
                };
                Some(Rectangle::new(
                    [(x0, 0.0), (x0 + width * 0.9, v)],
                    fill.filled(),
                ))
            });
            chart.draw_series(bars).map_err(&err)?;
            // Dropped samples have no residual in the fit: a grey stub on the axis says so.
            let dropped = one.dropped.iter().map(|&i| {
                let x0 = i as f64 - 0.4 + k as f64 * width;
                Rectangle::new([(x0, 0.0), (x0 + width * 0.9, top * 0.03)], GREY.filled())
            });
            chart.draw_series(dropped).map_err(&err)?;
        }
        if values.iter().flatten().all(|v| v.is_none()) {
            root.draw_text(
                "no detected corners recorded for these samples",
                &("sans-serif", 14).into_font().color(&BLACK),
                ((WIDTH - LEGEND_WIDTH) as i32 / 2 - 160, HEIGHT as i32 / 2),
            )
            .map_err(&err)?;
        }
        let mut entries: Vec<(Mark, String)> = series
            .iter()
            .enumerate()
            .map(|(k, s)| {
                (
                    Mark::Square(ANSWER_COLOURS[k % ANSWER_COLOURS.len()]),
                    s.label.to_string(),
                )
            })
            .collect();
        entries.push((Mark::Square(OUTLIER), "flagged outlier".into()));
        if series.iter().any(|s| !s.dropped.is_empty()) {
            entries.push((Mark::Square(GREY), "dropped from the fit".into()));
        }
        legend(&key, legend_title, &entries).map_err(&err)?;
        root.present().map_err(&err)?;
    }
    Ok(svg)
}

/// Most relative rotation axes [`rotation_axes`] draws: 2,016 pairs are those of 64 samples.
/// Every two samples make a pair, so a long recording's pairs grow with the square of its
/// samples (1,000 samples: 499,500 pairs, a 134 MB drawing); past this many, pairs are taken
/// evenly through the list, which shows the same spread.
pub const MAX_ROTATION_AXES: usize = 2016;

/// Axes of the relative rotation between every two samples (`R_j·R_iᵀ`, base frame), an axis
/// and its opposite folded together (z ≥ 0); two orthographic views of the unit sphere. At most
/// [`MAX_ROTATION_AXES`] pairs, evenly spaced through all of them (the title says how many).
pub fn rotation_axes(pairs: &[PosePair]) -> Result<String, ReportError> {
    let kind = "rotation-axes";
    let err = plot_error(kind);
    let all = pairs.len() * pairs.len().saturating_sub(1) / 2;
    let drawn = all.min(MAX_ROTATION_AXES);
    // The pairs in the order i < j, numbered; the chosen numbers, increasing.
    let mut chosen = evenly_spaced(all, MAX_ROTATION_AXES).peekable();
    let mut axes: Vec<([f64; 3], f64)> = Vec::with_capacity(drawn);
    let every_pair = (0..pairs.len()).flat_map(|i| ((i + 1)..pairs.len()).map(move |j| (i, j)));
    for (number, (i, j)) in every_pair.enumerate() {
        if chosen.next_if_eq(&number).is_none() {
            continue;
        }
        if let Some((axis, angle)) = relative_rotation_axis(
            &pairs[i].base_from_flange.rotation,
            &pairs[j].base_from_flange.rotation,
            1e-3,
        ) {
            axes.push((axis.into(), angle.to_degrees()));
        }
    }
    let title = if drawn < all {
        format!(
            "relative rotation axes (unit sphere, base frame; marker size ~ angle; {drawn} of {all} pairs, evenly through them)"
        )
    } else {
        "relative rotation axes (unit sphere, base frame; marker size ~ angle)".to_string()
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, 440)).into_drawing_area();
        root.fill(&WHITE).map_err(&err)?;
        let root = root.titled(&title, ("sans-serif", 16)).map_err(&err)?;
        let panels = root.split_evenly((1, 2));
        let views: [(&str, usize, usize); 2] = [
            ("seen from +z (x right, y up)", 0, 1),
            ("seen from +x (y right, z up)", 1, 2),
        ];
        for (panel, (title, u, v)) in panels.iter().zip(views) {
            sphere_view(panel, title, &axes, u, v).map_err(&err)?;
        }
        root.present().map_err(&err)?;
    }
    Ok(svg)
}

type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;
type PlotResult = Result<(), DrawingAreaErrorKind<std::io::Error>>;

fn sphere_view(
    panel: &Area<'_>,
    title: &str,
    axes: &[([f64; 3], f64)],
    u: usize,
    v: usize,
) -> PlotResult {
    let mut chart = ChartBuilder::on(panel)
        .caption(title, ("sans-serif", 13))
        .margin(10)
        .build_cartesian_2d(-1.1f64..1.1, -1.1f64..1.1)?;
    let circle = (0..=120).map(|k| {
        let t = k as f64 / 120.0 * std::f64::consts::TAU;
        (t.cos(), t.sin())
    });
    chart.draw_series(LineSeries::new(circle, BLACK.stroke_width(1)))?;
    for (a, b) in [((-1.0, 0.0), (1.0, 0.0)), ((0.0, -1.0), (0.0, 1.0))] {
        chart.draw_series(LineSeries::new([a, b], RGBColor(200, 200, 200)))?;
    }
    let max_angle = axes.iter().map(|a| a.1).fold(1.0f64, f64::max);
    chart.draw_series(axes.iter().map(|(a, angle)| {
        let size = 2.0 + 5.0 * angle / max_angle;
        Circle::new(
            (a[u], a[v]),
            size.round() as i32,
            ANSWER_COLOURS[0].mix(0.5).filled(),
        )
    }))?;
    Ok(())
}

/// A perspective sketch of the cell: base at the origin, the target, and the camera at every
/// sample, as the primary answer places them (metres, base frame).
pub fn poses_3d(input: &ReportInput) -> Result<String, ReportError> {
    let kind = "poses-3d";
    let err = plot_error(kind);
    let c = &input.answers[0].calibration;
    let mut cameras: Vec<Pose> = Vec::new();
    let mut targets: Vec<Pose> = Vec::new();
    let mut flanges: Vec<Pose> = Vec::new();
    for p in &input.pairs {
        flanges.push(p.base_from_flange);
        match input.setup {
            Setup::EyeInHand => cameras.push(p.base_from_flange * c.camera_mount),
            Setup::EyeToHand => targets.push(p.base_from_flange * c.target_mount),
        }
    }
    match input.setup {
        Setup::EyeInHand => targets.push(c.target_mount),
        Setup::EyeToHand => cameras.push(c.camera_mount),
    }
    let all: Vec<[f64; 3]> = cameras
        .iter()
        .chain(&targets)
        .chain(&flanges)
        .map(|p| {
            let t = p.translation.vector;
            [t.x, t.y, t.z]
        })
        .chain(std::iter::once([0.0, 0.0, 0.0]))
        .collect();
    let lo = |k: usize| all.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
    let hi = |k: usize| all.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max);
    let span = (0..3).map(|k| hi(k) - lo(k)).fold(0.1f64, f64::max);
    let pad = 0.15 * span;
    let range = |k: usize| {
        let mid = 0.5 * (lo(k) + hi(k));
        (mid - 0.5 * span - pad)..(mid + 0.5 * span + pad)
    };
    let triad = span * 0.08;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, 600)).into_drawing_area();
        root.fill(&WHITE).map_err(&err)?;
        let (root, key) = root.split_horizontally(WIDTH - LEGEND_WIDTH - 40);
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "cell sketch: base, board and camera (base frame, m)",
                ("sans-serif", 16),
            )
            .margin(10)
            // plotters' 3D y axis is vertical: map base (x, y, z) to chart (x, z, y).
            .build_cartesian_3d(range(0), range(2), range(1))
            .map_err(&err)?;
        chart.with_projection(|mut p| {
            p.pitch = 0.5;
            p.yaw = 0.7;
            p.scale = 0.85;
            p.into_matrix()
        });
        chart
            .configure_axes()
            .label_style(("sans-serif", 15))
            .x_labels(5)
            .y_labels(5)
            .z_labels(5)
            .draw()
            .map_err(&err)?;
        // Axis names beside the edges that carry each axis' ticks, beyond the tick labels (with
        // this view: base x along the front-left edge, base y along the front-right edge, base z
        // up the left edge; chart y is base z, chart z is base y).
        let (x, y, z) = (range(0), range(2), range(1));
        let (x_mid, z_mid) = (0.5 * (x.start + x.end), 0.5 * (z.start + z.end));
        let (x_out, z_out) = (0.22 * (x.end - x.start), 0.22 * (z.end - z.start));
        let axis_font = ("sans-serif", 18)
            .into_font()
            .style(FontStyle::Bold)
            .color(&BLACK)
            .pos(Pos::new(HPos::Center, VPos::Center));
        let names = [
            ("base x (m)", (x_mid, y.start, z.end + z_out)),
            ("base y (m)", (x.end + x_out, y.start, z_mid)),
            ("base z (m), up", (x.start, y.end, z.end)),
        ];
        chart
            .draw_series(
                names
                    .iter()
                    .map(|(name, at)| Text::new(name.to_string(), *at, axis_font.clone())),
            )
            .map_err(&err)?;
        let colours = [RED, GREEN, BLUE];
        let draw_triad =
            |chart: &mut ChartContext<'_, _, _>, pose: &Pose, length: f64, width: u32| {
                let o = pose.translation.vector;
                for (k, colour) in colours.iter().enumerate() {
                    let end = pose * nalgebra::Point3::from(nalgebra::Vector3::ith(k, length));
                    chart.draw_series(LineSeries::new(
                        [(o.x, o.z, o.y), (end.x, end.z, end.y)],
                        colour.stroke_width(width),
                    ))?;
                }
                Ok::<(), DrawingAreaErrorKind<std::io::Error>>(())
            };
        draw_triad(&mut chart, &Pose::identity(), 2.0 * triad, 4).map_err(&err)?;
        for t in &targets {
            draw_triad(&mut chart, t, 1.5 * triad, 3).map_err(&err)?;
        }
        for cam in &cameras {
            draw_triad(&mut chart, cam, triad, 1).map_err(&err)?;
        }
        let flange_points = flanges.iter().map(|p| {
            let o = p.translation.vector;
            Circle::new((o.x, o.z, o.y), 3, BLACK.filled())
        });
        chart.draw_series(flange_points).map_err(&err)?;
        // Name the single frames beside their origins.
        let label_font = ("sans-serif", 17).into_font().color(&BLACK);
        let mut names: Vec<(&str, Pose)> = vec![("base", Pose::identity())];
        match input.setup {
            Setup::EyeInHand => names.extend(targets.first().map(|t| ("board", *t))),
            Setup::EyeToHand => names.extend(cameras.first().map(|c| ("camera", *c))),
        }
        chart
            .draw_series(names.iter().map(|(name, pose)| {
                let o = pose.translation.vector;
                Text::new(name.to_string(), (o.x, o.z, o.y), label_font.clone())
            }))
            .map_err(&err)?;
        // The marks as drawn: the board's triads are 3 px wide, the camera's 1 px.
        let (first, second) = match input.setup {
            Setup::EyeInHand => (
                (Mark::Line(BLACK, 3), "board"),
                (Mark::Line(BLACK, 1), "camera at each sample"),
            ),
            Setup::EyeToHand => (
                (Mark::Line(BLACK, 1), "camera"),
                (Mark::Line(BLACK, 3), "board at each sample"),
            ),
        };
        legend(
            &key,
            "frames",
            &[
                (Mark::Line(BLACK, 4), "robot base".into()),
                (first.0, first.1.into()),
                (second.0, second.1.into()),
                (Mark::Dot(BLACK), "flange at each sample".into()),
                (Mark::Line(RED, 2), "x axis of a frame".into()),
                (Mark::Line(GREEN, 2), "y axis of a frame".into()),
                (Mark::Line(BLUE, 2), "z axis of a frame".into()),
            ],
        )
        .map_err(&err)?;
        root.present().map_err(&err)?;
    }
    Ok(svg)
}

/// Update size per iteration of the iterative method (rotation rad, translation m) and the
/// refinement cost per evaluation, on a log scale; one line per phase of the primary answer.
pub fn convergence(input: &ReportInput) -> Result<String, ReportError> {
    let kind = "convergence";
    let err = plot_error(kind);
    let trace = &input.answers[0].calibration.solver.trace;
    let series = |phase: Phase| -> Vec<(f64, f64)> {
        trace
            .iter()
            .filter(|s| s.phase == phase)
            .enumerate()
            .filter(|(_, s)| s.update > 0.0 && s.update.is_finite())
            .map(|(i, s)| (i as f64, s.update))
            .collect()
    };
    let lines = [
        ("rotation update (rad)", series(Phase::Rotation)),
        ("translation update (m)", series(Phase::Translation)),
        ("refine cost ½Σr²", series(Phase::Refine)),
    ];
    let points = lines.iter().flat_map(|l| l.1.iter());
    let (mut lo, mut hi, mut len) = (f64::INFINITY, f64::NEG_INFINITY, 1.0f64);
    for &(x, y) in points {
        lo = lo.min(y);
        hi = hi.max(y);
        len = len.max(x + 1.0);
    }
    if !lo.is_finite() {
        (lo, hi) = (1e-12, 1.0);
    }
    let steps: Vec<usize> = lines.iter().map(|l| l.1.len()).collect();
    let solver = &input.answers[0].calibration.solver;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE).map_err(&err)?;
        let (root, key) = root.split_horizontally(WIDTH - LEGEND_WIDTH - 60);
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!(
                    "solver convergence ({}, {} iterations: {} rotation, {} translation, {} refine steps)",
                    solver.method.name(),
                    solver.iterations,
                    steps[0],
                    steps[1],
                    steps[2]
                ),
                ("sans-serif", 15),
            )
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(75)
            .build_cartesian_2d(0f64..len, ((lo * 0.5)..(hi * 2.0)).log_scale())
            .map_err(&err)?;
        chart
            .configure_mesh()
            .x_desc("step within each phase")
            .y_desc("update size / cost (log)")
            .label_style(("sans-serif", 16))
            .axis_desc_style(("sans-serif", 17))
            .y_label_formatter(&|y| format!("{y:.0e}"))
            .draw()
            .map_err(&err)?;
        for (k, (_, points)) in lines.iter().enumerate() {
            let colour = ANSWER_COLOURS[k % ANSWER_COLOURS.len()];
            chart
                .draw_series(LineSeries::new(
                    points.iter().copied(),
                    colour.stroke_width(2),
                ))
                .map_err(&err)?;
            // A marker at every step: a phase of one step (the rotation often converges at
            // once) draws no line, and equal values of two phases would hide one line.
            chart
                .draw_series(points.iter().map(|&point| {
                    Circle::new(point, 3 + 2 * (k as i32 == 0) as i32, colour.filled())
                }))
                .map_err(&err)?;
        }
        let entries: Vec<(Mark, String)> = lines
            .iter()
            .enumerate()
            .map(|(k, (label, _))| {
                (
                    Mark::Line(ANSWER_COLOURS[k % ANSWER_COLOURS.len()], 2),
                    label.to_string(),
                )
            })
            .collect();
        legend(&key, "phase", &entries).map_err(&err)?;
        root.present().map_err(&err)?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_core::geometry::pose_from_rotvec;
    use nalgebra::Vector3;

    /// `n` samples whose flange turns about a different axis each time.
    fn samples(n: usize) -> Vec<PosePair> {
        (0..n)
            .map(|k| {
                let t = k as f64;
                let turn = Vector3::new((0.7 * t).sin(), (1.3 * t).cos(), 0.5) * (0.2 + 0.01 * t);
                PosePair::new(
                    pose_from_rotvec(Vector3::new(0.4, 0.0, 0.3), turn),
                    pose_from_rotvec(Vector3::zeros(), Vector3::zeros()),
                )
            })
            .collect()
    }

    /// Markers drawn: each axis is drawn in both views.
    fn markers(svg: &str) -> usize {
        svg.matches("<circle").count() / 2
    }

    /// Up to 64 samples every pair is drawn; past that, the drawing stays at
    /// `MAX_ROTATION_AXES` pairs however many samples there are, and its title says so.
    #[test]
    fn the_rotation_axes_of_a_long_recording_are_drawn_at_a_bounded_number() {
        for (n, drawn) in [
            (20, 190),
            (64, 2016),
            (200, MAX_ROTATION_AXES),
            (1000, MAX_ROTATION_AXES),
        ] {
            let svg = rotation_axes(&samples(n)).unwrap();
            assert_eq!(markers(&svg), drawn, "{n} samples");
            let all = n * (n - 1) / 2;
            assert_eq!(
                svg.contains(&format!("{drawn} of {all} pairs")),
                drawn < all,
                "{n} samples: the title"
            );
        }
    }
}
