//! Kinematics of Universal Robots arms: standard Denavit–Hartenberg parameters as
//! published by Universal Robots, forward kinematics to the flange (`tool0`, no TCP offset) and
//! the closed-form inverse kinematics with all (up to 8) solutions, plus joint limits.
//!
//! Frames: `T_base_flange` (`base_from_flange`) maps flange coordinates into the robot's base
//! frame, the same base frame the UR controller reports (x/y as on the controller, z up).
//! Units: metres and radians. Link `i` (1-based in DH tables, 0-based here) is
//! `T_{i-1}_{i} = Rz(θ_i) · Tz(d_i) · Tx(a_i) · Rx(α_i)`.
//!
//! The closed-form inverse assumes the UR structure (`a_1 = a_4 = a_5 = a_6 = 0`, `d_2 = d_3 = 0`,
//! `α = [π/2, 0, 0, π/2, −π/2, 0]`, three parallel middle joints); every published model here
//! (CB3 UR3/UR5/UR10, e-Series UR3e/UR5e/UR10e/UR16e, UR20, UR30) satisfies it. A calibrated
//! model (joint zero offsets, small link corrections: the simulator's true arm, or the model a
//! session estimated, `solver.arm_model`) breaks it by fractions of a millimetre: its inverse
//! starts from the closed form of its structure and is finished by Newton steps on its own
//! forward kinematics. This module depends only on `geometry` and the `Joints` type.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use crate::Joints;
use handeye_core::geometry::{dh_link, translation_distance, Pose};

/// Largest flange position error (m) of an inverse solution, checked by forward kinematics;
/// a candidate worse than this (numerical breakdown at a singularity) is dropped.
const SOLUTION_POSITION_TOLERANCE: f64 = 1e-7;
/// Largest flange rotation error (rad) of an inverse solution, as above.
const SOLUTION_ROTATION_TOLERANCE: f64 = 1e-7;
/// How far (in the cosine / sine argument) a target may lie outside the reachable set and still be
/// clamped onto its boundary, to absorb round-off for poses exactly on the boundary.
const BOUNDARY_SLACK: f64 = 1e-10;
/// Newton steps a calibrated model's inverse takes at most from its structure's closed form
/// (corrections of a fraction of a millimetre converge in two or three).
const NEWTON_STEPS: usize = 10;
/// The flange error (m and rad together) a Newton solution stops at: far inside the solution
/// tolerances above.
const NEWTON_DONE: f64 = 1e-12;
/// The joint step of the Newton Jacobian's central differences, rad.
const NEWTON_STEP_RAD: f64 = 1e-6;
/// Below this `|sin θ5|` the wrist is singular (joints 4 and 6 aligned): θ6 is then free and is
/// taken from the caller's preference.
const WRIST_SINGULAR_SIN: f64 = 1e-10;

/// A Universal Robots arm described by standard DH parameters and joint limits.
#[derive(Debug, Clone, PartialEq)]
pub struct UrModel {
    /// Model name, lower case (`ur5e`).
    pub name: String,
    /// DH link offsets `d_i`, m.
    pub d: [f64; 6],
    /// DH link lengths `a_i`, m (negative for UR's upper and lower arm, as UR publishes them).
    pub a: [f64; 6],
    /// DH link twists `α_i`, rad.
    pub alpha: [f64; 6],
    /// Joint zero offsets `δθ_i`, rad: link `i` turns by the reported joint angle plus this.
    /// Zero in a published model; an arm's calibration sets them (with corrections to `d`, `a`
    /// and `α`): the simulator's true arm (`arm_errors`), or the model an earlier session
    /// estimated (`solver.arm_model`).
    pub joint_offsets: [f64; 6],
    /// Joint limits `(min, max)` per joint, rad. Every model here is planned with ±2π on every
    /// joint but the elbow (±π); a cell narrows them with `robot.joint_ranges_deg`.
    pub joint_limits: [(f64, f64); 6],
}

