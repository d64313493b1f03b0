"""Model files: versioned, bit-packed, and refused with a clear error when wrong."""

import json

import numpy as np
import pytest

from antarium.ant.eye import EyeParams, View
from antarium.ant.models import make_model
from antarium.ant.storage import FORMAT_VERSION, ModelFileError, load_model, mbon_bytes, save_model

N_PN = 800


def view(seed: int) -> View:
    rng = np.random.default_rng(seed)
    return View(rng.random((16, 300), dtype=np.float32), 6, 50)


@pytest.mark.parametrize("kind", ["antcar", "ardin", "perfect_memory"])
def test_models_round_trip_through_a_file(tmp_path, kind):
    model = make_model(kind, N_PN, **({"seed": 5} if kind != "perfect_memory" else {}))
    for s in range(3):
        model.learn(view(s))
    path = save_model(tmp_path / "m.npz", model, EyeParams(), route=np.array([[0, 0], [1.0, 0.5]]))
    loaded, eye_params, route = load_model(path)
    assert loaded.kind == kind and eye_params == EyeParams() and loaded.learned_views == 3
    np.testing.assert_array_equal(route, [[0, 0], [1.0, 0.5]])
    probe = view(1)
    assert loaded.decide(probe).turn == model.decide(probe).turn


def test_route_mbons_take_1875_bytes_whatever_the_route_length():
    short, long_ = make_model("antcar", N_PN), make_model("antcar", N_PN)
    short.learn(view(0))
    for s in range(40):
        long_.learn(view(s))
    assert mbon_bytes(short) == mbon_bytes(long_) == {"left": 1875, "right": 1875, "nest": 625, "feeder": 625}


def _rewrite(path, **changes):
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    arrays.update(changes)
    np.savez(path, **arrays)


def test_wrong_version_shape_or_kind_is_refused(tmp_path):
    model = make_model("antcar", N_PN)
    path = save_model(tmp_path / "m.npz", model, EyeParams())
    _rewrite(path, version=np.array(FORMAT_VERSION + 1))
    with pytest.raises(ModelFileError, match=f"version {FORMAT_VERSION + 1} cannot be read; allowed: 1, 2, 3"):
        load_model(path)
    # a version 1 file (eye without row_gain) is still read, with the plain eye
    path = save_model(tmp_path / "m.npz", model, EyeParams(row_gain=True))
    eye = json.loads(str(np.load(path)["eye"]))
    del eye["row_gain"]
    _rewrite(path, version=np.array(1), eye=np.array(json.dumps(eye)))
    assert load_model(path)[1] == EyeParams()
    path = save_model(tmp_path / "m.npz", model, EyeParams())
    _rewrite(path, mbon_left=np.zeros(100, np.uint8))
    with pytest.raises(ModelFileError, match=r"must be \(1875,\) uint8"):
        load_model(path)
    path = save_model(tmp_path / "m.npz", model, EyeParams())
    params = json.loads(str(np.load(path)["params"]))
    params["n_kc"] = 1000
    _rewrite(path, params=np.array(json.dumps(params)))
    with pytest.raises(ModelFileError, match="has 15000 KCs, parameters say 1000"):
        load_model(path)
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ModelFileError, match="not an antarium ant model"):
        load_model(tmp_path / "junk.npz")
    with pytest.raises(FileNotFoundError):
        load_model(tmp_path / "missing.npz")


@pytest.mark.parametrize("cut", [100, 0.5, -10])
def test_a_truncated_file_is_refused_naming_it(tmp_path, cut):
    path = save_model(tmp_path / "m.npz", make_model("antcar", N_PN, n_kc=2000, place_n_kc=500), EyeParams())
    data = path.read_bytes()
    end = int(len(data) * cut) if isinstance(cut, float) else cut
    (tmp_path / "cut.npz").write_bytes(data[:end])
    with pytest.raises(ModelFileError, match=r"cut\.npz: damaged model file \(a truncated or corrupted"):
        load_model(tmp_path / "cut.npz")


def test_a_corrupted_entry_is_refused_naming_the_file(tmp_path):
    path = save_model(tmp_path / "m.npz", make_model("ardin", N_PN, n_kc=2000), EyeParams())
    data = bytearray(path.read_bytes())
    at = data.index(b"mbon_familiarity.npy") + 60  # inside the compressed member
    data[at:at + 40] = bytes(40)
    (tmp_path / "bad.npz").write_bytes(bytes(data))
    with pytest.raises(ModelFileError, match=r"bad\.npz: damaged model file"):
        load_model(tmp_path / "bad.npz")


@pytest.mark.parametrize(("changes", "message"), [
    ({"kind": None}, "entry 'kind' missing"),
    ({"learned_views": None}, "entry 'learned_views' missing"),
    ({"params": None}, "entry 'params' missing"),
    ({"version": np.array("3")}, r"entry 'version' must be a single int, got <U1"),
    ({"kind": np.array(3)}, "entry 'kind' must be a single str"),
    ({"learned_views": np.array([1, 2])}, r"entry 'learned_views' must be a single int, got int64 of shape \(2,\)"),
    ({"eye": "future"}, r"eye parameters: unknown \['future_field'\]; allowed: \['channel'"),
    ({"eye": "short"}, r"eye parameters: missing \['gamma'\]"),
    ({"eye": np.array("[1, 2]")}, "entry 'eye' must hold a JSON object of eye parameters, got list"),
    ({"eye": np.array("{")}, "entry 'eye' is not valid JSON"),
    ({"route": np.array([1.0, 2.0, 3.0])}, r"the route must be finite \(n, 2\) floats .* got float64 of shape \(3,\)"),
    ({"route": np.array([[0.0, np.nan]])}, r"the route must be finite \(n, 2\) floats"),
])
def test_a_file_with_a_wrong_or_missing_entry_is_refused_in_one_line(tmp_path, changes, message):
    path = save_model(tmp_path / "m.npz", make_model("antcar", N_PN, n_kc=2000, place_n_kc=500), EyeParams(),
                      route=np.array([[0.0, 0.0], [1.0, 0.0]]))
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    eye = json.loads(str(arrays["eye"]))
    if changes.get("eye") == "future":
        changes["eye"] = np.array(json.dumps({**eye, "future_field": 1}))
    elif changes.get("eye") == "short":
        changes["eye"] = np.array(json.dumps({k: v for k, v in eye.items() if k != "gamma"}))
    for key, value in changes.items():
        if value is None:
            del arrays[key]
        else:
            arrays[key] = value
    np.savez(path, **arrays)
    with pytest.raises(ModelFileError, match=message) as info:
        load_model(path)
    assert str(info.value).startswith(f"{path}: ") and "\n" not in str(info.value)
