"""The one place where an OpenGL context is created: moderngl over a standalone EGL context.

No display, no window. On machines without a GPU, Mesa's llvmpipe renders in software; the same code runs
unchanged on a GPU driver.
"""

from __future__ import annotations

import functools

#: What a Debian/Ubuntu machine needs for headless EGL rendering with Mesa.
SYSTEM_PACKAGES = "libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri"

_REQUIRED_GL = 330


def create_context():
    """A standalone moderngl context on EGL (OpenGL >= 3.3 core).

    Raises RuntimeError naming the missing system packages when EGL or a GL driver cannot be loaded.
    """
    try:
        import moderngl
    except ImportError as exc:  # pragma: no cover - moderngl is a hard dependency
        raise RuntimeError(f"moderngl is not installed ({exc}); pip install 'moderngl>=5.10'") from exc
    try:
        ctx = moderngl.create_context(standalone=True, backend="egl", require=_REQUIRED_GL)
    except Exception as exc:
        raise RuntimeError(
            f"cannot create an off-screen EGL/OpenGL {_REQUIRED_GL // 100}.{_REQUIRED_GL % 100 // 10} context "
            f"({exc}). Install the system packages: sudo apt-get install -y {SYSTEM_PACKAGES}"
        ) from exc
    return ctx


@functools.cache
def gl_renderer_string() -> str:
    """`describe` of this process's GL driver (probed once, with a context made and released for it)."""
    ctx = create_context()
    try:
        return describe(ctx)
    finally:
        ctx.release()


def describe(ctx) -> str:
    """'renderer, version' of a context, e.g. 'llvmpipe (LLVM 15.0.6, 256 bits), 4.5 (Core Profile) Mesa'."""
    with ctx:  # the strings are the current context's
        return f"{ctx.info['GL_RENDERER']}, {ctx.info['GL_VERSION']}"
