"""A simulated ROS 2 arm and camera served from a rendered handeye sim session, the way the UR
ROS 2 driver and a camera node would: `/joint_states` (100 Hz), `/tf` (base_link -> tool0, 50 Hz)
and `/tf_static` (base_link -> base, the UR driver's 180 degree turn), `/image_raw` (mono8,
15 Hz) with `/camera_info`, and the `FollowJointTrajectory` action on
`/scaled_joint_trajectory_controller/follow_joint_trajectory`, framed as rmw_cyclonedds frames
requests and replies (a 16-byte header: the client's id and a sequence number).

The views come from SESSION_DIR (a `handeye run` of a sim config with the same plan): the arm
at rest at plan pose k reports that session's recorded `T_base_flange` of pose k, and the camera
shows its frame k; an image stamped at time t shows where the arm was at t (before the arm
arrives, the previous view). Every goal, cancel and fault is printed on stdout as one JSON line.

Hand-guiding, as a person with the pendant's freedrive would: a line `guide K` on stdin moves the
arm to plan pose K's joints over --guide-s seconds, with no trajectory goal (joint speeds on
/joint_states, the flange from the forward kinematics while it moves), printing `guiding` when it
starts and `guided` when it stands there.

Freedrive as the UR driver (2.5 or later) serves it, with --freedrive humble|jazzy: the
controller manager's switch_controller service in that distribution's layout (strict switches
between the motion controller of --action and freedrive_mode_controller), and the freedrive
controller's keep-alive topic `~/enable_freedrive_mode` (freedrive ends after
--freedrive-timeout-s without `true`). Goals are then refused while the motion controller is
inactive, and `guide K` is refused unless the arm is in freedrive (the arm stops where it is when
freedrive ends mid-guide).

Faults for tests: --lose-first-switch request|reply (the first switch_controller request, or only
its reply, is lost in transit), --lose-first-goal request|reply (the first trajectory goal is
lost in transit, or only its reply is: the goal runs unanswered), --abort-goal N (the Nth goal ends ABORTED with PATH_TOLERANCE_VIOLATED),
--die-in-goal N (the process exits halfway through the Nth goal), --no-tool0 (the TF tree lacks
tool0), --succeed-without-moving N, --second-flange-publisher [N] (a second DDS writer on /tf, as
a second robot_state_publisher or a static publisher left running would be: base_link -> tool0
10 cm and 180 degrees from the driver's, at 200 Hz, while the arm stands; from the start, or from
the end of the Nth goal on), --jumping-flange N (from the end of the Nth goal on, while the arm
stands, every other base_link -> tool0 of the driver's own /tf writer is 5 mm off along x while
/joint_states stand: a flange pose that contradicts the joints), --flange-off-model N (from the
end of the Nth goal on, 0: from the start, while the arm stands, the driver's base_link -> tool0
is 40 mm off along x from the arm's forward kinematics, steadily: a chain that is not the
arm's), --huge-images [MB] (the image topic carries mono8 frames of MB megabytes, 100 by
default, once a second instead of the views: a camera node streaming far more than the
intrinsics' size; written from a thread of their own, serialised once, so the action server and
/tf keep being served; with --huge-images-from N, once the Nth goal has ended: a camera switched
while the arm stands).
"""

import glob
import json
import math
import os
import struct
import sys
import threading
import time

import numpy as np
import yaml

from . import dds
from . import msgs as m

JOINTS = [
    "shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
    "wrist_1_joint", "wrist_2_joint", "wrist_3_joint",
]


# Universal Robots' published DH parameters (d1, a2, a3, d4, d5, d6), metres; alpha is the same
# for every model: (pi/2, 0, 0, pi/2, -pi/2, 0).
UR_DH = {
    "ur5e": (0.1625, -0.425, -0.3922, 0.1333, 0.0997, 0.0996),
    "ur10e": (0.1807, -0.6127, -0.57155, 0.17415, 0.11985, 0.11655),
}


# Franka's published kinematics for its seven-joint arms (Panda, FR3), Craig's modified DH: per
# joint (a, d, alpha) of Rx(alpha) Tx(a) Rz(q) Tz(d), then the flange 0.107 m along the last z.
FRANKA_MDH = ((0, 0.333, 0), (0, 0, -math.pi / 2), (0, 0.316, math.pi / 2),
              (0.0825, 0, math.pi / 2), (-0.0825, 0.384, -math.pi / 2), (0, 0, math.pi / 2),
              (0.088, 0, math.pi / 2))
FRANKA_FLANGE_D = 0.107
FRANKA_LIMITS = ((-2.8973, 2.8973), (-1.7628, 1.7628), (-2.8973, 2.8973), (-3.0718, -0.0698),
                 (-2.8973, 2.8973), (-0.0175, 3.7525), (-2.8973, 2.8973))
