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
        ["console", "--config", config, "--out", str(session), "--addr", "127.0.0.1:0", "--wait"], work
    )
    try:
        page.goto(run.url())
        page.wait_for_selector("#manual:not(.hidden)", timeout=60000)
        # A live view arrives before any capture.
        page.wait_for_function("+document.getElementById('frame').dataset.count >= 1", timeout=60000)
        accepted = 0
        refused_close = False
        while accepted < captures:
            page.wait_for_function("document.getElementById('suggestion').textContent !== ''", timeout=60000)
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
