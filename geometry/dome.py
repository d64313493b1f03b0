"""`Dome`: every pixel of the Antarium — position, direction, address, photometric gain — as numpy arrays.

A thin cached object over the pure functions of `solid`, `layout`, `addressing` and `photometry`.
`load_dome()` builds it from the shipped layout in milliseconds and caches it per layout file.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np

from . import addressing
from .constants import GB_PER_PANEL, N_PANELS, N_PIXELS, PIXELS_PER_PANEL
from .layout import SHIPPED_LAYOUT, PanelLayout, load_layout, to_dome
from .photometry import DEFAULT_HALF_INTENSITY_DEG, compensation_gain, emission_angle
from .solid import PanelFrames, Solid, dome_panels


@dataclass(frozen=True, eq=False)
class Dome:
    """The dome's 20,350 pixels in global index order (g = panel * 370 + local).

    Array attributes (all read-only views):
      positions (20350, 3) float64 m; directions (20350, 3) unit; distance (20350,) m;
      azimuth, elevation (20350,) rad; emission_angle (20350,) rad; gain (20350,) in (0, 1];
      index, panel, pentagon, slot, local (20350,) int64; is_uv (20350,) bool;
      gb_index (19855,), uv_index (495,) int64; panel_axes (55, 3, 3) rows x, y, inward normal;
      panel_normals (55, 3) inward unit normals; panel_corners (55, 3, 3) m (apex, base 0, base 1).
    """

    solid: Solid
    layout: PanelLayout
    half_intensity_deg: float = DEFAULT_HALF_INTENSITY_DEG

    @cached_property
    def frames(self) -> PanelFrames:
        return dome_panels(self.solid)

    def _ro(self, a: np.ndarray) -> np.ndarray:
        a.flags.writeable = False
        return a

    @cached_property
    def positions(self) -> np.ndarray:
        return self._ro(to_dome(self.layout.local_xy, self.frames).reshape(N_PIXELS, 3))

    @cached_property
    def distance(self) -> np.ndarray:
        return self._ro(np.linalg.norm(self.positions, axis=1))

    @cached_property
    def directions(self) -> np.ndarray:
        return self._ro(self.positions / self.distance[:, None])

    @cached_property
    def azimuth(self) -> np.ndarray:
        return self._ro(np.arctan2(self.directions[:, 1], self.directions[:, 0]))

    @cached_property
    def elevation(self) -> np.ndarray:
        return self._ro(np.arcsin(np.clip(self.directions[:, 2], -1, 1)))

    @cached_property
    def index(self) -> np.ndarray:
        return self._ro(np.arange(N_PIXELS))

    @cached_property
    def panel(self) -> np.ndarray:
        return self._ro(self.index // PIXELS_PER_PANEL)

    @cached_property
    def local(self) -> np.ndarray:
        return self._ro(self.index % PIXELS_PER_PANEL)

    @cached_property
    def pentagon(self) -> np.ndarray:
        return self._ro(addressing.split_panel(self.panel)[0])

    @cached_property
    def slot(self) -> np.ndarray:
        return self._ro(addressing.split_panel(self.panel)[1])

    @cached_property
    def is_uv(self) -> np.ndarray:
        return self._ro(self.local >= GB_PER_PANEL)

    @cached_property
    def gb_index(self) -> np.ndarray:
        return self._ro(np.flatnonzero(~self.is_uv))

    @cached_property
    def uv_index(self) -> np.ndarray:
        return self._ro(np.flatnonzero(self.is_uv))

    @cached_property
    def panel_axes(self) -> np.ndarray:
        return self._ro(self.frames.axes.copy())

    @cached_property
    def panel_normals(self) -> np.ndarray:
        return self._ro(self.frames.axes[:, 2].copy())

    @cached_property
    def panel_corners(self) -> np.ndarray:
        return self._ro(self.frames.corners.copy())

    @cached_property
    def emission_angle(self) -> np.ndarray:
        return self._ro(emission_angle(self.positions, self.panel_normals[self.panel]))

    @cached_property
    def gain(self) -> np.ndarray:
        return self._ro(compensation_gain(self.positions, self.panel_normals[self.panel], self.half_intensity_deg))

    def address(self, g: int) -> addressing.PixelAddress:
        """Hardware address of pixel `g` (ValueError outside 0..20349)."""
        return addressing.address(g)

    def panel_pixels(self, panel: int) -> np.ndarray:
        """(370,) global indices of a panel's pixels in datagram order."""
        if isinstance(panel, bool) or not isinstance(panel, (int, np.integer)) or not 0 <= panel < N_PANELS:
            raise ValueError(f"panel must be an integer 0..{N_PANELS - 1}, got {panel!r}")
        return np.arange(panel * PIXELS_PER_PANEL, (panel + 1) * PIXELS_PER_PANEL)


def load_dome(layout_path: str | Path | None = None) -> Dome:
    """The dome built from a layout file (default: the shipped layout), cached per file: a file rewritten since
    (another modification time or size) is read again."""
    path = SHIPPED_LAYOUT if layout_path is None else Path(layout_path)
    try:
        stat = path.stat()
        stamp = (stat.st_mtime_ns, stat.st_size)
    except OSError:  # load_layout says what is wrong with the path
        stamp = None
    return _dome_of_file(path.resolve(), stamp)


@lru_cache(maxsize=4)
def _dome_of_file(path: Path, stamp: tuple[int, int] | None) -> Dome:
    """`load_dome`'s cache, keyed by the file and its (modification time in ns, size in bytes)."""
    return Dome(Solid(), load_layout(path))