FRANKA_HOME = (0.0, -math.pi / 4, 0.0, -3 * math.pi / 4, 0.0, math.pi / 2, math.pi / 4)
MODELS = sorted(["ur5e", "ur10e", "franka"])


def joint_count(model):
    return 7 if model == "franka" else 6


def franka_forward(q):
    """The flange of a Franka arm in its own base frame (4x4) at joints q."""
    T = np.eye(4)
    for (a, d, alpha), qi in zip(FRANKA_MDH, q):
        ca, sa, ct, st = math.cos(alpha), math.sin(alpha), math.cos(qi), math.sin(qi)
        T = T @ np.array([[ct, -st, 0, a],
                          [st * ca, ct * ca, -sa, -d * sa],
                          [st * sa, ct * sa, ca, d * ca],
                          [0, 0, 0, 1]])
    flange = np.eye(4)
    flange[2, 3] = FRANKA_FLANGE_D
    return T @ flange


def rotvec_of(R):
    """The rotation vector of a rotation matrix: from its skew part up to 90 degrees (exact near
    zero, where the IK converges), through its quaternion beyond (safe near pi)."""
    c = (R[0, 0] + R[1, 1] + R[2, 2] - 1) / 2
    if c > 0:
        v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2
        n = float(np.linalg.norm(v))
        return v if n < 1e-15 else v * (math.atan2(n, c) / n)
    x, y, z, w = quat_of(R)
    if w < 0:
        x, y, z, w = -x, -y, -z, -w
    n = math.sqrt(x * x + y * y + z * z)
    if n < 1e-15:
        return np.zeros(3)
    return np.array([x, y, z]) * (2 * math.atan2(n, w) / n)


def franka_inverse(target, seed_rng):
    """Joints inside Franka's limits whose flange is `target` (4x4, in the arm's base frame) to
    1e-10, by damped least squares from the home pose and then random starts; None if none."""
    lo = np.array([l for l, _ in FRANKA_LIMITS])
    hi = np.array([h for _, h in FRANKA_LIMITS])

    def error(q):
        T = franka_forward(q)
        return np.concatenate([target[:3, 3] - T[:3, 3], rotvec_of(target[:3, :3] @ T[:3, :3].T)])

    starts = [np.array(FRANKA_HOME)] + [seed_rng.uniform(lo, hi) for _ in range(30)]
    for q in starts:
        q = np.clip(q, lo + 1e-3, hi - 1e-3)
        for _ in range(100):
            e = error(q)
            if np.linalg.norm(e) < 1e-10:
                return q
            J = np.empty((6, 7))
            for j in range(7):
                dq = np.zeros(7)
                dq[j] = 1e-7
                J[:, j] = (e - error(q + dq)) / 1e-7
            step = J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(6), e)
            q = np.clip(q + step, lo + 1e-4, hi - 1e-4)
    return None


def forward(model, q, mount=None):
    """T_base_flange (4x4) at joints q. A UR: the product of Rz(q) Tz(d) Tx(a) Rx(alpha) per
    link. A Franka arm: its kinematics, its base at `mount` (T_base_armbase)."""
    if model == "franka":
        return mount @ franka_forward(q)
    d1, a2, a3, d4, d5, d6 = UR_DH[model]
    d = (d1, 0, 0, d4, d5, d6)
    a = (0, a2, a3, 0, 0, 0)
    alpha = (math.pi / 2, 0, 0, math.pi / 2, -math.pi / 2, 0)
    T = np.eye(4)
    for i in range(6):
        ct, st = math.cos(q[i]), math.sin(q[i])
        ca, sa = math.cos(alpha[i]), math.sin(alpha[i])
        T = T @ np.array([[ct, -st * ca, st * sa, a[i] * ct],
                          [st, ct * ca, -ct * sa, a[i] * st],
                          [0, sa, ca, d[i]],
                          [0, 0, 0, 1]])
    return T


def quat_of(R):
    """(x, y, z, w) of a rotation matrix."""
    w = math.sqrt(max(0.0, 1 + R[0, 0] + R[1, 1] + R[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1 + R[0, 0] - R[1, 1] - R[2, 2])) / 2, R[2, 1] - R[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1 - R[0, 0] + R[1, 1] - R[2, 2])) / 2, R[0, 2] - R[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1 - R[0, 0] - R[1, 1] + R[2, 2])) / 2, R[1, 0] - R[0, 1])
    return (x, y, z, w)


