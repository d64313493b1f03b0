"""An experiment's inputs as a second review found them: a route over a hole in the ground, and a world stated
with the wrong up axis."""

from __future__ import annotations

from pathlib import Path

import pytest

from antarium.ant.experiment.inputs import WorldSpec, eye_z
from antarium.ant.routes import Route, RouteError


def _ground_with_hole(path: Path) -> Path:
    """A 4 m ground at z = 0 (+z up, facing up) of one triangle: the half x >= y; the half x < y is a hole."""
    path.write_text("v -2 -2 0\nv 2 -2 0\nv 2 2 0\nf 1 2 3\n")
    return path


def _y_up_field(path: Path) -> Path:
    """A 4 m ground in the file's x-z plane (+y up, facing up) and a 0.2 m box on it: a y-up file."""
    lines = ["v -2 0 -2", "v 2 0 -2", "v 2 0 2", "v -2 0 2", "f 1 3 2", "f 1 4 3"]
    box = [(0.5, 0, -0.05), (0.6, 0, -0.05), (0.6, 0, 0.05), (0.5, 0, 0.05),
           (0.5, 0.2, -0.05), (0.6, 0.2, -0.05), (0.6, 0.2, 0.05), (0.5, 0.2, 0.05)]
    lines += [f"v {x} {y} {z}" for x, y, z in box]
    lines += ["f " + " ".join(str(i + 4) for i in f)
              for f in [(1, 2, 3, 4), (5, 8, 7, 6), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 8, 4), (4, 8, 5, 1)]]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_route_over_a_hole_in_the_ground_keeps_the_ground_before_it(tmp_path):
    """Route points over no surface (here a hole) keep the last ground height, where they raised IndexError."""
    world = WorldSpec(str(_ground_with_hole(tmp_path / "hole.obj")), eye_height_m=0.01)
    route = Route([(1.0, -1.0), (0.0, 0.0), (-1.0, 1.0)])   # starts on the ground, ends over the hole
    assert eye_z(world, route) == pytest.approx(0.01)


def test_a_world_stated_with_the_wrong_up_axis_is_one_line_naming_it(tmp_path):
    """A y-up file stated up = "z": its ground stands upright, nothing lies under the route, which is refused
    in one line pointing at the scale and up axis (it raised IndexError)."""
    obj = _y_up_field(tmp_path / "field.obj")
    route = Route([(0.0, 0.05), (0.3, 0.05)])
    assert eye_z(WorldSpec(str(obj), up="y", eye_height_m=0.01), route) == pytest.approx(0.01)
    with pytest.raises(RouteError, match=r"has no surface under it in world 'field'.*check its scale and up axis"):
        eye_z(WorldSpec(str(obj), up="z", eye_height_m=0.01), route)
