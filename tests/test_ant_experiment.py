"""Model experiments at scale: real route files and a mesh world at a stated scale and up axis, a TOML spec
expanded into runs, a LocalCluster of two workers on loopback giving the same rows as a serial run, seed for
seed, and a rerun after a kill that runs only what was not finished."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import textwrap
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")
pd = pytest.importorskip("pandas")

from antarium.ant.experiment.inputs import WorldSpec, eye_z, load_route, world_geometry  # noqa: E402
from antarium.ant.experiment.results import bootstrap_ci, load_results, report  # noqa: E402
from antarium.ant.experiment.runner import RUNS_DIR, run_experiment  # noqa: E402
from antarium.ant.experiment.spec import SpecError, expand, load_spec  # noqa: E402
from antarium.ant.routes import Route, RouteError  # noqa: E402

#: the run metrics that must not depend on which process ran it
SAME = ["lateral_median_m", "lateral_mad_m", "angular_median_deg", "angular_mad_deg", "arrived", "errors",
        "decisions", "distance_m", "learned_views", "memory_bytes"]


def _world_obj(path: Path) -> Path:
    """A 3 m x 3 m field in centimetres, +y up (as many modelling tools write OBJ): a terrain with a hill 8 cm high
    around (1.2, -1.2) m, six 40 cm boxes, a tree's canopy 3 m above the routes."""
    import trimesh

    g = np.linspace(-150.0, 150.0, 61)
    gx, gz = np.meshgrid(g, g, indexing="ij")          # file x, z (z is -y of the world)
    hill = 8.0 * np.exp(-((gx - 120.0) ** 2 + (gz - 120.0) ** 2) / (2 * 15.0 ** 2))
    verts = np.stack([gx.ravel(), hill.ravel(), gz.ravel()], 1)
    i = np.arange(60)[:, None] * 61 + np.arange(60)[None, :]
    faces = np.concatenate([np.stack([i, i + 1, i + 62], -1).reshape(-1, 3),
                            np.stack([i, i + 62, i + 61], -1).reshape(-1, 3)])
    parts = [trimesh.Trimesh(verts, faces, process=False)]
    rng = np.random.default_rng(3)
    for x, z in rng.uniform(-120, 60, (6, 2)):
        parts.append(trimesh.creation.box((20.0, 40.0, 20.0),
                                          trimesh.transformations.translation_matrix((x, 20.0, z))))
    parts.append(trimesh.creation.box((100.0, 10.0, 100.0),
                                      trimesh.transformations.translation_matrix((20.0, 300.0, 20.0))))
    trimesh.util.concatenate(parts).export(path)
    return path


@pytest.fixture(scope="module")
def field(tmp_path_factory):
    d = tmp_path_factory.mktemp("field")
    world = _world_obj(d / "field.obj")
    routes = d / "routes"
    routes.mkdir()
    for i, heading in enumerate((0.0, 2.0)):
        s = np.linspace(0, 0.25, 6)
        xy = np.stack([0.3 * i + s * math.cos(heading), -0.2 + s * math.sin(heading)], 1)
        text = "x_m,y_m,heading_deg\n" + "".join(f"{x:.4f},{y:.4f},{math.degrees(heading):.1f}\n" for x, y in xy)
        (routes / f"r{i}.csv").write_text(text)
    return d, world


def _spec(d: Path, models: str, extra: str = "", face_size: int = 64) -> Path:
    text = textwrap.dedent(f"""
        [experiment]
        face_size = {face_size}
        max_decisions = 12
        eye = {{cols = 10, rows = 4}}
        {extra}

        [[worlds]]
        scene = "field.obj"
        scale = 0.01
        up = "y"
        eye_height_m = 0.01

        [[route_sets]]
        paths = "routes"
    """) + models
    path = d / "spec.toml"
    path.write_text(text)
    return path


MODELS = """
[models.ardin]
n_kc = 200
[models.perfect_memory]
"""


