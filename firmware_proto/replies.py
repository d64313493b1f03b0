"""REPLY messages (class 2), distributor -> host. TD = 0xBF (class 2, address 63); INFO echoes the request tag.

    VERSION      0x81  body: VERSION_BODY (8 bytes)
    COUNTERS     0x82  body: one uint32 per name in COUNTER_NAMES (wrapping)
    TEMPERATURES 0x83  body: 55 x int16 panel temperature in 0.01 degC, then 55 x uint16 panel LED-supply current in mA
    FAULTS       0x84  body: uint16 total faults, then min(total, 360) entries of
                           (uint8 panel, uint16 LED 0..739, uint8 kind 1 = open / 2 = short)
    ACTUATORS    0x85  body: 495 x uint16 present polariser angle codes (panel-major, see `polariser`),
                           then 62 bytes: bit i (MSB first) set = actuator i on holding current
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from antarium.geometry.constants import LEDS_PER_PANEL, N_ACTUATORS, N_PANELS, PIXELS_PER_PANEL

from .errors import REASONS, FieldRangeError, LengthError, PanelError, UnknownTypeError
from .fields import Field, FieldTable
from .header import ADDR_ALL, CLASS_REPLY, CONTROL_HEADER_SIZE, PROTOCOL_VERSION, control_header, parse_control_header

OP_VERSION = 0x81
OP_COUNTERS = 0x82
OP_TEMPERATURES = 0x83
OP_FAULTS = 0x84
OP_ACTUATORS = 0x85
STATUS_OPCODES = (OP_COUNTERS, OP_TEMPERATURES, OP_FAULTS, OP_ACTUATORS)  # the answer to one STATUS_REQUEST

FIRMWARE_VERSION = (1, 0)

CAP_POLARISERS = 1 << 0
CAP_DOT_CORRECTION = 1 << 1
CAP_BRIGHTNESS = 1 << 2
CAP_FAULT_DETECTION = 1 << 3
CAP_TEMPERATURE = 1 << 4
CAP_IMMEDIATE = 1 << 5
CAPABILITIES = {
    "polarisers": CAP_POLARISERS,
    "dot_correction": CAP_DOT_CORRECTION,
    "brightness": CAP_BRIGHTNESS,
    "fault_detection": CAP_FAULT_DETECTION,
    "temperature": CAP_TEMPERATURE,
    "immediate": CAP_IMMEDIATE,
}
#: the capabilities the dome needs of a distributor (`dome_shortfall`): the server sends polariser angles every
#: frame; dot correction and brightness are its LED settings (`Link.send_config`); `antarium check` and the
#: telemetry report LED faults and panel temperatures, which read as "no faults" and 0 degC without them. Only
#: IMMEDIATE (single-panel tools, section 3 of docs/protocol.md) is optional.
REQUIRED_CAPABILITIES = ("polarisers", "dot_correction", "brightness", "fault_detection", "temperature")

VERSION_BODY = FieldTable(
    "VERSION",
    (
        Field("protocol_version", "B", 0, 255),
        Field("firmware_major", "B", 0, 255),
        Field("firmware_minor", "B", 0, 255),
        Field("n_panels", "B", 0, 255),  # uint8: any count is read, and flagged unless 55
        Field("pixels_per_panel", "H", 0, 0xFFFF),
        Field("capabilities", "H", 0, 0xFFFF),
    ),
)

#: the COUNTERS reply, in wire order
COUNTER_NAMES = (
    "datagrams_received",   # every datagram, good or bad
    "datagrams_accepted",   # passed every check
    "frames_received",      # LATCH messages accepted
    "frames_latched",       # latches at which all 55 panels showed the new frame
    "frames_dropped",       # latches at which at least one panel kept its previous image
    "panel_misses",         # (panel, latch) pairs that kept the previous image
    "superseded",           # panel images replaced by a newer frame before being latched
    "immediate",            # panel images shown on receipt (IMMEDIATE flag)
    "polariser_updates",
    "config_updates",
    "status_requests",
) + tuple(f"rejected_{r}" for r in REASONS)
COUNTERS_DTYPE = np.dtype(">u4")

TEMPERATURE_DTYPE = np.dtype(">i2")
CURRENT_DTYPE = np.dtype(">u2")
FAULT_DTYPE = np.dtype([("panel", "u1"), ("led", ">u2"), ("kind", "u1")])
FAULT_KINDS = {1: "open", 2: "short"}
MAX_FAULT_ENTRIES = 360
N_ACTUATORS_DOME = N_PANELS * N_ACTUATORS
HOLDING_BYTES = (N_ACTUATORS_DOME + 7) // 8  # 62


class Reply(NamedTuple):
    opcode: int
    tag: int
    fields: dict  # decoded body, JSON-serialisable


def _reply(opcode: int, tag: int, body: bytes) -> bytes:
    return control_header(CLASS_REPLY, ADDR_ALL, opcode, tag) + body


def encode_version(tag: int, capabilities: int) -> bytes:
    body = VERSION_BODY.pack(
        protocol_version=PROTOCOL_VERSION,
        firmware_major=FIRMWARE_VERSION[0],
        firmware_minor=FIRMWARE_VERSION[1],
        n_panels=N_PANELS,
        pixels_per_panel=PIXELS_PER_PANEL,
        capabilities=capabilities,
    )
    return _reply(OP_VERSION, tag, body)


def encode_counters(tag: int, counters: dict[str, int]) -> bytes:
    """`counters` by name (missing names count 0); values wrap modulo 2**32."""
    values = np.array([counters.get(n, 0) % (1 << 32) for n in COUNTER_NAMES], np.uint64).astype(COUNTERS_DTYPE)
    return _reply(OP_COUNTERS, tag, values.tobytes())


def encode_temperatures(tag: int, temperature_c, current_a) -> bytes:
    """(55,) panel temperatures (degC, -327..327) and (55,) LED-supply currents (A, 0..65.5)."""
    t = np.clip(np.rint(np.asarray(temperature_c, np.float64) * 100), -32768, 32767).astype(TEMPERATURE_DTYPE)
    i = np.clip(np.rint(np.asarray(current_a, np.float64) * 1000), 0, 65535).astype(CURRENT_DTYPE)
    if t.shape != (N_PANELS,) or i.shape != (N_PANELS,):
        raise ValueError(f"temperatures and currents must have shape ({N_PANELS},)")
    return _reply(OP_TEMPERATURES, tag, t.tobytes() + i.tobytes())


def encode_faults(tag: int, faults) -> bytes:
    """`faults`: iterable of (panel, led, kind 'open'|'short'); the first 360 are listed, all are counted."""
    faults = list(faults)
    kinds = {v: k for k, v in FAULT_KINDS.items()}
    entries = np.array(
        [(p, led, kinds[kind]) for p, led, kind in faults[:MAX_FAULT_ENTRIES]], FAULT_DTYPE
    )
    return _reply(OP_FAULTS, tag, len(faults).to_bytes(2, "big") + entries.tobytes())


def encode_actuators(tag: int, codes, holding) -> bytes:
    """(55, 9) present angle codes (uint16) and (55, 9) bool holding-current flags."""
    c = np.asarray(codes).astype(">u2").ravel()
    h = np.packbits(np.asarray(holding, bool).ravel())
    if c.size != N_ACTUATORS_DOME or h.size != HOLDING_BYTES:
        raise ValueError(f"actuator codes and holding flags must have shape ({N_PANELS}, {N_ACTUATORS})")
    return _reply(OP_ACTUATORS, tag, c.tobytes() + h.tobytes())


def _expect(buf, size: int, what: str) -> None:
    if len(buf) != size:
        raise LengthError(f"{what} reply must be {size} bytes, got {len(buf)}")


def foreign_version(buf) -> int | None:
    """The protocol version named by a VERSION reply of another protocol version, else None.

    A distributor says which protocol it speaks in the VERSION byte of its replies' header (section 2); its body
    may be laid out differently, so only the 4-byte header of a VERSION reply (TD 0xBF, opcode 0x81) is read.
    None for any datagram that is not such a reply, and for one of this side's own version (`decode_reply`)."""
    head = bytes(buf[:CONTROL_HEADER_SIZE])
    if len(head) < CONTROL_HEADER_SIZE or head[0] != (CLASS_REPLY << 6 | ADDR_ALL) or head[2] != OP_VERSION:
        return None
    return None if head[1] == PROTOCOL_VERSION else head[1]


