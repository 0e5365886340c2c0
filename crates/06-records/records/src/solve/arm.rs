//! The arm's own model in a session's solve (`solver.kinematics: joint_offsets`, issue #41): the
//! joint zero offsets fitted with the two transforms (`handeye_solve::kinematics`) from each
//! sample's recorded joints (the manifest's plan pose the visit was taken at) and the arm's
//! published DH model, then every robot pose corrected by them, so the rest of the solve (the
//! pose-space answer, the reprojection refinement, the verdict) works on the flange poses the
//! corrected arm reports.
//!
//! Frames: `T_base_flange` in the controller's base; the offsets in radians inside, degrees in
//! the result file. Depends on `config`, `result`, the folder's records and `solve`.

use handeye_core::geometry::{translation_distance, Pose};
use handeye_core::notice::{Notice, NoticeKind};
use handeye_core::setup::{PosePair, Setup};
use handeye_robot::arm_errors::ArmErrors;
use handeye_robot::kinematics::{UrModel, JOINT_NAMES};
use handeye_robot::Joints;
use handeye_solve::kinematics::{
    fit_arm as fit_model, ArmFit, ArmModel, ArmRefit, ArmSample, DhChain, LinkParameter,
    OffsetStatus,
};
use handeye_solve::{self as solve, ArmOffsetsFree, SolveError};

use crate::result::{
    JointOffsetYaml, KinematicsYaml, LinkCorrectionYaml, MeanMax, UncertaintyYaml, WithWithout,
};
use crate::{PlannedPose, PoseVisit, SessionError};
use handeye_config::schema::arm_model_unavailable;
use handeye_config::{CellConfig, KinematicsChoice};

/// The DH chain of a UR model, as the solver takes it.
pub fn dh_chain(model: &UrModel) -> DhChain {
    DhChain {
        d: model.d.to_vec(),
        a: model.a.to_vec(),
        alpha: model.alpha.to_vec(),
    }
}

/// The arm's model as a session's solve estimated it.
#[derive(Debug, Clone)]
pub struct ArmEstimate {
    /// The arm model whose published chain is the nominal (`ur10e`).
    pub model: String,
    /// That chain.
    pub chain: DhChain,
    /// The joint fit (offsets, the transforms with them, residuals with and without).
    pub fit: ArmFit,
    /// The joints of the samples fitted (rad, one list per sample): the recorded workspace.
    pub recorded_joints: Vec<Vec<f64>>,
    /// Whether the estimated offsets were refined in reprojection space with the transforms
    /// (over every board corner; their 1σ then that fit's).
    pub refined_in_reprojection: bool,
}

/// The session's samples and visits with the robot poses the arm's model corrects, and the model.
pub struct Corrected {
    /// The pose pairs, each `T_base_flange` corrected.
    pub pairs: Vec<PosePair>,
    /// The visits, each `T_base_flange` corrected.
    pub visits: Vec<PoseVisit>,
    /// The estimate.
    pub arm: ArmEstimate,
    /// What the fit was made of, to make it again without one sample (the verdict's held-out
    /// folds: [`ArmRefit::flanges_without`]).
    pub folds: ArmRefit,
    /// Each visit's joints (rad) by its sample id: where the reprojection refinement moves a
    /// frame's pose from as the offsets change.
    pub joints_by_id: Vec<(String, Vec<f64>)>,
}

impl Corrected {
    /// The reprojection refinement's arm columns: the offsets this fit estimated, refined from
    /// its model (the one the poses are corrected by) over every frame with its joints.
    pub fn free_in_reprojection(&self) -> ArmOffsetsFree {
        let fit = &self.arm.fit;
        ArmOffsetsFree {
            chain: self.arm.chain.clone(),
            start: fit.corrections(),
            free: fit
                .offsets
                .iter()
                .filter(|o| matches!(o.status, OffsetStatus::Estimated { .. }))
                .map(|o| o.joint)
                .collect(),
            joints: self.joints_by_id.clone(),
        }
    }
}

/// The joints a visit was taken at: its plan pose's (rad), if the plan has it.
fn joints_of(plan: &[PlannedPose], visit: &PoseVisit) -> Option<Vec<f64>> {
    plan.get(visit.plan_index)
        .map(|p| p.joints_deg.iter().map(|v| v.to_radians()).collect())
}

