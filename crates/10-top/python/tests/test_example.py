"""The runnable example (examples/calibrate_sim_cell.py) runs and finds the simulator's truth."""

import re
import subprocess
import sys
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "calibrate_sim_cell.py"


def errors_in(output):
    found = re.findall(r"error ([0-9.]+) mm, ([0-9.]+)° against the simulator's ground truth", output)
    assert len(found) == 2, output
    return [(float(mm), float(deg)) for mm, deg in found]


def test_the_example_calibrates_the_recorded_samples():
    run = subprocess.run([sys.executable, str(EXAMPLE)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "verdict: " in run.stdout
    for mm, deg in errors_in(run.stdout):
        assert mm < 0.5 and deg < 0.05, run.stdout


def test_the_example_on_a_session_folder(sim_session):
    run = subprocess.run([sys.executable, str(EXAMPLE), str(sim_session)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    for mm, deg in errors_in(run.stdout):
        assert mm < 0.5 and deg < 0.05, run.stdout
    assert "reprojection space:" in run.stdout
