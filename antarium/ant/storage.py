"""Model files: a versioned `.npz` with bit-packed KC -> MBON synapses (or stored views for perfect memory).

| key              | dtype, shape          | meaning                                                        |
|------------------|-----------------------|----------------------------------------------------------------|
| format           | str                   | "antarium-ant-model"                                           |
| version          | int                   | FORMAT_VERSION                                                 |
| kind             | str                   | a key of `models.MODELS` (antcar, ardin, perfect_memory, cx, ...) |
| params           | str (JSON)            | the model's parameters (the KC wiring is rebuilt from `seed`)  |
| eye              | str (JSON)            | the `EyeParams` the model learned with                         |
| n_pn             | int                   | projection neurons                                             |
| mbon_<name>      | uint8 (ceil(n_kc/8),) | bit-packed synapses of MBON <name> (1 = undepressed)           |
| n_kc_<name>      | int                   | KCs of MBON <name>                                             |
| views            | float16 (n, n_pn)     | perfect memory's stored views                                  |
| learned_views    | int                   | views learned                                                  |
| cpu4             | float64 (16,)         | the CX's CPU4 memory (cx, cxmb, one_ring; version >= 3)        |
| route            | float64 (n, 2)        | the learned route, metres (optional)                           |
| scene            | str                   | the scene it learned in, as `--scene` names it (optional)      |
"""

from __future__ import annotations

import json
import os
import zipfile
import zlib
from dataclasses import asdict, fields
from pathlib import Path

import numpy as np

from antarium.ant import ROUTE_MODELS
from antarium.ant.eye import EyeParams
from antarium.ant.models import MODELS, PerfectMemoryModel
from antarium.ant.mushroom_body import MBON

FORMAT = "antarium-ant-model"
FORMAT_VERSION = 3
#: versions this code reads: 1 lacks the eye's `row_gain` (False then); 3 adds the central-complex models' CPU4
READABLE_VERSIONS = (1, 2, 3)
#: version -> the eye parameters its files lack (their defaults then)
EYE_ADDED = {1: frozenset({"row_gain"})}


class ModelFileError(ValueError):
    """A model file that is not a valid antarium ant model of a readable version and shape."""


def save_model(path: str | os.PathLike, model, eye_params: EyeParams, route: np.ndarray | None = None,
               scene: str | None = None) -> Path:
    """Write `model` to `path` (.npz); the file is written beside and renamed, so a crash loses nothing (a folder
    is refused; nothing is left beside it on failure)."""
    path = Path(path)
    arrays: dict[str, np.ndarray] = {
        "format": np.array(FORMAT), "version": np.array(FORMAT_VERSION), "kind": np.array(model.kind),
        "params": np.array(json.dumps(asdict(model.params))), "eye": np.array(json.dumps(asdict(eye_params))),
        "n_pn": np.array(model.n_pn), "learned_views": np.array(model.learned_views),
    }
    if isinstance(model, PerfectMemoryModel):
        arrays["views"] = model.views.astype(np.float16)
    else:
        for name, mbon in getattr(model, "mbons", {}).items():
            arrays[f"mbon_{name}"] = mbon.packed()
            arrays[f"n_kc_{name}"] = np.array(mbon.n_kc)
    if hasattr(model, "cx"):
        arrays["cpu4"] = model.cx.memory()
    if route is not None:
        arrays["route"] = np.asarray(route, np.float64)
    if scene is not None:
        arrays["scene"] = np.array(scene)
    if path.is_dir():
        raise IsADirectoryError(f"{str(path)!r} is a folder; give the model file to write (e.g. ant.npz)")
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def load_model(path: str | os.PathLike):
    """(model, eye_params, route or None) from a file written by `save_model`; ModelFileError if invalid."""
    path = Path(path)
    try:
        data = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise
    except (zipfile.BadZipFile, EOFError) as exc:  # a zip archive cut short (a copy or a write interrupted)
        raise ModelFileError(f"{path}: damaged model file (a truncated or corrupted .npz archive: {exc})") from None
    except (OSError, ValueError):  # numpy's own message would suggest unpickling an untrusted file
        raise ModelFileError(f"{path}: not an antarium ant model file (not a NumPy .npz archive; "
                             f"write one with `antarium ant learn`)") from None
    if not isinstance(data, np.lib.npyio.NpzFile):  # a single array (.npy), whatever the file's name
        raise ModelFileError(f"{path}: not an antarium ant model file (a single NumPy array, .npy, not a .npz "
                             f"archive; write one with `antarium ant learn`)")
    try:
        with data:
            return _read(path, data)
    except ModelFileError:
        raise
    except (zipfile.BadZipFile, EOFError, zlib.error) as exc:  # an archive member truncated or corrupted
        raise ModelFileError(f"{path}: damaged model file (a truncated or corrupted .npz archive: {exc})") from None
    except ValueError as exc:  # an entry numpy cannot read, or parameters the model refuses
        raise ModelFileError(f"{path}: {exc}") from None


