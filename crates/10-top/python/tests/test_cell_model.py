"""Issue #38 through Python: `Session.solve` with a config whose lens file is wrong (fx and fy 6 %
long; the session's frames were rendered through the true lens) gives a verdict that names that
file and the parameter, with the estimate near the true focal length; never GOOD. The same
session solved with the right file is GOOD."""

import re

import handeye

from conftest import REPO


def config_with_lens(tmp_path, lens):
    """configs/sim-cell.yaml with its board by absolute path and `intrinsics: lens`."""
    text = (REPO / "configs" / "sim-cell.yaml").read_text()
    text = text.replace("target: targets/", f"target: {REPO / 'configs' / 'targets'}/")
    text = text.replace("intrinsics: cameras/sim-1280x720.yaml", f"intrinsics: {lens}")
    path = tmp_path / f"cell-{lens.stem}.yaml"
    path.write_text(text)
    return path


def test_a_wrong_lens_file_is_named_by_the_session_solve(sim_session, tmp_path):
    true_lens = REPO / "configs" / "cameras" / "sim-1280x720.yaml"
    text = true_lens.read_text()
    row = re.search(r"data: \[([0-9.]+), 0\.0, ([0-9.]+), 0\.0, ([0-9.]+),", text)
    fx, fy = float(row.group(1)), float(row.group(3))
    wrong_text = text.replace(
        row.group(0),
        f"data: [{fx * 1.06}, 0.0, {row.group(2)}, 0.0, {fy * 1.06},",
    )
    wrong = tmp_path / "wrong-camera-info.yaml"
    wrong.write_text(wrong_text)

    session = handeye.Session(sim_session)
    right = session.solve(config=config_with_lens(tmp_path, true_lens)).verdict
    assert right.level == "GOOD", str(right)

    verdict = session.solve(config=config_with_lens(tmp_path, wrong)).verdict
    assert verdict.level != "GOOD", str(verdict)
    assert str(wrong) in verdict.reason, verdict.reason
    assert f"fx in the file {fx * 1.06:.1f} px" in verdict.reason, verdict.reason
    model = verdict.figures["cell_model"]
    assert model["chosen"] == "intrinsics", model
    estimate = next(e for e in model["estimates"] if e["parameter"] == "fx")
    assert abs(estimate["file_value"] / fx - 1.06) < 1e-9, estimate
    assert abs(estimate["estimate"] / fx - 1.0) < 0.005, estimate
