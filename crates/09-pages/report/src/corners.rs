//! The per-corner evidence (Kalibr's report has both plots): every detected corner's
//! reprojection residual at the primary answer as a scatter, and where the corners fall in the
//! image with their residuals drawn as magnified arrows (the coverage map).
//!
//! Noise is a round cloud in the scatter and arrows pointing every way on the map; a wrong lens
//! model (intrinsics or distortion) shows as arrows that grow toward the edges or run the same way
//! in one region; empty parts of the map are parts of the image the board never covered, where
//! the intrinsics were not checked.

use std::borrow::Cow;
use std::fmt::Write;

use handeye_core::keeping_notable;
use nalgebra::{Point2, Vector2};
use plotters::prelude::*;

use super::sections::figure;
use super::{ReportError, ReportInput};

/// One detected corner of a sample, and its residual at the primary answer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerResidual {
    /// The sample (index into [`ReportInput::pairs`]).
    pub sample: usize,
    /// Where it was detected, px (OpenCV convention).
    pub detected_px: Point2<f64>,
    /// Detected minus reprojected at the answer's predicted `T_camera_target`, px.
    pub residual_px: Vector2<f64>,
}

/// The plot kinds of the corner section (`data-kind`); drawn when the input has corners.
pub const CORNER_PLOT_KINDS: [&str; 2] = ["corner-residuals", "corner-coverage"];

/// Colours of the samples in the scatter, cycled (ten distinguishable hues).
const SAMPLE_COLOURS: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

fn plot_error<E: std::fmt::Display>(kind: &'static str) -> impl Fn(E) -> ReportError {
    move |e| ReportError::Plot {
        kind,
        message: e.to_string(),
    }
}

/// Most corners the two plots draw (140 samples of a 6x6 aprilgrid's 144): a long recording's
/// corners would make a drawing of tens of megabytes (1,000 samples: 144,000 corners, 40 MB)
/// that shows no more. Past it, every corner at 3× the RMS or more is drawn (up to half of
/// this; they are what to look at) and the others evenly through the list.
pub(crate) const MAX_CORNERS_DRAWN: usize = 20_000;

/// The corners the plots draw ([`MAX_CORNERS_DRAWN`]), in their order; `rms` is theirs.
fn drawn(corners: &[CornerResidual], rms: f64) -> Cow<'_, [CornerResidual]> {
    if corners.len() <= MAX_CORNERS_DRAWN {
        return Cow::Borrowed(corners);
    }
    let far_from = 3.0 * rms;
    keeping_notable(corners.len(), MAX_CORNERS_DRAWN, |i| {
        corners[i].residual_px.norm() >= far_from
    })
    .into_iter()
    .map(|i| corners[i])
    .collect::<Vec<_>>()
    .into()
}

/// RMS of the residuals' lengths, px.
fn rms(corners: &[CornerResidual]) -> f64 {
    let sum: f64 = corners.iter().map(|c| c.residual_px.norm_squared()).sum();
    (sum / corners.len().max(1) as f64).sqrt()
}

/// The section: both plots, or a line saying why there are none.
pub(super) fn corners_section(
    html: &mut String,
    input: &ReportInput,
    id: &str,
) -> Result<(), ReportError> {
    let _ = writeln!(
        html,
        "<section id=\"{id}\"><h3>Corner residuals and coverage</h3>"
    );
    let corners = &input.corners;
    let Some((width, height)) = input.image_size.filter(|_| !corners.is_empty()) else {
        html.push_str("<p>No detected corners in this input (a plain dataset of pose pairs, or the board or intrinsics file could not be read): no per-corner plots.</p>\n</section>\n");
        return Ok(());
    };
    let samples = corners.iter().map(|c| c.sample).max().map_or(0, |m| m + 1);
    let rms = rms(corners);
    let _ = writeln!(
        html,
        "<p>Every detected corner's residual at the primary answer (detected − reprojected, px): <span data-key=\"corners.count\">{}</span> corners of {} samples, RMS <span data-key=\"corners.rms_px\">{:.3}</span> px. Noise is a round cloud on the left and arrows pointing every way on the right; arrows that grow toward the image edges or run the same way in one region are a lens model that does not fit (intrinsics or distortion), not noise. Parts of the {}×{} image without corners were never covered by the board: the intrinsics are untested there.</p>",
        corners.len(),
        samples,
        rms,
        width,
        height
    );
    let drawn = drawn(corners, rms);
    if drawn.len() < corners.len() {
        let _ = writeln!(
            html,
            "<p>The plots draw {} of the {} corners: every one at 3× the RMS or more (up to {}), and the others evenly through the samples.</p>",
            drawn.len(),
            corners.len(),
            MAX_CORNERS_DRAWN / 2
        );
    }
    figure(
        html,
        CORNER_PLOT_KINDS[0],
        &residual_scatter(corners, &drawn, rms)?,
    );
    figure(
        html,
        CORNER_PLOT_KINDS[1],
        &coverage_map(&drawn, rms, width, height)?,
    );
    html.push_str("</section>\n");
    Ok(())
}

