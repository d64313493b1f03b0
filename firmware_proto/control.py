"""System CONTROL messages (class 1): LATCH, STATUS_REQUEST, HELLO. Each is just the 4-byte control header.

    byte 0  TD       0x7F  (class 1, address 63 = the distributor / all panels)
    byte 1  VERSION  1
    byte 2  OPCODE   0x01 LATCH, 0x05 STATUS_REQUEST, 0x06 HELLO
    byte 3  INFO     LATCH: frame sequence 0..127 (bit 7 must be 0); requests: a tag 0..255 echoed in the replies
"""

from __future__ import annotations

from typing import NamedTuple

from .errors import FieldRangeError, LengthError, PanelError, UnknownTypeError
from .header import ADDR_ALL, CLASS_CONTROL, CONTROL_HEADER_SIZE, SEQ_MODULO, control_header, parse_control_header

OP_LATCH = 0x01
OP_STATUS_REQUEST = 0x05
OP_HELLO = 0x06
SYSTEM_OPCODES = (OP_LATCH, OP_STATUS_REQUEST, OP_HELLO)


class SystemMessage(NamedTuple):
    opcode: int
    info: int  # LATCH: sequence; requests: tag


def encode_latch(seq: int) -> bytes:
    """LATCH for frame `seq` (0..127): every panel holding that frame shows it now."""
    if not 0 <= seq < SEQ_MODULO:
        raise FieldRangeError(f"latch sequence {seq} out of range: allowed 0..{SEQ_MODULO - 1}")
    return control_header(CLASS_CONTROL, ADDR_ALL, OP_LATCH, seq)


def encode_status_request(tag: int) -> bytes:
    """STATUS_REQUEST: the distributor answers COUNTERS, TEMPERATURES, FAULTS, ACTUATORS with INFO = `tag`."""
    return control_header(CLASS_CONTROL, ADDR_ALL, OP_STATUS_REQUEST, tag)


def encode_hello(tag: int) -> bytes:
    """HELLO: the distributor answers VERSION with INFO = `tag`."""
    return control_header(CLASS_CONTROL, ADDR_ALL, OP_HELLO, tag)


def decode_system(buf) -> SystemMessage:
    """Check a LATCH / STATUS_REQUEST / HELLO datagram. Raises a ProtocolError subclass."""
    address, opcode, info = parse_control_header(buf, CLASS_CONTROL)
    if opcode not in SYSTEM_OPCODES:
        raise UnknownTypeError(f"opcode 0x{opcode:02x} is not a system control message (0x01, 0x05, 0x06)")
    if len(buf) != CONTROL_HEADER_SIZE:
        raise LengthError(f"system control message must be {CONTROL_HEADER_SIZE} bytes, got {len(buf)}")
    if address != ADDR_ALL:
        raise PanelError(f"system control message must be addressed to {ADDR_ALL} (all), got {address}")
    if opcode == OP_LATCH and info >= SEQ_MODULO:
        raise FieldRangeError(f"latch sequence {info} out of range: allowed 0..{SEQ_MODULO - 1}")
    return SystemMessage(opcode, info)