class LyingActionServer:
    """A FollowJointTrajectory action server of the driver's name on a DDS participant of its own
    (another process's, as far as discovery can tell): it accepts every goal and answers
    SUCCEEDED at once, moving nothing. Its replies reach the client beside the driver's."""

    def __init__(self, domain, loopback, action):
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        dp = dds.participant(domain, loopback)
        a = action + "/_action/"
        self.goal_r = DataReader(dp, Topic(dp, "rq" + a + "send_goalRequest", m.SendGoalRequest),
                                 qos=dds.qos_reliable())
        self.goal_w = DataWriter(dp, Topic(dp, "rr" + a + "send_goalReply", m.SendGoalReply),
                                 qos=dds.qos_reliable())
        self.res_r = DataReader(dp, Topic(dp, "rq" + a + "get_resultRequest", m.GetResultRequest),
                                qos=dds.qos_reliable())
        self.res_w = DataWriter(dp, Topic(dp, "rr" + a + "get_resultReply", m.GetResultReply),
                                qos=dds.qos_reliable())
        self.participant = dp
        self.goals = 0

    def serve(self):
        for req in self.goal_r.take(N=10):
            if hasattr(req, "goal_id"):
                self.goals += 1
                self.goal_w.write(m.SendGoalReply(req.client_id, req.seq, True, stamp_now()))
                say(event="liar_goal", n=self.goals)
        for req in self.res_r.take(N=10):
            if hasattr(req, "goal_id"):
                self.res_w.write(m.GetResultReply(req.client_id, req.seq, 4, m.FJTResult(0, "")))


def add_arguments(p):
    p.add_argument("session", help="a sim session folder (session.yaml, poses/, frames/)")
    p.add_argument("--camera-info", required=True, help="the camera_info YAML of the sim camera")
    p.add_argument("--start-joints-deg", default=None,
                   help="default: 0,-90,90,-90,-90,0 for a UR, Franka's home pose for franka")
    p.add_argument("--model", default="ur10e", choices=MODELS,
                   help="the arm's kinematics: a UR, or `franka` (seven joints, Franka's published "
                        "kinematics; mounted where it reaches every view, and each view's joints "
                        "found by its inverse kinematics)")
    p.add_argument("--joint-names", default=None,
                   help="the joint names it publishes and takes goals for (default: the UR driver's "
                        "six, or fr3_joint1..7 for franka; another arm's names may be given: the "
                        "kinematics inside stay the --model's)")
    p.add_argument("--action", default="/scaled_joint_trajectory_controller/follow_joint_trajectory")
    p.add_argument("--image-hz", type=float, default=15.0)
    p.add_argument("--guide-s", type=float, default=1.5, help="how long a `guide K` move takes")
    p.add_argument("--freedrive", choices=["humble", "jazzy"], default=None,
                   help="serve the UR driver's freedrive: switch_controller as this distribution lays it out")
    p.add_argument("--freedrive-timeout-s", type=float, default=1.0)
    p.add_argument("--lose-first-switch", choices=["request", "reply"], default=None,
                   help="the first switch_controller request is lost in transit (neither done nor "
                        "answered), or only its reply is (done, not answered)")
    p.add_argument("--lose-first-goal", choices=["request", "reply"], default=None,
                   help="the first trajectory goal request is lost in transit (neither run nor "
                        "answered), or only its reply is (run, not answered)")
    p.add_argument("--abort-goal", type=int, default=0)
    p.add_argument("--die-in-goal", type=int, default=0)
    p.add_argument("--no-tool0", action="store_true")
    p.add_argument("--second-flange-publisher", type=int, nargs="?", const=0, default=None,
                   metavar="N",
                   help="a second writer of base_link -> tool0 on /tf (200 Hz, while the arm stands): "
                        "the driver's flange turned 180 degrees about its x axis and 10 cm along its z; "
                        "from the start, or once goal N has ended")
    p.add_argument("--jumping-flange", type=int, default=None, metavar="N",
                   help="once goal N has ended, while the arm stands, every other base_link -> tool0 "
                        "message of the driver's /tf writer is 5 mm off along x (the joints stand)")
    p.add_argument("--flange-off-model", type=int, default=None, metavar="N",
                   help="once goal N has ended (0: from the start), while the arm stands, the driver's "
                        "base_link -> tool0 is 40 mm off along x, steadily (the joints are the arm's)")
    p.add_argument("--succeed-without-moving", type=int, default=0,
                   help="answer goal N SUCCEEDED at once and leave the arm where it stands")
    p.add_argument("--huge-images", type=float, nargs="?", const=100.0, default=None, metavar="MB",
                   help="publish mono8 frames of MB megabytes (10000 px wide) on the image topic, "
                        "once a second, instead of the rendered views")
    p.add_argument("--huge-images-from", type=int, default=0, metavar="N",
                   help="the huge images replace the views once goal N has ended (0: from the start)")
    p.add_argument("--duplicate-action-server", type=int, nargs="?", const=0, default=None,
                   metavar="N",
                   help="a second action server of the same name, on a DDS participant of its own "
                        "(a simulated controller left running beside the driver): it accepts every "
                        "goal and answers SUCCEEDED at once without moving anything; from the "
                        "start, or from when goal N is accepted")
    p.add_argument("--tf-flood", type=int, default=0, metavar="K",
                   help="K frame names nobody asked for on /tf (flood_0 ... flood_K-1, 500 to a "
                        "message, every second), and the driver's base_link -> tool0 only after "
                        "the first flood")
    p.add_argument("--max-joint-speed-deg", type=float, default=0.0,
                   help="report goals whose waypoint speeds exceed this (0: no check)")


