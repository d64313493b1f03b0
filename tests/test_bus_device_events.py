"""A trackball on another computer: its unplug reaches the server's bus source at once, not after the
silence timeout, and the loop's source recovers when the device is back."""

import threading
import time

from antarium import bus
from antarium.cli import main
from antarium.locomotion import open_source


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
