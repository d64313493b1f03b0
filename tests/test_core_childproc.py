"""Child processes end with their parent: the dome emulator (holding its UDP port and its real-time priority) and
the monitor (serving its page) are never left running after the process that started them was killed."""

import os
import signal
import subprocess
import sys

import pytest
from conftest import process_gone, wait_for

EMULATOR_PARENT = """
import time
from antarium.server.emulator_process import EmulatorProcess
emulator = EmulatorProcess()
emulator.start()
print(emulator.pid, flush=True)
time.sleep(600)
"""
MONITOR_PARENT = """
import time
from antarium import bus
from antarium.config import resolve
from antarium.monitor.process import MonitorProcess
config = resolve({"rig": {"name": "torphan"}, "bus": {"listen": [bus.free_tcp_endpoint()]},
                  "monitor": {"enabled": True, "port": 0}})
monitor = MonitorProcess(config)
while "http://" not in monitor.output():  # serving its page
    time.sleep(0.05)
print(monitor.child.proc.pid, flush=True)
time.sleep(600)
"""


@pytest.mark.parametrize("script", [EMULATOR_PARENT, MONITOR_PARENT], ids=["emulator", "monitor"])
def test_a_child_ends_when_its_parent_is_killed(script):
    parent = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    child = None
    try:
        child = int(parent.stdout.readline())
        assert not process_gone(child)
        parent.kill()  # SIGKILL: the parent cleans nothing up
        parent.wait(30)
        assert wait_for(lambda: process_gone(child), 30.0, 0.05), "the child outlived its parent"
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait()
        parent.stdout.close()
        if child is not None and not process_gone(child):
            os.kill(child, signal.SIGKILL)


def test_a_child_ends_when_its_parent_closes_it():
    from antarium.core.childproc import ChildProcess

    child = ChildProcess("antarium", ["emulate", "--port", "0"], end_with_parent=True)
    try:
        assert wait_for(lambda: "listening on" in child.output(), 60.0, 0.05), child.output()
        child.conn.close()  # as the parent's death would
        assert child.wait(30.0)
    finally:
        child.kill()


def _emulator_children(pid: int) -> list[int]:
    """The `antarium emulate` children of process `pid` (Linux /proc)."""
    found = []
    for task in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{task}/children") as fh:
            for child in map(int, fh.read().split()):
                try:
                    with open(f"/proc/{child}/cmdline", "rb") as cmd:
                        if b"emulate" in cmd.read().split(b"\0"):
                            found.append(child)
                except FileNotFoundError:
                    pass
    return found


@pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="finds the child through Linux /proc")
def test_bench_protocols_emulator_ends_when_the_bench_is_killed():
    bench = subprocess.Popen([sys.executable, "-m", "antarium", "bench", "protocol", "--seconds", "0.05",
                              "--frames", "100000"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    children = []
    try:
        assert wait_for(lambda: children.extend(_emulator_children(bench.pid)) or children, 120.0, 0.05)
        bench.kill()
        bench.wait(30)
        assert wait_for(lambda: all(process_gone(c) for c in children), 30.0, 0.05), "the emulator outlived the bench"
    finally:
        if bench.poll() is None:
            bench.kill()
            bench.wait()
        for c in children:
            if not process_gone(c):
                os.kill(c, signal.SIGKILL)
