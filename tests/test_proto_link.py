"""The dome link: one test class run against every back-end, and the UDP link surviving a vanishing peer."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from antarium.firmware_proto import link as link_module
from antarium.firmware_proto.emulator import Emulator
from antarium.firmware_proto.link import open_link
from antarium.firmware_proto.server import serve

WAIT_S = 2.0  # upper bound for replies over loopback; returns as soon as they are in


@pytest.fixture(params=sorted(link_module.BACKENDS))
def dome(request):
    """(link, emulator) for each back-end; the udp one talks to an emulator served on an ephemeral port."""
    if request.param == "virtual":
        with open_link("virtual") as link:
            yield link, link.emulator
        return
    emulator, stop, bound = Emulator(), threading.Event(), []
    ready = threading.Event()
    thread = threading.Thread(target=serve, args=(emulator, "127.0.0.1", 0),
                              kwargs={"ready": lambda a: (bound.append(a), ready.set()), "stop": stop}, daemon=True)
    thread.start()
    assert ready.wait(5)
    with open_link("udp", host="127.0.0.1", port=bound[0][1]) as link:
        yield link, emulator
    stop.set()
    thread.join(5)


def pattern(k: int) -> np.ndarray:
    f = np.zeros((20350, 2), np.uint16)
    f[:, 0] = 100 * k
    return f


class TestEveryBackend:
    def test_frames_arrive_whole(self, dome):
        link, emulator = dome
        seqs = [link.send_frame(pattern(k)) for k in range(1, 11)]
        assert seqs == list(range(10))
        t = link.telemetry(wait_s=WAIT_S)
        assert t["connected"] and t["counters"]["frames_latched"] == 10 and t["counters"]["frames_dropped"] == 0
        assert t["link"]["frames_sent"] == 10 and t["link"]["datagrams_failed"] == 0
        assert set(link.last_timings) == {"encode", "send"} and min(link.last_timings.values()) > 0
        assert np.array_equal(emulator.led_values(), pattern(10))
        json.dumps(t)  # JSON-serialisable

    def test_telemetry_contents(self, dome):
        link, _ = dome
        link.send_frame(pattern(1))
        t = link.telemetry(wait_s=WAIT_S)
        assert len(t["temperature_c"]) == 55 and len(t["current_a"]) == 55
        assert np.array(t["polariser_angles_deg"]).shape == (55, 9) and t["faults"] == []
        assert t["age_s"] < WAIT_S

    def test_polling_telemetry_does_not_flood_the_board(self, dome):
        link, emulator = dome
        link.status_interval_s = 10.0
        for _ in range(5):
            link.telemetry()  # wait_s = 0: at most one request per interval
        t = link.telemetry(wait_s=WAIT_S)  # waiting always asks
        assert t["counters"]["status_requests"] == 2 and link.counters["datagrams_sent"] == 3  # with HELLO
        assert emulator.counters["status_requests"] == 2

    def test_hello_reports_version_and_capabilities(self, dome):
        link, _ = dome
        v = link.hello(wait_s=WAIT_S)
        assert v["protocol_version"] == 1 and v["n_panels"] == 55 and "polarisers" in v["capability_names"]

    def test_polarisers_and_config(self, dome):
        link, emulator = dome
        target = np.full((55, 9), 1.2)
        assert link.send_polarisers(target)
        link.send_config(dot_correction=50, brightness=100)
        link.send_frame(pattern(4))
        link.telemetry(wait_s=WAIT_S)  # everything before it has been processed
        assert np.array_equal(emulator.led_values()[:, 0], np.full(20350, 200))
        assert np.allclose(emulator.actuators.target % np.pi, 1.2, atol=1e-4)

    def test_bad_input_raises_and_sends_nothing(self, dome):
        link, _ = dome
        before = dict(link.counters)
        with pytest.raises(ValueError, match="drive sum"):
            link.send_frame(np.full((20350, 2), 40000, np.uint16))
        with pytest.raises(ValueError, match="uint16"):
            link.send_frame(np.zeros((20350, 2), np.float32))
        with pytest.raises(ValueError, match="allowed"):
            link.send_polarisers(np.full((55, 9), 4.0))
        assert link.counters == before

    def test_closed_link_refuses(self, dome):
        link, _ = dome
        link.close()
        with pytest.raises(RuntimeError, match="closed"):
            link.send_frame(pattern(1))


def test_unknown_interface():
    with pytest.raises(ValueError, match="allowed"):
        open_link("can0")


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_emulate(port: int) -> subprocess.Popen:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "antarium", "emulate", "--port", str(port), "--seconds", "30"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
    )
    line = proc.stdout.readline()
    assert "listening on udp://127.0.0.1" in line, line
    return proc


def test_udp_link_survives_the_emulator_being_killed_and_restarted():
    port = free_udp_port()
    proc = start_emulate(port)
    try:
        with open_link("udp", port=port) as link:
            for k in range(5):
                link.send_frame(pattern(k))
            assert link.telemetry(wait_s=WAIT_S)["counters"]["frames_latched"] == 5
            proc.send_signal(signal.SIGKILL)
            proc.wait(5)
            for k in range(20):  # the peer is gone: ICMP port unreachable -> counted, not raised
                link.send_frame(pattern(k))
                time.sleep(0.002)
            t = link.telemetry(wait_s=0.2)
            assert t["link"]["peer_refused"] > 0 and t["link"]["frames_sent"] == 25
            proc = start_emulate(port)
            for k in range(3):
                link.send_frame(pattern(k))
            t = link.telemetry(wait_s=WAIT_S)
            assert t["counters"]["frames_latched"] == 3  # the new process counts from zero
    finally:
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=10)
    assert "statistics" in out and "frames_latched" in out


def test_emulate_command_runs_for_a_bounded_time_and_prints_statistics(capsys):
    from antarium.cli import main

    assert main(["emulate", "--port", "0", "--seconds", "0.3", "--fault", "1:2:open", "--line", "bits"]) == 0
    out = capsys.readouterr().out
    assert "listening on udp://127.0.0.1:" in out and "(line: bits)" in out
    assert "statistics" in out and "datagrams_received" in out


@pytest.mark.parametrize("spec, match", [("1:2", "PANEL:LED:KIND"), ("1:2:melted", "allowed"), ("99:2:open", "range")])
def test_emulate_command_refuses_bad_faults(capsys, spec, match):
    from antarium.cli import main

    assert main(["emulate", "--port", "0", "--seconds", "0.1", "--fault", spec]) == 2
    assert match in capsys.readouterr().err


def test_emulate_command_reports_a_busy_port(capsys):
    from antarium.cli import main

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        assert main(["emulate", "--port", str(s.getsockname()[1]), "--seconds", "0.1"]) == 2
    assert "cannot listen" in capsys.readouterr().err
