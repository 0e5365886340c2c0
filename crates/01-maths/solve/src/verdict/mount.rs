//! The verdict on one camera's mount solved with others (a cell with several cameras), by the
//! one-camera verdict's rules ([`super::rules`]) applied to what the joint solve measures of that
//! camera: its cell model (a given file the corners contradict), the held-out error of its own
//! samples, its mount's 1-sigma, with the same pose count for GOOD ([`GOOD_POSES`]). The cell's
//! verdict is its worst camera's ([`worst_camera`]).

use super::rules::{decide, held_out_finding, sigma_finding};
use super::{Accuracy, Basis, Figures, Finding, HeldOut, Level, Verdict, GOOD_POSES};
use crate::cell_model::CellModelSummary;
use crate::PoseSigma;

/// The verdict of a camera's mount from the joint solve, as [`super::assess`] judges one
/// camera's answer: its cell model's finding (a camera whose lens or board file is wrong is
/// never GOOD, and its verdict names the file), its held-out error (`held_out`, or why there is
/// none: CHECK) and its 1-sigma against `accuracy` (GOOD within it, CHECK up to the REDO factor,
/// REDO beyond), CHECK with fewer than [`GOOD_POSES`] samples; the worst leads, the others
/// follow under `also`.
pub fn assess_mount(
    sigma: &PoseSigma,
    held_out: Result<&HeldOut, &str>,
    samples: usize,
    accuracy: Accuracy,
    cell_model: Option<&CellModelSummary>,
) -> Verdict {
    let mut figures = Figures {
        poses: samples,
        cell_model: cell_model.cloned(),
        ..Figures::default()
    };
    let mut findings: Vec<Finding> = cell_model
        .and_then(|model| model.finding(accuracy))
        .into_iter()
        .collect();
    findings.extend(held_out_finding(held_out, accuracy, &mut figures));
    findings.extend(sigma_finding(
        sigma.translation_mm,
        sigma.rotation_deg,
        "",
        accuracy,
        &mut figures,
    ));
    if samples < GOOD_POSES {
        findings.push(Finding {
            level: Level::Check,
            basis: Basis::FewPoses,
            reason: format!("only {samples} samples (GOOD needs {GOOD_POSES})"),
            next_action: "add poses where it sees its board".into(),
        });
    }
    decide(findings, figures, accuracy)
}

/// The verdict of a camera left out of the joint solve (too few views, its own solve failed):
/// REDO, saying why.
pub fn left_out(why: &str, samples: usize, accuracy: Accuracy) -> Verdict {
    Verdict {
        level: Level::Redo,
        basis: Basis::Refused,
        reason: why.into(),
        next_action: "record poses where it sees its board".into(),
        accuracy,
        figures: Figures {
            poses: samples,
            ..Figures::default()
        },
        also: Vec::new(),
    }
}

