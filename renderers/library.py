"""Scenes by name, spec dict or file path — what a rig config or a bus command asks for.

    build_scene("habitat")
    build_scene({"scene": "grating", "period_deg": 20, "speed_deg_s": 30})
    build_scene("worlds/tree.glb")          # a mesh world under the default sky
    build_scene({"scene": "panorama", "path": "pano.exr", "uv": "pano_uv.png"})

Angles at this edge are in degrees and named `*_deg`; everything inside is SI.
"""

from __future__ import annotations

import math
from pathlib import Path

from antarium.core.numbers import check_number

from . import stimuli
from .panorama import IMAGE_SUFFIXES, Panorama
from .scene import Scene
from .sky import Sky

MESH_SUFFIXES = (".obj", ".ply", ".glb", ".gltf", ".stl")


def _deg(params: dict, key: str, default=None, suffix: str = "_deg"):
    """Pop `key` + suffix (degrees, or degrees per second) from params, in radians (default when absent; a value
    that is not a finite number, null included, raises ValueError naming it)."""
    if key + suffix not in params:
        return default
    return math.radians(check_number(key + suffix, params.pop(key + suffix)))


def _path(params: dict, key: str) -> str:
    """Pop the file path `key` from params (a string)."""
    value = params.pop(key)
    if not isinstance(value, (str, Path)):
        raise ValueError(f"{key} must be a file path (a string), got {repr(value)[:60]}")
    return str(value)


def _sky(params: dict) -> Sky:
    kw = {}
    for key in ("sun_azimuth", "sun_elevation", "sun_radius"):
        v = _deg(params, key)
        if v is not None:
            kw[key] = v
    for key in ("dop_max", "zenith", "ground", "sun_radiance"):
        if key in params:
            kw[key] = params.pop(key)
    return Sky(**kw)


def _uniform(p):
    return Scene(far=[stimuli.Uniform(p.pop("colour", 0.5))], name="uniform")


def _horizon(p):
    kw = {k: p.pop(k) for k in ("sky", "ground") if k in p}
    return Scene(far=[stimuli.Horizon(elevation=_deg(p, "elevation", 0.0), **kw)], name="horizon")


def _bar(d: dict) -> stimuli.Bar:
    if not isinstance(d, dict):
        raise ValueError(f"each of bars must be a table of bar parameters, got {repr(d)[:60]}")
    d = dict(d)
    bar = stimuli.Bar(azimuth=_deg(d, "azimuth", 0.0), width=_deg(d, "width", math.radians(10)),
                      bottom=_deg(d, "bottom", -math.pi / 2), top=_deg(d, "top", math.pi / 2))
    if d:
        raise ValueError(f"unknown bar parameter(s): {', '.join(sorted(d))}; allowed: azimuth_deg, width_deg, "
                         f"bottom_deg, top_deg")
    return bar


def _bars(p):
    if "bars" in p:
        specs = p.pop("bars")
        if not isinstance(specs, (list, tuple)):
            raise ValueError(f"bars must be a list of bar parameter tables, got {specs!r}")
        bars = [_bar(b) for b in specs]
    else:
        keys = ("azimuth_deg", "width_deg", "bottom_deg", "top_deg")
        bars = [_bar({k: p.pop(k) for k in keys if k in p})]
    kw = {k: p.pop(k) for k in ("colour", "background") if k in p}
    return Scene(far=[stimuli.Bars(bars=bars, **kw)], name="bars")


def _grating(p):
    kw = {k: p.pop(k) for k in ("waveform", "contrast", "mean", "colour") if k in p}
    g = stimuli.Grating(period=_deg(p, "period", math.radians(20)), orientation=_deg(p, "orientation", 0.0),
                        speed=_deg(p, "speed", 0.0, suffix="_deg_s"), phase=_deg(p, "phase", 0.0), **kw)
    return Scene(far=[g], name="grating")


def _checkerboard(p):
    kw = {k: p.pop(k) for k in ("colour_a", "colour_b") if k in p}
    return Scene(far=[stimuli.Checkerboard(size=_deg(p, "size", math.radians(15)), **kw)], name="checkerboard")