_SAY = threading.Lock()


def say(**kw):
    """One JSON event a line on stdout, written whole under a lock: print() writes the text and
    its newline in two writes, so two threads' events could share a line (the huge-image
    writer's first event and `ready` did, 2 starts in 5 under the test harness, which then read
    neither and waited for `ready` in vain)."""
    line = json.dumps(kw) + "\n"
    with _SAY:
        sys.stdout.write(line)
        sys.stdout.flush()


def stamp_now():
    t = time.time()
    return m.Time(int(t), int((t % 1) * 1e9))


def quat_mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


def pose_of(p):
    q = p["quaternion"]
    return np.array(p["translation"], float), (q["x"], q["y"], q["z"], q["w"])


def load_session(folder):
    from PIL import Image as PilImage

    with open(os.path.join(folder, "session.yaml")) as f:
        session = yaml.safe_load(f)
    plan = [pose_of(p["T_base_flange"]) for p in session["plan"]]
    plan_joints = [np.radians(p["joints_deg"]) for p in session["plan"]]
    views = {}
    for path in sorted(glob.glob(os.path.join(folder, "poses", "*.yaml"))):
        with open(path) as f:
            rec = yaml.safe_load(f)
        frame = np.asarray(PilImage.open(os.path.join(folder, rec["frame"])).convert("L"))
        views[rec["plan_index"]] = (pose_of(rec["T_base_flange"]), frame)
    return plan, plan_joints, views


class Arm:
    """The arm's state: joints, speeds, which view it shows; moved by trajectory goals."""

    def __init__(self, model, start, plan, views, mount=None):
        self.model, self.mount = model, mount
        self.lock = threading.Lock()
        self.q = np.array(start, float)
        self.qd = np.zeros(len(self.q))
        self.plan, self.views = plan, views
        self.view = None  # (pose, frame) of the plan pose the arm stands at
        self.goal = None  # (goal id, points [(t, q)], start time, done event)
        self.guide = None  # (plan index, from joints, to joints, start time, duration): by hand

    def nearest_view(self, q):
        """The rendered view of the plan pose whose flange position the arm's forward
        kinematics reaches (within 1 mm), or None."""
        T = forward(self.model, q, self.mount)
        d = [float(np.linalg.norm(t - T[:3, 3])) for t, _ in self.plan]
        k = int(np.argmin(d)) if d else -1
        if k < 0 or d[k] > 1e-3 or k not in self.views:
            say(event="no_view", joints=list(q), nearest=k, distance_m=d[k] if d else None)
            return None
        return self.views[k]

    def flange(self):
        """(translation, quaternion xyzw) of T_base_flange: the recorded one at a view, else the
        forward kinematics (moving, or at a pose with no view)."""
        if self.view is not None and self.goal is None and self.guide is None:
            return self.view[0]
        T = forward(self.model, self.q, self.mount)
        return T[:3, 3], quat_of(T[:3, :3])


class Freedrive:
    """The UR driver's controller manager and freedrive_mode_controller (see the module docs)."""

    FREEDRIVE = "freedrive_mode_controller"

    def __init__(self, args, R, W, action):
        if args.freedrive == "humble":
            req, self.reply = m.SwitchRequestHumble, m.SwitchReplyHumble
        else:
            req, self.reply = m.SwitchRequestJazzy, m.SwitchReplyJazzy
        self.motion = action.strip("/").split("/")[0]
        self.active = {self.motion}
        self.on, self.last, self.timeout = False, 0.0, args.freedrive_timeout_s
        self.lose_first, self.requests = args.lose_first_switch, 0
        self.switch_r = R("rq/controller_manager/switch_controllerRequest", req, dds.qos_reliable())
        self.switch_w = W("rr/controller_manager/switch_controllerReply", self.reply, dds.qos_reliable())
        self.enable_r = R(f"rt/{self.FREEDRIVE}/enable_freedrive_mode", m.Bool, dds.qos_reliable())

    def motion_active(self):
        return self.motion in self.active

    def set(self, on, why):
        self.on = on
        say(event="freedrive", on=on, why=why)

    def serve(self, now):
        """Answers switches and keep-alives; True when freedrive ended here."""
        was = self.on
        known = {self.motion, self.FREEDRIVE}
        try:
            requests = self.switch_r.take(N=10)
        except Exception as e:  # a request in another distribution's layout does not parse
            say(event="bad_request", service="switch_controller", error=str(e))
            requests = []
        for req in requests:
            if not hasattr(req, "strictness"):
                continue
            self.requests += 1
            lost = self.lose_first if self.requests == 1 else None
            if lost == "request":
                say(event="lost_switch", lost="request")
                continue
            act, deact = list(req.activate_controllers), list(req.deactivate_controllers)
            ok = (all(c in known and c not in self.active for c in act)
                  and all(c in self.active for c in deact))
            if ok:
                self.active = (self.active - set(deact)) | set(act)
                if self.FREEDRIVE not in self.active and self.on:
                    self.set(False, "controller deactivated")
            if lost == "reply":
                say(event="lost_switch", lost="reply", ok=ok, active=sorted(self.active))
                continue
            self.switch_w.write(self.reply(req.client_id, req.seq, ok))
            say(event="switch", activate=act, deactivate=deact, strictness=req.strictness, ok=ok,
                active=sorted(self.active))
        for msg in self.enable_r.take(N=100):
            if self.FREEDRIVE not in self.active:
                continue
            if msg.data:
                self.last = now
                if not self.on:
                    self.set(True, "enabled")
            elif self.on:
                self.set(False, "disabled")
        if self.on and now - self.last > self.timeout:
            self.set(False, "keep-alive timeout")
        return was and not self.on


