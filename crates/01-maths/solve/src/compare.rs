//! Every method on one data set (`handeye solve --compare`): each method's answer, its
//! residuals and its distance to the reference answer (the method asked for, by default the
//! refined one), as data ([`Comparison`]) and as one table ([`Comparison::table`]).
//!
//! A cross-check for users coming from OpenCV's `calibrateHandEye`: on good data all methods
//! agree within the noise; a method far from the rest points at a problem (degenerate motion
//! for the AX = XB methods, outliers for the linear ones). Pure: runs [`solve`]
//! once per method; depends only on the solver and the ground floor.

use std::fmt::Write as _;

use super::{solve, Calibration, Method, SolveError, SolveOptions};
use handeye_core::geometry::{rotvec, translation_distance, Pose};
use handeye_core::setup::{PosePair, Setup};

/// One method's answer and its distance to the reference answer.
#[derive(Debug, Clone, PartialEq)]
pub struct MethodAnswer {
    /// The full calibration (unknowns, residuals, warnings).
    pub calibration: Calibration,
    /// Distance of the camera mount's origin from the reference's, mm.
    pub camera_distance_mm: f64,
    /// Rotation between the camera mount and the reference's, degrees.
    pub camera_distance_deg: f64,
    /// Distance of the target mount's origin from the reference's, mm.
    pub target_distance_mm: f64,
    /// Rotation between the target mount and the reference's, degrees.
    pub target_distance_deg: f64,
}

/// One row of a comparison: a method and what it gave.
#[derive(Debug, Clone, PartialEq)]
pub struct ComparisonRow {
    /// The method.
    pub method: Method,
    /// Its answer, or why it gave none.
    pub answer: Result<MethodAnswer, SolveError>,
}

/// Every method's answer on one data set.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// The setup solved.
    pub setup: Setup,
    /// The method the distances are measured to.
    pub reference: Method,
    /// One row per method, in the order of [`Method::ALL`].
    pub rows: Vec<ComparisonRow>,
}

fn distance(a: &Pose, b: &Pose) -> (f64, f64) {
    (
        translation_distance(a, b) * 1e3,
        a.rotation.angle_to(&b.rotation).to_degrees(),
    )
}

/// Solves with every method of [`Method::ALL`] (all other options as given) and measures each
/// answer against the answer of `options.method`. Fails only when the reference method (or the
/// input checks every method shares) fails; another method's failure is kept in its row.
pub fn compare(
    setup: Setup,
    pairs: &[PosePair],
    options: &SolveOptions,
) -> Result<Comparison, SolveError> {
    let reference = solve(setup, pairs, options)?;
    let rows = Method::ALL
        .iter()
        .map(|&method| {
            let answer = if method == options.method {
                Ok(reference.clone())
            } else {
                solve(
                    setup,
                    pairs,
                    &SolveOptions {
                        method,
                        ..options.clone()
                    },
                )
            };
            let answer = answer.map(|calibration| {
                let (camera_distance_mm, camera_distance_deg) =
                    distance(&calibration.camera_mount, &reference.camera_mount);
                let (target_distance_mm, target_distance_deg) =
                    distance(&calibration.target_mount, &reference.target_mount);
                MethodAnswer {
                    calibration,
                    camera_distance_mm,
                    camera_distance_deg,
                    target_distance_mm,
                    target_distance_deg,
                }
            });
            ComparisonRow { method, answer }
        })
        .collect();
    Ok(Comparison {
        setup,
        reference: options.method,
        rows,
    })
}

/// `t [x, y, z] mm r [x, y, z]°` of a pose (rotation vector in degrees).
fn pose_cell(pose: &Pose) -> String {
    let t = pose.translation.vector * 1e3;
    let r = rotvec(&pose.rotation).map(f64::to_degrees);
    format!(
        "[{:8.1} {:8.1} {:8.1}] [{:7.2} {:7.2} {:7.2}]",
        t.x, t.y, t.z, r.x, r.y, r.z
    )
}

impl Comparison {
    /// The comparison as one text table: per method the two unknowns (translation mm, rotation
    /// vector degrees), the residual RMS and the distance of each unknown to the reference.
    pub fn table(&self) -> String {
        let (camera, target) = self.setup.unknown_names();
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{:<20} {:<55} {:<55} {:>18} {:>18} {:>18}",
            "method",
            format!("{camera} t (mm) / rotation vector (°)"),
            format!("{target} t (mm) / rotation vector (°)"),
            "residual RMS",
            format!("Δ {camera}"),
            format!("Δ {target}"),
        );
        for row in &self.rows {
            let name = if row.method == self.reference {
                format!("{} *", row.method.label())
            } else {
                row.method.label().to_string()
            };
            match &row.answer {
                Ok(a) => {
                    let c = &a.calibration;
                    let _ = writeln!(
                        out,
                        "{:<20} {:<55} {:<55} {:>8.2} mm {:>5.2}° {:>8.2} mm {:>5.2}° {:>8.2} mm {:>5.2}°",
                        name,
                        pose_cell(&c.camera_mount),
                        pose_cell(&c.target_mount),
                        c.residuals.translation_rms_mm,
                        c.residuals.rotation_rms_deg,
                        a.camera_distance_mm,
                        a.camera_distance_deg,
                        a.target_distance_mm,
                        a.target_distance_deg,
                    );
                }
                Err(e) => {
                    let _ = writeln!(out, "{name:<20} failed: {e}");
                }
            }
        }
        let _ = write!(
            out,
            "* reference ({}): Δ is each answer's distance to it (mm between origins, degrees between rotations)",
            self.reference.name()
        );
        out
    }
}
