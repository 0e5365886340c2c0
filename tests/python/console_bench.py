"""Measures what the console costs a run (not a test: prints figures for docs/console.md).

1. Wall time of a 20-pose simulated `handeye run`, alternating without the console and with the
   console open in headless Chromium, ROUNDS times each; prints each time and the medians.
2. Memory over a long run with the console and a page connected: the process's RSS sampled
   against the number of poses recorded.

Usage: console_bench.py CONFIG20 CONFIGLONG WORKDIR [ROUNDS]   (HANDEYE_BIN names the binary)"""

import pathlib
import resource
import shutil
import statistics
import sys
import time

from console_common import Handeye, launch, sync_playwright

config20, config_long, work = sys.argv[1], sys.argv[2], pathlib.Path(sys.argv[3])
rounds = int(sys.argv[4]) if len(sys.argv) > 4 else 3


def rss_kib(pid):
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def timed(args, page=None):
    """Wall time and CPU time (user + system, of handeye alone) of one run."""
    out = work / "s"
    shutil.rmtree(out, ignore_errors=True)
    c0 = cpu()
    t0 = time.monotonic()
    run = Handeye(["run", "--config", config20, "--output", str(out), *args], work)
    if page is not None:
        page.goto(run.url())
    code = run.wait(timeout=600)
    assert code == 0, run.output()
    return time.monotonic() - t0, cpu() - c0


with sync_playwright() as p:
    browser = launch(p)
    page = browser.new_page()
    plain, console = [], []
    for r in range(rounds):
        plain.append(timed([]))
        console.append(timed(["--console", "127.0.0.1:0"], page))
        print(
            f"round {r}: without {plain[-1][0]:.2f} s (cpu {plain[-1][1]:.2f} s), "
            f"with console + page {console[-1][0]:.2f} s (cpu {console[-1][1]:.2f} s)",
            flush=True,
        )
    for i, what in [(0, "wall"), (1, "cpu")]:
        a = statistics.median(x[i] for x in plain)
        b = statistics.median(x[i] for x in console)
        print(f"median {what}: without {a:.2f} s, with {b:.2f} s: {100 * (b - a) / a:+.1f} %")

    out = work / "long"
    shutil.rmtree(out, ignore_errors=True)
    run = Handeye(["run", "--config", config_long, "--output", str(out), "--console", "127.0.0.1:0"], work)
    page.goto(run.url())
    samples = []
    while run.proc.poll() is None:
        poses = len(list((out / "poses").glob("*.yaml"))) if (out / "poses").is_dir() else 0
        try:
            samples.append((poses, rss_kib(run.proc.pid)))
        except OSError:
            break
        time.sleep(0.5)
    assert run.proc.returncode == 0, run.output()
    print("poses recorded -> RSS (MiB):")
    seen = set()
    for poses, kib in samples:
        bucket = poses // 20
        if bucket not in seen and poses > 0:
            seen.add(bucket)
            print(f"  {poses:4d}  {kib / 1024:7.1f}")
    print(f"  peak (session loop and the final solve): {max(k for _, k in samples) / 1024:.1f} MiB")
    browser.close()
