"""An independent ROS 2 peer for handeye's live ROS 2 tests, on Eclipse Cyclone DDS (the
`cyclonedds` package from PyPI: no ROS installation). See scripts/ros2-peer.py."""
