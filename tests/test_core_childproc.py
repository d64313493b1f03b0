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
