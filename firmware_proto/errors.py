"""Typed protocol errors. Every error names what was wrong and what is allowed.

Each class carries a short `reason` key; the emulator counts rejected datagrams and serial frames under it.
All are `ValueError`s, so callers that only care about "bad input" can catch that.
"""

from __future__ import annotations


class ProtocolError(ValueError):
    """Base class of every wire-format error."""

    reason = "protocol"


class LengthError(ProtocolError):
    """A message is shorter or longer than its type requires."""

    reason = "length"


class UnknownTypeError(ProtocolError):
    """Unknown message class, opcode or serial frame type."""

    reason = "type"


class PanelError(ProtocolError):
    """Destination panel (or pentagon slot) out of range for this message."""

    reason = "panel"


class VersionError(ProtocolError):
    """The message carries a protocol version this code does not speak."""

    reason = "version"


class FieldRangeError(ProtocolError):
    """A field holds a value outside its allowed range."""

    reason = "field"


class FramingError(ProtocolError):
    """Panel-link frame without a valid preamble and sync byte, or not a whole number of bytes."""

    reason = "framing"


class ManchesterError(ProtocolError):
    """Panel-link line symbols that are not a valid Manchester bit (no mid-bit transition)."""

    reason = "manchester"


class CrcError(ProtocolError):
    """Panel-link frame whose CRC-16 does not match its contents."""

    reason = "crc"


#: every rejection reason, in the order the COUNTERS reply carries them (plus "stale", see `panel`)
REASONS = ("length", "type", "panel", "version", "field", "stale", "framing", "manchester", "crc")
