"""VIDEO datagrams: one panel's image per datagram, 55 per frame (message class 0).

Layout (1,112 bytes, big-endian):

    byte 0        TD      bits 7-6 = 0 (VIDEO), bits 5-0 = destination panel 0..54
    byte 1        INFO    bit 7 = IMMEDIATE (show on receipt), bits 6-0 = frame sequence 0..127
    bytes 2..     370 pixels in local pixel order, 3 bytes each:
                  L (uint16, big-endian) = luminance, C (uint8) = chromaticity

A green/blue pixel carries L = G + B and C = floor(255 * G / L + 1/2), the green share (C = 0 when L = 0); a UV
pixel carries L = plain + polarised drive and C = floor(255 * P / L + 1/2), the share of its polarised LED P.
The panel decodes the share S = (L * C + 127) div 255 (integer round-to-nearest): G = S, B = L - S for a green/blue
pixel, P = S, plain = L - S for a UV pixel. Each LED value is then within L / 510 + 1/2 LSB of the original.
"""

from __future__ import annotations

import numpy as np

from antarium.geometry.constants import GB_PER_PANEL, LEDS_PER_PANEL, N_PANELS, N_PIXELS, PIXELS_PER_PANEL

from .errors import FieldRangeError, LengthError, PanelError, UnknownTypeError
from .header import CLASS_VIDEO, FLAG_IMMEDIATE, SEQ_MODULO, split_td

VIDEO_HEADER_SIZE = 2
BYTES_PER_PIXEL = 3
PANEL_DATA_SIZE = PIXELS_PER_PANEL * BYTES_PER_PIXEL       # 1,110
VIDEO_PAYLOAD_SIZE = VIDEO_HEADER_SIZE + PANEL_DATA_SIZE   # 1,112

#: one pixel on the wire: 16-bit luminance (big-endian) then 8-bit chromaticity
PIXEL_DTYPE = np.dtype([("L", ">u2"), ("C", "u1")])


def check_frame(frame) -> np.ndarray:
    """`frame` if it is a valid LED frame: (20350, 2) uint16 with frame[:, 0] + frame[:, 1] <= 65535.

    Raises ValueError naming the shape, dtype or first offending pixel.
    """
    if not isinstance(frame, np.ndarray) or frame.shape != (N_PIXELS, 2) or frame.dtype != np.uint16:
        got = f"{frame.shape} {frame.dtype}" if isinstance(frame, np.ndarray) else type(frame).__name__
        raise ValueError(f"LED frame must be a ({N_PIXELS}, 2) uint16 array, got {got}")
    return frame


def video_info(seq: int, immediate: bool = False) -> int:
    """The VIDEO INFO byte for frame sequence `seq` (0..127)."""
    if not 0 <= seq < SEQ_MODULO:
        raise FieldRangeError(f"frame sequence {seq} out of range: allowed 0..{SEQ_MODULO - 1}")
    return (FLAG_IMMEDIATE if immediate else 0) | seq


def luma_chroma(share, other) -> tuple[np.ndarray, np.ndarray]:
    """Two LED drives (uint16 arrays, same shape) -> (L uint32, C uint8): L = share + other,
    C = floor(255 * share / L + 1/2), 0 where L == 0. Raises ValueError where L > 65535.
    """
    total = np.add(share, other, dtype=np.uint32)
    if total.size and int(total.max()) > 0xFFFF:
        bad = int(np.argmax(total > 0xFFFF))
        raise ValueError(
            f"pixel {bad}: drive sum {int(total.flat[bad])} > 65535; a pixel never draws more than one LED's current"
        )
    num = np.multiply(share, 510, dtype=np.uint32)
    num += total
    den = total << 1
    np.maximum(den, 1, out=den)
    num //= den
    return total, num.astype(np.uint8)


def split_luma_chroma(lum, chroma) -> tuple[np.ndarray, np.ndarray]:
    """(L, C) as on the wire -> (share, other) uint16: share = (L * C + 127) div 255, other = L - share."""
    lum = np.asarray(lum, dtype=np.uint32)
    share = lum * np.asarray(chroma, dtype=np.uint32)
    share += 127
    share //= 255
    return share.astype(np.uint16), (lum - share).astype(np.uint16)