/// The arm's model as `config` asks (`solver.kinematics`): with `joint_offsets`, fits it to
/// `pairs` (ids `pose-NNN` of `visits`, whose plan poses in `plan` hold the joints) and returns
/// the samples and visits corrected by it; with `auto` (the default), fits it where the arm's
/// model, the joints and the intrinsics are known and keeps it when the data choose it
/// ([`ArmFit::model_choice_margin`]), saying which in the notice, and then offers the DH link
/// corrections as [`ArmChoice::links`] when they pass [`ArmRefit::links_choice`] (the caller
/// keeps them unless its verdict with them contradicts a given file: link lengths absorb a
/// board printed at the wrong size); with `none`, nothing.
///
/// The start is the pose-space solve of the same samples with the config's options; the samples
/// it drops as outliers stay out of the arm's fit (and are corrected all the same).
pub fn estimate_arm(
    setup: Setup,
    config: &CellConfig,
    plan: &[PlannedPose],
    pairs: &[PosePair],
    visits: &[PoseVisit],
) -> Result<ArmChoice, SessionError> {
    let model = config.robot.model().and_then(UrModel::by_name);
    let chosen_by_data = match config.solver.kinematics() {
        KinematicsChoice::JointOffsets | KinematicsChoice::Dh => false,
        // The published model unless the data say otherwise; a cell whose arm or lens is not
        // known, or whose poses lack their joints, is not asked (the validation refuses
        // `joint_offsets` there).
        KinematicsChoice::Auto
            if model.is_some()
                && arm_model_unavailable(&config.robot, config.camera().intrinsics.as_deref())
                    .is_none()
                && pairs.iter().all(|p| {
                    visits
                        .iter()
                        .find(|v| Some(v.sample_id()) == p.id)
                        .is_some_and(|v| joints_of(plan, v).is_some())
                }) =>
        {
            true
        }
        _ => return Ok(ArmChoice::default()),
    };
    let estimated = match config.solver.kinematics() {
        KinematicsChoice::Dh => ArmModel::Dh,
        // `auto` starts from the offsets; the DH link corrections are then asked for below.
        _ => ArmModel::JointOffsets,
    };
    let corrected = fit_arm(setup, config, plan, pairs, visits, (model, estimated))?;
    if !chosen_by_data {
        return Ok(ArmChoice {
            corrected: Some(corrected),
            ..ArmChoice::default()
        });
    }
    let fit = &corrected.arm.fit;
    let (gain, k) = (fit.model_choice_margin(), fit.estimated());
    let figures = format!(
        "{k} joint zero offsets against the {}'s published model: χ² {:.1} with them, {:.1} without, {} than noise alone explains in 99 % of cells ({:.1})",
        corrected.arm.model,
        fit.chi2[0],
        fit.chi2[1],
        if gain > 0.0 { "more" } else { "no more" },
        fit.model_choice_threshold()
    );
    if gain <= 0.0 {
        let notice = Notice::info(
            NoticeKind::Other,
            format!("the arm's published model is kept: the data do not choose the arm's own model ({figures})"),
        );
        return Ok(ArmChoice {
            notice: Some(notice),
            ..ArmChoice::default()
        });
    }
    // The offsets are chosen: do the DH link corrections earn their place beside them? (A fit
    // that fails leaves the offsets, said.)
    let chose = format!("the data choose the arm's own model ({figures})");
    let offsets_only = format!("{chose}: the robot poses are corrected by the offsets (`solver.kinematics: none` keeps the published model)");
    let (links, said) = match corrected.folds.links_choice(&corrected.arm.fit) {
        Ok((folds, fit, choice)) => {
            let figures = format!(
                "{} DH link corrections beside the offsets: χ² {:.1} with them, {:.1} without under the noise with them, a drop of {:.1} in units of the residuals' own variance (χ²/dof {:.3}), {} than noise alone explains in 99 % of cells ({:.1}); the two answers {:.3} mm apart (the links pay beyond {:.3} mm: √2 × the 1σ they add to the transforms)",
                choice.added,
                choice.chi2[0],
                choice.chi2[1],
                choice.statistic(),
                choice.variance_factor,
                if choice.fit_margin() > 0.0 { "more" } else { "no more" },
                choice.threshold(),
                choice.difference_mm2.sqrt(),
                (2.0 * choice.added_variance_mm2).max(0.0).sqrt(),
            );
            if choice.chosen() {
                let model = corrected.arm.model.clone();
                let notice = Notice::info(
                    NoticeKind::Other,
                    format!("{chose} with its DH link corrections ({figures}): the robot poses are corrected by both (`solver.kinematics: joint_offsets` keeps the offsets alone, `none` the published model)"),
                );
                let links = (corrected_by(folds, fit, &model, plan, visits), notice);
                (Some(links), format!("its DH link corrections ({figures})"))
            } else {
                let why = if choice.fit_margin() > 0.0 {
                    ": the data need them, but the answer would be no nearer the truth with them"
                } else {
                    ""
                };
                (
                    None,
                    format!("its DH link corrections are left out{why} ({figures})"),
                )
            }
        }
        Err(e) => (
            None,
            format!("its DH link corrections could not be fitted ({e})"),
        ),
    };
    // With the links offered, the offsets' notice stands only if the caller refuses them (and
    // then says why after it).
    let notice = match links {
        Some(_) => offsets_only,
        None => format!("{offsets_only}; {said}"),
    };
    Ok(ArmChoice {
        corrected: Some(corrected),
        notice: Some(Notice::info(NoticeKind::Other, notice)),
        links,
    })
}

