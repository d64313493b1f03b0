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


def mollweide_directions(width: int) -> tuple[np.ndarray, np.ndarray]:
    """(H*W, 3) unit directions of a Mollweide raster (H = W/2) and the (H*W,) mask of pixels on the map."""
    h = width // 2
    x = ((np.arange(width) + 0.5) / width * 2 - 1) * 2 * np.sqrt(2)
    y = (1 - (np.arange(h) + 0.5) / h * 2) * np.sqrt(2)
    gx, gy = np.meshgrid(x, y)
    theta = np.arcsin(np.clip(gy / np.sqrt(2), -1, 1))
    lat = np.arcsin(np.clip((2 * theta + np.sin(2 * theta)) / np.pi, -1, 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        lon = np.pi * gx / (2 * np.sqrt(2) * np.cos(theta))
    inside = np.abs(lon) <= np.pi
    az = -lon  # seen from inside: azimuth grows to the left
    d = np.stack([np.cos(lat) * np.cos(az), np.cos(lat) * np.sin(az), np.sin(lat)], axis=-1).reshape(-1, 3)
    return np.nan_to_num(d), inside.ravel()


def led_map(frame: np.ndarray, dome, width: int = 1200, dot_deg: float = 0.9) -> np.ndarray:
    """(W/2, W, 3) uint8 sRGB Mollweide map of an LED frame; every LED a dot of radius `dot_deg`."""
    from scipy.spatial import cKDTree

    d, inside = mollweide_directions(width)
    dist, idx = cKDTree(dome.directions).query(d, distance_upper_bound=2 * np.sin(np.radians(dot_deg) / 2))
    hit = inside & np.isfinite(dist)
    colours = frame_colours(frame, np.asarray(dome.is_uv))
    img = np.zeros((len(d), 3))
    img[inside] = 0.015  # the map's outline, so the dome's edge stays visible
    img[hit] = colours[idx[hit]]
    return _to_srgb8(img).reshape(width // 2, width, 3)


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


def dome_picture(frame: np.ndarray, dome, path: str | Path, title: str, width_px: int = 1400) -> Path:
    """Write a PNG `width_px` wide: the LEDs of `frame` (20350, 2) uint16 on a Mollweide map seen from inside,
    one dot per LED in its display colour, with azimuth/elevation axes, the front marked and a colour key."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from antarium.plots import style

    fig = style.pyplot().figure(figsize=(12.0, 7.2))
    ax = fig.add_subplot(projection="mollweide")
    rgb = _to_srgb8(frame_colours(frame, np.asarray(dome.is_uv))) / 255.0
    gb, uv = dome.gb_index, dome.uv_index
    ax.scatter(-dome.azimuth[gb], dome.elevation[gb], s=7, c=rgb[gb], marker="h", linewidths=0)
    ax.scatter(-dome.azimuth[uv], dome.elevation[uv], s=14, c=rgb[uv], edgecolors="0.45", linewidths=0.5)
    style.dome_axes(ax, float(np.degrees(dome.elevation.min())))
    key = [Patch(color=(0, 1, 0), label="green LED drive"), Patch(color=(0, 0, 1), label="blue LED drive"),
           Patch(color=(0.8, 0, 1), label="UV pixel (grey ring): plain + polarised UV drive"),
           Patch(color="black", label="black: LED off, or seam between panels (no LEDs)"),
           Line2D([], [], marker="^", mfc="none", mec="red", mew=1.5, ls="none", label="front (azimuth 0°, +x)")]
    style.legend(ax, "below", handles=key)
    ax.set_title(title)
    return style.save(fig, path, dpi=max(20, round(width_px / 12.0)))