/// The first joint of `joints` outside its range in `limits` (`[(min, max)]`, rad): its 0-based
/// index and value; a non-finite value counts as outside. For any arm, with or without a model
/// (the caller has checked that `limits` has a range for each joint).
pub fn outside_ranges(limits: &[(f64, f64)], joints: &Joints) -> Option<(usize, f64)> {
    joints
        .iter()
        .zip(limits.iter())
        .position(|(q, (lo, hi))| !(q.is_finite() && *q >= *lo && *q <= *hi))
        .map(|i| (i, joints[i]))
}

/// The joint names, base to wrist 3, as messages and the README use them.
pub const JOINT_NAMES: [&str; 6] = ["base", "shoulder", "elbow", "wrist 1", "wrist 2", "wrist 3"];

/// UR's twist angles, the same for every arm of the family.
const UR_ALPHA: [f64; 6] = [FRAC_PI_2, 0.0, 0.0, FRAC_PI_2, -FRAC_PI_2, 0.0];
/// Default joint limits: ±2π on every joint but the elbow (±π), as the controller ships.
// Universal Robots' published ranges are ±360° on every joint (the UR3/UR3e wrist 3 turns
// without end); ur_description keeps the elbow within ±180°, as its own links collide beyond.
const UR_LIMITS: [(f64, f64); 6] = [
    (-TAU, TAU),
    (-TAU, TAU),
    (-PI, PI),
    (-TAU, TAU),
    (-TAU, TAU),
    (-TAU, TAU),
];

/// The published DH parameters of one arm: `[d1, a2, a3, d4, d5, d6]`, m (every other `a`/`d`
/// is zero on a UR).
struct Published {
    name: &'static str,
    d1: f64,
    a2: f64,
    a3: f64,
    d4: f64,
    d5: f64,
    d6: f64,
}

/// Every arm the tool knows, as Universal Robots publishes it: "DH Parameters for calculations of
/// kinematics and dynamics"
/// (<https://www.universal-robots.com/articles/ur/application-installation/dh-parameters-for-calculations-of-kinematics-and-dynamics/>).
/// Checked against that page for the e-Series and the UR20, against the CB3 manual's appendix
/// ("Robot DH Parameter", the CB3 values matching its latest UR5 series 3 table) and against
/// Universal Robots' `ur_description` kinematics for the UR16e and UR30. The UR30 also matches
/// its datasheet reach (1300 mm ≈ a2 + a3 + d5).
#[rustfmt::skip] // one arm a line, as the published table reads
const PUBLISHED: [Published; 9] = [
    // CB3 series.
    Published { name: "ur3", d1: 0.1519, a2: -0.24365, a3: -0.21325, d4: 0.11235, d5: 0.08535, d6: 0.0819 },
    Published { name: "ur5", d1: 0.089159, a2: -0.425, a3: -0.39225, d4: 0.10915, d5: 0.09465, d6: 0.0823 },
    Published { name: "ur10", d1: 0.1273, a2: -0.612, a3: -0.5723, d4: 0.163941, d5: 0.1157, d6: 0.0922 },
    // e-Series.
    Published { name: "ur3e", d1: 0.15185, a2: -0.24355, a3: -0.2132, d4: 0.13105, d5: 0.08535, d6: 0.0921 },
    Published { name: "ur5e", d1: 0.1625, a2: -0.425, a3: -0.3922, d4: 0.1333, d5: 0.0997, d6: 0.0996 },
    Published { name: "ur10e", d1: 0.1807, a2: -0.6127, a3: -0.57155, d4: 0.17415, d5: 0.11985, d6: 0.11655 },
    Published { name: "ur16e", d1: 0.1807, a2: -0.4784, a3: -0.36, d4: 0.17415, d5: 0.11985, d6: 0.11655 },
    // UR20 / UR30.
    Published { name: "ur20", d1: 0.2363, a2: -0.862, a3: -0.7287, d4: 0.201, d5: 0.1593, d6: 0.1543 },
    Published { name: "ur30", d1: 0.2363, a2: -0.637, a3: -0.5037, d4: 0.201, d5: 0.1593, d6: 0.1543 },
];

impl UrModel {
    /// The names [`UrModel::by_name`] accepts, lower case, CB3 first, then e-Series, UR20, UR30.
    pub const NAMES: [&'static str; 9] = [
        "ur3", "ur5", "ur10", "ur3e", "ur5e", "ur10e", "ur16e", "ur20", "ur30",
    ];

