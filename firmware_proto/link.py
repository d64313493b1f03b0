"""The dome link (python-can style): `open_link(interface, **kwargs)` over a registry of back-ends.

Every back-end speaks the same datagrams through the same `Link` methods; a back-end only moves bytes
(`_transmit`, `_receive`). Back-ends are imported lazily, when opened.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from importlib import import_module

import numpy as np

from antarium.geometry.constants import N_ACTUATORS, N_PANELS

from .budget import wire_bits
from .config import check_percent, dot_correction_table, encode_brightness, encode_dot_correction
from .control import encode_hello, encode_latch, encode_status_request
from .errors import ProtocolError
from .header import ADDR_ALL, PROTOCOL_VERSION, SEQ_MODULO, split_td
from .polariser import OP_POLARISER, angles_to_codes, codes_to_angles, encode_polarisers
from .replies import (
    OP_ACTUATORS,
    OP_COUNTERS,
    OP_FAULTS,
    OP_TEMPERATURES,
    OP_VERSION,
    STATUS_OPCODES,
    Reply,
    decode_reply,
    dome_shortfall,
    foreign_version,
)
from .video import VIDEO_PAYLOAD_SIZE, encode_frame, video_info

#: interface name -> "module:Class"
BACKENDS: dict[str, str] = {
    "udp": "antarium.firmware_proto.udp:UdpLink",
    "virtual": "antarium.firmware_proto.virtual:VirtualLink",
}


def open_link(interface: str, **kwargs) -> Link:
    """Open the dome link `interface` ("udp" or "virtual"); kwargs go to the back-end's constructor."""
    if interface not in BACKENDS:
        raise ValueError(f"link interface {interface!r} unknown: allowed {sorted(BACKENDS)}")
    module_name, cls_name = BACKENDS[interface].split(":")
    return getattr(import_module(module_name), cls_name)(**kwargs)


#: no reply for this long is an outage: the link says HELLO again (the distributor may have rebooted)
OUTAGE_S = 1.0
#: an unanswered HELLO is repeated, with the next status request, after this long (seconds)
HELLO_RETRY_S = 0.5
#: an actuator at rest (on holding current) further than this from its last commanded angle (in angle codes,
#: 364 = 1 degree) did not get that update: it is sent again, at most once every POLARISER_RECHECK_S seconds
POLARISER_TOLERANCE_CODES = 364
POLARISER_RECHECK_S = 1.0
_POLARISERS = (OP_POLARISER, ADDR_ALL)  # the key of the whole-dome polariser update in `Link._held`


class IncompatibleDistributor(RuntimeError):
    """The distributor's VERSION names a protocol this host does not speak: no frame is sent."""


