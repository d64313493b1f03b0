"""From sampled radiance to the LED frame and polariser angles (pure numpy, preallocated buffers).

Sampled radiance per LED is (N, 4) [G, B, UV, polarised UV] in 16-bit units (65535 = full drive at gain 1).
GB pixel: (G, B) * gain * brightness * channel gains; if G + B exceeds 65535 both are scaled down by the same
factor (hue kept; a pixel never draws more than one LED's current). UV pixel: total UV radiance I with
polarised share P: plain LED = I - P, polarised LED = P, so their sum is I <= 65535 and the degree of
polarisation is P / I.
"""

from __future__ import annotations

import numpy as np

from antarium.geometry.constants import GB_PER_PANEL, N_PANELS, PIXELS_PER_PANEL

FULL = 65535.0


class FrameConverter:
    """Converts (20350, 4) float32 sampled radiance into a (20350, 2) uint16 LED frame without allocating."""

    def __init__(self, gain: np.ndarray, brightness: float = 1.0):
        gain = np.asarray(gain, dtype=np.float32)
        if gain.shape != (N_PANELS * PIXELS_PER_PANEL,):
            raise ValueError(f"per-LED gain must have shape ({N_PANELS * PIXELS_PER_PANEL},), got {gain.shape}")
        self._gain = gain.reshape(N_PANELS, PIXELS_PER_PANEL)
        self.brightness = 1.0
        self.channel_gain = (1.0, 1.0, 1.0)
        self.swap_green_blue = False
        self.contrast = 1.0
        self._f = np.empty((N_PANELS, PIXELS_PER_PANEL, 2), dtype=np.float32)
        self._s = np.empty((N_PANELS, GB_PER_PANEL), dtype=np.float32)
        self._uv_before = np.empty(N_PANELS * PIXELS_PER_PANEL, dtype=np.float32)
        self._ratio = np.empty(N_PANELS * PIXELS_PER_PANEL, dtype=np.float32)
        self.configure(brightness=brightness)

    def configure(self, brightness=None, channel_gain=None, swap_green_blue=None, contrast=None) -> None:
        if brightness is not None:
            if not (np.isfinite(brightness) and 0 <= brightness <= 1):
                raise ValueError(f"brightness must be in [0, 1], got {brightness!r}")
            self.brightness = float(brightness)
        if channel_gain is not None:
            self.channel_gain = tuple(float(g) for g in channel_gain)
        if swap_green_blue is not None:
            self.swap_green_blue = bool(swap_green_blue)
        if contrast is not None:
            self.contrast = float(contrast)
        g = self._gain * self.brightness
        cg = self.channel_gain
        self._g_gb = np.stack([g[:, :GB_PER_PANEL] * cg[0], g[:, :GB_PER_PANEL] * cg[1]], axis=-1).astype(np.float32)
        self._g_uv = (g[:, GB_PER_PANEL:] * cg[2]).astype(np.float32)

    def __call__(self, radiance: np.ndarray, out: np.ndarray) -> np.ndarray:
        """radiance: (20350, 4) float32 (modified in place when contrast != 1); out: (20350, 2) uint16."""
        r = radiance.reshape(N_PANELS, PIXELS_PER_PANEL, 4)
        if self.contrast != 1.0:
            self._apply_contrast(radiance)
        f = self._f
        src = r[:, :GB_PER_PANEL, 1::-1] if self.swap_green_blue else r[:, :GB_PER_PANEL, 0:2]
        gb = f[:, :GB_PER_PANEL]
        np.multiply(src, self._g_gb, out=gb)
        # keep G + B <= 65535 by scaling both (hue preserved)
        s = self._s
        np.add(gb[..., 0], gb[..., 1], out=s)
        np.maximum(s, FULL, out=s)
        np.divide(FULL, s, out=s)
        gb *= s[..., None]
        uv = f[:, GB_PER_PANEL:]
        total, pol = r[:, GB_PER_PANEL:, 2], r[:, GB_PER_PANEL:, 3]
        np.minimum(pol, total, out=uv[..., 1])
        np.subtract(total, uv[..., 1], out=uv[..., 0])
        uv *= self._g_uv[..., None]
        np.clip(f, 0.0, FULL, out=f)
        # truncation (not rounding) keeps every pair's sum <= 65535
        np.copyto(out.reshape(N_PANELS, PIXELS_PER_PANEL, 2), f, casting="unsafe")
        return out

    def _apply_contrast(self, radiance: np.ndarray) -> None:
        """Scale deviations of G, B, UV from their means over all LEDs; the polarised share keeps its degree."""
        rgb = radiance[:, :3]
        np.copyto(self._uv_before, radiance[:, 2])
        m = rgb.mean(axis=0)
        rgb -= m
        rgb *= np.float32(self.contrast)
        rgb += m
        np.maximum(rgb, 0.0, out=rgb)
        self._ratio.fill(0.0)
        np.divide(radiance[:, 2], self._uv_before, out=self._ratio, where=self._uv_before > 0)
        radiance[:, 3] *= self._ratio


def polariser_angles(directions: np.ndarray, e_vectors: np.ndarray, panel_axes: np.ndarray) -> np.ndarray:
    """Polariser angle (rad, [0, pi)) in the panel plane from the panel's +x axis, per UV pixel.

    directions, e_vectors: (M, 3) dome-frame view directions of the UV pixels and the wanted e-vectors;
    panel_axes: (M, 3, 3) rows x, y, inward normal of each pixel's panel. The polariser lies in the panel
    plane; light leaving it towards the centre along -d carries the projection of the polariser axis u onto
    the plane normal to d, which is parallel to e when u lies in span(e, d): u = n x (e x d).
    """
    n = panel_axes[:, 2]
    u = np.cross(n, np.cross(e_vectors, directions))
    ang = np.arctan2(np.einsum("ij,ij->i", u, panel_axes[:, 1]), np.einsum("ij,ij->i", u, panel_axes[:, 0]))
    return np.mod(ang, np.pi)
