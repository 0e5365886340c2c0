//! The arm's own errors (issue #41): joint zero offsets estimated with the two transforms.
//!
//! Monte Carlo over drawn arm errors (seeded): the shipped sim cells' own plans (their joints,
//! from the plan check of `configs/sim-cell.yaml` and `configs/sim-cell-eye-to-hand.yaml`, a
//! UR10e), each pose's flange reported through the published model (`FK_nominal(q)`, with the
//! arm's repeatability noise) while the board is seen from the true arm (`FK_true(q)`, with
//! board-pose noise): synthetic pose pairs, so the draws run in seconds in a debug build. The
//! truth is in the controller's frames (`ArmErrors::fold`: the base and last joint offsets no
//! data can tell from the transforms). Then one whole run of `configs/sim-cell-arm-errors.yaml`
//! through the binary (rendered frames, detection, the solve with `solver.kinematics:
//! joint_offsets`), checked against its truth. The DH corrections (`solver.kinematics: dh`)
//! over the same plans with link errors drawn too. The exports of the arm's model (ur-calibration,
//! dh-table, arm-urdf) read back by parsers of their own; the fit against scipy's
//! (`reference.rs`).

use std::path::Path;

use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use handeye_core::geometry::{pose_from_rotvec, translation_distance, Pose};
use handeye_core::setup::{CellTransforms, PosePair, Setup, ViewSigma};
use handeye_robot::arm_errors::{ArmErrorSigmas, ArmErrors};
use handeye_robot::kinematics::UrModel;
use handeye_solve::kinematics::{fit_joint_offsets, ArmFit, ArmSample, OffsetStatus};
use handeye_solve::{NoiseModel, SolveOptions};

use crate::util::{config_variant, pose_error_mm_deg, repo};

mod reference;

/// Draws per setup (the issue asks for at least 20).
const DRAWS: u64 = 24;

/// The board-pose noise of the synthetic samples, 1σ per axis (mm, °), besides the arm's
/// repeatability (0.02 mm, 0.002°, as the shipped cells' `robot:`).
#[derive(Debug, Clone, Copy)]
struct BoardNoise(f64, f64);

/// The rendered sim cell's: its pose-space residuals with the arm model are 0.02–0.05 mm and
/// 0.005–0.007° RMS over 30 poses, arm repeatability included.
const RENDERED: BoardNoise = BoardNoise(0.02, 0.005);
/// Five times that: a poorer lens or board.
const PESSIMISTIC: BoardNoise = BoardNoise(0.1, 0.02);

/// A shipped cell's plan joints (rad), its arm model and its physical truth.
type ShippedPlan = (Vec<Vec<f64>>, UrModel, CellTransforms);

/// The shipped cell `config`'s plan joints (rad), its arm model and its physical truth.
fn shipped_plan(config: &Path) -> ShippedPlan {
    let prepared = handeye_session::cell::prepare(config).unwrap();
    let joints: Vec<Vec<f64>> = prepared
        .report
        .poses
        .iter()
        .filter_map(|p| p.joints.as_ref().map(|q| q.iter().copied().collect()))
        .collect();
    let truth = prepared.config.camera().simulation.unwrap();
    (joints, prepared.arm.unwrap(), truth)
}

/// Both shipped cells (eye in hand, eye to hand) with their plans generated at 30 poses, by
/// config name: [`shipped_plan`] of each.
fn shipped_cells_at_30_poses() -> Vec<(&'static str, ShippedPlan)> {
    let dir = tempfile::tempdir().unwrap();
    ["sim-cell.yaml", "sim-cell-eye-to-hand.yaml"]
        .into_iter()
        .map(|config| {
            let variant = config_variant(dir.path(), config, config, &[("count: 20", "count: 30")]);
            (config, shipped_plan(&variant))
        })
        .collect()
}

/// Samples of the cell `truth` whose arm has `errors`: reported through `model` with the arm's
/// repeatability (0.02 mm, 0.002°), seen through the true arm with the board-pose noise `board`.
fn samples(
    joints: &[Vec<f64>],
    model: &UrModel,
    errors: &ArmErrors,
    physical: &CellTransforms,
    board: BoardNoise,
    seed: u64,
) -> (Vec<ArmSample>, CellTransforms) {
    let repeatability = BoardNoise(0.02, 0.002);
    samples_with(
        joints,
        model,
        errors,
        physical,
        [board, repeatability],
        seed,
    )
}

/// A pose error drawn with 1σ `mm` per translation axis and `deg` per rotation axis.
fn drawn_noise(rng: &mut StdRng, mm: f64, deg: f64) -> Pose {
    let (t, r) = (
        Normal::new(0.0, mm * 1e-3).unwrap(),
        Normal::new(0.0, deg.to_radians()).unwrap(),
    );
    pose_from_rotvec(
        Vector3::from_fn(|_, _| t.sample(rng)),
        Vector3::from_fn(|_, _| r.sample(rng)),
    )
}

/// [`samples`] with the board-pose noise and the arm's repeatability `[board, arm]`.
fn samples_with(
    joints: &[Vec<f64>],
    model: &UrModel,
    errors: &ArmErrors,
    physical: &CellTransforms,
    [board, arm_noise]: [BoardNoise; 2],
    seed: u64,
) -> (Vec<ArmSample>, CellTransforms) {
    let (arm, truth) = errors.fold(model, physical);
    let mut rng = StdRng::seed_from_u64(seed);
    let mut noise = |mm: f64, deg: f64| drawn_noise(&mut rng, mm, deg);
    let out = joints
        .iter()
        .enumerate()
        .map(|(i, q)| {
            let q6 = handeye_robot::Joints::from_fn(6, |k| q[k]);
            let reported = model.forward(&q6) * noise(arm_noise.0, arm_noise.1);
            let flange = arm.forward(&q6);
            let seen = match truth.setup {
                Setup::EyeInHand => {
                    truth.camera_mount.inverse() * flange.inverse() * truth.target_mount
                }
                Setup::EyeToHand => truth.camera_mount.inverse() * flange * truth.target_mount,
            };
            let mut pair = PosePair::new(reported, seen * noise(board.0, board.1));
            pair.id = Some(format!("pose-{i:03}"));
            ArmSample {
                pair,
                joints: q.clone(),
            }
        })
        .collect();
    (out, truth)
}

/// The larger translation (mm) and rotation (°) error of the two transforms against `truth`.
fn transform_error(camera: &Pose, target: &Pose, truth: &CellTransforms) -> (f64, f64) {
    let (ct, cr) = pose_error_mm_deg(camera, &truth.camera_mount);
    let (tt, tr) = pose_error_mm_deg(target, &truth.target_mount);
    (ct.max(tt), cr.max(tr))
}

/// The pose-space solve without the arm's model, then the joint fit with it.
fn solve_both(setup: Setup, model: &UrModel, samples: &[ArmSample]) -> (Pose, Pose, ArmFit) {
    solve_both_with(setup, model, samples, &SolveOptions::default())
}

/// [`solve_both`] with `options`.
fn solve_both_with(
    setup: Setup,
    model: &UrModel,
    samples: &[ArmSample],
    options: &SolveOptions,
) -> (Pose, Pose, ArmFit) {
    let pairs: Vec<PosePair> = samples.iter().map(|s| s.pair.clone()).collect();
    let plain = handeye_solve::solve(setup, &pairs, options).unwrap();
    let noise: NoiseModel = plain.noise.map_or(options.noise, |n| n.model());
    let fit = fit_joint_offsets(
        setup,
        &handeye_records::solve::dh_chain(model),
        samples,
        (&plain.camera_mount, &plain.target_mount),
        noise,
        options,
    )
    .unwrap();
    (plain.camera_mount, plain.target_mount, fit)
}

/// What the draws of one setup gave.
#[derive(Debug, Default)]
struct Tally {
    draws: usize,
    /// Draws whose every estimated offset is within 3σ of the truth.
    within_3_sigma: usize,
    /// Draws with both transforms within 0.5 mm / 0.05°.
    within_bar: usize,
    /// Largest transform error with the arm model, (mm, °).
    worst_with: (f64, f64),
    /// Mean transform translation error, mm: with, without.
    mean_mm: [f64; 2],
    /// Largest transform translation error without the arm model, mm.
    worst_without_mm: f64,
    /// RMS of (estimate − truth) / 1σ over every estimated offset of every draw (1 when the
    /// 1σ are right).
    normalised_rms: f64,
    /// The estimated offsets' 1σ, degrees, sorted.
    sigmas_deg: Vec<f64>,
    /// Draws whose data choose the arm's model (`ArmFit::model_choice_margin` positive: what
    /// `solver.kinematics: auto`, the default, keeps).
    chosen: usize,
    /// Draws whose `auto` answer (with the model where chosen, without elsewhere) has both
    /// transforms within 0.5 mm / 0.05°.
    auto_within_bar: usize,
    /// Mean transform translation error of the `auto` answer, mm.
    auto_mean_mm: f64,
}

/// The draws of `sigmas` for the plan `joints` of the cell `physical`.
fn monte_carlo(
    (joints, model, physical): &(Vec<Vec<f64>>, UrModel, CellTransforms),
    sigmas: &ArmErrorSigmas,
    board: BoardNoise,
) -> Tally {
    let mut tally = Tally::default();
    let mut squares = Vec::new();
    for draw in 0..DRAWS {
        let errors = ArmErrors::draw(1000 + draw, sigmas);
        let (samples, truth) = samples(joints, model, &errors, physical, board, draw);
        let (camera, target, fit) = solve_both(physical.setup, model, &samples);
        let without = transform_error(&camera, &target, &truth);
        let with = transform_error(&fit.camera_mount, &fit.target_mount, &truth);
        tally.draws += 1;
        let chosen = fit.model_choice_margin() > 0.0;
        tally.chosen += usize::from(chosen);
        let auto = if chosen { with } else { without };
        tally.auto_mean_mm += auto.0 / DRAWS as f64;
        tally.auto_within_bar += usize::from(auto.0 <= 0.5 && auto.1 <= 0.05);
        tally.mean_mm[0] += with.0 / DRAWS as f64;
        tally.mean_mm[1] += without.0 / DRAWS as f64;
        tally.worst_without_mm = tally.worst_without_mm.max(without.0);
        tally.worst_with = (
            tally.worst_with.0.max(with.0),
            tally.worst_with.1.max(with.1),
        );
        if with.0 <= 0.5 && with.1 <= 0.05 {
            tally.within_bar += 1;
        }
        // Base and wrist 3 are absorbed on a UR, in both setups; the four others estimated.
        for j in [0, 5] {
            assert!(
                matches!(
                    fit.offsets[j].status,
                    OffsetStatus::Absorbed { by: Some(_) }
                ),
                "draw {draw}: {:?}",
                fit.offsets[j]
            );
        }
        let mut all = true;
        for o in &fit.offsets[1..5] {
            let OffsetStatus::Estimated { sigma_rad } = o.status else {
                panic!("draw {draw}: {o:?} not estimated");
            };
            let error = o.offset_rad - errors.joint_offsets_rad[o.joint];
            tally.sigmas_deg.push(sigma_rad.to_degrees());
            squares.push((error / sigma_rad).powi(2));
            all &= error.abs() <= 3.0 * sigma_rad;
        }
        if all {
            tally.within_3_sigma += 1;
        }
    }
    tally.normalised_rms = (squares.iter().sum::<f64>() / squares.len() as f64).sqrt();
    tally.sigmas_deg.sort_by(f64::total_cmp);
    tally
}

fn print(what: &str, t: &Tally) {
    eprintln!(
        "{what}: {} draws, the data choose the arm's model in {} (auto: within the bar in {}, mean {:.3} mm), offsets within 3σ in {} (normalised error RMS {:.2}, median 1σ {:.4}°), transforms within 0.5 mm / 0.05° in {} (worst {:.3} mm / {:.4}°); mean transform error {:.3} mm with the arm model, {:.3} mm without (worst {:.3} mm)",
        t.draws,
        t.chosen,
        t.auto_within_bar,
        t.auto_mean_mm,
        t.within_3_sigma,
        t.normalised_rms,
        t.sigmas_deg[t.sigmas_deg.len() / 2],
        t.within_bar,
        t.worst_with.0,
        t.worst_with.1,
        t.mean_mm[0],
        t.mean_mm[1],
        t.worst_without_mm
    );
}

