"""The monitor over a long trial: it keeps the top views of the last few scenes only (a script that loads a scene of
new parameters per trial does not grow it without end); in the page (headless chromium against `antarium monitor`
and the stand-in rig of tests/test_monitor_page.py), a status field of odd content leaves the other tables following
the status, and a pose far from the others (a glitch kilometres away) never stops the path view or the page."""

from __future__ import annotations

import asyncio
import json

import pytest
from test_monitor_browser import _wait
from test_monitor_page import _m, _shows_led_frame, page_browser, rig  # noqa: F401 - pytest fixtures


def test_only_the_last_scenes_top_views_are_kept():
    from antarium.monitor.app import TopViews

    views = TopViews(kept=2)
    names = [json.dumps({"scene": "uniform", "value": k / 10}) for k in range(5)]

    async def ask(order):
        return [(await views.get(name))["scene"] for name in order]

    assert asyncio.run(ask(names)) == names  # each the view of the scene asked for
    assert views.names == names[-2:]
    asyncio.run(ask([names[3]]))  # asked for again: kept longest
    assert views.names == [names[4], names[3]]


def test_a_long_list_in_the_status_leaves_the_other_tables_live(page_browser, rig):  # noqa: F811
    rig, url = rig
    rig.status = {**rig.status, "trial": "first"}
    page_browser.get(url)
    _wait(lambda: "first" in page_browser.find_element("id", "trial").text, 30, "the trial shown")
    # 200,000 numbers: spread into Math.min they overflowed the stack, and the tables after it stopped following
    rig.status = {**rig.status, "trial": "second", "telemetry": {"currents_a": [0.5] * 200_000}}
    _wait(lambda: "second" in page_browser.find_element("id", "trial").text, 30, "the next trial shown")
    assert "0.50 .. 0.50 (200000)" in page_browser.find_element("id", "telemetry").text
    assert _m(page_browser, "errors") == 0, _m(page_browser, "lastError")


@pytest.mark.parametrize("far", [1e8, 1e16])
def test_a_pose_far_away_never_stops_the_page(page_browser, rig, far):  # noqa: F811
    rig, url = rig
    page_browser.get(url)
    _wait(lambda: (_m(page_browser, "pathLength") or 0) > 3, 30, "the page has a path")
    # 1e16 m: 0.1 added to it changed nothing, and the grid's loop never ended; 1e8 m from the path's start: 1e9
    # grid lines, the tab crashed (1e6 m: 19 s of the page's time)
    rig.x = far
    _wait(lambda: f"{far:.3f}" in page_browser.find_element("id", "poseinfo").text, 30, "the far pose shown")
    _shows_led_frame(page_browser, rig, 40)  # and the page goes on drawing
    grid = page_browser.execute_script("return gridText(gridStep(pathBox.span))")
    assert grid.endswith(" m") and float(grid[:-2]) * 40 >= far, grid  # at most 40 lines across the view
