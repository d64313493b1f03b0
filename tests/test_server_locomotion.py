"""The locomotion back-ends shipped with the server: one test class run against every one of them."""

import re
import time

import numpy as np
import pytest

from antarium import bus
from antarium.core.clock import MonotonicClock, SimulatedClock
from antarium.locomotion import BallSample, LocomotionSource, open_source, wire
from antarium.locomotion.scripted import ScriptedSource


def _write_csv(path, n=200, rate=100.0):
    lines = ["t,seq,rx,ry,rz"]
    for i in range(n):
        lines.append(f"{10 + i / rate},{i},0.0,-0.002,0.0")
    path.write_text("\n".join(lines) + "\n")
    return path


class Feeder:
    """Publishes locomotion structs from a client session, as a trackball driver would."""

    def __init__(self, section, rig):
        self.session = bus.open_session(section, "client")
        self.pub = bus.locomotion_publisher(self.session, rig)  # the trackball driver's: blocks, never drops
        self.seq = 0

    def push(self, n):
        for _ in range(n):
            self.seq += 1
            self.pub.put(wire.encode(BallSample(0.0, self.seq, (0.0, -0.002, 0.0))))

    def close(self):
        self.session.close()


@pytest.fixture(params=["scripted", "replay", "bus"])
def backend(request, tmp_path):
    """(source, advance(seconds) -> None) for each back-end."""
    if request.param == "bus":
        section = {"listen": [bus.free_tcp_endpoint()]}
        server = bus.open_session(section, "server")
        # silence that long is no loss here (a loaded machine); the silence test is below
        src = open_source("bus", rig="tloco", session=server, clock=MonotonicClock(), timeout_s=60.0)
        src.start()
        feeder = Feeder(section, "tloco")
        deadline = time.monotonic() + 20.0  # until the route is up: samples put before it are not delivered
        while src.received == 0 and time.monotonic() < deadline:
            feeder.push(1)
            time.sleep(0.05)
        assert src.received > 0, "the feeder's samples never reached the bus source"
        src.read()

        def advance(seconds):
            feeder.push(int(seconds * 100))
            deadline = time.monotonic() + 3.0
            while src.received < feeder.seq and time.monotonic() < deadline:
                time.sleep(0.01)

        yield src, advance
        src.stop()
        feeder.close()
        server.close()
        return
    clock = SimulatedClock()
    if request.param == "scripted":
        src = open_source("scripted", speed=0.01, rate_hz=100.0, clock=clock)
    else:
        src = open_source("replay", path=str(_write_csv(tmp_path / "walk.csv")), clock=clock)
    src.start()
    yield src, clock.advance
    src.stop()


class TestEveryBackend:
    def test_is_a_locomotion_source(self, backend):
        src, _ = backend
        assert isinstance(src, LocomotionSource)
        assert src.status()["connected"] is True

    def test_read_returns_ordered_samples_with_increasing_seq(self, backend):
        src, advance = backend
        advance(0.5)
        samples = src.read()
        assert len(samples) >= 40
        seqs = [s.seq for s in samples]
        assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
        assert all(isinstance(s, BallSample) and len(s.rotation) == 3 for s in samples)
        assert src.read() == []  # nothing new

    def test_forward_walk_rolls_the_ball_about_minus_y(self, backend):
        src, advance = backend
        advance(0.3)
        total = np.sum([s.rotation for s in src.read()], axis=0)
        assert total[1] < 0 and abs(total[0]) < 1e-9 and abs(total[2]) < 1e-9


def test_scripted_path_is_followed():
    clock = SimulatedClock()
    src = ScriptedSource(path=[(0, 0), (0.1, 0), (0.1, 0.1)], speed=0.05, clock=clock)
    src.start()
    clock.advance(10.0)
    from antarium.core.ball import pole_motion

    moves = np.array([pole_motion(s.rotation)[:2] for s in src.read()])
    end = moves.sum(axis=0)
    assert end == pytest.approx([0.1, 0.1], abs=1e-3)