def _sky_scene(p):
    return Scene(far=[_sky(p)], name="sky")


def _panorama(p):
    if "path" not in p:
        raise ValueError("a panorama scene needs 'path' (an equirectangular image)")
    path = _path(p, "path")
    kw = {k: p.pop(k) for k in ("exposure", "uv_ratio") if k in p}
    if "uv" in p:
        kw["uv"] = _path(p, "uv")
    return Scene(far=[_sky(p), Panorama(path, **kw)], name=Path(path).stem)


def _mesh_world(p):
    from .meshes import load_mesh_objects

    if "path" not in p:
        raise ValueError("a mesh scene needs 'path' (OBJ, PLY, GLB/GLTF or STL)")
    path = _path(p, "path")
    units = {k: p.pop(k) for k in ("scale", "up", "origin") if k in p}
    far = [_sky(p)]
    if "panorama" in p:
        far.append(Panorama(_path(p, "panorama")))
    return Scene(far=far, objects=load_mesh_objects(path, **units), name=Path(path).stem)


def _habitat(p):
    from .habitat import habitat_scene

    kw = {k: check_number(k, p.pop(k), 0, integer=True)
          for k in ("seed", "n_trees", "n_bushes", "n_tussocks", "n_stones") if k in p}
    if "size" in p:
        kw["size"] = check_number("size (m)", p.pop("size"), 20.0)
    return habitat_scene(**kw)


#: scene name -> builder taking a dict of parameters (popping what it uses)
SCENES = {
    "habitat": _habitat,
    "uniform": _uniform,
    "horizon": _horizon,
    "bars": _bars,
    "bar": _bars,
    "grating": _grating,
    "checkerboard": _checkerboard,
    "sky": _sky_scene,
    "panorama": _panorama,
    "mesh": _mesh_world,
}


def build_scene(spec) -> Scene:
    """A `Scene` from a name, a path or a dict {"scene": name_or_path, **parameters}.

    Raises ValueError (unknown name or parameter, bad value) or FileNotFoundError (missing file), naming it.
    """
    if isinstance(spec, Scene):
        return spec
    if isinstance(spec, Path):
        spec = str(spec)
    if isinstance(spec, str):
        spec = {"scene": spec}
    if not isinstance(spec, dict) or "scene" not in spec:
        raise ValueError(f"a scene is a name ({', '.join(SCENES)}), a file path, or a table with 'scene'; "
                         f"got {spec!r}")
    params = dict(spec)
    name = params.pop("scene")
    if not isinstance(name, str):
        raise ValueError(f"scene must be a name or a path, got {name!r}")
    builder = SCENES.get(name)
    if builder is None:
        suffix = Path(name).suffix.lower()
        if suffix in (*MESH_SUFFIXES, *IMAGE_SUFFIXES) and "path" in params:
            raise ValueError(f"scene {name!r} is a file already; give either it or 'path' "
                             f"({repr(params['path'])[:60]}), not both")
        if suffix in MESH_SUFFIXES:
            builder, params["path"] = _mesh_world, name
        elif suffix in IMAGE_SUFFIXES:
            builder, params["path"] = _panorama, name
        elif suffix:
            raise ValueError(f"unsupported scene file format {suffix!r} ({name}); meshes: {', '.join(MESH_SUFFIXES)}"
                             f"; panoramas: {', '.join(IMAGE_SUFFIXES)}")
        else:
            raise ValueError(f"unknown scene {name!r}; known: {', '.join(SCENES)}, or a mesh/image file path")
    scene = builder(params)
    edits = {k: params.pop(k) for k in ("rotation_deg", "channel_gain", "swap_green_blue", "lowpass_deg",
                                          "contrast") if k in params}
    if params:
        raise ValueError(f"unknown parameter(s) for scene {name!r}: {', '.join(sorted(params))}")
    if "rotation_deg" in edits:
        scene.rotation = _deg(edits, "rotation")
    for key, value in edits.items():
        setattr(scene, key, value)
    scene.__post_init__()
    return scene