/// What [`estimate_arm`] found of the arm's model.
#[derive(Default)]
pub struct ArmChoice {
    /// The samples and visits corrected by the model kept (none: the published model).
    pub corrected: Option<Corrected>,
    /// The choice, with its figures, for the result's notices (`auto` only).
    pub notice: Option<Notice>,
    /// With `auto`: the DH link corrections beside the offsets, with the notice that replaces
    /// [`ArmChoice::notice`], when the data choose them too.
    pub links: Option<(Corrected, Notice)>,
}

/// The arm model of an earlier session's result `file` (`solver.arm_model`): `config`'s arm's
/// published model with the joint zero offsets and link
/// corrections of the file's `kinematics:` section, and that section. Read when the cell is
/// prepared (plans are checked and moves solved through it: the flange goes where the plan
/// says) and by the solve (every reported pose corrected through it). Errors: the file
/// unreadable, without a `kinematics:` section, of another arm model, or a correction of an
/// unknown joint or parameter.
pub fn given_arm_model(
    file: &std::path::Path,
    config: &CellConfig,
) -> Result<(UrModel, KinematicsYaml), SessionError> {
    let refused = |why: String| {
        SessionError::ArmModel(format!("solver.arm_model: {}: {why}", file.display()))
    };
    let result = crate::result::ResultFile::load(file).map_err(|e| refused(e.to_string()))?;
    let section = result.kinematics.ok_or_else(|| {
        refused("no `kinematics:` section: give the result of a session solved with `solver.kinematics: joint_offsets | dh`".into())
    })?;
    let name = config.robot.model().unwrap_or("none");
    if section.model != name {
        return Err(refused(format!(
            "the model of a `{}`, this cell's arm is a `{name}`",
            section.model
        )));
    }
    let mut arm = UrModel::by_name(name)
        .ok_or_else(|| refused(format!("no published kinematics for `{name}`")))?;
    for (j, o) in section.joint_offsets.iter().enumerate().take(6) {
        arm.joint_offsets[j] = o.offset_deg.to_radians();
    }
    for l in &section.links {
        let joint = JOINT_NAMES
            .iter()
            .position(|n| *n == l.joint)
            .ok_or_else(|| {
                refused(format!(
                    "a link correction of an unknown joint `{}`",
                    l.joint
                ))
            })?;
        let parameter = LinkParameter::ALL
            .into_iter()
            .find(|p| p.name() == l.parameter)
            .ok_or_else(|| refused(format!("an unknown link parameter `{}`", l.parameter)))?;
        let value = l.correction / unit_of(parameter).1;
        match parameter {
            LinkParameter::ThetaOffset => arm.joint_offsets[joint] = value,
            LinkParameter::D => arm.d[joint] += value,
            LinkParameter::A => arm.a[joint] += value,
            LinkParameter::Alpha => arm.alpha[joint] += value,
        }
    }
    Ok((arm, section))
}

/// The session's samples and visits with every robot pose corrected by the arm's model in
/// `file` (see [`given_arm_model`]): the pose the controller reported through its published
/// model moved to where the given model puts the flange at the same joints. Errors: those of
/// [`given_arm_model`], or a pose without its joints.
pub(super) fn apply_given_model(
    file: &std::path::Path,
    config: &CellConfig,
    plan: &[PlannedPose],
    pairs: &[PosePair],
    visits: &[PoseVisit],
) -> Result<(Vec<PosePair>, Vec<PoseVisit>, Notice), SessionError> {
    let refused = |why: String| {
        SessionError::ArmModel(format!("solver.arm_model: {}: {why}", file.display()))
    };
    let (arm, section) = given_arm_model(file, config)?;
    let published = arm.published();
    let correct = |reported: &Pose, joints: &Joints| {
        reported * published.forward(joints).inverse() * arm.forward(joints)
    };
    // A UR model's six joints, or none to correct through.
    let six = |v: &PoseVisit| {
        joints_of(plan, v)
            .and_then(|q| Joints::from_slice(&q).ok())
            .filter(|q| q.len() == 6)
    };
    let joints_for = |id: &Option<String>| {
        visits
            .iter()
            .find(|v| Some(v.sample_id()) == *id)
            .and_then(six)
    };
    let mut corrected_pairs = Vec::with_capacity(pairs.len());
    for pair in pairs {
        let joints = joints_for(&pair.id).ok_or_else(|| {
            refused(format!(
                "sample {} has no recorded joints (the six of a {}) to correct its pose through",
                pair.id.as_deref().unwrap_or("?"),
                section.model
            ))
        })?;
        corrected_pairs.push(PosePair {
            base_from_flange: correct(&pair.base_from_flange, &joints),
            ..pair.clone()
        });
    }
    let corrected_visits = visits
        .iter()
        .map(|v| {
            let mut v = v.clone();
            if let Some(joints) = six(&v) {
                v.base_from_flange = correct(&v.base_from_flange, &joints);
            }
            v
        })
        .collect();
    let moved = MeanMax::of(
        pairs
            .iter()
            .zip(&corrected_pairs)
            .map(|(a, b)| translation_distance(&a.base_from_flange, &b.base_from_flange) * 1e3),
    );
    let notice = Notice::info(
        NoticeKind::Other,
        format!(
            "the robot poses are corrected by the arm's model in {} ({} of the {}, estimated by an earlier session; nothing of the arm estimated again){}",
            file.display(),
            section.estimated,
            section.model,
            moved.map_or(String::new(), |m| format!(
                ": the flange moved by {:.3} mm mean ({:.3} max) over these {} poses",
                m.mean, m.max, pairs.len()
            ))
        ),
    );
    Ok((corrected_pairs, corrected_visits, notice))
}

