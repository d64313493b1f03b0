"""[loop] cpu: the frame loop's thread alone on one CPU, the rest of the rig (threads, child processes) elsewhere."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

import pytest

from antarium import cpu
from antarium.config import ConfigError, resolve

pytestmark = pytest.mark.skipif(not cpu.supported() or len(os.sched_getaffinity(0)) < 2,
                                reason="needs Linux with two or more usable CPUs")


def test_isolation_places_the_loop_thread_alone_and_everything_else_elsewhere():
    usable = os.sched_getaffinity(0)
    stop = threading.Event()
    other = threading.Thread(target=stop.wait, daemon=True)
    other.start()
    # a child with a second thread: both threads of it must move
    child = subprocess.Popen([sys.executable, "-c", "import threading, time; threading.Thread(target=time.sleep, "
                              "args=(30,)).start(); time.sleep(30)"])
    time.sleep(0.5)
    isolation = cpu.Isolation("auto")
    try:
        assert isolation.cpu == max(usable) and isolation.others == usable - {max(usable)}
        isolation.apply(threading.get_native_id())
        assert os.sched_getaffinity(0) == {isolation.cpu}  # this (the "loop") thread
        assert os.sched_getaffinity(other.native_id) == isolation.others
        child_threads = [int(t) for t in os.listdir(f"/proc/{child.pid}/task")]
        assert len(child_threads) == 2
        assert all(os.sched_getaffinity(t) == isolation.others for t in child_threads)
        isolation.release()
        for target in (0, other.native_id, child.pid):
            assert os.sched_getaffinity(target) == usable
    finally:
        isolation.release()
        stop.set()
        child.kill()
        child.wait()


def test_a_cpu_the_process_may_not_use_is_refused():
    with pytest.raises(ValueError, match="is not one this process may use"):
        cpu.Isolation(max(os.sched_getaffinity(0)) + 1000)


@pytest.mark.parametrize("value", ["auto", "off", 0, 3])
def test_cpu_setting_accepts_auto_off_and_numbers(value):
    assert resolve({"loop": {"cpu": value}})["loop"]["cpu"] == value


@pytest.mark.parametrize("value", [-1, "fast", 1.5, True])
def test_bad_cpu_setting_names_what_is_allowed(value):
    with pytest.raises(ConfigError, match=r'\[loop\] cpu must be a CPU number \(>= 0\), "auto" or "off"'):
        resolve({"loop": {"cpu": value}})