/// Joint offsets drawn with 1σ 0.03° on every joint (no link errors: the model estimated is
/// the model simulated), both shipped cells with their plans generated at 30 poses (at 20 the
/// eye-to-hand cell's transforms meet the bar in 19 draws of 24: `poses_needed_for_the_offsets`).
#[test]
fn drawn_joint_offsets_are_found_within_their_sigma_and_the_transforms_within_the_bar() {
    let sigmas = ArmErrorSigmas {
        joint_offset_rad: 0.03f64.to_radians(),
        ..ArmErrorSigmas::default()
    };
    for (config, cell) in shipped_cells_at_30_poses() {
        assert!(cell.0.len() >= 25, "{} plan poses", cell.0.len());
        let t = monte_carlo(&cell, &sigmas, RENDERED);
        print(config, &t);
        // ≥ 95 % of the draws, and 1σ that are 1σ.
        assert!(20 * t.within_3_sigma >= 19 * t.draws, "{config}: {t:?}");
        assert!(20 * t.within_bar >= 19 * t.draws, "{config}: {t:?}");
        assert!((0.6..1.5).contains(&t.normalised_rms), "{config}: {t:?}");
        // Without the arm model the same errors cost more, and the data say so: `auto` keeps
        // the model in ≥ 95 % of the draws.
        assert!(t.mean_mm[1] > 2.0 * t.mean_mm[0], "{config}: {t:?}");
        assert!(20 * t.chosen >= 19 * t.draws, "{config}: {t:?}");
        assert!(20 * t.auto_within_bar >= 19 * t.draws, "{config}: {t:?}");
        // With five times the board noise the offsets' 1σ still cover the truth (the bar on
        // the transforms is then the noise's, not the arm's: printed).
        let t = monte_carlo(&cell, &sigmas, PESSIMISTIC);
        print(&format!("{config}, 5x board noise"), &t);
        assert!(20 * t.within_3_sigma >= 19 * t.draws, "{config}: {t:?}");
    }
}

/// An arm exactly as published (no joint offsets, no link errors), the same cells, plans and
/// noise: the data do not choose the arm's model (`solver.kinematics: auto` keeps the published
/// one) in ≥ 95 % of the draws — at the rendered cell's board noise and at five times it.
#[test]
fn an_arm_as_published_is_not_given_a_model_by_the_default() {
    let exact = ArmErrorSigmas {
        joint_offset_rad: 0.0,
        ..ArmErrorSigmas::default()
    };
    for (config, cell) in shipped_cells_at_30_poses() {
        for (noise, board) in [("rendered", RENDERED), ("5x", PESSIMISTIC)] {
            let t = monte_carlo(&cell, &exact, board);
            print(&format!("{config}, an exact arm, {noise} board noise"), &t);
            assert!(20 * t.chosen <= t.draws, "{config}, {noise}: {t:?}");
            if noise == "rendered" {
                assert!(20 * t.auto_within_bar >= 19 * t.draws, "{config}: {t:?}");
            }
        }
    }
}

/// Joint offsets drawn as in the test above, seen in views of mixed precision (a fixed camera
/// watching the board on the flange sees it near and far): in 10–40 % of the views the board-pose
/// noise is 1–8 times the typical (log-uniform), each view's recorded 1-sigma off by up to
/// ±25 %. The arm's fit weighs each view as the pose-space solve does: its transforms nearer the
/// truth than with every view alike (as the fit took them before), its offsets' 1-sigma honest.
#[test]
fn joint_offsets_seen_in_views_of_mixed_precision_weigh_each_view_at_its_precision() {
    use rand::Rng;
    for (config, (joints, model, physical)) in shipped_cells_at_30_poses() {
        // Per weighing (each view at its precision, every view alike): mean transform error
        // (mm), mean squared normalised offset error, draws choosing the model.
        let mut tally = [(0.0, 0.0, 0usize); 2];
        for draw in 0..DRAWS {
            let errors = ArmErrors::draw(2000 + draw, &ArmErrorSigmas::default());
            let (mut samples, truth) = samples(
                &joints,
                &model,
                &errors,
                &physical,
                BoardNoise(0.0, 0.0),
                draw,
            );
            let mut rng = StdRng::seed_from_u64(3000 + draw);
            let noisy_share = rng.random_range(0.1..0.4);
            for sample in &mut samples {
                let k: f64 = if rng.random_bool(noisy_share) {
                    8f64.powf(rng.random::<f64>())
                } else {
                    1.0
                };
                let (mm, deg) = (k * RENDERED.0, k * RENDERED.1);
                sample.pair.camera_from_target *= drawn_noise(&mut rng, mm, deg);
                let misread = rng.random_range(0.75..1.25);
                sample.pair.view_sigma = Some(ViewSigma {
                    rotation_deg: deg * misread,
                    translation_mm: mm * misread,
                });
            }
            for (i, weigh_views) in [true, false].into_iter().enumerate() {
                let options = SolveOptions {
                    weigh_views,
                    ..SolveOptions::default()
                };
                let (_, _, fit) = solve_both_with(physical.setup, &model, &samples, &options);
                let (mm, _) = transform_error(&fit.camera_mount, &fit.target_mount, &truth);
                let squares: f64 = fit.offsets[1..5]
                    .iter()
                    .filter_map(|o| match o.status {
                        OffsetStatus::Estimated { sigma_rad } => Some(
                            ((o.offset_rad - errors.joint_offsets_rad[o.joint]) / sigma_rad)
                                .powi(2),
                        ),
                        _ => None,
                    })
                    .sum();
                tally[i].0 += mm / DRAWS as f64;
                tally[i].1 += squares / (4 * DRAWS) as f64;
                tally[i].2 += usize::from(fit.model_choice_margin() > 0.0);
            }
        }
        eprintln!(
            "{config}, drawn offsets, views of mixed precision, {DRAWS} draws: mean transform error {:.3} mm weighed, {:.3} mm alike; offsets' normalised error RMS {:.2} weighed, {:.2} alike; model chosen in {} weighed, {} alike",
            tally[0].0, tally[1].0, tally[0].1.sqrt(), tally[1].1.sqrt(), tally[0].2, tally[1].2
        );
        // Measured: 0.066 against 0.087 mm in hand, 0.207 against 0.355 mm to hand; the
        // offsets' 1-sigma honest both ways (normalised error RMS 0.89–0.99).
        assert!(tally[0].0 <= 0.85 * tally[1].0, "{config}: {tally:?}");
        assert!(tally[0].1.sqrt() <= 1.5, "{config}: {tally:?}");
    }
}

/// Link length and twist errors of a few tenths of a millimetre and hundredths of a degree
/// besides the offsets: `joint_offsets` does not model them (the DH corrections would). The
/// figures are printed; the offsets must still make the answer better on average.
#[test]
fn with_length_and_twist_errors_too_the_offsets_still_help() {
    let sigmas = ArmErrorSigmas {
        joint_offset_rad: 0.03f64.to_radians(),
        length_m: 0.2e-3,
        twist_rad: 0.01f64.to_radians(),
    };
    let cell = shipped_plan(&repo().join("configs/sim-cell.yaml"));
    let t = monte_carlo(&cell, &sigmas, RENDERED);
    print("sim-cell.yaml with 0.2 mm / 0.01° link errors", &t);
    assert!(t.mean_mm[0] < t.mean_mm[1], "{t:?}");
}

/// `solver.kinematics: dh` (`fit_arm` with `ArmModel::Dh`): 24 drawn arms per shipped cell
/// (offsets 0.03°, link lengths 0.2 mm, twists 0.01°, 1σ each; the plans generated at 30
/// poses, the rendered cell's board noise and the arm's repeatability). The truth is taken in
/// the parametrisation the data determine: the same fit of the same poses without any noise
/// (it reproduces every seen board pose to 1e-4 mm: the held parameters are absorbed or
/// undetermined exactly). Asserted: eye-in-hand, both transforms within 0.5 mm / 0.05° of that
/// truth in ≥ 95 % of the draws; both setups, both transforms within 3 of their reported 1σ in
/// ≥ 95 % of the draws, each estimated parameter within 3σ of its truth in ≥ 95 % of the
/// draws, the parameters' errors over 1σ of RMS 0.7–1.3. Printed: the parameters held, the
/// eye-to-hand bar figure, and the transform error of the joint offsets alone against the
/// physical truth.
#[test]
fn drawn_dh_errors_are_found_within_their_sigma_and_the_transforms_within_the_bar() {
    use handeye_solve::kinematics::{fit_arm, ArmModel};
    use std::collections::BTreeMap;
    let sigmas = ArmErrorSigmas {
        joint_offset_rad: 0.03f64.to_radians(),
        length_m: 0.2e-3,
        twist_rad: 0.01f64.to_radians(),
    };
    let dir = tempfile::tempdir().unwrap();
    for (config, count) in [("sim-cell.yaml", 30), ("sim-cell-eye-to-hand.yaml", 30)] {
        let variant = config_variant(
            dir.path(),
            config,
            config,
            &[("count: 20", &format!("count: {count}"))],
        );
        let (joints, model, physical) = shipped_plan(&variant);
        assert!(
            joints.len() + 5 >= count,
            "{config}: {} poses",
            joints.len()
        );
        let chain = handeye_records::solve::dh_chain(&model);
        let (mut within_bar, mut worst, mut offsets_only_mm) = (0, (0.0f64, 0.0f64), 0.0);
        let (mut within_sigma, mut sigma_mm) = (0, Vec::new());
        let mut outside: BTreeMap<String, usize> = BTreeMap::new();
        let mut squares = Vec::new();
        let mut held = String::new();
        for draw in 0..DRAWS {
            let errors = ArmErrors::draw(3000 + draw, &sigmas);
            let (noisy, physical_truth) =
                samples(&joints, &model, &errors, &physical, RENDERED, draw);
            let none = BoardNoise(0.0, 0.0);
            let (exact, _) = samples_with(&joints, &model, &errors, &physical, [none, none], draw);
            let (_, _, offsets_only) = solve_both(physical.setup, &model, &noisy);
            offsets_only_mm += transform_error(
                &offsets_only.camera_mount,
                &offsets_only.target_mount,
                &physical_truth,
            )
            .0 / DRAWS as f64;
            let pairs: Vec<PosePair> = noisy.iter().map(|s| s.pair.clone()).collect();
            let options = SolveOptions::default();
            let plain = handeye_solve::solve(physical.setup, &pairs, &options).unwrap();
            let fit = fit_arm(
                ArmModel::Dh,
                physical.setup,
                &chain,
                &noisy,
                (&plain.camera_mount, &plain.target_mount),
                plain.noise.map_or(options.noise, |n| n.model()),
                &options,
            )
            .unwrap();
            let fixed = SolveOptions {
                estimate_noise: handeye_solve::EstimateNoise::NONE,
                ..SolveOptions::default()
            };
            let truth = fit_arm(
                ArmModel::Dh,
                physical.setup,
                &chain,
                &exact,
                (&fit.camera_mount, &fit.target_mount),
                fit.noise.model(),
                &fixed,
            )
            .unwrap();
            assert!(
                truth.translation_rms_mm[0] < 1e-4,
                "{config} draw {draw}: the noise-free fit leaves {} mm",
                truth.translation_rms_mm[0]
            );
            let error = (
                pose_error_mm_deg(&fit.camera_mount, &truth.camera_mount),
                pose_error_mm_deg(&fit.target_mount, &truth.target_mount),
            );
            let (mm, deg) = (error.0 .0.max(error.1 .0), error.0 .1.max(error.1 .1));
            worst = (worst.0.max(mm), worst.1.max(deg));
            // The transforms' own 1σ (the link corrections' uncertainty included) cover their
            // error: each within 3σ.
            let u = fit.uncertainty.as_ref().expect("the fit's 1σ");
            let ratio = [
                error.0 .0 / u.camera_mount.translation_mm,
                error.0 .1 / u.camera_mount.rotation_deg,
                error.1 .0 / u.target_mount.translation_mm,
                error.1 .1 / u.target_mount.rotation_deg,
            ]
            .into_iter()
            .fold(0.0f64, f64::max);
            within_sigma += usize::from(ratio <= 3.0);
            sigma_mm.push(
                u.camera_mount
                    .translation_mm
                    .max(u.target_mount.translation_mm),
            );
            within_bar += usize::from(mm <= 0.5 && deg <= 0.05);
            let (ours, theirs) = (fit.corrections(), truth.corrections());
            let rows = fit
                .offsets
                .iter()
                .map(|o| (o.joint, 0, "theta_offset", o.status))
                .chain(
                    fit.links
                        .iter()
                        .map(|l| (l.joint, l.parameter as usize, l.parameter.name(), l.status)),
                );
            let mut this_held = Vec::new();
            for (j, p, name, status) in rows {
                let OffsetStatus::Estimated { sigma_rad } = status else {
                    this_held.push(format!("{name}{j}: {status:?}"));
                    continue;
                };
                let e = (ours[j][p] - theirs[j][p]) / sigma_rad;
                squares.push(e * e);
                *outside.entry(format!("{name}{j}")).or_insert(0) += usize::from(e.abs() > 3.0);
            }
            held = this_held.join(", ");
        }
        let rms = (squares.iter().sum::<f64>() / squares.len() as f64).sqrt();
        eprintln!(
            "{config}, dh: transforms within 0.5 mm / 0.05° of the truth in {within_bar} of {DRAWS} (worst {:.3} mm / {:.4}°, within 3 of their 1σ in {within_sigma}, median translation 1σ {:.3} mm); parameters outside 3σ per draw: {outside:?}; error / 1σ RMS {rms:.2}; held (last draw): {held}; the joint offsets alone: mean transform error {offsets_only_mm:.3} mm against the physical truth",
            worst.0,
            worst.1,
            crate::util::median(sigma_mm)
        );
        assert!(
            20 * within_sigma >= 19 * DRAWS as usize,
            "{config}: {within_sigma}"
        );
        // The bar holds eye-in-hand; eye-to-hand the shipped plan leaves the transforms with a
        // median 0.86 mm 1σ once the links are free (0.46 mm at 60 poses; measured: 10 of 24
        // within the bar at 30 poses, 9 at 60; the 1σ cover the error in 24 of 24), so there
        // the honest 1σ are what is asserted.
        if physical.setup == Setup::EyeInHand {
            assert!(
                20 * within_bar >= 19 * DRAWS as usize,
                "{config}: {within_bar}"
            );
        }
        for (param, n) in &outside {
            assert!(
                20 * n <= DRAWS as usize,
                "{config}: {param} outside 3σ in {n} draws"
            );
        }
        assert!((0.7..1.3).contains(&rms), "{config}: error / 1σ RMS {rms}");
    }
}

