"""What the monitor keeps of the rig's streams (`antarium.monitor.hub.Hub`), fed samples directly as zenoh's
callbacks would give them (a stand-in session records the callbacks): LED payloads that are not this version's dome
frames are dropped and counted, never forwarded to a page; a restarted rig's path is not joined to its last run's."""

from __future__ import annotations

import numpy as np
import zenoh

from antarium import bus
from antarium.core.pose import Pose
from antarium.monitor.hub import PATH_EVERY, Hub
from antarium.monitor.led_stream import encode_leds


class _Payload:
    def __init__(self, data: bytes) -> None:
        self._data = data

    def to_bytes(self) -> bytes:
        return self._data


class _Sample:
    def __init__(self, data: bytes = b"", kind=None) -> None:
        self.payload, self.kind = _Payload(data), kind


class _Sub:
    def undeclare(self) -> None:
        pass


class _Session:
    """What `Hub` asks of a zenoh session: subscribers (their callbacks kept here by key) and liveliness."""

    def __init__(self) -> None:
        self.callbacks: dict[str, object] = {}

    def declare_subscriber(self, key, callback, **_):
        self.callbacks[key] = callback
        return _Sub()

    def liveliness(self):
        return self


def _hub() -> tuple[Hub, _Session]:
    session = _Session()
    return Hub(session, "thub"), session


def _pose(hub: Hub, frame: int, t: float, x: float) -> None:
    p = Pose(x, 0.0, 0.0, 0.0)
    hub._on_pose(_Sample(bus.encode_pose(frame, t, p, 0.0, True, False)))


def _alive(hub: Hub, up: bool) -> None:
    hub._on_alive(_Sample(kind=zenoh.SampleKind.PUT if up else zenoh.SampleKind.DELETE))


def test_led_payloads_a_page_cannot_draw_are_dropped_and_counted():
    hub, _ = _hub()
    good = encode_leds(10, 0.1, 0.0, np.full((20350, 2), 7, np.uint16))
    other_version = bytearray(encode_leds(777, 0.1, 0.0, np.full((20350, 2), 7, np.uint16)))
    other_version[0] = 2
    for bad in (b"\x02" + bytes(20), bytes(other_version), good[:-2],
                encode_leds(11, 0.1, 0.0, np.zeros((100, 2), np.uint16)),  # not the dome's pixel count
                encode_leds(12, 0.1, 0.0, np.zeros((20350, 3), np.uint16))):
        hub._on_leds(_Sample(bad))
    assert hub.leds is None and hub.leds_dropped == 5
    hub._on_leds(_Sample(good))
    leds, updates = hub.since({})
    assert leds == good
    assert updates["leds_dropped"]["count"] == 5 and "3 channels" in updates["leds_dropped"]["error"]


def _xs(updates: dict) -> list[float]:
    return [p[1] for p in updates.get("path", [])]


def test_a_restarted_rig_starts_a_new_path():
    hub, _ = _hub()
    _alive(hub, True)
    for f in range(0, 50, PATH_EVERY):
        _pose(hub, f, f / 190, 1.0 + f / 1000)
    seen: dict = {}
    _, first = hub.since(seen)
    assert first["path_reset"] and _xs(first) == [1.0 + f / 1000 for f in range(0, 50, PATH_EVERY)]
    # the server stops (its liveliness token goes) and a new one starts at frame 0 at the origin
    _alive(hub, False)
    _alive(hub, True)
    for f in range(0, 20, PATH_EVERY):
        _pose(hub, f, f / 190, 0.0)
    _, after = hub.since(seen)  # a page open all along is told to draw the path anew
    assert after["path_reset"] and _xs(after) == [0.0] * 4
    _, opened_now = hub.since({})  # and a page opened now gets the new run's path only
    assert _xs(opened_now) == [0.0] * 4
    _, nothing_new = hub.since(seen)
    assert "path" not in nothing_new and "path_reset" not in nothing_new


def test_time_going_backwards_starts_a_new_path():
    """A restart the monitor did not see go (its liveliness lost and back within one update)."""
    hub, _ = _hub()
    for f in range(500, 600, PATH_EVERY):
        _pose(hub, f, f / 190, 2.0)
    seen: dict = {}
    hub.since(seen)
    for f in range(0, 20, PATH_EVERY):
        _pose(hub, f, f / 190, 0.0)
    _, after = hub.since(seen)
    assert after["path_reset"] and _xs(after) == [0.0] * 4
    ts = [p[0] for p in hub.since({})[1]["path"]]
    assert ts == sorted(ts)


def _json_sample(obj) -> _Sample:
    import json

    return _Sample(json.dumps(obj).encode())


def test_a_monitor_opened_during_a_trial_shows_its_start_and_metadata_from_the_status():
    """A monitor that subscribed after `trial_started` showed '(started before the monitor)' and no elapsed time for
    the whole trial: the status carries the trial's start and metadata."""
    hub, _ = _hub()
    hub._on_status(_json_sample({"trial": "late", "trial_started": {"t": 12.5, "metadata": {"ant": 7}}}))
    assert hub.trial == {"name": "late", "metadata": {"ant": 7}, "t_start": 12.5}
    hub._on_status(_json_sample({"trial": None, "trial_started": None}))
    assert hub.trial is None
    hub._on_status(_json_sample({"trial": "old server"}))  # a status without the key: shown as unknown, as before
    assert hub.trial == {"name": "old server", "metadata": None, "t_start": None}


def test_the_trial_start_from_the_event_and_from_the_status_is_the_same_instant():
    hub, _ = _hub()
    hub._on_event(_json_sample({"t": 12.5001, "kind": "trial_started",
                                "data": {"name": "a", "metadata": {}, "monotonic": 12.5, "utc": "x", "path": "p"}}))
    assert hub.trial == {"name": "a", "metadata": {}, "t_start": 12.5}
    hub._on_status(_json_sample({"trial": "a", "trial_started": {"t": 12.5, "metadata": {}}}))
    assert hub.trial == {"name": "a", "metadata": {}, "t_start": 12.5}
