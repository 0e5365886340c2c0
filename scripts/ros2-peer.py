#!/usr/bin/env python3
"""An independent ROS 2 peer for handeye, on Eclipse Cyclone DDS from PyPI (`pip install
cyclonedds numpy pyyaml`; no ROS installation). It speaks ROS 2's DDS naming (`rt/` topics,
`pkg::msg::dds_::Type_` types, `rq/…Request` / `rr/…Reply` for services and actions) with message
definitions of its own (ros2_peer/msgs.py), so it checks handeye's wire format from outside.

  ros2-peer.py [--domain N] [--loopback] tf-static [--timeout S] [--expect N] [--collect S]
      reads /tf_static as a late joiner (transient local) and prints the transforms as JSON
      (with --collect, every publisher's latched message heard within S seconds).
  ros2-peer.py [--domain N] [--loopback] camera-chain [--link L] [--optical O] [--offset X Y Z]
      publishes a camera driver's /tf_static chain, as a RealSense driver does:
      L -> <camera>_color_frame (offset X Y Z, turned 0.4 deg about z) -> O (the optical rotation).
  ros2-peer.py [--domain N] [--loopback] sim-cell SESSION_DIR ...
      serves a simulated arm and camera from a rendered sim session (see ros2_peer/sim_cell.py).
"""

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from ros2_peer import dds  # noqa: E402


def transform_json(t):
    tr, q = t.transform.translation, t.transform.rotation
    return {
        "parent": t.header.frame_id,
        "child": t.child_frame_id,
        "stamp": [t.header.stamp.sec, t.header.stamp.nanosec],
        "translation": [tr.x, tr.y, tr.z],
        "quaternion_xyzw": [q.x, q.y, q.z, q.w],
    }


def tf_static(args):
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from ros2_peer.msgs import TFMessage

    dp = dds.participant(args.domain, args.loopback)
    depth = 100 if args.collect is not None else 1
    reader = DataReader(dp, Topic(dp, "rt" + args.topic, TFMessage), qos=dds.qos_static(depth))
    if args.collect is not None:
        # Every publisher's latched message: each writer's last one, as tf2 keeps them.
        heard = []
        end = time.monotonic() + args.collect
        while time.monotonic() < end:
            for msg in reader.take(N=10):
                heard.extend(transform_json(t) for t in msg.transforms)
            time.sleep(0.02)
        print(json.dumps({"transforms": heard}), flush=True)
        return 0 if len(heard) >= args.expect else 3
    end = time.monotonic() + args.timeout
    while time.monotonic() < end:
        for msg in reader.take(N=10):
            if len(msg.transforms) < args.expect:
                continue
            out = [transform_json(t) for t in msg.transforms]
            print(json.dumps({"transforms": out}), flush=True)
            return 0
        time.sleep(0.02)
    print(f"no message with {args.expect} transforms on {args.topic} within {args.timeout} s", file=sys.stderr)
    return 3


def camera_chain(args):
    """A camera driver's static chain, latched until killed (or --duration)."""
    import math

    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic

    from ros2_peer import msgs as m

    dp = dds.participant(args.domain, args.loopback)
    writer = DataWriter(dp, Topic(dp, "rt/tf_static", m.TFMessage), qos=dds.qos_static())
    t = time.time()
    stamp = m.Time(int(t), int((t % 1) * 1e9))
    middle = args.link.rsplit("_link", 1)[0] + "_color_frame"
    half = math.radians(0.4) / 2
    x, y, z = args.offset
    chain = [
        (args.link, middle, (x, y, z), (0.0, 0.0, math.sin(half), math.cos(half))),
        # REP 103 body axes to the optical frame (z forward, x right, y down).
        (middle, args.optical, (0.0, 0.0, 0.0), (-0.5, 0.5, -0.5, 0.5)),
    ]
    writer.write(m.TFMessage([
        m.TransformStamped(m.Header(stamp, parent), child,
                           m.Transform(m.Vector3(*tr), m.Quaternion(*q)))
        for parent, child, tr, q in chain
    ]))
    print("published", flush=True)
    end = time.monotonic() + args.duration
    while time.monotonic() < end:
        time.sleep(0.05)
    return 0


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0))
    p.add_argument("--loopback", action="store_true", help="use 127.0.0.1 only, unicast discovery")
    sub = p.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("tf-static")
    t.add_argument("--topic", default="/tf_static")
    t.add_argument("--timeout", type=float, default=20.0)
    t.add_argument("--expect", type=int, default=1)
    t.add_argument("--collect", type=float, default=None)
    c = sub.add_parser("camera-chain")
    c.add_argument("--link", default="camera_link")
    c.add_argument("--optical", default="camera_color_optical_frame")
    c.add_argument("--offset", type=float, nargs=3, default=[0.0, 0.032, 0.0])
    c.add_argument("--duration", type=float, default=120.0)
    if "sim-cell" in sys.argv:
        from ros2_peer import sim_cell

        sim_cell.add_arguments(sub.add_parser("sim-cell"))
    args = p.parse_args()
    if args.cmd == "tf-static":
        return tf_static(args)
    if args.cmd == "camera-chain":
        return camera_chain(args)
    from ros2_peer import sim_cell

    return sim_cell.run(args)


if __name__ == "__main__":
    sys.exit(main())