    fn from_published(p: &Published) -> Self {
        UrModel {
            name: p.name.to_string(),
            d: [p.d1, 0.0, 0.0, p.d4, p.d5, p.d6],
            a: [0.0, p.a2, p.a3, 0.0, 0.0, 0.0],
            alpha: UR_ALPHA,
            joint_offsets: [0.0; 6],
            joint_limits: UR_LIMITS,
        }
    }

    /// The published model of this arm (its name's), with this model's joint limits: what its
    /// controller computes the flange pose it reports with. A published model's is itself.
    pub fn published(&self) -> Self {
        let mut published = UrModel::by_name(&self.name).unwrap_or_else(|| self.structure());
        published.joint_limits = self.joint_limits;
        published
    }

    /// Whether this model has the UR structure exactly (no joint offsets, no corrections off
    /// it): its closed-form inverse is exact.
    fn is_structural(&self) -> bool {
        *self == self.structure()
    }

    /// This model with every parameter off the UR structure dropped: joint offsets zero,
    /// `a_1 = a_4 = a_5 = a_6 = 0`, `d_2 = d_3 = 0`, UR's twists. Its closed form is the start
    /// of a calibrated model's inverse.
    fn structure(&self) -> Self {
        let mut s = self.clone();
        s.joint_offsets = [0.0; 6];
        s.a = [0.0, self.a[1], self.a[2], 0.0, 0.0, 0.0];
        s.d = [self.d[0], 0.0, 0.0, self.d[3], self.d[4], self.d[5]];
        s.alpha = UR_ALPHA;
        s
    }

    /// The UR5e (Universal Robots' published DH parameters).
    pub fn ur5e() -> Self {
        Self::from_published(&PUBLISHED[4])
    }

    /// The UR10e (Universal Robots' published DH parameters).
    pub fn ur10e() -> Self {
        Self::from_published(&PUBLISHED[5])
    }

    /// The model called `name` (one of [`UrModel::NAMES`]; case-insensitive), if known.
    pub fn by_name(name: &str) -> Option<Self> {
        let wanted = name.trim().to_ascii_lowercase();
        PUBLISHED
            .iter()
            .find(|p| p.name == wanted)
            .map(Self::from_published)
    }

    /// The transform of DH link `i` (0-based) at joint angle `theta` (the link's own angle, its
    /// offset added already): `T_{i}_{i+1}` in 0-based frame numbers, i.e.
    /// `Rz(θ) · Tz(d) · Tx(a) · Rx(α)`.
    fn link(&self, i: usize, theta: f64) -> Pose {
        dh_link(theta, self.d[i], self.a[i], self.alpha[i])
    }

    /// Forward kinematics: the flange pose `T_base_flange` at `joints` (rad), six of them (a
    /// plan's joint count is checked against the arm's before any kinematics). Limits are not
    /// checked here; see [`UrModel::within_limits`].
    pub fn forward(&self, joints: &Joints) -> Pose {
        debug_assert_eq!(joints.len(), 6, "a UR arm has six joints");
        (0..6).fold(Pose::identity(), |acc, i| {
            acc * self.link(i, joints[i] + self.joint_offsets[i])
        })
    }

    /// Whether every joint lies inside its limits (bounds included) and is finite.
    pub fn within_limits(&self, joints: &Joints) -> bool {
        joints
            .iter()
            .zip(self.joint_limits.iter())
            .all(|(q, (lo, hi))| q.is_finite() && *q >= *lo && *q <= *hi)
    }

    /// The first joint of `joints` outside its limit (0-based index and its value, rad), if any;
    /// a non-finite value counts as outside.
    pub fn outside_limits(&self, joints: &Joints) -> Option<(usize, f64)> {
        outside_ranges(&self.joint_limits, joints)
    }

    /// This model with the arm's own joint limits (whatever a cell narrowed them to).
    pub fn with_arm_limits(&self) -> Self {
        UrModel {
            joint_limits: UR_LIMITS,
            ..self.clone()
        }
    }