/// The joint zero offsets of `model`'s published chain fitted to `pairs` with the two
/// transforms, and the samples and visits corrected by them.
fn fit_arm(
    setup: Setup,
    config: &CellConfig,
    plan: &[PlannedPose],
    pairs: &[PosePair],
    visits: &[PoseVisit],
    (model, estimated): (Option<UrModel>, ArmModel),
) -> Result<Corrected, SessionError> {
    let failed = |source: SolveError| SessionError::Solve {
        stage: "the arm's joint offsets",
        source: Box::new(source),
    };
    let model = model.ok_or_else(|| {
        failed(SolveError::RefinementFailed(
            "the arm's model has no published kinematics",
        ))
    })?;
    let chain = dh_chain(&model);
    let options = config.solver.to_options();
    // Each view at its precision in the arm's fit and its χ² as in the start's solve: a far view
    // taken as a typical one would read its noise as the arm's error.
    let pairs = options.weighted(pairs);
    let mut samples = Vec::with_capacity(pairs.len());
    for (index, pair) in pairs.iter().enumerate() {
        let joints = visits
            .iter()
            .find(|v| Some(v.sample_id()) == pair.id)
            .and_then(|v| joints_of(plan, v))
            .ok_or_else(|| {
                failed(SolveError::ArmJoints {
                    index,
                    id: pair.id.clone(),
                    found: 0,
                    expected: chain.joints(),
                })
            })?;
        samples.push(ArmSample {
            pair: pair.clone(),
            joints,
        });
    }
    let start = solve::solve(setup, &pairs, &options).map_err(failed)?;
    let folds = ArmRefit {
        setup,
        model: estimated,
        chain: chain.clone(),
        samples,
        // The start's outliers stay out of the arm's fit (and are corrected all the same).
        dropped: start.dropped.clone(),
        start: (start.camera_mount, start.target_mount),
        noise: start.noise.map_or(options.noise, |n| n.model()),
        options,
    };
    let fit = folds.fit_without(None).map_err(failed)?;
    Ok(corrected_by(folds, fit, &model.name, plan, visits))
}

/// The session's samples and visits corrected by `fit`, the fit of `folds` (the arm `model`'s
/// published chain).
fn corrected_by(
    folds: ArmRefit,
    fit: ArmFit,
    model: &str,
    plan: &[PlannedPose],
    visits: &[PoseVisit],
) -> Corrected {
    let pairs = folds
        .samples
        .iter()
        .zip(folds.corrected_flanges(&fit))
        .map(|(s, base_from_flange)| PosePair {
            base_from_flange,
            ..s.pair.clone()
        })
        .collect();
    let arm = ArmEstimate {
        model: model.to_string(),
        chain: folds.chain.clone(),
        fit,
        recorded_joints: folds.samples.iter().map(|s| s.joints.clone()).collect(),
        refined_in_reprojection: false,
    };
    let joints_by_id = visits
        .iter()
        .filter_map(|v| Some((v.sample_id(), joints_of(plan, v)?)))
        .collect();
    let visits = visits
        .iter()
        .map(|v| {
            let mut v = v.clone();
            if let Some(joints) = joints_of(plan, &v) {
                v.base_from_flange = arm.corrected(&v.base_from_flange, &joints);
            }
            v
        })
        .collect();
    Corrected {
        pairs,
        visits,
        arm,
        folds,
        joints_by_id,
    }
}

