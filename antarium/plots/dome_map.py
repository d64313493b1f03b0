"""Pictures a person can look at: LED frames as an equal-area (Mollweide) map, cube-map atlases as images.

Display colours: green drive -> green, blue drive -> blue, UV (plain + polarised) -> violet (red + blue),
then sRGB-encoded. The map is seen from inside the dome: azimuth 0 (+x) in the centre, azimuth growing to the
left, the zenith at the top.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _to_srgb8(linear: np.ndarray) -> np.ndarray:
    c = np.clip(linear, 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return (s * 255 + 0.5).astype(np.uint8)


def frame_colours(frame: np.ndarray, is_uv: np.ndarray) -> np.ndarray:
    """(20350, 3) linear display RGB in [0, 1] of an LED frame (drive / 65535)."""
    f = frame.astype(np.float64) / 65535.0
    rgb = np.zeros((len(f), 3))
    rgb[~is_uv, 1] = f[~is_uv, 0]
    rgb[~is_uv, 2] = f[~is_uv, 1]
    uv = f[is_uv].sum(axis=1)
    rgb[is_uv, 0] = 0.6 * uv
    rgb[is_uv, 2] = uv
    return rgb


def atlas_image(cube: np.ndarray) -> np.ndarray:
    """(6N, N, 3) uint8 sRGB image of a (6, N, N, 4) atlas [G, B, UV, pol UV], faces top to bottom in
    `cubemap.FACES` order, each face upright."""
    n = cube.shape[1]
    rgb = np.zeros((6, n, n, 3))
    rgb[..., 0] = 0.6 * cube[..., 2]
    rgb[..., 1] = cube[..., 0]
    rgb[..., 2] = np.maximum(cube[..., 1], cube[..., 2])
    return _to_srgb8(rgb[:, ::-1].reshape(6 * n, n, 3))


def check_png_path(path: str | Path, what: str = "image") -> Path:
    """`path` as a Path; ValueError in one line unless its name ends in .png."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"{what} {str(path)!r} must be a .png file name (e.g. {path.with_suffix('.png').name!r})")
    return path


def save_png(image: np.ndarray, path: str | Path) -> Path:
    """Write an (H, W, 3) uint8 RGB image as PNG (the name must end in .png); returns the absolute path."""
    import cv2

    path = check_png_path(path).expanduser().resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), image[:, :, ::-1]):
        raise ValueError(f"cannot write image {path} (is the suffix .png and the folder writable?)")
    return path


#: narrowest dome map (pixels) whose text stays legible
MIN_WIDTH_PX = 400
#: pixels per inch the dome map's text is drawn for (its point sizes legible at this scale)
_PX_PER_INCH = 100.0


def dome_picture(frame: np.ndarray, dome, path: str | Path, title: str, width_px: int = 1400) -> Path:
    """Write a PNG exactly `width_px` wide (at least MIN_WIDTH_PX; ValueError below): the LEDs of `frame`
    (20350, 2) uint16 on a Mollweide map seen from inside, one dot per LED in its display colour, with
    azimuth/elevation axes, the front marked and a colour key. The figure is drawn at the size that puts about
    100 pixels in an inch, so that the text keeps a legible size in pixels at every width."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from antarium.plots import style

    if int(width_px) != width_px or width_px < MIN_WIDTH_PX:
        raise ValueError(f"dome map width must be a whole number of pixels >= {MIN_WIDTH_PX} (narrower pictures "
                         f"have illegible text), got {width_px}")
    inches = float(np.clip(width_px / _PX_PER_INCH, MIN_WIDTH_PX / _PX_PER_INCH, 12.0))
    fig = style.pyplot().figure(figsize=(inches, 0.6 * inches))
    ax = fig.add_subplot(projection="mollweide")
    rgb = _to_srgb8(frame_colours(frame, np.asarray(dome.is_uv))) / 255.0
    gb, uv = dome.gb_index, dome.uv_index
    dot = (inches / 12.0) ** 2  # marker areas (points^2) shrink with the map
    ax.scatter(-dome.azimuth[gb], dome.elevation[gb], s=7 * dot, c=rgb[gb], marker="h", linewidths=0)
    ax.scatter(-dome.azimuth[uv], dome.elevation[uv], s=14 * dot, c=rgb[uv], edgecolors="0.45", linewidths=0.5)
    style.dome_axes(ax, float(np.degrees(dome.elevation.min())))
    ax.xaxis.label.set_wrap(True)  # within the figure's width: the text keeps its size in a narrow picture
    key = [Patch(color=(0, 1, 0), label="green LED drive"), Patch(color=(0, 0, 1), label="blue LED drive"),
           Patch(color=(0.8, 0, 1), label="UV pixel (grey ring): plain + polarised UV drive"),
           Patch(color="black", label="black: LED off, or seam between panels (no LEDs)"),
           Line2D([], [], marker="^", mfc="none", mec="red", mew=1.5, ls="none", label="front (azimuth 0°, +x)")]
    style.legend(ax, "below", handles=key, ncol=3 if inches >= 9.0 else 1)
    ax.set_title(title, wrap=True)
    return style.save(fig, path, width_px=int(width_px))
