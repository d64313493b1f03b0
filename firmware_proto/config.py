"""CONFIG control messages (class 1): per-LED dot correction and global brightness.

DOT_CORRECTION (opcode 0x03), to one panel (TD = 0x40 | panel):
    4-byte control header (INFO 0), then 740 bytes: percent 0..100 of LED k = 2 * local + led.
BRIGHTNESS (opcode 0x04), to the whole dome (TD = 0x7F):
    4-byte control header (INFO 0), then 1 byte: percent 0..100.

A panel drives LED k at  value * dot[k] * brightness / 10000  (integer, rounded to nearest); both take effect at
once on what the dome shows (they are driver current settings, not frame data).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from antarium.geometry.constants import LEDS_PER_PANEL, N_PANELS, N_PIXELS

from .errors import FieldRangeError, LengthError, PanelError, UnknownTypeError
from .header import ADDR_ALL, CLASS_CONTROL, CONTROL_HEADER_SIZE, control_header, parse_control_header

OP_DOT_CORRECTION = 0x03
OP_BRIGHTNESS = 0x04
CONFIG_OPCODES = (OP_DOT_CORRECTION, OP_BRIGHTNESS)
MAX_PERCENT = 100


class ConfigMessage(NamedTuple):
    opcode: int
    address: int           # panel for DOT_CORRECTION, ADDR_ALL for BRIGHTNESS
    percent: np.ndarray    # (740,) uint8 for DOT_CORRECTION, (1,) uint8 for BRIGHTNESS


def check_percent(name: str, values) -> np.ndarray:
    """Integer percentages 0..100 as uint8. Raises ValueError naming the first bad entry."""
    a = np.asarray(values)
    if a.dtype.kind not in "iu" and not (a.dtype.kind == "f" and np.all(np.isfinite(a)) and np.all(a == np.rint(a))):
        raise ValueError(f"{name} must be whole percentages 0..100, got dtype {a.dtype}")
    bad = (a < 0) | (a > MAX_PERCENT)
    if np.any(bad):
        i = int(np.argmax(bad.ravel()))
        raise ValueError(f"{name} entry {i} is {a.ravel()[i]}: allowed 0..{MAX_PERCENT} percent")
    return a.astype(np.uint8)


def dot_correction_table(dot) -> np.ndarray:
    """Dot correction percent 0..100 per LED as (55, 740) uint8 (LED k = 2 * local + led), from a scalar (every
    LED), (55, 740), or (20350, 2) in frame layout. Raises ValueError naming the shape or the first bad entry."""
    dot = np.asarray(dot)
    if dot.ndim == 0:
        dot = np.full((N_PANELS, LEDS_PER_PANEL), dot)
    if dot.shape == (N_PIXELS, 2):
        dot = dot.reshape(N_PANELS, LEDS_PER_PANEL)
    if dot.shape != (N_PANELS, LEDS_PER_PANEL):
        raise ValueError(f"dot correction must be a scalar, ({N_PANELS}, {LEDS_PER_PANEL}) or ({N_PIXELS}, 2); "
                         f"got shape {dot.shape}")
    return check_percent("dot correction", dot)


def read_dot_correction(value: int | str) -> np.ndarray:
    """A rig's `[link] dot_correction` as `dot_correction_table`: a percent for every LED, or the path of a .npy
    file of percents ((55, 740) or (20350, 2)). Raises ValueError naming the file and what is wrong with it."""
    if isinstance(value, str):
        try:
            table = np.load(value, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise ValueError(f"dot correction file {value!r} cannot be read as a .npy array ({exc})") from None
        try:
            return dot_correction_table(table)
        except ValueError as exc:
            raise ValueError(f"dot correction file {value!r}: {exc}") from None
    return dot_correction_table(value)


def encode_dot_correction(panel: int, percent) -> bytes:
    """Dot correction of the 740 LEDs of `panel` (percent 0..100, LED k = 2 * local + led) -> one datagram."""
    p = check_percent("dot correction", percent)
    if p.shape != (LEDS_PER_PANEL,):
        raise ValueError(f"dot correction of one panel must have shape ({LEDS_PER_PANEL},), got {p.shape}")
    if not 0 <= panel < N_PANELS:
        raise PanelError(f"dot correction panel {panel} out of range: allowed 0..{N_PANELS - 1}")
    return control_header(CLASS_CONTROL, panel, OP_DOT_CORRECTION) + p.tobytes()


def encode_brightness(percent: int) -> bytes:
    """Global brightness, percent 0..100 -> one datagram."""
    p = check_percent("brightness", np.asarray([percent]))
    return control_header(CLASS_CONTROL, ADDR_ALL, OP_BRIGHTNESS) + p.tobytes()


def decode_config(buf) -> ConfigMessage:
    """Check a DOT_CORRECTION or BRIGHTNESS datagram -> ConfigMessage. Raises a ProtocolError subclass."""
    address, opcode, info = parse_control_header(buf, CLASS_CONTROL)
    if opcode not in CONFIG_OPCODES:
        raise UnknownTypeError(f"opcode 0x{opcode:02x} is not a config message (0x03, 0x04)")
    if opcode == OP_DOT_CORRECTION:
        size, ok_address = CONTROL_HEADER_SIZE + LEDS_PER_PANEL, address < N_PANELS
        allowed = f"a panel 0..{N_PANELS - 1}"
    else:
        size, ok_address, allowed = CONTROL_HEADER_SIZE + 1, address == ADDR_ALL, f"{ADDR_ALL} (all)"
    if len(buf) != size:
        raise LengthError(f"config opcode 0x{opcode:02x} must be {size} bytes, got {len(buf)}")
    if not ok_address:
        raise PanelError(f"config opcode 0x{opcode:02x} address {address} not allowed: must be {allowed}")
    if info != 0:
        raise FieldRangeError(f"config info byte must be 0, got {info}")
    percent = np.frombuffer(bytes(buf), np.uint8, offset=CONTROL_HEADER_SIZE).copy()
    if percent.max() > MAX_PERCENT:
        i = int(np.argmax(percent > MAX_PERCENT))
        raise FieldRangeError(f"config percent entry {i} is {percent[i]}: allowed 0..{MAX_PERCENT}")
    return ConfigMessage(opcode, address, percent)
