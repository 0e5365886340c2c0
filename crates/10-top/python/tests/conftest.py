"""Shared fixtures of the Python tests: the `handeye` binary (for the CLI comparisons), a
recorded session of the simulated cell, and seeded synthetic pose pairs.

A test that needs a tool that is missing (the `handeye` binary, OpenCV, PyYAML) skips with the
reason; with HANDEYE_REQUIRE_TOOLS=1 (scripts/test.sh sets it) the skip is a failure instead,
as in the Rust tests (tests/util/mod.rs `skip`).
"""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))

REPO = Path(__file__).resolve().parents[4]


def need(why):
    """Skips the test (fails it under HANDEYE_REQUIRE_TOOLS=1)."""
    if os.environ.get("HANDEYE_REQUIRE_TOOLS"):
        pytest.fail(f"HANDEYE_REQUIRE_TOOLS is set but the test would skip: {why}")
    pytest.skip(why)


def handeye_binary():
    """The `handeye` CLI cargo built: $HANDEYE_BIN, else the target dir's debug/release build."""
    if os.environ.get("HANDEYE_BIN"):
        return Path(os.environ["HANDEYE_BIN"])
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    for profile in ("debug", "release"):
        candidate = target / profile / "handeye"
        if candidate.is_file():
            return candidate
    found = shutil.which("handeye")
    return Path(found) if found else None


@pytest.fixture(scope="session")
def cli():
    binary = handeye_binary()
    if binary is None or not binary.is_file():
        need("no `handeye` binary (build it with cargo, or set HANDEYE_BIN)")

    def run(*args, check=True):
        result = subprocess.run(
            [str(binary), *map(str, args)], capture_output=True, text=True, cwd=REPO
        )
        if check and result.returncode != 0:
            raise AssertionError(f"handeye {' '.join(map(str, args))} failed:\n{result.stderr}")
        return result

    return run


@pytest.fixture(scope="session")
def sim_session(cli, tmp_path_factory):
    """A session of the simulated cell (configs/sim-cell.yaml) recorded by `handeye run`."""
    out = tmp_path_factory.mktemp("sim") / "session"
    cli("run", "--config", REPO / "configs" / "sim-cell.yaml", "--out", out, "--yes")
    return out


@pytest.fixture(scope="session")
def sim_session_eye_to_hand(cli, tmp_path_factory):
    """A session of the simulated eye-to-hand cell (configs/sim-cell-eye-to-hand.yaml)."""
    out = tmp_path_factory.mktemp("sim-eth") / "session"
    cli("run", "--config", REPO / "configs" / "sim-cell-eye-to-hand.yaml", "--out", out, "--yes")
    return out


@pytest.fixture(scope="session")
def yaml():
    try:
        import yaml as pyyaml
    except ImportError:
        need("PyYAML is not installed (pip install pyyaml)")
    return pyyaml


@pytest.fixture(scope="session")
def cv2():
    """OpenCV, the independent reference (skipped with the reason when it is not installed)."""
    try:
        import cv2 as opencv
    except ImportError:
        need("OpenCV is not installed (pip install opencv-python-headless)")
    return opencv


def opencv_inputs(flange, camera):
    """4x4 T_base_flange and T_camera_target lists as cv2.calibrateHandEye takes them."""
    return (
        [T[:3, :3] for T in flange],
        [T[:3, 3:4] for T in flange],
        [T[:3, :3] for T in camera],
        [T[:3, 3:4] for T in camera],
    )


def as_matrix(R, t):
    """A 4x4 transform from a 3x3 rotation and a translation of any shape."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.ravel(t)
    return T