/// The residuals of `drawn` (of `corners`, whose figures the side gives; `rms` is theirs) as
/// points (dx right, dy down as in the image), one colour per sample, with a circle at the RMS;
/// equal scales on both axes.
fn residual_scatter(
    corners: &[CornerResidual],
    drawn: &[CornerResidual],
    rms: f64,
) -> Result<String, ReportError> {
    let kind = CORNER_PLOT_KINDS[0];
    let err = plot_error(kind);
    let largest = corners
        .iter()
        .map(|c| c.residual_px.abs().max())
        .fold(0.0f64, f64::max);
    // The cloud fills the plot; a few far corners stay inside (they are what to look at).
    let half = (largest * 1.1).max(3.0 * rms).max(1e-3);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 470)).into_drawing_area();
        root.fill(&WHITE).map_err(&err)?;
        let (plot, side) = root.split_horizontally(500);
        let mut chart = ChartBuilder::on(&plot)
            .caption(
                "corner residuals, detected − reprojected (px)",
                ("sans-serif", 16),
            )
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(-half..half, half..-half)
            .map_err(&err)?;
        chart
            .configure_mesh()
            .x_desc("dx (px)")
            .y_desc("dy (px, down)")
            .light_line_style(WHITE)
            .draw()
            .map_err(&err)?;
        let circle = (0..=120).map(|k| {
            let t = k as f64 / 120.0 * std::f64::consts::TAU;
            (rms * t.cos(), rms * t.sin())
        });
        chart
            .draw_series(LineSeries::new(circle, BLACK.stroke_width(1)))
            .map_err(&err)?;
        chart
            .draw_series(drawn.iter().map(|c| {
                let colour = SAMPLE_COLOURS[c.sample % SAMPLE_COLOURS.len()];
                Circle::new(
                    (c.residual_px.x, c.residual_px.y),
                    2,
                    colour.mix(0.6).filled(),
                )
            }))
            .map_err(&err)?;
        let font = ("sans-serif", 16).into_font().color(&BLACK);
        let lines = [
            format!("{} corners", corners.len()),
            format!("RMS {rms:.3} px (circle)"),
            format!("largest {largest:.3} px"),
            "colour: sample".to_string(),
        ];
        for (k, line) in lines.iter().enumerate() {
            side.draw(&Text::new(
                line.clone(),
                (10, 40 + 24 * k as i32),
                font.clone(),
            ))
            .map_err(&err)?;
        }
        root.present().map_err(&err)?;
    }
    Ok(svg)
}

