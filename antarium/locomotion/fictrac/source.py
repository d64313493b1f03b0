"""FicTrac as a `LocomotionSource`: its live socket stream (UDP or TCP) and replay of its `.dat` logs.

    open_source("fictrac", transport="udp", host="127.0.0.1", port=5000)   # we receive FicTrac's datagrams
    open_source("fictrac", transport="tcp", host="127.0.0.1", port=5000)   # FicTrac 2.0 (2.1 sends UDP only)
    open_source("fictrac-replay", path="run.dat", speed=1.0, clock=clock)

Malformed lines (a TCP line cut by a disconnect included), and frames that do not convert to a sample, are counted
(`status()["malformed"]`) and skipped; samples dropped from a full queue (`read()` fell `max_queue` behind) are
counted (`dropped_samples`);
a jump of FicTrac's frame counter is counted as a gap; a step back of it, or of the sequence counter (column 23:
FicTrac reset its tracking), as a reset. The live source calls itself connected while frames arrive at least
every `timeout_s`.
"""

from __future__ import annotations

import socket
from dataclasses import replace
from pathlib import Path
from typing import Any

from antarium.core.clock import Clock, MonotonicClock
from antarium.locomotion import BallSample, LocomotionSource, ReaderSource, positive
from antarium.locomotion.fictrac.protocol import FicTracFrame, FicTracParseError, parse_line, to_sample
from antarium.locomotion.fictrac.timeline import replay_times
from antarium.locomotion.replay import check_speed

TRANSPORTS = ("udp", "tcp")
MAX_LINE = 4096  # bytes; a longer line without newline is garbage


def _max_match_error(value: float | None) -> float | None:
    """The match error at which a sample's quality reaches 0 (None: quality 1 always), checked."""
    if value is None:
        return None
    return positive(value, "FicTrac max_match_error", "FicTrac's match error; leave it out for quality 1")


class _Counters:
    """Line statistics shared by the live and replay sources."""

    def __init__(self, max_match_error: float | None) -> None:
        self.counts = dict.fromkeys(("lines", "frames", "malformed", "gaps", "lost_frames", "resets"), 0)
        self._prev: tuple[int, int] | None = None  # frame counter, sequence counter
        self.max_match_error = max_match_error
        self.last_error = ""

    def malformed(self, reason: str) -> None:
        """Count a line that yields no sample."""
        self.counts["lines"] += 1
        self.counts["malformed"] += 1
        self.last_error = reason

    def parse(self, line: bytes | str, t: float) -> tuple[FicTracFrame, BallSample] | None:
        """The frame of `line` and its sample at host time `t` (s), or None (counted malformed)."""
        try:
            frame = parse_line(line)
        except FicTracParseError as exc:
            self.malformed(str(exc))
            return None
        try:
            sample = to_sample(frame, t, self.max_match_error)
        except (ArithmeticError, TypeError, ValueError) as exc:  # never end the reader thread
            self.malformed(f"FicTrac frame {frame.frame} does not convert to a sample: {exc}")
            return None
        self.counts["lines"] += 1
        if self._prev is not None:
            step = frame.frame - self._prev[0]
            if step < 1 or frame.seq < self._prev[1]:  # FicTrac restarted, or reset its tracking (column 23)
                self.counts["resets"] += 1
            elif step > 1:
                self.counts["gaps"] += 1
                self.counts["lost_frames"] += step - 1
        self._prev = (frame.frame, frame.seq)
        self.counts["frames"] += 1
        return frame, sample