def load_route_model(path: str | os.PathLike):
    """`load_model` of a route model's file (a kind in `ROUTE_MODELS`: what `antarium ant run | serve` release on
    a route); ModelFileError naming the kind of any other (the central-complex models home by path integration)."""
    model, eye_params, route = load_model(path)
    if model.kind not in ROUTE_MODELS:
        raise ModelFileError(f"{path} holds a {model.kind} model; a route is followed by a route model "
                             f"({', '.join(ROUTE_MODELS)}); the central-complex models home by path integration: "
                             f"`antarium ant homing | arena | displace`")
    return model, eye_params, route


def learned_scene(path: str | os.PathLike) -> str | None:
    """The scene the model of a file `load_model` read learned in (`save_model`'s `scene`); None when the file
    does not say (files before 2026-11-28, or a scene given as an object)."""
    with np.load(path, allow_pickle=False) as data:
        return _scalar(Path(path), data, "scene", str) if "scene" in data.files else None


def _entry(path: Path, data, key: str, kind: str = "") -> np.ndarray:
    """The archive's entry `key`; ModelFileError naming it when it is missing."""
    if key not in data.files:
        raise ModelFileError(f"{path}: entry {key!r} missing{f' (a {kind} model file has one)' if kind else ''}")
    return data[key]


def _scalar(path: Path, data, key: str, kind: type) -> int | str:
    """The 0-d entry `key` as an int or a str; ModelFileError naming it and its dtype when it is not one."""
    value = _entry(path, data, key)
    ok = np.issubdtype(value.dtype, np.integer) if kind is int else value.dtype.kind == "U"
    if value.shape != () or not ok:
        raise ModelFileError(f"{path}: entry {key!r} must be a single {kind.__name__}, "
                             f"got {value.dtype} of shape {value.shape}")
    return kind(value)


def _json(path: Path, data, key: str, cls, what: str, optional: frozenset[str] = frozenset()):
    """The dataclass `cls` from the JSON object in entry `key`, its keys cls's fields (those in `optional` may be
    left out: their defaults then)."""
    try:
        raw = json.loads(_scalar(path, data, key, str))
    except json.JSONDecodeError as exc:
        raise ModelFileError(f"{path}: entry {key!r} is not valid JSON ({exc})") from None
    known = {f.name for f in fields(cls)}
    if not isinstance(raw, dict):
        raise ModelFileError(f"{path}: entry {key!r} must hold a JSON object of {what}, got {type(raw).__name__}")
    unknown, missing = sorted(set(raw) - known), sorted(known - optional - set(raw))
    if unknown or missing:
        wrong = "; ".join([f"unknown {unknown}"] * bool(unknown) + [f"missing {missing}"] * bool(missing))
        raise ModelFileError(f"{path}: {what}: {wrong}; allowed: {sorted(known)}")
    try:
        return cls(**raw)
    except (TypeError, ValueError) as exc:
        raise ModelFileError(f"{path}: {what}: {exc}") from None


