"""Child processes end with their parent: the dome emulator is never left running (holding its UDP port and its
real-time priority) after the process that started it was killed."""

import os
import signal
import subprocess
import sys

from conftest import process_gone, wait_for

PARENT = """
import time
from antarium.server.emulator_process import EmulatorProcess
emulator = EmulatorProcess()
emulator.start()
print(emulator.pid, flush=True)
time.sleep(600)
"""


def test_the_emulator_ends_when_its_parent_is_killed():
    parent = subprocess.Popen([sys.executable, "-c", PARENT], stdout=subprocess.PIPE, text=True)
    emulator = None
    try:
        emulator = int(parent.stdout.readline())
        assert not process_gone(emulator)
        parent.kill()  # SIGKILL: the parent cleans nothing up
        parent.wait(30)
        assert wait_for(lambda: process_gone(emulator), 30.0, 0.05), "the emulator outlived its parent"
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait()
        parent.stdout.close()
        if emulator is not None and not process_gone(emulator):
            os.kill(emulator, signal.SIGKILL)


def test_a_child_ends_when_its_parent_closes_it():
    from antarium.core.childproc import ChildProcess

    child = ChildProcess("antarium", ["emulate", "--port", "0"], end_with_parent=True)
    try:
        assert wait_for(lambda: "listening on" in child.output(), 60.0, 0.05), child.output()
        child.conn.close()  # as the parent's death would
        assert child.wait(30.0)
    finally:
        child.kill()
