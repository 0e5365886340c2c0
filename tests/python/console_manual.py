"""Browser test of `handeye console` (hand-guided capture) on the simulated cell, driven only
from the page: go to the suggested view, capture, repeat; a second capture at the same place is
refused as too close; finish; the verdict is GOOD.

Usage: console_manual.py CONFIG WORKDIR CAPTURES [SCREENSHOT_DIR]   (HANDEYE_BIN names the binary)"""

import pathlib
import sys

from console_common import Handeye, js_count, launch, sync_playwright

config, work, captures = sys.argv[1], pathlib.Path(sys.argv[2]), int(sys.argv[3])
shots = pathlib.Path(sys.argv[4]) if len(sys.argv) > 4 else None
session = work / "manual"


def log_count(page):
    return page.evaluate(js_count("#log div"))


def wait_log(page, before, pattern):
    """Waits for a message after the first `before` ones matching `pattern`; returns its text."""
    page.wait_for_function(
        "([n, re]) => [...document.querySelectorAll('#log div')].slice(n).some(d => new RegExp(re).test(d.textContent))",
        arg=[before, pattern],
        timeout=60000,
    )
    texts = page.eval_on_selector_all("#log div", "ds => ds.map(d => d.textContent)")[before:]
    return next(t for t in texts if __import__("re").search(pattern, t))


with sync_playwright() as p:
    browser = launch(p)
    page = browser.new_page(viewport={"width": 1280, "height": 860})
    run = Handeye(
        ["console", "--config", config, "--output", str(session), "--addr", "127.0.0.1:0", "--wait"], work
    )
    try:
        page.goto(run.url())
        page.wait_for_selector("#manual:not(.hidden)", timeout=60000)
        # A live view arrives before any capture.
        page.wait_for_function("+document.getElementById('frame').dataset.count >= 1", timeout=60000)
        accepted = 0
        refused_close = False
        axis_seen = False
        while accepted < captures:
            page.wait_for_function("document.getElementById('suggestion').textContent !== ''", timeout=60000)
            if accepted >= 1 and not axis_seen:
                # After a capture the suggestion's rotation axis is a target on the sphere view:
                # an orange ring drawn on the canvas where the axis lands.
                page.wait_for_function("document.getElementById('axes').dataset.target !== ''", timeout=60000)
                x, y = map(float, page.eval_on_selector("#axes", "c => c.dataset.target").split(","))
                assert 0 <= x <= 150 and 0 <= y <= 150, (x, y)
                orange = page.evaluate(
                    """([x, y]) => { const d = document.getElementById('axes').getContext('2d')
                         .getImageData(Math.round(x) - 10, Math.round(y) - 10, 21, 21).data;
                       let n = 0; for (let i = 0; i < d.length; i += 4)
                         if (d[i] > 150 && d[i + 1] > 100 && d[i + 1] < 190 && d[i + 2] < 90) n++;
                       return n; }""",
                    [x, y],
                )
                assert orange >= 10, f"no target drawn at the suggested axis ({x}, {y}): {orange} orange pixels"
                axis_seen = True
            n = log_count(page)
            page.click("#goto")
            wait_log(page, n, "at the suggested view|not sent|no suggestion")
            n = log_count(page)
            page.click("#capture")
            text = wait_log(page, n, r"accepted|refused|too close|blurred")
            if "accepted" in text:
                accepted += 1
                if not refused_close:
                    # The same place again adds nothing: refused at once.
                    n = log_count(page)
                    page.click("#capture")
                    assert "too close" in wait_log(page, n, r"accepted|refused|too close|blurred")
                    refused_close = True
        assert axis_seen or captures < 2
        assert page.evaluate(js_count("#plan tr[data-state=captured]")) == captures
        page.wait_for_function("document.getElementById('estimate').dataset.samples >= 3", timeout=60000)
        if shots:
            page.screenshot(path=str(shots / "console-manual.png"))
        page.click("#finish")
        page.wait_for_function(
            "['GOOD','CHECK','REDO'].includes(document.getElementById('verdict').textContent)",
            timeout=180000,
        )
        verdict = page.text_content("#verdict")
        assert verdict == "GOOD", f"verdict {verdict}:\n" + run.output()
        run.enter()
        assert run.wait() == 0, run.output()
    finally:
        run.kill()
    assert len(list((session / "poses").glob("*.yaml"))) >= captures
    assert (session / "result.yaml").is_file()
    browser.close()
print("console_manual: ok")
