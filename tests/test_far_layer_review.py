"""The far layer's builder process as a trial relies on it: a builder that hangs mid-trial is noticed, killed and
reported (status error, hence the server's alarm), and frames are drawn in full, as when it dies (real EGL)."""

from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest
from conftest import wait_for

from antarium.core.childproc import ChildProcess
from antarium.core.pose import Pose
from antarium.renderers import far_layer, prepared
from antarium.renderers.habitat import habitat_scene
from antarium.renderers.renderer import Renderer


def _first_layer(r: Renderer, out: np.ndarray) -> None:
    deadline = time.monotonic() + 60
    while r.layer_frames == 0 and time.monotonic() < deadline:
        r.render(Pose(0.0, 0.0, 0.01, 0.0), out=out, t=0.0)
        time.sleep(0.005)
    assert r.layer_frames >= 1


def test_a_hung_builder_is_killed_and_reported(dome, monkeypatch):
    r = Renderer(dome, face_size=64, layer_face_size=64, far_layer="async")
    try:
        r.set_scene(habitat_scene(n_tussocks=60, n_stones=20, n_bushes=3, n_trees=2))
        out = np.empty((20350, 2), np.uint16)
        _first_layer(r, out)
        pid = r.far_layer_status()["pid"]
        monkeypatch.setattr(far_layer, "BUILD_TIMEOUT_S", 0.5, raising=False)
        os.kill(pid, signal.SIGSTOP)  # hung: alive, never answers
        try:
            k, deadline = 0, time.monotonic() + 20
            while not r.far_layer_status()["error"] and time.monotonic() < deadline:
                k += 1  # the ant walks 1 mm a frame: new layers are asked for
                r.render(Pose(0.001 * k, 0.0, 0.01, 0.0), out=out, t=0.0)
                time.sleep(0.01)
            status = r.far_layer_status()
            assert f"far-layer process {pid} hung" in status["error"]
            with pytest.raises(ProcessLookupError):  # killed and reaped, not left stopped until the next scene
                os.kill(pid, 0)
            r.render(Pose(0.001 * k, 0.0, 0.01, 0.0), out=out, t=0.0)
            assert r.far_layer_status()["full_frames"] == status["full_frames"] + 1
            assert out.any()
        finally:
            try:
                os.kill(pid, signal.SIGCONT)
            except ProcessLookupError:
                pass
    finally:
        r.release()


SMALL_HABITAT = {"scene": "habitat", "n_tussocks": 60, "n_stones": 20, "n_bushes": 3, "n_trees": 2}


def _hung_prepare(dome, monkeypatch, then) -> tuple[list, ChildProcess]:
    """prepare_scene in a thread, its scene's process stopped (SIGSTOP: alive, never answering) as it starts, then
    `then(renderer)`; returns (what the thread raised or returned, the process) once the thread has ended (30 s)."""
    started: list[ChildProcess] = []

    def spied(*args, **kwargs):
        child = ChildProcess(*args, **kwargs)
        os.kill(child.pid, signal.SIGSTOP)
        started.append(child)
        return child

    monkeypatch.setattr(prepared, "ChildProcess", spied)
    r = Renderer(dome, face_size=64, layer_face_size=64, far_layer="async")
    outcome: list = []

    def run() -> None:
        try:
            outcome.append(prepared.prepare_scene(r, SMALL_HABITAT))
        except Exception as exc:  # noqa: BLE001 - what the test looks at
            outcome.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        assert wait_for(lambda: started, 10.0)
        then(r)
        thread.join(30)
        assert not thread.is_alive(), "prepare_scene still waits for a scene process that never answers"
    finally:
        if thread.is_alive():  # the code before the fix: end the wait so that nothing is left behind
            started[0].kill()
            thread.join(10)
        r.release()
    return outcome, started[0]


def test_a_scene_process_that_never_answers_fails_the_load(dome, monkeypatch):
    monkeypatch.setattr(prepared, "PREPARE_TIMEOUT_S", 1.0, raising=False)
    outcome, child = _hung_prepare(dome, monkeypatch, lambda r: None)
    assert isinstance(outcome[0], RuntimeError) and "did not answer within 1 s (hung)" in str(outcome[0])
    assert not child.running


def test_a_prepare_ends_when_its_renderer_is_released(dome, monkeypatch):
    outcome, child = _hung_prepare(dome, monkeypatch, lambda r: r.release())
    assert isinstance(outcome[0], RuntimeError) and "renderer was released" in str(outcome[0])
    assert not child.running
