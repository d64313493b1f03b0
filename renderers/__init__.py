"""Off-screen rendering: cube maps of a 3D scene sampled per LED.

    from antarium.renderers import Renderer, build_scene
    renderer = Renderer(load_dome())
    renderer.set_scene("habitat")            # or {"scene": "grating", "period_deg": 20}, or a file path
    frame = renderer.render(Pose(0, 0, 0.01, 0))   # (20350, 2) uint16 LED frame

Importing this package imports no GL: the context is created by `antarium.renderers.gl.create_context`
when a `Renderer` is built.
"""

from importlib import import_module

_LAZY = {
    "Renderer": "antarium.renderers.renderer",
    "Scene": "antarium.renderers.scene",
    "SceneObject": "antarium.renderers.scene",
    "MeshData": "antarium.renderers.scene",
    "build_scene": "antarium.renderers.library",
    "SCENES": "antarium.renderers.library",
}


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'antarium.renderers' has no attribute {name!r}")
    return getattr(import_module(module), name)


__all__ = list(_LAZY)