/// How many poses the offsets need: the first N poses of a 40-pose generated plan of each
/// shipped cell, over the draws, the offsets' median 1σ and the mean transform error with and
/// without the arm's model.
#[test]
fn poses_needed_for_the_offsets() {
    let dir = tempfile::tempdir().unwrap();
    let sigmas = ArmErrorSigmas {
        joint_offset_rad: 0.03f64.to_radians(),
        ..ArmErrorSigmas::default()
    };
    for base in ["sim-cell.yaml", "sim-cell-eye-to-hand.yaml"] {
        let config = config_variant(dir.path(), base, base, &[("count: 20", "count: 40")]);
        let (joints, model, physical) = shipped_plan(&config);
        let mut figures = Vec::new();
        for n in [8, 12, 16, 20, 30, 40]
            .into_iter()
            .filter(|&n| n <= joints.len())
        {
            let cell = (joints[..n].to_vec(), model.clone(), physical);
            let t = monte_carlo(&cell, &sigmas, RENDERED);
            figures.push((
                n,
                t.sigmas_deg[t.sigmas_deg.len() / 2],
                t.mean_mm[0],
                t.mean_mm[1],
            ));
        }
        eprintln!(
            "{base} poses: (N, median offset 1σ °, mean transform error mm with, without): {figures:?}"
        );
        let (first, last) = (figures[0], figures[figures.len() - 1]);
        assert!(last.0 >= 30 && last.1 < first.1, "{figures:?}");
    }
}

#[test]
fn the_shipped_arm_errors_cell_finds_its_offsets_and_transforms_through_the_binary() {
    let dir = tempfile::tempdir().unwrap();
    let config = config_variant(
        dir.path(),
        "sim-cell-arm-errors.yaml",
        "sim-cell-arm-errors.yaml",
        &[],
    );
    let session = dir.path().join("session");
    let output = crate::util::run_cli(&config, &session);
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    eprintln!("{stdout}");
    assert!(stdout.contains("arm model truth check"), "{stdout}");
    let cell = handeye_config::CellConfig::load(&config).unwrap();
    let truth = cell.camera().simulation.unwrap();
    let errors = cell.arm_errors.unwrap();
    let result_path = session.join("result.yaml");
    let result = handeye_records::result::ResultFile::load(&result_path).unwrap();
    // The transforms, against the truth in the controller's frames.
    let mounts = result.mounts(&result_path).unwrap();
    let (mm, deg) = transform_error(&mounts.camera_mount, &mounts.target_mount, &truth);
    eprintln!("transforms: {mm:.3} mm, {deg:.4}° from the truth");
    assert!(mm <= 0.5 && deg <= 0.05, "{mm} mm, {deg}°");
    // The offsets, each with its 1σ in the result file; base and wrist 3 absorbed.
    let kinematics = result
        .kinematics
        .expect("the result records the arm's model");
    assert_eq!(kinematics.model, "ur10e");
    assert_eq!(kinematics.joint_offsets.len(), 6);
    assert_eq!(
        kinematics.joint_offsets[0].absorbed_by.as_deref(),
        Some("T_base_target")
    );
    assert_eq!(
        kinematics.joint_offsets[5].absorbed_by.as_deref(),
        Some("T_flange_camera")
    );
    for (j, o) in kinematics.joint_offsets.iter().enumerate().take(5).skip(1) {
        let sigma = o.sigma_deg.unwrap_or_else(|| panic!("joint {j}: {o:?}"));
        let error = o.offset_deg - errors.joint_offsets_rad[j].to_degrees();
        eprintln!("{}: error {error:+.4}° (1σ {sigma:.4}°)", o.joint);
        assert!(
            error.abs() <= 3.0 * sigma,
            "{}: {error}° vs 1σ {sigma}°",
            o.joint
        );
    }
    assert!(kinematics.translation_rms_mm.with < kinematics.translation_rms_mm.without);
    // What it bought over the recorded workspace: the flange against the true arm, the mean
    // error with the estimated model under a quarter of the published model's (0.08 mm against
    // 0.69 mm measured), and the result says how far the model moves the flange.
    let line = stdout
        .lines()
        .find(|l| l.contains("flange position over the 30 recorded poses"))
        .unwrap_or_else(|| panic!("no flange truth line: {stdout}"));
    let figures: Vec<f64> = line
        .split(": ")
        .nth(1)
        .unwrap()
        .split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .filter_map(|w| w.parse().ok())
        .collect();
    let (published, estimated) = (figures[0], figures[2]);
    assert!(estimated < 0.25 * published, "{line}");
    let moved = kinematics
        .flange_correction_mm
        .expect("flange_correction_mm");
    assert!(
        (0.5 * published..2.0 * published).contains(&moved.mean) && moved.max >= moved.mean,
        "{moved:?} against the published model's {published} mm"
    );
    // The report shows the arm's model: its section, each offset held or estimated, the
    // figures of result.yaml.
    let page = std::fs::read_to_string(session.join("report.html")).unwrap();
    let shown = |key: &str| -> f64 {
        let tag = format!("data-key=\"{key}\">");
        let start = page
            .find(&tag)
            .unwrap_or_else(|| panic!("no {key} on the page"))
            + tag.len();
        let end = start + page[start..].find('<').unwrap();
        page[start..end].parse().unwrap()
    };
    assert!((shown("kinematics.flange_correction_mm.mean") - moved.mean).abs() < 1e-3);
    assert!(
        (shown("kinematics.translation_rms_mm.with") - kinematics.translation_rms_mm.with).abs()
            < 1e-3
    );
    assert!(
        page.contains("held: absorbed by T_base_target"),
        "no held offset on the page"
    );
    // `verify --session` checks the samples as the solve saw them: the robot poses corrected by
    // the arm's model, refitted without each left-out sample. It checked them as recorded,
    // where they disagree by the arm's errors (1.09 mm, CHECK, blaming "a frame or robot pose
    // recorded wrong") while the run's held-out figure was 0.05 mm, GOOD.
    let held = result
        .verdict
        .as_ref()
        .and_then(|v| v.figures.held_out)
        .expect("the run's held-out figure");
    let verify = crate::util::succeeds(
        crate::util::handeye()
            .args(["verify", "--session"])
            .arg(&session),
    );
    assert!(
        verify.contains("corrected them with the arm's own model"),
        "{verify}"
    );
    crate::util::assert_leave_one_out_is_held_out(&verify, &held);
    assert!(verify.contains("verdict: GOOD"), "{verify}");
    // The old form one flag away: the samples as recorded disagree by the arm's errors.
    let recorded = crate::util::succeeds(
        crate::util::handeye()
            .args(["verify", "--as-recorded", "--session"])
            .arg(&session),
    );
    assert!(
        !recorded.contains("corrected them") && recorded.contains("verdict: CHECK"),
        "{recorded}"
    );
    // A held-out run of the result on the cell predicts the arm where its estimated model puts
    // it, as the answer's own poses were: with the robot poses as the controller reports them
    // (its published model) the fresh views disagree by the arm's errors, which verify called
    // CHECK, 1.18 mm, "was the camera or the board moved since the calibration?".
    let holdout = crate::util::succeeds(&mut crate::util::holdout_command(
        &config,
        &result_path,
        &dir.path().join("holdout"),
    ));
    assert!(
        holdout.contains(&format!(
            "corrected by the arm's model in {}",
            result_path.display()
        )),
        "{holdout}"
    );
    let rms = holdout
        .split("translation at the target RMS ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|t| t.parse::<f64>().ok())
        .unwrap_or_else(|| panic!("no holdout RMS: {holdout}"));
    assert!(rms < 0.3, "holdout {rms} mm: {holdout}");
    assert!(holdout.contains("verdict: GOOD"), "{holdout}");
}

/// `solver.kinematics` absent is `auto`: the data choose. The shipped arm-errors cell without
/// the key keeps the arm's model (its offsets explain the residuals) and meets the bar; the
/// shipped sim cell, whose arm is exactly as published, keeps the published model and says
/// why. `none` keeps the old default one key away.
#[test]
fn by_default_the_data_choose_the_arms_model_through_the_binary() {
    let dir = tempfile::tempdir().unwrap();
    let run = |base: &str, edits: &[(&str, &str)], name: &str| {
        let config = config_variant(dir.path(), base, &format!("{name}.yaml"), edits);
        let session = dir.path().join(name);
        let output = crate::util::run_cli(&config, &session);
        assert!(
            output.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
        let result_path = session.join("result.yaml");
        let result = handeye_records::result::ResultFile::load(&result_path).unwrap();
        let cell = handeye_config::CellConfig::load(&config).unwrap();
        let mounts = result.mounts(&result_path).unwrap();
        let (mm, deg) = transform_error(
            &mounts.camera_mount,
            &mounts.target_mount,
            &cell.camera().simulation.unwrap(),
        );
        let said: Vec<String> = result.notices.iter().map(|n| n.message.clone()).collect();
        eprintln!("{name}: {mm:.3} mm, {deg:.4}° from the truth; {said:?}");
        (result, (mm, deg), said)
    };
    let errors_auto = [(", kinematics: joint_offsets}", "}")];
    let (result, (mm, deg), said) = run("sim-cell-arm-errors.yaml", &errors_auto, "errors-auto");
    assert!(result.kinematics.is_some(), "{said:?}");
    assert!(
        said.iter()
            .any(|m| m.contains("the data choose the arm's own model")),
        "{said:?}"
    );
    assert!(mm <= 0.5 && deg <= 0.05, "{mm} mm, {deg}°");
    // A replay solves as the run did: the same choice, the same answer.
    let replayed = dir.path().join("errors-auto-replay/result.yaml");
    let replay = crate::util::handeye()
        .arg("replay")
        .arg(dir.path().join("errors-auto"))
        .arg("-o")
        .arg(&replayed)
        .output()
        .unwrap();
    assert!(
        replay.status.success(),
        "{}",
        String::from_utf8_lossy(&replay.stderr)
    );
    let again = handeye_records::result::ResultFile::load(&replayed).unwrap();
    assert_eq!(
        again.kinematics.map(|k| k.joint_offsets.len()),
        result.kinematics.as_ref().map(|k| k.joint_offsets.len())
    );
    let errors_none = [(", kinematics: joint_offsets}", ", kinematics: none}")];
    let (result, (mm_none, _), _) = run("sim-cell-arm-errors.yaml", &errors_none, "errors-none");
    assert!(result.kinematics.is_none());
    assert!(
        mm_none > mm,
        "without the arm's model {mm_none} mm, with it {mm} mm"
    );
    // Link errors ten times the shipped cell's (0.2 mm, 0.01°): `auto` keeps the DH link
    // corrections beside the offsets, and its answer is nearer the truth than the offsets'
    // alone (`joint_offsets`, one key away).
    let links = [
        (", kinematics: joint_offsets}", "}"),
        (
            "length_mm: 0.02, twist_deg: 0.001",
            "length_mm: 0.2, twist_deg: 0.01",
        ),
    ];
    let (result, (mm_links, deg_links), said) =
        run("sim-cell-arm-errors.yaml", &links, "links-auto");
    let estimated = result.kinematics.as_ref().map(|k| k.estimated.clone());
    assert_eq!(estimated.as_deref(), Some("dh"), "{said:?}");
    assert!(
        said.iter()
            .any(|m| m.contains("the data choose the arm's own model")
                && m.contains("with its DH link corrections")),
        "{said:?}"
    );
    // The same cell with the shipped config's `kinematics: joint_offsets` kept.
    let offsets_alone = [links[1]];
    let (_, (mm_offsets, _), _) = run("sim-cell-arm-errors.yaml", &offsets_alone, "links-offsets");
    assert!(
        mm_links < mm_offsets && mm_links <= 0.5 && deg_links <= 0.05,
        "auto with the links {mm_links} mm / {deg_links}°, the offsets alone {mm_offsets} mm"
    );
    let (result, (mm, deg), said) = run("sim-cell.yaml", &[], "exact-auto");
    assert!(result.kinematics.is_none(), "{said:?}");
    assert!(
        said.iter()
            .any(|m| m.contains("the arm's published model is kept")),
        "{said:?}"
    );
    assert!(mm <= 0.5 && deg <= 0.05, "{mm} mm, {deg}°");
}

/// `simulation.arm_errors` and `solver.kinematics` in a config: read, drawn repeatably, folded
/// into the truth; mistakes named by file and key.
#[test]
fn arm_errors_and_kinematics_keys_are_read_and_checked() {
    use handeye_config::CellConfig;
    let base = std::fs::read_to_string(repo().join("configs/sim-cell-arm-errors.yaml")).unwrap();
    let file = repo().join("configs/sim-cell-arm-errors.yaml");
    let cell = CellConfig::parse(&base, &file).unwrap();
    let errors = cell.arm_errors.unwrap();
    assert_eq!(
        Some(errors),
        CellConfig::parse(&base, &file).unwrap().arm_errors,
        "the draw repeats"
    );
    assert!(errors
        .joint_offsets_rad
        .iter()
        .all(|v| v.abs() < 0.2f64.to_radians()));
    // The truth is folded: the sim arm's base and wrist 3 offsets are in the transforms.
    let arm = cell.true_arm.clone().unwrap();
    assert_eq!((arm.joint_offsets[0], arm.joint_offsets[5]), (0.0, 0.0));
    let plain = CellConfig::load(&repo().join("configs/sim-cell.yaml")).unwrap();
    let (moved_mm, _) = pose_error_mm_deg(
        &cell.camera().simulation.unwrap().target_mount,
        &plain.camera().simulation.unwrap().target_mount,
    );
    assert!(moved_mm > 0.01 && moved_mm < 2.0, "{moved_mm}");

    let refused = |from: &str, to: &str| {
        assert!(base.contains(from), "{from}");
        let text = base.replace(from, to);
        CellConfig::parse(&text, &file).unwrap_err().to_string()
    };
    let draw = "arm_errors: {seed: 41, joint_offset_deg: 0.03, length_mm: 0.02, twist_deg: 0.001}";
    let message = refused(
        draw,
        "arm_errors: {seed: 41, joint_offset_deg: 0.03, d_mm: [0, 0, 0, 0, 0, 0]}",
    );
    assert!(
        message.contains("sim-cell-arm-errors.yaml")
            && message.contains("simulation.arm_errors")
            && message.contains("not both"),
        "{message}"
    );
    let message = refused(draw, "arm_errors: {joint_offset_deg: 0.03}");
    assert!(message.contains("simulation.arm_errors.seed"), "{message}");
    let message = refused(draw, "arm_errors: {a_mm: [0.1, 0.2]}");
    assert!(
        message.contains("simulation.arm_errors.a_mm") && message.contains("2 values"),
        "{message}"
    );
    let message = refused(draw, "arm_errors: {seed: 1, twist_deg: 3}");
    assert!(
        message.contains("simulation.arm_errors.twist_deg"),
        "{message}"
    );
    let dh = CellConfig::parse(
        &base.replace("kinematics: joint_offsets", "kinematics: dh"),
        &file,
    )
    .unwrap();
    assert_eq!(dh.solver.kinematics(), handeye_config::KinematicsChoice::Dh);
    let text = base
        .replace("intrinsics: cameras/sim-1280x720.yaml\n", "")
        .replace(
            "camera:\n  backend: sim\n",
            "camera:\n  backend: sim\n  intrinsics: cameras/sim-1280x720.yaml\n",
        );
    let message = CellConfig::parse(&text, &file).unwrap_err().to_string();
    assert!(
        message.contains("solver.kinematics") && message.contains("intrinsics"),
        "{message}"
    );
    let message = refused("kinematics: joint_offsets", "kinematics: all");
    assert!(message.contains("solver"), "{message}");
    // Absent: nothing estimated, and the shipped demo cell is unchanged.
    assert_eq!(plain.solver.kinematics, None);
    assert_eq!(
        plain.solver.kinematics(),
        handeye_config::KinematicsChoice::Auto
    );
    assert!(plain.arm_errors.is_none() && plain.true_arm.is_none());
}

/// A joint's origin as a URDF gives it (`xyz`, `rpy` = `Rz(yaw)·Ry(pitch)·Rx(roll)`), read from
/// a parsed ur_calibration YAML by key.
fn urdf_origin(entry: &serde_yaml_ng::Value) -> Pose {
    let get = |key: &str| {
        entry
            .get(key)
            .and_then(serde_yaml_ng::Value::as_f64)
            .unwrap_or_else(|| panic!("no {key} in {entry:?}"))
    };
    Pose::from_parts(
        nalgebra::Translation3::new(get("x"), get("y"), get("z")),
        nalgebra::UnitQuaternion::from_euler_angles(get("roll"), get("pitch"), get("yaw")),
    )
}

/// `T_base_tool0` of a ur_calibration YAML at `q`, as ur_description chains it: each joint's
/// origin then its turn about z; `base` is `base_link_inertia` and `tool0` is `wrist_3_link`
/// (their fixed transforms compose to the identity).
fn urdf_forward(text: &str, q: &[f64]) -> Pose {
    let doc: serde_yaml_ng::Value = serde_yaml_ng::from_str(text).unwrap();
    let kinematics = doc.get("kinematics").expect("a kinematics mapping");
    assert!(kinematics
        .get("hash")
        .and_then(serde_yaml_ng::Value::as_str)
        .is_some_and(|h| h.starts_with("calib_")));
    [
        "shoulder",
        "upper_arm",
        "forearm",
        "wrist_1",
        "wrist_2",
        "wrist_3",
    ]
    .iter()
    .zip(q)
    .fold(Pose::identity(), |acc, (link, angle)| {
        acc * urdf_origin(kinematics.get(*link).unwrap())
            * Pose::from_parts(
                nalgebra::Translation3::identity(),
                nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), *angle),
            )
    })
}

