"""An experiment's inputs and results, as a review found them (issue 21): a report of one spec's runs only, route
sets as conditions, the ground under the eye, worlds below z = 0, files a scene loads, route file headers,
recursive globs and the --world flags."""

from __future__ import annotations

import argparse
import tomllib
from pathlib import Path

import numpy as np
import pytest
from conftest import write_world_panorama

pytest.importorskip("distributed")
pd = pytest.importorskip("pandas")

from antarium.ant.experiment import command  # noqa: E402
from antarium.ant.experiment.inputs import WorldSpec, eye_z, load_route, route_files  # noqa: E402
from antarium.ant.experiment.results import CONDITION, report, summary  # noqa: E402
from antarium.ant.experiment.runner import RUNS_DIR, run_experiment  # noqa: E402
from antarium.ant.experiment.spec import expand  # noqa: E402
from antarium.ant.routes import Route, RouteError  # noqa: E402

ROUTE = "x_m,y_m\n0,0\n0.1,0\n0.2,0.02\n"


def _spec(experiment: str = "", worlds: str = '[[worlds]]\nscene = "pano.png"\n',
          sets: str = '[[route_sets]]\npaths = "routes"\n') -> dict:
    return tomllib.loads(f"[experiment]\nface_size = 55\neye = {{cols = 10, rows = 4}}\n{experiment}\n{worlds}{sets}"
                         "[models.perfect_memory]\n")


@pytest.fixture()
def pano(tmp_path):
    """A panorama world (pano.png) and a route folder with one route."""
    write_world_panorama(tmp_path / "pano.png")
    (tmp_path / "routes").mkdir()
    (tmp_path / "routes" / "r0.csv").write_text(ROUTE)
    return tmp_path


def test_the_report_covers_this_specs_runs_and_counts_the_others(pano):
    """A spec edited (max_decisions) and run again into the same --out: a new run id, and the report holds only
    the new spec's runs, saying how many rows of other specs sit in runs/; each row states its settings."""
    before = expand(_spec("max_decisions = 2"), pano)
    after = expand(_spec("max_decisions = 3"), pano)
    assert before.runs[0].run_id != after.runs[0].run_id
    out = pano / "out"
    for exp in (before, after):
        assert run_experiment(exp.runs, out, serial=True, progress_bar=False).done == 1
    text = report(out, after.routes, after.metrics, [r.run_id for r in after.runs])
    assert text.startswith(f"1 runs of this spec: 1 done, 0 failed, 0 without a result yet; 1 rows of other specs "
                           f"in {out / RUNS_DIR} not summarised")
    df = pd.read_parquet(out / "results.parquet")
    run = after.runs[0]
    assert list(df.run_id) == [run.run_id]
    row = df.iloc[0]
    assert (row.face_size, row.max_decisions, row.decisions) == (56, 3, 3)  # the spec's 55, as drawn
    assert row.eye_z_m == pytest.approx(0.01) and row.route_source == str(pano / "routes" / "r0.csv")
    assert pd.read_csv(out / "summary.csv")["runs"].tolist() == [1]


def test_route_sets_are_conditions_of_their_own(pano):
    """One route in two route sets: two conditions, summarised apart."""
    sets = '[[route_sets]]\nname = "day1"\npaths = "routes"\n[[route_sets]]\nname = "day2"\npaths = "routes"\n'
    runs = expand(_spec(sets=sets), pano).runs
    assert len({r.condition for r in runs}) == 2 and "route_set" in CONDITION
    df = pd.DataFrame([{**{k: getattr(r, k) for k in ("route_set", "model", "protocol", "lateral_cm",
                                                      "heading_deg")},
                        "world": r.world.name, "status": "done", "errors": float(i)} for i, r in enumerate(runs)])
    table = summary(df, ("errors",))
    assert sorted(table.route_set) == ["day1", "day2"] and sorted(table.errors) == [0.0, 1.0]