def test_scripted_meander_is_seeded():
    def walk(seed):
        clock = SimulatedClock()
        src = ScriptedSource(meander=1.0, seed=seed, clock=clock)
        src.start()
        clock.advance(3.0)
        return [s.rotation for s in src.read()]

    assert walk(1) == walk(1) and walk(1) != walk(2)


def test_replay_from_trial_log_reproduces_the_recorded_samples(tmp_path):
    from antarium.trial_log import TrialLog

    recorded = [BallSample(5.0 + i * 0.01, i, (0.001 * i, 0.0, -0.001), None, 0.5) for i in range(50)]
    with TrialLog(tmp_path / "t.h5", {}, "x") as log:
        log.add_samples(recorded)
    clock = SimulatedClock(100.0)
    src = open_source("replay", path=str(tmp_path / "t.h5"), clock=clock)
    src.start()
    clock.advance(0.245)
    first = src.read()
    assert [s.seq for s in first] == list(range(25))
    clock.advance(10.0)
    rest = src.read()
    assert [s.rotation for s in first + rest] == [s.rotation for s in recorded]
    assert rest[-1].t == pytest.approx(100.0 + 0.49) and src.status()["finished"]


@pytest.mark.parametrize("kwargs, match", [
    ({"speed": -1}, "speed"), ({"tether": "loose"}, "tether"), ({"path": [(0, 0)]}, "at least 2"),
    ({"rate_hz": 0}, "rate_hz"),
    ({"heading_deg": float("nan")}, r"scripted source heading_deg must be a number in \[-3600.0, 3600.0\], got nan$"),
    ({"heading_deg": float("inf")}, r"heading_deg must be a number in \[-3600.0, 3600.0\], got inf$"),
    ({"heading_deg": "90"}, r"heading_deg must be a number in \[-3600.0, 3600.0\], got '90'$"),
    ({"duration": "10"}, r"scripted source duration must be a finite number > 0 \(s; leave it out for no end\), "
                         r"got '10'$"),
    ({"duration": 0}, r"duration must be a finite number > 0 .*, got 0$"),
    ({"duration": float("nan")}, r"duration must be a finite number > 0 .*, got nan$"),
    ({"tether": "fixed", "heading_deg": 90.0}, r"heading_deg applies to the free_yaw tether only .*"
                                                r"\[loop\] start_heading_deg\), got 90.0$"),
])
def test_scripted_rejects_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ScriptedSource(**kwargs)


def test_scripted_heading_and_duration_are_kept():
    clock = SimulatedClock()
    src = ScriptedSource(speed=0.02, heading_deg=90.0, duration=0.5, rate_hz=100.0, clock=clock)
    src.start()
    clock.advance(2.0)
    samples = src.read()
    assert len(samples) == 50  # 0.5 s at 100 Hz, then no more
    total = np.sum([s.rotation for s in samples], axis=0)  # walked 0.01 m along the dome's +y: rx = dy / r
    assert total == pytest.approx([0.01 / src.radius, 0.0, 0.0], abs=1e-12)
    assert ScriptedSource(tether="fixed", heading_deg=0.0).tether == "fixed"  # the default heading is fine


def test_replay_refuses_non_finite_values_naming_file_line_and_column(tmp_path):
    path = tmp_path / "walk.csv"
    where = f"^replay CSV '{re.escape(str(path))}'"
    path.write_text("t,rx,ry,rz\n0.0,0,-0.001,0\n0.01,nan,-0.001,0\n0.02,0,-0.001,0\n")
    with pytest.raises(ValueError, match=where + " line 3: rx must be a finite number, got nan$"):
        open_source("replay", path=str(path))
    path.write_text("t,rx,ry,rz,quality\n0.0,0,-0.001,0,1\n0.01,0,-0.001,0,1\n0.02,0,-0.001,0,inf\n")
    with pytest.raises(ValueError, match=where + " line 4: quality must be a finite number, got inf$"):
        open_source("replay", path=str(path))


