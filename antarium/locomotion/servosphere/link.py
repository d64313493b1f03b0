"""The motor link: rotor step rates out, `Status` replies (step counts, faults) back, over a byte port.

`MotorLink` owns the protocol (encode, stream decode, sequence numbers, step-count unwrapping); a back-end only
supplies the port (`write(bytes)`, non-blocking `read() -> bytes`, `close()`): pyserial for a real rig, the
simulated rig's port (latency, drops, garbling in front of the firmware emulator) for tests and demos.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from antarium.locomotion.servosphere import finite_numbers
from antarium.locomotion.servosphere import protocol as p

#: consecutive writes the port may refuse (its write timeout passed: the device is not reading) before the link
#: counts as broken; each refused message is dropped (the firmware's watchdog stops the rotors when commands stop).
#: 100 is about 0.5 s of the loop's commands
MAX_STALLED_WRITES = 100


class PortStalled(OSError):
    """The port did not take a write within its write timeout: the message is dropped (or cut: the firmware's
    decoder counts it garbled and resynchronises on the next header)."""


class Port(Protocol):
    def write(self, data: bytes) -> None: ...

    def read(self) -> bytes: ...

    def close(self) -> None: ...


class MotorLink:
    """Commands and replies over `port`. `poll()` returns the new `Status` messages; `steps` holds the unwrapped
    cumulative step counts (int64) of the newest one; `errors` counts garbled or unknown messages by kind;
    `stalled` the messages the port did not take in time (dropped; `PortStalled`), which break the link only when
    MAX_STALLED_WRITES come one after another."""

    def __init__(self, port: Port) -> None:
        self.port = port
        self.decoder = p.Decoder()
        self.seq = 0
        self.sent = 0
        self.received = 0
        self.stalled = 0
        self._stalled_run = 0  # stalled writes since the last one the port took
        self.steps: np.ndarray | None = None
        self._raw: np.ndarray | None = None

    def _send(self, msg) -> int:
        try:
            self.port.write(p.encode(msg))
        except PortStalled as exc:
            self.stalled += 1
            self._stalled_run += 1
            if self._stalled_run >= MAX_STALLED_WRITES:
                raise RuntimeError(f"the motor link's port took none of the last {self._stalled_run} messages "
                                   f"({exc}): the microcontroller is not reading") from None
            return msg.seq
        self._stalled_run = 0
        self.sent += 1
        return msg.seq

    def _next(self) -> int:
        self.seq = (self.seq + 1) % 65536
        return self.seq

    def send_rates(self, rates) -> int:
        """Step rates (3,) steps/s (rounded to integers); returns the message's seq. ValueError, nothing sent, for
        anything but 3 finite numbers."""
        if not finite_numbers(rates, 3):
            raise ValueError(f"motor link rates must be 3 finite numbers (steps/s), got {rates!r}")
        r1, r2, r3 = (int(round(float(x))) for x in rates)
        return self._send(p.SetRates(self._next(), r1, r2, r3))

    def stop(self) -> int:
        return self._send(p.Stop(self._next()))

    def clear_faults(self) -> int:
        return self._send(p.ClearFaults(self._next()))

    def poll(self) -> list[tuple[p.Status, np.ndarray]]:
        """Replies that arrived since the last call, oldest first, each with its step counts unwrapped from int32
        (int64 (3,), counted from the first reply); `steps` is the newest."""
        out = []
        for msg in self.decoder.feed(self.port.read()):
            if not isinstance(msg, p.Status):
                continue
            raw = np.array([msg.steps1, msg.steps2, msg.steps3], dtype=np.int64)
            if self._raw is None:
                self.steps = raw.copy()
            else:
                delta = (raw - self._raw + 2 ** 31) % 2 ** 32 - 2 ** 31
                self.steps = self.steps + delta
            self._raw = raw
            out.append((msg, self.steps))
        self.received += len(out)
        return out

    @property
    def errors(self) -> dict[str, int]:
        return dict(self.decoder.errors)

    def close(self) -> None:
        self.port.close()


class SerialPort:
    """pyserial behind `Port`: `url` is a device (/dev/ttyACM0, COM3) or any pyserial URL."""

    def __init__(self, url: str, baudrate: int = 1_000_000) -> None:
        import serial  # pyserial, only for a real rig

        try:
            self._serial = serial.serial_for_url(url, baudrate=baudrate, timeout=0, write_timeout=0.01)
        except (serial.SerialException, ValueError) as exc:
            raise RuntimeError(f"cannot open servosphere serial port {url!r}: {exc}") from None

    def write(self, data: bytes) -> None:
        import serial

        try:
            self._serial.write(data)
        except serial.SerialTimeoutException as exc:  # the device's buffer is full: it did not read for 10 ms
            raise PortStalled(f"serial write of {len(data)} bytes not taken: {exc}") from exc

    def read(self) -> bytes:
        n = self._serial.in_waiting
        return self._serial.read(n) if n else b""

    def close(self) -> None:
        self._serial.close()


def open_serial_link(url: str, baudrate: int = 1_000_000, **_: Any) -> MotorLink:
    """The `serial` back-end: a microcontroller running the reference firmware on `url`."""
    return MotorLink(SerialPort(url, baudrate))
