//! The arm's own kinematic errors: how a real arm's geometry differs from the published DH model
//! its controller computes the flange pose with (joint zero offsets, link length and twist
//! errors), and the true arm those errors make (a [`UrModel`] with joint offsets and corrected
//! links, the one shape of a calibrated arm).
//!
//! A controller reports `FK_nominal(q)`; the flange is at `FK_true(q)`. The simulated cell uses
//! this to report through the nominal model while its camera sees the true flange, as a real
//! cell does (issue #41).
//!
//! Two of the six joint offsets cannot be told from the cell's transforms by any data: the base
//! joint's offset turns the whole arm about the base z axis (`FK_true = Rz(δ1)·F'(q)`), and the
//! last joint's offset turns the flange about its own axis (`FK_true = F'(q)·K`, `K` constant).
//! [`ArmErrors::fold`] moves them into the cell's transforms: the truth in the frames the
//! controller reports in, which is the truth a calibration can find and the one its user needs.
//!
//! Frames: `T_base_flange`; metres and radians. Depends on `kinematics` and the ground floor.

use nalgebra::{UnitQuaternion, Vector3};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

use super::kinematics::UrModel;
use handeye_core::geometry::{dh_link, Pose};
use handeye_core::setup::{CellTransforms, Setup};

/// Differences of a true arm from its nominal DH model, per joint (base first): the true link
/// `i` is `Rz(θ_i + δθ_i) · Tz(d_i + δd_i) · Tx(a_i + δa_i) · Rx(α_i + δα_i)`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ArmErrors {
    /// Joint zero offsets `δθ`, rad (the true angle is the reported one plus this).
    pub joint_offsets_rad: [f64; 6],
    /// Link offset errors `δd`, m.
    pub d_m: [f64; 6],
    /// Link length errors `δa`, m.
    pub a_m: [f64; 6],
    /// Link twist errors `δα`, rad.
    pub alpha_rad: [f64; 6],
}

/// Standard deviations of a random draw of [`ArmErrors`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ArmErrorSigmas {
    /// Of each joint zero offset, rad.
    pub joint_offset_rad: f64,
    /// Of each link offset `d` and length `a`, m.
    pub length_m: f64,
    /// Of each link twist `α`, rad.
    pub twist_rad: f64,
}

impl ArmErrors {
    /// Errors drawn from zero-mean normal distributions with `sigmas`, repeatably from `seed`.
    /// Every joint gets an offset, every link a `d`, an `a` and an `α` error. A negative or
    /// non-finite sigma counts as zero (the config refuses those before).
    pub fn draw(seed: u64, sigmas: &ArmErrorSigmas) -> ArmErrors {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut six = |sigma: f64| {
            let sigma = if sigma.is_finite() {
                sigma.max(0.0)
            } else {
                0.0
            };
            [0; 6].map(|_| {
                let z: f64 = StandardNormal.sample(&mut rng);
                sigma * z
            })
        };
        let joint_offsets_rad = six(sigmas.joint_offset_rad);
        let d_m = six(sigmas.length_m);
        let a_m = six(sigmas.length_m);
        let alpha_rad = six(sigmas.twist_rad);
        ArmErrors {
            joint_offsets_rad,
            d_m,
            a_m,
            alpha_rad,
        }
    }

    /// The true arm of `nominal` with these errors (its joint limits are the nominal's).
    pub fn true_arm(&self, nominal: &UrModel) -> UrModel {
        let mut model = nominal.clone();
        for i in 0..6 {
            model.d[i] += self.d_m[i];
            model.a[i] += self.a_m[i];
            model.alpha[i] += self.alpha_rad[i];
            model.joint_offsets[i] += self.joint_offsets_rad[i];
        }
        model
    }

