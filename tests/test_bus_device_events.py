"""A trackball on another computer: its unplug reaches the server's bus source at once, not after the
silence timeout, and the loop's source recovers when the device is back."""

import json
import threading
import time

import pytest

from antarium import bus
from antarium.cli import main
from antarium.locomotion import BallSample, open_source, wire
from antarium.locomotion.bus import BusSource


def test_remote_unplug_marks_the_bus_source_disconnected_within_100_ms(tmp_path):
    endpoint = bus.free_tcp_endpoint()
    rig = tmp_path / "rig.toml"
    rig.write_text(f'[rig]\nname = "tev"\n\n[bus]\nlisten = ["{endpoint}"]\n')
    lost_at: list[float] = []
    with bus.open_session({"listen": [endpoint]}, "server") as server:
        server.declare_subscriber(
            bus.events_key("tev"),
            lambda s: lost_at.append(time.monotonic()) if b"locomotion_lost" in s.payload.to_bytes() else None,
        )
        # timeout_s 0.5 is longer than the 0.3 s outage: only the driver's event can reveal it
        src = open_source("bus", rig="tev", session=server, timeout_s=0.5)
        src.start()
        cli = threading.Thread(target=main, args=([
            "trackball", "--emulate", "--config", str(rig), "--seconds", "2.0", "--unplug-at", "0.8",
            "--replug-after", "0.3"],))
        cli.start()
        seen_false = None
        back = False
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and cli.is_alive():
            connected = src.status()["connected"]
            if not connected and seen_false is None:
                seen_false = time.monotonic()
            if seen_false is not None and connected:
                back = True
                break
            time.sleep(0.001)
        cli.join(30)
        src.stop()
    assert lost_at, "the trackball published no locomotion_lost event"
    assert seen_false is not None, "the bus source never reported the unplug"
    assert seen_false - lost_at[0] < 0.1
    assert back, "the bus source did not recover after the replug"
    assert "locomotion_lost" in src.status()["last_error"]


class _Payload:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data

    def to_string(self) -> str:
        return self.data.decode()


class _Sample:  # what a zenoh subscriber's callback gets, at the seam the bus source reads
    def __init__(self, data: bytes) -> None:
        self.payload = _Payload(data)


def _ball(seq: int) -> _Sample:
    return _Sample(wire.encode(BallSample(0.0, seq, (0.0, -0.001, 0.0))))


def _lost(**extra) -> _Sample:
    return _Sample(json.dumps({"event": "locomotion_lost", "source": "usb", "reason": "unplugged", **extra}).encode())


@pytest.mark.parametrize("stragglers", [[], [9], [8, 9]])
def test_samples_published_before_an_unplug_do_not_hide_it_when_they_arrive_after_its_event(stragglers):
    # each subscription has its own zenoh thread: the driver's last samples (up to seq 9) may come after its event
    src = BusSource("tev", session=object(), timeout_s=0.5)
    for seq in range(10 - len(stragglers)):
        src._on_sample(_ball(seq))
    src._on_event(_lost(last_seq=9))
    assert src.status()["connected"] is False
    for seq in stragglers:
        src._on_sample(_ball(seq))
        assert src.status()["connected"] is False, f"sample {seq} was published before the unplug"
    src._on_sample(_ball(0))  # the device is back (its sequence restarted): this one is new
    assert src.status()["connected"] is True
    assert src.received == 11


def test_without_last_seq_the_next_sample_clears_the_loss_and_back_always_does():
    src = BusSource("tev", session=object(), timeout_s=0.5)
    src._on_sample(_ball(1))
    src._on_event(_lost())
    assert src.status()["connected"] is False
    src._on_sample(_ball(2))
    assert src.status()["connected"] is True
    src._on_event(_lost(last_seq=5))  # sample 5 never arrives: "locomotion_back" still resumes it
    src._on_event(_Sample(b'{"event": "locomotion_back", "source": "usb"}'))
    assert src.status()["connected"] is True


def test_an_event_nested_too_deeply_is_skipped_by_the_bus_source_without_a_traceback(capfd):
    """A JSON array nested 100,000 deep overflows Python's JSON reader (RecursionError, not ValueError): it is a
    malformed message like any other, skipped without an exception in the bus thread; the next event is read."""
    deep = b"[" * 100_000
    assert bus.json_object(deep) is None
    endpoint = bus.free_tcp_endpoint()
    with bus.open_session({"listen": [endpoint]}, "server") as server, \
            bus.open_session({"listen": [endpoint]}, "client") as driver:
        src = open_source("bus", rig="tdeep", session=server, timeout_s=30.0)
        src.start()
        try:
            time.sleep(0.5)  # the subscription reaches the driver's session
            driver.put(bus.events_key("tdeep"), deep)
            driver.put(bus.events_key("tdeep"), json.dumps({"event": "locomotion_lost", "source": "usb"}))
            deadline = time.monotonic() + 10
            while src.status()["connected"] and time.monotonic() < deadline:
                time.sleep(0.01)
            assert not src.status()["connected"]
        finally:
            src.stop()
    assert "RecursionError" not in capfd.readouterr().err
