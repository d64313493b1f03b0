"""Every trackball back-end through one interface (python-can style), and publication on the bus."""

import json
import socket
import threading
import time

import pytest
from conftest import wait_for

from antarium import bus
from antarium.cli import main
from antarium.core.clock import SimulatedClock
from antarium.locomotion import BallSample, LocomotionSource, open_source, wire
from antarium.locomotion.fictrac.protocol import FicTracFrame, format_line
from antarium.locomotion.trackball.emulator import EmulatedTrackball, constant


def _fictrac_line(i: int) -> str:
    values = [0.0] * 25
    values[0] = values[22] = i
    values[7] = 0.02
    values[21] = 10.0 * i
    return format_line(FicTracFrame(*values))


def _open_usb(tmp_path):
    src = open_source("usb", backend=EmulatedTrackball(motion=constant((0.0, 0.0, 1.0)), realtime=False))
    return src, lambda: None


def _open_fictrac(tmp_path):
    src = open_source("fictrac", port=0)

    def feed():
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for i in range(1, 6):
                tx.sendto(_fictrac_line(i).encode(), src.address)

    return src, feed


def _open_replay(tmp_path):
    path = tmp_path / "log.dat"
    path.write_text("".join(_fictrac_line(i)[4:] + "\n" for i in range(1, 6)))  # FicTrac ends every line
    clock = SimulatedClock()
    src = open_source("fictrac-replay", path=path, clock=clock)
    return src, lambda: clock.advance(1.0)


@pytest.mark.parametrize("opener", [_open_usb, _open_fictrac, _open_replay], ids=["usb", "fictrac", "fictrac-replay"])
class TestEveryBackend:
    def test_start_read_status_stop(self, opener, tmp_path):
        src, feed = opener(tmp_path)
        assert isinstance(src, LocomotionSource)
        src.start()
        src.start()  # idempotent
        try:
            feed()
            got = []
            deadline = time.monotonic() + 5.0
            while len(got) < 5:
                assert time.monotonic() < deadline
                got.extend(src.read())
                time.sleep(0.002)
            assert all(isinstance(s, BallSample) for s in got)
            assert all(len(s.rotation) == 3 and 0.0 <= s.quality <= 1.0 for s in got)
            seqs = [s.seq for s in got]
            assert seqs == sorted(seqs)
            assert abs(got[1].rotation[2]) > 0  # each back-end's samples carry yaw
            status = src.status()
            assert status["connected"] is True
            json.dumps(status)  # the status is JSON-serialisable for the server's status message
        finally:
            src.stop()
            src.stop()  # safe twice


def test_cli_publishes_samples_and_unplug_events_on_the_bus(tmp_path):
    import zenoh

    endpoint = bus.free_tcp_endpoint()
    rig = tmp_path / "rig.toml"
    rig.write_text(f'[rig]\nname = "tb"\n\n[bus]\nlisten = ["{endpoint}"]\n')
    events: list[dict] = []
    with bus.open_session({"listen": [endpoint]}, "server") as server:
        raw = server.declare_subscriber(bus.locomotion_key("tb"), zenoh.handlers.FifoChannel(100000))
        server.declare_subscriber(bus.events_key("tb"), lambda s: events.append(json.loads(s.payload.to_string())))
        status_sub = server.declare_subscriber(bus.rig_key("tb", "trackball", "status"),
                                               zenoh.handlers.RingChannel(4))
        loop_source = open_source("bus", rig="tb", session=server)  # the server's own back-end for remote balls
        loop_source.start()
        code = []
        cli = threading.Thread(target=lambda: code.append(main([
            "trackball", "--emulate", "--config", str(rig), "--seconds", "1.2", "--unplug-at", "0.6",
            "--replug-after", "0.1"])))
        cli.start()
        cli.join(30)
        time.sleep(0.1)
        samples = []
        while (s := raw.try_recv()) is not None:
            samples.append(wire.decode(s.payload.to_bytes(), t=0.0))
        via_loop = loop_source.read()
        loop_source.stop()
        status = status_sub.try_recv()
    assert code == [0]
    assert len(samples) > 300 and len(via_loop) > 300
    assert all(b.seq > a.seq for a, b in zip(samples, samples[1:], strict=False) if b.seq)  # 0 after the replug
    assert [e["event"] for e in events if e["source"] == "usb"][-2:] == ["locomotion_lost", "locomotion_back"]
    assert status is not None and "connected" in json.loads(status.payload.to_string())


def test_frame_loop_holds_the_pose_while_the_usb_trackball_is_unplugged():
    """In-process: the server's frame loop reads the USB driver; unplugged, it holds the pose and logs an event."""
    from antarium.core.clock import MonotonicClock
    from antarium.server.frame_loop import FrameLoop

    events = []
    backend = EmulatedTrackball(motion=constant((0.0, -0.6, 0.0)), realtime=True)  # the ant walks 3 cm/s forward
    src = open_source("usb", backend=backend)
    loop = FrameLoop(clock=MonotonicClock(), source=src, on_event=lambda t, kind, data: events.append((t, kind)))


    with src:
        loop.start_thread()
        try:
            assert wait_for(lambda: loop.pose.x > 0.003)
            t_unplug = time.monotonic()
            backend.unplug()
            assert wait_for(lambda: not loop.locomotion_connected, 1.0)
            seen_after = time.monotonic() - t_unplug
            held = loop.pose
            time.sleep(0.2)
            assert loop.pose == held  # no samples, no drift
            backend.replug()
            assert wait_for(lambda: loop.locomotion_connected and loop.pose.x > held.x + 0.002)
        finally:
            loop.stop()
            loop.join(2.0)
    kinds = [k for _, k in events]
    assert "locomotion_lost" in kinds and kinds.index("locomotion_back") > kinds.index("locomotion_lost")
    assert abs(loop.pose.y) < 1e-3 and loop.pose.heading == 0.0
    print(f"frame loop saw the unplug after {seen_after * 1e3:.1f} ms")


def test_cli_names_a_usb_trackball_that_never_appears(tmp_path, capsys):
    """No device: one line naming it (while it waits, and as the error at the end), not only `connected: false`."""
    usb_backend = pytest.importorskip("usb.backend.libusb1")
    if usb_backend.get_backend() is None:
        pytest.skip("no libusb-1.0 here")
    rig = tmp_path / "rig.toml"
    rig.write_text("[trackball]\nvendor_id = 0xfffe\nproduct_id = 0xfffd\n")
    assert main(["trackball", "--config", str(rig), "--seconds", "1.3", "--no-bus"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "no USB trackball fffe:fffd found" in err[-1] and err[-1].startswith("antarium trackball: error:")
    assert any("still waiting" in line and "fffe:fffd" in line for line in err[:-1])


@pytest.mark.parametrize("content", [b"\x89PNG\r\n\x1a\n\x00\x00", b""])
def test_cli_refuses_a_replay_file_that_is_not_a_fictrac_log(tmp_path, capsys, content):
    fake = tmp_path / "fake.png"
    fake.write_bytes(content)
    assert main(["trackball", "--source", "fictrac-replay", "--path", str(fake), "--seconds", "1", "--no-bus"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"--path {fake}: not a FicTrac .dat log" in err