    /// The true arm with the base and last joint offsets folded into the cell's transforms
    /// `truth` (see the module docs): returns that arm (those two offsets zero) and the
    /// transforms in the controller's frames. The pair sees exactly what the unfolded arm and
    /// `truth` see: `FK_true(q) = Rz(δ1) · F'(q) · K` with `K = M6⁻¹ · Rz(δ6) · M6`, `M6` the true
    /// last link at zero angle, so a base-side transform turns by `Rz(−δ1)` and a flange-side one
    /// is `K` times it.
    pub fn fold(&self, nominal: &UrModel, truth: &CellTransforms) -> (UrModel, CellTransforms) {
        let arm = self.true_arm(nominal);
        let base_turn = Pose::from_parts(
            nalgebra::Translation3::identity(),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -arm.joint_offsets[0]),
        );
        let last = dh_link(0.0, arm.d[5], arm.a[5], arm.alpha[5]);
        let turn = dh_link(arm.joint_offsets[5], 0.0, 0.0, 0.0);
        let flange_turn = last.inverse() * turn * last;
        let (camera_mount, target_mount) = match truth.setup {
            Setup::EyeInHand => (
                flange_turn * truth.camera_mount,
                base_turn * truth.target_mount,
            ),
            Setup::EyeToHand => (
                base_turn * truth.camera_mount,
                flange_turn * truth.target_mount,
            ),
        };
        (
            self.folded_arm(nominal),
            CellTransforms {
                setup: truth.setup,
                camera_mount,
                target_mount,
            },
        )
    }

    /// The true arm of [`ArmErrors::fold`]: the base and last joint offsets zero (folded into the
    /// transforms), so its flange is the one the controller's frames hold.
    pub fn folded_arm(&self, nominal: &UrModel) -> UrModel {
        let mut arm = self.true_arm(nominal);
        arm.joint_offsets[0] = nominal.joint_offsets[0];
        arm.joint_offsets[5] = nominal.joint_offsets[5];
        arm
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Joints;
    use handeye_core::geometry::translation_distance;
    use rand::Rng;

    fn errors() -> ArmErrors {
        ArmErrors::draw(
            5,
            &ArmErrorSigmas {
                joint_offset_rad: 0.05f64.to_radians(),
                length_m: 3e-4,
                twist_rad: 0.02f64.to_radians(),
            },
        )
    }

    #[test]
    fn draws_repeat_and_differ_from_the_nominal() {
        let a = errors();
        assert_eq!(a, errors());
        assert!(a.joint_offsets_rad.iter().all(|v| *v != 0.0));
        let nominal = UrModel::ur10e();
        let q = Joints::from([0.3, -1.2, 1.4, -0.8, 1.1, 0.4]);
        let moved = translation_distance(&a.true_arm(&nominal).forward(&q), &nominal.forward(&q));
        // A few tenths of a millimetre per link and hundredths of a degree per joint over a
        // 1.3 m arm: the flange is off by a fraction of a millimetre to a few millimetres.
        assert!(moved > 1e-4 && moved < 5e-3, "{moved}");
    }

    #[test]
    fn folding_the_unobservable_offsets_sees_the_same_board() {
        let nominal = UrModel::ur10e();
        let errors = errors();
        let pose = |t: [f64; 3], r: [f64; 3]| {
            handeye_core::geometry::pose_from_rotvec(Vector3::from(t), Vector3::from(r))
        };
        for setup in [Setup::EyeInHand, Setup::EyeToHand] {
            let truth = CellTransforms {
                setup,
                camera_mount: pose([0.03, -0.07, 0.04], [0.02, -0.01, 1.56]),
                target_mount: pose([0.5, -0.15, 0.0], [0.01, -0.02, 0.3]),
            };
            let (folded_arm, folded) = errors.fold(&nominal, &truth);
            assert_eq!(folded_arm.joint_offsets[0], 0.0);
            assert_eq!(folded_arm.joint_offsets[5], 0.0);
            let arm = errors.true_arm(&nominal);
            for q in [
                Joints::from([0.3, -1.2, 1.4, -0.8, 1.1, 0.4]),
                Joints::from([-1.0, -2.0, 0.7, 0.3, -0.6, 2.5]),
            ] {
                // T_camera_target as the camera sees it, from each description.
                let seen = |arm: &UrModel, t: &CellTransforms| match setup {
                    Setup::EyeInHand => {
                        t.camera_mount.inverse() * arm.forward(&q).inverse() * t.target_mount
                    }
                    Setup::EyeToHand => t.camera_mount.inverse() * arm.forward(&q) * t.target_mount,
                };
                let a = seen(&arm, &truth);
                let b = seen(&folded_arm, &folded);
                assert!(translation_distance(&a, &b) < 1e-12);
                assert!(a.rotation.angle_to(&b.rotation) < 1e-12);
            }
        }
    }

    /// A calibrated arm's inverse (its structure's closed form finished by Newton steps) puts
    /// its own flange on the target: for 20 drawn arms (offsets 0.05°, links 0.3 mm / 0.02°,
    /// both e-Series sizes) and random joints away from the singularities, every branch the
    /// published model finds at the same pose is found, each within 1e-9 m / 1e-9 rad of the
    /// target through the calibrated arm's forward kinematics, and the joints that made the pose
    /// are among them.
    #[test]
    fn a_calibrated_arms_inverse_reaches_its_own_flange() {
        let mut rng = StdRng::seed_from_u64(41);
        for (draw, nominal) in (0..20).zip([UrModel::ur5e(), UrModel::ur10e()].iter().cycle()) {
            let arm = ArmErrors::draw(
                draw,
                &ArmErrorSigmas {
                    joint_offset_rad: 0.05f64.to_radians(),
                    length_m: 3e-4,
                    twist_rad: 0.02f64.to_radians(),
                },
            )
            .true_arm(nominal);
            assert_eq!(arm.published(), *nominal);
            let q = loop {
                let q = Joints::from_fn(6, |_| rng.random_range(-2.5..2.5));
                if q[4].sin().abs() > 0.2 && q[2].sin().abs() > 0.2 {
                    break q;
                }
            };
            let target = arm.forward(&q);
            let solutions = arm.inverse(&target);
            assert_eq!(
                solutions.len(),
                nominal.inverse(&target).len(),
                "draw {draw}"
            );
            for s in &solutions {
                let reached = arm.forward(s);
                assert!(
                    translation_distance(&reached, &target) < 1e-9,
                    "draw {draw}"
                );
                assert!(
                    reached.rotation.angle_to(&target.rotation) < 1e-9,
                    "draw {draw}"
                );
            }
            let nearest = arm
                .inverse_nearest(&target, &q)
                .expect("the pose's own joints");
            let apart = (0..6)
                .map(|i| (nearest[i] - q[i]).abs())
                .fold(0.0, f64::max);
            assert!(apart < 1e-8, "draw {draw}: {apart}");
        }
    }
}