impl ArmEstimate {
    /// The flange at `joints` (rad) by the published chain and by the estimated model.
    fn flanges(&self, joints: &[f64]) -> (Pose, Pose) {
        let zero = vec![0.0; self.chain.joints()];
        (
            self.chain.forward(joints, &zero),
            self.chain
                .forward_corrected(joints, &self.fit.corrections()),
        )
    }

    /// How far the estimated model moves the flange from the published one's, over the
    /// recorded joints, mm.
    pub fn flange_correction_mm(&self) -> Option<MeanMax> {
        MeanMax::of(self.recorded_joints.iter().map(|q| {
            let (published, estimated) = self.flanges(q);
            translation_distance(&published, &estimated) * 1e3
        }))
    }

    /// The offsets as the reprojection refinement left them (`refined`: the value of each
    /// offset it refined); the rest of the model as fitted. Each keeps the larger of the two
    /// fits' 1σ: the reprojection fit's weighs the corners and the arm's repeatability, and
    /// link errors the offsets do not model leave a bias its scatter does not show (the shipped
    /// arm-errors cell's 0.02 mm / 0.001° links put the shoulder 3.2 of its σ off), while the
    /// pose-space fit's noise is estimated from the residuals those errors leave.
    pub fn refine_offsets(&mut self, refined: &[handeye_solve::RefinedOffset]) {
        for r in refined {
            let Some(o) = self.fit.offsets.iter_mut().find(|o| o.joint == r.joint) else {
                continue;
            };
            o.offset_rad = r.offset_rad;
            if let (OffsetStatus::Estimated { sigma_rad }, Some(sigma)) =
                (&mut o.status, r.sigma_rad)
            {
                *sigma_rad = sigma_rad.max(sigma);
            }
            self.refined_in_reprojection = true;
        }
    }

    /// A reported flange pose at `joints` (rad) corrected by the fitted model.
    pub fn corrected(&self, reported: &Pose, joints: &[f64]) -> Pose {
        self.chain
            .corrected_flange(reported, joints, &self.fit.corrections())
    }

    /// The result file's `kinematics:` section.
    pub fn result_section(&self) -> KinematicsYaml {
        let fit = &self.fit;
        let joint_offsets = fit
            .offsets
            .iter()
            .map(|o| {
                let mut row = JointOffsetYaml {
                    joint: joint_name(o.joint),
                    offset_deg: o.offset_rad.to_degrees(),
                    sigma_deg: None,
                    absorbed_by: None,
                    undetermined: false,
                };
                match o.status {
                    OffsetStatus::Estimated { sigma_rad } => {
                        row.sigma_deg = Some(sigma_rad.to_degrees());
                    }
                    OffsetStatus::Absorbed { by } => {
                        row.absorbed_by = Some(by.unwrap_or("both").to_string());
                    }
                    OffsetStatus::Undetermined => row.undetermined = true,
                }
                row
            })
            .collect();
        let uncertainty = fit
            .uncertainty
            .as_ref()
            .map(|u| UncertaintyYaml::of(fit.setup, u));
        KinematicsYaml {
            model: self.model.clone(),
            estimated: match fit.model {
                ArmModel::JointOffsets => KinematicsChoice::JointOffsets,
                ArmModel::Dh => KinematicsChoice::Dh,
            }
            .name()
            .to_string(),
            joint_offsets,
            links: fit.links.iter().map(link_row).collect(),
            translation_rms_mm: WithWithout {
                with: fit.translation_rms_mm[0],
                without: fit.translation_rms_mm[1],
            },
            rotation_rms_deg: WithWithout {
                with: fit.rotation_rms_deg[0],
                without: fit.rotation_rms_deg[1],
            },
            uncertainty,
            flange_correction_mm: self.flange_correction_mm(),
        }
    }

