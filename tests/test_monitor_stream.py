"""The decimated LED stream (`antarium/<rig>/leds`): golden bytes, refusals, and what the server publishes is what
the (virtual) dome shows; the `[monitor]` section's checks."""

import asyncio
import json
import os
import threading

import numpy as np
import pytest
from conftest import wait_for

from antarium import bus
from antarium.config import ConfigError, resolve
from antarium.firmware_proto.link import open_link
from antarium.firmware_proto.video import VIDEO_HEADER_SIZE, decode_panel_data, encode_frame
from antarium.monitor.led_stream import LED_HEADER, LedPublisher, decode_leds, encode_leds, led_key
from antarium.monitor.settings import allowed
from antarium.server import Server


def test_golden_bytes_and_round_trip():
    values = np.array([[1, 2], [0x1234, 0xFFFF]], np.uint16)
    payload = encode_leds(7, 1.5, 2.0, values)
    assert payload == (bytes([1, 0, 2, 0, 7, 0, 0, 0, 2, 0, 0, 0]) + np.float64(1.5).tobytes()
                       + np.float64(2.0).tobytes() + bytes([1, 0, 2, 0, 0x34, 0x12, 0xFF, 0xFF]))
    d = decode_leds(payload, pixels=2)
    assert (d["frame"], d["t"], d["t_wall"]) == (7, 1.5, 2.0)
    np.testing.assert_array_equal(d["values"], values)
    assert LED_HEADER.size == 28 and f"{LED_HEADER.size}-byte header + 20,350 × 2 u16" in open("docs/bus.md").read()


@pytest.mark.parametrize("payload, pixels, message", [
    (b"\x01\x00", None, "at least 28 bytes"),
    (b"\x02" + bytes(27), None, "version 2 not supported"),
    (encode_leds(1, 0.0, 0.0, np.zeros((3, 2), np.uint16))[:-1], None, "must be 40 bytes, got 39"),
    (encode_leds(1, 0.0, 0.0, np.zeros((3, 3), np.uint16)), None, "3 channels; allowed: 2"),
    # by default only the dome's frames: 20,350 pixels
    (encode_leds(1, 0.0, 0.0, np.zeros((3, 2), np.uint16)), 20350, "3 pixels; the dome has 20350"),
    (encode_leds(1, 0.0, 0.0, np.zeros((20351, 2), np.uint16)), 20350, "20351 pixels; the dome has 20350"),
])
def test_malformed_payloads_are_refused(payload, pixels, message):
    with pytest.raises(bus.StreamError, match=message):
        decode_leds(payload, pixels=pixels)
    if pixels == 20350:
        with pytest.raises(bus.StreamError, match=message):
            decode_leds(payload)  # the default


def test_a_failed_put_is_counted_and_reported_and_the_stream_goes_on():
    """The LED stream's thread, on a stand-in zenoh session whose publisher's put fails twice, then works."""
    class Publisher:
        def __init__(self):
            self.sent, self.calls = [], 0

        def put(self, payload):
            self.calls += 1
            if self.calls <= 2:
                raise RuntimeError("zenoh: no route")
            self.sent.append(decode_leds(payload)["frame"])

        def undeclare(self):
            pass

    class Session:
        def declare_publisher(self, key):
            assert key == led_key("tput")
            return publisher

    publisher, lines = Publisher(), []
    stream = LedPublisher(Session(), "tput", every=1, report=lines.append)
    values = np.zeros((20350, 2), np.uint16)
    try:
        for frame in range(3):  # each offered once its thread has tried to put the one before
            stream.offer(frame, frame / 190, values)
            assert wait_for(lambda n=frame: publisher.calls > n, 5.0), f"frame {frame} was never put"
    finally:
        stream.close()
    assert publisher.sent == [2] and stream.failed == 2 and stream.last_error == "RuntimeError: zenoh: no route"
    assert lines == ["antarium serve: the LED stream's put failed (1 so far, the stream goes on): "
                     "RuntimeError: zenoh: no route"]