/// The cell's verdict from its cameras' (name, verdict): the worst camera's, its reason
/// naming the camera (the first camera when several are equally bad); GOOD when every camera
/// is.
pub fn worst_camera<'a>(
    cameras: impl IntoIterator<Item = (&'a str, &'a Verdict)>,
    accuracy: Accuracy,
) -> Verdict {
    let mut worst: Option<(&str, &Verdict)> = None;
    for (name, verdict) in cameras {
        if verdict.level > worst.map_or(Level::Good, |(_, w)| w.level) {
            worst = Some((name, verdict));
        }
    }
    match worst {
        Some((name, verdict)) => Verdict {
            reason: format!("camera `{name}`: {}", verdict.reason),
            next_action: format!("camera `{name}`: {}", verdict.next_action),
            ..verdict.clone()
        },
        None => Verdict {
            level: Level::Good,
            basis: Basis::WithinAccuracy,
            reason: "every camera is GOOD".into(),
            next_action: "use it".into(),
            accuracy,
            figures: Figures::default(),
            also: Vec::new(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sigma(translation_mm: f64, rotation_deg: f64) -> PoseSigma {
        PoseSigma {
            rotation_deg,
            translation_mm,
            rotation_axes_deg: [rotation_deg; 3],
            translation_axes_mm: [translation_mm; 3],
        }
    }

    fn held(translation_rms_mm: f64) -> HeldOut {
        HeldOut {
            poses: 12,
            translation_rms_mm,
            rotation_rms_deg: 0.01,
            working_distance_mm: 500.0,
        }
    }

    #[test]
    fn a_mount_is_judged_by_the_worse_of_its_sigma_and_its_held_out_error() {
        let accuracy = Accuracy::default();
        let good = assess_mount(&sigma(0.1, 0.01), Ok(&held(0.5)), 12, accuracy, None);
        assert_eq!(
            (good.level, good.basis),
            (Level::Good, Basis::WithinAccuracy)
        );
        let held_out = assess_mount(&sigma(0.1, 0.01), Ok(&held(2.0)), 12, accuracy, None);
        assert_eq!(
            (held_out.level, held_out.basis),
            (Level::Check, Basis::HeldOutError)
        );
        let unsure = assess_mount(&sigma(4.0, 0.01), Ok(&held(0.5)), 12, accuracy, None);
        assert_eq!(
            (unsure.level, unsure.basis),
            (Level::Redo, Basis::Uncertainty)
        );
        let few = assess_mount(
            &sigma(0.1, 0.01),
            Ok(&held(0.5)),
            GOOD_POSES - 1,
            accuracy,
            None,
        );
        assert_eq!((few.level, few.basis), (Level::Check, Basis::FewPoses));
        let unchecked = assess_mount(&sigma(0.1, 0.01), Err("only 4 samples"), 12, accuracy, None);
        assert_eq!(unchecked.level, Level::Check);
        assert!(
            unchecked.reason.contains("only 4 samples"),
            "{}",
            unchecked.reason
        );
    }

    fn summary(chosen: crate::cell_model::Explanation) -> CellModelSummary {
        use crate::cell_model::{Candidate, Estimate, Explanation, GivenFile};
        let candidate = |explanation, bic| Candidate {
            explanation,
            chi2: bic,
            parameters: 12,
            bic,
            rms_px: 0.1,
            sigma_translation_mm: 0.1,
            sigma_rotation_deg: 0.01,
        };
        CellModelSummary {
            chosen,
            candidates: vec![
                candidate(Explanation::AsGiven, 5000.0),
                candidate(Explanation::BoardScale, 4000.0),
                candidate(Explanation::Intrinsics, 100.0),
            ],
            estimates: vec![Estimate {
                file: GivenFile::Intrinsics,
                parameter: "fx".into(),
                file_value: 848.0,
                estimate: 800.0,
                sigma: 0.05,
            }],
            determined: true,
            ambiguous: false,
            immaterial: None,
            unverifiable: Vec::new(),
            residuals: 5000,
            sigma_translation_mm: 0.1,
            sigma_rotation_deg: 0.01,
            written: Vec::new(),
        }
    }

    #[test]
    fn a_good_mount_with_a_wrong_lens_file_is_not_good_and_names_the_file() {
        use crate::cell_model::Explanation;
        let accuracy = Accuracy::default();
        let good = assess_mount(&sigma(0.1, 0.01), Ok(&held(0.5)), 12, accuracy, None);
        let mount = |sigma_mm, model| {
            assess_mount(&sigma(sigma_mm, 0.01), Ok(&held(0.5)), 12, accuracy, model)
        };
        let (wrong_lens, as_given) = (
            summary(Explanation::Intrinsics),
            summary(Explanation::AsGiven),
        );
        let wrong = mount(0.1, Some(&wrong_lens));
        assert_eq!(
            (wrong.level, wrong.basis),
            (Level::Check, Basis::Intrinsics)
        );
        assert!(
            wrong.reason.contains("fx in the file 848.0 px"),
            "{}",
            wrong.reason
        );
        assert!(wrong.also.is_empty(), "a GOOD mount adds no finding");
        assert!(wrong.figures.cell_model.is_some());
        // A worse mount verdict leads; the cell model's finding follows it.
        let both = mount(4.0, Some(&wrong_lens));
        assert_eq!((both.level, both.basis), (Level::Redo, Basis::Uncertainty));
        assert_eq!(both.also[0].basis, Basis::Intrinsics);
        // Files as given: the verdict stands, with the model's figures.
        let right = mount(0.1, Some(&as_given));
        assert_eq!(
            (right.level, right.reason.as_str()),
            (Level::Good, good.reason.as_str())
        );
        assert!(right.figures.cell_model.is_some());
    }

    #[test]
    fn the_cell_is_its_worst_camera_named() {
        let accuracy = Accuracy::default();
        let good = assess_mount(&sigma(0.1, 0.01), Ok(&held(0.5)), 12, accuracy, None);
        let check = assess_mount(&sigma(0.1, 0.01), Ok(&held(2.0)), 12, accuracy, None);
        let cell = worst_camera([("wrist", &good), ("left", &check)], accuracy);
        assert_eq!(cell.level, Level::Check);
        assert!(
            cell.reason.starts_with("camera `left`: "),
            "{}",
            cell.reason
        );
        let all_good = worst_camera([("wrist", &good)], accuracy);
        assert_eq!(all_good.level, Level::Good);
    }
}