def huge_images(writer, megabytes, active):
    """Writes a mono8 frame of `megabytes` MB (10000 px wide) on `writer` once a second while
    `active()`, forever.

    Serialising 100 MB through the Python binding takes over 10 s (a loop over bytes), which
    would stall this peer's action server and hide what the test is about; so the frame is
    serialised once from a small image whose data field is then replaced, and only the stamp
    (bytes 4..12, after the 4-byte encapsulation header) is rewritten before each raw write."""
    from cyclonedds._clayer import ddspy_write

    width = 10000
    height = max(1, int(megabytes * 1e6) // width)
    size = width * height
    small = m.Image(m.Header(stamp_now(), "camera_optical_frame"), height, width, "mono8", 0,
                    width, bytes(4)).serialize()
    # The data sequence ends the message: its uint32 length, then its 4 bytes.
    frame = bytearray(small[:-8] + struct.pack("<I", size) + bytes(size))
    first = True
    while True:
        if not active():
            time.sleep(0.01)
            continue
        t = time.time()
        frame[4:12] = struct.pack("<iI", int(t), int((t % 1) * 1e9))
        started = time.monotonic()
        ddspy_write(writer._ref, bytes(frame))
        if first:
            say(event="huge_image", bytes=size, width=width, height=height,
                write_s=time.monotonic() - started)
            first = False
        time.sleep(max(0.0, 1.0 - (time.monotonic() - started)))


def cdr_bytes(frame):
    return frame.tobytes()


def matrix_of(pose):
    """4x4 of (translation, quaternion xyzw)."""
    t, (x, y, z, w) = pose
    T = np.eye(4)
    T[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                 [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                 [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    T[:3, 3] = t
    return T


def franka_plan(plan):
    """A Franka arm's mount (T_base_armbase) and, per plan pose, the joints that reach it: the
    arm stands 0.3 m back from the views' centre (towards the base's origin) and 0.55 m below
    it, facing the views (its reach, 0.855 m, then covers every view of the shipped plan with
    its wrist's ranges)."""
    centre = np.mean([t for t, _ in plan], axis=0)
    yaw = math.atan2(centre[1], centre[0])
    mount = np.eye(4)
    mount[:3, :3] = [[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]]
    mount[:3, 3] = centre - mount[:3, :3] @ np.array([0.3, 0.0, 0.55])
    rng = np.random.default_rng(7)
    joints = []
    for k, pose in enumerate(plan):
        q = franka_inverse(np.linalg.inv(mount) @ matrix_of(pose), rng)
        if q is None:
            raise SystemExit(f"franka: plan pose {k} is out of the arm's reach from its mount")
        joints.append(q)
    return mount, joints


def run(args):
    plan, plan_joints, views = load_session(args.session)
    with open(args.camera_info) as f:
        ci = yaml.safe_load(f)
    dof = joint_count(args.model)
    mount = None
    if args.model == "franka":
        mount, plan_joints = franka_plan(plan)
        default_start, default_names = np.degrees(FRANKA_HOME), [f"fr3_joint{i}" for i in range(1, 8)]
    else:
        default_start, default_names = (0, -90, 90, -90, -90, 0), JOINTS
    start = np.radians([float(v) for v in args.start_joints_deg.split(",")]
                       if args.start_joints_deg else default_start)
    joint_names = args.joint_names.split(",") if args.joint_names else list(default_names)
    if len(joint_names) != dof or len(start) != dof:
        raise SystemExit(f"--joint-names, --start-joints-deg: expected {dof} values for {args.model}")
    arm = Arm(args.model, start, plan, views, mount)

    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    dp = dds.participant(args.domain, args.loopback)
    W = lambda name, T, qos: DataWriter(dp, Topic(dp, name, T), qos=qos)  # noqa: E731
    R = lambda name, T, qos: DataReader(dp, Topic(dp, name, T), qos=qos)  # noqa: E731
    js_w = W("rt/joint_states", m.JointState, dds.qos_reliable())
    tf_w = W("rt/tf", m.TFMessage, dds.qos_reliable(100))
    # Another node's writer of the same topic (its own DDS writer, so its own publisher gid).
    tf2_w = (W("rt/tf", m.TFMessage, dds.qos_reliable(100))
             if args.second_flange_publisher is not None else None)
    tfs_w = W("rt/tf_static", m.TFMessage, dds.qos_static())
    img_w = W("rt/image_raw", m.Image, dds.qos_sensor())
    info_w = W("rt/camera_info", m.CameraInfo, dds.qos_sensor())
    a = "/_action/"
    base = args.action
    goal_r = R("rq" + base + a + "send_goalRequest", m.SendGoalRequest, dds.qos_reliable())
    goal_w = W("rr" + base + a + "send_goalReply", m.SendGoalReply, dds.qos_reliable())
    res_r = R("rq" + base + a + "get_resultRequest", m.GetResultRequest, dds.qos_reliable())
    res_w = W("rr" + base + a + "get_resultReply", m.GetResultReply, dds.qos_reliable())
    can_r = R("rq" + base + a + "cancel_goalRequest", m.CancelGoalRequest, dds.qos_reliable())
    can_w = W("rr" + base + a + "cancel_goalReply", m.CancelGoalReply, dds.qos_reliable())
    fb_w = W("rt" + base + a + "feedback", m.FeedbackMessage, dds.qos_reliable())
    freedrive = Freedrive(args, R, W, base) if args.freedrive else None
    liar = None

    # base_link -> base: the UR driver's static turn of 180 degrees about z.
    turn = (0.0, 0.0, 1.0, 0.0)
    tfs_w.write(m.TFMessage([m.TransformStamped(
        m.Header(stamp_now(), "base_link"), "base",
        m.Transform(m.Vector3(0, 0, 0), m.Quaternion(*turn)))]))

    K = ci["camera_matrix"]["data"]
    info = m.CameraInfo(
        header=m.Header(stamp_now(), "camera_optical_frame"),
        height=ci["image_height"], width=ci["image_width"],
        distortion_model=ci.get("distortion_model", "plumb_bob"),
        d=list(ci["distortion_coefficients"]["data"]), k=list(K),
        r=[1, 0, 0, 0, 1, 0, 0, 0, 1],
        p=[K[0], 0, K[2], 0, 0, K[4], K[5], 0, 0, 0, 1, 0])

    goals = {}  # goal uuid bytes -> dict(status, result, waiting=[(client_id, seq)])
    goal_count = [0]
    goal_requests = [0]
    arrived_count = [0]

    def finish(gid, status, code=0, text=""):
        g = goals[gid]
        g["status"], g["code"], g["text"] = status, code, text
        for cid, seq in g["waiting"]:
            res_w.write(m.GetResultReply(cid, seq, status, m.FJTResult(code, text)))
        g["waiting"] = []

    def serve():
        for req in goal_r.take(N=10):
            if not hasattr(req, "goal_id"):
                continue
            gid = bytes(req.goal_id.uuid)
            tr = req.goal.trajectory
            goal_requests[0] += 1
            lost = args.lose_first_goal if goal_requests[0] == 1 else None
            if lost == "request":
                say(event="goal_lost", what="request")
                continue
            goal_count[0] += 1
            n = goal_count[0]
            pts = [(p.time_from_start.sec + p.time_from_start.nanosec * 1e-9, np.array(p.positions),
                    np.array(p.velocities) if len(p.velocities) == dof else None) for p in tr.points]
            ok = list(tr.joint_names) == joint_names and pts and all(len(q) == dof for _, q, _ in pts) and arm.guide is None
            # An inactive controller's action server takes no goals.
            ok = ok and (freedrive is None or freedrive.motion_active())
            max_speed = max((float(np.max(np.abs(v))) for _, _, v in pts if v is not None), default=0.0)
            if lost == "reply":
                say(event="goal_lost", what="reply")
            else:
                goal_w.write(m.SendGoalReply(req.client_id, req.seq, bool(ok), stamp_now()))
            say(event="goal", n=n, accepted=bool(ok), points=len(pts),
                duration_s=pts[-1][0] if pts else 0.0, max_joint_speed_rad_s=max_speed,
                joint_names=list(tr.joint_names))
            if not ok:
                continue
            goals[gid] = {"status": 2, "waiting": [], "n": n}
            with arm.lock:
                arm.goal = (gid, pts, time.monotonic(), arm.q.copy(), n)
        for req in res_r.take(N=10):
            if not hasattr(req, "goal_id"):
                continue
            gid = bytes(req.goal_id.uuid)
            g = goals.get(gid)
            if g is None:
                res_w.write(m.GetResultReply(req.client_id, req.seq, 0, m.FJTResult(-1, "unknown goal")))
            elif g["status"] in (4, 5, 6):
                res_w.write(m.GetResultReply(req.client_id, req.seq, g["status"], m.FJTResult(g["code"], g["text"])))
            else:
                g["waiting"].append((req.client_id, req.seq))
        for req in can_r.take(N=10):
            if not hasattr(req, "goal_info"):
                continue
            gid = bytes(req.goal_info.goal_id.uuid)
            canceling = []
            with arm.lock:
                if arm.goal and (arm.goal[0] == gid or not any(gid)):
                    cur = arm.goal[0]
                    arm.goal = None
                    arm.qd = np.zeros(dof)
                    # Stopped between views: no rendered view, the flange from the kinematics.
                    arm.view = None
                    canceling.append(m.GoalInfo(m.UUID(list(cur)), stamp_now()))
                    say(event="cancel", n=goals[cur]["n"], joints=list(arm.q))
                    finish(cur, 5, 0, "canceled")
            can_w.write(m.CancelGoalReply(req.client_id, req.seq, 0 if canceling else 2, canceling))

    def hand_guide(now):
        """A person moving the arm: a smooth (cosine) joint path to the plan pose, no goal."""
        k, q0, q1, t0, duration = arm.guide
        f = min(1.0, (now - t0) / duration)
        if f >= 1.0:
            arm.q, arm.qd, arm.guide = q1.copy(), np.zeros(dof), None
            arm.view = arm.nearest_view(arm.q)
            say(event="guided", k=k, at=time.time())
            return
        s = (1 - math.cos(math.pi * f)) / 2
        arm.q = q0 + s * (q1 - q0)
        arm.qd = (q1 - q0) * math.pi / 2 * math.sin(math.pi * f) / duration

    def read_commands():
        for line in sys.stdin:
            words = line.split()
            if len(words) == 2 and words[0] == "guide" and words[1].isdigit():
                k = int(words[1])
                if k >= len(plan_joints):
                    say(event="bad_command", line=line.strip())
                    continue
                with arm.lock:
                    if arm.goal:
                        say(event="bad_command", line=line.strip(), why="a goal is running")
                        continue
                    if freedrive is not None and not freedrive.on:
                        say(event="bad_command", line=line.strip(), why="not in freedrive")
                        continue
                    arm.guide = (k, arm.q.copy(), plan_joints[k], time.monotonic(), args.guide_s)
                say(event="guiding", k=k)
            elif words:
                say(event="bad_command", line=line.strip())

    threading.Thread(target=read_commands, daemon=True).start()
    def huge_now():
        return args.huge_images is not None and arrived_count[0] >= args.huge_images_from

    if args.huge_images is not None:
        threading.Thread(target=huge_images, args=(img_w, args.huge_images, huge_now),
                         daemon=True).start()

    def step(now):
        with arm.lock:
            if arm.guide:
                hand_guide(now)
                return
            if not arm.goal:
                return
            gid, pts, t0, q0, n = arm.goal
            t = now - t0
            total = pts[-1][0]
            if args.die_in_goal == n and t > total / 2:
                say(event="die", n=n)
                os._exit(0)
            if args.succeed_without_moving == n:
                arm.goal = None
                arm.qd = np.zeros(dof)
                say(event="succeeded_without_moving", n=n)
                finish(gid, 4)
                return
            if args.abort_goal == n and t > total / 2:
                arm.goal = None
                arm.qd = np.zeros(dof)
                arm.view = None
                say(event="abort", n=n)
                finish(gid, 6, -4, "simulated: path tolerance violated at joint shoulder_lift_joint")
                return
            if t >= total:
                arm.q = pts[-1][1].copy()
                arm.qd = np.zeros(dof)
                arm.goal = None
                arm.view = arm.nearest_view(arm.q)
                finish(gid, 4)
                arrived_count[0] += 1
                say(event="arrived", n=n, at=time.time())
                return
            prev_t, prev_q = 0.0, q0
            for tk, qk, _ in pts:
                if t <= tk:
                    f = (t - prev_t) / max(tk - prev_t, 1e-9)
                    q = prev_q + f * (qk - prev_q)
                    arm.qd = (qk - prev_q) / max(tk - prev_t, 1e-9)
                    arm.q = q
                    break
                prev_t, prev_q = tk, qk

    # The joints of each plan pose (degrees): a taught plan for this arm pairs them with the
    # flange pose it reports there.
    say(event="ready", poses=len(views), plan_joints_deg=[list(np.degrees(q)) for q in plan_joints])
    next_js = next_tf = next_tf2 = next_img = next_info = time.monotonic()
    second = 0
    jumps = 0
    off_model = 0
    flooded = False
    next_flood = time.monotonic()
    while True:
        now = time.monotonic()
        serve()
        if liar is None and args.duplicate_action_server is not None \
                and goal_count[0] >= args.duplicate_action_server:
            liar = LyingActionServer(args.domain, args.loopback, base)
            say(event="duplicate_action_server", after_goal=goal_count[0])
        if liar is not None:
            liar.serve()
        if args.tf_flood and now >= next_flood:
            # Another node's frames: names nobody asked for, enough to fill a listener's cap.
            for start in range(0, args.tf_flood, 500):
                tf_w.write(m.TFMessage([m.TransformStamped(
                    m.Header(stamp_now(), "world"), f"flood_{k}",
                    m.Transform(m.Vector3(0.0, 0.0, 0.0), m.Quaternion(0.0, 0.0, 0.0, 1.0)))
                    for k in range(start, min(start + 500, args.tf_flood))]))
            if not flooded:
                say(event="tf_flood", frames=args.tf_flood)
            flooded = True
            next_flood = now + 1.0
        if freedrive is not None and freedrive.serve(now) and arm.guide:
            # Freedrive ended mid-guide: the arm holds where it is.
            with arm.lock:
                k = arm.guide[0]
                arm.guide, arm.qd = None, np.zeros(dof)
                arm.view = arm.nearest_view(arm.q)
            say(event="guide_stopped", k=k)
        step(now)
        with arm.lock:
            q, qd, view, flange = arm.q.copy(), arm.qd.copy(), arm.view, arm.flange()
        if now >= next_js:
            js_w.write(m.JointState(m.Header(stamp_now(), "base_link"), joint_names, list(q), list(qd), []))
            next_js += 0.01
        if now >= next_tf and not args.no_tool0 and (flooded or not args.tf_flood):
            (t, rot) = flange
            # base_link -> tool0 = turn * T_base_flange
            tq = quat_mul(turn, rot)
            tt = (-t[0], -t[1], t[2])
            if args.jumping_flange is not None and goal_count[0] >= args.jumping_flange:
                with arm.lock:
                    standing = arm.goal is None and arm.guide is None
                if standing:
                    jumps += 1
                    if jumps % 2 == 0:
                        tt = (tt[0] + 0.005, tt[1], tt[2])
                    if jumps == 1:
                        say(event="jumping_flange", offset_m=0.005)
            if args.flange_off_model is not None and goal_count[0] >= args.flange_off_model:
                with arm.lock:
                    standing = arm.goal is None and arm.guide is None
                if standing:
                    tt = (tt[0] + 0.04, tt[1], tt[2])
                    off_model += 1
                    if off_model == 1:
                        say(event="flange_off_model", offset_m=0.04)
            tf_w.write(m.TFMessage([m.TransformStamped(
                m.Header(stamp_now(), "base_link"), "tool0",
                m.Transform(m.Vector3(*tt), m.Quaternion(*tq)))]))
            next_tf += 0.02
        elif now >= next_tf:
            next_tf += 0.02
        if tf2_w is not None and now >= next_tf2:
            next_tf2 += 0.005
            with arm.lock:
                standing = arm.goal is None and arm.guide is None
            if standing and goal_count[0] >= args.second_flange_publisher:
                # The driver's flange, then 10 cm along its z and turned 180 degrees about its x.
                t, rot = flange
                R = matrix_of((t, rot))[:3, :3]
                t2 = np.asarray(t) + R[:, 2] * 0.10
                rot2 = quat_mul(rot, (1.0, 0.0, 0.0, 0.0))
                tf2_w.write(m.TFMessage([m.TransformStamped(
                    m.Header(stamp_now(), "base_link"), "tool0",
                    m.Transform(m.Vector3(-t2[0], -t2[1], t2[2]), m.Quaternion(*quat_mul(turn, rot2))))]))
                second += 1
                if second == 1:
                    say(event="second_flange_publisher", offset_m=0.10, turn_deg=180.0)
        if view is None and now >= next_img:
            # No rendered view here (the start pose): a grey frame without a board.
            view = (None, np.full((ci["image_height"], ci["image_width"]), 128, np.uint8))
        if now >= next_img and view is not None and not huge_now():
            frame = view[1]
            h, w = frame.shape
            img_w.write(m.Image(m.Header(stamp_now(), "camera_optical_frame"), h, w, "mono8", 0, w,
                                cdr_bytes(frame)))
            next_img += 1.0 / args.image_hz
        if now >= next_info:
            info.header.stamp = stamp_now()
            info_w.write(info)
            next_info += 0.5
        time.sleep(0.002)