def test_a_looped_replay_never_repeats_sequence_numbers(tmp_path):
    path = tmp_path / "gappy.csv"
    rows = [f"{i * 0.01},{s},0,-0.001,0" for i, s in enumerate([0, 1, 2, 5, 6, 7])]  # 3 and 4 were lost
    path.write_text("t,seq,rx,ry,rz\n" + "\n".join(rows) + "\n")
    clock = SimulatedClock()
    src = open_source("replay", path=str(path), loop=True, clock=clock)
    src.start()
    clock.advance(0.175)  # a lap lasts 0.06 s: 18 samples
    assert [s.seq for s in src.read()] == [0, 1, 2, 5, 6, 7, 8, 9, 10, 13, 14, 15, 16, 17, 18, 21, 22, 23]


@pytest.mark.parametrize("radius", [0.05, 0.1])
def test_the_scripted_walker_walks_its_speed_whatever_the_ball_radius(radius, tmp_path):
    from antarium.config import resolve
    from antarium.server.server import Server

    config = resolve({"loop": {"ball_radius_m": radius, "rate_hz": 100.0, "realtime_priority": 0, "cpu": "off"},
                      "bus": {"enabled": False}, "link": {"interface": "virtual"}, "log": {"dir": str(tmp_path)},
                      "locomotion": {"source": "scripted", "speed": 0.03}})
    server = Server(config, clock=SimulatedClock(), renderer_factory=None, echo=lambda line: None)
    server.run(seconds=2.0)
    assert server.source.radius == radius
    assert np.hypot(server.loop.pose.x, server.loop.pose.y) == pytest.approx(0.06, abs=1e-3)


def test_replay_rejects_bad_files(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        open_source("replay", path=str(tmp_path / "none.csv"))
    bad = tmp_path / "bad.csv"
    bad.write_text("t,rx\n0,1\n")
    with pytest.raises(ValueError, match="lacks columns"):
        open_source("replay", path=str(bad))
    with pytest.raises(ValueError, match="unknown locomotion source 'mouse'"):
        open_source("mouse")


@pytest.mark.parametrize("timeout_s", [0, -1.0, float("nan"), float("inf"), "0.5"])
def test_bus_source_timeout_must_be_a_positive_number(timeout_s):
    with pytest.raises(ValueError, match=r"^bus source timeout_s must be a finite number > 0 \(s without samples "
                                         rf"before it is not connected\), got {timeout_s!r}$"):
        open_source("bus", timeout_s=timeout_s)


def test_bus_source_counts_malformed_payloads_and_reports_silence():
    section = {"listen": [bus.free_tcp_endpoint()]}
    clock = MonotonicClock()
    with bus.open_session(section, "server") as server, bus.open_session(section, "client") as client:
        src = open_source("bus", rig="tbad", session=server, timeout_s=0.2, clock=clock)
        src.start()
        pub = client.declare_publisher(bus.locomotion_key("tbad"))
        time.sleep(0.3)
        pub.put(b"short")
        pub.put(wire.encode(BallSample(0.0, 1, (0.0, 0.0, 0.0))))
        deadline = time.monotonic() + 3
        while src.received < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert src.malformed == 1 and "44 bytes" in src.status()["last_error"]
        assert src.status()["connected"] is True
        time.sleep(0.3)
        assert src.status()["connected"] is False
        src.stop()


@pytest.mark.parametrize(("name", "options", "hint"), [
    ("usb", {"trackball": {"vendor_id": 0x1209, "product_id": 0x0001}},
     "plug it in and check `lsusb`, the udev rule of docs/trackball_usb.md and [trackball] vendor_id/product_id"),
    ("fictrac", {"transport": "udp", "host": "127.0.0.1", "port": 2001},
     "is FicTrac running and sending to udp 127.0.0.1:2001 (its sock_port)?"),
    ("bus", {"rig": "r7"},
     "is `antarium trackball` (or a simulated ant) running for rig 'r7' and publishing on antarium/r7/locomotion?"),
    ("scripted", {}, ""),  # never lost: nothing to check
])
def test_each_source_says_what_to_check_when_it_delivers_nothing(name, options, hint):
    """What serve prints with locomotion_lost (built, not started: no device, socket or session is opened)."""
    assert open_source(name, **options).lost_hint() == hint
