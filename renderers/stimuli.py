"""Synthetic far-field stimuli defined in angular units (pure numpy functions of world direction).

Every layer has `evaluate(d, t) -> (N, 5) float32 [G, B, UV, polarised UV, alpha]` for (N, 3) unit world
directions at time t (s). Azimuth is measured from +x counter-clockwise, elevation from the horizon.
`yaw_rate` (rad/s) is non-zero when the layer's motion is a rotation about the vertical (drawn for free by
rotating the view); `time_varying` is True when the layer must be re-evaluated every frame.

Every colour must be showable (`channels.check_showable`: green + blue <= 1 on a GB pixel), and patterns that
vary with azimuth must meet themselves at azimuth +-180 deg (`check_no_seam`): both are refused, not shown wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from antarium.core.numbers import check_number

from .channels import check_showable, parse_colour

#: phase mismatch (cycles) allowed where a pattern meets itself at azimuth +-180 deg (1e-3 cycle: invisible)
SEAM_TOLERANCE = 1e-3
#: |sin(orientation)| below which a grating is a drum (varies with azimuth only): sin(pi) is 1.2e-16, not 0
DRUM_TOLERANCE = 1e-9
#: Fastest grating drift accepted (rad/s): 100 turns a second, far past what any frame rate shows without temporal
#: aliasing; a speed of 1e308 deg/s overflowed the drum's yaw and turned the dome black
MAX_SPEED = 200 * np.pi


def azimuth_elevation(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) unit vectors -> azimuth in (-pi, pi], elevation in [-pi/2, pi/2] (radians)."""
    return np.arctan2(d[:, 1], d[:, 0]), np.arcsin(np.clip(d[:, 2], -1.0, 1.0))


def _rgba(colour: np.ndarray, n: int, alpha: float | np.ndarray = 1.0) -> np.ndarray:
    out = np.zeros((n, 5), dtype=np.float32)
    out[:, :3] = colour
    out[:, 4] = alpha
    return out


def check_no_seam(cycles: float, what: str, valid: str, nearest) -> None:
    """Refuse a pattern with `cycles` (float) repeats in one turn of azimuth unless that is a whole number: else its
    two ends disagree at azimuth +-180 deg, a seam (a drum turning carries it round as a moving edge).
    what: the pattern and its parameters; valid: the rule for seamless values; nearest(n) -> the value giving n."""
    if abs(cycles - round(cycles)) <= SEAM_TOLERANCE:
        return
    options = sorted({f"{nearest(n):.8g}" for n in (math.floor(cycles), math.ceil(cycles)) if n >= 1}, key=float)
    raise ValueError(f"{what} has a seam at azimuth +-180 deg ({cycles:.4g} repeats around the dome, not a whole "
                     f"number); {valid}: nearest {' or '.join(options)} deg")


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
        self.elevation = check_number("horizon elevation (rad)", self.elevation)
        if not abs(self.elevation) < np.pi / 2:
            raise ValueError(f"horizon elevation must be within (-90, 90) degrees, "
                             f"got {math.degrees(self.elevation):g}")

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
        for name in ("azimuth", "width", "bottom", "top"):
            setattr(self, name, check_number(f"bar {name} (rad)", getattr(self, name)))
        if not 0 < self.width <= 2 * np.pi:
            raise ValueError(f"bar width must be in (0, 360] degrees, got {math.degrees(self.width):g}")
        if not -np.pi / 2 <= self.bottom < self.top <= np.pi / 2:
            raise ValueError(
                f"bar elevations must satisfy -90 <= bottom < top <= 90 degrees, "
                f"got bottom={math.degrees(self.bottom):g}, top={math.degrees(self.top):g}"
            )

    def covers(self, d: np.ndarray) -> np.ndarray:
        """(N,) bool: which directions the bar covers."""
        az, el = azimuth_elevation(d)
        return (np.abs(_wrap(az - self.azimuth)) <= self.width / 2) & (el >= self.bottom) & (el <= self.top)


