"""Declared field tables: fixed big-endian layouts with a range per field (dpkt style)."""

from __future__ import annotations

import operator
import struct
from dataclasses import dataclass

from .errors import FieldRangeError, LengthError


@dataclass(frozen=True)
class Field:
    """One field: `name`, a `struct` format character (byte order comes from the table), allowed lo..hi."""

    name: str
    fmt: str
    lo: int
    hi: int


class FieldTable:
    """A fixed layout of `Field`s in network byte order (big-endian), with range-checked pack/unpack."""

    def __init__(self, name: str, fields: tuple[Field, ...]) -> None:
        self.name = name
        self.fields = fields
        self._struct = struct.Struct(">" + "".join(f.fmt for f in fields))
        self.size = self._struct.size

    def _check(self, values) -> None:
        for f, v in zip(self.fields, values, strict=True):
            if not f.lo <= v <= f.hi:
                raise FieldRangeError(f"{self.name}.{f.name} = {v} out of range: allowed {f.lo}..{f.hi}")

    def pack(self, **values: int) -> bytes:
        """Bytes of the table filled from `values` (every field by name). Raises FieldRangeError."""
        missing = [f.name for f in self.fields if f.name not in values]
        extra = sorted(set(values) - {f.name for f in self.fields})
        if missing or extra:
            raise ValueError(f"{self.name}: missing fields {missing}, unknown fields {extra}")
        ordered = []
        for f in self.fields:
            v = values[f.name]
            try:  # an int or a numpy integer; a float or a bool is refused, never truncated
                if isinstance(v, bool):
                    raise TypeError
                v = operator.index(v)
            except TypeError:
                raise FieldRangeError(f"{self.name}.{f.name} must be an integer, got {v!r}") from None
            ordered.append(v)
        self._check(ordered)
        return self._struct.pack(*ordered)

    def unpack(self, buf, offset: int = 0) -> dict[str, int]:
        """Fields of `buf[offset:offset + size]` by name. Raises LengthError, FieldRangeError."""
        if len(buf) - offset < self.size:
            raise LengthError(f"{self.name}: need {self.size} bytes at offset {offset}, got {len(buf) - offset}")
        values = self._struct.unpack_from(buf, offset)
        self._check(values)
        return {f.name: v for f, v in zip(self.fields, values, strict=True)}
