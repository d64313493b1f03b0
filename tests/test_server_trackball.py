"""The server with the (emulated) USB trackball as its source: unplugging it holds the pose, marks the log
and publishes an event; plugging it back resumes the closed loop."""

import pytest
from conftest import wait_for

from antarium.config import resolve
from antarium.server import Server
from antarium.trial_log import read_table


def test_unplugged_trackball_holds_the_pose_and_resumes(tmp_path):
    config = resolve({"rig": {"name": "ttb"}, "bus": {"enabled": False},
                      "locomotion": {"source": "usb", "emulate": True},
                      "log": {"dir": str(tmp_path), "flush_s": 0.1}})
    lines = []
    server = Server(config, renderer_factory=None, link=False, record="unplug", echo=lines.append)
    server.start_thread()
    try:
        loop, device = server.loop, server.source.backend
        assert wait_for(lambda: loop.pose.x > 0.005, 10.0)
        device.unplug()
        assert wait_for(lambda: not loop.locomotion_connected, 5.0)
        held = loop.pose
        frames = loop.frame
        assert wait_for(lambda: loop.frame > frames + 40, 5.0)
        assert loop.pose == held
        assert "locomotion source disconnected" in " ".join(server.status()["alarms"])
        device.replug()
        assert wait_for(lambda: loop.locomotion_connected and loop.pose.x > held.x, 10.0)
    finally:
        server.stop()
    frames = read_table(server.trial_paths[0], "frames")
    assert (frames["locomotion_connected"] == 0).any() and frames["locomotion_connected"][-1] == 1
    kinds = list(read_table(server.trial_paths[0], "events")["kind"])
    assert kinds.index("locomotion_lost") < kinds.index("locomotion_back")
    x_while_lost = frames["x"][frames["locomotion_connected"] == 0]
    assert x_while_lost == pytest.approx(x_while_lost[0])
    # stderr names the device and what to check, not the source's ~30 status counters (those are on the bus)
    lost = next(line for line in lines if line.startswith("antarium serve: locomotion_lost"))
    assert lost == ("antarium serve: locomotion_lost: usb 1209:0001 delivers nothing (USB error: [Errno 19] No such "
                    "device (it may have been disconnected)); the pose is held (losses so far: 1); plug it in and "
                    "check `lsusb`, the udev rule of docs/trackball_usb.md and [trackball] "
                    "vendor_id/product_id")
    assert "antarium serve: locomotion_back: usb 1209:0001 delivers again (losses so far: 1)" in lines
