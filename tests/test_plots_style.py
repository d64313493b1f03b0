"""Every picture the project writes follows the house style (antarium.plots.style), checked on the matplotlib
figure objects: a title, axis labels with units, legends outside the data, dome maps with the front, azimuth
and elevation marked and a colour key (issue #20, point 12)."""

import math

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

from antarium.ant.agent import Track  # noqa: E402
from antarium.ant.routes import Route  # noqa: E402
from antarium.geometry import load_dome  # noqa: E402
from antarium.plots import ant, dome_map, layout, paths, servosphere, style  # noqa: E402


@pytest.fixture
def figures(monkeypatch):
    """The figures handed to `style.save`, checked and kept (written all the same)."""
    kept = []
    real = style.save

    def keep(fig, path, dpi=110, **kw):
        kept.append((fig, [t.get_text() for ax in fig.axes for t in ax.texts],
                     [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()],
                     style.problems(fig)))
        return real(fig, path, dpi, **kw)

    monkeypatch.setattr(style, "save", keep)
    return kept


def _track() -> Track:
    track = Track()
    for k in range(30):
        track.t.append(0.02 * k)
        track.xy.append((0.05 * k, 0.03 + 0.001 * k))
        track.heading.append(0.0)
        track.traces.append({"lambda_left": 0.1 + 0.01 * math.sin(k), "lambda_right": 0.12, "motivation": 1.0})
    track.put_back.append(12)
    return track


def _all_pictures(tmp_path) -> dict[str, object]:
    dome = load_dome()
    frame = np.zeros((dome.positions.shape[0], 2), np.uint16)
    frame[dome.gb_index, 0] = 20000
    route = Route(np.array([[0.0, 0.0], [1.5, 0.05]]))
    return {
        "layout map": layout.mollweide_map(dome, tmp_path / "layout_mollweide.png"),
        "layout 3d": layout.dome_3d(dome, tmp_path / "layout_3d.png"),
        "dome map": dome_map.dome_picture(frame, dome, tmp_path / "dome.png", "a test frame", width_px=600),
        "ant paths": ant.plot_paths(tmp_path / "paths.png", route, {"followed": _track()}, "a run",
                                    notes="lateral error 1 cm"),
        "ant traces": ant.plot_traces(tmp_path / "traces.png", _track(), "Antcar"),
        "world path": paths.world_path(np.linspace(0, 1, 50), np.zeros(50), np.linspace(0, 2, 50), np.array([20]),
                                       tmp_path / "path.png", "a walk"),
        "servosphere": servosphere.error_figure(np.random.default_rng(1).normal(0, 1, 500),
                                                np.random.default_rng(2).normal(0, 1, 500),
                                                np.zeros((10, 2)), np.zeros((10, 2)), tmp_path / "err.png", "errors"),
    }


def test_every_picture_has_a_title_labels_with_units_and_legends_outside_the_data(tmp_path, figures):
    written = _all_pictures(tmp_path)
    assert len(figures) == len(written)
    for (fig, _, _legend, wrong), (name, path) in zip(figures, written.items(), strict=True):
        assert wrong == [], name
        assert path.stat().st_size > 10_000, name
        for ax in fig.axes:
            if ax.has_data() and getattr(ax, "_colorbar", None) is None:
                assert ax.get_title() or fig._suptitle, name
                assert "(" in ax.get_ylabel(), name


def test_dome_maps_mark_the_front_and_the_azimuth_and_have_a_colour_key(tmp_path, figures):
    _all_pictures(tmp_path)
    for fig, texts, legend, _ in (figures[0], figures[2]):
        ax = fig.axes[0]
        assert ax.name == "mollweide"
        assert ax.get_xlabel().startswith("azimuth (°") and ax.get_ylabel() == "elevation (°)"
        assert any(t.startswith("front (azimuth 0°") for t in legend)
        assert {"150°", "120°", "90°", "60°", "30°", "0°", "-30°", "-60°", "-90°", "-120°", "-150°"} <= set(texts)
    key = figures[2][2]
    assert any("seam between panels" in t for t in key) and any(t.startswith("UV pixel") for t in key)


def test_azimuth_ticks_are_rounded_not_truncated():
    assert [style.azimuth_label(d) for d in (119.99999999, 59.9999999, -29.9999999, 180.0, 181.0)] == \
        ["120°", "60°", "-30°", "180°", "-179°"]


def test_the_traces_run_per_decision_and_the_paths_mark_the_release(tmp_path, figures):
    _all_pictures(tmp_path)
    paths_fig, _, paths_legend, _ = figures[3]
    assert "followed: release point" in paths_legend
    assert "lateral error 1 cm" in paths_fig.axes[0].get_title()
    traces_fig = figures[4][0]
    assert traces_fig.axes[-1].get_xlabel().startswith("decision since release (count")
    assert {ax.get_ylabel() for ax in traces_fig.axes} == {"λ (1: 0 familiar .. 1 novel)", "signal (1)"}
    assert "motivation (constant 1)" in figures[4][2]


def test_a_picture_that_breaks_the_style_is_refused(tmp_path):
    fig, ax = style.figure()
    ax.plot([0, 1], [0, 1], label="a line")
    ax.set_xlabel("x")
    ax.legend(loc="upper left")
    with pytest.raises(ValueError, match="no title.*'x' has no unit.*legend inside the axes"):
        style.save(fig, tmp_path / "bad.png")
    assert not (tmp_path / "bad.png").exists()


def test_every_picture_goes_through_the_house_style():
    """No module outside antarium/plots imports matplotlib or saves a figure itself."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    own = root / "antarium" / "plots"
    sources = [p for folder in ("antarium", "examples", "geometry", "renderers", "firmware_proto")
               for p in (root / folder).rglob("*.py") if own not in p.parents]
    offenders = [str(p.relative_to(root)) for p in sources
                 if "savefig" in (text := p.read_text()) or "import matplotlib" in text]
    assert offenders == []
