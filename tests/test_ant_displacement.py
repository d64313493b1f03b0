"""The displacement experiment (PI vs visual memory): the ant is put down beside the feeder, the fictive nest that
its path integration points to is recorded and marked in the picture."""

import json
import math

import numpy as np
import pytest
from matplotlib.figure import Figure

from antarium.ant.homing import displacement


def test_displacement_records_and_marks_the_fictive_nest(tmp_path, monkeypatch):
    drawn = {}
    save = Figure.savefig

    def keep(fig, *args, **kwargs):  # the picture as drawn: its labelled markers
        for line in fig.axes[0].get_lines():
            drawn[line.get_label()] = np.column_stack(line.get_data())
        return save(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    result = displacement(tmp_path, seed=1, n_outbound=40, n_inbound=30, lateral=0.3, ks=(1.0, 0.0))
    fictive = np.array(result["fictive_nest_xy_m"])
    assert math.isclose(np.hypot(*fictive), 0.3, rel_tol=1e-9)   # put down 0.3 m beside the feeder
    saved = json.loads((tmp_path / "displacement_sky.json").read_text())
    assert saved["fictive_nest_xy_m"] == result["fictive_nest_xy_m"]
    assert set(saved["runs"]) == {"1.0", "0.0"}
    np.testing.assert_allclose(drawn["fictive nest (where PI points)"], [fictive], atol=1e-12)
    np.testing.assert_allclose(drawn["nest"], [[0.0, 0.0]])
    assert (tmp_path / "displacement_sky.png").stat().st_size > 0


def test_an_outbound_without_a_compass_cue_is_one_clear_error(tmp_path):
    """No polarised sky (the uniform scene): the outbound walk loses its cue at once; this was an IndexError on
    the empty outbound (no feeder to displace the ant from), and no file is written."""
    with pytest.raises(ValueError, match="the outbound walk ended without a compass cue at decision 0: the sky "
                                         "compass has no cue.*no feeder to displace the ant from"):
        displacement(tmp_path, seed=0, n_outbound=3, n_inbound=2, lateral=0.1, ks=(1.0,), scene="uniform")
    assert not list(tmp_path.iterdir())


def test_a_lateral_that_is_not_finite_is_refused_before_the_walks(tmp_path):
    """NaN was found only after the outbound and the first trip home, as 'pose x must be a finite number'."""
    with pytest.raises(ValueError, match="lateral displacement must be a finite number of metres"):
        displacement(tmp_path, seed=0, n_outbound=3, n_inbound=2, lateral=math.nan, ks=(1.0,))
