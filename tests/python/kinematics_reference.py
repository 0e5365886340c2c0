#!/usr/bin/env python3
"""An independent reference for handeye's arm fit (issue #41, tests/it/kinematics/reference.rs).

Reads JSON on stdin: a list of problems, each

    {"setup": "eye_in_hand" | "eye_to_hand",
     "model": "joint_offsets" | "dh",                       # what is estimated (default offsets)
     "dh": {"d": [..], "a": [..], "alpha": [..]},          # the arm's nominal standard DH chain
     "sigma_rotation_rad": s_r, "sigma_translation_m": s_t,  # the board-pose noise, 1 sigma
     "start": {"camera_mount": 4x4, "target_mount": 4x4},    # the two transforms to start from
     "samples": [{"joints": [..], "weight": w,
                  "base_from_flange": 4x4,                  # T_base_flange as reported
                  "camera_from_target": 4x4}]}              # T_camera_target as measured

and writes a list of answers as JSON on stdout. Nothing of handeye is used: the problem is
written here from its statement, solved by scipy.optimize.least_squares.

The model. The controller reports T_base_flange through the nominal chain, FK(q); with joint
zero offsets d the flange is at FK(q + d), so the flange pose of a sample is the reported one
moved by the change of model: F(d) = T_reported . FK(q)^-1 . FK(q + d). With "model": "dh" every
link's parameters are corrected too: link i is Rz(q_i + dtheta_i) . Tz(d_i + dd_i) .
Tx(a_i + da_i) . Rx(alpha_i + dalpha_i). The board is then seen
at inv(X) . inv(F) . Y (eye-in-hand: X = T_flange_camera, Y = T_base_target) or
inv(X) . F . Y (eye-to-hand: X = T_base_camera, Y = T_flange_target). The residual of a
sample is the rotation vector of R_measured^T . R_predicted over s_r and the translation
difference (camera frame) over s_t, both times sqrt(weight). Parameters: each transform as a
rotation vector and a translation, and the offsets of the joints the data observe.

Which parameters the data observe is decided here too: one whose Jacobian column (at the start,
all corrections zero) keeps less than ABSORBED of its norm once the twelve transform columns are
projected out is absorbed by the transforms and held at zero; of the rest, in order (joint by
joint, each joint's theta, d, a, alpha), one that keeps less than ABSORBED once the transforms'
and the parameters kept before it are projected out is undetermined and held at zero.

The covariance is (J^T J)^-1 scaled by chi2/dof at the optimum; a transform's 1 sigma is the
square root of the trace of its rotation block (as a left perturbation exp(dtheta) . R, rad) and
of its translation block (m).
"""

import json
import sys

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

# A column keeping less than this fraction of its norm lies in the transforms' span (the reported
# poses' reading noise leaves a few 1e-5 of an exactly absorbed column; an observed one keeps
# more than a tenth).
ABSORBED = 1e-3
STEP = 1e-7


def dh(theta, d, a, alpha):
    """One standard DH link: Rz(theta) . Tz(d) . Tx(a) . Rx(alpha)."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def forward(chain, joints):
    out = np.eye(4)
    for q, d, a, alpha in zip(joints, chain["d"], chain["a"], chain["alpha"]):
        out = out @ dh(q, d, a, alpha)
    return out


def inverse(t):
    out = np.eye(4)
    out[:3, :3] = t[:3, :3].T
    out[:3, 3] = -t[:3, :3].T @ t[:3, 3]
    return out


def transform(params):
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(params[:3]).as_matrix()
    out[:3, 3] = params[3:6]
    return out


def as_params(t):
    return np.concatenate([Rotation.from_matrix(t[:3, :3]).as_rotvec(), t[:3, 3]])


class Problem:
    def __init__(self, spec):
        self.eye_in_hand = spec["setup"] == "eye_in_hand"
        self.chain = spec["dh"]
        self.joints = len(self.chain["d"])
        self.sr = spec["sigma_rotation_rad"]
        self.st = spec["sigma_translation_m"]
        self.samples = []
        for s in spec["samples"]:
            q = np.array(s["joints"], dtype=float)
            reported = np.array(s["base_from_flange"], dtype=float)
            self.samples.append(
                (
                    q,
                    reported @ inverse(forward(self.chain, q)),
                    np.array(s["camera_from_target"], dtype=float),
                    np.sqrt(s.get("weight", 1.0)),
                )
            )

    def corrected(self, q, corrections):
        """FK of the chain with each link's (theta, d, a, alpha) corrections."""
        out = np.eye(4)
        for i, (qi, d, a, alpha) in enumerate(zip(q, self.chain["d"], self.chain["a"], self.chain["alpha"])):
            c = corrections[i]
            out = out @ dh(qi + c[0], d + c[1], a + c[2], alpha + c[3])
        return out

    def residuals(self, x, free):
        cam = transform(x[0:6])
        target = transform(x[6:12])
        corrections = np.zeros((self.joints, 4))
        for value, (j, p) in zip(x[12:], free):
            corrections[j, p] = value
        out = []
        for q, correction, measured, scale in self.samples:
            flange = correction @ self.corrected(q, corrections)
            chain = inverse(flange) if self.eye_in_hand else flange
            predicted = inverse(cam) @ chain @ target
            rot = Rotation.from_matrix(measured[:3, :3].T @ predicted[:3, :3]).as_rotvec()
            out.append(rot * scale / self.sr)
            out.append((predicted[:3, 3] - measured[:3, 3]) * scale / self.st)
        return np.concatenate(out)

    def jacobian(self, x, free):
        cols = []
        for k in range(len(x)):
            e = np.zeros(len(x))
            e[k] = STEP
            cols.append((self.residuals(x + e, free) - self.residuals(x - e, free)) / (2 * STEP))
        return np.stack(cols, axis=1)