/// A reader of an exported arm model: `T_base_tool0` of the file's text at the joints.
type ForwardOf = fn(&str, &[f64]) -> Pose;

/// `T_base_tool0` of a DH table (`--format dh-table`) at `q`: its lines read as
/// `joint a d alpha theta_offset` (comments `#`), each link `Rz(q + theta_offset) · Tz(d) ·
/// Tx(a) · Rx(alpha)` composed here from those numbers.
fn dh_table_forward(text: &str, q: &[f64]) -> Pose {
    let rows: Vec<Vec<f64>> = text
        .lines()
        .filter(|l| !l.trim_start().starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            l.split_whitespace()
                .skip(1)
                .map(|v| v.parse::<f64>().unwrap_or_else(|e| panic!("{l}: {e}")))
                .collect()
        })
        .collect();
    assert_eq!(rows.len(), 6, "{text}");
    let turn = |axis: &nalgebra::Unit<Vector3<f64>>, angle: f64| {
        Pose::from_parts(
            nalgebra::Translation3::identity(),
            nalgebra::UnitQuaternion::from_axis_angle(axis, angle),
        )
    };
    let shift = |x: f64, z: f64| {
        Pose::from_parts(
            nalgebra::Translation3::new(x, 0.0, z),
            nalgebra::UnitQuaternion::identity(),
        )
    };
    rows.iter()
        .zip(q)
        .fold(Pose::identity(), |acc, (row, angle)| {
            let (a, d, alpha, offset) = (row[0], row[1], row[2], row[3]);
            acc * turn(&Vector3::z_axis(), angle + offset)
                * shift(0.0, d)
                * shift(a, 0.0)
                * turn(&Vector3::x_axis(), alpha)
        })
}

/// `T_base_tool0` of a URDF (`--format arm-urdf`) at `q`, read by roxmltree: from the link
/// `base`, each joint whose parent is the current link, its `origin xyz rpy`
/// (`Rz(yaw)·Ry(pitch)·Rx(roll)`), then a revolute joint's turn about its `axis` by the next
/// angle of `q`, until `tool0`.
fn urdf_chain_forward(text: &str, q: &[f64]) -> Pose {
    let doc = roxmltree::Document::parse(text).unwrap();
    let numbers = |node: roxmltree::Node, key: &str| -> Vec<f64> {
        node.attribute(key)
            .unwrap_or_else(|| panic!("no {key}"))
            .split_whitespace()
            .map(|v| v.parse().unwrap())
            .collect()
    };
    let (mut link, mut pose, mut angles) = ("base".to_string(), Pose::identity(), q.iter());
    while link != "tool0" {
        let joint = doc
            .descendants()
            .find(|n| {
                n.has_tag_name("joint")
                    && n.children()
                        .any(|c| c.has_tag_name("parent") && c.attribute("link") == Some(&link))
            })
            .unwrap_or_else(|| panic!("no joint from {link}"));
        let child = |tag: &str| joint.children().find(|c| c.has_tag_name(tag));
        let origin = child("origin").unwrap();
        let (xyz, rpy) = (numbers(origin, "xyz"), numbers(origin, "rpy"));
        pose *= Pose::from_parts(
            nalgebra::Translation3::new(xyz[0], xyz[1], xyz[2]),
            nalgebra::UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
        );
        if joint.attribute("type") == Some("revolute") {
            let axis = numbers(child("axis").unwrap(), "xyz");
            pose *= Pose::from_parts(
                nalgebra::Translation3::identity(),
                nalgebra::UnitQuaternion::from_axis_angle(
                    &nalgebra::Unit::new_normalize(Vector3::new(axis[0], axis[1], axis[2])),
                    *angles.next().expect("more joints than angles"),
                ),
            );
        }
        link = child("child")
            .unwrap()
            .attribute("link")
            .unwrap()
            .to_string();
    }
    assert!(angles.next().is_none(), "fewer joints than angles");
    pose
}

