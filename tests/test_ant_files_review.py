"""A modeller's files: model files and route files read right or refused in one line, outputs where asked."""

import numpy as np
import pytest

from antarium.ant.eye import EyeParams
from antarium.ant.models import make_model
from antarium.ant.routes import Route, RouteError
from antarium.ant.storage import ModelFileError, load_model, save_model
from antarium.cli import main

N_PN = 800


def test_a_single_array_file_named_npz_is_refused_naming_it(tmp_path):
    path = tmp_path / "ant.npz"
    with open(path, "wb") as fh:  # np.save to a handle: a .npy array whatever the name
        np.save(fh, np.zeros(3))
    with pytest.raises(ModelFileError, match=r"ant\.npz: not an antarium ant model file \(a single NumPy array"):
        load_model(path)


def test_saving_a_model_onto_a_folder_is_refused_and_leaves_nothing(tmp_path):
    (tmp_path / "ant").mkdir()
    model = make_model("ardin", N_PN, seed=1)
    with pytest.raises(IsADirectoryError, match="is a folder; give the model file"):
        save_model(tmp_path / "ant", model, EyeParams())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ant"]


def test_learn_refuses_an_out_folder_before_the_learning_walk(tmp_path, capsys):
    (tmp_path / "models").mkdir()
    log = tmp_path / "walk.h5"
    rc = main(["ant", "learn", "--model", "ardin", "--route", "curved:1", "--length", "0.3", "--log", str(log),
               "--out", str(tmp_path / "models")])
    assert rc == 2 and "is a folder; give the model file" in capsys.readouterr().err
    assert not log.exists()  # refused before the walk ran (its log is the walk's first output)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["models"]


def test_a_route_files_header_names_its_columns(tmp_path):
    (tmp_path / "yx.csv").write_text("y_m,x_m\n0,0\n0,1\n0,2\n")
    np.testing.assert_array_equal(Route.load(tmp_path / "yx.csv").points, [[0, 0], [1, 0], [2, 0]])
    (tmp_path / "txy.csv").write_text("t,x,y\n0,0,0\n1,1,0\n2,2,0\n")
    with pytest.raises(RouteError, match=r"txy\.csv: header 't, x, y' — a route file's header names the columns"):
        Route.load(tmp_path / "txy.csv")


def test_a_route_file_may_open_with_a_comment_or_a_blank_line(tmp_path):
    (tmp_path / "r.csv").write_text("# walked 2026-11-27\n\nx_m,y_m,heading_deg\n0,0,90\n1,0,90\n1,1,90\n")
    np.testing.assert_array_equal(Route.load(tmp_path / "r.csv").points, [[0, 0], [1, 0], [1, 1]])


@pytest.mark.parametrize("text, message", [
    ("x_m,y_m\n-1e308,0\n1e308,0\n", "length must be a finite number of metres"),
    ("", "empty route file"),
    ("x_m,y_m\n0,0\nnan,1\n", "line 3: 'nan' is not a finite number"),
    ("x_m,y_m\n0.5,0.5\n0.5,0.5\n", r"r\.csv: a route needs at least two distinct points, got 1"),
])
def test_an_odd_route_file_is_refused_naming_the_file(tmp_path, text, message):
    (tmp_path / "r.csv").write_text(text)
    with pytest.raises(RouteError, match=message):
        Route.load(tmp_path / "r.csv")


def test_learn_reads_a_route_file_by_its_header(tmp_path, monkeypatch):
    """`ant learn --route FILE` follows the header's column order (the learned route is stored in the model)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "yx.csv").write_text("y_m,x_m\n0,0\n0,0.1\n0,0.2\n")
    assert main(["ant", "learn", "--model", "ardin", "--route", "yx.csv", "--spacing", "0.1",
                 "--out", "ant.npz"]) == 0
    _, _, route = load_model(tmp_path / "ant.npz")
    np.testing.assert_array_equal(route, [[0, 0], [0.1, 0], [0.2, 0]])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ant.npz", "yx.csv"]


def _logged_scene(log) -> str:
    import json

    import h5py

    with h5py.File(log, "r") as f:
        return json.loads(f.attrs["config"])["ant"]["scene"]


def test_run_shows_the_model_the_scene_it_learned_in(tmp_path, monkeypatch, capsys):
    """A model learned in `--scene bars` is released in bars, not in the default habitat (its file says where)."""
    monkeypatch.chdir(tmp_path)
    assert main(["ant", "learn", "--model", "ardin", "--route", "curved:1", "--length", "0.2", "--scene", "bars",
                 "--out", "ant.npz"]) == 0
    assert main(["ant", "run", "ant.npz", "--max-decisions", "2", "--out", "run"]) == 0
    assert _logged_scene(tmp_path / "run" / "run.h5") == "bars"
    assert main(["ant", "run", "ant.npz", "--max-decisions", "2", "--scene", "uniform", "--out", "run2"]) == 0
    assert _logged_scene(tmp_path / "run2" / "run.h5") == "uniform"
    assert "scene: uniform" in capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ant.npz", "run", "run2"]
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["run.h5", "run.json", "run_paths.png",
                                                                   "run_traces.png"]


@pytest.mark.parametrize("option, value", [("--lateral-cm", "nan"), ("--heading-deg", "inf")])
def test_run_refuses_a_non_finite_release_before_writing(tmp_path, monkeypatch, capsys, option, value):
    monkeypatch.chdir(tmp_path)
    model = make_model("ardin", N_PN, seed=1)
    save_model(tmp_path / "ant.npz", model, EyeParams(), route=np.array([[0, 0], [0.2, 0.0]]))
    assert main(["ant", "run", "ant.npz", option, value, "--out", "run"]) == 2
    assert f"{option} must be a finite number" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ant.npz"]  # no folder, no log blocking the next run
