"""Browser test of `handeye run --console` on the simulated cell: the page shows frames and pose
states as they change; STOP on the page stops the arm part-way with every sample kept; a resume
with the console open completes the plan and the page shows the verdict.

Usage: console_run.py CONFIG WORKDIR [SCREENSHOT_DIR]   (HANDEYE_BIN names the binary)"""

import os
import pathlib
import sys
from urllib.parse import urljoin

from console_common import Handeye, js_count, launch, sync_playwright

config, work = sys.argv[1], pathlib.Path(sys.argv[2])
shots = pathlib.Path(sys.argv[3]) if len(sys.argv) > 3 else None
session = work / "session"
POSES = 10

with sync_playwright() as p:
    browser = launch(p)
    page = browser.new_page(viewport={"width": 1280, "height": 860})
    # Every request the page makes is answered (no favicon 404 on each load).
    failed_requests = []
    page.on("response", lambda r: failed_requests.append(f"{r.status} {r.url}") if r.status >= 400 else None)

    run = Handeye(["run", "--config", config, "--output", str(session), "--console", "127.0.0.1:0"], work)
    try:
        page.goto(run.url())
        # Before the first frame: a note, not a broken-image icon.
        if page.get_attribute("#frame", "src") is None:
            assert page.is_visible("#no-frame") and not page.is_visible("#frame")
        # The plan table fills, then pose states change and frames arrive while the arm moves.
        page.wait_for_function(js_count("#plan tr") + f" == {POSES}", timeout=60000)
        page.wait_for_function("document.querySelector('#plan tr[data-state=moving]') !== null", timeout=60000)
        page.wait_for_function(js_count("#plan tr[data-state=captured]") + " >= 2", timeout=120000)
        page.wait_for_function("+document.getElementById('frame').dataset.count >= 2", timeout=60000)
        frames_before = int(page.get_attribute("#frame", "data-count"))
        page.wait_for_function(
            f"+document.getElementById('frame').dataset.count > {frames_before}", timeout=60000
        )
        page.wait_for_function("document.getElementById('estimate').dataset.samples >= 3", timeout=120000)
        if shots:
            page.screenshot(path=str(shots / "console-run.png"))
        page.click("#stop")
        code = run.wait()
        out = run.output()
        assert code != 0, "a stopped run must not exit 0:\n" + out
        assert "interrupted at plan pose" in out and "resume with" in out, out
        # The page says so too.
        page.wait_for_function("document.getElementById('verdict').textContent === 'stopped'", timeout=10000)
    finally:
        run.kill()

    records = sorted((session / "poses").glob("*.yaml"))
    assert 2 <= len(records) < POSES, f"stopped part-way: {len(records)} of {POSES} poses recorded"
    kept = {r.name for r in records}

    resume = Handeye(
        ["run", "--resume", str(session), "--console", "127.0.0.1:0", "--wait"], work
    )
    try:
        url = resume.url()
        page.goto(url)
        page.wait_for_function(
            "['GOOD','CHECK','REDO'].includes(document.getElementById('verdict').textContent)",
            timeout=180000,
        )
        verdict = page.text_content("#verdict")
        assert verdict == "GOOD", f"verdict {verdict}:\n" + resume.output()
        # The run is over: the page says so, and nothing is "pending" or "live" any more.
        assert page.text_content("#conn") == "run ended", page.text_content("#conn")
        assert "pending" not in page.text_content("#progress"), page.text_content("#progress")
        assert not page.is_visible("#no-frame")
        # Every pose captured: those kept from before the stop and those taken now.
        assert page.evaluate(js_count("#plan tr[data-state=captured]")) == POSES
        assert page.is_visible("#report")
        # The page's own report link carries the console's secret; without it the report is
        # refused.
        report = page.request.get(urljoin(url, page.get_attribute("#report", "href")))
        assert report.ok and "<html" in report.text().lower()
        assert page.request.get(urljoin(url, "/report")).status == 401
        if shots:
            page.screenshot(path=str(shots / "console-verdict.png"))
        resume.enter()
        assert resume.wait() == 0, resume.output()
    finally:
        resume.kill()
    assert kept <= {r.name for r in (session / "poses").glob("*.yaml")}
    assert len(list((session / "poses").glob("*.yaml"))) == POSES
    assert not failed_requests, failed_requests
    browser.close()
print("console_run: ok")
