"""Pictures of degenerate data say what they show (found by a review of the pictures): no positions, no
decisions, no finite metric, a trip that lost its compass cue before its first step. Each picture either draws the
data or says in words why there is none; a blank figure is refused by the house style. Checked on the matplotlib
figures handed to `style.save`."""

import math

import matplotlib
import numpy as np
import pandas as pd
import pytest

matplotlib.use("Agg")

from antarium.ant.agent import Track  # noqa: E402
from antarium.ant.experiment.results import bootstrap_ci  # noqa: E402
from antarium.ant.homing import Trip  # noqa: E402
from antarium.ant.routes import Route  # noqa: E402
from antarium.plots import ant, experiments, homing, paths, style  # noqa: E402


@pytest.fixture
def saved(monkeypatch):
    """The figures handed to `style.save` (written all the same), in order."""
    kept = []
    real = style.save

    def keep(fig, path, *args, **kwargs):
        kept.append(fig)
        return real(fig, path, *args, **kwargs)

    monkeypatch.setattr(style, "save", keep)
    return kept


def _texts(fig) -> list[str]:
    return [t.get_text() for ax in fig.axes if ax.get_visible() for t in ax.texts]


def _legend(ax) -> list[str]:
    return [t.get_text() for t in ax.get_legend().get_texts()]


def _track(n: int, nan: bool = False) -> Track:
    track = Track()
    for k in range(n):
        track.t.append(0.02 * k)
        track.xy.append((0.05 * k, 0.01))
        track.heading.append(0.0)
        track.traces.append({"lambda_left": math.nan if nan else 0.1, "lambda_right": math.nan if nan else 0.2})
    return track


def _runs(metric: list[float]) -> pd.DataFrame:
    return pd.DataFrame([dict(status="done", model="antcar", protocol="antcar", world="habitat", route_set="curved",
                              route=f"r{i}", seed=i, errors=0, lateral_median_m=m, track_x=np.linspace(0, 1, 5),
                              track_y=np.full(5, 0.1 * i), **{"param.lr": 0.1 * (1 + i % 2)})
                         for i, m in enumerate(metric)])


def test_a_blank_picture_is_refused_by_the_house_style(tmp_path):
    fig, ax = style.figure()
    style.label(ax, "nothing", "x (m)", "y (m)")
    with pytest.raises(ValueError, match="nothing drawn"):
        style.save(fig, tmp_path / "blank.png")
    assert not (tmp_path / "blank.png").exists()


def test_a_world_path_without_positions_says_so(tmp_path, saved):
    empty = np.zeros(0)
    paths.world_path(empty, empty, empty, np.zeros(0, int), tmp_path / "p.png", "no frames")
    assert _texts(saved[-1]) == ["no position to draw: 0 frames, none with a finite x and y"]


def test_a_world_path_starts_at_its_first_finite_position(tmp_path, saved):
    x, y = np.array([np.nan, 0.02, 0.05]), np.array([np.nan, 0.01, 0.0])
    paths.world_path(x, y, np.arange(3.0), np.zeros(0, int), tmp_path / "p.png", "first frame lost")
    start = next(line for line in saved[-1].axes[0].get_lines() if line.get_label() == "start")
    assert (start.get_xdata()[0], start.get_ydata()[0]) == pytest.approx((2.0, 1.0))  # cm


@pytest.mark.parametrize("track", [_track(0), _track(4, nan=True)], ids=["no decision", "all NaN"])
def test_traces_without_a_finite_signal_say_so(tmp_path, saved, track):
    ant.plot_traces(tmp_path / "t.png", track, "Antcar")
    assert _texts(saved[-1]) == [f"no model signal with a finite value in {len(track.traces)} decisions"]
    assert saved[-1].axes[0].get_title() == "Antcar: model signals"


def test_a_run_without_positions_is_named_in_the_path_legend(tmp_path, saved):
    route = Route(np.array([[0.0, 0.0], [1.0, 0.0]]))
    ant.plot_paths(tmp_path / "p.png", route, {"Antcar": _track(0), "Willshaw": _track(3)}, "two runs")
    legend = _legend(saved[-1].axes[0])
    assert "Antcar: no position recorded (0 decisions)" in legend
    assert "Willshaw" in legend


def _trip(n: int, lost: str | None = None) -> Trip:
    return Trip(np.array([[0.01 * i, 0.0] for i in range(1, n + 1)]).reshape(-1, 2), np.zeros(n), [], lost)


def test_the_distance_plot_names_a_trip_without_decisions_and_draws_no_infinity(tmp_path, saved):
    homing.plot_distance(tmp_path / "d.png", {"seed 0": (_trip(50), _trip(0, "decision 0: no sky")),
                                              "seed 1": (_trip(0), _trip(10)), "seed 2": (_trip(50), _trip(20))},
                         "distance", 0.01)
    ax = saved[-1].axes[0]
    assert _legend(ax)[:3] == ["seed 0: no homeward decision", "seed 1: no outbound path (length 0)", "seed 2"]
    drawn = [line.get_ydata() for line in ax.get_lines() if line.get_label().startswith("seed")]
    assert [len(y) for y in drawn] == [0, 0, 20]
    assert np.isfinite(drawn[2]).all() and drawn[2][0] == pytest.approx(100 * 0.01 / 0.50)


def test_a_trip_that_lost_its_cue_before_its_first_step_is_marked_where_it_began(tmp_path, saved):
    homing.plot_trips(tmp_path / "t.png", {"seed 0": (_trip(50), _trip(0, "decision 0: no sky"))}, "trips")
    crosses = [line for line in saved[-1].axes[0].get_lines() if line.get_label() == homing.LOST_CUE]
    assert [(line.get_xdata()[0], line.get_ydata()[0]) for line in crosses] == [pytest.approx((0.5, 0.0))]


def test_metric_vs_parameter_without_a_finite_value_says_so(tmp_path, saved):
    experiments.plot_metric_vs_parameter(_runs([math.nan] * 4), "lateral_median_m", "param.lr", tmp_path / "m.png",
                                         ci=bootstrap_ci, conditions=("world", "model", "protocol"))
    assert _texts(saved[-1]) == ["no done run with lr set and a finite lateral_median_m (of 4 runs)"]
    assert saved[-1].axes[0].get_legend() is None


def test_best_and_worst_rank_only_runs_with_a_finite_metric(tmp_path, saved):
    experiments.plot_worst_and_best(_runs([math.nan, 0.1, math.nan, 0.2, 0.3]), {}, tmp_path / "wb.png")
    fig = saved[-1]
    titles = [ax.get_title() for ax in fig.axes if ax.get_visible()]
    assert [t.split(":")[0] for t in titles] == ["best 1 of 3", "best 2 of 3", "worst 1 of 3"]
    assert not any("nan" in t for t in titles)
    assert "2 without a finite lateral_median_m not ranked" in fig._suptitle.get_text()


def test_best_and_worst_without_a_ranked_run_say_so(tmp_path, saved):
    experiments.plot_worst_and_best(_runs([math.nan, math.nan]), {}, tmp_path / "wb.png")
    assert _texts(saved[-1]) == ["no done run with a finite lateral_median_m"]