/// `handeye export RESULT --format ur-calibration | dh-table | arm-urdf` of a result with the
/// arm's model: each read back by a parser of its own (a generic YAML parser chained as
/// ur_description chains it; the table's numbers composed as DH links; roxmltree's URDF chained
/// joint by joint) reproduces the corrected flange poses (the joint offsets and three link
/// corrections of `estimated: dh`) within 1e-6 m and 1e-6 rad at 50 random joint vectors.
#[test]
fn the_arm_model_exports_reproduce_the_corrected_flange_poses() {
    use handeye_records::result::{
        JointOffsetYaml, KinematicsYaml, LinkCorrectionYaml, WithWithout,
    };
    let model = UrModel::ur10e();
    // Link corrections as `estimated: dh` writes them: the shoulder's a, the elbow's alpha, the
    // wrist 1's d.
    let links = [
        ("shoulder", "a", "mm", 0.12),
        ("elbow", "alpha", "deg", 0.01),
        ("wrist 1", "d", "mm", -0.05),
    ];
    let offsets_deg = [0.0, 0.0531, -0.0201, -0.0008, 0.0727, 0.0];
    let kinematics = KinematicsYaml {
        model: "ur10e".into(),
        estimated: "dh".into(),
        joint_offsets: offsets_deg
            .iter()
            .enumerate()
            .map(|(j, o)| JointOffsetYaml {
                joint: format!("joint {j}"),
                offset_deg: *o,
                sigma_deg: Some(0.001),
                absorbed_by: None,
                undetermined: false,
            })
            .collect(),
        links: links
            .iter()
            .map(|(joint, parameter, unit, correction)| LinkCorrectionYaml {
                joint: (*joint).into(),
                parameter: (*parameter).into(),
                unit: (*unit).into(),
                correction: *correction,
                sigma: Some(0.01),
                absorbed_by: None,
                undetermined: false,
            })
            .collect(),
        translation_rms_mm: WithWithout {
            with: 0.0,
            without: 0.0,
        },
        rotation_rms_deg: WithWithout {
            with: 0.0,
            without: 0.0,
        },
        uncertainty: None,
        flange_correction_mm: None,
    };
    // Through the binary, from a result file: the shipped arm-errors cell solved with
    // `kinematics: dh` (its section names every link correction), then given the section above.
    let dir = tempfile::tempdir().unwrap();
    let session = dir.path().join("session");
    let config = config_variant(
        dir.path(),
        "sim-cell-arm-errors.yaml",
        "cell.yaml",
        &[("kinematics: joint_offsets", "kinematics: dh")],
    );
    let run = crate::util::run_cli(&config, &session);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let result_path = session.join("result.yaml");
    let mut result = handeye_records::result::ResultFile::load(&result_path).unwrap();
    let solved = result.kinematics.as_ref().expect("the arm's model");
    assert_eq!(solved.estimated, "dh");
    assert_eq!(solved.links.len(), 18, "{solved:?}");
    let estimated = solved.links.iter().filter(|l| l.sigma.is_some()).count();
    assert!(estimated >= 10, "{solved:?}");
    // The run's truth check names every estimated link correction against the simulator's.
    let stdout = String::from_utf8_lossy(&run.stdout);
    let checked: Vec<&str> = stdout
        .lines()
        .skip_while(|l| *l != "arm model truth check (estimated link corrections):")
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .collect();
    assert_eq!(checked.len(), estimated, "{stdout}");
    assert!(
        checked
            .iter()
            .all(|l| l.contains("σ) against the simulator's")),
        "{stdout}"
    );
    result.kinematics = Some(kinematics);
    result.save(&result_path).unwrap();
    let mut errors = ArmErrors {
        joint_offsets_rad: offsets_deg.map(f64::to_radians),
        ..ArmErrors::default()
    };
    errors.a_m[1] = 0.12e-3;
    errors.alpha_rad[2] = 0.01f64.to_radians();
    errors.d_m[3] = -0.05e-3;
    let corrected = errors.true_arm(&model);
    let forms: [(&str, ForwardOf); 3] = [
        ("ur-calibration", urdf_forward),
        ("dh-table", dh_table_forward),
        ("arm-urdf", urdf_chain_forward),
    ];
    for (format, forward) in forms {
        let out = dir.path().join(format);
        let export = crate::util::handeye()
            .args(["export"])
            .arg(&result_path)
            .args(["--format", format, "-o"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(
            export.status.success(),
            "{format}: {}",
            String::from_utf8_lossy(&export.stderr)
        );
        let text = std::fs::read_to_string(&out).unwrap();
        let mut rng = StdRng::seed_from_u64(3);
        let mut worst = (0.0f64, 0.0f64);
        for _ in 0..50 {
            let q: Vec<f64> = (0..6)
                .map(|_| rand::Rng::random_range(&mut rng, -3.0..3.0))
                .collect();
            let expected = corrected.forward(&handeye_robot::Joints::from_fn(6, |k| q[k]));
            let (mm, deg) = pose_error_mm_deg(&forward(&text, &q), &expected);
            assert!(
                mm < 1e-3 && deg.to_radians() < 1e-6,
                "{format}: {mm} mm, {deg}° at {q:?}\n{text}"
            );
            worst = (worst.0.max(mm), worst.1.max(deg.to_radians()));
        }
        eprintln!(
            "{format}: worst {:.1e} m, {:.1e} rad from the corrected model",
            worst.0 * 1e-3,
            worst.1
        );
    }
    // A result without the arm's model is refused, naming the key.
    result.kinematics = None;
    result.save(&result_path).unwrap();
    for (format, _) in forms {
        let refused = crate::util::handeye()
            .args(["export"])
            .arg(&result_path)
            .args(["--format", format])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&refused.stderr);
        assert!(
            !refused.status.success() && stderr.contains("kinematics"),
            "{format}: {stderr}"
        );
    }
}

/// #41: the held-out check of an answer whose robot poses the arm's model corrects refits the
/// model without each held-out sample. Fitted to that sample too, the model (the DH corrections
/// here, 24 parameters over the shipped sim cell's 20 poses) predicts it partly from itself.
/// Against fresh poses of the same cell (the plan's joints moved by up to 15°, new noise: the
/// true error of predicting a pose the fit has not seen), the refitted held-out error is the
/// nearer estimate, and the one fitted to every sample the lower, in most draws.
#[test]
fn the_held_out_check_refits_the_arms_model_without_each_sample() {
    use handeye_solve::kinematics::{fit_arm, ArmModel, ArmRefit};
    use handeye_solve::verdict::held_out_refitting;
    use rand::Rng;
    const HELD_OUT_DRAWS: u64 = 8;
    let sigmas = ArmErrorSigmas {
        joint_offset_rad: 0.03f64.to_radians(),
        length_m: 0.2e-3,
        twist_rad: 0.01f64.to_radians(),
    };
    let (joints, model, physical) = shipped_plan(&repo().join("configs/sim-cell.yaml"));
    let setup = physical.setup;
    let chain = handeye_records::solve::dh_chain(&model);
    let options = SolveOptions::default();
    let (mut nearer, mut lower) = (0, 0);
    for draw in 0..HELD_OUT_DRAWS {
        let errors = ArmErrors::draw(5000 + draw, &sigmas);
        let (noisy, _) = samples(&joints, &model, &errors, &physical, RENDERED, draw);
        let pairs: Vec<PosePair> = noisy.iter().map(|s| s.pair.clone()).collect();
        let plain = handeye_solve::solve(setup, &pairs, &options).unwrap();
        let noise = plain.noise.map_or(options.noise, |n| n.model());
        let start = (plain.camera_mount, plain.target_mount);
        let fit = fit_arm(
            ArmModel::Dh,
            setup,
            &chain,
            &noisy,
            (&start.0, &start.1),
            noise,
            &options,
        )
        .unwrap();
        let corrected: Vec<PosePair> = noisy
            .iter()
            .map(|s| PosePair {
                base_from_flange: fit.corrected_flange(&chain, s),
                ..s.pair.clone()
            })
            .collect();
        let full = handeye_solve::solve(setup, &corrected, &options).unwrap();
        let refit = ArmRefit {
            setup,
            model: ArmModel::Dh,
            chain: chain.clone(),
            samples: noisy.clone(),
            dropped: plain.dropped.clone(),
            start,
            noise,
            options: options.clone(),
        };
        let refitted = held_out_refitting(
            setup,
            &corrected,
            &options,
            &full,
            Some(&|k| refit.flanges_without(k)),
        )
        .unwrap()
        .translation_rms_mm;
        let fitted_to_all = handeye_solve::verdict::held_out(setup, &corrected, &options, &full)
            .unwrap()
            .translation_rms_mm;
        // Fresh poses: the plan's joints moved, seen through the same arm with new noise.
        let mut rng = StdRng::seed_from_u64(9000 + draw);
        let moved: Vec<Vec<f64>> = joints
            .iter()
            .map(|q| {
                q.iter()
                    .map(|v| v + rng.random_range(-15f64..15.0).to_radians())
                    .collect()
            })
            .collect();
        let (fresh, _) = samples(&moved, &model, &errors, &physical, RENDERED, 100 + draw);
        let squares: Vec<f64> = fresh
            .iter()
            .map(|s| {
                let predicted = handeye_core::setup::predict(
                    setup,
                    &full.camera_mount,
                    &full.target_mount,
                    &fit.corrected_flange(&chain, s),
                );
                let e = (predicted.translation.vector
                    - s.pair.camera_from_target.translation.vector)
                    .norm()
                    * 1e3;
                e * e
            })
            .collect();
        let fresh_rms = (squares.iter().sum::<f64>() / squares.len() as f64).sqrt();
        eprintln!(
            "draw {draw}: held-out {refitted:.4} mm refitted per fold, {fitted_to_all:.4} mm fitted to all; fresh poses {fresh_rms:.4} mm"
        );
        if (refitted - fresh_rms).abs() < (fitted_to_all - fresh_rms).abs() {
            nearer += 1;
        }
        if fitted_to_all < refitted {
            lower += 1;
        }
    }
    eprintln!("refitted nearer the fresh error in {nearer} of {HELD_OUT_DRAWS} draws, fitted-to-all lower in {lower}");
    assert!(
        nearer >= 6,
        "refitted nearer in {nearer} of {HELD_OUT_DRAWS}"
    );
    assert!(
        lower >= 6,
        "fitted-to-all lower in {lower} of {HELD_OUT_DRAWS}"
    );
}

/// #41: `plan check` says what a plan determines of the arm's model before anything moves (the
/// model fitted to noise-free samples of the nominal cell at the plan's joints, at the
/// configured noise). Its predicted 1σ of each offset is the spread of the offsets fitted to
/// samples drawn at that noise (30 draws: each within 0.7–1.4× of the spread); the base and
/// last joints are named as absorbed, and so is wrist 2 when the plan moves neither it nor
/// wrist 3 (its offset then only turns the flange-side transform). The poses it says the model
/// needs (the first N of the plan) give each transform an RMS error within the accuracy asked
/// over 30 draws at that noise.
#[test]
fn plan_check_predicts_the_offsets_sigma_and_names_a_joint_the_plan_does_not_move() {
    use handeye_solve::kinematics::{fit_arm, ArmModel};
    let config_path = repo().join("configs/sim-cell-arm-errors.yaml");
    let prepared = handeye_session::cell::prepare(&config_path).unwrap();
    let note = prepared
        .report
        .notes
        .iter()
        .find(|n| n.starts_with("solver.kinematics: joint_offsets"))
        .unwrap_or_else(|| panic!("no arm model note: {:?}", prepared.report.notes))
        .clone();
    eprintln!("{note}");
    assert!(
        note.contains("base (absorbed by T_base_target)")
            && note.contains("wrist 3 (absorbed by T_flange_camera)"),
        "{note}"
    );
    let predicted = |joint: &str| -> f64 {
        let at = note
            .find(&format!("{joint} "))
            .unwrap_or_else(|| panic!("{joint}: {note}"));
        let rest = &note[at + joint.len() + 1..];
        rest[..rest.find('°').unwrap()].parse().unwrap()
    };
    // Draws at the configured noise, fitted with it fixed (as the prediction assumes).
    let (joints, model, physical) = shipped_plan(&config_path);
    let options = SolveOptions {
        estimate_noise: handeye_solve::EstimateNoise::NONE,
        ..prepared.config.solver.to_options()
    };
    let noise = options.noise;
    let board = BoardNoise(
        noise.translation_sigma_m * 1e3,
        noise.rotation_sigma_rad.to_degrees(),
    );
    let chain = handeye_records::solve::dh_chain(&model);
    let none = ArmErrors::default();
    let names = ["shoulder", "elbow", "wrist 1", "wrist 2"];
    // The offsets' fit of the first `n` poses drawn at that noise with `seed`.
    let drawn_fit = |n: usize, seed: u64| {
        let (noisy, _) = samples_with(
            &joints[..n],
            &model,
            &none,
            &physical,
            [board, BoardNoise(0.0, 0.0)],
            seed,
        );
        fit_arm(
            ArmModel::JointOffsets,
            physical.setup,
            &chain,
            &noisy,
            (&physical.camera_mount, &physical.target_mount),
            noise,
            &options,
        )
        .unwrap()
    };
    let mut estimates: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    for draw in 0..30 {
        let fit = drawn_fit(joints.len(), 7000 + draw);
        for (k, e) in estimates.iter_mut().enumerate() {
            e.push(fit.offsets[k + 1].offset_rad.to_degrees());
        }
    }
    for (name, values) in names.iter().zip(&estimates) {
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        let spread = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>()
            / (values.len() - 1) as f64)
            .sqrt();
        let ratio = predicted(name) / spread;
        eprintln!(
            "{name}: predicted 1σ {:.4}°, spread of 30 draws {spread:.4}° ({ratio:.2}×)",
            predicted(name)
        );
        assert!((0.7..=1.4).contains(&ratio), "{name}: {ratio}");
    }
    // How many poses it needs: the first N of the plan, fitted to draws at the configured
    // noise, give each transform an RMS error within the accuracy asked (its 1σ is).
    let needed: usize = {
        let at = note.find("the first ").expect("the poses needed") + "the first ".len();
        note[at..].split(' ').next().unwrap().parse().unwrap()
    };
    assert!(
        (8..joints.len()).contains(&needed),
        "{needed} poses: {note}"
    );
    let accuracy = prepared.config.verdict.accuracy();
    let mut squares = [0.0f64; 4];
    for draw in 0..30 {
        let fit = drawn_fit(needed, 8000 + draw);
        let camera = pose_error_mm_deg(&fit.camera_mount, &physical.camera_mount);
        let target = pose_error_mm_deg(&fit.target_mount, &physical.target_mount);
        for (sum, e) in squares
            .iter_mut()
            .zip([camera.0, camera.1, target.0, target.1])
        {
            *sum += e * e / 30.0;
        }
    }
    let rms = squares.map(f64::sqrt);
    eprintln!("the first {needed} poses, 30 draws: RMS error camera mount {:.3} mm / {:.4}°, target mount {:.3} mm / {:.4}°", rms[0], rms[1], rms[2], rms[3]);
    assert!(
        rms[0].max(rms[2]) <= accuracy.translation_mm
            && rms[1].max(rms[3]) <= accuracy.rotation_deg,
        "{rms:?}"
    );
    // A plan whose wrists 2 and 3 never move: wrist 2's offset is no longer estimated.
    let plan: Vec<_> = prepared
        .report
        .validated()
        .unwrap()
        .into_iter()
        .map(|(pose, mut q)| {
            q[4] = 0.3;
            q[5] = -0.2;
            (pose, q)
        })
        .collect();
    let fixed = handeye_records::solve::plan_observability(
        &prepared.config,
        prepared.arm.as_ref().unwrap(),
        &prepared.config.camera().nominal,
        &plan,
    )
    .unwrap();
    eprintln!("{fixed}");
    let estimated = &fixed[..fixed.find("; held at 0").unwrap_or(fixed.len())];
    assert!(!estimated.contains("wrist 2 0."), "{fixed}");
    assert!(
        fixed.contains("wrist 2 (absorbed")
            || fixed.contains("not determined by these poses: wrist 2"),
        "{fixed}"
    );
}

