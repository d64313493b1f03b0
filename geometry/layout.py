"""The LED layout of one panel (the same PCB on all 55), its seeded optimisation, and the shipped result.

Both the 361 green/blue pixels and the 9 UV pixels sit on hexagonal lattices inside the triangle (see
`lattice`), at least `margin` from the board edge and at least `min_pitch` apart. Among the lattices that
hold exactly the required number of pixels, the search picks the one that minimises the coefficient of
variation of the nearest-neighbour angle seen from the dome centre, over all pixels of the dome — so the
spacing across panel seams counts as much as the spacing within a panel. UV pixels also keep `uv_clearance`
from every GB pixel (room for the two UV LEDs and the polariser's axle).

The search is a grid over (pitch, offset) for the three symmetric lattice variants, then a seeded local
refinement; the result is shipped in `data/layout.npz` and loads in milliseconds.
`antarium layout --regenerate` recomputes it; a test checks that the recomputation matches the shipped file
within a nanometre (the last bits of floating point differ between CPUs), and that file by its checksum.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from .constants import GB_PER_PANEL, UV_PER_PANEL
from .lattice import VARIANTS, count_grid, points_in_triangle
from .solid import PanelFrames, Solid, dome_panels

SHIPPED_LAYOUT = Path(__file__).parent / "data" / "layout.npz"
LAYOUT_FORMAT = 1


#: Every length of `LayoutParams` lies in (0, MAX_LENGTH) metres
MAX_LENGTH = 0.1


@dataclass(frozen=True)
class LayoutParams:
    """Parameters of the layout search (metres)."""

    margin: float = 0.004  # LED centre to board edge
    gb_min_pitch: float = 0.008  # GB pixel pitch lower bound (3.2 mm LEDs + placement clearance)
    uv_min_pitch: float = 0.040  # UV pixel pitch lower bound (polariser disc and aircore actuator)
    uv_clearance: float = 0.004  # UV pixel centre to any GB pixel centre
    seed: int = 2020
    grid_pitches: int = 120
    grid_offsets: int = 32
    refine_steps: int = 60

    def __post_init__(self) -> None:
        for name in ("margin", "gb_min_pitch", "uv_min_pitch", "uv_clearance"):
            v = getattr(self, name)
            if not (np.isfinite(v) and 0 < v < MAX_LENGTH):
                raise ValueError(f"{name} must be a length in metres in (0, {MAX_LENGTH:g}), got {v!r}")
        for name in ("grid_pitches", "grid_offsets", "refine_steps"):
            v = getattr(self, name)
            if not (isinstance(v, int) and 2 <= v <= 10_000):
                raise ValueError(f"{name} must be an integer in 2..10000, got {v!r}")


@dataclass(frozen=True)
class Lattice:
    variant: str
    pitch: float  # m
    offset: float  # m


@dataclass(frozen=True)
class PanelLayout:
    """gb: (361, 2), uv: (9, 2) float64 panel-local positions (m); row order = local pixel index order."""

    gb: np.ndarray
    uv: np.ndarray
    gb_lattice: Lattice
    uv_lattice: Lattice
    params: LayoutParams = field(default_factory=LayoutParams)

    @property
    def local_xy(self) -> np.ndarray:
        """(370, 2) all pixels of a panel in local index order (GB first, then UV)."""
        return np.vstack([self.gb, self.uv])


def to_dome(local_xy: np.ndarray, frames: PanelFrames) -> np.ndarray:
    """(55, N, 3) metres: panel-local points (N, 2) placed on every panel."""
    ax = frames.axes
    return frames.origin[:, None, :] + local_xy[None, :, 0:1] * ax[:, None, 0] + local_xy[None, :, 1:2] * ax[:, None, 1]


def nearest_neighbour_angles(directions: np.ndarray) -> np.ndarray:
    """(N,) rad: angle from each unit vector (N, 3) to its nearest neighbour."""
    from scipy.spatial import cKDTree

    chord, _ = cKDTree(directions).query(directions, k=2)
    return 2 * np.arcsin(np.clip(chord[:, 1] / 2, 0, 1))


def _objective(local_xy: np.ndarray, frames: PanelFrames) -> float:
    """Coefficient of variation of the nearest-neighbour angle over the whole dome."""
    p = to_dome(local_xy, frames).reshape(-1, 3)
    a = nearest_neighbour_angles(p / np.linalg.norm(p, axis=1, keepdims=True))
    return float(a.std() / a.mean())


def _pitch_windows(n: int, min_pitch: float, solid: Solid, margin: float) -> list[tuple[float, float]]:
    """Pitch ranges (lo, hi) in m to search for n points, in order, each 0.7..1.3 x the pitch at which n points
    tile an area (`lo` raised to `min_pitch`; a range with nothing above it left out): first the estimate the
    shipped layout was searched with (kept so that it is found again: a rough inset that shrinks too fast beyond
    a margin of about 12 mm), then the triangle inset by `margin` (the area times (1 - margin / inradius)^2)."""
    area = 0.5 * solid.base_edge * solid.height
    inradius = 2 * area / (solid.base_edge + 2 * solid.leg)
    areas = (area * max(1 - 4 * margin * (1 / solid.base_edge + 1 / solid.height), 0.0) ** 2,
             area * max(1 - margin / inradius, 0.0) ** 2)
    windows = []
    for inset in areas:
        p_fit = np.sqrt(2 * inset / (np.sqrt(3) * n))
        if min_pitch <= 1.3 * p_fit and p_fit > 0:
            windows.append((max(min_pitch, 0.7 * p_fit), 1.3 * p_fit))
    return windows


def _grid(n: int, lo: float, hi: float, params: LayoutParams, solid: Solid) -> list[Lattice]:
    """The lattices of the (pitch, offset) grid over pitches lo..hi (m) that hold exactly n points."""
    pitches = np.linspace(lo, hi, params.grid_pitches).tolist()
    found = []
    for variant in VARIANTS:
        period = max(pitches) * (1.0 if variant == "columns" else np.sqrt(3) / 2)
        offsets = np.linspace(0, period, params.grid_offsets, endpoint=False)
        counts = count_grid(np.array(pitches), offsets, variant, solid.base_edge, solid.height, params.margin)
        for i, j in zip(*np.nonzero(counts == n), strict=True):
            found.append(Lattice(variant, pitches[i], float(offsets[j])))
    return found


def _search(
    n: int, min_pitch: float, params: LayoutParams, solid: Solid, frames: PanelFrames, name: str,
    valid=lambda pts: True, progress: bool = False,
) -> tuple[Lattice, np.ndarray]:
    """Best lattice holding exactly n points (see module docstring): the grid over the first of
    `_pitch_windows` where a lattice holds them (and is `valid`), then the refinement."""
    from tqdm import tqdm

    base, height, margin = solid.base_edge, solid.height, params.margin
    windows = _pitch_windows(n, min_pitch, solid, margin)
    if not windows:
        raise ValueError(
            f"{n} {name} pixels do not fit at min_pitch {min_pitch * 1e3:.1f} mm with margin "
            f"{margin * 1e3:.1f} mm: the triangle holds them only at pitches up to about "
            f"{max((hi for _, hi in _pitch_windows(n, 0.0, solid, margin)), default=0.0) * 1e3:.1f} mm"
        )

    def score(lat: Lattice) -> float:
        pts = points_in_triangle(lat.pitch, lat.offset, lat.variant, base, height, margin)
        if len(pts) != n or not valid(pts):
            return np.inf
        return _objective(pts, frames)

    best, best_score, held = None, np.inf, False
    for lo, hi in windows:
        candidates = _grid(n, lo, hi, params, solid)
        held = held or bool(candidates)
        for lat in tqdm(candidates, desc=f"{name} layout", disable=not progress, leave=False):
            s = score(lat)
            if s < best_score:
                best, best_score = lat, s
        if best is not None:
            break
    if not held:
        raise ValueError(
            f"no symmetric hexagonal lattice holds exactly {n} {name} pixels with margin {margin * 1e3:.1f} mm "
            f"and pitch >= {min_pitch * 1e3:.1f} mm; allowed: a smaller margin or min_pitch"
        )
    if best is None:
        raise ValueError(
            f"no lattice of {n} {name} pixels keeps uv_clearance {params.uv_clearance * 1e3:.1f} mm from the GB "
            "pixels; allowed: a smaller uv_clearance"
        )
    rng = np.random.default_rng(params.seed)
    step_p, step_o = (hi - lo) / params.grid_pitches, best.pitch / params.grid_offsets
    for k in range(params.refine_steps):
        shrink = 1.0 - k / params.refine_steps
        trial = Lattice(
            best.variant,
            float(best.pitch + rng.normal() * step_p * shrink),
            float(best.offset + rng.normal() * step_o * shrink),
        )
        if trial.pitch >= min_pitch:
            s = score(trial)
            if s < best_score:
                best, best_score = trial, s
    return best, points_in_triangle(best.pitch, best.offset, best.variant, base, height, margin)


def generate_layout(
    params: LayoutParams | None = None, solid: Solid | None = None, progress: bool = False
) -> PanelLayout:
    """Run the seeded layout search (a few seconds)."""
    params = params or LayoutParams()
    solid = solid or Solid()
    frames = dome_panels(solid)
    from scipy.spatial import cKDTree

    gb_lat, gb = _search(GB_PER_PANEL, params.gb_min_pitch, params, solid, frames, "GB", progress=progress)
    gb_tree = cKDTree(gb)

    def clear_of_gb(pts: np.ndarray) -> bool:
        return bool(gb_tree.query(pts)[0].min() >= params.uv_clearance)

    uv_lat, uv = _search(UV_PER_PANEL, params.uv_min_pitch, params, solid, frames, "UV", clear_of_gb, progress)
    return PanelLayout(gb, uv, gb_lat, uv_lat, params)


def save_layout(layout: PanelLayout, path: Path | str) -> None:
    np.savez(
        path,
        format=LAYOUT_FORMAT,
        gb=layout.gb,
        uv=layout.uv,
        gb_lattice=np.array([layout.gb_lattice.variant, layout.gb_lattice.pitch, layout.gb_lattice.offset]),
        uv_lattice=np.array([layout.uv_lattice.variant, layout.uv_lattice.pitch, layout.uv_lattice.offset]),
        params=np.array(list(asdict(layout.params).items()), dtype=object),
    )


def load_layout(path: Path | str | None = None) -> PanelLayout:
    """Load a layout file (default: the shipped one)."""
    path = Path(path) if path is not None else SHIPPED_LAYOUT
    if not path.is_file():
        raise FileNotFoundError(f"layout file not found: {path} (regenerate with `antarium layout --regenerate`)")
    with np.load(path, allow_pickle=True) as z:
        if int(z["format"]) != LAYOUT_FORMAT:
            raise ValueError(f"layout file {path} has format {int(z['format'])}; allowed: {LAYOUT_FORMAT}")
        gb, uv = z["gb"], z["uv"]
        if gb.shape != (GB_PER_PANEL, 2) or uv.shape != (UV_PER_PANEL, 2):
            raise ValueError(f"layout file {path} holds {gb.shape} GB and {uv.shape} UV positions; "
                             f"allowed: ({GB_PER_PANEL}, 2) and ({UV_PER_PANEL}, 2)")
        lat = [Lattice(str(v), float(p), float(o)) for v, p, o in (z["gb_lattice"], z["uv_lattice"])]
        params = LayoutParams(**{k: type(getattr(LayoutParams, k))(v) for k, v in z["params"]})
    return PanelLayout(gb, uv, lat[0], lat[1], params)
