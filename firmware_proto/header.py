"""The first bytes of every datagram between host and distributor (UDP payload).

Byte 0 of every datagram is TD, the type/destination byte:  bits 7-6 = message class, bits 5-0 = address
(panel 0..54, or 63 = the distributor / the whole dome). A VIDEO datagram has one more header byte (INFO:
bit 7 = IMMEDIATE flag, bits 6-0 = frame sequence); CONTROL and REPLY datagrams have the 4-byte
`CONTROL_HEADER` (TD, VERSION, OPCODE, INFO) followed by the opcode's body. All multi-byte fields big-endian.
"""

from __future__ import annotations

from numbers import Integral

from antarium.geometry.constants import N_PANELS

from .errors import LengthError, PanelError, UnknownTypeError, VersionError
from .fields import Field, FieldTable

PROTOCOL_VERSION = 1

CLASS_VIDEO = 0    # host -> distributor, 1,112 bytes, one panel's image
CLASS_CONTROL = 1  # host -> distributor: latch, polarisers, configuration, requests
CLASS_REPLY = 2    # distributor -> host: version, counters, temperatures, faults, actuators
# class 3 is reserved and rejected

ADDR_ALL = 63      # the distributor itself / every panel

SEQ_MODULO = 128   # frame sequence numbers are 7 bits
FLAG_IMMEDIATE = 0x80  # VIDEO INFO bit 7: show this panel image on receipt, without waiting for a latch

CONTROL_HEADER = FieldTable(
    "control header",
    (
        Field("td", "B", 0, 255),
        Field("version", "B", 0, 255),
        Field("opcode", "B", 0, 255),
        Field("info", "B", 0, 255),
    ),
)
CONTROL_HEADER_SIZE = CONTROL_HEADER.size  # 4


def td_byte(msg_class: int, address: int) -> int:
    """The type/destination byte of a message of `msg_class` for `address` (panel 0..54 or ADDR_ALL)."""
    if msg_class not in (CLASS_VIDEO, CLASS_CONTROL, CLASS_REPLY):
        raise UnknownTypeError(f"message class {msg_class} unknown: allowed 0 (video), 1 (control), 2 (reply)")
    check_address(address, allow_all=True)
    return (msg_class << 6) | address


def split_td(td: int) -> tuple[int, int]:
    """TD byte -> (message class 0..3, address 0..63)."""
    return td >> 6, td & 0x3F


def check_address(address: int, allow_all: bool) -> int:
    """`address` if it is a panel 0..54 (or ADDR_ALL when `allow_all`), else PanelError (also for a float or bool)."""
    if not isinstance(address, bool) and isinstance(address, Integral) and (
            0 <= address < N_PANELS or (allow_all and address == ADDR_ALL)):
        return int(address)
    allowed = f"0..{N_PANELS - 1}" + (f" or {ADDR_ALL} (all)" if allow_all else "")
    raise PanelError(f"address {address} out of range: allowed {allowed}")


def control_header(msg_class: int, address: int, opcode: int, info: int = 0) -> bytes:
    """The 4 header bytes of a CONTROL or REPLY message."""
    return CONTROL_HEADER.pack(td=td_byte(msg_class, address), version=PROTOCOL_VERSION, opcode=opcode, info=info)


def parse_control_header(buf, msg_class: int) -> tuple[int, int, int]:
    """Check the 4-byte header of a CONTROL or REPLY datagram -> (address, opcode, info).

    Raises LengthError (shorter than 4 bytes), UnknownTypeError (other class), VersionError.
    """
    if len(buf) < CONTROL_HEADER_SIZE:
        raise LengthError(f"datagram of {len(buf)} bytes is shorter than the {CONTROL_HEADER_SIZE}-byte header")
    h = CONTROL_HEADER.unpack(buf)
    cls, address = split_td(h["td"])
    if cls != msg_class:
        raise UnknownTypeError(f"message class {cls}, expected {msg_class}")
    if h["version"] != PROTOCOL_VERSION:
        raise VersionError(f"protocol version {h['version']} not supported: this side speaks {PROTOCOL_VERSION}")
    return address, h["opcode"], h["info"]


def seq_newer(a: int, b: int) -> bool:
    """True if 7-bit sequence `a` is later than `b` (serial-number arithmetic, half window 63)."""
    return 0 < (a - b) % SEQ_MODULO < SEQ_MODULO // 2