class FicTracSource(ReaderSource):
    """FicTrac's live stream on loopback or the lab network."""

    def __init__(
        self,
        transport: str = "udp",
        host: str = "127.0.0.1",
        port: int = 5000,
        clock: Clock | None = None,
        max_match_error: float | None = None,
        timeout_s: float = 1.0,
        retry_s: float = 0.2,
        max_queue: int = 100_000,
    ) -> None:
        if transport not in TRANSPORTS:
            raise ValueError(f"FicTrac transport must be one of {', '.join(TRANSPORTS)}, got {transport!r}")
        if not isinstance(port, int) or not 0 <= port <= 65535:
            raise ValueError(f"FicTrac port must be an integer 0..65535, got {port!r}")
        self.transport, self.host, self.port = transport, host, port
        self.clock = clock or MonotonicClock()
        self.timeout_s = positive(timeout_s, "FicTrac timeout_s", "s without frames before it is not connected")
        self.retry_s = positive(retry_s, "FicTrac retry_s", "s between tries to connect to FicTrac over tcp")
        self._stats = _Counters(_max_match_error(max_match_error))
        super().__init__(max_queue, "FicTrac max_queue")
        self._sock: socket.socket | None = None
        self._last_frame: float | None = None
        self._tcp_connected = False
        self._sender_terminates = False  # the sender ends its lines with a newline (FicTrac does)
        self._dropped = 0  # samples dropped from a full queue (read() fell max_queue behind)

    @property
    def address(self) -> tuple[str, int]:
        """The bound UDP address (port resolved when 0 was asked) or the TCP peer."""
        if self.transport == "udp" and self._sock is not None:
            return self._sock.getsockname()[:2]
        return (self.host, self.port)

    @property
    def thread_name(self) -> str:
        return f"fictrac-{self.transport}"

    def _open(self) -> None:
        if self.transport == "udp":
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                sock.bind((self.host, self.port))
            except OSError as exc:
                sock.close()
                raise RuntimeError(f"cannot listen for FicTrac on udp {self.host}:{self.port}: {exc}") from None
            sock.settimeout(0.05)
            self._sock = sock

    def _close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def lost_hint(self) -> str:
        return f"is FicTrac running and sending to {self.transport} {self.host}:{self.port} (its sock_port)?"

    def status(self) -> dict[str, Any]:
        now = self.clock.now()
        fresh = self._last_frame is not None and now - self._last_frame <= self.timeout_s
        connected = fresh and (self.transport == "udp" or self._tcp_connected)
        return {"connected": connected, "source": f"fictrac-{self.transport}", "address": list(self.address),
                "last_error": self._stats.last_error, **self._stats.counts, "dropped_samples": self._dropped}

    def _line(self, line: bytes) -> None:
        t = self.clock.now()
        parsed = self._stats.parse(line, t)
        if parsed is not None:
            if self._push(parsed[1]):  # read() fell max_queue behind: the oldest sample went
                self._dropped += 1
            self._last_frame = t

    def _cut(self, pending: bytes, reason: str) -> None:
        """The TCP connection ended (`reason`): a line it cut (`pending`, without its end of line) is counted
        malformed, as the UDP path and the .dat replay count theirs."""
        if pending.strip():
            self._stats.malformed("FicTrac line cut by disconnect")
        self._stats.last_error = reason if not pending.strip() else f"FicTrac line cut by disconnect ({reason})"

    def _run(self) -> None:
        if self.transport == "udp":
            self._run_udp()
        else:
            self._run_tcp()

    def _run_udp(self) -> None:
        sock = self._sock
        while not self._stop.is_set():
            try:
                data = sock.recv(65536)
            except TimeoutError:
                continue
            except OSError as exc:
                self._stats.last_error = f"udp receive failed: {exc}"
                continue
            # FicTrac ends each line with a newline: once a sender has done so, a datagram without one was cut
            terminated = data.endswith(b"\n")
            self._sender_terminates = self._sender_terminates or terminated
            lines = data.splitlines()
            for k, line in enumerate(lines):
                if k == len(lines) - 1 and self._sender_terminates and not terminated:
                    self._stats.malformed("FicTrac datagram cut short (its line has no end of line)")
                elif line.strip():
                    self._line(line)

    def _run_tcp(self) -> None:
        while not self._stop.is_set():
            try:
                sock = socket.create_connection((self.host, self.port), timeout=self.retry_s)
            except OSError as exc:
                self._stats.last_error = f"cannot connect to FicTrac at tcp {self.host}:{self.port}: {exc}"
                self._stop.wait(self.retry_s)
                continue
            sock.settimeout(0.05)
            self._tcp_connected = True
            pending = b""
            with sock:
                while not self._stop.is_set():
                    try:
                        data = sock.recv(65536)
                    except TimeoutError:
                        continue
                    except OSError as exc:
                        self._cut(pending, f"FicTrac connection lost: {exc}")
                        break
                    if not data:
                        self._cut(pending, "FicTrac closed the connection")
                        break
                    *lines, pending = (pending + data).split(b"\n")
                    for line in lines:
                        if line.strip():
                            self._line(line)
                    if len(pending) > MAX_LINE:
                        self._stats.malformed(f"FicTrac line longer than {MAX_LINE} bytes")
                        pending = b""
            self._tcp_connected = False


class FicTracReplay(LocomotionSource):
    """A FicTrac `.dat` log played back on `clock`, paced by its timestamps (field 22) divided by `speed`.

    Field 22 is repaired first (`timeline.replay_times`: a log made from a video holds wall-clock times
    in its first and last frames); a sample's `t_device` is that repaired time, seconds from the first frame.
    A last line without its end of line (the log was cut while being written) is counted malformed.
    """

    def __init__(
        self, path: str | Path, clock: Clock | None = None, speed: float = 1.0, max_match_error: float | None = None
    ) -> None:
        self.speed = check_speed("fictrac-replay", speed)
        self.path = Path(path)
        self.clock = clock or MonotonicClock()
        self._stats = _Counters(_max_match_error(max_match_error))
        self._frames: list[tuple[float, BallSample, float]] = []  # (replay offset s, sample, log time s)
        self._next = 0
        self._t0: float | None = None

    def start(self) -> None:
        if self._t0 is not None:
            return
        try:
            data = self.path.read_bytes()
        except FileNotFoundError:
            raise FileNotFoundError(f"FicTrac log {str(self.path)!r} not found") from None
        lines, frames = data.splitlines(), []
        for k, line in enumerate(lines):
            if not line.strip():
                continue
            if k == len(lines) - 1 and not data.endswith(b"\n"):
                self._stats.malformed(f"the last line of {self.path.name} is cut short (no end of line)")
                continue
            parsed = self._stats.parse(line, 0.0)
            if parsed is not None:
                frames.append(parsed)
        times = replay_times([f.timestamp_ms for f, _ in frames])
        self._frames = [(float(t) / self.speed, s, float(t)) for t, (_, s) in zip(times, frames, strict=True)]
        self._t0 = self.clock.now()

    def read(self) -> list[BallSample]:
        if self._t0 is None:
            return []
        elapsed = self.clock.now() - self._t0 + 1e-9  # a frame due now is not missed by rounding
        out = []
        frames = self._frames
        while self._next < len(frames) and frames[self._next][0] <= elapsed:
            offset, sample, t_log = frames[self._next]
            out.append(replace(sample, t=self._t0 + offset, t_device=t_log))  # the log's own time, repaired
            self._next += 1
        return out

    @property
    def finished(self) -> bool:
        return self._t0 is not None and self._next >= len(self._frames)

    def status(self) -> dict[str, Any]:
        return {"connected": self._t0 is not None, "source": "fictrac-replay",
                "path": str(self.path), "finished": self.finished, "replayed": self._next,
                "last_error": self._stats.last_error, **self._stats.counts}
