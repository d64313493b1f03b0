"""`antarium serve` with `[locomotion] source = "servosphere"`: the simulated servosphere drives the emulated dome in
closed loop and the trial log holds its table next to the unchanged ones."""

import math

import numpy as np
import pytest

from antarium.config import resolve
from antarium.core.ball import pole_motion
from antarium.core.clock import SimulatedClock
from antarium.locomotion.servosphere.source import FAULTS
from antarium.server import Server
from antarium.trial_log import SERVOSPHERE_DTYPE, read_table


def small_renderer(render_cfg, clock=None):
    from antarium.renderers import Renderer

    return Renderer(face_size=55, clock=clock)


def test_serve_closes_the_loop_on_the_free_ants_walk(tmp_path):
    config = resolve({
        "rig": {"name": "tservo"},
        "bus": {"enabled": False},
        "log": {"dir": str(tmp_path / "logs"), "flush_s": 0.1},
        "render": {"scene": {"scene": "horizon", "elevation_deg": 5}},
        "link": {"interface": "virtual"},
        "loop": {"rate_hz": 190.0, "realtime_priority": 0, "cpu": "off", "ball_radius_m": 0.06},
        "locomotion": {"source": "servosphere", "simulation": {"seed": 5, "speed": 0.05, "meander": 1.0}},
    })
    server = Server(config, clock=SimulatedClock(), renderer_factory=small_renderer, record="servo",
                    echo=lambda line: None)
    server.run(seconds=1.0)
    rig = server.source.rig
    path = server.trial_paths[0]
    frames = read_table(path, "frames")
    samples = read_table(path, "locomotion")
    servo = read_table(path, "servosphere")
    assert len(frames["frame"]) >= 185 and frames["link_ok"][-1] == 1
    # the dome's pose moved by the ant's walk, reconstructed from the rotors' step counts
    moved = np.array([frames["x"][-1] - frames["x"][0], frames["y"][-1] - frames["y"][0]])
    walked = sum(np.array(pole_motion((rx, ry, rz), rig.geometry.sphere_radius)[:2])
                 for rx, ry, rz in zip(samples["rx"], samples["ry"], samples["rz"], strict=True))
    assert np.linalg.norm(moved) > 0.03 and np.linalg.norm(moved - walked) < 0.01 * rig.walked + 1e-3
    # the servosphere's own table: 700 rows a second with tracker error, commands and the ant's orientation
    assert set(SERVOSPHERE_DTYPE.names) <= set(servo)
    assert len(servo["t"]) == pytest.approx(700 * 1.0, rel=0.05)
    err = np.hypot(servo["err_x_mm"], servo["err_y_mm"])[50:]
    assert np.median(err) < 2.0 and np.all(servo["faults"] == 0)
    assert abs(math.remainder(float(servo["heading"][-1]) - rig.ant_heading, math.tau)) < math.radians(5)
    assert len(FAULTS) <= 32  # fits the faults column
    assert server.source.loop.geometry.sphere_radius == 0.06  # the loop's ball


def test_two_ball_radii_are_refused():
    from antarium.locomotion import open_source

    with pytest.raises(ValueError, match="one value"):
        open_source("servosphere", clock=SimulatedClock(), ball_radius=0.05, rotors={"sphere_radius": 0.06})