def test_world_scale_and_up_axis_and_route_checks(field):
    d, obj = field
    world = WorldSpec(str(obj), scale=0.01, up="y", eye_height_m=0.01)
    geometry = world_geometry(world)
    assert geometry.extent == pytest.approx((-1.5, -1.5, 1.5, 1.5), abs=1e-6)   # cm, +y up -> m, +z up
    assert eye_z(world, load_route(d / "routes" / "r0.csv").route, geometry) == pytest.approx(0.01, abs=1e-6)
    with pytest.raises(RouteError, match="outside world"):
        eye_z(world, Route([(0.0, 0.0), (2.0, 0.0)]), geometry)
    with pytest.raises(RouteError, match="under the ground"):
        eye_z(world, Route([(0.9, -1.2), (1.35, -1.2)]), geometry)
    # stated in the wrong unit, the same route leaves the world
    with pytest.raises(RouteError, match="outside world"):
        eye_z(WorldSpec(str(obj), scale=0.001, up="y"), Route([(0.0, 0.0), (0.2, 0.0)]))


def test_route_file_heading_column_sets_the_release_heading(field):
    d, _ = field
    ri = load_route(d / "routes" / "r1.csv")
    assert ri.release_heading == pytest.approx(2.0, abs=1e-3)
    exp = load_spec(_spec(d, MODELS))
    r1 = [r for r in exp.runs if r.route == "r1"]
    assert r1 and all(abs(r.route_heading_deg) < 0.1 for r in r1)   # the file's heading is the route's own


def test_route_files_are_read_and_bad_ones_named_by_line(tmp_path):
    def route(name, text):
        (tmp_path / name).write_text(text)
        return tmp_path / name

    plain = load_route(route("plain.txt", "# a comment, with a comma\n0 0\n0.5 0\n1.0 0.1\n"))
    headed = load_route(route("headed.csv", "# field 3\ny_m, x_m\n\n0, 0\n0, 0.5\n0.1, 1.0\n"))
    np.testing.assert_allclose(headed.route.points, plain.route.points)
    assert plain.release_heading is None
    for name, text, message in [
        ("bad.csv", "x_m,y_m\n0,0\n\n1,abc\n", "bad.csv, line 4: 'abc' is not a number; a route file holds x_m"),
        ("ragged.csv", "0,0\n1,0,5\n", "ragged.csv, line 2: 3 columns where the rows before have 2"),
        ("header.csv", "x_m,y_m\n", "header.csv: a header and no points"),
        ("one.csv", "0\n1\n", "one.csv: a route file needs columns x_m, y_m (metres), got 1 column"),
    ]:
        with pytest.raises(RouteError) as err:
            load_route(route(name, text))
        assert message in str(err.value)


EXAMPLE_SPECS = sorted((Path(__file__).resolve().parent.parent / "examples" / "experiment").glob("*.toml"))
#: runs each example spec names in its comment (models x routes x grid points)
EXAMPLE_RUNS = {"ardin_eye": 1 * 13 * 4, "heldout_habitat": 3 * 6, "heldout_habitat_8m": 3 * 13, "sweep": 3 * 10 * 3}


@pytest.mark.parametrize("path", EXAMPLE_SPECS, ids=[p.stem for p in EXAMPLE_SPECS])
def test_the_example_specs_expand_into_the_runs_they_name(path):
    """Every spec in examples/experiment loads (its worlds built, its routes checked against them) and expands
    into the runs its comment names."""
    assert len(load_spec(path).runs) == EXAMPLE_RUNS[path.stem]


def test_bad_spec_gets_one_clear_line(field):
    d, _ = field
    with pytest.raises(SpecError, match="unknown parameter 'bogus'"):
        load_spec(_spec(d, "[models.ardin]\nbogus = 1\n"))
    with pytest.raises(SpecError, match="expected one of ardin, antcar, got 'sometimes'"):
        load_spec(_spec(d, MODELS, 'protocols = ["sometimes"]'))


@pytest.fixture(scope="module")
def pano(tmp_path_factory):
    """A folder with panorama worlds (pano.png, wa/pano.png, wb/pano.png: no mesh, nothing to check routes
    against) and a route folder, for fast in-process spec expansion."""
    import cv2

    d = tmp_path_factory.mktemp("pano")
    for folder, grey in (".", 200), ("wa", 150), ("wb", 100):
        (d / folder).mkdir(exist_ok=True)
        img = np.zeros((32, 64, 3), np.uint8)
        img[:16] = grey
        cv2.imwrite(str(d / folder / "pano.png"), img)
    (d / "routes").mkdir()
    (d / "routes" / "r1.csv").write_text("x_m,y_m\n0,0\n0.1,0\n0.2,0\n")
    return d