/// `solver.kinematics: auto` and the DH link corrections: after the data choose the joint offsets,
/// `ArmRefit::links_choice` (what the session's choice runs) keeps the link corrections only
/// when the data need them (the nested χ² test at 1 %) and the answer is expected nearer the
/// truth with them (the offsets' bias, read from how far the two answers lie apart, against
/// the scatter the links add). 24 drawn arms per class on the shipped cells' 30-pose plans:
/// an exact arm, offsets of 0.03° alone, offsets with links of 0.2 mm / 0.01° (1σ each), at the
/// rendered cell's board noise and five times it. The truth is the noise-free DH fit of the
/// same poses (the parametrisation the data determine, as in the DH test above). Asserted:
/// without link errors the links are kept in at most 1 draw of 24 (no false alarm); with them,
/// eye-in-hand at the rendered noise, kept in ≥ 18 (left out where the offsets' answer is as
/// near: measured 22) and the answer within 0.5 mm / 0.05° in ≥ 23;
/// in every class the mean error of `auto`'s answer is within 1.2× the better of the offsets
/// always and the links always (where the links cost more than they correct, as eye-to-hand at
/// five times the noise, `auto` mostly leaves them out).
#[test]
fn auto_keeps_the_dh_link_corrections_where_they_bring_the_answer_nearer() {
    use handeye_solve::kinematics::{fit_arm, ArmModel, ArmRefit};
    let offsets_alone = ArmErrorSigmas {
        joint_offset_rad: 0.03f64.to_radians(),
        ..ArmErrorSigmas::default()
    };
    let with_links = ArmErrorSigmas {
        length_m: 0.2e-3,
        twist_rad: 0.01f64.to_radians(),
        ..offsets_alone
    };
    let exact = ArmErrorSigmas {
        joint_offset_rad: 0.0,
        ..ArmErrorSigmas::default()
    };
    for (config, (joints, model, physical)) in shipped_cells_at_30_poses() {
        let chain = handeye_records::solve::dh_chain(&model);
        for (class, sigmas, board) in [
            ("an exact arm", exact, RENDERED),
            ("offsets alone", offsets_alone, RENDERED),
            ("offsets alone, 5x board noise", offsets_alone, PESSIMISTIC),
            ("offsets and links", with_links, RENDERED),
            ("offsets and links, 5x board noise", with_links, PESSIMISTIC),
        ] {
            let (mut kept, mut within_bar) = (0, 0);
            // Mean transform translation error, mm: auto, the offsets always, the links always.
            let mut mean_mm = [0.0; 3];
            for draw in 0..DRAWS {
                let errors = ArmErrors::draw(5000 + draw, &sigmas);
                let (noisy, _) = samples(&joints, &model, &errors, &physical, board, draw);
                let none = BoardNoise(0.0, 0.0);
                let (exact_samples, _) =
                    samples_with(&joints, &model, &errors, &physical, [none, none], draw);
                let pairs: Vec<PosePair> = noisy.iter().map(|s| s.pair.clone()).collect();
                let options = SolveOptions::default();
                let plain = handeye_solve::solve(physical.setup, &pairs, &options).unwrap();
                let refit = ArmRefit {
                    setup: physical.setup,
                    model: ArmModel::JointOffsets,
                    chain: chain.clone(),
                    samples: noisy,
                    dropped: plain.dropped.clone(),
                    start: (plain.camera_mount, plain.target_mount),
                    noise: plain.noise.map_or(options.noise, |n| n.model()),
                    options: options.clone(),
                };
                let offsets = refit.fit_without(None).unwrap();
                let (_, links, choice) = refit.links_choice(&offsets).unwrap();
                let fixed = SolveOptions {
                    estimate_noise: handeye_solve::EstimateNoise::NONE,
                    ..SolveOptions::default()
                };
                let truth = fit_arm(
                    ArmModel::Dh,
                    physical.setup,
                    &chain,
                    &exact_samples,
                    (&links.camera_mount, &links.target_mount),
                    links.noise.model(),
                    &fixed,
                )
                .unwrap();
                let error = |camera: &Pose, target: &Pose| {
                    let (c, t) = (
                        pose_error_mm_deg(camera, &truth.camera_mount),
                        pose_error_mm_deg(target, &truth.target_mount),
                    );
                    (c.0.max(t.0), c.1.max(t.1))
                };
                let chosen = offsets.model_choice_margin() > 0.0 && choice.chosen();
                kept += usize::from(chosen);
                let auto = match (offsets.model_choice_margin() > 0.0, chosen) {
                    (false, _) => error(&plain.camera_mount, &plain.target_mount),
                    (true, false) => error(&offsets.camera_mount, &offsets.target_mount),
                    (true, true) => error(&links.camera_mount, &links.target_mount),
                };
                within_bar += usize::from(auto.0 <= 0.5 && auto.1 <= 0.05);
                for (sum, mm) in mean_mm.iter_mut().zip([
                    auto.0,
                    error(&offsets.camera_mount, &offsets.target_mount).0,
                    error(&links.camera_mount, &links.target_mount).0,
                ]) {
                    *sum += mm / DRAWS as f64;
                }
            }
            eprintln!(
                "{config}, {class}: the links kept in {kept} of {DRAWS}, auto within 0.5 mm / 0.05° in {within_bar}; mean transform error {:.3} mm (auto), {:.3} mm (offsets always), {:.3} mm (links always)",
                mean_mm[0], mean_mm[1], mean_mm[2]
            );
            let better = mean_mm[1].min(mean_mm[2]);
            assert!(mean_mm[0] <= 1.2 * better, "{config}, {class}: {mean_mm:?}");
            if sigmas.length_m == 0.0 {
                assert!(
                    20 * kept <= DRAWS as usize,
                    "{config}, {class}: kept {kept}"
                );
            } else if physical.setup == Setup::EyeInHand && board.0 == RENDERED.0 {
                assert!(
                    4 * kept >= 3 * DRAWS as usize,
                    "{config}, {class}: kept {kept}"
                );
                assert!(
                    20 * within_bar >= 19 * DRAWS as usize,
                    "{config}, {class}: {within_bar}"
                );
            }
        }
    }
}

