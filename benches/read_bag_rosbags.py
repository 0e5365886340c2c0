#!/usr/bin/env python3
"""Reads every message of a ROS 2 bag with the pure-Python `rosbags` package and deserialises it:
the Python reader `benches/bag.rs` compares `handeye import bag`'s CPU time and memory with.

    read_bag_rosbags.py BAG_FOLDER
"""

import sys
from pathlib import Path

from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore


def main() -> None:
    store = get_typestore(Stores.ROS2_HUMBLE)
    count = 0
    with Reader(Path(sys.argv[1])) as reader:
        for connection, _, raw in reader.messages():
            store.deserialize_cdr(raw, connection.msgtype)
            count += 1
    print(f"rosbags: {count} messages deserialised")


if __name__ == "__main__":
    main()