    /// Lines for people: each joint's offset with its 1σ or why it was held, and the residuals
    /// with and without the arm's model.
    pub fn describe(&self) -> Vec<String> {
        let fit = &self.fit;
        let mut lines = vec![format!(
            "arm model ({}, {} estimated with the transforms): pose-space residual RMS {:.3} mm / {:.4}° with it, {:.3} mm / {:.4}° with the published model",
            self.model,
            match fit.model {
                ArmModel::JointOffsets => "joint zero offsets",
                ArmModel::Dh => "joint zero offsets and DH link corrections",
            },
            fit.translation_rms_mm[0],
            fit.rotation_rms_deg[0],
            fit.translation_rms_mm[1],
            fit.rotation_rms_deg[1],
        )];
        if self.refined_in_reprojection {
            lines.push(
                "  the joint offsets refined in reprojection space with the transforms, over every board corner (each 1σ the larger of that fit's and the pose-space fit's)"
                    .to_string(),
            );
        }
        if let Some(moved) = self.flange_correction_mm() {
            lines.push(format!(
                "  the flange where the estimated model puts it: {:.3} mm mean ({:.3} max) from the published model's over the {} recorded poses",
                moved.mean,
                moved.max,
                self.recorded_joints.len()
            ));
        }
        for o in &fit.offsets {
            let what = match o.status {
                OffsetStatus::Estimated { sigma_rad } => format!(
                    "{:+.4}° ± {:.4}° (1σ)",
                    o.offset_rad.to_degrees(),
                    sigma_rad.to_degrees()
                ),
                OffsetStatus::Absorbed { by: Some(by) } => {
                    format!("absorbed by {by} (no data can tell them apart): held at 0")
                }
                OffsetStatus::Absorbed { by: None } => {
                    "absorbed by the two transforms together: held at 0".to_string()
                }
                OffsetStatus::Undetermined => {
                    "not determined by these poses (add poses that move this joint further): held at 0"
                        .to_string()
                }
            };
            lines.push(format!("  {} offset: {what}", joint_name(o.joint)));
        }
        let mut held = Vec::new();
        for l in &fit.links {
            let row = link_row(l);
            let name = format!("{} {}", row.joint, row.parameter);
            match (row.sigma, row.absorbed_by) {
                (Some(sigma), _) => lines.push(format!(
                    "  {name}: {:+.4} {unit} ± {sigma:.4} {unit} (1σ)",
                    row.correction,
                    unit = row.unit
                )),
                (None, Some(by)) => held.push(format!("{name} (absorbed by {by})")),
                (None, None) => held.push(format!("{name} (not determined by these poses)")),
            }
        }
        if !held.is_empty() {
            lines.push(format!("  held at 0: {}", held.join(", ")));
        }
        lines
    }

    /// The estimated offsets and link corrections (`dh`) against the simulator's true arm
    /// errors, each in its 1σ, one line each, for the simulated cell's truth check. A link
    /// correction stands for what the data can tell of it: a parameter held beside it (absorbed
    /// by the transforms, or not determined) may have moved part of its truth into it.
    pub fn compare_with_truth(&self, truth: &ArmErrors) -> String {
        let mut lines = vec!["arm model truth check (estimated joint offsets):".to_string()];
        // The flange over the recorded workspace against the true arm in the controller's
        // frames (its base and last offsets folded into the transforms: no model can hold them).
        if let Some(true_arm) = UrModel::by_name(&self.model).map(|m| truth.folded_arm(&m)) {
            let errors: Vec<(f64, f64)> = self
                .recorded_joints
                .iter()
                .filter_map(|q| {
                    let at = Joints::from_slice(q).ok()?;
                    let true_flange = true_arm.forward(&at);
                    let (published, estimated) = self.flanges(q);
                    Some((
                        translation_distance(&true_flange, &published) * 1e3,
                        translation_distance(&true_flange, &estimated) * 1e3,
                    ))
                })
                .collect();
            if let (Some(before), Some(after)) = (
                MeanMax::of(errors.iter().map(|e| e.0)),
                MeanMax::of(errors.iter().map(|e| e.1)),
            ) {
                lines.push(format!(
                    "  flange position over the {} recorded poses against the simulator's true arm: {:.3} mm mean ({:.3} max) with the published model, {:.3} mm ({:.3}) with the estimated one",
                    errors.len(),
                    before.mean,
                    before.max,
                    after.mean,
                    after.max
                ));
            }
        }
        for o in &self.fit.offsets {
            if let OffsetStatus::Estimated { sigma_rad } = o.status {
                let error = o.offset_rad - truth.joint_offsets_rad[o.joint];
                lines.push(format!(
                    "  {} offset: error {:+.4}° ({:.1}σ) against the simulator's {:+.4}°",
                    joint_name(o.joint),
                    error.to_degrees(),
                    error.abs() / sigma_rad,
                    truth.joint_offsets_rad[o.joint].to_degrees()
                ));
            }
        }
        let estimated: Vec<_> = self
            .fit
            .links
            .iter()
            .filter(|l| matches!(l.status, OffsetStatus::Estimated { .. }))
            .collect();
        if !estimated.is_empty() {
            lines.push("arm model truth check (estimated link corrections):".to_string());
        }
        for l in estimated {
            let OffsetStatus::Estimated { sigma_rad: sigma } = l.status else {
                continue;
            };
            let true_value = match l.parameter {
                LinkParameter::ThetaOffset => truth.joint_offsets_rad[l.joint],
                LinkParameter::D => truth.d_m[l.joint],
                LinkParameter::A => truth.a_m[l.joint],
                LinkParameter::Alpha => truth.alpha_rad[l.joint],
            };
            let (unit, scale) = unit_of(l.parameter);
            let error = l.value - true_value;
            lines.push(format!(
                "  {} {}: error {:+.4} {unit} ({:.1}σ) against the simulator's {:+.4} {unit}",
                joint_name(l.joint),
                l.parameter.name(),
                error * scale,
                error.abs() / sigma,
                true_value * scale,
            ));
        }
        lines.join("\n")
    }
}