def _read(path: Path, data):
    if "format" not in data.files or str(data["format"]) != FORMAT:
        raise ModelFileError(f"{path}: not an antarium ant model file (no format tag {FORMAT!r})")
    version = _scalar(path, data, "version", int)
    if version not in READABLE_VERSIONS:
        raise ModelFileError(f"{path}: model file version {version} cannot be read; "
                             f"allowed: {', '.join(map(str, READABLE_VERSIONS))}")
    kind = _scalar(path, data, "kind", str)
    if kind not in MODELS:
        raise ModelFileError(f"{path}: model kind {kind!r} not known; allowed: {', '.join(MODELS)}")
    cls, params_cls = MODELS[kind]
    params = _json(path, data, "params", params_cls, f"{kind} parameters")
    eye_params = _json(path, data, "eye", EyeParams, "eye parameters", EYE_ADDED.get(version, frozenset()))
    n_pn = _scalar(path, data, "n_pn", int)
    if n_pn != eye_params.n_pn:
        raise ModelFileError(f"{path}: n_pn {n_pn} does not match the eye's {eye_params.n_pn} PNs")
    if cls is PerfectMemoryModel:
        views = _entry(path, data, "views", kind)
        if views.ndim != 2 or views.shape[1] != n_pn:
            raise ModelFileError(f"{path}: stored views must have shape (n, {n_pn}), got {views.shape}")
        model = cls(n_pn, params, views.astype(np.float32))
    else:
        model = cls(n_pn, params)
        mbons = {}
        for name, mbon in getattr(model, "mbons", {}).items():
            key = f"mbon_{name}"
            if key not in data.files:
                raise ModelFileError(f"{path}: MBON {name!r} missing")
            n_kc = _scalar(path, data, f"n_kc_{name}", int)
            if n_kc != mbon.n_kc:
                raise ModelFileError(f"{path}: MBON {name!r} has {n_kc} KCs, parameters say {mbon.n_kc}")
            try:
                mbons[name] = MBON.from_packed(data[key], n_kc)
            except ValueError as exc:
                raise ModelFileError(f"{path}: {exc}") from None
        if hasattr(model, "mbons"):
            model.mbons = mbons
        model.learned_views = _scalar(path, data, "learned_views", int)
        if model.learned_views < 0:
            raise ModelFileError(f"{path}: learned_views must be >= 0, got {model.learned_views}")
        if hasattr(model, "cx"):
            if "cpu4" not in data.files:
                raise ModelFileError(f"{path}: the {kind} model's CPU4 memory (cpu4) is missing")
            try:
                model.restore(data["cpu4"])
            except ValueError as exc:
                raise ModelFileError(f"{path}: {exc}") from None
    route = None
    if "route" in data.files:
        route = data["route"]
        if route.ndim != 2 or route.shape[1] != 2 or not np.issubdtype(route.dtype, np.floating) \
                or not np.all(np.isfinite(route)):
            raise ModelFileError(f"{path}: the route must be finite (n, 2) floats (x, y in metres), "
                                 f"got {route.dtype} of shape {route.shape}")
    return model, eye_params, route


def mbon_bytes(model) -> dict[str, int]:
    """Bytes of the learned memory as a model file stores it (`save_model`, before compression), for every kind
    alike: per MBON its bit-packed synapses, the CX's CPU4 (float64), or perfect memory's views in float16
    ({'views': bytes}; a running model holds them in float32, in a store with room to grow: more than this)."""
    if isinstance(model, PerfectMemoryModel):
        return {"views": int(model.views.size * np.dtype(np.float16).itemsize)}
    sizes = {name: int(mbon.packed().nbytes) for name, mbon in getattr(model, "mbons", {}).items()}
    if hasattr(model, "cx"):
        sizes["cpu4"] = int(model.cx.memory().nbytes)
    return sizes
