"""Routes, the route frame, and the metrics of route following."""

import math

import numpy as np
import pytest

from antarium.ant.metrics import (
    RunSummary,
    arrived,
    median_mad,
    off_route,
    route_errors,
    stopping_distance,
)
from antarium.ant.routes import Route, RouteError, curved_route


def test_a_route_needs_two_distinct_finite_points(tmp_path):
    with pytest.raises(RouteError, match="at least two distinct points, got 1"):
        Route([[0, 0], [0, 0]])
    with pytest.raises(RouteError, match="at least two distinct points, got 1"):
        Route([[1.0, 2.0]])
    with pytest.raises(RouteError, match=r"\(n, 2\)"):
        Route([1, 2, 3])
    with pytest.raises(RouteError, match="finite"):
        Route([[0, 0], [math.nan, 1]])
    (tmp_path / "one.csv").write_text("x_m,y_m\n0.5,0.5\n")
    with pytest.raises(RouteError, match="at least two"):
        Route.load(tmp_path / "one.csv")


def test_route_files_round_trip(tmp_path):
    r = curved_route(3, length=2.0)
    r.save(tmp_path / "r.csv")
    np.testing.assert_allclose(Route.load(tmp_path / "r.csv").points, r.points)
    (tmp_path / "plain.txt").write_text("0 0\n1 0\n1 1\n")
    assert Route.load(tmp_path / "plain.txt").length == pytest.approx(2.0)


def test_a_heading_given_once_may_leave_the_cells_below_it_empty(tmp_path):
    """A spreadsheet exports a heading given only on the first row as empty cells below: refused before
    ("line 3: '' is not a number"); only the first row's heading is used. Empty x or y, or an empty first heading,
    are still refused with their line."""
    from antarium.ant.routes import read_route_file

    (tmp_path / "sheet.csv").write_text("x_m,y_m,heading_deg\n0,0,90\n1,0,\n1,1,\n")
    route, heading = read_route_file(tmp_path / "sheet.csv")
    assert route.length == pytest.approx(2.0) and heading == pytest.approx(math.pi / 2)
    (tmp_path / "plain.csv").write_text("0,0,45\n2,0,\n")
    assert read_route_file(tmp_path / "plain.csv")[1] == pytest.approx(math.pi / 4)
    for text, line in (("x_m,y_m,heading_deg\n0,0,90\n,0,\n", 3), ("x_m,y_m,heading_deg\n0,0,\n1,0,\n", 2)):
        (tmp_path / "bad.csv").write_text(text)
        with pytest.raises(RouteError, match=f"line {line}: '' is not a number"):
            read_route_file(tmp_path / "bad.csv")


def test_projection_gives_signed_lateral_error_and_the_route_heading():
    r = Route([[0, 0], [1, 0], [1, 1]])
    s, d, h = r.project([[0.5, 0.1], [0.5, -0.2], [1.2, 0.5]])
    np.testing.assert_allclose(s, [0.5, 0.5, 1.5])
    np.testing.assert_allclose(d, [0.1, -0.2, -0.2])      # left of the direction of travel is positive
    np.testing.assert_allclose(h, [0, 0, math.pi / 2])
    pts, heads = r.sample(0.5)
    assert len(pts) == 5 and heads[-1] == pytest.approx(math.pi / 2)


def test_curved_routes_are_seeded_smooth_and_as_long_as_asked():
    a, b, c = curved_route(1), curved_route(1), curved_route(2)
    np.testing.assert_array_equal(a.points, b.points)
    assert not np.allclose(a.points, c.points)
    assert a.length == pytest.approx(10.0, rel=1e-6)
    turn = np.diff(np.unwrap(np.arctan2(*np.diff(a.points, axis=0).T[::-1])))
    assert np.abs(turn).max() < math.radians(10)


def test_metrics_as_the_field_reports_them():
    r = Route([[0, 0], [2, 0]])
    lat, ang = route_errors(r, [[0.5, 0.1], [1.0, -0.3]], [math.radians(10), math.radians(-20)])
    np.testing.assert_allclose(lat, [0.1, 0.3])
    np.testing.assert_allclose(np.degrees(ang), [10, 20])
    assert median_mad([1, 2, 3, 4, 100]) == (3.0, 1.0)
    assert list(off_route(r, [[1, 0.1], [1, 0.25]])) == [False, True]
    assert arrived(r, [[1.95, 0.02]], 0.1) and not arrived(r, [[1.5, 0]], 0.1)
    assert stopping_distance(r.reversed(), [0.3, 0.4]) == pytest.approx(0.5)  # homing: the nest is the end
    summary = RunSummary.of(r, [[0, 0.01], [1, 0.03], [2, 0.02]], [0, 0, 0], True, 1)
    assert summary.lateral_median == pytest.approx(0.02) and summary.distance == pytest.approx(2.0, abs=1e-3)
