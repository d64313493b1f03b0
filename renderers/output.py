"""From sampled radiance to the LED frame and the polariser angles.

Sampled radiance per LED is a pair in [0, 1] (1 = full drive at gain 1): [green, blue] for a GB pixel,
[UV, polarised UV] for a UV pixel. GB pixel: (G, B) * 65535 * gain * brightness * channel gain; if G + B
exceeds 65535 both are scaled by the same factor (hue kept; a pixel never draws more than one LED's current).
UV pixel: total UV radiance I with polarised share P: plain LED = I - P, polarised LED = P, so their sum is
I <= 65535 and the degree of polarisation is P / I (a UV above 65535 after the gains scales both down together,
as a GB pair is, so the degree stays). This split assumes the polarised LED seen through its polariser
emits the same UV radiance per drive unit as the plain LED; the polariser's transmission is not modelled. A real
polariser passes at most half of unpolarised light (an ideal one: a requested degree 0.75 would come out as 0.60 and
the pixel's UV at 62.5 % to 100 % of the request), so a rig must measure, per UV pixel, the ratio of the two LEDs'
emitted radiance per drive unit (and the polariser's extinction ratio, which lowers the degree further) and equalise
them, e.g. by lowering the plain LED's dot correction to that ratio (docs/rendering.md). Channel gains and the
green/blue swap act on the LED channels (a swapped frame's green LEDs show the scene's blue, scaled by the green
gain).
"""

from __future__ import annotations

import numpy as np

from antarium.firmware_proto.polariser import wrap_angles
from antarium.geometry.constants import GB_PER_PANEL, N_PANELS, PIXELS_PER_PANEL

from .scene import check_channel_gain, check_contrast

FULL = 65535.0


class FrameConverter:
    """Converts (20350, 2) float32 pair radiances into a (20350, 2) uint16 LED frame without allocating."""

    def __init__(self, gain: np.ndarray, brightness: float = 1.0):
        gain = np.asarray(gain, dtype=np.float64)
        n = N_PANELS * PIXELS_PER_PANEL
        if gain.shape != (n,):
            raise ValueError(f"per-LED gain must have shape ({n},), got {gain.shape}")
        self._led_gain = gain
        self.is_uv = (np.arange(n) % PIXELS_PER_PANEL) >= GB_PER_PANEL
        self.brightness = 1.0
        self.channel_gain = (1.0, 1.0, 1.0)
        self.swap_green_blue = False
        self.contrast = 1.0
        #: counts configure() calls, so that a copy of `gain` elsewhere (the GPU path's) knows when it is stale
        self.version = 0
        self._gain = np.empty((n, 2), dtype=np.float32)
        self._uv_before = np.empty((N_PANELS, PIXELS_PER_PANEL - GB_PER_PANEL), dtype=np.float32)
        self.configure(brightness=brightness)

    def configure(self, brightness=None, channel_gain=None, swap_green_blue=None, contrast=None) -> None:
        if brightness is not None and not (np.isfinite(brightness) and 0 <= brightness <= 1):
            raise ValueError(f"brightness must be in [0, 1], got {brightness!r}")
        if channel_gain is not None:
            channel_gain = check_channel_gain(channel_gain)
        if contrast is not None:
            contrast = check_contrast(contrast)
        if brightness is not None:
            self.brightness = float(brightness)
        if channel_gain is not None:
            self.channel_gain = channel_gain
        if swap_green_blue is not None:
            self.swap_green_blue = bool(swap_green_blue)
        if contrast is not None:
            self.contrast = contrast
        self.version += 1
        g = FULL * self._led_gain * self.brightness
        cg = self.channel_gain
        self._gain[:, 0] = np.where(self.is_uv, g * cg[2], g * cg[0])
        self._gain[:, 1] = np.where(self.is_uv, g * cg[2], g * cg[1])

    @property
    def gain(self) -> np.ndarray:
        """(20350, 2) float32: 65535 * LED gain * brightness * channel gain of each output column."""
        return self._gain

    def __call__(self, pairs: np.ndarray, out: np.ndarray) -> np.ndarray:
        """pairs: (20350, 2) float32 (modified in place when contrast != 1); out: (20350, 2) uint16."""
        from .kernels import convert_pairs

        if self.contrast != 1.0:
            self._apply_contrast(pairs)
        convert_pairs(pairs, self._gain, self.is_uv, self.swap_green_blue, out)
        return out

    def _apply_contrast(self, pairs: np.ndarray) -> None:
        """Scale deviations of G, B (over GB pixels) and UV (over UV pixels) from their means; the polarised
        share keeps its degree of polarisation."""
        c = np.float32(self.contrast)
        p = pairs.reshape(N_PANELS, PIXELS_PER_PANEL, 2)
        gb, uv = p[:, :GB_PER_PANEL], p[:, GB_PER_PANEL:]
        m = gb.mean(axis=(0, 1), dtype=np.float64).astype(np.float32)  # float32 sums drift by ~1e-4 here
        gb -= m
        gb *= c
        gb += m
        np.maximum(gb, 0.0, out=gb)
        np.copyto(self._uv_before, uv[..., 0])
        m_uv = np.float32(uv[..., 0].mean(dtype=np.float64))
        uv[..., 0] = np.maximum(m_uv + c * (uv[..., 0] - m_uv), 0.0)
        uv[..., 1] *= np.divide(uv[..., 0], self._uv_before, out=np.zeros_like(self._uv_before),
                                where=self._uv_before > 0)


def polariser_angles(directions: np.ndarray, e_vectors: np.ndarray, panel_axes: np.ndarray) -> np.ndarray:
    """Polariser angle (rad, [0, pi)) in the panel plane from the panel's +x axis towards its +y axis
    (counter-clockwise seen from the dome centre), per UV pixel.

    directions, e_vectors: (M, 3) dome-frame view directions of the UV pixels and the wanted e-vectors;
    panel_axes: (M, 3, 3) rows x, y, inward normal of each pixel's panel. The polariser lies in the panel
    plane; light leaving it towards the centre along -d carries the projection of the polariser axis u onto
    the plane normal to d, which is parallel to e when u lies in span(e, d): u = n x (e x d).
    """
    n = panel_axes[:, 2]
    u = np.cross(n, np.cross(e_vectors, directions))
    ang = np.arctan2(np.einsum("ij,ij->i", u, panel_axes[:, 1]), np.einsum("ij,ij->i", u, panel_axes[:, 0]))
    return wrap_angles(ang)