def encode_frame(frame: np.ndarray, seq: int, immediate: bool = False, out: np.ndarray | None = None) -> np.ndarray:
    """LED frame (20350, 2) uint16 -> the 55 VIDEO datagrams as rows of a (55, 1112) uint8 array.

    `seq` is the 7-bit frame sequence; `out` (55, 1112) uint8 is reused when given. Raises ValueError on a
    frame of the wrong shape/dtype or one violating frame[:, 0] + frame[:, 1] <= 65535.
    """
    check_frame(frame)
    info = video_info(seq, immediate)
    if out is None:
        out = np.empty((N_PANELS, VIDEO_PAYLOAD_SIZE), np.uint8)
    elif out.shape != (N_PANELS, VIDEO_PAYLOAD_SIZE) or out.dtype != np.uint8 or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous ({N_PANELS}, {VIDEO_PAYLOAD_SIZE}) uint8 array")
    by_panel = frame.reshape(N_PANELS, PIXELS_PER_PANEL, 2)
    share = by_panel[:, :, 0].copy()   # green; for UV pixels the polarised LED (column 1)
    other = by_panel[:, :, 1].copy()   # blue; for UV pixels the plain LED (column 0)
    share[:, GB_PER_PANEL:], other[:, GB_PER_PANEL:] = by_panel[:, GB_PER_PANEL:, 1], by_panel[:, GB_PER_PANEL:, 0]
    lum, chroma = luma_chroma(share, other)
    out[:, 0] = np.arange(N_PANELS, dtype=np.uint8)  # TD: class 0, panel
    out[:, 1] = info
    pixels = out[:, VIDEO_HEADER_SIZE:].view(PIXEL_DTYPE)  # (55, 370)
    pixels["L"] = lum
    pixels["C"] = chroma
    return out


def parse_video(payload) -> tuple[int, int, bool]:
    """Check a VIDEO datagram -> (panel, seq, immediate). Raises LengthError, UnknownTypeError, PanelError."""
    if len(payload) != VIDEO_PAYLOAD_SIZE:
        raise LengthError(f"VIDEO datagram must be {VIDEO_PAYLOAD_SIZE} bytes, got {len(payload)}")
    cls, panel = split_td(payload[0])
    if cls != CLASS_VIDEO:
        raise UnknownTypeError(f"message class {cls} is not VIDEO (0)")
    if panel >= N_PANELS:
        raise PanelError(f"VIDEO panel {panel} out of range: allowed 0..{N_PANELS - 1}")
    info = payload[1]
    return panel, info & (SEQ_MODULO - 1), bool(info & FLAG_IMMEDIATE)


def decode_panel_data(data) -> np.ndarray:
    """Panel pixel data, (n, 1110) uint8 (or n * 1110 bytes) -> (n, 740) uint16 LED values, LED = 2*local + led."""
    arr = np.frombuffer(data, np.uint8) if isinstance(data, (bytes, bytearray, memoryview)) else np.asarray(data)
    if arr.size % PANEL_DATA_SIZE:
        raise LengthError(f"panel data must be a multiple of {PANEL_DATA_SIZE} bytes, got {arr.size}")
    pixels = np.ascontiguousarray(arr, dtype=np.uint8).reshape(-1, PANEL_DATA_SIZE).view(PIXEL_DTYPE)
    share, other = split_luma_chroma(pixels["L"], pixels["C"])
    leds = np.empty((pixels.shape[0], LEDS_PER_PANEL), np.uint16)
    leds[:, 0::2] = share   # green
    leds[:, 1::2] = other   # blue
    uv = 2 * GB_PER_PANEL   # UV pixels: the share is the polarised LED (1), the rest the plain one (0)
    leds[:, uv + 1::2] = share[:, GB_PER_PANEL:]
    leds[:, uv::2] = other[:, GB_PER_PANEL:]
    return leds


def decode_frame(datagrams) -> np.ndarray:
    """The 55 VIDEO datagrams of one frame (any order, (55, 1112) uint8 or a list of bytes) -> (20350, 2) uint16.

    Raises ProtocolError subclasses on a bad datagram and ValueError unless every panel appears exactly once.
    """
    rows = [bytes(d) for d in datagrams]
    panels = [parse_video(d)[0] for d in rows]
    if sorted(panels) != list(range(N_PANELS)):
        raise ValueError(f"a frame needs exactly one VIDEO datagram per panel 0..{N_PANELS - 1}, got panels {panels}")
    order = np.argsort(panels)
    data = b"".join(rows[i][VIDEO_HEADER_SIZE:] for i in order)
    return decode_panel_data(data).reshape(N_PIXELS, 2)
