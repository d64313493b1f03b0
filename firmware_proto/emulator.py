"""The distributor board and its 55 panels, in-process: feed it UDP payloads, read what the dome shows.

`Emulator.handle_datagram(payload)` never raises: every datagram is counted, and a bad one is dropped and
counted under its rejection reason (`errors.REASONS`). The distributor routes each checked datagram to one of
11 `PentagonLink`s, which carry serial frames to their five panels either bit-exactly (line="bits": framed,
CRC'd, Manchester-coded, optionally corrupted, decoded and checked) or on the fast path (line="fast": the same
frames and checks without the bit level). Both give identical results.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable

import numpy as np

from antarium.core.clock import Clock, MonotonicClock
from antarium.geometry.constants import (
    CHIPS_PER_PANEL,
    LEDS_PER_PANEL,
    N_ACTUATORS,
    N_PANELS,
    N_PENTAGONS,
    N_PIXELS,
    PANELS_PER_PENTAGON,
)

from . import panel_link
from .actuator import COIL_VOLTAGE_V, AircoreBank
from .config import OP_BRIGHTNESS, OP_DOT_CORRECTION, decode_config
from .control import OP_HELLO, OP_LATCH, OP_STATUS_REQUEST, decode_system
from .errors import ProtocolError, UnknownTypeError
from .header import CLASS_CONTROL, CLASS_VIDEO, parse_control_header, split_td
from .led_driver import (
    FAULT_NAMES,
    FAULT_NONE,
    FAULT_OPEN,
    detected_faults,
    emitted,
    flicker_frequency_hz,
    supply_current_a,
)
from .panel import Panel
from .panel_link import (
    FAULT_BITMAP_BYTES,
    PANEL_STATUS_HEAD,
    SLOT_ALL,
    ST_BRIGHTNESS,
    ST_DOT_CORRECTION,
    ST_LATCH,
    ST_PANEL_STATUS,
    ST_POLARISER,
    ST_STATUS_POLL,
    ST_VIDEO,
    SerialFrame,
)
from .polariser import CODES_PER_PI, OP_POLARISER, decode_polarisers
from .replies import (
    CAPABILITIES,
    COUNTER_NAMES,
    encode_actuators,
    encode_counters,
    encode_faults,
    encode_temperatures,
    encode_version,
)
from .thermal import LED_SUPPLY_V, PanelThermal
from .video import decode_panel_data, parse_video

LINE_MODES = ("fast", "bits")
THERMAL_UPDATE_S = 0.05  # the panel power feeding the thermal model is refreshed at most this often


class PentagonLink:
    """The serial link from the distributor to the five panels of pentagon `index`.

    `corrupt`, if given, maps the half-bit symbols of every frame (both directions) to what arrives (bits mode).
    """

    def __init__(self, index: int, panels: list[Panel], counters: Counter, line: str,
                 corrupt: Callable[[np.ndarray], np.ndarray] | None = None) -> None:
        if line not in LINE_MODES:
            raise ValueError(f"line mode {line!r} unknown: allowed {LINE_MODES}")
        self.index = index
        self.panels = panels
        self.counters = counters
        self.line = line
        self.corrupt = corrupt

    def _carry(self, frame: SerialFrame) -> SerialFrame:
        if self.line == "fast":
            return panel_link.check_serial_frame(frame)
        symbols = panel_link.to_line(frame)
        if self.corrupt is not None:
            symbols = self.corrupt(symbols)
        return panel_link.from_line(symbols)

    def send(self, frame: SerialFrame) -> list:
        """Carry `frame` to its panel(s); returns their answers (empty if the frame was lost on the line)."""
        try:
            frame = self._carry(frame)
        except ProtocolError as exc:
            self.counters[f"rejected_{exc.reason}"] += 1
            return []
        return self._deliver(frame)

    def receive_line(self, symbols) -> list:
        """Half-bit symbols arriving at the panels of this link (any content). Never raises; bad frames are
        counted and dropped."""
        try:
            frame = panel_link.from_line(symbols)
        except ProtocolError as exc:
            self.counters[f"rejected_{exc.reason}"] += 1
            return []
        if frame.ftype == ST_PANEL_STATUS:  # upstream only: a panel ignores it
            self.counters["rejected_type"] += 1
            return []
        return self._deliver(frame)

    def _deliver(self, frame: SerialFrame) -> list:
        if frame.slot == SLOT_ALL:
            return [p.receive(frame) for p in self.panels]
        return [self.panels[frame.slot].receive(frame)]

    def upstream(self, frame: SerialFrame) -> SerialFrame | None:
        """A panel's frame on its way back to the distributor (same line, same checks); None if lost."""
        try:
            return self._carry(frame)
        except ProtocolError as exc:
            self.counters[f"rejected_{exc.reason}"] += 1
            return None