/// The image frame with the detected corners `drawn`, each residual drawn as an arrow magnified
/// so that the RMS residual (`rms`, of every corner) is about 2 % of the image width, coloured
/// from blue (0) to red (3× RMS and over).
fn coverage_map(
    drawn: &[CornerResidual],
    rms: f64,
    width: u32,
    height: u32,
) -> Result<String, ReportError> {
    let kind = CORNER_PLOT_KINDS[1];
    let err = plot_error(kind);
    let (w, h) = (f64::from(width.max(1)), f64::from(height.max(1)));
    let rms = rms.max(1e-9);
    // The RMS residual drawn about 2 % of the image width, at a round magnification (1, 2, 5 ×
    // a power of ten) a reader can take in.
    let wanted = (0.02 * w / rms).max(1.0);
    let decade = 10f64.powf(wanted.log10().floor());
    let gain = [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * decade)
        .find(|g| *g <= wanted)
        .unwrap_or(decade);
    let plot_width = 640.0;
    let plot_height = (plot_width * h / w).clamp(200.0, 900.0);
    let mut svg = String::new();
    {
        let root =
            SVGBackend::with_string(&mut svg, (900, plot_height as u32 + 90)).into_drawing_area();
        root.fill(&WHITE).map_err(&err)?;
        let (plot, side) = root.split_horizontally(plot_width as u32 + 70);
        let mut chart = ChartBuilder::on(&plot)
            .caption(
                format!("where the corners are, residuals ×{gain:.0} (image px)"),
                ("sans-serif", 16),
            )
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(55)
            .build_cartesian_2d(0.0..w, h..0.0)
            .map_err(&err)?;
        chart
            .configure_mesh()
            .x_desc("u (px)")
            .y_desc("v (px)")
            .light_line_style(WHITE)
            .draw()
            .map_err(&err)?;
        let colour = |size: f64| {
            let s = (size / (3.0 * rms)).clamp(0.0, 1.0);
            RGBColor((40.0 + 200.0 * s) as u8, 90, (220.0 - 190.0 * s) as u8)
        };
        chart
            .draw_series(drawn.iter().map(|c| {
                let end = c.detected_px + c.residual_px * gain;
                PathElement::new(
                    [(c.detected_px.x, c.detected_px.y), (end.x, end.y)],
                    colour(c.residual_px.norm()).stroke_width(1),
                )
            }))
            .map_err(&err)?;
        chart
            .draw_series(drawn.iter().map(|c| {
                Circle::new(
                    (c.detected_px.x, c.detected_px.y),
                    1,
                    colour(c.residual_px.norm()).filled(),
                )
            }))
            .map_err(&err)?;
        let font = ("sans-serif", 16).into_font().color(&BLACK);
        side.draw(&Text::new("residual", (10, 40), font.clone()))
            .map_err(&err)?;
        for (k, (label, size)) in [
            ("0 px".to_string(), 0.0),
            (format!("{rms:.3} px (RMS)"), rms),
            (format!("≥ {:.3} px", 3.0 * rms), 3.0 * rms),
        ]
        .into_iter()
        .enumerate()
        {
            let y = 64 + 24 * k as i32;
            side.draw(&Rectangle::new(
                [(10, y), (22, y + 12)],
                colour(size).filled(),
            ))
            .map_err(&err)?;
            side.draw(&Text::new(label, (30, y), font.clone()))
                .map_err(&err)?;
        }
        root.present().map_err(&err)?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `samples` samples of 144 corners, each residual 0.1 px but every 500th corner's 2 px.
    fn corners(samples: usize) -> Vec<CornerResidual> {
        (0..samples * 144)
            .map(|k| CornerResidual {
                sample: k / 144,
                detected_px: Point2::new((k % 1280) as f64, (k % 720) as f64),
                residual_px: Vector2::new(if k % 500 == 0 { 2.0 } else { 0.1 }, 0.0),
            })
            .collect()
    }

    /// A session's corners are all drawn; a long recording's are drawn at
    /// `MAX_CORNERS_DRAWN`, every far one among them, the others from every part of the list.
    #[test]
    fn the_plots_of_a_long_recording_draw_every_far_corner_and_a_bounded_number() {
        let few = corners(100);
        assert_eq!(drawn(&few, rms(&few)).len(), few.len());
        let many = corners(1000);
        let shown = drawn(&many, rms(&many));
        assert_eq!(shown.len(), MAX_CORNERS_DRAWN);
        let far = |c: &&CornerResidual| c.residual_px.x > 1.0;
        assert_eq!(
            shown.iter().filter(far).count(),
            many.iter().filter(far).count()
        );
        let last_sample = shown.iter().map(|c| c.sample).max().unwrap();
        assert!(
            last_sample >= 990,
            "the last samples are drawn too: {last_sample}"
        );
        let section = |corners: Vec<CornerResidual>| {
            let mut html = String::new();
            let input = ReportInput {
                title: String::new(),
                setup: handeye_core::setup::Setup::EyeInHand,
                pairs: Vec::new(),
                answers: Vec::new(),
                frames: None,
                holdout: None,
                verdict: None,
                arm_time: None,
                nominal: None,
                corners,
                image_size: Some((1280, 720)),
                robot_frames: Default::default(),
                arm: None,
            };
            corners_section(&mut html, &input, "corners").unwrap();
            html
        };
        assert!(!section(few).contains("The plots draw"));
        assert!(section(many).contains(&format!(
            "The plots draw {MAX_CORNERS_DRAWN} of the 144000 corners"
        )));
    }
}