/// A seven-joint arm (issue #41): the arm fit is written for any DH chain, and a lab's Franka
/// or KUKA iiwa has seven joints. The chain is a KUKA LBR iiwa 7's link dimensions (standard DH:
/// `d` 0.34, 0, 0.40, 0, 0.40, 0, 0.126 m, `a` zero, `α` ∓90° alternating), both setups: a
/// camera on the flange looking at a board below, and a board on the flange seen by a camera
/// in the cell. 30 configurations drawn around a bent-elbow home (each joint ±35°, kept when the
/// board is 0.25–1 m in front of the camera, within 30° of its axis and turned less than 60°
/// from it). 24 drawn arms with 0.03° offsets on every joint, the flange reported through the
/// published chain with the UR cells' repeatability, the board seen from the true chain at the
/// rendered cell's board noise. The truth is the noise-free fit of the same configurations (the
/// parametrisation the data determine: the base and last joints' offsets are absorbed by the
/// two transforms, as on a UR). Asserted in each setup: those two held and the five others
/// estimated, within 3σ in ≥ 95 % of the draws (error / 1σ RMS 0.6–1.5), both transforms within
/// 0.5 mm / 0.05° in ≥ 95 %, the data choose the offsets in ≥ 95 %; an exact arm is given
/// offsets in at most 1 of 24 (no false alarm). Printed: the error the offsets cause without
/// the arm's model.
#[test]
fn a_seven_joint_arms_offsets_are_found_with_the_transforms() {
    use handeye_solve::kinematics::{fit_arm, ArmModel, DhChain};
    use std::f64::consts::{FRAC_PI_2, PI};
    let chain = DhChain {
        d: vec![0.34, 0.0, 0.40, 0.0, 0.40, 0.0, 0.126],
        a: vec![0.0; 7],
        alpha: vec![
            -FRAC_PI_2, FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, FRAC_PI_2, 0.0,
        ],
    };
    let zero = vec![0.0; 7];
    let home: Vec<f64> = [0.0, 30.0, 0.0, -60.0, 0.0, 90.0, 0.0]
        .iter()
        .map(|d: &f64| d.to_radians())
        .collect();
    let at_home = chain.forward(&home, &zero);
    for setup in [Setup::EyeInHand, Setup::EyeToHand] {
        // (camera mount, target mount) of the setup; the board faces the camera at home.
        let (camera_mount, target_mount) = match setup {
            Setup::EyeInHand => {
                let camera =
                    pose_from_rotvec(Vector3::new(0.05, 0.0, 0.04), Vector3::new(0.0, 0.0, 0.02));
                let board = at_home
                    * camera
                    * pose_from_rotvec(Vector3::new(0.0, 0.0, 0.5), Vector3::new(0.1, -0.05, 0.0));
                (camera, board)
            }
            Setup::EyeToHand => {
                let board =
                    pose_from_rotvec(Vector3::new(0.0, 0.03, 0.05), Vector3::new(0.05, 0.0, 0.0));
                let camera = at_home
                    * board
                    * pose_from_rotvec(Vector3::new(0.02, 0.0, 0.6), Vector3::new(PI, 0.0, 0.0));
                (camera, board)
            }
        };
        let seen_from = |flange: &Pose| match setup {
            Setup::EyeInHand => camera_mount.inverse() * flange.inverse() * target_mount,
            Setup::EyeToHand => camera_mount.inverse() * flange * target_mount,
        };
        let mut rng = StdRng::seed_from_u64(7);
        let spread = rand_distr::Uniform::new(-35f64.to_radians(), 35f64.to_radians()).unwrap();
        let mut configurations = Vec::new();
        while configurations.len() < 30 {
            let q: Vec<f64> = home.iter().map(|h| h + spread.sample(&mut rng)).collect();
            let board = seen_from(&chain.forward(&q, &zero));
            let t = board.translation.vector;
            let off_axis = t.xy().norm().atan2(t.z);
            let turned = (board.rotation * Vector3::z()).z.abs().acos();
            if (0.25..1.0).contains(&t.z)
                && off_axis < 30f64.to_radians()
                && turned < 60f64.to_radians()
            {
                configurations.push(q);
            }
        }
        let sample_set = |offsets: &[f64], [board, arm]: [BoardNoise; 2], seed: u64| {
            let mut rng = StdRng::seed_from_u64(seed);
            let mut noise = |mm: f64, deg: f64| drawn_noise(&mut rng, mm, deg);
            configurations
                .iter()
                .enumerate()
                .map(|(i, q)| {
                    let reported = chain.forward(q, &zero) * noise(arm.0, arm.1);
                    let seen = seen_from(&chain.forward(q, offsets)) * noise(board.0, board.1);
                    let mut pair = PosePair::new(reported, seen);
                    pair.id = Some(format!("pose-{i:03}"));
                    ArmSample {
                        pair,
                        joints: q.clone(),
                    }
                })
                .collect::<Vec<_>>()
        };
        // The pose-space solve without the arm's model, and the offsets' fit from it.
        let fit = |samples: &[ArmSample], options: &SolveOptions| {
            let pairs: Vec<PosePair> = samples.iter().map(|s| s.pair.clone()).collect();
            let plain = handeye_solve::solve(setup, &pairs, options).unwrap();
            let noise = plain.noise.map_or(options.noise, |n| n.model());
            let fit = fit_arm(
                ArmModel::JointOffsets,
                setup,
                &chain,
                samples,
                (&plain.camera_mount, &plain.target_mount),
                noise,
                options,
            )
            .unwrap();
            (plain, fit)
        };
        let repeatability = BoardNoise(0.02, 0.002);
        let none = BoardNoise(0.0, 0.0);
        let (mut within_3_sigma, mut within_bar, mut chosen, mut false_alarms) = (0, 0, 0, 0);
        let (mut squares, mut without_mm) = (Vec::new(), 0.0);
        for draw in 0..DRAWS {
            let normal = Normal::new(0.0, 0.03f64.to_radians()).unwrap();
            let mut offsets_rng = StdRng::seed_from_u64(7000 + draw);
            let offsets: Vec<f64> = (0..7).map(|_| normal.sample(&mut offsets_rng)).collect();
            let noisy = sample_set(&offsets, [RENDERED, repeatability], draw);
            let (plain, ours) = fit(&noisy, &SolveOptions::default());
            let (_, truth) = fit(
                &sample_set(&offsets, [none, none], draw),
                &SolveOptions {
                    estimate_noise: handeye_solve::EstimateNoise::NONE,
                    noise: ours.noise.model(),
                    ..SolveOptions::default()
                },
            );
            assert!(
                truth.translation_rms_mm[0] < 1e-4,
                "{setup:?} draw {draw}: the noise-free fit leaves {} mm",
                truth.translation_rms_mm[0]
            );
            for j in [0, 6] {
                assert!(
                    matches!(ours.offsets[j].status, OffsetStatus::Absorbed { .. }),
                    "{setup:?} draw {draw}: joint {} {:?}",
                    j + 1,
                    ours.offsets[j]
                );
            }
            let mut all = true;
            for (o, t) in ours.offsets[1..6].iter().zip(&truth.offsets[1..6]) {
                let OffsetStatus::Estimated { sigma_rad } = o.status else {
                    panic!("{setup:?} draw {draw}: {o:?} not estimated");
                };
                let e = (o.offset_rad - t.offset_rad) / sigma_rad;
                squares.push(e * e);
                all &= e.abs() <= 3.0;
            }
            within_3_sigma += usize::from(all);
            let error = |camera: &Pose, target: &Pose| {
                let (c, t) = (
                    pose_error_mm_deg(camera, &truth.camera_mount),
                    pose_error_mm_deg(target, &truth.target_mount),
                );
                (c.0.max(t.0), c.1.max(t.1))
            };
            let with = error(&ours.camera_mount, &ours.target_mount);
            within_bar += usize::from(with.0 <= 0.5 && with.1 <= 0.05);
            without_mm += error(&plain.camera_mount, &plain.target_mount).0 / DRAWS as f64;
            chosen += usize::from(ours.model_choice_margin() > 0.0);
            let (_, exact_arm) = fit(
                &sample_set(&zero, [RENDERED, repeatability], draw),
                &SolveOptions::default(),
            );
            false_alarms += usize::from(exact_arm.model_choice_margin() > 0.0);
        }
        let rms = (squares.iter().sum::<f64>() / squares.len() as f64).sqrt();
        eprintln!(
            "seven joints ({setup:?}, iiwa 7 chain, 30 configurations, 0.03° offsets): offsets within 3σ in {within_3_sigma} of {DRAWS} (error / 1σ RMS {rms:.2}), transforms within 0.5 mm / 0.05° in {within_bar}, chosen by the data in {chosen}; without the arm's model the transforms are {without_mm:.3} mm off on average; an exact arm given offsets in {false_alarms}"
        );
        let n = DRAWS as usize;
        assert!(20 * within_3_sigma >= 19 * n, "{setup:?}: {within_3_sigma}");
        assert!(20 * within_bar >= 19 * n, "{setup:?}: {within_bar}");
        assert!(20 * chosen >= 19 * n, "{setup:?}: {chosen}");
        assert!(20 * false_alarms <= n, "{setup:?}: {false_alarms}");
        assert!((0.6..1.5).contains(&rms), "{setup:?}: {rms}");
    }
}

/// An adaptive plan that estimates the arm's offsets (`plan.adaptive: true` beside
/// `solver.kinematics: joint_offsets`) chooses for the joint spread that tells them from the
/// transforms: the next-best-view planner scores each candidate with the offsets free
/// (`nbv::ArmOffsets`). The shipped arm-errors cell (eye-in-hand) and eye-to-hand cell with
/// their plans generated at 90 candidates, 10 poses chosen with and without the arm in the
/// predictions. Asserted in both: with the arm the worst offset 1σ and the transforms' 1σ
/// (offsets free) are both smaller (measured: 0.038° → 0.027° and 0.39 → 0.37 mm eye-in-hand,
/// 0.121° → 0.093° and 1.92 → 1.44 mm eye-to-hand).
#[test]
fn an_adaptive_plan_that_estimates_the_offsets_chooses_poses_that_determine_them() {
    let dir = tempfile::tempdir().unwrap();
    for (base, count) in [
        ("sim-cell-arm-errors.yaml", "count: 30"),
        ("sim-cell-eye-to-hand.yaml", "count: 20"),
    ] {
        let config = config_variant(dir.path(), base, base, &[(count, "count: 90")]);
        let prepared = handeye_session::cell::prepare(&config).unwrap();
        let candidates: Vec<_> = prepared
            .report
            .poses
            .iter()
            .filter(|p| p.problems.is_empty())
            .filter_map(|p| p.joints.map(|q| (p.base_from_flange, q)))
            .collect();
        assert!(
            candidates.len() >= 60,
            "{base}: {} candidates",
            candidates.len()
        );
        let figures = ten_poses_with_and_without_the_arm(&prepared, &candidates);
        let (blind, aware) = (figures[0], figures[1]);
        eprintln!("{base}: 10 adaptive poses, (worst offset 1σ °, transforms' 1σ mm) without the arm in the predictions {blind:?}, with it {aware:?}");
        assert!(
            aware.0 < blind.0 && aware.1 < blind.1,
            "{base}: {figures:?}"
        );
    }
}

/// What 10 poses chosen from `candidates` by the next-best-view planner fed the nominal cell's
/// exact samples determine, without and with the arm's offsets in its predictions: the worst
/// offset 1σ (°) and the transforms' 1σ (mm, offsets free) of the offsets' fit of those poses at
/// the configured noise.
fn ten_poses_with_and_without_the_arm(
    prepared: &handeye_session::cell::PreparedCell,
    candidates: &[(Pose, handeye_robot::Joints)],
) -> Vec<(f64, f64)> {
    use handeye_plan::nbv::{AdaptivePlanner, ArmOffsets};
    use handeye_session::{CellPlanner, PlanSource};
    use handeye_solve::kinematics::{estimable_offsets, fit_arm, ArmModel};
    let nominal = prepared.config.camera().nominal;
    let chain = handeye_records::solve::dh_chain(prepared.arm.as_ref().unwrap());
    let options = prepared.config.solver.to_options();
    let joints: Vec<Vec<f64>> = candidates.iter().map(|(_, q)| q.to_vec()).collect();
    let mounts = (&nominal.camera_mount, &nominal.target_mount);
    let free = estimable_offsets(nominal.setup, &chain, &joints, mounts, options.noise);
    assert_eq!(
        free,
        vec![1, 2, 3, 4],
        "a UR's base and wrist 3 offsets are absorbed"
    );
    let mut figures = Vec::new();
    for arm in [
        None,
        Some(ArmOffsets {
            chain: chain.clone(),
            free,
        }),
    ] {
        let mut planner = AdaptivePlanner::new(
            nominal.setup,
            nominal.camera_mount,
            nominal.target_mount,
            candidates.to_vec(),
            options.clone(),
            // Never met (exact samples solve to a 1σ near zero): ten poses each.
            0.0,
            10,
        );
        if let Some(arm) = arm {
            planner = planner.with_arm(arm);
        }
        // As a run drives it: the cell's planner over its one camera, the candidates all seen.
        let mut planner = CellPlanner::new(vec![planner], vec![vec![true; candidates.len()]], 10);
        let (mut samples, mut chosen) = (vec![Vec::new()], Vec::new());
        while let Some((pose, q)) = planner.next_pose(&samples) {
            let mut pair = PosePair::new(pose, nominal.camera_from_target(&pose));
            pair.id = Some(format!("pose-{:03}", samples[0].len()));
            chosen.push(ArmSample {
                pair: pair.clone(),
                joints: q.to_vec(),
            });
            samples[0].push(pair);
        }
        assert_eq!(chosen.len(), 10);
        let fixed = SolveOptions {
            estimate_noise: handeye_solve::EstimateNoise::NONE,
            ..options.clone()
        };
        let fit = fit_arm(
            ArmModel::JointOffsets,
            nominal.setup,
            &chain,
            &chosen,
            mounts,
            options.noise,
            &fixed,
        )
        .unwrap();
        // The fit scales its covariance by χ²/dof, which exact samples drive to its floor:
        // undone, the 1σ are the configured noise's (as `plan check` reports them).
        let u = fit.uncertainty.as_ref().unwrap();
        let prior = 1.0 / u.variance_factor.sqrt();
        let worst_offset_deg = fit
            .offsets
            .iter()
            .filter_map(|o| match o.status {
                OffsetStatus::Estimated { sigma_rad } => Some(sigma_rad.to_degrees() * prior),
                _ => None,
            })
            .fold(0.0f64, f64::max);
        let transforms_mm = u
            .camera_mount
            .translation_mm
            .max(u.target_mount.translation_mm)
            * prior;
        figures.push((worst_offset_deg, transforms_mm));
    }
    figures
}

