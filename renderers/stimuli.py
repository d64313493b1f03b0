"""Synthetic far-field stimuli defined in angular units (pure numpy functions of world direction).

Every layer has `evaluate(d, t) -> (N, 5) float32 [G, B, UV, polarised UV, alpha]` for (N, 3) unit world
directions at time t (s). Azimuth is measured from +x counter-clockwise, elevation from the horizon.
`yaw_rate` (rad/s) is non-zero when the layer's motion is a rotation about the vertical (drawn for free by
rotating the view); `time_varying` is True when the layer must be re-evaluated every frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .channels import parse_colour


def azimuth_elevation(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) unit vectors -> azimuth in (-pi, pi], elevation in [-pi/2, pi/2] (radians)."""
    return np.arctan2(d[:, 1], d[:, 0]), np.arcsin(np.clip(d[:, 2], -1.0, 1.0))


def _rgba(colour: np.ndarray, n: int, alpha: float | np.ndarray = 1.0) -> np.ndarray:
    out = np.zeros((n, 5), dtype=np.float32)
    out[:, :3] = colour
    out[:, 4] = alpha
    return out


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2 * np.pi) - np.pi


def _samples_per(step: float, detail: float) -> int:
    """Sub-samples per grid step so that features of size `detail` (rad) get >= 2 samples (1..8)."""
    return int(min(8, max(2, math.ceil(2 * step / detail))))


class _Static:
    yaw_rate = 0.0
    time_varying = False

    def supersample(self, step: float) -> int:
        """Sub-samples per axis needed to average this layer over a grid cell of `step` (rad): sharp edges."""
        return 2


@dataclass
class Uniform(_Static):
    """A uniform field of one colour (linear G, B, UV radiances, or a grey level)."""

    colour: object = 0.5

    def __post_init__(self):
        self.colour = parse_colour(self.colour, "uniform colour")

    def supersample(self, step):
        return 1

    def evaluate(self, d, t=0.0):
        return _rgba(self.colour, len(d))


@dataclass
class Horizon(_Static):
    """Featureless scene: `ground` below `elevation` (radians), `sky` above; no sun, no polarisation."""

    sky: object = (0.18, 0.30, 0.45)
    ground: object = (0.06, 0.03, 0.008)
    elevation: float = 0.0

    def __post_init__(self):
        self.sky = parse_colour(self.sky, "horizon sky colour")
        self.ground = parse_colour(self.ground, "horizon ground colour")
        if not (np.isfinite(self.elevation) and abs(self.elevation) < np.pi / 2):
            raise ValueError(f"horizon elevation must be within (-90, 90) degrees, got {self.elevation!r} rad")

    def evaluate(self, d, t=0.0):
        out = _rgba(self.ground, len(d))
        out[d[:, 2] > np.sin(self.elevation), :3] = self.sky
        return out


@dataclass
class Bar:
    """A bar between two azimuth edges: centre `azimuth` and `width`, from `bottom` to `top` elevation (rad)."""

    azimuth: float = 0.0
    width: float = np.radians(10.0)
    bottom: float = -np.pi / 2
    top: float = np.pi / 2

    def __post_init__(self):
        vals = (self.azimuth, self.width, self.bottom, self.top)
        if not all(np.isfinite(v) for v in vals):
            raise ValueError(f"bar azimuth, width, bottom and top must be finite, got {vals!r}")
        if not 0 < self.width <= 2 * np.pi:
            raise ValueError(f"bar width must be in (0, 360] degrees, got {np.degrees(self.width)!r}")
        if not -np.pi / 2 <= self.bottom < self.top <= np.pi / 2:
            raise ValueError(
                f"bar elevations must satisfy -90 <= bottom < top <= 90 degrees, "
                f"got bottom={np.degrees(self.bottom)!r}, top={np.degrees(self.top)!r}"
            )

    def covers(self, d: np.ndarray) -> np.ndarray:
        """(N,) bool: which directions the bar covers."""
        az, el = azimuth_elevation(d)
        return (np.abs(_wrap(az - self.azimuth)) <= self.width / 2) & (el >= self.bottom) & (el <= self.top)


