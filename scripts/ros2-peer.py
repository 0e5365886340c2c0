#!/usr/bin/env python3
"""An independent ROS 2 peer for handeye, on Eclipse Cyclone DDS from PyPI (`pip install
cyclonedds numpy pyyaml`; no ROS installation). It speaks ROS 2's DDS naming (`rt/` topics,
`pkg::msg::dds_::Type_` types, `rq/…Request` / `rr/…Reply` for services and actions) with message
definitions of its own (ros2_peer/msgs.py), so it checks handeye's wire format from outside.

  ros2-peer.py [--domain N] [--loopback] tf-static [--timeout S] [--expect N]
      reads /tf_static as a late joiner (transient local) and prints the transforms as JSON.
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


def tf_static(args):
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from ros2_peer.msgs import TFMessage

    dp = dds.participant(args.domain, args.loopback)
    reader = DataReader(dp, Topic(dp, "rt" + args.topic, TFMessage), qos=dds.qos_static())
    end = time.monotonic() + args.timeout
    while time.monotonic() < end:
        for msg in reader.take(N=10):
            if len(msg.transforms) < args.expect:
                continue
            out = []
            for t in msg.transforms:
                tr, q = t.transform.translation, t.transform.rotation
                out.append({
                    "parent": t.header.frame_id,
                    "child": t.child_frame_id,
                    "stamp": [t.header.stamp.sec, t.header.stamp.nanosec],
                    "translation": [tr.x, tr.y, tr.z],
                    "quaternion_xyzw": [q.x, q.y, q.z, q.w],
                })
            print(json.dumps({"transforms": out}), flush=True)
            return 0
        time.sleep(0.02)
    print(f"no message with {args.expect} transforms on {args.topic} within {args.timeout} s", file=sys.stderr)
    return 3


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0))
    p.add_argument("--loopback", action="store_true", help="use 127.0.0.1 only, unicast discovery")
    sub = p.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("tf-static")
    t.add_argument("--topic", default="/tf_static")
    t.add_argument("--timeout", type=float, default=20.0)
    t.add_argument("--expect", type=int, default=1)
    if "sim-cell" in sys.argv:
        from ros2_peer import sim_cell

        sim_cell.add_arguments(sub.add_parser("sim-cell"))
    args = p.parse_args()
    if args.cmd == "tf-static":
        return tf_static(args)
    from ros2_peer import sim_cell

    return sim_cell.run(args)


if __name__ == "__main__":
    sys.exit(main())