    /// All inverse-kinematics solutions for `base_from_flange` that lie inside the joint limits.
    ///
    /// The closed form has up to 8 branches (shoulder left/right × wrist up/down × elbow
    /// up/down). Each branch is returned once, each joint as the representative nearest to 0
    /// that is inside its limits (with ±2π limits a joint also has a twin 2π away; use
    /// [`UrModel::inverse_nearest`] to pick the twin nearest to a current configuration).
    /// At a wrist singularity (`θ5 = 0` or `π`) joint 6 is set to 0. Every solution is verified by
    /// forward kinematics to 1e-7 m / 1e-7 rad. Empty when the pose is out of reach or
    /// non-finite.
    pub fn inverse(&self, base_from_flange: &Pose) -> Vec<Joints> {
        self.branches(base_from_flange, 0.0)
            .into_iter()
            .filter_map(|q| self.wrap_into_limits(&q, &Joints::zeros(6)))
            .collect()
    }

    /// The inverse-kinematics solution inside the joint limits nearest to `seed` (largest joint
    /// difference minimised, then the sum of squares), each joint taking the 2π twin nearest to
    /// the seed. At a wrist singularity joint 6 keeps the seed's value (as far as possible).
    /// `None` when no solution is inside the limits.
    pub fn inverse_nearest(&self, base_from_flange: &Pose, seed: &Joints) -> Option<Joints> {
        let cost = |q: &Joints| {
            let max = q
                .iter()
                .zip(seed)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            let sq: f64 = q.iter().zip(seed).map(|(a, b)| (a - b).powi(2)).sum();
            (max, sq)
        };
        self.branches(base_from_flange, seed[5])
            .into_iter()
            .filter_map(|q| self.wrap_into_limits(&q, seed))
            .min_by(|a, b| {
                let (ma, sa) = cost(a);
                let (mb, sb) = cost(b);
                ma.total_cmp(&mb).then(sa.total_cmp(&sb))
            })
    }

    /// Moves each joint by multiples of 2π to the value nearest `preferred` that lies inside the
    /// limits; `None` if some joint has no such value.
    fn wrap_into_limits(&self, q: &Joints, preferred: &Joints) -> Option<Joints> {
        let mut out = Joints::zeros(6);
        for i in 0..6 {
            let (lo, hi) = self.joint_limits[i];
            // The twin nearest to the preference, then step inward if that one is outside.
            let k = ((preferred[i] - q[i]) / TAU).round();
            let mut best: Option<f64> = None;
            for dk in [0.0, -1.0, 1.0, -2.0, 2.0] {
                let v = q[i] + (k + dk) * TAU;
                if v >= lo && v <= hi {
                    let better = match best {
                        None => true,
                        Some(b) => (v - preferred[i]).abs() < (b - preferred[i]).abs(),
                    };
                    if better {
                        best = Some(v);
                    }
                }
            }
            out[i] = best?;
        }
        Some(out)
    }

    /// The inverse's branches, each joint in (−π, π], verified by forward kinematics and
    /// de-duplicated: the closed form's, or for a calibrated model the closed form of its
    /// structure finished by Newton steps on its own kinematics. `theta6_if_singular` is used for
    /// joint 6 when the wrist is singular.
    fn branches(&self, base_from_flange: &Pose, theta6_if_singular: f64) -> Vec<Joints> {
        if self.is_structural() {
            return self.closed_form(base_from_flange, theta6_if_singular);
        }
        let mut out: Vec<Joints> = Vec::new();
        for start in self
            .structure()
            .closed_form(base_from_flange, theta6_if_singular)
        {
            let Some(q) = self.newton(base_from_flange, start) else {
                continue;
            };
            let q = Joints::from_fn(6, |i| wrap_pi(q[i]));
            if self.reaches(&q, base_from_flange)
                && !out.iter().any(|o| max_angle_diff(o, &q) < 1e-9)
            {
                out.push(q);
            }
        }
        out
    }

