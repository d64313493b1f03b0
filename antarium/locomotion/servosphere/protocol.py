"""Servosphere motor-link wire format, version 1 (docs/servosphere.md): host <-> microcontroller over serial.

Every message: SYNC (0xA5 0x5A) | version u8 | type u8 | length u8 | payload | CRC-16/CCITT-FALSE (u16 LE)
over version..payload. Integers little-endian. One declared field table per message type; `encode(msg)` and
`Decoder.feed(bytes)` are the pair; a garbled or truncated message raises or is counted, never mis-read.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, fields

SYNC = b"\xa5\x5a"
VERSION = 1
HEADER = struct.Struct("<BBB")  # version, type, payload length
CRC = struct.Struct("<H")
MAX_PAYLOAD = 64

#: fault bits reported by the firmware (FAULT) and set by the host when it loses the firmware
FAULT_STALL_1, FAULT_STALL_2, FAULT_STALL_3 = 0x01, 0x02, 0x04
FAULT_WATCHDOG = 0x08  # no valid command within the watchdog time: motors ramped to 0
FAULT_BAD_MESSAGE = 0x10  # the firmware received a message it could not decode


class ProtocolError(ValueError):
    """A message that cannot be encoded or decoded."""


class ChecksumError(ProtocolError):
    """The CRC does not match: bytes were garbled on the line."""


class VersionError(ProtocolError):
    """A message of another protocol version."""


class UnknownTypeError(ProtocolError):
    """A message type this version does not define."""


class LengthError(ProtocolError):
    """A payload whose length does not fit its type."""


def _table_entry(i: int) -> int:
    crc = i << 8
    for _ in range(8):
        crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


_TABLE = [_table_entry(i) for i in range(256)]


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection); crc16(b"123456789") == 0x29B1."""
    crc = 0xFFFF
    for byte in data:
        crc = ((crc << 8) & 0xFFFF) ^ _TABLE[((crc >> 8) ^ byte) & 0xFF]
    return crc


# -- messages: (type code, struct of the payload) declared once per class ---------------------------------
@dataclass(frozen=True, slots=True)
class SetRates:
    """Host -> firmware: step rates (steps/s, signed) for the three rotors; `seq` echoes back in `Status`."""

    TYPE = 0x01
    FORMAT = struct.Struct("<Hiii")
    seq: int
    rate1: int
    rate2: int
    rate3: int


@dataclass(frozen=True, slots=True)
class Stop:
    """Host -> firmware: ramp all rotors to 0 at the acceleration limit."""

    TYPE = 0x02
    FORMAT = struct.Struct("<H")
    seq: int


@dataclass(frozen=True, slots=True)
class ClearFaults:
    """Host -> firmware: clear the latched fault bits (motors stay stopped until the next SetRates)."""

    TYPE = 0x03
    FORMAT = struct.Struct("<H")
    seq: int


@dataclass(frozen=True, slots=True)
class Status:
    """Firmware -> host, after every command: cumulative step counts (int32, wrapping), the firmware clock
    (microseconds, u32 wrapping), the latched fault bits and the `seq` of the command it answers."""

    TYPE = 0x81
    FORMAT = struct.Struct("<HIiiiB")
    seq: int
    t_us: int
    steps1: int
    steps2: int
    steps3: int
    faults: int


MESSAGES = {cls.TYPE: cls for cls in (SetRates, Stop, ClearFaults, Status)}


def encode(msg) -> bytes:
    """The bytes of one message; ProtocolError for a field out of its range."""
    try:
        payload = msg.FORMAT.pack(*(getattr(msg, f.name) for f in fields(msg)))
    except struct.error as exc:
        raise ProtocolError(f"{type(msg).__name__} field out of range ({exc}); allowed: the widths of "
                            f"{msg.FORMAT.format!r}") from None
    body = HEADER.pack(VERSION, msg.TYPE, len(payload)) + payload
    return SYNC + body + CRC.pack(crc16(body))


def decode(data: bytes):
    """One whole message (SYNC .. CRC) -> its dataclass; typed ProtocolError otherwise."""
    if len(data) < 7 or data[:2] != SYNC:
        raise ProtocolError(f"a message starts with {SYNC.hex()} and has at least 7 bytes, got {data[:8].hex()}")
    version, kind, length = HEADER.unpack_from(data, 2)
    if len(data) != 7 + length:
        raise LengthError(f"message length {len(data)} bytes does not match its header's payload {length}")
    body = data[2:5 + length]
    (crc,) = CRC.unpack_from(data, 5 + length)
    if crc != crc16(body):
        raise ChecksumError(f"CRC {crc:#06x} does not match {crc16(body):#06x}")
    if version != VERSION:
        raise VersionError(f"protocol version {version}; allowed: {VERSION}")
    cls = MESSAGES.get(kind)
    if cls is None:
        raise UnknownTypeError(f"message type {kind:#04x}; allowed: {', '.join(f'{k:#04x}' for k in MESSAGES)}")
    if length != cls.FORMAT.size:
        raise LengthError(f"{cls.__name__} payload must be {cls.FORMAT.size} bytes, got {length}")
    return cls(*cls.FORMAT.unpack_from(data, 5))


class Decoder:
    """Stream decoder: `feed(bytes)` returns the whole messages found; garbled bytes are skipped to the next SYNC
    and counted in `errors` (by error class name), so one bad byte costs one message, not the stream."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.errors: dict[str, int] = {}

    def feed(self, data: bytes) -> list:
        buf = self._buf
        buf += data
        out = []
        while True:
            start = buf.find(SYNC)
            if start < 0:
                if len(buf) > 1:  # junk; keep a last byte that may start a SYNC
                    self._count("ProtocolError")
                    del buf[:-1]
                break
            if start:
                self._count("ProtocolError")
                del buf[:start]
            if len(buf) < 5:
                break
            length = buf[4]
            if length > MAX_PAYLOAD:
                self._count("LengthError")
                del buf[:2]
                continue
            if len(buf) < 7 + length:
                break
            try:
                out.append(decode(bytes(buf[:7 + length])))
                del buf[:7 + length]
            except ProtocolError as exc:
                self._count(type(exc).__name__)
                del buf[:2]  # resynchronise on the next SYNC
        return out

    def _count(self, name: str) -> None:
        self.errors[name] = self.errors.get(name, 0) + 1
