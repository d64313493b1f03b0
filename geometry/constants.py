"""Counts, sizes and tolerances of the Antarium, in one place (SI units)."""

from __future__ import annotations

# The solid: a biscribed pentakis dodecahedron without its bottom pyramid.
BASE_EDGE_M = 0.368          # triangle base = dodecahedron edge (Kocsi et al. 2020)
N_PENTAGONS = 11
PANELS_PER_PENTAGON = 5
N_PANELS = N_PENTAGONS * PANELS_PER_PENTAGON  # 55

# Pixels: local index 0..360 are green/blue pixels, 361..369 the UV pixels (UV slot = actuator 0..8).
GB_PER_PANEL = 361
UV_PER_PANEL = 9
PIXELS_PER_PANEL = GB_PER_PANEL + UV_PER_PANEL  # 370
N_GB = N_PANELS * GB_PER_PANEL                  # 19,855
N_UV = N_PANELS * UV_PER_PANEL                  # 495
N_PIXELS = N_PANELS * PIXELS_PER_PANEL          # 20,350

# LEDs: two per pixel. GB pixel: 0 = green, 1 = blue. UV pixel: 0 = plain UV, 1 = UV behind the polariser.
LEDS_PER_PIXEL = 2
LEDS_PER_PANEL = PIXELS_PER_PANEL * LEDS_PER_PIXEL  # 740

# MBI5040-class drivers: 16 channels each, 47 per panel in 4 SPI daisy chains.
CHANNELS_PER_CHIP = 16
CHIPS_PER_PANEL = 47
CHIPS_PER_CHAIN = (12, 12, 12, 11)
N_CHAINS = len(CHIPS_PER_CHAIN)
N_ACTUATORS = UV_PER_PANEL  # polariser actuators per panel

# Tolerances
VERTEX_RTOL = 1e-12  # every vertex lies on the circumsphere to this relative tolerance