/// The unit a link parameter is written in (`d`, `a` in mm; `alpha`, `theta_offset` in
/// degrees) and the factor from the solver's m or rad to it.
fn unit_of(parameter: LinkParameter) -> (&'static str, f64) {
    match parameter {
        LinkParameter::Alpha | LinkParameter::ThetaOffset => ("deg", 1f64.to_degrees()),
        LinkParameter::D | LinkParameter::A => ("mm", 1e3),
    }
}

/// A link correction's row of the result file.
fn link_row(l: &handeye_solve::kinematics::LinkCorrection) -> LinkCorrectionYaml {
    let (unit, scale) = unit_of(l.parameter);
    let mut row = LinkCorrectionYaml {
        joint: joint_name(l.joint),
        parameter: l.parameter.name().to_string(),
        unit: unit.to_string(),
        correction: l.value * scale,
        sigma: None,
        absorbed_by: None,
        undetermined: false,
    };
    match l.status {
        OffsetStatus::Estimated { sigma_rad } => row.sigma = Some(sigma_rad * scale),
        OffsetStatus::Absorbed { by } => row.absorbed_by = Some(by.unwrap_or("both").to_string()),
        OffsetStatus::Undetermined => row.undetermined = true,
    }
    row
}

/// A joint's name (`base` … `wrist 3`), or `joint N` past a UR's six.
fn joint_name(joint: usize) -> String {
    JOINT_NAMES
        .get(joint)
        .map_or_else(|| format!("joint {}", joint + 1), |n| (*n).to_string())
}

/// What `plan`'s joints determine of the arm's model before anything moves (issue #41: plans
/// that make it observable): the model `config` asks for (`solver.kinematics: joint_offsets |
/// dh`) fitted to noise-free samples of the nominal cell `nominal` at the plan's joints, at the
/// configured noise, so its 1σ are what the plan can give. A note for `plan check` (its lines
/// after the first indented): each joint offset's 1σ or why it is held (absorbed, or not
/// determined by these poses: a joint the plan does not move enough), the link corrections'
/// largest 1σ (dh), and the transforms' 1σ with the model and without it. `None` when the
/// config estimates no model or the fit fails.
pub fn plan_observability(
    config: &CellConfig,
    arm: &UrModel,
    nominal: &handeye_core::setup::CellTransforms,
    plan: &[(Pose, Joints)],
) -> Option<String> {
    let estimated = match config.solver.kinematics() {
        KinematicsChoice::JointOffsets => ArmModel::JointOffsets,
        KinematicsChoice::Dh => ArmModel::Dh,
        _ => return None,
    };
    let chain = dh_chain(arm);
    let samples: Vec<ArmSample> = plan
        .iter()
        .enumerate()
        .map(|(i, (_, joints))| {
            let flange = arm.forward(joints);
            let mut pair = PosePair::new(flange, nominal.camera_from_target(&flange));
            pair.id = Some(format!("pose-{i:03}"));
            ArmSample {
                pair,
                joints: joints.iter().copied().collect(),
            }
        })
        .collect();
    let options = solve::SolveOptions {
        estimate_noise: solve::EstimateNoise::NONE,
        ..config.solver.to_options()
    };
    let pairs: Vec<PosePair> = samples.iter().map(|s| s.pair.clone()).collect();
    let without = solve::solve(nominal.setup, &pairs, &options).ok()?;
    let fit = fit_model(
        estimated,
        nominal.setup,
        &chain,
        &samples,
        (&nominal.camera_mount, &nominal.target_mount),
        options.noise,
        &options,
    )
    .ok()?;
    // The fits scale their covariance by χ²/dof, which noise-free samples drive to its floor:
    // undone, the 1σ are the configured noise's.
    let prior = |u: &solve::Uncertainty| 1.0 / u.variance_factor.sqrt();
    let sigma_of = |u: Option<&solve::Uncertainty>| {
        u.map(|u| {
            (
                u.camera_mount
                    .translation_mm
                    .max(u.target_mount.translation_mm)
                    * prior(u),
                u.camera_mount.rotation_deg.max(u.target_mount.rotation_deg) * prior(u),
            )
        })
    };
    let fit_prior = fit.uncertainty.as_ref().map_or(1.0, prior);
    let mut estimated_offsets = Vec::new();
    let mut held = Vec::new();
    let mut undetermined = Vec::new();
    for o in &fit.offsets {
        let name = joint_name(o.joint);
        match o.status {
            OffsetStatus::Estimated { sigma_rad } => {
                estimated_offsets.push(format!("{name} {:.4}°", sigma_rad.to_degrees() * fit_prior))
            }
            OffsetStatus::Absorbed { by } => held.push(format!(
                "{name} (absorbed by {})",
                by.unwrap_or("both transforms")
            )),
            OffsetStatus::Undetermined => undetermined.push(name),
        }
    }
    let what = match estimated {
        ArmModel::JointOffsets => "joint_offsets",
        ArmModel::Dh => "dh",
    };
    let mut lines = vec![format!(
        "solver.kinematics: {what} from these {} poses at the configured noise: joint offsets' 1σ {}{}",
        plan.len(),
        if estimated_offsets.is_empty() {
            "none estimable".to_string()
        } else {
            estimated_offsets.join(", ")
        },
        if held.is_empty() {
            String::new()
        } else {
            format!("; held at 0: {}", held.join(", "))
        }
    )];
    if estimated == ArmModel::Dh {
        let rows: Vec<LinkCorrectionYaml> = fit.links.iter().map(link_row).collect();
        let largest = |unit: &str| {
            rows.iter()
                .filter(|r| r.unit == unit)
                .filter_map(|r| r.sigma)
                .fold(0.0f64, f64::max)
                * fit_prior
        };
        lines.push(format!(
            "  {} DH link corrections estimable, 1σ up to {:.3} mm and {:.4}°",
            rows.iter().filter(|r| r.sigma.is_some()).count(),
            largest("mm"),
            largest("deg")
        ));
    }
    if let (Some(with), Some(plain)) = (
        sigma_of(fit.uncertainty.as_ref()),
        sigma_of(without.uncertainty.as_ref()),
    ) {
        lines.push(format!(
            "  the transforms' 1σ {:.3} mm / {:.4}° with the arm's model, {:.3} mm / {:.4}° with the published one",
            with.0, with.1, plain.0, plain.1
        ));
    }
    if !undetermined.is_empty() {
        lines.push(format!(
            "  offsets not determined by these poses: {} (add poses that move these joints further)",
            undetermined.join(", ")
        ));
    }
    lines.push(poses_needed(
        config, estimated, &chain, &samples, nominal, &fit,
    ));
    Some(lines.join("\n"))
}

