#!/usr/bin/env python3
"""Packs frames and TF written by tests/it/bag_import.rs into a ROS 2 bag with `rosbags`.

The writer is the pure-Python `rosbags` package (not our code), so the import is tested on bags
an independent implementation serialised. Usage:

    make_bag.py SPEC.json OUT_BAG_FOLDER

SPEC.json (paths relative to it):
    storage: "mcap" | "sqlite3"
    image_topic, camera_info_topic (or null), frame_id
    image_kind: "mono8" (raw bytes, width*height) | "png" | "jpeg" (encoded file bytes)
    width, height
    camera_info: {k: [9], d: [..], distortion_model} or null
    tf: [[stamp_ns, parent, child, tx, ty, tz, qx, qy, qz, qw], ...]   (one TFMessage per stamp)
    tf_static: [[...same...]]   (one TFMessage at the start)
    images: [[stamp_ns, file], ...]   (a third element: its receive time, ns)
    image_format (optional): the CompressedImage format label, instead of image_kind
    is_bigendian, extra_bytes (optional, mono8): the flag written, zero bytes added past the
        last row (a header that lies about its data)

A TF row may end with an 11th element, its receive time (ns): rows are then grouped into
messages by receive time instead (a /tf_static row received later is a second message). A stamp
may be [sec, nanosec] instead of ns, written as is (a broken writer's nanosec >= 1e9). An image
file `random:N` is N bytes from os.urandom (mono8 only; for big, incompressible bags).
"""

import json
import os
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore


def main() -> None:
    spec_path = Path(sys.argv[1])
    out = Path(sys.argv[2])
    spec = json.loads(spec_path.read_text())
    base = spec_path.parent
    ts = get_typestore(Stores.ROS2_HUMBLE)
    Time = ts.types['builtin_interfaces/msg/Time']
    Header = ts.types['std_msgs/msg/Header']
    TransformStamped = ts.types['geometry_msgs/msg/TransformStamped']
    Transform = ts.types['geometry_msgs/msg/Transform']
    Vector3 = ts.types['geometry_msgs/msg/Vector3']
    Quaternion = ts.types['geometry_msgs/msg/Quaternion']
    TFMessage = ts.types['tf2_msgs/msg/TFMessage']
    Image = ts.types['sensor_msgs/msg/Image']
    CompressedImage = ts.types['sensor_msgs/msg/CompressedImage']
    CameraInfo = ts.types['sensor_msgs/msg/CameraInfo']
    RegionOfInterest = ts.types['sensor_msgs/msg/RegionOfInterest']

    def ns(stamp) -> int:
        if isinstance(stamp, list):
            return int(stamp[0]) * 1_000_000_000 + int(stamp[1])
        return int(stamp)

    def header(stamp, frame: str):
        if isinstance(stamp, list):
            sec, nanosec = int(stamp[0]), int(stamp[1])
        else:
            sec, nanosec = int(stamp) // 1_000_000_000, int(stamp) % 1_000_000_000
        return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame)

    def transform(row):
        stamp, parent, child, tx, ty, tz, qx, qy, qz, qw = row[:10]
        return TransformStamped(
            header=header(stamp, parent), child_frame_id=child,
            transform=Transform(translation=Vector3(x=tx, y=ty, z=tz),
                                rotation=Quaternion(x=qx, y=qy, z=qz, w=qw)))

    plugin = StoragePlugin.MCAP if spec['storage'] == 'mcap' else StoragePlugin.SQLITE3
    kind = spec['image_kind']
    width, height = spec['width'], spec['height']
    cache: dict[str, bytes] = {}
    events = []  # (receive time, order, connection key, message builder)
    by_receive: dict[int, list] = {}
    for row in spec['tf']:
        receive = int(row[10]) if len(row) > 10 else ns(row[0])
        by_receive.setdefault(receive, []).append(row)
    for receive, rows in by_receive.items():
        events.append((receive, 1, 'tf', rows))
    for row in spec['images']:
        stamp, name = row[:2]
        # The recorder receives a frame a little after its stamp (or when a third element says).
        receive = int(row[2]) if len(row) > 2 else ns(stamp) + 1_000_000
        events.append((receive, 2, 'image', (stamp, name)))
    if spec.get('camera_info') is not None:
        first = min(ns(row[0]) for row in spec['images'])
        events.append((first, 0, 'info', first))
    events.sort(key=lambda e: (e[0], e[1]))
    static_messages: dict[int, list] = {}
    for row in spec['tf_static']:
        receive = int(row[10]) if len(row) > 10 else -1
        static_messages.setdefault(receive, []).append(row)

    with Writer(out, version=9, storage_plugin=plugin) as writer:
        tf_conn = writer.add_connection('/tf', TFMessage.__msgtype__, typestore=ts)
        static_conn = writer.add_connection('/tf_static', TFMessage.__msgtype__, typestore=ts)
        image_type = Image if kind == 'mono8' else CompressedImage
        image_conn = writer.add_connection(spec['image_topic'], image_type.__msgtype__, typestore=ts)
        info_conn = None
        if spec.get('camera_info') is not None:
            info_conn = writer.add_connection(spec['camera_info_topic'], CameraInfo.__msgtype__,
                                              typestore=ts)
        start = events[0][0] if events else 0
        for receive, rows in sorted(static_messages.items()):
            msg = TFMessage(transforms=[transform(r) for r in rows])
            writer.write(static_conn, start if receive < 0 else receive,
                         ts.serialize_cdr(msg, TFMessage.__msgtype__))
        for receive, _, key, payload in events:
            if key == 'tf':
                msg = TFMessage(transforms=[transform(r) for r in payload])
                writer.write(tf_conn, receive, ts.serialize_cdr(msg, TFMessage.__msgtype__))
            elif key == 'info':
                ci = spec['camera_info']
                msg = CameraInfo(
                    header=header(payload, spec['frame_id']), height=height, width=width,
                    distortion_model=ci['distortion_model'],
                    d=np.array(ci['d'], dtype=np.float64), k=np.array(ci['k'], dtype=np.float64),
                    r=np.eye(3).flatten(),
                    p=np.array([ci['k'][0], 0, ci['k'][2], 0, 0, ci['k'][4], ci['k'][5], 0, 0, 0, 1, 0],
                               dtype=np.float64),
                    binning_x=0, binning_y=0,
                    roi=RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
                writer.write(info_conn, receive, ts.serialize_cdr(msg, CameraInfo.__msgtype__))
            else:
                stamp, name = payload
                if name.startswith('random:'):
                    data = np.frombuffer(os.urandom(int(name[7:])), dtype=np.uint8)
                else:
                    if name not in cache:
                        cache[name] = (base / name).read_bytes()
                    data = np.frombuffer(cache[name], dtype=np.uint8)
                if kind == 'mono8':
                    if spec.get('extra_bytes'):
                        data = np.concatenate([data, np.zeros(spec['extra_bytes'], np.uint8)])
                    msg = Image(header=header(stamp, spec['frame_id']), height=height, width=width,
                                encoding='mono8', is_bigendian=spec.get('is_bigendian', 0),
                                step=width, data=data)
                else:
                    msg = CompressedImage(header=header(stamp, spec['frame_id']),
                                          format=spec.get('image_format', kind), data=data)
                writer.write(image_conn, receive, ts.serialize_cdr(msg, image_type.__msgtype__))


if __name__ == '__main__':
    main()
