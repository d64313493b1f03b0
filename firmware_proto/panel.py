"""One triangle panel's FPGA: buffers a frame, applies the latch rule, takes polariser and driver settings,
answers status polls. Arrays that span the dome (latched LED values, dot correction, actuators, temperatures)
live in the `Emulator`; a panel works on its own row of them.

Latch rule (see docs/protocol.md): a panel keeps at most one pending image, tagged with its 7-bit frame
sequence. A VIDEO frame is accepted unless its sequence is not newer than the last LATCH the panel saw, or older
than the pending image (both count as "stale"); a newer one replaces the pending image ("superseded"). On
LATCH s the panel shows its pending image if and only if that image is frame s; otherwise it keeps showing its
previous image (a "miss"). A pending image of frame s + 1 (it overtook this latch) stays pending; any other is
discarded.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from antarium.geometry.constants import PANELS_PER_PENTAGON

from .errors import ProtocolError
from .header import FLAG_IMMEDIATE, SEQ_MODULO, seq_newer
from .led_driver import FAULT_OPEN, FAULT_SHORT
from .panel_link import (
    PANEL_STATUS_HEAD,
    ST_BRIGHTNESS,
    ST_DOT_CORRECTION,
    ST_LATCH,
    ST_PANEL_STATUS,
    ST_POLARISER,
    ST_STATUS_POLL,
    ST_VIDEO,
    SerialFrame,
)
from .polariser import codes_to_angles

if TYPE_CHECKING:
    from .emulator import Emulator


class Panel:
    """The FPGA of panel `index` (0..54) of `dome`."""

    def __init__(self, index: int, dome: Emulator) -> None:
        self.index = index
        self.slot = index % PANELS_PER_PENTAGON
        self.dome = dome
        self.pending: bytes | None = None
        self.pending_seq = 0
        self.last_latch: int | None = None

    def receive(self, frame: SerialFrame):
        """Act on one checked serial frame. Returns True/False for LATCH (shown or kept the previous image),
        the PANEL_STATUS frame for STATUS_POLL, else None."""
        ftype = frame.ftype
        if ftype == ST_VIDEO:
            return self._video(frame.info, frame.data)
        if ftype == ST_LATCH:
            return self._latch(frame.info & (SEQ_MODULO - 1))
        if ftype == ST_POLARISER:
            codes = np.frombuffer(frame.data, ">u2")
            self.dome.queue_polariser(self.index, codes_to_angles(codes))
            return None
        if ftype == ST_DOT_CORRECTION:
            self.dome.set_dot_correction(self.index, np.frombuffer(frame.data, np.uint8))
            return None
        if ftype == ST_BRIGHTNESS:
            self.dome.set_brightness(self.index, frame.data[0])
            return None
        if ftype == ST_STATUS_POLL:
            return SerialFrame(ST_PANEL_STATUS, self.slot, 0, self.status_data())
        raise ProtocolError(f"panel {self.index} cannot act on serial frame type 0x{ftype:x}")

    def _video(self, info: int, data: bytes) -> None:
        seq = info & (SEQ_MODULO - 1)
        counters = self.dome.counters
        if info & FLAG_IMMEDIATE:
            counters["immediate"] += 1
            self.dome.show([(self.index, data)])
            return
        if self.last_latch is not None and not seq_newer(seq, self.last_latch):
            counters["rejected_stale"] += 1
            return
        if self.pending is not None:
            if seq_newer(self.pending_seq, seq):
                counters["rejected_stale"] += 1
                return
            counters["superseded"] += 1
        self.pending, self.pending_seq = data, seq

    def _latch(self, seq: int) -> bool:
        self.last_latch = seq
        if self.pending is None:
            return False
        if self.pending_seq == seq:
            self.dome.queue_latched(self.index, self.pending)
            self.pending = None
            return True
        if self.pending_seq != (seq + 1) % SEQ_MODULO:  # only the next frame, having overtaken this latch, waits
            self.dome.counters["superseded"] += 1
            self.pending = None
        return False

    def status_data(self) -> bytes:
        """PANEL_STATUS data: temperature, supply current, holding bits, open/short bitmaps, actuator codes."""
        snap, p = self.dome.sensor_snapshot(), self.index
        head = PANEL_STATUS_HEAD.pack(
            temperature_cc=int(snap["temperature_cc"][p]),
            current_ma=int(snap["current_ma"][p]),
            holding=int(snap["holding_bits"][p]),
        )
        detected = self.dome.detected[p]
        return (
            head
            + np.packbits(detected == FAULT_OPEN).tobytes()
            + np.packbits(detected == FAULT_SHORT).tobytes()
            + snap["codes"][p].tobytes()
        )