/// How many of a plan's poses (the first, in its order) the arm's model needs: the fewest
/// whose fit at the configured noise estimates every offset the whole plan does, with the
/// transforms' 1σ within the accuracy asked (`verdict.accuracy_*`). Information only grows
/// with poses, so the figures fall with each one added and the fewest are found by bisection.
fn poses_needed(
    config: &CellConfig,
    estimated: ArmModel,
    chain: &DhChain,
    samples: &[ArmSample],
    nominal: &handeye_core::setup::CellTransforms,
    whole: &ArmFit,
) -> String {
    let accuracy = config.verdict.accuracy();
    let options = solve::SolveOptions {
        estimate_noise: solve::EstimateNoise::NONE,
        ..config.solver.to_options()
    };
    let estimated_count = whole.estimated();
    let enough = |n: usize| -> bool {
        let Ok(fit) = fit_model(
            estimated,
            nominal.setup,
            chain,
            &samples[..n],
            (&nominal.camera_mount, &nominal.target_mount),
            options.noise,
            &options,
        ) else {
            return false;
        };
        let Some(u) = fit.uncertainty.as_ref() else {
            return false;
        };
        // Exact samples drive χ²/dof to its floor: undone, the 1σ are the configured noise's.
        let prior = 1.0 / u.variance_factor.sqrt();
        fit.estimated() >= estimated_count
            && u.camera_mount
                .translation_mm
                .max(u.target_mount.translation_mm)
                * prior
                <= accuracy.translation_mm
            && u.camera_mount.rotation_deg.max(u.target_mount.rotation_deg) * prior
                <= accuracy.rotation_deg
    };
    let all = samples.len();
    if !enough(all) {
        return format!(
            "  the transforms' 1σ with the arm's model are not within the {} mm / {}° asked even with all {all} poses: add poses, or estimate less (`solver.kinematics: joint_offsets`)",
            accuracy.translation_mm, accuracy.rotation_deg
        );
    }
    // The fewest that are enough: `low` is not (or too few to fit), `high` is.
    let (mut low, mut high) = (2, all);
    while high - low > 1 {
        let mid = (low + high) / 2;
        if enough(mid) {
            high = mid;
        } else {
            low = mid;
        }
    }
    format!(
        "  the first {high} of these {all} poses determine every offset above with the transforms within the {} mm / {}° asked",
        accuracy.translation_mm, accuracy.rotation_deg
    )
}