def _expand(d: Path, experiment: str = "", worlds: str = '[[worlds]]\nscene = "pano.png"\n',
            sets: str = '[[route_sets]]\npaths = "routes"\n', models: str = "[models.perfect_memory]\n"):
    return expand(tomllib.loads(f"[experiment]\n{experiment}\n{worlds}{sets}{models}"), d)


ANTCAR = "[models.antcar]\n"
#: (spec part, its text, the SpecError's message): one line naming the key, the value and what is allowed
BAD_SPECS = [
    # unknown keys in releases and curved (7)
    ("experiment", "releases = [{lateral_m = 0.05, heading = 20}]",
     "experiment.releases[0]: unknown key 'lateral_m'; allowed: lateral_cm, heading_deg"),
    ("sets", "[[route_sets]]\ncurved = {seeds = [0], length = 0.3}\n",
     "route_sets[0].curved: unknown key 'length'; allowed: seeds, length_m"),
    ("sets", '[[route_sets]]\npaths = "routes"\nnmae = "x"\n',
     "route_sets[0]: unknown key 'nmae'; allowed: name, paths, curved"),
    # integers: max_decisions >= 0 (0: three times the route), face_size 55..2048; no floats, no booleans (8)
    ("experiment", "max_decisions = -5", "experiment.max_decisions: expected an integer >= 0, got -5"),
    ("experiment", "max_decisions = 2.0", "experiment.max_decisions: expected an integer >= 0, got 2.0"),
    ("experiment", "max_decisions = true", "experiment.max_decisions: expected an integer >= 0, got True"),
    ("experiment", "face_size = 0", "experiment.face_size: expected an integer >= 55 and <= 2048, got 0"),
    ("experiment", "face_size = 64.9", "experiment.face_size: expected an integer >= 55 and <= 2048, got 64.9"),
    ("experiment", 'face_size = "big"', "experiment.face_size: expected an integer >= 55 and <= 2048, got 'big'"),
    ("experiment", "seeds = [-1]", "experiment.seeds[0]: expected an integer >= 0, got -1"),
    # empty lists give no runs (9)
    ("experiment", "seeds = []",
     "experiment.seeds: an empty list gives no runs; give at least one item (an integer >= 0)"),
    ("experiment", "protocols = []",
     "experiment.protocols: an empty list gives no runs; give at least one item (one of ardin, antcar)"),
    ("experiment", "releases = []",
     "experiment.releases: an empty list gives no runs; give at least one item (a table of lateral_cm, "
     "heading_deg)"),
    ("sets", "[[route_sets]]\ncurved = {seeds = [], length_m = 0.3}\n",
     "route_sets[0].curved.seeds: an empty list gives no runs; give at least one item (an integer >= 0)"),
    ("models", ANTCAR + "amplitude_deg = []\n",
     "models.antcar.amplitude_deg: an empty list gives no runs; give at least one item (a finite number)"),
    # types and values (10)
    ("experiment", "releases = [5]", "experiment.releases[0]: expected a table of lateral_cm, heading_deg, got 5"),
    ("experiment", "releases = {lateral_cm = 5}",
     "experiment.releases: expected a list, each item a table of lateral_cm, heading_deg, got {'lateral_cm': 5}"),
    ("experiment", "releases = [{lateral_cm = nan}]",
     "experiment.releases[0].lateral_cm: expected a finite number, got nan"),
    ("experiment", 'releases = [{heading_deg = "5"}]',
     "experiment.releases[0].heading_deg: expected a finite number, got '5'"),
    ("experiment", "eye = 5", "experiment.eye: expected a table of channel, cols, rows, elevation_min_deg, "
     "elevation_max_deg, sigma_deg, fine_per_col, fine_elevation_deg, neighbours, gamma, row_gain, got 5"),
    ("experiment", "eye = {cols = 10.5}", "experiment.eye.cols: expected an integer, got 10.5"),
    ("experiment", 'metrics = "errors"', "experiment.metrics: expected a list, each item one of "
     "lateral_median_m, lateral_mad_m, angular_median_deg, angular_mad_deg, arrived, errors, decisions, "
     "distance_m, ms_per_decision_model, ms_per_decision_loop, memory_bytes, learned_views, got 'errors'"),
    ("sets", "[[route_sets]]\ncurved = {seeds = [0], length_m = inf}\n",
     "route_sets[0].curved.length_m: expected a finite number > 0, got inf"),
    ("sets", '[[route_sets]]\npaths = "routes"\ncurved = {seeds = [0]}\n',
     'route_sets[0]: give one of paths = "folder or glob" or curved = {seeds = [...], length_m = ...}'),
    ("worlds", '[[worlds]]\nscene = "pano.png"\nscale = "0.01"\n',
     "worlds[0].scale: expected a finite number > 0, got '0.01'"),
    ("worlds", '[[worlds]]\nscene = "pano.png"\nseed = nan\n',
     "worlds[0].seed: expected a finite number, a string or true/false, got nan"),
    ("models", "[models]\nperfect_memory = 5\n", "models.perfect_memory: expected a table of scan_deg, "
     "scan_step_deg, step, eye.channel, eye.cols, eye.rows, eye.elevation_min_deg, eye.elevation_max_deg, "
     "eye.sigma_deg, eye.fine_per_col, eye.fine_elevation_deg, eye.neighbours, eye.gamma, eye.row_gain, "
     "learn_spacing_m, got 5"),
    ("models", ANTCAR + "amplitude_deg = nan\n", "models.antcar.amplitude_deg: expected a finite number, got nan"),
    ("models", ANTCAR + "amplitude_deg = " + "9" * 400 + "\n",  # TOML integers may be too large for a float
     "models.antcar.amplitude_deg: expected a finite number, got " + "9" * 57 + "..."),
    ("models", ANTCAR + 'amplitude_deg = "big"\n',
     "models.antcar.amplitude_deg: expected a finite number, got 'big'"),
    ("models", ANTCAR + "amplitude_deg = [10, 10.0]\n",
     "models.antcar.amplitude_deg[1]: 10.0 repeats models.antcar.amplitude_deg[0] = 10 (the same value); "
     "give each once"),
    ("models", ANTCAR + "n_kc = 1.5e3\n", "models.antcar.n_kc: expected an integer, got 1500.0"),
    ("models", ANTCAR + 'task = 5\n', "models.antcar.task: expected a string, got 5"),
    ("models", "[models.ardin]\nseed = 3\n", "models.ardin: unknown parameter 'seed'; allowed: n_kc, pn_per_kc, "
     "kappa, scan_deg, scan_step_deg, step, eye.channel, eye.cols, eye.rows, eye.elevation_min_deg, "
     "eye.elevation_max_deg, eye.sigma_deg, eye.fine_per_col, eye.fine_elevation_deg, eye.neighbours, eye.gamma, "
     "eye.row_gain, learn_spacing_m"),
    # learn_spacing_m = 0 would run the model's default spacing (6)
    ("models", "[models.perfect_memory]\nlearn_spacing_m = 0\n",
     "models.perfect_memory.learn_spacing_m: expected a finite number > 0, got 0"),
    ("models", "[models.perfect_memory]\nlearn_spacing_m = [0.02, -0.01]\n",
     "models.perfect_memory.learn_spacing_m[1]: expected a finite number > 0, got -0.01"),
    # values out of a model's or the eye's range, and models that do not follow routes: refused when the spec is
    # read, not run by run (each run failed with the same error, or a KeyError for the central-complex models)
    ("models", ANTCAR + "kappa = [0.01, 2.0]\n", "[models.antcar] with kappa = 2.0: kappa must be in (0, 1], got 2.0"),
    ("models", ANTCAR + "phi_max = 2\n", "[models.antcar] with phi_max = 2.0: Antcar phi_max must be in (0, pi/2) "
     "rad, got 2.0"),
    ("models", "[models.ardin]\nscan_step_deg = 0\n", "[models.ardin] with scan_step_deg = 0.0: Ardin scan_step_deg "
     "must be > 0 deg, got 0.0"),
    ("models", "[models.perfect_memory]\nstep = -0.02\n", "[models.perfect_memory] with step = -0.02: perfect "
     "memory step must be > 0 m, got -0.02"),
    ("models", "[models.ardin]\neye.gamma = [1.0, 0.0]\n", "[models.ardin] with eye.gamma = 0.0: eye gamma must be "
     "in (0, 1] (1 = linear response), got 0.0"),
    ("models", "[models.cx]\n", "models: unknown model 'cx'; allowed: antcar, ardin, perfect_memory"),
    ("models", '[models.ardin]\n"eye.gamma" = 1.0\neye.gamma = 0.5\n',
     'models.ardin: eye.gamma given twice (as "eye.gamma" and in its eye table)'),
    # two worlds of one name would be pooled into one condition (1)
    ("worlds", '[[worlds]]\nscene = "wa/pano.png"\n[[worlds]]\nscene = "wb/pano.png"\n',
     "worlds[0] ({d}/wa/pano.png) and worlds[1] ({d}/wb/pano.png) are both named 'pano': their runs would be one "
     'condition; give each [[worlds]] its own name = "..."'),
    ("worlds", '[[worlds]]\nscene = "habitat"\n[[worlds]]\nscene = "habitat"\nseed = 7\n',
     "worlds[0] (habitat) and worlds[1] (habitat seed=7) are both named 'habitat': their runs would be one "
     'condition; give each [[worlds]] its own name = "..."'),
    ("sets", '[[route_sets]]\npaths = "routes"\n[[route_sets]]\nname = "routes"\ncurved = {seeds = [0]}\n',
     "route_sets[0] (paths = 'routes') and route_sets[1] (curved = {seeds = [0], length_m = 10}) are both named "
     "'routes': their runs would be one condition; give each [[route_sets]] its own name = \"...\""),
]