def dome_shortfall(version: dict) -> str | None:
    """One line naming what a VERSION reply of this protocol version (`decode_reply`'s fields) reports that the
    dome cannot work with, and what it requires: a panel count other than 55, pixels per panel other than 370,
    a capability of `REQUIRED_CAPABILITIES` missing. None when it reports what the dome needs."""
    wrong = []
    if version["n_panels"] != N_PANELS:
        wrong.append(f"{version['n_panels']} panels, {N_PANELS} required (check the panel cables and power)")
    if version["pixels_per_panel"] != PIXELS_PER_PANEL:
        wrong.append(f"{version['pixels_per_panel']} pixels per panel, {PIXELS_PER_PANEL} required (wrong panel "
                     "firmware)")
    missing = [n for n in REQUIRED_CAPABILITIES if not version["capabilities"] & CAPABILITIES[n]]
    if missing:
        wrong.append(f"capability 0x{version['capabilities']:04x}, without {', '.join(missing)}; required: "
                     f"{', '.join(REQUIRED_CAPABILITIES)} (update the distributor's firmware)")
    return "the distributor reports " + "; ".join(wrong) if wrong else None


def decode_reply(buf) -> Reply:
    """Check any REPLY datagram -> Reply(opcode, tag, fields). Raises a ProtocolError subclass."""
    address, opcode, tag = parse_control_header(buf, CLASS_REPLY)
    if address != ADDR_ALL:
        raise PanelError(f"replies come from address {ADDR_ALL}, got {address}")
    buf = bytes(buf)
    h = CONTROL_HEADER_SIZE
    if opcode == OP_VERSION:
        _expect(buf, h + VERSION_BODY.size, "VERSION")
        f = VERSION_BODY.unpack(buf, h)
        f["capability_names"] = sorted(n for n, bit in CAPABILITIES.items() if f["capabilities"] & bit)
        return Reply(opcode, tag, f)
    if opcode == OP_COUNTERS:
        _expect(buf, h + 4 * len(COUNTER_NAMES), "COUNTERS")
        values = np.frombuffer(buf, COUNTERS_DTYPE, offset=h)
        return Reply(opcode, tag, {n: int(v) for n, v in zip(COUNTER_NAMES, values, strict=True)})
    if opcode == OP_TEMPERATURES:
        _expect(buf, h + 4 * N_PANELS, "TEMPERATURES")
        t = np.frombuffer(buf, TEMPERATURE_DTYPE, N_PANELS, h) / 100.0
        i = np.frombuffer(buf, CURRENT_DTYPE, N_PANELS, h + 2 * N_PANELS) / 1000.0
        return Reply(opcode, tag, {"temperature_c": t.tolist(), "current_a": i.tolist()})
    if opcode == OP_FAULTS:
        if len(buf) < h + 2:
            raise LengthError(f"FAULTS reply needs at least {h + 2} bytes, got {len(buf)}")
        total = int.from_bytes(buf[h:h + 2], "big")
        _expect(buf, h + 2 + FAULT_DTYPE.itemsize * min(total, MAX_FAULT_ENTRIES), "FAULTS")
        e = np.frombuffer(buf, FAULT_DTYPE, offset=h + 2)
        if e.size and (e["panel"].max() >= N_PANELS or e["led"].max() >= LEDS_PER_PANEL
                       or not np.isin(e["kind"], list(FAULT_KINDS)).all()):
            raise FieldRangeError(
                f"FAULTS entry out of range: panel 0..{N_PANELS - 1}, LED 0..{LEDS_PER_PANEL - 1}, kind 1 or 2"
            )
        faults = [{"panel": int(p), "led": int(k), "kind": FAULT_KINDS[int(c)]} for p, k, c in e.tolist()]
        return Reply(opcode, tag, {"total": total, "faults": faults})
    if opcode == OP_ACTUATORS:
        _expect(buf, h + 2 * N_ACTUATORS_DOME + HOLDING_BYTES, "ACTUATORS")
        codes = np.frombuffer(buf, ">u2", N_ACTUATORS_DOME, h).astype(np.uint16)
        hold = np.unpackbits(np.frombuffer(buf, np.uint8, HOLDING_BYTES, h + 2 * N_ACTUATORS_DOME))
        return Reply(opcode, tag, {
            "angle_codes": codes.reshape(N_PANELS, N_ACTUATORS).tolist(),
            "holding": hold[:N_ACTUATORS_DOME].astype(bool).reshape(N_PANELS, N_ACTUATORS).tolist(),
        })
    raise UnknownTypeError(f"reply opcode 0x{opcode:02x} unknown: allowed 0x81..0x85")