@dataclass
class Bars(_Static):
    """One or several bars of `colour` on `background` (None: transparent, an overlay on the layers under it; the
    first layer of a scene lies on black)."""

    bars: list = field(default_factory=lambda: [Bar()])
    colour: object = 0.0
    background: object = 0.5

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
    stripes. Radiance = mean * (1 + contrast * wave) * colour, wave in [-1, 1]; its peak must be showable
    (green + blue <= 1: the default grey colour 0.5 at mean 0.5 and contrast 1 peaks at G = B = UV = 0.5).
    Wherever it varies with azimuth (orientation not +-pi/2) it must repeat a whole number of times around the
    dome, |cos(orientation)| * 2 pi / period, or it would have a seam at azimuth +-pi: a drum's period divides
    2 pi; an oblique grating's period is |cos(orientation)| * 2 pi / n (n = 1, 2, ...), so only such periods.
    """

    period: float = np.radians(20.0)
    orientation: float = 0.0
    waveform: str = "sine"
    contrast: float = 1.0
    mean: float = 0.5
    colour: object = 0.5
    speed: float = 0.0
    phase: float = 0.0

    def __post_init__(self):
        if self.waveform not in ("sine", "square"):
            raise ValueError(f"grating waveform must be 'sine' or 'square', got {self.waveform!r}")
        for name in ("period", "orientation", "speed", "phase"):
            setattr(self, name, check_number(f"grating {name} (rad)", getattr(self, name)))
        if not abs(self.speed) <= MAX_SPEED:
            raise ValueError(f"grating speed must be within +-{math.degrees(MAX_SPEED):g} deg/s (100 turns a second), "
                             f"got {math.degrees(self.speed):g}")
        self.contrast = check_number("grating contrast", self.contrast, 0.0, 1.0)
        self.mean = check_number("grating mean", self.mean, 0.0)
        if not 0 < self.period <= 2 * np.pi:
            raise ValueError(f"grating period must be in (0, 360] degrees, got {math.degrees(self.period):g}")
        self.colour = parse_colour(self.colour, "grating colour", showable=False)
        peak = self.mean * (1.0 + self.contrast)
        check_showable(peak * self.colour, f"grating peak, mean {self.mean:g} * (1 + contrast {self.contrast:g}) "
                                           "* colour,")
        across = abs(math.cos(self.orientation))
        check_no_seam(across * 2 * np.pi / self.period,
                      f"grating period {math.degrees(self.period):g} deg at orientation "
                      f"{math.degrees(self.orientation):g} deg",
                      "seamless periods are |cos(orientation)| * 360 / n deg", lambda n: across * 360.0 / n)

    def supersample(self, step):
        return _samples_per(step, self.period / 2)

    @property
    def _is_drum(self) -> bool:
        return abs(math.sin(self.orientation)) < DRUM_TOLERANCE

    @property
    def yaw_rate(self) -> float:
        return float(self.speed * np.cos(self.orientation)) if self._is_drum else 0.0

    @property
    def time_varying(self) -> bool:
        return self.speed != 0.0 and not self._is_drum

    def wave(self, d: np.ndarray, t: float = 0.0) -> np.ndarray:
        az, el = azimuth_elevation(d)
        u = np.cos(self.orientation) * az + np.sin(self.orientation) * el
        # a drum's table and texture are made at t = 0 and turned by the renderer (`yaw_rate`); evaluated at a later t
        # it is redrawn every frame (a far field of two yaw rates), and must move itself
        x = 2 * np.pi * (u - self.speed * t) / self.period + self.phase
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
    """Squares of `size` (rad) in azimuth and elevation, alternating between `colour_a` and `colour_b`; an even
    number of squares must fit around the dome (size = pi / n), or the ones at azimuth +-pi would not alternate."""

    size: float = np.radians(15.0)
    colour_a: object = 0.0
    colour_b: object = 0.5

    def __post_init__(self):
        self.size = check_number("checkerboard square size (rad)", self.size)
        if not 0 < self.size <= np.pi:
            raise ValueError(f"checkerboard square size must be in (0, 180] degrees, got {math.degrees(self.size):g}")
        check_no_seam(np.pi / self.size, f"checkerboard of {math.degrees(self.size):g} deg squares",
                      "seamless sizes are 180 / n deg (an even number of squares around)", lambda n: 180.0 / n)
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