class Emulator:
    """Distributor + 55 panels. `clock` times actuators and heat; `line` is "fast" or "bits"; `corrupt` is a
    line-corruption function for bits mode (see PentagonLink)."""

    def __init__(self, clock: Clock | None = None, line: str = "fast",
                 corrupt: Callable[[np.ndarray], np.ndarray] | None = None) -> None:
        self.clock = clock or MonotonicClock()
        t0 = self.clock.now()
        self.counters: Counter = Counter({name: 0 for name in COUNTER_NAMES})
        self.counters["internal_errors"] = 0
        self.last_error = ""
        self.panels = [Panel(p, self) for p in range(N_PANELS)]
        self.links = [
            PentagonLink(k, self.panels[k * PANELS_PER_PENTAGON:(k + 1) * PANELS_PER_PENTAGON],
                         self.counters, line, corrupt)
            for k in range(N_PENTAGONS)
        ]
        self.raw = np.zeros((N_PANELS, LEDS_PER_PANEL), np.uint16)       # latched, decoded, uncorrected
        self.dot = np.full((N_PANELS, LEDS_PER_PANEL), 100, np.uint8)    # percent
        self.brightness = np.full(N_PANELS, 100, np.uint8)               # percent (global, kept per panel)
        self.faults = np.zeros((N_PANELS, LEDS_PER_PANEL), np.uint8)     # injected
        self.detected = np.zeros((N_PANELS, LEDS_PER_PANEL), np.uint8)   # reported (sticky)
        self.actuators = AircoreBank((N_PANELS, N_ACTUATORS), t0)
        self.thermal = PanelThermal(N_PANELS, t0)
        self.panel_current_a = supply_current_a(self.raw, CHIPS_PER_PANEL)
        self._next_thermal = t0
        self._power_changed_t: float | None = None  # the drive changed then; not yet fed to the thermal model
        self._latched: list[tuple[int, bytes]] = []
        self._polariser_targets = np.zeros((N_PANELS, N_ACTUATORS))
        self._polariser_commanded = np.zeros((N_PANELS, N_ACTUATORS), bool)
        self._shown: np.ndarray | None = None
        self._drive_cache: np.ndarray | None = None
        # upstream status as last received from the panels
        self.status_temperature_c = np.full(N_PANELS, self.thermal.ambient_c)
        self.status_current_a = self.panel_current_a.copy()
        self.status_codes = np.zeros((N_PANELS, N_ACTUATORS), np.uint16)
        self.status_holding = np.ones((N_PANELS, N_ACTUATORS), bool)  # at power-up at rest on holding current
        self._panel_faults: dict[int, list[tuple[int, int, str]]] = {}
        self._snapshot: dict[str, np.ndarray] | None = None

    # ---- datagrams ----
    def handle_datagram(self, payload) -> list[bytes]:
        """Process one UDP payload (bytes-like); returns the reply datagrams to send back. Never raises."""
        self.counters["datagrams_received"] += 1
        try:
            replies = self._dispatch(payload)
        except ProtocolError as exc:
            self.counters[f"rejected_{exc.reason}"] += 1
            self.last_error = str(exc)
            return []
        except Exception as exc:  # the board must not stop, whatever arrives; counted and reported
            self.counters["internal_errors"] += 1
            self.last_error = f"{type(exc).__name__}: {exc}"
            return []
        self.counters["datagrams_accepted"] += 1
        return replies

    def _dispatch(self, payload) -> list[bytes]:
        if not isinstance(payload, bytes):
            payload = bytes(payload)
        if not payload:
            raise UnknownTypeError("empty datagram")
        cls, _ = split_td(payload[0])
        if cls == CLASS_VIDEO:
            panel, _, _ = parse_video(payload)
            link = self.links[panel // PANELS_PER_PENTAGON]
            link.send(SerialFrame(ST_VIDEO, panel % PANELS_PER_PENTAGON, payload[1], payload[2:]))
            return []
        if cls != CLASS_CONTROL:
            raise UnknownTypeError(f"message class {cls} not accepted by the distributor: allowed 0 (video), "
                                   "1 (control)")
        _, opcode, _ = parse_control_header(payload, CLASS_CONTROL)
        self._refresh_power(self.clock.now())  # before a control message changes the drive (or polls the panels)
        if opcode == OP_LATCH:
            self._latch(decode_system(payload).info)
            return []
        if opcode == OP_POLARISER:
            msg = decode_polarisers(payload)
            panels = range(N_PANELS) if msg.codes.shape[0] == N_PANELS else [msg.address]
            for row, p in zip(msg.codes, panels, strict=True):
                self._to_panel(p, ST_POLARISER, row.astype(">u2").tobytes())
            self._flush_polarisers()
            self.counters["polariser_updates"] += 1
            return []
        if opcode in (OP_DOT_CORRECTION, OP_BRIGHTNESS):
            msg = decode_config(payload)
            if opcode == OP_DOT_CORRECTION:
                self._to_panel(msg.address, ST_DOT_CORRECTION, msg.percent.tobytes())
            else:
                for link in self.links:
                    link.send(SerialFrame(ST_BRIGHTNESS, SLOT_ALL, 0, msg.percent.tobytes()))
            self.counters["config_updates"] += 1
            return []
        if opcode == OP_STATUS_REQUEST:
            tag = decode_system(payload).info
            self.counters["status_requests"] += 1
            return self._status_replies(tag)
        if opcode == OP_HELLO:
            return [encode_version(decode_system(payload).info, sum(CAPABILITIES.values()))]
        raise UnknownTypeError(f"control opcode 0x{opcode:02x} unknown: allowed 0x01..0x06")

    def _to_panel(self, panel: int, ftype: int, data: bytes) -> list:
        link = self.links[panel // PANELS_PER_PENTAGON]
        return link.send(SerialFrame(ftype, panel % PANELS_PER_PENTAGON, 0, data))

    def _latch(self, seq: int) -> None:
        shown = 0
        for link in self.links:
            shown += sum(bool(r) for r in link.send(SerialFrame(ST_LATCH, SLOT_ALL, seq, b"")))
        self.counters["frames_received"] += 1
        self.counters["frames_latched" if shown == N_PANELS else "frames_dropped"] += 1
        self.counters["panel_misses"] += N_PANELS - shown
        self._flush()

    # ---- what the panels show ----
    def queue_latched(self, panel: int, data: bytes) -> None:
        """A panel latched `data`; decoded with all others of the same latch in one vectorised step."""
        self._latched.append((panel, data))

    def show(self, items: list[tuple[int, bytes]]) -> None:
        """Decode panel images (panel, 1110 bytes of pixel data) into the latched LED values now."""
        self._refresh_power(self.clock.now())
        self._latched.extend(items)
        self._flush()

    def _flush(self) -> None:
        if not self._latched:
            return
        items, self._latched = self._latched, []
        idx = np.fromiter((p for p, _ in items), np.intp, len(items))
        self.raw[idx] = decode_panel_data(b"".join(d for _, d in items))
        self._changed()

    def _changed(self) -> None:
        """The drive of some LED changed: refresh caches, fault detection and (rate-limited) the heat input."""
        self._shown = None
        self._drive_cache = None
        t = self.clock.now()
        if self.faults.any():  # sticky: an LED not driven now keeps the kind last detected, a driven one the latest
            found = detected_faults(self._drive(), self.faults)
            np.copyto(self.detected, found, where=found != FAULT_NONE)
        if self._power_changed_t is None:
            self._power_changed_t = t
        self._refresh_power(t)

    def _refresh_power(self, t: float, force: bool = False) -> None:
        """Feed the present drive's power to the heat model from the time the drive changed, at most every
        THERMAL_UPDATE_S of emulator time (any time with `force`). Called before anything changes the drive, so a
        change the rate limit held back counts from when it happened, not from the next change or status poll."""
        if self._power_changed_t is not None and (force or t >= self._next_thermal):
            self._update_power(self._power_changed_t)
            self._power_changed_t = None
            self._next_thermal = t + THERMAL_UPDATE_S

    def _drive(self) -> np.ndarray:
        """(55, 740) uint16 driver values: latched values * dot correction * brightness, rounded."""
        if self._drive_cache is None:
            if (self.dot == 100).all() and (self.brightness == 100).all():
                self._drive_cache = self.raw
            else:
                scale = self.dot.astype(np.uint32) * self.brightness[:, None]  # 0..10000
                self._drive_cache = ((self.raw * scale + 5000) // 10000).astype(np.uint16)
        return self._drive_cache

    def _update_power(self, t: float) -> None:
        drive = self._drive()
        if self.faults.any():
            drive = np.where(self.faults == FAULT_OPEN, 0, drive)  # an open LED draws nothing; a short still does
        self.panel_current_a = supply_current_a(drive, CHIPS_PER_PANEL)
        coils = self.actuators.supply_current_a(t).sum(axis=1)
        self.thermal.set_power(t, LED_SUPPLY_V * self.panel_current_a + COIL_VOLTAGE_V * coils)

    def led_values(self) -> np.ndarray:
        """(20350, 2) uint16, read-only: the light every LED emits now (latched, dot-corrected, dimmed, faulty
        LEDs dark), in global pixel order; column 0 = green / plain UV, column 1 = blue / polarised UV."""
        if self._shown is None:
            shown = emitted(self._drive(), self.faults) if self.faults.any() else self._drive().copy()
            shown = shown.reshape(N_PIXELS, 2)
            shown.flags.writeable = False
            self._shown = shown
        return self._shown

    def flicker_frequency_hz(self) -> np.ndarray:
        """(20350, 2) effective PWM flicker frequency of every LED as it is driven now (Hz; 0 = dark)."""
        return flicker_frequency_hz(self.led_values())

    # ---- settings reached through the panels ----
    def set_dot_correction(self, panel: int, percent: np.ndarray) -> None:
        self.dot[panel] = percent
        self._changed()

    def set_brightness(self, panel: int, percent: int) -> None:
        self.brightness[panel] = percent
        self._changed()

    def queue_polariser(self, panel: int, angles: np.ndarray) -> None:
        """A panel was told to turn its polarisers to `angles` (9,); applied with the others of the same
        datagram in one vectorised step."""
        self._polariser_targets[panel] = angles
        self._polariser_commanded[panel] = True

    def _flush_polarisers(self) -> None:
        if not self._polariser_commanded.any():
            return
        t = self.clock.now()
        present = self.actuators.polariser_angle(t)
        moved = self._polariser_commanded & (np.abs(np.sin(self._polariser_targets - present)) > 1e-9)
        self.actuators.command_polariser(t, self._polariser_targets, moved)
        self._polariser_commanded[:] = False

    def polariser_angles(self) -> np.ndarray:
        """(55, 9) present e-vector angles of the polarisers, rad in [0, pi)."""
        return self.actuators.polariser_angle(self.clock.now())

    # ---- faults ----
    def inject_fault(self, panel: int, led: int, kind: str) -> None:
        """Make LED `led` (0..739) of `panel` open or short from now on (`kind` "open" | "short" | "none")."""
        codes = {"none": FAULT_NONE, **{v: k for k, v in FAULT_NAMES.items()}}
        if kind not in codes:
            raise ValueError(f"fault kind {kind!r} unknown: allowed {sorted(codes)}")
        if not (0 <= panel < N_PANELS and 0 <= led < LEDS_PER_PANEL):
            raise ValueError(f"fault address ({panel}, {led}) out of range: panel 0..54, LED 0..739")
        self._refresh_power(self.clock.now())
        self.faults[panel, led] = codes[kind]
        if kind == "none":
            self.detected[panel, led] = FAULT_NONE
        self._changed()

    # ---- upstream ----
    def sensor_snapshot(self) -> dict[str, np.ndarray]:
        """What the panels' sensors read at the present STATUS_POLL (computed once per request, for all panels):
        temperature in 0.01 degC, LED-supply current in mA, holding bits, big-endian angle codes."""
        if self._snapshot is None:
            t = self.clock.now()
            angles = self.actuators.polariser_angle(t)
            self._snapshot = {
                "temperature_cc": np.clip(np.rint(self.thermal.advance(t) * 100), -32768, 32767).astype(np.int64),
                "current_ma": np.clip(np.rint(self.panel_current_a * 1000), 0, 0xFFFF).astype(np.int64),
                "holding_bits": self.actuators.holding(t).astype(np.int64) @ (1 << np.arange(N_ACTUATORS)),
                "codes": (np.rint(angles * (CODES_PER_PI / np.pi)).astype(np.int64) % CODES_PER_PI).astype(">u2"),
            }
        return self._snapshot

    def _status_replies(self, tag: int) -> list[bytes]:
        t = self.clock.now()
        self._refresh_power(t, force=True)
        self._update_power(t)
        self._snapshot = None
        for p in range(N_PANELS):
            answers = self._to_panel(p, ST_STATUS_POLL, b"")
            back = self.links[p // PANELS_PER_PENTAGON].upstream(answers[0]) if answers else None
            if back is None:
                continue  # lost: keep the last known status of this panel
            self._read_panel_status(p, back.data)
        faults = [f for p in range(N_PANELS) for f in self._panel_faults.get(p, [])]
        self._snapshot = None
        return [
            encode_counters(tag, self.counters),
            encode_temperatures(tag, self.status_temperature_c, self.status_current_a),
            encode_faults(tag, faults),
            encode_actuators(tag, self.status_codes, self.status_holding),
        ]

    def _read_panel_status(self, p: int, data: bytes) -> None:
        head = PANEL_STATUS_HEAD.unpack(data)
        self.status_temperature_c[p] = head["temperature_cc"] / 100
        self.status_current_a[p] = head["current_ma"] / 1000
        self.status_holding[p] = (head["holding"] >> np.arange(N_ACTUATORS)) & 1
        o = PANEL_STATUS_HEAD.size
        bits = np.unpackbits(np.frombuffer(data, np.uint8, 2 * FAULT_BITMAP_BYTES, o)).reshape(2, -1)
        bits = bits[:, :LEDS_PER_PANEL]
        self.status_codes[p] = np.frombuffer(data, ">u2", N_ACTUATORS, o + 2 * FAULT_BITMAP_BYTES)
        leds_open, leds_short = np.flatnonzero(bits[0]), np.flatnonzero(bits[1])
        self._panel_faults[p] = [(p, int(k), "open") for k in leds_open] + [(p, int(k), "short") for k in leds_short]

    def stats(self) -> dict:
        """Counters by name (COUNTER_NAMES plus internal_errors) and the last rejection's message."""
        return {**{k: int(v) for k, v in self.counters.items()}, "last_error": self.last_error}