def _box_obj(path: Path, z0: float, z1: float) -> Path:
    """A closed 4 m x 4 m slab from z0 to z1 (m), and a 0.5 m post on it."""
    import trimesh

    slab = trimesh.creation.box((4.0, 4.0, z1 - z0), trimesh.transformations.translation_matrix((0, 0, (z0 + z1) / 2)))
    post = trimesh.creation.box((0.3, 0.3, 0.5), trimesh.transformations.translation_matrix((1.0, 1.0, z1 + 0.25)))
    trimesh.util.concatenate([slab, post]).export(path)
    return path


def test_the_ground_is_the_top_of_a_thick_slab_not_its_underside(tmp_path):
    """The eye stands on the surface facing up: 1 cm above a 0.3 m slab's top, not inside it at its underside; a
    terrain wound the other way (clockwise seen from above) has no such surface and is refused in one line."""
    route = Route([(0.0, 0.0), (0.2, 0.0), (0.3, 0.05)])
    slab = WorldSpec(str(_box_obj(tmp_path / "slab.obj", 0.0, 0.3)), eye_height_m=0.01)
    assert eye_z(slab, route) == pytest.approx(0.31, abs=1e-6)
    (tmp_path / "down.obj").write_text("v -2 -2 0\nv 2 -2 0\nv 2 2 0\nv -2 2 0\nf 3 2 1\nf 4 3 1\n")
    with pytest.raises(RouteError, match=r"world 'down' has 1 surface\(s\) under the route's start \(0.000, 0.000\) "
                                         "m and no ground: none faces up"):
        eye_z(WorldSpec(str(tmp_path / "down.obj")), route)


def test_a_world_below_z_0_runs_and_reports_its_own_coordinates(tmp_path):
    """Survey coordinates: the ground at z = -0.5 m runs as the same ground at z = 0 does (same track), and the
    row's eye_z_m is the world's own."""
    rows = {}
    for name, z0 in (("low", -0.8), ("level", -0.3)):
        d = tmp_path / name
        (d / "routes").mkdir(parents=True)
        (d / "routes" / "r0.csv").write_text(ROUTE)
        _box_obj(d / "w.obj", z0, z0 + 0.3)
        exp = expand(_spec("max_decisions = 3", worlds='[[worlds]]\nscene = "w.obj"\n'), d)
        assert run_experiment(exp.runs, d / "out", serial=True, progress_bar=False).done == 1
        rows[name] = pd.read_parquet(next((d / "out" / RUNS_DIR).glob("*.parquet"))).iloc[0]
    assert rows["low"].eye_z_m == pytest.approx(-0.49, abs=1e-6)
    assert rows["level"].eye_z_m == pytest.approx(0.01, abs=1e-6)
    np.testing.assert_allclose(rows["low"].track_x, rows["level"].track_x, atol=1e-9)
    np.testing.assert_allclose(rows["low"].track_y, rows["level"].track_y, atol=1e-9)


def test_an_edited_gltf_buffer_or_obj_material_is_a_new_run(tmp_path):
    """The run id holds every file the scene loads: a glTF's external buffer, an OBJ's MTL file."""
    import trimesh

    (tmp_path / "routes").mkdir()
    (tmp_path / "routes" / "r0.csv").write_text(ROUTE)
    ground = trimesh.creation.box((4.0, 0.1, 4.0), trimesh.transformations.translation_matrix((0, -0.05, 0)))
    for name, data in trimesh.exchange.gltf.export_gltf(trimesh.Scene(ground)).items():
        (tmp_path / name).write_bytes(data)
    (tmp_path / "ground.obj").write_text("mtllib ground.mtl\nusemtl sand\nv -2 -2 0\nv 2 -2 0\nv 2 2 0\nv -2 2 0\n"
                                         "f 1 2 3\nf 1 3 4\n")
    (tmp_path / "ground.mtl").write_text("newmtl sand\nKd 0.8 0.7 0.5\n")
    buffer = next(tmp_path.glob("*.bin"))
    edited = bytearray(buffer.read_bytes())
    edited[-2] ^= 1                                     # a mantissa bit of the buffer's last float
    for world, other, data in (('scene = "model.gltf"\nup = "y"', buffer, bytes(edited)),
                               ('scene = "ground.obj"', tmp_path / "ground.mtl", b"newmtl sand\nKd 0.3 0.7 0.5\n")):
        spec = _spec(worlds=f"[[worlds]]\n{world}\n")
        first = expand(spec, tmp_path).runs[0].run_id
        other.write_bytes(data)
        assert expand(spec, tmp_path).runs[0].run_id != first, other.name


