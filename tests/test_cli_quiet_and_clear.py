"""CLI manners: no files nobody asked for, progress while a long benchmark works, no unsafe advice."""

from __future__ import annotations

import numpy as np

from antarium.cli import main


def test_layout_export_writes_only_the_table(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["layout", "--export", "leds.csv"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["leds.csv"]
    assert "picture:" not in capsys.readouterr().out


def test_layout_export_to_a_bad_name_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["layout", "--export", "missing/leds.csv"]) == 2
    assert main(["layout", "--export", "leds.txt"]) == 2
    out, err = capsys.readouterr()
    assert out == ""  # no summary printed before the refusal
    assert err.splitlines() == ["antarium layout: error: --export: folder 'missing' does not exist",
                                "antarium layout: error: --export file must end in .csv or .json, got 'leds.txt'"]
    assert list(tmp_path.iterdir()) == []


def test_layout_draws_pictures_by_default_and_with_out(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["layout", "--export", "leds.csv", "--out", "pics"]) == 0
    assert sorted(p.name for p in (tmp_path / "pics").iterdir()) == ["layout_3d.png", "layout_mollweide.png"]


def test_bench_render_says_what_it_is_doing_before_each_workload(monkeypatch, capsys):
    from antarium.bench import render as bench
    from antarium.renderers.library import build_scene

    calls = []

    def fake_measure(renderer, scene, frames, warmup=20):   # the GL work itself is not what is tested here
        calls.append(capsys.readouterr().err)
        return {"scene": scene.name, "triangles": scene.n_triangles, "frames": frames, "fps": 1.0,
                "ms_per_frame": 1.0, "cpu_ms_per_frame": 1.0, "builder_cpu_ms_per_frame": 0.0,
                "render_ms": 1.0, "sample_ms": 0.0, "convert_ms": 0.0}

    monkeypatch.setattr(bench, "measure", fake_measure)
    monkeypatch.setattr(bench, "workloads", lambda: {"grating": (lambda: build_scene("grating"), {}),
                                                     "habitat-layer": (lambda: build_scene("uniform"), {})})
    assert main(["bench", "render", "--frames", "3"]) == 0
    assert len(calls) == 2
    assert "workload 1/2 'grating' on the cpu path: 3 frames" in calls[0] and "workload 2/2 'habitat-layer'" in calls[1]


def test_a_bad_model_file_does_not_suggest_unpickling(tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"garbage")
    assert main(["ant", "run", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "bad.npz: not an antarium ant model file" in err and "pickle" not in err


def test_a_model_file_that_is_an_npz_of_something_else_is_named(tmp_path, capsys):
    other = tmp_path / "other.npz"
    np.savez(other, x=np.zeros(3))
    assert main(["ant", "run", str(other), "--out", str(tmp_path / "o")]) == 2
    assert "other.npz: not an antarium ant model file" in capsys.readouterr().err