@pytest.mark.parametrize(("part", "text", "message"), BAD_SPECS,
                         ids=[f"{i}-{m.split(':')[0].split(' ')[0]}" for i, (_, _, m) in enumerate(BAD_SPECS)])
def test_bad_spec_values_get_one_clear_line(pano, part, text, message):
    """Every key's type, range and allowed keys are checked the same way: a SpecError naming the key, the value
    and what is allowed (never an AttributeError, a silently ignored key or a run that ends with NaN)."""
    with pytest.raises(SpecError) as err:
        _expand(pano, **{part: text})
    assert str(err.value) == message.replace("{d}", str(pano.resolve()))


def test_model_eye_keys_quoted_or_dotted_are_one(pano):
    """TOML reads an unquoted eye.gamma in a model table as a table eye = {gamma = ...}: the same runs as the
    quoted "eye.gamma" (it was refused as an unknown parameter 'eye')."""
    quoted = _expand(pano, models='[models.ardin]\n"eye.gamma" = [1.0, 0.5]\n"eye.cols" = 25\n')
    dotted = _expand(pano, models="[models.ardin]\neye.gamma = [1.0, 0.5]\neye.cols = 25\n")
    assert [r.params for r in dotted.runs] == [r.params for r in quoted.runs]
    assert {dict(r.params)["eye.gamma"] for r in dotted.runs} == {1.0, 0.5}


