#!/usr/bin/env bash
# Runs every test, after installing what a fresh machine lacks: a C/C++ toolchain, ur_rtde 1.6.5
# built from source into a cached prefix (for the `ur-rtde` driver and its tests against the mock
# controller), and the ur_rtde Python wheel (the independent client the mock is tested with).
# Safe to run again: every step skips work already done. Runs as any user: Debian packages go
# through scripts/apt-install.sh (root, or sudo without a password), Python packages into the
# user's site (or the active venv) when not root.
#
#   scripts/test.sh            every test (what CI runs)
#   scripts/test.sh --quick    a check of a build in a few minutes: installs nothing, runs the unit
#                              tests of every crate and the integration tests of the solver,
#                              configs, files in and out and the simulated cell; a test whose
#                              tool is missing says so and skips
#   scripts/test.sh ARGS...    extra arguments go to `cargo test`
set -euo pipefail
cd "$(dirname "$0")/.."

if [ "${1:-}" = "--quick" ]; then
  shift
  cargo test --workspace --lib --bins -q "$@"
  # The integration areas that need no browser, arm library or Python packages.
  cargo test --test it -q "$@" -- cli_names:: cli_run:: closed_forms:: config:: dataset:: \
    driver:: formats:: friction:: layers:: plausibility:: cameras:: solve:: verdict::
  exit 0
fi

need_apt=()
command -v cc >/dev/null || need_apt+=(build-essential)
command -v pkg-config >/dev/null || need_apt+=(pkg-config)
# Headless Chromium for the report's real-browser test (tests/it/report.rs).
command -v chromium >/dev/null || need_apt+=(chromium)
# Poppler's pdftoppm renders the printable board PDF so the detector can read it back
# (tests/it/cellkit.rs): an independent PDF reader, not ours.
command -v pdftoppm >/dev/null || need_apt+=(poppler-utils)
# Fast DDS, the other ROS 2 middleware (tests/it/ros2_live/fastdds.rs): its C++ peer is generated
# by fastddsgen and linked with Debian's Fast DDS (scripts/fastdds_peer).
command -v fastddsgen >/dev/null || need_apt+=(fastddsgen)
[ -e /usr/include/fastdds/dds/domain/DomainParticipant.hpp ] || need_apt+=(libfastrtps-dev)
[ -e /usr/include/fastcdr/Cdr.h ] || need_apt+=(libfastcdr-dev)
if [ ${#need_apt[@]} -gt 0 ]; then
  bash scripts/apt-install.sh "${need_apt[@]}"
fi

export UR_RTDE_PREFIX="${UR_RTDE_PREFIX:-/opt/ur_rtde-1.6.5}"
bash scripts/install-ur-rtde.sh

# pip into the user's site when not root and not in a venv (never into the system's Python).
pip_install() {
  if [ "$(id -u)" -ne 0 ] && [ -z "${VIRTUAL_ENV:-}" ]; then
    python3 -m pip install -q --user "$@"
  else
    python3 -m pip install -q "$@"
  fi
}

if ! python3 -c "import rtde_control, rtde_receive" 2>/dev/null; then
  pip_install ur_rtde==1.6.5 || pip_install ur_rtde==1.6.5
fi

# numpy + OpenCV for tests/it/boards.rs and tests/it/kalibr_print.rs (tests/python/*.py render
# ChArUco/chessboard/Kalibr-aprilgrid frames independently of us and compute OpenCV's figures).
# The test falls back to a venv of its own when this install is refused (PEP 668).
python3 -c "import cv2, numpy" 2>/dev/null || pip_install numpy "opencv-python-headless<5" || true
# scipy for tests/it/kinematics/reference.rs (tests/python/kinematics_reference.py fits the arm's
# joint offsets with scipy's least_squares, the independent reference of ours); where the user
# install is refused (PEP 668), into the venv the test looks for.
if ! python3 -c "import numpy, scipy.optimize" 2>/dev/null && ! pip_install numpy scipy; then
  scipy_venv="${CARGO_TARGET_DIR:-target}/tmp/scipy-venv"
  "$scipy_venv/bin/python" -c "import numpy, scipy.optimize" 2>/dev/null \
    || { python3 -m venv "$scipy_venv" && "$scipy_venv/bin/pip" install -q numpy scipy; }
fi
# Playwright drives the Debian chromium above in tests/it/console.rs (no browser download).
python3 -c "import playwright.sync_api" 2>/dev/null || pip_install playwright
# ROS 2 bag import (tests/it/bag_import.rs): bags are written by the pure-Python `rosbags` package,
# installed into the venv the test looks for (it creates the same venv itself when missing).
bag_venv="${CARGO_TARGET_DIR:-target}/tmp/bag-venv"
if ! "$bag_venv/bin/python" -c "import rosbags, numpy" 2>/dev/null; then
  python3 -m venv "$bag_venv" && "$bag_venv/bin/pip" install -q rosbags numpy
fi

# Live ROS 2 (tests/it/ros2_live): the independent peer is Eclipse Cyclone DDS's Python binding
# (no ROS installation), in the venv the tests look for (they create the same venv when missing).
ros2_venv="${CARGO_TARGET_DIR:-target}/tmp/ros2-venv"
if ! "$ros2_venv/bin/python" -c "import cyclonedds, numpy, yaml, PIL" 2>/dev/null; then
  python3 -m venv "$ros2_venv" && "$ros2_venv/bin/pip" install -q cyclonedds numpy pyyaml pillow
fi

# Everything the comparison tests need is installed above: a test that would skip for a missing
# tool (python3, chromium) fails instead (tests/util/mod.rs `skip`).
export HANDEYE_REQUIRE_TOOLS=1
cargo test --workspace --features handeye/ur-rtde,handeye/ros2 "$@"
# The live tests that flood loopback DDS with 12 MB and 100 MB frames starve the peers of the live
# tests beside them on a 2-core machine (#[ignore] says so): here they run alone, one at a time.
cargo test --features handeye/ros2 --test it "$@" -- --ignored --test-threads=1 ros2_live::oversized::

# The Python package (crates/10-top/python, docs/python.md): its abi3 wheel built by maturin in the same
# target dir (the dev profile, whose dependencies the build above already compiled), installed into
# a venv of its own (which sees the numpy and OpenCV installed above), and its pytest suite, which
# compares with the `handeye` binary cargo test just built and with OpenCV.
target_dir="${CARGO_TARGET_DIR:-target}"
py_venv="$target_dir/tmp/py-venv"
if ! { [ -x "$py_venv/bin/maturin" ] && "$py_venv/bin/python" -c "import pytest, yaml" 2>/dev/null; }; then
  python3 -m venv --system-site-packages "$py_venv"
  "$py_venv/bin/pip" install -q maturin pytest pyyaml
fi
"$py_venv/bin/python" -c "import numpy, cv2" 2>/dev/null \
  || "$py_venv/bin/pip" install -q numpy "opencv-python-headless<5"
rm -rf "$target_dir/wheels"
"$py_venv/bin/maturin" build -m crates/10-top/python/Cargo.toml -o "$target_dir/wheels"
"$py_venv/bin/pip" install -q --force-reinstall --no-deps "$target_dir"/wheels/handeye-*.whl
HANDEYE_BIN="$target_dir/debug/handeye" "$py_venv/bin/python" -m pytest crates/10-top/python/tests -q -rs
