"""A distributor that never answers: the link is down from the first frame, and even a run shorter than the
start-up allowance reports the outage (issue 20, point 8)."""

import socket

from antarium.config import resolve
from antarium.server import Server


def _silent_udp_port() -> int:
    """A UDP port on loopback with nothing listening (bound, read and closed at once)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_missing_distributor_is_reported_from_the_start(tmp_path):
    config = resolve({
        "rig": {"name": "nodist"}, "bus": {"enabled": False}, "log": {"dir": str(tmp_path / "logs")},
        "link": {"interface": "udp", "spawn_emulator": False, "port": _silent_udp_port()},
        "loop": {"rate_hz": 100.0},
    })
    server = Server(config, renderer_factory=None, echo=lambda line: None)
    server.start_thread()
    try:
        status = server.status()
        assert status["link_ok"] is False
        assert any(a.startswith("dome link down: the distributor has not answered") for a in status["alarms"])
    finally:
        server.stop()
    assert server.final_stats["frames"] > 0 and not server.final_stats["link_ok"]
    assert server.final_stats["link_outages"] == 1  # a run shorter than 5 s still counts the dark dome
