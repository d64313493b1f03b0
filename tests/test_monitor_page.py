"""The monitor page in headless chromium (as tests/test_monitor_browser.py) against `antarium monitor` and a stand-in
rig on the bus (a zenoh session publishing what the test sets: poses, status, events, LED frames, raw payloads):
data the page cannot show never stops it, nothing from the bus is shown as HTML, LED payloads it cannot draw never
stop its LED frames, and a websocket that reconnects does not draw the path twice."""

from __future__ import annotations

import json
import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest
from test_monitor_browser import _start_monitor, _stop, _wait, open_chromium

from antarium import bus
from antarium.monitor.led_stream import encode_leds, led_key

RIG = "tpage"


@pytest.fixture(scope="module")
def page_browser():
    driver = open_chromium()
    yield driver
    driver.quit()


class FakeRig:
    """Publishes, every 50 ms, a pose (frame +5 each time, at `x`, `y`), an LED frame numbered `led_frame` (or
    `raw`, a payload as it is, when set) and `status`; `event()` publishes one event."""

    def __init__(self, endpoint: str) -> None:
        self.session = bus.open_session({"listen": [endpoint]}, role="server")
        self.token = self.session.liveliness().declare_token(bus.alive_key(RIG))
        self.x, self.y, self.frame, self.poses = 0.0, 0.0, 0, 0
        self.led_frame, self.raw = 1, None
        self.status = {"t": 0.0, "scene": None, "trial": None, "frame_rate_hz": 190.0}
        self.values = np.full((20350, 2), 3000, np.uint16)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            self.frame += 5
            pose = SimpleNamespace(x=self.x, y=self.y, z=0.0, heading=0.1)  # a Pose refuses NaN; the bus need not
            self.session.put(bus.pose_key(RIG), bus.encode_pose(self.frame, self.frame / 190, pose, 0.0, True, False))
            self.poses += 1
            raw = self.raw
            self.session.put(led_key(RIG), raw if raw is not None else
                             encode_leds(self.led_frame, self.frame / 190, time.time(), self.values))
            self.session.put(bus.status_key(RIG), json.dumps({**self.status, "t": self.frame / 190}))
            time.sleep(0.05)

    def event(self, event: dict) -> None:
        self.session.put(bus.events_key(RIG), json.dumps(event))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        self.token.undeclare()
        self.session.close()


@pytest.fixture()
def rig(tmp_path):
    """(the stand-in rig, the monitor page's URL)."""
    endpoint = bus.free_tcp_endpoint()
    config = tmp_path / "rig.toml"
    config.write_text(f'[rig]\nname = "{RIG}"\n[bus]\nlisten = ["{endpoint}"]\n')
    fake = FakeRig(endpoint)
    monitor, url = _start_monitor(config)
    try:
        yield fake, url
    finally:
        _stop(monitor)
        fake.close()


def _m(driver, name: str):
    return driver.execute_script(f"return window.antariumMonitor.{name}")


def _shows_led_frame(driver, rig: FakeRig, frame: int) -> None:
    rig.led_frame = frame
    _wait(lambda: _m(driver, "frame") == frame, 30, f"the page draws LED frame {frame}")


def test_a_pose_without_position_and_status_of_the_wrong_types_never_stop_the_page(page_browser, rig):
    rig, url = rig
    rig.x = 0.25
    page_browser.get(url)
    _shows_led_frame(page_browser, rig, 10)
    _wait(lambda: "0.250, 0.000" in page_browser.find_element("id", "poseinfo").text, 30, "the page shows x, y")
    rig.x = float("nan")  # sent to the page as null
    _wait(lambda: "–, 0.000" in page_browser.find_element("id", "poseinfo").text, 30, "x shown as –")
    _shows_led_frame(page_browser, rig, 20)  # the page still draws
    # status fields of types the page does not expect
    rig.status = {**rig.status, "telemetry": {"polariser_angles_deg": "broken"}, "alarms": "disk <b>full</b>",
                  "frame_rate_hz": "fast", "latency": [1, 2]}
    _wait(lambda: page_browser.find_element("id", "alarms").text == "disk <b>full</b>", 30, "the alarm shown")
    _shows_led_frame(page_browser, rig, 30)
    rig.x = 0.5  # and the path and pose go on too
    _wait(lambda: "0.500, 0.000" in page_browser.find_element("id", "poseinfo").text, 30, "the page shows x again")
    assert "fast" not in page_browser.find_element("id", "loop").text  # shown as "–", not thrown on