    /// Newton steps on this model's forward kinematics from `start` (a joint solution of its
    /// structure, a fraction of a millimetre from `target`) until the flange is on `target`;
    /// `None` when they do not converge (the start next to a singularity).
    fn newton(&self, target: &Pose, start: Joints) -> Option<Joints> {
        // The flange error as a twist in the base frame: translation, then rotation vector.
        let error = |q: &Joints| {
            let fk = self.forward(q);
            let dp = target.translation.vector - fk.translation.vector;
            let dr = (target.rotation * fk.rotation.inverse()).scaled_axis();
            nalgebra::Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
        };
        // The structure's joints are the links' own angles; this model's are those less the
        // offsets.
        let mut q = Joints::from_fn(6, |i| start[i] - self.joint_offsets[i]);
        for _ in 0..NEWTON_STEPS {
            let e = error(&q);
            if e.norm() < NEWTON_DONE {
                return Some(q);
            }
            // The Jacobian of the flange error by central differences (6 forward kinematics).
            let mut jacobian = nalgebra::Matrix6::zeros();
            for j in 0..6 {
                let mut plus = q;
                let mut minus = q;
                plus[j] += NEWTON_STEP_RAD;
                minus[j] -= NEWTON_STEP_RAD;
                let column = (error(&minus) - error(&plus)) / (2.0 * NEWTON_STEP_RAD);
                jacobian.set_column(j, &column);
            }
            let step = jacobian.lu().solve(&e)?;
            for (i, s) in step.iter().enumerate() {
                q[i] += s;
            }
        }
        (error(&q).norm() < NEWTON_DONE).then_some(q)
    }

    /// The closed-form branches of the UR structure (see the module docs), verified by forward
    /// kinematics and de-duplicated.
    fn closed_form(&self, base_from_flange: &Pose, theta6_if_singular: f64) -> Vec<Joints> {
        let target = base_from_flange;
        if !target.translation.vector.iter().all(|v| v.is_finite())
            || !target.rotation.coords.iter().all(|v| v.is_finite())
        {
            return Vec::new();
        }
        let [_, _, _, d4, _, d6] = self.d;
        let (a2, a3) = (self.a[1], self.a[2]);
        let rot = target.rotation.to_rotation_matrix();
        let x6 = rot.matrix().column(0).into_owned();
        let y6 = rot.matrix().column(1).into_owned();
        let z6 = rot.matrix().column(2).into_owned();
        let p06 = target.translation.vector;

        let mut out: Vec<Joints> = Vec::new();

        // θ1: the wrist centre (frame 5 origin) lies at height d4 along joint 1's z axis
        // (s1, −c1, 0): p05x·s1 − p05y·c1 = d4.
        let p05 = p06 - d6 * z6;
        let r = p05.x.hypot(p05.y);
        if r < 1e-12 {
            return out; // wrist centre on the base axis: shoulder singular, no unique θ1
        }
        let Some(asin_arg) = clamp_unit(d4 / r) else {
            return out;
        };
        let phi = p05.y.atan2(p05.x);
        let psi = asin_arg.asin();
        for theta1 in [phi + psi, phi + PI - psi] {
            let (s1, c1) = theta1.sin_cos();
            let z1 = Vector3::new(s1, -c1, 0.0);
            // θ5: the flange origin's height along z1 is d4 + d6·cos θ5.
            let Some(c5) = clamp_unit((p06.dot(&z1) - d4) / d6) else {
                continue;
            };
            let acos5 = c5.acos();
            for theta5 in [acos5, -acos5] {
                let s5 = theta5.sin();
                // θ6: z1 seen from the flange is (cos θ6 · sin θ5, −sin θ6 · sin θ5, cos θ5).
                let theta6 = if s5.abs() < WRIST_SINGULAR_SIN {
                    theta6_if_singular
                } else {
                    (-y6.dot(&z1) / s5).atan2(x6.dot(&z1) / s5)
                };
                // Peel joints 1, 5, 6 off; what remains is the planar 3R chain of joints 2–4.
                let base_from_1 = self.link(0, theta1);
                let four_from_flange = self.link(4, theta5) * self.link(5, theta6);
                let one_from_4 = base_from_1.inverse() * target * four_from_flange.inverse();
                // T_1_4 = Rz(θ2)Tx(a2) · Rz(θ3)Tx(a3) · Rz(θ4) · [Tz(d4)Rx(α4)]; strip the bracket.
                let tail = Isometry3::from_parts(
                    Translation3::new(0.0, 0.0, d4),
                    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), self.alpha[3]),
                );
                let planar = one_from_4 * tail.inverse();
                let (px, py) = (planar.translation.x, planar.translation.y);
                let m = planar.rotation.to_rotation_matrix();
                let phi234 = m[(1, 0)].atan2(m[(0, 0)]);
                let Some(c3) =
                    clamp_unit((px * px + py * py - a2 * a2 - a3 * a3) / (2.0 * a2 * a3))
                else {
                    continue;
                };
                let acos3 = c3.acos();
                for theta3 in [acos3, -acos3] {
                    let s3 = theta3.sin();
                    let theta2 = py.atan2(px) - (a3 * s3).atan2(a2 + a3 * c3);
                    let theta4 = phi234 - theta2 - theta3;
                    let q =
                        Joints::from([theta1, theta2, theta3, theta4, theta5, theta6].map(wrap_pi));
                    if self.reaches(&q, target) && !out.iter().any(|o| max_angle_diff(o, &q) < 1e-9)
                    {
                        out.push(q);
                    }
                }
            }
        }
        out
    }

    /// Whether `q` puts the flange on `target` within the solution tolerances.
    fn reaches(&self, q: &Joints, target: &Pose) -> bool {
        let fk = self.forward(q);
        translation_distance(&fk, target) < SOLUTION_POSITION_TOLERANCE
            && fk.rotation.angle_to(&target.rotation) < SOLUTION_ROTATION_TOLERANCE
    }
}

