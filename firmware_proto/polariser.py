"""POLARISER control messages (class 1, opcode 0x02): target e-vector angles of the UV polariser actuators.

    4-byte control header (TD = 0x40 | panel, or 0x7F for the whole dome; OPCODE 0x02; INFO 0)
    body  9 (one panel) or 55 * 9 (whole dome, panel-major) angle codes, uint16 big-endian

Angle code a <-> angle theta = a * pi / 65536 rad, theta in [0, pi) (resolution 0.0027 deg). Angle j of a panel
drives the actuator behind UV pixel local 361 + j, measured in the panel plane from the panel's local +x axis
towards its +y axis (the polariser axis cos theta * x + sin theta * y): counter-clockwise as seen from the dome
centre, clockwise from outside the dome (docs/geometry.md). The real actuators and their firmware must turn the
polariser in this sense, with code 0 along +x: the renderer's angles (`renderers.output.polariser_angles`) assume
it and nothing on the wire can check it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from antarium.geometry.constants import N_ACTUATORS, N_PANELS

from .errors import FieldRangeError, LengthError, UnknownTypeError
from .header import (
    ADDR_ALL,
    CLASS_CONTROL,
    CONTROL_HEADER_SIZE,
    check_address,
    control_header,
    parse_control_header,
)

OP_POLARISER = 0x02
CODES_PER_PI = 65536
CODE_DTYPE = np.dtype(">u2")


class PolariserMessage(NamedTuple):
    address: int       # panel 0..54, or ADDR_ALL
    codes: np.ndarray  # (n_panels, 9) uint16 angle codes; n_panels = 1 or 55


def _radians(angles) -> np.ndarray:
    """`angles` as a float64 array (radians); ValueError naming the polariser angles when they are not real numbers
    (a string, a complex number; None becomes NaN, which `angles_to_codes` refuses)."""
    if np.iscomplexobj(angles):
        raise ValueError(f"polariser angles must be real numbers (radians), got complex values {angles!r:.80}")
    try:
        return np.asarray(angles, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"polariser angles must be real numbers (radians), got {angles!r:.80}") from None


def wrap_angles(angles) -> np.ndarray:
    """Finite angles in radians, any value -> the same e-vector axes in [0, pi) (float64, a new array).

    An e-vector is an axis, so angles are taken modulo pi; a remainder that rounds to pi itself (np.mod of a tiny
    negative angle) is 0, the same axis, so the result always passes `angles_to_codes`. Raises ValueError for
    values that are not real numbers.
    """
    a = np.mod(_radians(angles), np.pi)
    return np.where(a >= np.pi, 0.0, a)


def angles_to_codes(angles) -> np.ndarray:
    """Angles in radians, each in [0, pi) -> uint16 codes round(angle * 65536 / pi) mod 65536.

    Raises ValueError naming the first non-finite or out-of-range angle (or values that are not real numbers).
    """
    a = _radians(angles)
    bad = ~np.isfinite(a) | (a < 0) | (a >= np.pi)
    if bad.any():
        i = np.unravel_index(int(np.argmax(bad)), a.shape)
        raise ValueError(f"polariser angle at {tuple(int(v) for v in i)} is {float(a[i])!r} rad: allowed [0, pi)")
    return (np.rint(a * (CODES_PER_PI / np.pi)).astype(np.int64) % CODES_PER_PI).astype(np.uint16)


def codes_to_angles(codes) -> np.ndarray:
    """uint16 codes -> angles in radians [0, pi)."""
    return np.asarray(codes, dtype=np.float64) * (np.pi / CODES_PER_PI)


def encode_polarisers(angles, panel: int | None = None) -> bytes:
    """(55, 9) angles (rad, [0, pi)) for the whole dome (panel None), or (9,) angles for one `panel` (0..54; the
    whole-dome address 63 takes 55 x 9) -> one datagram. Raises ValueError (a PanelError for the panel)."""
    if panel is not None:
        check_address(panel, allow_all=False)
    a = _radians(angles)
    expected = (N_PANELS, N_ACTUATORS) if panel is None else (N_ACTUATORS,)
    if a.shape != expected:
        raise ValueError(f"polariser angles must have shape {expected}, got {a.shape}")
    header = control_header(CLASS_CONTROL, ADDR_ALL if panel is None else panel, OP_POLARISER)
    return header + angles_to_codes(a).astype(CODE_DTYPE).tobytes()


def decode_polarisers(buf) -> PolariserMessage:
    """Check a POLARISER datagram -> PolariserMessage. Raises a ProtocolError subclass."""
    address, opcode, info = parse_control_header(buf, CLASS_CONTROL)
    if opcode != OP_POLARISER:
        raise UnknownTypeError(f"opcode 0x{opcode:02x} is not POLARISER (0x{OP_POLARISER:02x})")
    check_address(address, allow_all=True)
    n = N_PANELS if address == ADDR_ALL else 1
    size = CONTROL_HEADER_SIZE + 2 * N_ACTUATORS * n
    if len(buf) != size:
        raise LengthError(f"POLARISER datagram to address {address} must be {size} bytes, got {len(buf)}")
    if info != 0:
        raise FieldRangeError(f"POLARISER info byte must be 0, got {info}")
    codes = np.frombuffer(bytes(buf), CODE_DTYPE, offset=CONTROL_HEADER_SIZE).astype(np.uint16)
    return PolariserMessage(address, codes.reshape(n, N_ACTUATORS))