def test_the_stream_carries_the_frame_the_dome_shows(tmp_path):
    """Open loop, still pose, static scene: every frame is the same, so the newest frame on the stream must be what
    the panels of the emulator behind the virtual link latched (before their dot correction)."""
    config = resolve({"rig": {"name": "tleds"}, "bus": {"listen": [bus.free_tcp_endpoint()]},
                      "loop": {"closed_loop": False, "realtime_priority": 0, "cpu": "off"},
                      "render": {"scene": "horizon", "face_size_px": 64, "far_layer": "off"},
                      "log": {"dir": str(tmp_path)}, "monitor": {"leds_every_frames": 4}})
    link = open_link("virtual")
    got: list[dict] = []
    lock = threading.Lock()
    with Server(config, link=link, echo=lambda line: None).start_thread() as server:
        session = bus.open_session(config.bus, role="client")

        def keep(sample):
            with lock:
                got.append(decode_leds(sample.payload.to_bytes()))

        sub = session.declare_subscriber(led_key("tleds"), keep)
        assert wait_for(lambda: len(got) >= 10, 20.0)
        sub.undeclare()
        session.close()
        server.stop()
    shown = link.emulator.raw.reshape(20350, 2)  # the values the 55 panels latched, in global pixel order
    with lock:
        newest = got[-1]
    assert all(d["frame"] % 4 == 0 for d in got)
    assert newest["values"].shape == (20350, 2) and shown.max() > 0
    # the wire carries luma + 8-bit chroma: what the panels latch is the sent frame through that code
    on_wire = encode_frame(newest["values"], 0)[:, VIDEO_HEADER_SIZE:]
    np.testing.assert_array_equal(decode_panel_data(on_wire).reshape(20350, 2), shown)


def test_monitor_section_checks():
    s = resolve({"monitor": {"port": 0, "allow": ["10.1.2.3", "192.168.10.0/24"], "update_hz": 30}}).monitor
    assert s.allow == ["10.1.2.3/32", "192.168.10.0/24"] and s.update_hz == 30.0 and not s.commands
    assert allowed("192.168.10.7", s.allow) and not allowed("192.168.11.7", s.allow)
    assert allowed("::ffff:10.1.2.3", s.allow) and not allowed(None, s.allow)
    for bad, message in [({"colour": 1}, "unknown key 'colour' in \\[monitor\\]; allowed: allow, commands"),
                         ({"port": 70000}, "port must be in \\[0, 65535\\]"),
                         ({"commands": "yes"}, "commands must be true or false"),
                         ({"allow": ["lab"]}, "'lab' is not an address or network"),
                         ({"allow": []}, "allow is empty: no browser could open the page; name at least one")]:
        with pytest.raises(ConfigError, match=message):
            resolve({"monitor": bad})


def test_serve_starts_and_stops_the_monitor_when_the_config_enables_it(tmp_path):
    import socket
    import urllib.request

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    config = resolve({"rig": {"name": "tspawn"}, "bus": {"listen": [bus.free_tcp_endpoint()]},
                      "loop": {"realtime_priority": 0, "cpu": "off"}, "log": {"dir": str(tmp_path)},
                      "monitor": {"enabled": True, "port": port}})

    def page():
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=1) as r:
                return r.status == 200 and "antarium monitor" in r.read().decode()
        except OSError:
            return False

    async def websocket():  # a browser offers compression; the monitor sends LED frames as they are
        import aiohttp

        url = f"ws://127.0.0.1:{port}/ws"
        async with aiohttp.ClientSession() as session, session.ws_connect(url, compress=15) as ws:
            return ws.compress, json.loads((await ws.receive()).data)

    with Server(config, renderer_factory=None, link=False, echo=lambda line: None).start_thread() as server:
        assert wait_for(page, 30.0)
        compress, hello = asyncio.run(websocket())
        assert compress == 0 and hello["type"] == "hello" and hello["rig"] == "tspawn", (compress, hello)
        pid = server.monitor.child.pid
    with pytest.raises(ProcessLookupError):  # ended and reaped with the server
        os.kill(pid, 0)
    assert not page()