class Link(ABC):
    """What every back-end offers; a back-end implements `_transmit` and `_receive`.

    The link says HELLO when it opens and again with a status request every `HELLO_RETRY_S` until a VERSION reply
    arrives (a
    distributor that boots after the host still gets one), and again after an outage of `OUTAGE_S`.

    The state the panels must hold, and lose when the distributor boots (they power up at angle 0, dot correction
    and brightness 100 %), is one table, `_held`: the last POLARISER, DOT_CORRECTION and BRIGHTNESS message to
    each address (`_send_held`). The distributor may not hold them when it answers for the first time since the
    link opened or since an outage (it may have booted or rebooted since, or a message was lost in the outage),
    when a COUNTERS reply shows no more status requests than the one before (it restarted between two polls; the
    link then says HELLO again too), or when a message did not go out (the transport failed): the link then sends
    them again, with the next `telemetry` or `hello`. The polariser angles are also sent again when an ACTUATORS
    reply asked for after the update shows an actuator at rest elsewhere (the update or the panel's serial frame
    was lost).
    """

    #: `telemetry(wait_s=0)` sends a new STATUS_REQUEST at most this often (seconds); a request with wait_s > 0
    #: always goes out. Answering one costs the distributor about 2 ms, so a frame loop polling every frame
    #: must not ask every frame.
    status_interval_s = 0.0

    def __init__(self) -> None:
        self._seq = 0
        self._frame_buf = np.empty((N_PANELS, VIDEO_PAYLOAD_SIZE), np.uint8)
        self._panel_td = np.arange(N_PANELS, dtype=np.uint8)  # VIDEO class 0, panel k
        self._held: dict[tuple[int, int], bytes] = {}  # (opcode, address) -> the last message that set it
        self._unsure: set[tuple[int, int]] = set()  # held state the distributor may have lost: sent again
        self._last_polariser_codes: np.ndarray | None = None  # (55, 9) codes of the last POLARISER update
        self._polarisers_checkable = False  # an ACTUATORS reply asked for after the last update has arrived
        self._polariser_tag = 0  # the request tag when the last update went out
        self._polarisers_rechecked_t: float | None = None
        self._answering = False  # a reply arrived since the link opened and since the last outage
        self._status_requests: int | None = None  # the distributor's count in the last COUNTERS since then
        self._tag = 0
        self._status: dict = {}
        self._last_reply_t: float | None = None
        self._last_request_t: float | None = None
        self.counters = {"frames_sent": 0, "datagrams_sent": 0, "datagrams_failed": 0,
                         "replies_received": 0, "replies_rejected": 0, "state_resent": 0,
                         "state_resent_bits": 0}
        self.closed = False
        self.last_timings: dict[str, float] = {}
        self.hello_pending = True           # no VERSION since the link opened or since the last outage
        self._last_hello_t: float | None = None
        self.incompatible: str | None = None
        self.mismatch: str | None = None  # what the distributor's VERSION reports that the dome cannot use

    # ---- back-end seam ----
    @abstractmethod
    def _transmit(self, data) -> bool:
        """Send one datagram; False (never an exception) when the transport failed."""

    @abstractmethod
    def _receive(self, timeout_s: float) -> bytes | None:
        """The next upstream datagram, waiting up to `timeout_s`; None when there is none."""

    # ---- public API ----
    def send(self, data) -> bool:
        """Send one raw datagram; transport failures are counted, never raised (RuntimeError once closed)."""
        if self.closed:
            raise RuntimeError("the dome link is closed")
        ok = self._transmit(data)
        self.counters["datagrams_sent" if ok else "datagrams_failed"] += 1
        return ok

    def send_frame(self, frame: np.ndarray) -> int:
        """Send LED frame (20350, 2) uint16 as 55 VIDEO datagrams and its LATCH; returns its 7-bit sequence.
        `last_timings` then holds the seconds spent to "encode" and "send" (for the virtual link "send" includes
        the emulator's work).

        Raises ValueError on a bad frame and IncompatibleDistributor when the distributor speaks another protocol
        version (nothing sent); never raises for transport problems (counted).
        """
        seq = self._seq
        t0 = time.perf_counter()
        encode_frame(frame, seq, out=self._frame_buf)
        return self._send_encoded(seq, t0)

    def _send_encoded(self, seq: int, t0: float) -> int:
        """Send the frame encoded in `_frame_buf` since `t0` (perf_counter s) and its LATCH; count it. Nothing to a
        distributor of another protocol version (IncompatibleDistributor)."""
        if self.incompatible:
            raise IncompatibleDistributor(self.incompatible)
        t1 = time.perf_counter()
        self._send_frame_datagrams(encode_latch(seq))
        self.last_timings = {"encode": t1 - t0, "send": time.perf_counter() - t1}
        self._seq = (seq + 1) % SEQ_MODULO
        self.counters["frames_sent"] += 1
        return seq

    def send_packed(self, datagrams: np.ndarray) -> int:
        """Send a frame packed elsewhere (the renderer's GPU path): its 55 VIDEO datagrams, (55, 1112) uint8 with
        TD and pixels set; the sequence goes into every INFO byte here, then the LATCH. Returns the sequence, like
        `send_frame`. Raises ValueError on a wrong shape or a TD that is not VIDEO panel 0..54 in order, and
        IncompatibleDistributor as `send_frame` does."""
        d = datagrams
        if not isinstance(d, np.ndarray) or d.shape != self._frame_buf.shape or d.dtype != np.uint8:
            got = f"{d.shape} {d.dtype}" if isinstance(d, np.ndarray) else type(d).__name__
            raise ValueError(f"packed frame must be a ({N_PANELS}, {VIDEO_PAYLOAD_SIZE}) uint8 array, got {got}")
        if not np.array_equal(d[:, 0], self._panel_td):
            raise ValueError("packed frame: byte 0 of row k must be the VIDEO TD of panel k (0..54)")
        seq = self._seq
        t0 = time.perf_counter()
        np.copyto(self._frame_buf, d)
        self._frame_buf[:, 1] = video_info(seq)
        return self._send_encoded(seq, t0)

    def _send_frame_datagrams(self, latch: bytes) -> None:
        """The frame in `_frame_buf`, then its LATCH, one datagram at a time (a back-end may batch them)."""
        for row in self._frame_buf:
            self.send(row.data)
        self.send(latch)

    def send_polarisers(self, angles, force: bool = False) -> bool:
        """Send (55, 9) polariser e-vector angles (rad, [0, pi)) in one datagram; returns whether it went out.
        Skipped (False) when their 16-bit codes equal the last ones sent, unless `force`. Raises ValueError on
        bad angles."""
        a = np.asarray(angles, dtype=np.float64)
        if a.shape != (N_PANELS, N_ACTUATORS):
            raise ValueError(f"polariser angles must have shape ({N_PANELS}, {N_ACTUATORS}), got {a.shape}")
        codes = angles_to_codes(a)
        if (not force and _POLARISERS not in self._unsure and self._last_polariser_codes is not None
                and np.array_equal(codes, self._last_polariser_codes)):
            return False
        ok = self._send_held(encode_polarisers(a))  # one that failed is sent again (class doc), same angles or not
        self._last_polariser_codes = codes
        return ok

    def _send_held(self, datagram: bytes) -> bool:
        """Send a message that sets state the panels must hold (POLARISER, DOT_CORRECTION, BRIGHTNESS) and keep it
        in `_held` as the latest for its opcode and address; one that did not go out stays marked to be sent
        again (see the class doc). Returns whether it went out."""
        ok = self.send(datagram)
        key = (datagram[2], split_td(datagram[0])[1])
        self._held[key] = datagram
        if not ok:
            self._unsure.add(key)
            return False
        self._unsure.discard(key)
        if key == _POLARISERS:  # replies to requests sent before it show the angles before it
            self._polarisers_checkable = False
            self._polariser_tag = self._tag
        return True

    def _resend_held(self) -> None:
        """Send the held messages the distributor may have lost again, in the order they were first set (see the
        class doc); nothing to a distributor of another protocol version."""
        if self.incompatible:
            return
        for key in [k for k in self._held if k in self._unsure]:
            if self._send_held(self._held[key]):
                self.counters["state_resent"] += 1
                self.counters["state_resent_bits"] += wire_bits(len(self._held[key]))  # for the frames' budget

    def _distributor_may_have_rebooted(self) -> None:
        """Everything held is sent again with the next `telemetry` or `hello`, and VERSION asked for again."""
        self._unsure.update(self._held)
        self.hello_pending = True

    def send_config(self, dot_correction=None, brightness: int | None = None) -> None:
        """Send driver settings: `dot_correction` percent 0..100 per LED — a scalar, (55, 740) (LED k = 2*local
        + led) or (20350, 2) in frame layout — and/or global `brightness` percent 0..100. Raises ValueError
        (nothing sent). The link keeps them and sends them again to a distributor that may have lost them (class
        doc)."""
        if dot_correction is not None:
            dot = dot_correction_table(dot_correction)
        if brightness is not None:
            check_percent("brightness", np.asarray([brightness]))
        datagrams = [] if dot_correction is None else [encode_dot_correction(p, dot[p]) for p in range(N_PANELS)]
        if brightness is not None:
            datagrams.append(encode_brightness(int(brightness)))
        for d in datagrams:
            self._send_held(d)

    def hello(self, wait_s: float = 0.0) -> dict | None:
        """Ask for the distributor's VERSION reply; returns it if the answer to this HELLO (its tag) arrives
        within `wait_s`, else None (also when an earlier HELLO was answered)."""
        self._tag = (self._tag + 1) % 256
        self.send(encode_hello(self._tag))
        self._last_hello_t = time.monotonic()
        answered = self._drain(wait_s, until={OP_VERSION}, tag=self._tag)
        self._resend_held()
        return self._status.get("version") if answered else None

    def telemetry(self, wait_s: float = 0.0) -> dict:
        """Latest upstream status, JSON-serialisable.

        Sends a STATUS_REQUEST (with wait_s = 0 at most every `status_interval_s`) and collects replies for up to
        `wait_s` seconds (0: only what has already arrived; never blocks). Keys: "link" (this side's counters),
        "connected" (an answer ever arrived) and, once the distributor has answered: "age_s" (since the last
        reply), "counters", "temperature_c", "current_a", "faults", "fault_total", "polariser_codes",
        "polariser_angles_deg" (the polarisers' angles reported, degrees), "holding", "version" (protocol, firmware,
        panels, capabilities and their names; from a distributor of another protocol version only
        "protocol_version") once HELLO was answered, "hello"
        ("waiting" until then and after an outage, else "answered"), "incompatible" (the reason) when the
        distributor's protocol version is not ours, and "mismatch" (one line: what it reports and what the dome
        requires) when its VERSION reports other than 55 panels of 370 pixels or lacks a required capability.
        """
        now = time.monotonic()
        if wait_s > 0 or self._last_request_t is None or now - self._last_request_t >= self.status_interval_s:
            if self._last_reply_t is not None and now - self._last_reply_t > OUTAGE_S:
                self.hello_pending = True
                self._answering = False
            if self.hello_pending and (self._last_hello_t is None or now - self._last_hello_t >= HELLO_RETRY_S):
                self._tag = (self._tag + 1) % 256
                self.send(encode_hello(self._tag))
                self._last_hello_t = now
            self._tag = (self._tag + 1) % 256
            self.send(encode_status_request(self._tag))
            self._last_request_t = now
        self._drain(wait_s, until=set(STATUS_OPCODES), tag=self._tag)
        self._resend_held()
        out = {**self._status, "link": dict(self.counters), "connected": self._last_reply_t is not None,
               "hello": "waiting" if self.hello_pending else "answered"}
        if self.incompatible:
            out["incompatible"] = self.incompatible
        if self.mismatch:
            out["mismatch"] = self.mismatch
        if self._last_reply_t is not None:
            out["age_s"] = time.monotonic() - self._last_reply_t
        return out

    def _drain(self, wait_s: float, until: set[int], tag: int | None = None) -> bool:
        """Read replies until every opcode in `until` (with `tag`, if given) arrived or `wait_s` passed; whether
        they all arrived."""
        deadline = time.monotonic() + wait_s
        seen: set[int] = set()
        while True:
            data = self._receive(max(0.0, deadline - time.monotonic()))
            if data is None:
                return False
            try:
                reply = decode_reply(data)
            except ProtocolError:
                version = foreign_version(data)  # a VERSION of another protocol: read as far as its version
                if version is None:
                    self.counters["replies_rejected"] += 1
                    continue
                reply = Reply(OP_VERSION, data[3], {"protocol_version": version})
            self.counters["replies_received"] += 1
            self._last_reply_t = time.monotonic()
            if not self._answering:  # the first answer since the link opened or since an outage
                self._answering = True
                self._status_requests = None
                self._unsure.update(self._held)
            self._absorb(reply.opcode, reply.fields)
            if reply.opcode == OP_ACTUATORS:
                self._check_polarisers(reply.tag, reply.fields)
            if tag is None or reply.tag == tag:
                seen.add(reply.opcode)
            if until <= seen:
                return True

    def _check_polarisers(self, tag: int, f: dict) -> None:
        """Mark the last polariser update for sending again when an actuator at rest is not at its angle."""
        if self._last_polariser_codes is None or _POLARISERS in self._unsure:
            return
        if not self._polarisers_checkable:  # replies to requests sent before the update show the angles before it
            if not 0 < (tag - self._polariser_tag) % 256 < 128:
                return
            self._polarisers_checkable = True
        codes = np.asarray(f["angle_codes"], np.int64)
        off = np.abs((codes - self._last_polariser_codes + 32768) % 65536 - 32768)
        if not (np.asarray(f["holding"], bool) & (off > POLARISER_TOLERANCE_CODES)).any():
            return
        now = time.monotonic()
        if self._polarisers_rechecked_t is None or now - self._polarisers_rechecked_t >= POLARISER_RECHECK_S:
            self._polarisers_rechecked_t = now
            self._unsure.add(_POLARISERS)

    def _absorb(self, opcode: int, f: dict) -> None:
        s = self._status
        if opcode == OP_VERSION:
            self.hello_pending = False
            v = f["protocol_version"]
            s["version"] = f  # of another protocol version: {"protocol_version": v}, all its header says
            if "firmware_major" in f:  # decoded whole: this side's header version
                firmware = f" {f['firmware_major']}.{f['firmware_minor']}"
                self.mismatch = dome_shortfall(f)
            else:
                firmware = ""
                self.mismatch = None  # nothing more is read from it: `incompatible` says why
            self.incompatible = None if v == PROTOCOL_VERSION else (
                f"the distributor speaks protocol version {v}; this host speaks {PROTOCOL_VERSION}: no frames are "
                f"sent (update the host or the distributor's firmware{firmware})")
        elif opcode == OP_COUNTERS:
            # every COUNTERS reply answers a newer request, which it counts: a count that did not grow started
            # again from 0 (a stale or duplicated reply would only send the held state once more)
            if self._status_requests is not None and f["status_requests"] <= self._status_requests:
                self._distributor_may_have_rebooted()
            self._status_requests = f["status_requests"]
            s["counters"] = f
        elif opcode == OP_TEMPERATURES:
            s["temperature_c"], s["current_a"] = f["temperature_c"], f["current_a"]
        elif opcode == OP_FAULTS:
            s["faults"], s["fault_total"] = f["faults"], f["total"]
        elif opcode == OP_ACTUATORS:
            s["polariser_codes"] = f["angle_codes"]
            s["polariser_angles_deg"] = np.degrees(codes_to_angles(f["angle_codes"])).tolist()  # the bus' unit
            s["holding"] = f["holding"]

    def close(self) -> None:
        self.closed = True

    def __enter__(self) -> Link:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