def test_routes_of_one_name_in_a_set_are_refused_and_globbed_folders_name_them(pano, tmp_path):
    (tmp_path / "routes").mkdir()
    for name in ("r1.csv", "r1.txt"):
        (tmp_path / "routes" / name).write_text("0 0\n0.1 0\n")
    with pytest.raises(SpecError) as err:
        _expand(pano, sets=f'[[route_sets]]\npaths = "{tmp_path}/routes"\n')
    assert str(err.value) == (f"route_sets[0].paths = '{tmp_path}/routes': {tmp_path}/routes/r1.csv and "
                              f"{tmp_path}/routes/r1.txt are both route 'r1'; rename one, or put them in route sets "
                              "of their own")
    for day, y in ("day1", 0.0), ("day2", 0.5):
        (pano / day).mkdir(exist_ok=True)
        (pano / day / "r1.csv").write_text(f"0 {y}\n0.1 {y}\n")
    exp = _expand(pano, sets='[[route_sets]]\npaths = "day*/r1.csv"\n')
    assert [(r.route, r.route_source) for r in exp.runs] == [("day1/r1", str(pano.resolve() / "day1/r1.csv")),
                                                             ("day2/r1", str(pano.resolve() / "day2/r1.csv"))]
    assert sorted(exp.routes) == [("day*/r1.csv", "day1/r1"), ("day*/r1.csv", "day2/r1")]
    assert [r.route for r in _expand(pano).runs] == ["r1"]     # a folder's routes: their stems