@dataclass
class Bars(_Static):
    """One or several bars of `colour` on `background` (None: transparent, an overlay on other layers)."""

    bars: list = field(default_factory=lambda: [Bar()])
    colour: object = 0.0
    background: object = 1.0

    def __post_init__(self):
        if not self.bars:
            raise ValueError("a bar stimulus needs at least one bar")
        self.bars = [b if isinstance(b, Bar) else Bar(**b) for b in self.bars]
        self.colour = parse_colour(self.colour, "bar colour")
        self.background = None if self.background is None else parse_colour(self.background, "bar background")

    def covers(self, d):
        return np.logical_or.reduce([b.covers(d) for b in self.bars])

    def evaluate(self, d, t=0.0):
        inside = self.covers(d)
        if self.background is None:
            return _rgba(self.colour, len(d), inside.astype(np.float32))
        out = _rgba(self.background, len(d))
        out[inside, :3] = self.colour
        return out


@dataclass
class Grating:
    """Sine or square grating in (azimuth, elevation) coordinates, drifting at `speed` (rad/s).

    Phase varies along the direction `orientation` (rad) in the azimuth-elevation plane: 0 gives vertical
    stripes varying with azimuth (a drum; drifting = rotating about the vertical, free), pi/2 horizontal
    stripes. Radiance = mean * (1 + contrast * wave) * colour, wave in [-1, 1].
    """

    period: float = np.radians(20.0)
    orientation: float = 0.0
    waveform: str = "sine"
    contrast: float = 1.0
    mean: float = 0.5
    colour: object = 1.0
    speed: float = 0.0
    phase: float = 0.0

    def __post_init__(self):
        if self.waveform not in ("sine", "square"):
            raise ValueError(f"grating waveform must be 'sine' or 'square', got {self.waveform!r}")
        for name in ("period", "orientation", "contrast", "mean", "speed", "phase"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"grating {name} must be finite, got {getattr(self, name)!r}")
        if not 0 < self.period <= 2 * np.pi:
            raise ValueError(f"grating period must be in (0, 360] degrees, got {np.degrees(self.period)!r}")
        if not (0 <= self.contrast <= 1 and self.mean >= 0 and self.mean * (1 + self.contrast) <= 1):
            raise ValueError(f"grating contrast must be in [0, 1] and mean*(1+contrast) <= 1, got "
                             f"contrast={self.contrast!r}, mean={self.mean!r}")
        self.colour = parse_colour(self.colour, "grating colour")

    def supersample(self, step):
        return _samples_per(step, self.period / 2)

    @property
    def _is_drum(self) -> bool:
        return float(np.sin(self.orientation)) == 0.0

    @property
    def yaw_rate(self) -> float:
        return float(self.speed * np.cos(self.orientation)) if self._is_drum else 0.0

    @property
    def time_varying(self) -> bool:
        return self.speed != 0.0 and not self._is_drum

    def wave(self, d: np.ndarray, t: float = 0.0) -> np.ndarray:
        az, el = azimuth_elevation(d)
        u = np.cos(self.orientation) * az + np.sin(self.orientation) * el
        shift = 0.0 if self._is_drum else self.speed * t
        x = 2 * np.pi * (u - shift) / self.period + self.phase
        s = np.sin(x)
        return s if self.waveform == "sine" else np.where(s >= 0, 1.0, -1.0)

    def evaluate(self, d, t=0.0):
        level = self.mean * (1.0 + self.contrast * self.wave(d, t))
        out = np.zeros((len(d), 5), dtype=np.float32)
        out[:, :3] = level[:, None] * self.colour[None, :]
        out[:, 4] = 1.0
        return out


@dataclass
class Checkerboard(_Static):
    """Squares of `size` (rad) in azimuth and elevation, alternating between `colour_a` and `colour_b`."""

    size: float = np.radians(15.0)
    colour_a: object = 0.0
    colour_b: object = 1.0

    def __post_init__(self):
        if not (np.isfinite(self.size) and 0 < self.size <= np.pi):
            raise ValueError(f"checkerboard square size must be in (0, 180] degrees, got {self.size!r} rad")
        self.colour_a = parse_colour(self.colour_a, "checkerboard colour_a")
        self.colour_b = parse_colour(self.colour_b, "checkerboard colour_b")

    def supersample(self, step):
        return _samples_per(step, self.size)

    def evaluate(self, d, t=0.0):
        az, el = azimuth_elevation(d)
        odd = (np.floor(az / self.size) + np.floor(el / self.size)) % 2 == 1
        out = _rgba(self.colour_a, len(d))
        out[odd, :3] = self.colour_b
        return out
