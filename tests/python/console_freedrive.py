"""Browser test of freedrive on a UR arm (ur_rtde against the mock controller, started by the
Rust test that runs this script): the page switches freedrive on, the test pushes the arm "by
hand" to the suggested view, the page captures there, switches freedrive off; the page asks for
confirmation before the real arm's first move to a suggestion. Talks to the Rust side over
stdin/stdout lines: prints `JOINTS <deg...>` and `FREEDRIVE_ON`, waits for `MOVED`; prints
`FREEDRIVE_OFF` at the end.

Usage: console_freedrive.py CONFIG WORKDIR   (HANDEYE_BIN names the binary)"""

import pathlib
import re
import sys

from console_common import Handeye, launch, sync_playwright

config, work = sys.argv[1], pathlib.Path(sys.argv[2])


def wait_log(page, before, pattern):
    page.wait_for_function(
        "([n, re]) => [...document.querySelectorAll('#log div')].slice(n).some(d => new RegExp(re).test(d.textContent))",
        arg=[before, pattern],
        timeout=60000,
    )
    texts = page.eval_on_selector_all("#log div", "ds => ds.map(d => d.textContent)")[before:]
    return next(t for t in texts if re.search(pattern, t))


def logs(page):
    return page.evaluate("document.querySelectorAll('#log div').length")


with sync_playwright() as p:
    browser = launch(p)
    page = browser.new_page()
    run = Handeye(["console", "--config", config, "--output", str(work / "fd"), "--addr", "127.0.0.1:0"], work)
    try:
        page.goto(run.url())
        page.wait_for_selector("#manual:not(.hidden)", timeout=60000)
        assert "REAL ARM" in page.text_content("#cell")
        page.wait_for_function("document.getElementById('suggestion').textContent !== ''", timeout=60000)
        joints = re.search(r"joints \[([^\]]+)\]", page.text_content("#suggestion")).group(1)
        n = logs(page)
        page.click("#freedrive-on")
        text = wait_log(page, n, "freedrive")
        assert text == "freedrive on", text
        print("JOINTS " + " ".join(j.strip() for j in joints.split(",")), flush=True)
        print("FREEDRIVE_ON", flush=True)
        assert sys.stdin.readline().strip() == "MOVED"
        n = logs(page)
        page.click("#capture")
        text = wait_log(page, n, r"accepted|refused|too close|blurred")
        assert "accepted" in text, text
        page.wait_for_function("document.getElementById('arm').dataset.freedrive === 'true'", timeout=30000)
        n = logs(page)
        page.click("#freedrive-off")
        text = wait_log(page, n, "freedrive off")
        assert text == "freedrive off", text
        print("FREEDRIVE_OFF", flush=True)
        # The first move of the real arm to a suggestion waits for the page's confirmation.
        page.wait_for_function("document.getElementById('suggestion').textContent !== ''", timeout=60000)
        page.click("#goto")
        page.wait_for_selector("#confirm.open", timeout=30000)
        n = logs(page)
        page.click("#confirm-yes")
        wait_log(page, n, "at the suggested view")
        page.click("#stop")
        code = run.wait(120)
        assert code != 0 and "interrupted" in run.output(), run.output()
    finally:
        run.kill()
    browser.close()
print("console_freedrive: ok", flush=True)