def test_route_paths_are_the_specs_own_wherever_it_is_read_from(pano, monkeypatch):
    """Route files are relative to the spec's folder and made absolute: the same spec named by another path, read
    in another folder, gives the same runs, and a worker in another folder finds the files."""
    from antarium.ant.experiment import execute

    spec = pano / "spec.toml"
    spec.write_text('[[worlds]]\nscene = "pano.png"\n[[route_sets]]\npaths = "routes"\n[models.perfect_memory]\n')
    monkeypatch.chdir(pano)
    here = load_spec("spec.toml").runs
    monkeypatch.chdir("/")
    there = load_spec(spec).runs
    assert [r.route_source for r in here] == [r.route_source for r in there] == [str(pano.resolve() / "routes/r1.csv")]
    assert [r.run_id for r in here] == [r.run_id for r in there]
    np.testing.assert_allclose(execute._route(there[0].route_source, there[0].route_sha1).points,
                               [[0, 0], [0.1, 0], [0.2, 0]])


def test_an_edited_route_or_world_file_is_a_new_run(pano, tmp_path):
    """The run id holds the SHA-1 of the route's points and of the world's file: a rerun after an edit runs
    again instead of skipping it as done; a worker given a run whose file changed since fails it."""
    import cv2

    from antarium.ant.experiment import execute

    (tmp_path / "routes").mkdir()
    route = tmp_path / "routes" / "r1.csv"
    route.write_text("x_m,y_m\n0,0\n0.1,0\n0.2,0\n")
    (tmp_path / "w.png").write_bytes((pano / "pano.png").read_bytes())
    spec = {"worlds": [{"scene": "w.png"}], "route_sets": [{"paths": "routes"}], "models": {"perfect_memory": {}}}
    before = expand(spec, tmp_path).runs[0]
    route.write_text("x_m,y_m\n0,0\n0,0.3\n0,0.6\n")
    edited = expand(spec, tmp_path).runs[0]
    assert edited.route_source == before.route_source and edited.run_id != before.run_id
    with pytest.raises(RouteError, match="r1.csv' changed since the spec was read"):
        execute._route(before.route_source, before.route_sha1)
    img = cv2.imread(str(tmp_path / "w.png"))
    cv2.imwrite(str(tmp_path / "w.png"), 255 - img)
    other_world = expand(spec, tmp_path).runs[0]
    assert other_world.world.digest != edited.world.digest and other_world.run_id != edited.run_id
    assert expand(spec, tmp_path).runs[0].run_id == other_world.run_id      # nothing edited: the same run


def test_seeds_repeat_only_the_models_that_have_one(pano):
    exp = _expand(pano, "seeds = [0, 1, 2]", models="[models.perfect_memory]\n[models.ardin]\n")
    assert sorted((r.model, r.seed) for r in exp.runs) == [("ardin", 0), ("ardin", 1), ("ardin", 2),
                                                           ("perfect_memory", 0)]


def test_numbers_that_are_equal_are_one_condition(pano):
    """10 and 10.0 of a float parameter (or a release) are one run id and one condition."""
    a = _expand(pano, "releases = [{lateral_cm = 5}]", models=ANTCAR + "amplitude_deg = 10\n").runs
    b = _expand(pano, "releases = [{lateral_cm = 5.0}]", models=ANTCAR + "amplitude_deg = 10.0\n").runs
    assert a[0].params == (("amplitude_deg", 10.0),) and a[0].lateral_cm == 5.0
    assert [r.run_id for r in a] == [r.run_id for r in b] and a[0].condition == b[0].condition


