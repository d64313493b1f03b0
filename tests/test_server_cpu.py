"""[loop] cpu: the frame loop's thread alone on one CPU, the rest of the rig (threads, child processes) elsewhere."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from antarium.config import ConfigError, resolve
from antarium.core import realtime

pytestmark = pytest.mark.skipif(not realtime.supported() or len(os.sched_getaffinity(0)) < 2,
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
    isolation = realtime.Isolation("auto")
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


def test_a_second_placement_walks_only_what_came_since_and_places_it(monkeypatch):
    """Once a second in the loop's idle time: with nothing new it reads two /proc entries and walks nothing; a
    thread or a process (with its threads) the loop's thread started since lands on the other CPUs."""
    isolation = realtime.Isolation("auto")
    me = threading.get_native_id()
    walks = []
    real_descendants = realtime.descendants
    monkeypatch.setattr(realtime, "descendants", lambda *a: walks.append(1) or real_descendants(*a))
    stop = threading.Event()
    child = None

    def seen() -> tuple:
        """What `apply` compares: this process's threads and the children of this ("the loop's") thread."""
        return set(os.listdir("/proc/self/task")), sorted(realtime._thread_children("self", [me]))

    def walks_of_an_apply() -> int:
        """Walks (0 or 1) of one `apply` right after another, with nothing coming or going in between (a thread
        or child process of an earlier test that ends is something that changed: retried then)."""
        for _ in range(20):
            first = seen()
            isolation.apply(me)
            before, n = seen(), len(walks)
            isolation.apply(me)
            if first == before == seen():
                break
        return len(walks) - n

    try:
        assert walks_of_an_apply() == 0  # nothing came: no walk
        late = threading.Thread(target=stop.wait, daemon=True)  # started on the loop's CPU: it inherits it
        late.start()
        assert os.sched_getaffinity(late.native_id) == {isolation.cpu}
        n = len(walks)
        isolation.apply(me)
        assert len(walks) == n + 1 and os.sched_getaffinity(late.native_id) == isolation.others
        child = subprocess.Popen([sys.executable, "-c", "import threading, time; threading.Thread(target="
                                  "time.sleep, args=(30,)).start(); time.sleep(30)"])
        time.sleep(0.5)
        n = len(walks)
        isolation.apply(me)
        assert len(walks) == n + 1
        threads = [int(t) for t in os.listdir(f"/proc/{child.pid}/task")]
        assert len(threads) == 2 and all(os.sched_getaffinity(t) == isolation.others for t in threads)
        assert walks_of_an_apply() == 0
    finally:
        isolation.release()
        stop.set()
        if child is not None:
            child.kill()
            child.wait()


def test_a_cpu_the_process_may_not_use_is_refused():
    with pytest.raises(ValueError, match="is not one this process may use"):
        realtime.Isolation(max(os.sched_getaffinity(0)) + 1000)


@pytest.mark.parametrize("value", ["auto", "off", 0, 3])
def test_cpu_setting_accepts_auto_off_and_numbers(value):
    assert resolve({"loop": {"cpu": value}}).loop.cpu == value


@pytest.mark.parametrize("value", [-1, "fast", 1.5, True])
def test_bad_cpu_setting_names_what_is_allowed(value):
    with pytest.raises(ConfigError, match=r'\[loop\] cpu must be a CPU number \(>= 0\), "auto" or "off"'):
        resolve({"loop": {"cpu": value}})


def _realtime_allowed() -> bool:
    allowed = []

    def probe():
        try:
            realtime.set_realtime(1)
            allowed.append(True)
        except (AttributeError, OSError):
            pass

    probe_thread = threading.Thread(target=probe)  # a thread of its own: the test's thread stays as it is
    probe_thread.start()
    probe_thread.join()
    return bool(allowed)


def _policy(tid: int) -> tuple[int, int]:
    return os.sched_getscheduler(tid) & ~os.SCHED_RESET_ON_FORK, os.sched_getparam(tid).sched_priority


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"  # a zombie has no policy left
    except OSError:
        return False


def _comm(tid: int) -> str:
    try:
        return Path(f"/proc/self/task/{tid}/comm").read_text().strip()
    except OSError:
        return "(ended)"


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_text().replace("\0", " ")[:100]
    except OSError:
        return "(ended)"


def _thread_policies() -> dict[int, tuple[int, int]]:
    """Scheduling of every thread of this process that still runs (one may end between listing and asking)."""
    policies = {}
    for name in os.listdir("/proc/self/task"):
        try:
            policies[int(name)] = _policy(int(name))
        except ProcessLookupError:
            pass
    return policies