def left_perturbation(rotvec):
    """The 3x3 map from a change of the rotation vector to the left perturbation exp(dtheta) . R."""
    r = Rotation.from_rotvec(rotvec)
    out = np.zeros((3, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = STEP
        out[:, k] = (Rotation.from_rotvec(rotvec + e) * r.inv()).as_rotvec() / STEP
    return out


def solve(spec):
    problem = Problem(spec)
    start = np.concatenate(
        [
            as_params(np.array(spec["start"]["camera_mount"], dtype=float)),
            as_params(np.array(spec["start"]["target_mount"], dtype=float)),
        ]
    )
    parameters = 4 if spec.get("model") == "dh" else 1
    every = [(j, p) for j in range(problem.joints) for p in range(parameters)]
    full = problem.jacobian(np.concatenate([start, np.zeros(len(every))]), every)

    def remains(k, span):
        column = full[:, 12 + k]
        fit, *_ = np.linalg.lstsq(span, column, rcond=None)
        return float(np.linalg.norm(column - span @ fit) / np.linalg.norm(column))

    transforms = full[:, :12]
    absorbed = [remains(k, transforms) for k in range(len(every))]
    free, held = [], {}
    kept = transforms
    for k, param in enumerate(every):
        if absorbed[k] < ABSORBED:
            held[param] = "absorbed"
        elif remains(k, kept) < ABSORBED:
            held[param] = "undetermined"
        else:
            free.append(param)
            kept = np.hstack([kept, full[:, 12 + k : 13 + k]])
    # The offsets' share kept of each joint's column (the offsets model's record of it).
    remains_offsets = [absorbed[k] for k, (j, p) in enumerate(every) if p == 0]
    x0 = np.concatenate([start, np.zeros(len(free))])
    fit = least_squares(
        problem.residuals, x0, args=(free,), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15,
        max_nfev=20000,
    )
    jac = problem.jacobian(fit.x, free)
    m, p = jac.shape
    chi2 = float(fit.fun @ fit.fun)
    cov = np.linalg.inv(jac.T @ jac) * chi2 / (m - p)

    def sigma(at):
        rot = left_perturbation(fit.x[at : at + 3])
        rot_cov = rot @ cov[at : at + 3, at : at + 3] @ rot.T
        return {
            "rotation_rad": float(np.sqrt(np.trace(rot_cov))),
            "translation_m": float(np.sqrt(np.trace(cov[at + 3 : at + 6, at + 3 : at + 6]))),
        }

    offsets = [None] * problem.joints
    offset_sigmas = [None] * problem.joints
    corrections = [[None] * 4 for _ in range(problem.joints)]
    correction_sigmas = [[None] * 4 for _ in range(problem.joints)]
    for k, (j, p) in enumerate(free):
        corrections[j][p] = float(fit.x[12 + k])
        correction_sigmas[j][p] = float(np.sqrt(cov[12 + k, 12 + k]))
        if p == 0:
            offsets[j] = corrections[j][p]
            offset_sigmas[j] = correction_sigmas[j][p]
    return {
        "status": int(fit.status),
        "nfev": int(fit.nfev),
        "chi2": chi2,
        "camera_mount": transform(fit.x[0:6]).tolist(),
        "target_mount": transform(fit.x[6:12]).tolist(),
        "camera_mount_sigma": sigma(0),
        "target_mount_sigma": sigma(6),
        "offsets_rad": offsets,
        "offset_sigmas_rad": offset_sigmas,
        "corrections": corrections,
        "correction_sigmas": correction_sigmas,
        "held": {f"{j},{p}": why for (j, p), why in held.items()},
        "remains": remains_offsets,
    }


def main():
    problems = json.load(sys.stdin)
    json.dump([solve(p) for p in problems], sys.stdout)


if __name__ == "__main__":
    main()
