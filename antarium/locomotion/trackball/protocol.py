"""The trackball's USB protocol: the interrupt-IN report and the vendor control requests.

Full description for firmware writers: `docs/trackball_usb.md`. All fields little-endian.

Report (32 bytes, interrupt IN endpoint 0x81, one per sample period):

| offset | type   | field        | meaning                                                         |
|-------:|--------|--------------|-----------------------------------------------------------------|
| 0      | u8     | report_id    | 0x54 ('T')                                                      |
| 1      | u8     | flags        | bit 0: sensor 0 overflowed, bit 1: sensor 1 overflowed; others 0 |
| 2      | u8     | squal0       | surface quality of sensor 0 (sensor's SQUAL register, 0..255)   |
| 3      | u8     | squal1       | surface quality of sensor 1                                     |
| 4      | u32    | seq          | report counter, +1 per report, wraps at 2**32; 0 after START     |
| 8      | u64    | t_us         | device time of the end of the sample period, microseconds       |
| 16     | i32 x4 | dx0 dy0 dx1 dy1 | counts moved during the period (sensor x / y axes)           |
"""

from __future__ import annotations

import struct
from typing import NamedTuple

N_SENSORS = 2
REPORT_ID = 0x54
REPORT = struct.Struct("<BBBBIQiiii")
REPORT_SIZE = REPORT.size  # 32
FLAG_OVERFLOW0 = 0x01
FLAG_OVERFLOW1 = 0x02
_FLAGS_KNOWN = FLAG_OVERFLOW0 | FLAG_OVERFLOW1

# USB descriptors the driver relies on
INTERFACE_CLASS_VENDOR = 0xFF
ENDPOINT_IN = 0x81
MAX_RATE_HZ = 1000

# Vendor control requests (recipient: interface 0). OUT = host to device, IN = device to host.
REQUEST_TYPE_OUT = 0x41  # vendor | interface | host-to-device
REQUEST_TYPE_IN = 0xC1  # vendor | interface | device-to-host
REQ_START = 0x01  # wValue 0: reset seq and device time, start sending reports
REQ_STOP = 0x02  # wValue 0: stop sending reports
REQ_SET_RATE = 0x03  # wValue: reports per second, 1..1000
REQ_SET_RESOLUTION = 0x04  # wValue: counts per inch, 100..12000 (sensor rounds to its own step)
REQ_GET_INFO = 0x05  # IN, wLength 8: see INFO
PROTOCOL_VERSION = 1
RATE_RANGE = (1, MAX_RATE_HZ)
RESOLUTION_RANGE = (100, 12000)

#: GET_INFO reply: protocol version u8, number of sensors u8, rate u16 (Hz), resolution u16 (cpi),
#: running u8 (0/1), reserved u8
INFO = struct.Struct("<BBHHBB")


class ReportError(ValueError):
    """A report that cannot be decoded (counted and dropped by the driver)."""


class ShortReportError(ReportError):
    """A report of the wrong length."""


class BadReportError(ReportError):
    """A report of the right length with a wrong id or unknown flag bits."""


class Report(NamedTuple):
    seq: int
    t_us: int
    counts: tuple[int, int, int, int]  # dx0, dy0, dx1, dy1
    squal: tuple[int, int]
    overflow: tuple[bool, bool]


def encode_report(report: Report) -> bytes:
    flags = (FLAG_OVERFLOW0 if report.overflow[0] else 0) | (FLAG_OVERFLOW1 if report.overflow[1] else 0)
    return REPORT.pack(REPORT_ID, flags, *report.squal, report.seq & 0xFFFFFFFF, report.t_us, *report.counts)


def decode_report(data: bytes | bytearray | memoryview) -> Report:
    """Decode one report; raises `ShortReportError` or `BadReportError`."""
    if len(data) != REPORT_SIZE:
        raise ShortReportError(f"trackball report must be {REPORT_SIZE} bytes, got {len(data)}")
    rid, flags, q0, q1, seq, t_us, dx0, dy0, dx1, dy1 = REPORT.unpack(data)
    if rid != REPORT_ID:
        raise BadReportError(f"trackball report id must be 0x{REPORT_ID:02x}, got 0x{rid:02x}")
    if flags & ~_FLAGS_KNOWN:
        raise BadReportError(f"trackball report flags 0x{flags:02x} set unknown bits (allowed mask 0x03)")
    return Report(seq, t_us, (dx0, dy0, dx1, dy1), (q0, q1), (bool(flags & 1), bool(flags & 2)))


class Info(NamedTuple):
    protocol_version: int
    n_sensors: int
    rate_hz: int
    resolution_cpi: int
    running: bool


def encode_info(info: Info) -> bytes:
    return INFO.pack(info.protocol_version, info.n_sensors, info.rate_hz, info.resolution_cpi, int(info.running), 0)


def decode_info(data: bytes | bytearray) -> Info:
    if len(data) != INFO.size:
        raise ShortReportError(f"GET_INFO reply must be {INFO.size} bytes, got {len(data)}")
    version, n, rate, cpi, running, _ = INFO.unpack(bytes(data))
    return Info(version, n, rate, cpi, bool(running))


def seq_gap(previous: int | None, seq: int) -> int:
    """Reports missing between `previous` and `seq` (u32 wrap-around; 0 when consecutive or first)."""
    if previous is None:
        return 0
    return (seq - previous - 1) & 0xFFFFFFFF