@pytest.mark.skipif(not _realtime_allowed(), reason="needs permission for SCHED_FIFO (CAP_SYS_NICE or rtprio)")
def test_real_time_goes_to_the_loop_and_its_helper_the_emulator_below_the_rest_ordinary(tmp_path):
    from conftest import wait_for

    from antarium import bus
    from antarium.server import Server

    p = 10
    config = resolve({
        "rig": {"name": "tsched"}, "bus": {"listen": [bus.free_tcp_endpoint()]},
        "log": {"dir": str(tmp_path)},
        "render": {"scene": {"scene": "habitat", "n_tussocks": 30, "n_stones": 5, "n_bushes": 2, "n_trees": 1}},
        "link": {"interface": "udp", "spawn_emulator": True},
        "loop": {"realtime_priority": p, "rate_hz": 100.0},
    })
    me = threading.get_native_id()
    assert _policy(me) == (os.SCHED_OTHER, 0)
    server = Server(config, record="sched", echo=lambda line: None)
    server.start_thread()
    try:
        assert wait_for(lambda: server.loop.frame > 50, 30.0)
        time.sleep(1.2)  # the status thread places threads started since the first frame
        loop_tid = server._loop_thread.native_id
        assert _policy(loop_tid) == (os.SCHED_FIFO, p)
        assert os.sched_getscheduler(loop_tid) & os.SCHED_RESET_ON_FORK  # nothing inherits it by accident
        threads = _thread_policies()
        # the renderer's sampling helper runs with the loop; every other thread of the process (this test's own,
        # the status thread, the bus') stays as it started
        helpers = [t for t, pol in threads.items() if t != loop_tid and pol == (os.SCHED_FIFO, p)]
        assert len(helpers) == 1
        assert threads[server._status_thread.native_id] == (os.SCHED_OTHER, 0)
        assert threads[me] == (os.SCHED_OTHER, 0)
        # nothing else shares the loop's priority (zenoh's shared-memory watchdogs run SCHED_FIFO 1 of their own)
        fifo = {t: (pol, _comm(t)) for t, pol in threads.items()
                if t not in (loop_tid, *helpers) and pol[0] == os.SCHED_FIFO and pol[1] > 1}
        assert not fifo, fifo
        # the emulator below the loop and its helper; the far-layer builder and the log writer ordinary, the
        # builder at nice 10 (it yields its CPU to the server's threads, which may hold the loop's GIL)
        emulator = server.emulator.pid
        assert _policy(emulator) == (os.SCHED_FIFO, p - 2)
        builder = server.renderer.far_layer_status()["pid"]
        children = realtime.descendants()
        assert builder in children and len(children) >= 3
        # the rig's own processes (`python -m antarium...`); a browser an earlier test drove may still be ending
        others = {c: _policy(c) for c in children if c != emulator and _alive(c) and "-m antarium" in _cmdline(c)}
        wrong = {c: (pol, _cmdline(c)) for c, pol in others.items() if pol != (os.SCHED_OTHER, 0)}
        assert not wrong, wrong
        assert os.getpriority(os.PRIO_PROCESS, builder) == 10
    finally:
        server.stop()
    # all undone: no thread of this process real-time any more (but zenoh's own shared-memory watchdogs, at 1)
    still = {t: (pol, _comm(t)) for t, pol in _thread_policies().items()
             if pol[0] in (os.SCHED_FIFO, os.SCHED_RR) and pol[1] > 1}
    assert not still, still


def _in_loop_thread(placement, body):
    """body() in a thread placed as the frame loop's (real-time, its own CPU); placement released after."""
    out = {}

    def loop():
        placement.before_building()
        placement.before_frames()
        try:
            out["result"] = body()
        except BaseException as exc:  # noqa: BLE001 - re-raised in the test's thread
            out["error"] = exc
        finally:
            placement.release()

    thread = threading.Thread(target=loop)
    thread.start()
    thread.join()
    if "error" in out:
        raise out["error"]
    return out["result"]


@pytest.mark.skipif(not _realtime_allowed(), reason="needs permission for SCHED_FIFO (CAP_SYS_NICE or rtprio)")
def test_work_beside_the_loop_and_the_processes_it_starts_have_the_loops_cpu_until_it_ends():
    from antarium.server.placement import LoopPlacement

    placement = LoopPlacement(resolve({"loop": {"realtime_priority": 5, "cpu": "auto"}}).loop, echo=print)
    cpu = max(os.sched_getaffinity(0))
    caller = threading.get_ident()
    seen = {}

    def prepare(tag):
        child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
        placement.place_threads()  # the status thread's tick while the work runs: it leaves the child there
        seen.update(tag=tag, thread=threading.get_ident(), cpus=os.sched_getaffinity(0),
                    child=child, child_cpus=os.sched_getaffinity(child.pid))
        return "prepared"

    def body():
        others = os.sched_getaffinity(0)
        result = placement.beside_loop(prepare, "scene")
        with pytest.raises(ValueError, match="bad scene"):  # raised in the helper thread, reaches the caller
            placement.beside_loop(lambda: (_ for _ in ()).throw(ValueError("bad scene")))
        return result, others, os.sched_getaffinity(seen["child"].pid)

    try:
        result, others, child_after = _in_loop_thread(placement, body)
        assert result == "prepared" and seen["tag"] == "scene" and seen["thread"] != caller
        assert seen["cpus"] == {cpu} and seen["child_cpus"] == {cpu}
        assert others == {cpu}                                       # the caller was the loop's thread
        assert child_after == os.sched_getaffinity(0) - {cpu}         # once the work ended: the other CPUs
    finally:
        if "child" in seen:
            seen["child"].kill()
            seen["child"].wait()


def test_work_beside_an_ordinary_loop_runs_in_the_callers_thread_and_its_errors_reach_the_caller():
    from antarium.server.placement import LoopPlacement

    placement = LoopPlacement(resolve({"loop": {"realtime_priority": 0, "cpu": "auto"}}).loop, echo=print)

    def body():
        me = threading.get_ident()
        assert placement.beside_loop(threading.get_ident) == me   # an ordinary loop would share its CPU with it
        with pytest.raises(ValueError, match="bad scene"):
            placement.beside_loop(lambda: (_ for _ in ()).throw(ValueError("bad scene")))
        return True

    assert _in_loop_thread(placement, body)
