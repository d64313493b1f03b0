"""Hardware addresses of every pixel and LED (pure functions on integer numpy arrays or ints).

Pixel global index  g = panel * 370 + local,  panel = pentagon * 5 + slot.
LED index in panel  k = 2 * local + led      (led 0 = green / plain UV, 1 = blue / polarised UV)
Driver position     chip = k // 16, channel = k % 16, chain = first chain whose cumulative chip count
                    exceeds chip, chip_in_chain = chip - chips before that chain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .constants import (
    CHANNELS_PER_CHIP,
    CHIPS_PER_CHAIN,
    GB_PER_PANEL,
    LEDS_PER_PANEL,
    LEDS_PER_PIXEL,
    N_PANELS,
    N_PIXELS,
    PANELS_PER_PENTAGON,
    PIXELS_PER_PANEL,
)

_CHAIN_START = np.concatenate([[0], np.cumsum(CHIPS_PER_CHAIN)])  # [0, 12, 24, 36, 47]


def _check_range(name: str, value, stop: int) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind not in "iu":
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if arr.size and (arr.min() < 0 or arr.max() >= stop):
        raise ValueError(f"{name} out of range: allowed 0..{stop - 1}, got {value!r}")
    return arr


def split_global(g):
    """Global pixel index (0..20349) -> (panel 0..54, local 0..369)."""
    g = _check_range("pixel index", g, N_PIXELS)
    return g // PIXELS_PER_PANEL, g % PIXELS_PER_PANEL


def join_global(panel, local):
    """(panel, local) -> global pixel index."""
    panel = _check_range("panel", panel, N_PANELS)
    local = _check_range("local pixel index", local, PIXELS_PER_PANEL)
    return panel * PIXELS_PER_PANEL + local


def split_panel(panel):
    """Panel 0..54 -> (pentagon 0..10, slot 0..4)."""
    panel = _check_range("panel", panel, N_PANELS)
    return panel // PANELS_PER_PENTAGON, panel % PANELS_PER_PENTAGON


def join_panel(pentagon, slot):
    """(pentagon, slot) -> panel."""
    pentagon = _check_range("pentagon", pentagon, N_PANELS // PANELS_PER_PENTAGON)
    slot = _check_range("slot", slot, PANELS_PER_PENTAGON)
    return pentagon * PANELS_PER_PENTAGON + slot


def is_uv_local(local):
    """True for the UV pixels (local index 361..369)."""
    local = _check_range("local pixel index", local, PIXELS_PER_PANEL)
    return local >= GB_PER_PANEL


def led_to_driver(local, led):
    """(local pixel, led 0/1) -> (chain 0..3, chip_in_chain, channel 0..15)."""
    local = _check_range("local pixel index", local, PIXELS_PER_PANEL)
    led = _check_range("led", led, LEDS_PER_PIXEL)
    k = local * LEDS_PER_PIXEL + led
    chip = k // CHANNELS_PER_CHIP
    chain = np.searchsorted(_CHAIN_START, chip, side="right") - 1
    return chain, chip - _CHAIN_START[chain], k % CHANNELS_PER_CHIP


def driver_to_led(chain, chip_in_chain, channel):
    """(chain, chip_in_chain, channel) -> (local pixel, led). Unused channels raise ValueError."""
    chain = _check_range("chain", chain, len(CHIPS_PER_CHAIN))
    chip_in_chain = _check_range("chip_in_chain", chip_in_chain, max(CHIPS_PER_CHAIN))
    channel = _check_range("channel", channel, CHANNELS_PER_CHIP)
    chain, chip_in_chain, channel = np.broadcast_arrays(chain, chip_in_chain, channel)
    short = chip_in_chain >= np.asarray(CHIPS_PER_CHAIN)[chain]
    if np.any(short):
        i = np.flatnonzero(short)[0]
        c = int(chain.flat[i])
        raise ValueError(f"chip_in_chain out of range: chain {c} has chips 0..{CHIPS_PER_CHAIN[c] - 1}, "
                         f"got {int(chip_in_chain.flat[i])}")
    k = (_CHAIN_START[chain] + chip_in_chain) * CHANNELS_PER_CHIP + channel
    if np.any(k >= LEDS_PER_PANEL):
        i = np.flatnonzero(k >= LEDS_PER_PANEL)[0]
        raise ValueError(f"driver channel is not connected: chain {int(chain.flat[i])}, chip "
                         f"{int(chip_in_chain.flat[i])}, channel {int(channel.flat[i])} (LED index {int(k.flat[i])}; "
                         f"allowed up to {LEDS_PER_PANEL - 1})")
    return k // LEDS_PER_PIXEL, k % LEDS_PER_PIXEL


@dataclass(frozen=True, slots=True)
class PixelAddress:
    """Every address of one pixel. `actuator` is the polariser actuator (0..8) of a UV pixel, else None."""

    index: int
    panel: int
    pentagon: int
    slot: int
    local: int
    is_uv: bool
    actuator: int | None
    # (chain, chip_in_chain, channel) of LED 0 and LED 1
    drivers: tuple[tuple[int, int, int], tuple[int, int, int]]


def address(g: int) -> PixelAddress:
    """The full hardware address of global pixel index `g`."""
    if isinstance(g, bool) or not isinstance(g, (int, np.integer)):
        raise ValueError(f"pixel index must be an integer 0..{N_PIXELS - 1}, got {g!r}")
    panel, local = (int(v) for v in split_global(int(g)))
    pentagon, slot = (int(v) for v in split_panel(panel))
    uv = bool(is_uv_local(local))
    drivers = tuple(tuple(int(v) for v in led_to_driver(local, led)) for led in range(LEDS_PER_PIXEL))
    return PixelAddress(int(g), panel, pentagon, slot, local, uv, local - GB_PER_PANEL if uv else None, drivers)
