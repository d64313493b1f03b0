"""From ordinary RGB content to the dome's channels: linear green, blue and UV radiance (pure numpy).

The dome's pixels emit green (~520 nm), blue (~470 nm) and UV (~375 nm); ant photoreceptors peak near 550,
430 and 375 nm and are blind to red. Scene content carries linear radiance in [0, 1] per channel
(1 = full LED drive at gain 1); a GB pixel draws at most one LED's current, so it shows green + blue <= 1
(`check_showable`). RGB images and vertex colours are sRGB-encoded and map as

    G = 0.15 R + 0.85 G,   B = B,   UV = uv_ratio * B   (unless an explicit UV layer is given)

after sRGB decoding. `uv_ratio` defaults to 0.25: vegetation, soil and rock reflect little UV, while the
sky (see `sky`) is bright in UV, which gives natural scenes the UV/green skyline contrast ants use.
"""

from __future__ import annotations

import numpy as np

from antarium.core.numbers import as_real

#: rows: dome G, B, UV; columns: linear R, G, B (the UV row uses DEFAULT_UV_RATIO)
DEFAULT_UV_RATIO = 0.25
CHANNELS = ("green", "blue", "uv")
#: rounding allowance on green + blue <= 1 (a sum of decimal fractions such as 0.7 + 0.3 may land just above 1)
SHOWABLE_TOLERANCE = 1e-9


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> linear radiance in [0, 1] (IEC 61966-2-1)."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def rgb_to_gbu(rgb_linear: np.ndarray, uv: np.ndarray | None = None, uv_ratio: float = DEFAULT_UV_RATIO) -> np.ndarray:
    """(..., 3) linear RGB -> (..., 3) float32 linear dome G, B, UV; `uv` (...,) replaces the derived UV."""
    rgb = np.asarray(rgb_linear, dtype=np.float64)
    if rgb.shape[-1] != 3:
        raise ValueError(f"RGB content must have 3 channels in its last axis, got shape {rgb.shape}")
    out = np.empty(rgb.shape, dtype=np.float32)
    out[..., 0] = 0.15 * rgb[..., 0] + 0.85 * rgb[..., 1]
    out[..., 1] = rgb[..., 2]
    out[..., 2] = uv_ratio * rgb[..., 2] if uv is None else uv
    return out


def parse_colour(value, name: str = "colour", showable: bool = True) -> np.ndarray:
    """A colour given as a grey level (a number) or (G, B, UV) linear radiances -> (3,) float64 in [0, 1].

    showable: also refuse a colour whose green + blue exceeds 1 (`check_showable`); False for a colour that is
    only a factor of what is shown (a grating's, scaled by its mean and contrast: it checks its peak itself).
    Anything else (a string, a bool, None, a table, a wrong length) raises one ValueError naming `name`.
    """
    items = value.tolist() if isinstance(value, np.ndarray) else value
    items = list(items) if isinstance(items, (list, tuple)) else [items]
    arr = np.array([as_real(v) for v in items], dtype=np.float64)  # NaN for what is not a real number
    if arr.shape == (1,):
        arr = np.repeat(arr, 3)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)) or np.any(arr < 0) or np.any(arr > 1):
        raise ValueError(f"{name} must be a level or (green, blue, uv) linear radiances in [0, 1], "
                         f"got {repr(value)[:60]}")
    if showable:
        check_showable(arr, name)
    return arr


def check_showable(colour: np.ndarray, name: str) -> None:
    """Refuse (3,) linear G, B, UV radiances a pixel cannot show: a GB pixel draws at most one LED's current, so
    green + blue <= 1 (`output.FrameConverter` would scale a larger pair down, flattening its peaks and changing
    its ratio to UV); each channel <= 1. A grey level is therefore at most 0.5."""
    g, b, uv = (float(c) for c in colour)
    if g + b > 1.0 + SHOWABLE_TOLERANCE or max(g, b, uv) > 1.0 + SHOWABLE_TOLERANCE:
        raise ValueError(f"{name} (green {g:.4g}, blue {b:.4g}, uv {uv:.4g}) cannot be shown: a GB pixel draws at "
                         f"most one LED's current, so green + blue must be <= 1 (a grey level <= 0.5), "
                         f"got {g + b:.4g}")