GRID = """
[models.ardin]
n_kc = [100, 200]
[models.perfect_memory]
"""


@pytest.fixture(scope="module")
def serial(field, tmp_path_factory):
    d, _ = field
    exp = load_spec(_spec(d, GRID, 'seeds = [0, 1]'))
    assert len(exp.runs) == 2 * (2 * 2 + 1)   # routes x (ardin's grid x seeds + perfect memory, which has none)
    out = tmp_path_factory.mktemp("serial")
    p = run_experiment(exp.runs, out, serial=True, progress_bar=False)
    assert (p.done, p.failed) == (10, 0)
    return exp, out


def test_two_workers_equal_a_serial_run_and_a_rerun_skips_what_is_done(serial, tmp_path):
    exp, serial_out = serial
    p = run_experiment(exp.runs, tmp_path, workers=2, progress_bar=False)
    assert (p.done, p.failed) == (10, 0)
    a = load_results(serial_out).set_index("run_id").sort_index()
    b = load_results(tmp_path).set_index("run_id").sort_index()
    assert list(a.index) == list(b.index) and b["worker"].nunique() == 2
    for col in SAME:
        np.testing.assert_allclose(a[col].astype(float), b[col].astype(float), rtol=1e-9, atol=1e-9, err_msg=col)
    again = run_experiment(exp.runs, tmp_path, workers=2, progress_bar=False)
    assert (again.skipped, again.done) == (10, 0)


def test_summary_per_condition_and_pictures(serial):
    exp, out = serial
    text = report(out, exp.routes, exp.metrics)
    table = pd.read_csv(out / "summary.csv")
    # ardin x 2 n_kc (2 routes x 2 seeds), perfect memory (2 routes; it has no seed)
    assert len(table) == 3 and list(table.sort_values(["model", "param.n_kc"])["runs"]) == [4, 4, 2]
    df = load_results(out)
    pm = df[df.model == "perfect_memory"]
    row = table[table.model == "perfect_memory"].iloc[0]
    assert row["errors"] == pytest.approx(pm["errors"].mean())
    assert row["errors_lo"] <= row["errors"] <= row["errors_hi"] or not np.isfinite(row["errors_lo"])
    assert "perfect_memory" in text
    for name in ("results.parquet", "worst_and_best_paths.png", "errors_vs_n_kc.png", "lateral_median_m_vs_n_kc.png"):
        assert (out / name).stat().st_size > 0, name


def test_bootstrap_interval_covers_the_mean_and_narrows_with_more_data():
    rng = np.random.default_rng(1)
    small, large = rng.normal(3.0, 1.0, 10), rng.normal(3.0, 1.0, 1000)
    lo_s, hi_s = bootstrap_ci(small)
    lo_l, hi_l = bootstrap_ci(large)
    assert lo_s < small.mean() < hi_s and lo_l < large.mean() < hi_l
    assert hi_l - lo_l < (hi_s - lo_s) / 5
    assert all(math.isnan(v) for v in bootstrap_ci([1.0]))


def test_a_failed_run_is_recorded_and_the_others_go_on(field, tmp_path):
    """A run that fails when it runs (here: its route file changed after the spec was read; values out of range
    are refused with the spec) is a row with its error, and the other runs are done."""
    d, _ = field
    (tmp_path / "late").mkdir()
    route = tmp_path / "late" / "r9.csv"
    route.write_text("0.0 -0.2\n0.25 -0.2\n")
    exp = load_spec(_spec(d, f'[[route_sets]]\nname = "late"\npaths = "{tmp_path}/late"\n[models.perfect_memory]\n'))
    route.write_text("0.0 -0.2\n0.2 -0.2\n")
    p = run_experiment(exp.runs, tmp_path / "out", serial=True, progress_bar=False)
    assert (p.done, p.failed) == (2, 1)
    df = load_results(tmp_path / "out")
    assert list(df.loc[df.status == "failed", "route"]) == ["r9"]
    assert set(df.loc[df.status == "failed", "error"].str.contains("changed since the spec was read")) == {True}