ROUTE_FILES = [
    # (text, the points read or the RouteError's message)
    ("nan,0\n0.1,0\n0.2,0\n", "line 1: 'nan' is not a finite number"),
    ("0,0\n0.1,inf\n", "line 2: 'inf' is not a finite number"),
    ("t,x,y\n0,0,0\n1,0.1,0\n", "header 't, x, y' — a route file's header names the columns x_m, y_m (metres) and "
                                "optionally heading_deg (degrees), each once, and no others"),
    ("x_cm,y_cm\n0,0\n10,0\n", "header 'x_cm, y_cm'"),
    ("x_m,y_m,heading_rad\n0,0,1.57\n0.1,0,1.57\n", "header 'x_m, y_m, heading_rad'"),
    ("x_m,y_m\nm,m\n0,0\n0.1,0\n", "line 2: 'm' is not a number"),
    ("y_m,X_M,heading_deg\n0,0,90\n0,0.1,90\n", ([[0, 0], [0.1, 0]], 90.0)),
    ("\ufeff0 0 30\n0.1 0 30\n", ([[0, 0], [0.1, 0]], 30.0)),    # no header: x_m, y_m, heading_deg
]


@pytest.mark.parametrize(("text", "expected"), ROUTE_FILES, ids=range(len(ROUTE_FILES)))
def test_a_route_files_header_names_its_columns(tmp_path, text, expected):
    """A header is a first row with a field that is not a number; it names x_m, y_m (and heading_deg) and nothing
    else; every value is a finite number."""
    path = tmp_path / "r.csv"
    path.write_text(text, encoding="utf-8")
    if isinstance(expected, str):
        with pytest.raises(RouteError) as err:
            load_route(path)
        assert f"r.csv, {expected}" in str(err.value) or f"r.csv: {expected}" in str(err.value)
    else:
        ri = load_route(path)
        np.testing.assert_allclose(ri.route.points, expected[0])
        assert np.degrees(ri.release_heading) == pytest.approx(expected[1])


def test_a_route_glob_with_two_stars_recurses(tmp_path):
    for sub in ("", "day1/", "day1/am/"):
        (tmp_path / "routes" / sub).mkdir(parents=True, exist_ok=True)
        (tmp_path / "routes" / sub / f"r{len(sub)}.csv").write_text(ROUTE)
    folder, files = route_files("routes/**/*.csv", tmp_path)
    assert folder == tmp_path / "routes"
    assert [f.relative_to(folder).as_posix() for f in files] == ["day1/am/r8.csv", "day1/r5.csv", "r0.csv"]


@pytest.mark.parametrize(("flags", "message"), [
    (["--world-scale", "0.01"], "--world-scale without --world"),
    (["--up", "y", "--eye-height-m", "0.02"], "--up, --eye-height-m without --world"),
    (["--world", "pano.png", "--eye-height-m", "-1"], "--eye-height-m must be a finite number > 0, got -1.0"),
])
def test_world_flags_need_world_and_errors_name_the_flags(pano, flags, message):
    (pano / "spec.toml").write_text('[experiment]\nface_size = 55\nmax_decisions = 1\n[[route_sets]]\n'
                                    'paths = "routes"\n[models.perfect_memory]\n')
    parser = argparse.ArgumentParser()
    command.add_arguments(parser)
    args = parser.parse_args([str(pano / "spec.toml"), "--out", str(pano / "out"), "--serial",
                              *[str(pano / f) if f.endswith(".png") else f for f in flags]])
    with pytest.raises(ValueError, match=message.replace("-1.0", r"-1\.0")):
        command.run(args)
    assert not (pano / "out").exists()
