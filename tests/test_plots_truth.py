"""The pictures say what the data say (found by a review of the pictures scientists put in papers): azimuth ticks
under their own meridians, no pooled conditions, each run shown once, no data dropped unnoticed, labels that
name the real step, axis and clock, one legend entry per kind of mark. Checked on the matplotlib objects."""

import math
from types import SimpleNamespace

import matplotlib
import numpy as np
import pandas as pd
import pytest

matplotlib.use("Agg")

from matplotlib.figure import Figure  # noqa: E402

from antarium.ant.agent import Track  # noqa: E402
from antarium.ant.homing import Trip  # noqa: E402
from antarium.ant.routes import Route  # noqa: E402
from antarium.plots import ant, dome_map, experiments, homing, servosphere, style  # noqa: E402

CONDITIONS = ("world", "model", "protocol", "lateral_cm", "heading_deg")


@pytest.fixture
def figures(monkeypatch):
    """Every figure written (through the house style or not), drawn, in order."""
    kept = []
    real = Figure.savefig

    def keep(fig, *args, **kwargs):
        fig.canvas.draw()
        kept.append(fig)
        return real(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    return kept


def _legend(ax) -> list[str]:
    return [t.get_text() for t in ax.get_legend().get_texts()]


# --- 1: azimuth ticks ---------------------------------------------------------------------------------------------

def test_each_azimuth_tick_sits_straight_under_its_meridian_on_the_horizon():
    fig = style.pyplot().figure(figsize=(12, 7.2))
    ax = fig.add_subplot(projection="mollweide")
    style.dome_axes(ax, -56.8)
    fig.canvas.draw()
    ticks = [t for t in ax.texts if t.get_text().endswith("°")]
    assert len(ticks) == 11
    for t in ticks:
        box = t.get_window_extent()
        az = math.radians(float(t.get_text().removesuffix("°")))
        x_meridian, y_horizon = ax.transData.transform((-az, 0.0))
        assert abs((box.x0 + box.x1) / 2 - x_meridian) < 1.0, t.get_text()  # pixels
        lat = ax.transData.inverted().transform(((box.x0 + box.x1) / 2, (box.y0 + box.y1) / 2))[1]
        assert -10.0 < math.degrees(lat) <= 0.0, t.get_text()  # just under the horizon, among the LEDs
    style.pyplot().close(fig)


# --- 10: the width asked for --------------------------------------------------------------------------------------

@pytest.mark.parametrize("width", [400, 500, 1200])
def test_the_dome_map_is_the_width_asked_for(tmp_path, width):
    import cv2

    from antarium.geometry import load_dome

    dome = load_dome()
    frame = np.zeros((dome.positions.shape[0], 2), np.uint16)
    path = dome_map.dome_picture(frame, dome, tmp_path / "map.png", "a frame", width_px=width)
    assert cv2.imread(str(path)).shape[1] == width


def test_a_dome_map_too_narrow_to_read_is_refused_in_one_line(tmp_path, capsys):
    from antarium.cli import main

    with pytest.raises(ValueError, match=f"whole number of pixels >= {dome_map.MIN_WIDTH_PX}"):
        dome_map.dome_picture(np.zeros((20350, 2), np.uint16), None, tmp_path / "m.png", "x", width_px=64)
    assert main(["render", "uniform", "--width", "64", "--out", str(tmp_path / "v.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"antarium render: error: --width must be at least {dome_map.MIN_WIDTH_PX} pixels (narrower "
                   "maps have illegible text) and at most 8192, got 64"]
    assert not (tmp_path / "v.png").exists()


# --- 2, 3, 12: experiments ----------------------------------------------------------------------------------------

def _experiment() -> pd.DataFrame:
    """lr has no effect, noise adds 10 m; lr = 0.3 ran once."""
    rows = [dict(status="done", model="antcar", protocol="antcar", world="habitat", lateral_cm=0.0, heading_deg=0.0,
                 **{"param.lr": lr, "param.noise": noise}, seed=seed, lateral_median_m=10 * noise + 0.01 * seed,
                 errors=0)
            for lr in (0.1, 0.2) for noise in (0.0, 1.0) for seed in range(3)]
    rows.append(dict(rows[0], **{"param.lr": 0.3}, lateral_median_m=0.0))
    return pd.DataFrame(rows)


def test_metric_vs_parameter_pools_no_condition_and_marks_a_single_run(tmp_path, figures):
    from antarium.ant.experiment.results import bootstrap_ci

    experiments.plot_metric_vs_parameter(_experiment(), "lateral_median_m", "param.lr", tmp_path / "lr.png",
                                         ci=bootstrap_ci, conditions=CONDITIONS)
    ax = figures[-1].axes[0]
    means = sorted(tuple(np.round(c.lines[0].get_ydata(), 3)) for c in ax.containers)
    assert means == [(0.01, 0.01), (10.01, 10.01)]  # one line per noise, not their pooled 5.01
    for c in ax.containers:  # every bar drawn spans an interval
        assert all(np.ptp(s[:, 1]) > 0 for s in c.lines[2][0].get_segments())
    hollow = [line for line in ax.get_lines() if line.get_marker() == "o" and line.get_mfc() == "white"
              and len(line.get_xdata())]
    assert [(list(h.get_xdata()), list(h.get_ydata())) for h in hollow] == [([0.3], [0.0])]
    assert _legend(ax) == ["noise = 0.0", "noise = 1.0", "hollow: n = 1 run (no interval)"]
    assert style.problems(figures[-1]) == []
    assert ax.get_ylabel() == "lateral median (m)"


@pytest.mark.parametrize("runs, best, worst", [(2, 1, 1), (5, 3, 2), (8, 3, 3)])
def test_best_and_worst_runs_are_disjoint_and_each_shown_once(tmp_path, figures, runs, best, worst):
    df = pd.DataFrame([dict(status="done", model="antcar", route_set="curved", route=f"r{i}", seed=i, errors=0,
                            lateral_median_m=0.1 * i, track_x=np.linspace(0, 1, 5), track_y=np.zeros(5),
                            **{"param.lr": 0.1}) for i in range(runs)])
    experiments.plot_worst_and_best(df, {}, tmp_path / "wb.png")
    titles = [ax.get_title() for ax in figures[-1].axes if ax.get_visible()]
    seeds = [int(t.rsplit("seed ", 1)[1]) for t in titles]
    assert len(seeds) == len(set(seeds)) == best + worst
    assert [t.split()[0] for t in titles] == ["best"] * best + ["worst"] * worst
    assert max(seeds[:best]) < min(seeds[best:])  # the best are better than every worst
    assert style.problems(figures[-1]) == []


def test_a_run_and_its_twin_under_the_other_protocol_have_different_titles(tmp_path, figures):
    """Two runs alike but for the protocol (or the release) were two panels with the same title."""
    df = pd.DataFrame([dict(status="done", model="antcar", route_set="curved", route="r2", seed=0, errors=0,
                            protocol=protocol, lateral_cm=lateral, heading_deg=0.0, lateral_median_m=0.1 + 0.01 * i,
                            track_x=np.linspace(0, 1, 5), track_y=np.zeros(5), **{"param.lr": 0.1})
                       for i, (protocol, lateral) in enumerate([("ardin", 0.0), ("antcar", 0.0), ("ardin", 20.0)])])
    experiments.plot_worst_and_best(df, {}, tmp_path / "wb.png", n=2)
    titles = [ax.get_title() for ax in figures[-1].axes if ax.get_visible()]
    assert len(titles) == 3 and len({t.split(": ", 1)[1] for t in titles}) == 3
    assert "antcar's protocol" in titles[1] and "released 20 cm 0 deg off" in titles[2]


# --- 4: servosphere error -----------------------------------------------------------------------------------------

def _area(patch) -> float:
    x, y = patch.get_path().vertices.T
    return 0.5 * abs(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1)))


def test_the_error_histogram_covers_the_distances_and_drops_none_unnoticed(tmp_path, figures):
    rng = np.random.default_rng(0)
    ex, ey = 2.0 + 0.1 * rng.standard_normal(5000), 2.0 + 0.1 * rng.standard_normal(5000)  # 2.83 mm off the apex
    ex[0] = 40.0  # one wild frame
    servosphere.error_figure(ex, ey, None, None, tmp_path / "err.png", "diagonal offset")
    ax = figures[-1].axes[0]
    distance = next(p for p in ax.patches if p.get_label().startswith("distance"))
    d = np.hypot(ex, ey)
    assert distance.get_path().vertices[:, 0].max() >= np.percentile(d, 99.9)
    assert _area(distance) == pytest.approx(np.mean(d <= distance.get_path().vertices[:, 0].max()), rel=1e-6)
    assert "1 of 5000 beyond" in distance.get_label()  # the wild frame is counted, not silently dropped
    assert _area(distance) == pytest.approx(4999 / 5000, rel=1e-6)


# --- 5, 8, 9: homing ----------------------------------------------------------------------------------------------

def _trips():
    out = Trip(np.array([[0.01 * i, 0.0] for i in range(1, 101)]), np.zeros(100), [])
    home_a = Trip(np.array([[1 - 0.01 * i, 0.0] for i in range(1, 50)]), np.zeros(49), [], "decision 49: no sky")
    home_b = Trip(np.array([[1 - 0.01 * i, 0.5] for i in range(1, 50)]), np.zeros(49), [], "decision 49: no sky")
    return out, home_a, home_b


def test_homing_distance_names_the_models_step(tmp_path, figures):
    out, home_a, _ = _trips()
    homing.plot_distance(tmp_path / "d.png", {"seed 0": (out, home_a)}, "distance", 0.02)
    assert "2 cm" in figures[-1].axes[0].get_xlabel()


def test_trip_maps_mark_each_start_where_it_was_and_each_kind_once(tmp_path, figures):
    out, home_a, home_b = _trips()
    homing.plot_trips(tmp_path / "t.png", {"home 1": (out, home_a), "displaced, k = 0": (out, home_b)}, "trips",
                      {"fictive nest": (0.0, 0.5)}, {"displaced, k = 0": (1.0, 0.5)})
    ax = figures[-1].axes[0]
    legend = _legend(ax)
    assert len(legend) == len(set(legend))
    assert {homing.TURNED_HOME, homing.PUT_DOWN, homing.LOST_CUE} <= set(legend)
    starts = {line.get_marker(): line.get_xydata().tolist() for line in ax.get_lines()
              if line.get_marker() in ("s", "D")}
    assert starts == {"s": [[1.0, 0.0]], "D": [[1.0, 0.5]]}  # the feeder; the displaced release point
    lines = {line.get_label(): line.get_xydata() for line in ax.get_lines()}
    assert lines["displaced, k = 0"][0].tolist() == [1.0, 0.5]  # the trip home drawn from where it began


def test_the_arena_shows_a_trip_that_repeats_home_1_over_it(tmp_path, figures):
    out, home, _ = _trips()
    clutter = SimpleNamespace(centres=[(0.5, 0.3)], radii=[0.05])
    again = Trip(home.xy.copy(), home.heading, [])
    homing.plot_arena(tmp_path / "a.png", clutter, {"outbound": out, "cx": home, "cx_again": again}, "arena")
    ax = figures[-1].axes[0]
    by_label = {line.get_label(): line for line in ax.get_lines()}
    first = by_label["home 1: CX (MBONs learn to the nest)"]
    repeat = next(line for label, line in by_label.items() if label.startswith("home 2: CX alone"))
    assert "same path as home 1" in repeat.get_label()
    assert repeat.get_linestyle() == "--" and repeat.get_linewidth() < first.get_linewidth()
    assert ax.get_lines().index(repeat) > ax.get_lines().index(first)  # drawn over it


# --- 6, 7, 11: the virtual ant's run ------------------------------------------------------------------------------

def _track() -> Track:
    track = Track()
    for k in range(21):
        track.t.append(100.0 + 0.5 * k)  # the rig's clock, not the ant's
        track.xy.append((min(0.1 * k, 1.0), max(0.0, 0.1 * (k - 10))) if k != 5 else (0.5, 0.3))
        track.heading.append(0.0)
        track.traces.append({"lambda_left": 0.1 * (k % 3), "lambda_right": 0.2, "lambda_diff": 0.1 * (k % 3) - 0.2,
                             "motivation": float(k)})
    track.put_back.append(5)
    return track


def test_traces_run_per_decision_with_the_signed_difference_on_its_own_axis(tmp_path, figures):
    ant.plot_traces(tmp_path / "tr.png", _track(), "traces")
    axes = figures[-1].axes
    diff = next(ax for ax in axes if "λ left − λ right" in ax.get_ylabel())
    assert [line.get_label() for line in diff.get_lines() if not line.get_label().startswith("_")] == ["lambda diff"]
    assert any(list(line.get_ydata()) == [0.0, 0.0] for line in diff.get_lines())  # the zero line
    for ax in axes:
        assert "lambda diff" not in _legend(ax) or ax is diff
        data = [line for line in ax.get_lines() if not line.get_label().startswith("_")]
        assert all(list(line.get_xdata()) == list(range(21)) for line in data)
    assert axes[-1].get_xlabel().startswith("decision since release (count")


def test_the_paths_mark_where_the_ant_was_picked_up_and_where_it_was_put_back(tmp_path, figures):
    route = Route([(0, 0), (1, 0), (1, 1)])
    ant.plot_paths(tmp_path / "p.png", route, {"followed": _track()}, "east then north")
    lines = {line.get_label(): line.get_xydata().tolist() for line in figures[-1].axes[0].get_lines()}
    assert lines["followed: picked up (off the route)"] == [[0.5, 0.3]]
    assert lines["followed: put back on the route"] == [[0.5, 0.0]]