/// The arm's model used from then on (issue #41, "use the answer"): a camera mounted anew on the
/// same arm is solved with the model an earlier session estimated (`solver.arm_model: its
/// result.yaml`), nothing of the arm estimated again. The shipped arm-errors cell is run once
/// with `kinematics: joint_offsets`; a second session of the same arm (its other plan seed)
/// with the first's result is within the bar and far nearer the truth than the same session
/// with the published model; a file without an arm model, or of another arm, is refused by
/// name; `kinematics` beside it is refused when the config is read.
#[test]
fn an_arm_model_estimated_earlier_corrects_a_later_session() {
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str, edits: &[(&str, &str)]| {
        let config = config_variant(
            dir.path(),
            "sim-cell-arm-errors.yaml",
            &format!("{name}.yaml"),
            edits,
        );
        let session = dir.path().join(name);
        let output = crate::util::run_cli(&config, &session);
        let cell = handeye_config::CellConfig::load(&config);
        (output, session, cell)
    };
    let (first, first_session, _) = run("first", &[]);
    assert!(
        first.status.success(),
        "{}",
        String::from_utf8_lossy(&first.stderr)
    );
    let earlier = first_session.join("result.yaml");
    let later_plan = ("max_roll_deg: 20, seed: 1", "max_roll_deg: 20, seed: 2");
    let error_of = |session: &Path, cell: &handeye_config::CellConfig| {
        let path = session.join("result.yaml");
        let result = handeye_records::result::ResultFile::load(&path).unwrap();
        let mounts = result.mounts(&path).unwrap();
        let said: Vec<String> = result.notices.iter().map(|n| n.message.clone()).collect();
        let error = transform_error(
            &mounts.camera_mount,
            &mounts.target_mount,
            &cell.camera().simulation.unwrap(),
        );
        (error, result.kinematics.is_some(), said)
    };
    let given = format!(", arm_model: {}}}", earlier.display());
    let (output, session, cell) = run(
        "given",
        &[later_plan, (", kinematics: joint_offsets}", &given)],
    );
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let cell = cell.unwrap();
    let ((mm, deg), estimated, said) = error_of(&session, &cell);
    let (given_session, given_output) = (session, output);
    assert!(!estimated, "nothing of the arm is estimated again");
    assert!(
        said.iter()
            .any(|m| m.contains("the robot poses are corrected by the arm's model in")),
        "{said:?}"
    );
    let (output, session, cell) = run(
        "published",
        &[
            later_plan,
            (", kinematics: joint_offsets}", ", kinematics: none}"),
        ],
    );
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let cell = cell.unwrap();
    let ((mm_published, _), _, _) = error_of(&session, &cell);
    eprintln!("a later session of the same arm: {mm:.3} mm / {deg:.4}° with the earlier model, {mm_published:.3} mm with the published one");
    assert!(mm <= 0.5 && deg <= 0.05, "{mm} mm, {deg}°");
    assert!(mm < 0.5 * mm_published, "{mm} mm against {mm_published} mm");
    // The plan's poses reached: moves are solved through the model used (the flange goes
    // where the plan says), so the true arm's flange at each pose's joints is on the planned
    // pose to the model's accuracy with the earlier model, and off by what the arm's errors
    // do with the published one. Both sessions plan the same views (one seed).
    let true_arm = cell.true_arm.expect("the arm-errors cell's true arm");
    let reached = |session: &Path| {
        let folder = handeye_records::folder::SessionFolder::open(session).unwrap();
        let plan = folder.read_manifest().unwrap().plan;
        let off: Vec<f64> = plan
            .iter()
            .map(|p| translation_distance(&true_arm.forward(&p.joints()), &p.base_from_flange))
            .collect();
        (
            off.iter().sum::<f64>() / off.len() as f64 * 1e3,
            off.iter().copied().fold(0.0, f64::max) * 1e3,
        )
    };
    let ((given_mean, given_max), (published_mean, published_max)) =
        (reached(&given_session), reached(&session));
    eprintln!("the plan's poses reached within {given_mean:.3} mm mean ({given_max:.3} max) through the earlier model, {published_mean:.3} mm ({published_max:.3}) through the published one");
    assert!(given_max < 0.2, "{given_max} mm");
    let plan_note = format!(
        "{}{}",
        String::from_utf8_lossy(&given_output.stdout),
        String::from_utf8_lossy(&given_output.stderr)
    );
    assert!(
        plan_note.contains(
            "the moves are solved through the ur10e model as an earlier session estimated it"
        ),
        "{plan_note}"
    );
    assert!(
        given_mean < 0.25 * published_mean,
        "{given_mean} mm against {published_mean} mm"
    );
    // A held-out run of the later answer predicts the arm where the model the cell gives puts
    // it, as that answer's own poses were (its result estimates no model of its own).
    let holdout = crate::util::succeeds(&mut crate::util::holdout_command(
        &dir.path().join("given.yaml"),
        &given_session.join("result.yaml"),
        &dir.path().join("holdout"),
    ));
    assert!(
        holdout.contains(&format!(
            "corrected by the arm's model in {}",
            earlier.display()
        )) && holdout.contains("verdict: GOOD"),
        "{holdout}"
    );
    // A result without an arm model is refused by name.
    let plain = dir.path().join("plain.yaml");
    let mut without: serde_yaml_ng::Value =
        serde_yaml_ng::from_str(&std::fs::read_to_string(&earlier).unwrap()).unwrap();
    without
        .as_mapping_mut()
        .unwrap()
        .remove("kinematics")
        .unwrap();
    let text = serde_yaml_ng::to_string(&without).unwrap();
    std::fs::write(&plain, text).unwrap();
    let given = format!(", arm_model: {}}}", plain.display());
    let (output, refused_session, _) = run(
        "no-model",
        &[later_plan, (", kinematics: joint_offsets}", &given)],
    );
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    // Refused when the cell is prepared, before the arm moves: no session was recorded.
    assert!(!refused_session.exists(), "{stderr}");
    assert!(
        stderr.contains("solver.arm_model") && stderr.contains("no `kinematics:` section"),
        "{stderr}"
    );
    // `kinematics` beside it: refused when the config is read.
    let given = format!(
        ", kinematics: joint_offsets, arm_model: {}}}",
        earlier.display()
    );
    let (_, _, cell) = run("both", &[(", kinematics: joint_offsets}", &given)]);
    let error = cell.unwrap_err().to_string();
    assert!(
        error.contains("solver.arm_model") && error.contains("leave out `kinematics`"),
        "{error}"
    );
}

/// Frames of the cell `truth` seen through the true `arm` at `joints`: the robot pose reported
/// through `model` with the arm's repeatability (0.02 mm, 0.002°), every board corner the camera
/// sees with 0.2 px of noise, and the board pose by PnP from them (the pose-space sample).
fn corner_frames(
    joints: &[Vec<f64>],
    (model, arm): (&UrModel, &UrModel),
    truth: &CellTransforms,
    seed: u64,
) -> (Vec<handeye_solve::Frame>, Vec<ArmSample>) {
    use handeye_solve::Frame;
    let board =
        handeye_vision::Board::load(&repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap();
    let camera = handeye_core::camera_model::CameraModel::load(
        &repo().join("configs/cameras/sim-1280x720.yaml"),
    )
    .unwrap();
    let mut rng = StdRng::seed_from_u64(seed);
    let pixel = Normal::new(0.0, 0.2).unwrap();
    let (t, r) = (
        Normal::new(0.0, 0.02e-3).unwrap(),
        Normal::new(0.0, 0.002f64.to_radians()).unwrap(),
    );
    let mut frames = Vec::new();
    let mut samples = Vec::new();
    for (i, q) in joints.iter().enumerate() {
        let q6 = handeye_robot::Joints::from_fn(6, |k| q[k]);
        let repeatability = pose_from_rotvec(
            Vector3::from_fn(|_, _| t.sample(&mut rng)),
            Vector3::from_fn(|_, _| r.sample(&mut rng)),
        );
        let reported = model.forward(&q6) * repeatability;
        let flange = arm.forward(&q6);
        let camera_from_target = match truth.setup {
            Setup::EyeInHand => {
                truth.camera_mount.inverse() * flange.inverse() * truth.target_mount
            }
            Setup::EyeToHand => truth.camera_mount.inverse() * flange * truth.target_mount,
        };
        let corners =
            crate::util::seen_corners(&board, &camera, &camera_from_target, &pixel, &mut rng);
        if corners.len() < 40 {
            continue;
        }
        let correspondences: Vec<_> = corners
            .iter()
            .map(|c| (c.point_in_target, c.pixel))
            .collect();
        let measured =
            handeye_vision::pnp::estimate_pose_from_points(&camera, &correspondences, 36)
                .unwrap()
                .camera_from_target;
        let id = format!("pose-{i:03}");
        let mut pair = PosePair::new(reported, measured);
        pair.id = Some(id.clone());
        samples.push(ArmSample {
            pair,
            joints: q.clone(),
        });
        frames.push(Frame {
            base_from_flange: reported,
            corners,
            id: Some(id),
        });
    }
    (frames, samples)
}

/// The arm's joint offsets estimated in reprojection space with the transforms (issue #41):
/// the pose-space fit's offsets and transforms refined over every board corner, each frame's
/// robot pose moving through the arm's chain with the offsets. Both shipped cells' plans (30
/// poses), 20 draws each of joint offsets (0.03°), 0.2 px corner noise (the board poses by PnP
/// from the same corners are noisier than the rendered cell's): the offsets the pose-space fit
/// estimates are within 3σ (the reprojection fit's) of the truth in ≥ 95 % of the draws, and
/// the transforms are nearer the truth than the pose-space fit's (mean error below 0.6×) and
/// within 0.5 mm / 0.05° in at least as many draws. Measured: eye in hand 20 of 20 within 3σ,
/// 20 within the bar (mean 0.079 mm against 0.160 in pose space; worst offset error 0.0095°
/// against 0.0174°); eye to hand 20 of 20 within 3σ, 18 within the bar against 6 (0.224 mm
/// against 0.580; 0.032° against 0.058°).
#[test]
fn the_joint_offsets_are_refined_in_reprojection_space_with_the_transforms() {
    use handeye_solve::{refine_reprojection, ArmOffsetsFree, ReprojectionOptions, RobotPrior};
    let sigmas = ArmErrorSigmas {
        joint_offset_rad: 0.03f64.to_radians(),
        ..ArmErrorSigmas::default()
    };
    for (config, (joints, model, physical)) in shipped_cells_at_30_poses() {
        let chain = handeye_records::solve::dh_chain(&model);
        let camera = handeye_core::camera_model::CameraModel::load(
            &repo().join("configs/cameras/sim-1280x720.yaml"),
        )
        .unwrap();
        let (mut draws, mut within_3_sigma, mut within_bar) = (0, 0, 0);
        let (mut pose_space_deg, mut reprojection_deg, mut worst_mm) = (0.0f64, 0.0f64, 0.0f64);
        let (mut mean_mm, mut pose_space_within_bar) = ([0.0f64; 2], 0);
        for draw in 0..20u64 {
            let errors = ArmErrors::draw(3000 + draw, &sigmas);
            let (arm, truth) = errors.fold(&model, &physical);
            let (frames, samples) = corner_frames(&joints, (&model, &arm), &truth, draw);
            let (_, _, fit) = solve_both(physical.setup, &model, &samples);
            let start = fit.corrections();
            let free: Vec<usize> = fit
                .offsets
                .iter()
                .filter(|o| matches!(o.status, OffsetStatus::Estimated { .. }))
                .map(|o| o.joint)
                .collect();
            let corrected: Vec<handeye_solve::Frame> = frames
                .iter()
                .zip(&samples)
                .map(|(frame, sample)| handeye_solve::Frame {
                    base_from_flange: chain.corrected_flange(
                        &frame.base_from_flange,
                        &sample.joints,
                        &start,
                    ),
                    ..frame.clone()
                })
                .collect();
            let refined = refine_reprojection(
                physical.setup,
                &corrected,
                &camera,
                &fit.camera_mount,
                &fit.target_mount,
                &ReprojectionOptions {
                    pixel_sigma_px: 0.2,
                    robot_prior: Some(RobotPrior {
                        translation_sigma_m: 0.02e-3,
                        rotation_sigma_rad: 0.002f64.to_radians(),
                    }),
                    arm: Some(ArmOffsetsFree {
                        chain: chain.clone(),
                        start: start.clone(),
                        free: free.clone(),
                        joints: samples
                            .iter()
                            .map(|s| (s.pair.id.clone().unwrap(), s.joints.clone()))
                            .collect(),
                    }),
                    ..ReprojectionOptions::default()
                },
            )
            .unwrap();
            assert_eq!(refined.arm_offsets.len(), free.len());
            draws += 1;
            let mut all_within = true;
            for o in &refined.arm_offsets {
                let true_offset = arm.joint_offsets[o.joint];
                let sigma = o.sigma_rad.expect("a 1σ");
                all_within &= (o.offset_rad - true_offset).abs() <= 3.0 * sigma;
                reprojection_deg =
                    reprojection_deg.max((o.offset_rad - true_offset).abs().to_degrees());
                let pose_space = fit.offsets[o.joint].offset_rad;
                pose_space_deg = pose_space_deg.max((pose_space - true_offset).abs().to_degrees());
            }
            within_3_sigma += usize::from(all_within);
            let (mm, deg) = transform_error(&refined.camera_mount, &refined.target_mount, &truth);
            worst_mm = worst_mm.max(mm);
            within_bar += usize::from(mm <= 0.5 && deg <= 0.05);
            let (pose_mm, pose_deg) = transform_error(&fit.camera_mount, &fit.target_mount, &truth);
            mean_mm[0] += mm / 20.0;
            mean_mm[1] += pose_mm / 20.0;
            pose_space_within_bar += usize::from(pose_mm <= 0.5 && pose_deg <= 0.05);
        }
        eprintln!(
            "{config}: offsets in reprojection space within 3σ in {within_3_sigma} of {draws}; transforms within the bar in {within_bar} (pose space {pose_space_within_bar}), mean {:.3} mm (pose space {:.3}), worst {worst_mm:.3} mm; worst offset error {reprojection_deg:.4}° (pose space {pose_space_deg:.4}°)",
            mean_mm[0], mean_mm[1]
        );
        assert!(20 * within_3_sigma >= 19 * draws, "{config}");
        assert!(mean_mm[0] < 0.6 * mean_mm[1], "{config}: {mean_mm:?}");
        assert!(within_bar >= pose_space_within_bar, "{config}");
        if physical.setup == Setup::EyeInHand {
            assert!(20 * within_bar >= 19 * draws, "{config}");
        }
    }
}