def test_nothing_from_the_bus_is_shown_as_html(page_browser, rig):
    rig, url = rig
    name = '<img src=x onerror="window.pwned=1">cond-A'
    page_browser.get(url)
    _shows_led_frame(page_browser, rig, 10)
    rig.event({"t": 1.0, "kind": "trial_started", "data": {"name": name, "metadata": {"note": "<i>x</i> a<b"}}})
    rig.status = {**rig.status, "trial": name, "alarms": ["<img src=y onerror=\"window.pwned=2\">alarm"],
                  "telemetry": {"<b>key</b>": "<img src=z onerror=\"window.pwned=3\">"}}
    _wait(lambda: "cond-A" in page_browser.find_element("id", "trial").text
          and "alarm" in page_browser.find_element("id", "alarms").text
          and "note" in page_browser.find_element("id", "trial").text, 30, "the trial and alarm shown")
    _shows_led_frame(page_browser, rig, 20)  # the page went on past drawing them
    shown = {k: page_browser.find_element("id", k).text for k in ("trial", "alarms", "telemetry")}
    assert name in shown["trial"] and "note: <i>x</i> a<b" in shown["trial"], shown
    assert shown["alarms"] == '<img src=y onerror="window.pwned=2">alarm', shown
    assert '<b>key</b> <img src=z onerror="window.pwned=3">' in shown["telemetry"], shown
    assert page_browser.execute_script("return document.querySelectorAll('img, b, i').length") == 0
    assert page_browser.execute_script("return window.pwned") is None


def test_led_payloads_the_page_cannot_draw_never_stop_its_led_frames(page_browser, rig):
    rig, url = rig
    page_browser.get(url)
    _shows_led_frame(page_browser, rig, 10)
    # payloads that are no LED frames of this version, each the newest on the bus for a while (the monitor sends a
    # page only the newest): each would hold one of the page's two LED frames in flight for good
    other_version = bytearray(encode_leds(777777, 0.0, time.time(), np.full((20350, 2), 65535, np.uint16)))
    other_version[0] = 2
    for raw in (b"\x02" + bytes(20), bytes(other_version), b"\x01" + bytes(40)):
        rig.raw = raw
        time.sleep(0.3)
    rig.raw = None
    _shows_led_frame(page_browser, rig, 20)
    assert _m(page_browser, "ledsDropped") >= 1  # the monitor dropped them and told the page
    assert "LED frames not drawable" in page_browser.find_element("id", "ledsbad").text

    # and the page checks the header itself: a frame of another version or size is refused, its credit returned
    refused, frame = page_browser.execute_script("""
        const buf = new ArrayBuffer(28 + 4 * 20350), dv = new DataView(buf);
        dv.setUint8(0, 2); dv.setUint16(2, 2, true); dv.setUint32(4, 777777, true); dv.setUint32(8, 20350, true);
        const before = window.antariumMonitor.ledsRefused;
        onLeds(buf); onLeds(new ArrayBuffer(21)); onLeds(buf.slice(0, 28 + 4 * 20349));
        return [window.antariumMonitor.ledsRefused - before, window.antariumMonitor.frame];""")
    assert refused == 3 and frame != 777777
    _shows_led_frame(page_browser, rig, 30)
    assert _m(page_browser, "frame") != 777777


def test_a_reconnected_page_does_not_draw_the_path_twice(page_browser, rig):
    rig, url = rig
    page_browser.get(url)
    _wait(lambda: (_m(page_browser, "pathLength") or 0) > 10, 30, "the page has a path")

    def walk():  # the stand-in walks along +x: x grows with every pose
        while not done.is_set():
            rig.x += 0.001
            time.sleep(0.01)

    done = threading.Event()
    walker = threading.Thread(target=walk, daemon=True)
    walker.start()
    try:
        _wait(lambda: (_m(page_browser, "pathLength") or 0) > 20, 30, "the path grows")
        page_browser.execute_script("window.oldSocket = socket; socket.close();")  # what a network blip does
        _wait(lambda: page_browser.execute_script(
            "return socket !== window.oldSocket && socket.readyState === 1"), 30, "the page reconnects")
        after = _m(page_browser, "updates")
        _wait(lambda: _m(page_browser, "updates") > after + 3, 30, "updates after the reconnection")
        xs = page_browser.execute_script("return path.map((p) => p[1])")
        poses = rig.poses
    finally:
        done.set()
        walker.join(5)
    backwards = sum(1 for a, b in zip(xs, xs[1:], strict=False) if b < a)
    assert backwards == 0 and len(xs) <= poses, (backwards, len(xs), poses)


def test_a_rig_whose_server_sends_no_led_frames_is_said_on_the_page(page_browser, rig):
    """`[monitor] leds_every_frames = 0` on the server: the dome stays dark, and the page says why."""
    rig, url = rig
    page_browser.get(url)
    _shows_led_frame(page_browser, rig, 10)
    assert page_browser.find_element("id", "ledsoff").text == ""
    rig.status = {**rig.status, "led_stream_every_frames": 0}
    _wait(lambda: "leds_every_frames = 0" in page_browser.find_element("id", "ledsoff").text, 30, "the page says so")
    assert "sends no LED frames" in page_browser.find_element("id", "ledsoff").text
    rig.status = {**rig.status, "led_stream_every_frames": 5}
    _wait(lambda: page_browser.find_element("id", "ledsoff").text == "", 30, "the note goes with the stream back")