/// `v` if it is in [−1, 1], clamped onto it if within round-off, else `None` (out of reach).
fn clamp_unit(v: f64) -> Option<f64> {
    if !v.is_finite() || v.abs() > 1.0 + BOUNDARY_SLACK {
        None
    } else {
        Some(v.clamp(-1.0, 1.0))
    }
}

/// The angle wrapped into (−π, π].
fn wrap_pi(angle: f64) -> f64 {
    let w = angle.rem_euclid(TAU);
    if w > PI {
        w - TAU
    } else {
        w
    }
}

/// The largest per-joint difference between two configurations, modulo 2π.
fn max_angle_diff(a: &Joints, b: &Joints) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| wrap_pi(x - y).abs())
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_joints(rng: &mut impl Rng) -> Joints {
        Joints::from_fn(6, |_| rng.random_range(-PI..PI))
    }

    /// Away from the wrist, elbow and shoulder singularities, where the branch that produced a
    /// pose is well conditioned and recovered to 1e-9.
    fn well_conditioned(model: &UrModel, q: &Joints) -> bool {
        let p05 = model.forward(q).translation.vector
            - model.d[5] * (model.forward(q).rotation * Vector3::z());
        q[4].sin().abs() > 0.1 && q[2].sin().abs() > 0.1 && p05.xy().norm() > 0.2
    }

    #[test]
    fn zero_joints_give_the_published_home_pose() {
        // At zero joints the UR arm lies stretched along −x: x = a2 + a3, y = −(d4 + d6),
        // z = d1 − d5; the flange orientation is Rx(π/2): x along +x, z along −y.
        for model in [UrModel::ur5e(), UrModel::ur10e()] {
            let pose = model.forward(&Joints::zeros(6));
            let [d1, _, _, d4, d5, d6] = model.d;
            let expected = Vector3::new(model.a[1] + model.a[2], -(d4 + d6), d1 - d5);
            assert!(
                (pose.translation.vector - expected).norm() < 1e-12,
                "{}: {:?}",
                model.name,
                pose.translation
            );
            let rot = pose.rotation.to_rotation_matrix();
            assert!((rot * Vector3::x() - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-12);
            assert!((rot * Vector3::z() - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-12);
        }
        // UR5e numbers spelled out: (−0.8172, −0.2329, 0.0628) m.
        let p = UrModel::ur5e()
            .forward(&Joints::zeros(6))
            .translation
            .vector;
        assert!((p - Vector3::new(-0.8172, -0.2329, 0.0628)).norm() < 1e-12);
    }

    #[test]
    fn inverse_round_trips_random_configurations() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        for model in [UrModel::ur5e(), UrModel::ur10e()] {
            let mut checked = 0;
            while checked < 500 {
                let q = random_joints(&mut rng);
                if !well_conditioned(&model, &q) {
                    continue;
                }
                checked += 1;
                let pose = model.forward(&q);
                let all = model.inverse(&pose);
                assert!(!all.is_empty() && all.len() <= 8);
                for s in &all {
                    let fk = model.forward(s);
                    assert!((fk.translation.vector - pose.translation.vector).norm() < 1e-9);
                    assert!(fk.rotation.angle_to(&pose.rotation) < 1e-9);
                    assert!(model.within_limits(s));
                }
                // The generating configuration is one of the branches ...
                assert!(
                    all.iter().any(|s| max_angle_diff(s, &q) < 1e-9),
                    "{}: {q:?} not among {all:?}",
                    model.name
                );
                // ... and the nearest solution to it is itself, exactly (not a 2π twin).
                let near = model.inverse_nearest(&pose, &q).unwrap();
                let err = near
                    .iter()
                    .zip(&q)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                assert!(err < 1e-9, "{}: {near:?} vs {q:?}", model.name);
            }
        }
    }

    #[test]
    fn generic_pose_has_eight_solutions() {
        let model = UrModel::ur5e();
        let q = Joints::from([0.3, -1.2, 1.4, -0.8, 1.1, 0.4]);
        assert_eq!(model.inverse(&model.forward(&q)).len(), 8);
    }

    #[test]
    fn nearest_picks_the_twin_close_to_the_seed() {
        let model = UrModel::ur5e();
        let q = Joints::from([0.3, -1.2, 1.4, -0.8, 1.1, 0.4]);
        let seed = Joints::from([0.3 - TAU + 0.1, -1.2, 1.4, -0.8, 1.1, 0.4 - TAU]);
        let near = model.inverse_nearest(&model.forward(&q), &seed).unwrap();
        assert!(max_angle_diff(&near, &q) < 1e-9);
        assert!((near[0] - (0.3 - TAU)).abs() < 1e-9 && (near[5] - seed[5]).abs() < 1e-9);
    }

    #[test]
    fn wrist_singularity_keeps_seed_joint6() {
        let model = UrModel::ur5e();
        let q = Joints::from([0.3, -1.2, 1.4, -0.8, 0.0, 0.7]);
        let pose = model.forward(&q);
        let near = model.inverse_nearest(&pose, &q).unwrap();
        let fk = model.forward(&near);
        assert!((fk.translation.vector - pose.translation.vector).norm() < 1e-9);
        assert!(fk.rotation.angle_to(&pose.rotation) < 1e-9);
        assert!((near[5] - 0.7).abs() < 1e-9, "{near:?}");
    }

    #[test]
    fn unreachable_and_non_finite_poses_have_no_solution() {
        let model = UrModel::ur5e();
        let far = Isometry3::translation(2.0, 0.0, 0.3);
        assert!(model.inverse(&far).is_empty());
        assert!(model.inverse_nearest(&far, &Joints::zeros(6)).is_none());
        let nan = Isometry3::translation(f64::NAN, 0.0, 0.3);
        assert!(model.inverse(&nan).is_empty());
    }

    #[test]
    fn narrowed_limits_filter_solutions() {
        let mut model = UrModel::ur5e();
        let q = Joints::from([0.3, -1.2, 1.4, -0.8, 1.1, 0.4]);
        let pose = model.forward(&q);
        // Elbow only positive: half of the branches remain, all with θ3 > 0.
        model.joint_limits[2] = (0.0, PI);
        let all = model.inverse(&pose);
        assert_eq!(all.len(), 4);
        assert!(all.iter().all(|s| s[2] > 0.0 && model.within_limits(s)));
        assert!(!model.within_limits(&Joints::from([0.0, 0.0, -0.1, 0.0, 0.0, 0.0])));
        assert!(!model.within_limits(&Joints::from([f64::NAN, 0.0, 0.1, 0.0, 0.0, 0.0])));
    }

    #[test]
    fn by_name_is_case_insensitive() {
        assert_eq!(UrModel::by_name("UR10e"), Some(UrModel::ur10e()));
        assert_eq!(UrModel::by_name(" ur5e "), Some(UrModel::ur5e()));
        assert_eq!(UrModel::by_name("ur7"), None);
        for name in UrModel::NAMES {
            assert_eq!(
                UrModel::by_name(name).map(|m| m.name),
                Some(name.to_string())
            );
        }
    }
}
