"""`antarium bench monitor`'s own measuring: the browser's CPU time over its process tree, and the browser started
SCHED_IDLE (a real child process tree, no browser needed)."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from antarium.bench.cpu import process_tree_cpu_s
from antarium.bench.monitor import idle_browser, page_figures, page_lines

BURN = "import time\nt = time.process_time()\nwhile time.process_time() - t < {s}: pass\n"


def test_the_cpu_time_of_a_process_tree_counts_its_grandchildren():
    # a shell whose child burns 0.3 s of CPU and then sleeps, so that it is still there to be counted
    script = f"{sys.executable} -c '{BURN.format(s=0.3)}import time; time.sleep(30)' & wait"
    shell = subprocess.Popen(["/bin/sh", "-c", script])
    try:
        before = process_tree_cpu_s(shell.pid)
        deadline = time.monotonic() + 20
        while process_tree_cpu_s(shell.pid) < 0.25 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert before < 0.25 <= process_tree_cpu_s(shell.pid) < 5.0
        assert process_tree_cpu_s(os.getpid()) > process_tree_cpu_s(shell.pid)  # we are its parent
    finally:
        subprocess.run(["pkill", "-P", str(shell.pid)], check=False)
        shell.kill()
        shell.wait()


def test_the_idle_browser_script_runs_the_browser_sched_idle_with_its_arguments(tmp_path):
    fake = tmp_path / "browser"  # stands for chromium: says its scheduling class and arguments
    fake.write_text(f"#!{sys.executable}\nimport os, sys\n"
                    "print(os.sched_getscheduler(0) == os.SCHED_IDLE, sys.argv[1:])\n")
    fake.chmod(0o755)
    out = subprocess.run([idle_browser(str(fake), str(tmp_path)), "--headless=new", "a b"],
                         capture_output=True, text=True, check=True).stdout
    assert out.strip() == "True ['--headless=new', 'a b']"


def test_a_page_that_drew_no_led_frame_is_reported_not_a_crash():
    """With the LED stream off (`[monitor] leds_every_frames = 0`) the page paints no LED frame: the report says so
    after the three loop runs instead of failing on the missing figures."""
    page = page_figures({"drawn": 0, "measured": [], "first_draw_ms": None, "paint": [], "draw_ms": []}, 10.0, 1.0)
    assert page_lines(page) == [
        "  first contentful paint none, first LED frame drawn none after navigation",
        "  updates drawn   0.0 /s over 10.0 s",
        "  frame -> screen: no LED frame drawn (is the LED stream on? [monitor] leds_every_frames)"]
    drew = page_figures({"drawn": 40, "measured": [0.02, 0.04], "first_draw_ms": 812.4, "paint": [301.2],
                         "draw_ms": [3.0, 4.0]}, 2.0, 0.5)
    assert page_lines(drew)[:2] == ["  first contentful paint 301 ms, first LED frame drawn 812 ms after navigation",
                                    "  updates drawn   20.0 /s over 2.0 s"]
    assert page_lines(drew)[2].startswith("  browser CPU     12.5 ms per update drawn")