def test_a_face_size_the_renderer_cannot_draw_with_is_refused_by_the_spec(field):
    """A face too small for the LED footprint would leave LEDs without a texel: refused before any run starts."""
    d, _ = field
    with pytest.raises(SpecError, match=r"experiment.face_size: expected an integer >= 55 and <= 2048, got 16"):
        load_spec(_spec(d, "[models.perfect_memory]\n", face_size=16))


def test_runs_carry_the_face_size_the_renderer_draws(field):
    """A spec's face_size 55 is drawn at 56 (`mip_face_size`): the runs, their ids and their rows say 56 (they said
    55 until 2026-11-27), and a spec of 56 names the same runs."""
    d, _ = field
    runs55 = load_spec(_spec(d, "[models.perfect_memory]\n", face_size=55)).runs
    runs56 = load_spec(_spec(d, "[models.perfect_memory]\n", face_size=56)).runs
    assert {r.face_size for r in runs55} == {56}
    assert [r.run_id for r in runs55] == [r.run_id for r in runs56]


def test_kill_then_rerun_runs_each_run_once(field, tmp_path):
    """A sweep killed half way restarts and completes; no run is done twice (each run's worker pid is kept)."""
    d, _ = field
    spec = _spec(d, MODELS, "seeds = [0, 1, 2, 3]")   # 2 routes x (ardin x 4 seeds + perfect memory) = 10 runs
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "antarium.cli", "ant", "experiment", str(spec), "--out", str(out), "--serial"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    runs = out / RUNS_DIR
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and len(list(runs.glob("*.parquet")) if runs.is_dir() else []) < 1:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    first = {p.name: p.stat().st_mtime_ns for p in runs.glob("*.parquet")}
    assert 1 <= len(first) < 10, "the kill came after every run finished: nothing to resume"
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    after = {p.name: p.stat().st_mtime_ns for p in runs.glob("*.parquet")}
    assert len(after) == 10 and all(after[k] == v for k, v in first.items())
    assert not list(runs.glob("*.tmp*"))


def test_a_panorama_world_has_no_extent_and_any_route_fits(tmp_path):
    import cv2

    img = np.zeros((32, 64, 3), np.uint8)
    img[:16] = 200
    cv2.imwrite(str(tmp_path / "pano.png"), img)
    world = WorldSpec(str(tmp_path / "pano.png"), eye_height_m=0.02)
    assert world_geometry(world).extent is None
    assert eye_z(world, Route([(100.0, 0.0), (101.0, 0.0)])) == pytest.approx(0.02)


def test_local_workers_share_the_cores_among_their_software_rasterisers(monkeypatch):
    from antarium.ant.experiment import runner

    monkeypatch.delenv("LP_NUM_THREADS", raising=False)
    monkeypatch.setattr(runner.os, "cpu_count", lambda: 16)
    assert runner.worker_env(4) == {"LP_NUM_THREADS": "4"} and runner.worker_env(32) == {"LP_NUM_THREADS": "1"}
    monkeypatch.setenv("LP_NUM_THREADS", "0")  # the user's choice is kept (inherited by the workers)
    assert runner.worker_env(4) == {}


def test_local_workers_start_without_dasks_malloc_trim_threshold_or_profiler(monkeypatch):
    """Dask's MALLOC_TRIM_THRESHOLD_ would make every array above 128 kB a fresh mmap in the workers; its profiler
    takes the interpreter lock every 10 ms for a dashboard that local clusters do not serve."""
    import dask
    from distributed import Client

    from antarium.ant.experiment import runner

    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    monkeypatch.delenv("LP_NUM_THREADS", raising=False)
    with runner.local_cluster(1) as cluster, Client(cluster) as client:
        env = next(iter(client.run(lambda: dict(os.environ)).values()))
        profiling = next(iter(client.run(lambda: dask.config.get("distributed.worker.profile.enabled")).values()))
    assert profiling is False
    assert "MALLOC_TRIM_THRESHOLD_" not in env and "MALLOC_TRIM_THRESHOLD_" not in os.environ
    assert env["OMP_NUM_THREADS"] == "1" and env["LP_NUM_THREADS"] == str(max(1, os.cpu_count() or 1))
