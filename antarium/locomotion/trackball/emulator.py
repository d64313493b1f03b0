"""An emulated trackball implemented as a pyusb backend, so the driver's real pyusb code path runs without hardware.

    backend = EmulatedTrackball(motion=walk(speed=0.03, turn_rate=0.5), truth=TrackballConfig())
    dev = usb.core.find(backend=backend, idVendor=0x1209, idProduct=0x0001)

The device behaves as `docs/trackball_usb.md` specifies: one vendor interface, interrupt-IN endpoint 0x81
with 32-byte reports, vendor control requests START / STOP / SET_RATE / SET_RESOLUTION / GET_INFO (others
stall). Reports come from a scripted ball motion (`motion(t)` -> angular velocity, rad/s, dome frame)
through the forward kinematics of the `truth` config (its sensor placement, counts per mm and signs are
the hardware's; the driver's config may differ, which is what calibration fixes). Fractional counts are
carried over like a real sensor's. A motion may instead have a method `rotation(t0, t1)` giving the
rotation vector (rad) over a device-time interval, which is then used exactly (e.g. a virtual ant's steps).

Timing: `realtime=True` paces reports on a clock (a late host gets one report holding all the counts since
the last, as the firmware does): the wall clock, or the injected `clock` (`antarium.core.clock`; with a
`SimulatedClock` the device keeps step with a frame loop on that clock — call `wake()` after the clock moved);
`realtime=False` returns a report on every read, each covering one sample period of device time (tests,
benchmarks). `transfers` counts the transfers handed to the host, `due()` says whether a report is ready now.

Faults, by report index n (0 = first report after START): `faults={n: kind}` with kind
"short" (a 7-byte transfer), "garbage" (32 bytes with a wrong id), "drop" (the report is lost: a
sequence gap), "lift" (sensor 1 reads nothing: slip), "duplicate" (the report is sent twice, the same bytes) or
"unplug" (the device vanishes before report n) or "hang" (from report n on the endpoint sends nothing while GET_INFO
still says running, as a firmware whose report path hung; a START counts reports from 0 again, so with n > 0 a
restart revives it for n reports, with n = 0 it stays silent).
`unplug()` / `replug()` do the same from any thread; `replug_after_s` replugs by itself.
"""

from __future__ import annotations

import array
import errno
import random
import threading
import time
from collections.abc import Callable
from types import SimpleNamespace

import numpy as np
import usb.backend
import usb.core

from antarium.core.clock import Clock
from antarium.locomotion.trackball import protocol as P
from antarium.locomotion.trackball.config import TrackballConfig

LIBUSB_ERROR_NO_DEVICE = -4
LIBUSB_ERROR_TIMEOUT = -7
LIBUSB_ERROR_PIPE = -9
FAULT_KINDS = ("short", "garbage", "drop", "lift", "duplicate", "unplug", "hang")
#: tolerance (s) when comparing clock readings with report ends, so that a frame loop's slots on a period
#: that is a multiple of the report period meet the reports exactly despite rounding
_TIME_EPS_S = 1e-9

Motion = Callable[[float], "tuple[float, float, float] | np.ndarray"]


def constant(omega: tuple[float, float, float]) -> Motion:
    """A ball turning at a constant angular velocity (rad/s, dome frame)."""
    w = np.asarray(omega, dtype=float)
    return lambda t: w


def segments(parts: list[tuple[float, tuple[float, float, float]]]) -> Motion:
    """Piecewise-constant angular velocity: [(duration_s, omega rad/s), ...]; still after the last."""
    ends = np.cumsum([d for d, _ in parts])
    omegas = [np.asarray(w, dtype=float) for _, w in parts]
    still = np.zeros(3)

    def motion(t: float) -> np.ndarray:
        i = int(np.searchsorted(ends, t, side="right"))
        return omegas[i] if i < len(omegas) else still

    return motion


def walk(speed: float = 0.03, turn_rate: float = 0.5, radius: float = 0.05, period_s: float = 4.0) -> Motion:
    """An ant walking forward at `speed` (m/s) while weaving: yaw rate `turn_rate` * sin(2 pi t / period) rad/s.

    Walking forward (+x) turns the ball about -y (its top moves backwards); the ant turning left
    (counter-clockwise) turns the ball clockwise: omega_z = -yaw rate.
    """

    def motion(t: float) -> np.ndarray:
        return np.array([0.0, -speed / radius, -turn_rate * np.sin(2 * np.pi * t / period_s)])

    return motion


class Turns:
    """Motion for calibration: `schedule` whole turns about an axis in a device-time window; still otherwise."""

    def __init__(self) -> None:
        self._start, self._end, self._omega = 0.0, 0.0, np.zeros(3)

    def schedule(self, start: float, axis: tuple[float, float, float], turns: float, duration: float) -> float:
        """Turn `turns` times about unit `axis` from device time `start` (s) for `duration` s; returns the end."""
        self._omega = np.asarray(axis, dtype=float) * 2 * np.pi * turns / duration
        self._start, self._end = start, start + duration
        return self._end

    def __call__(self, t: float) -> np.ndarray:
        return self._omega if self._start <= t < self._end else np.zeros(3)


def _no_device() -> usb.core.USBError:
    return usb.core.USBError("No such device (it may have been disconnected)", LIBUSB_ERROR_NO_DEVICE, errno.ENODEV)


def _stall(why: str) -> usb.core.USBError:
    return usb.core.USBError(f"Pipe error (request stalled: {why})", LIBUSB_ERROR_PIPE, errno.EPIPE)


class EmulatedTrackball(usb.backend.IBackend):
    """A pyusb backend holding one emulated trackball (see the module docstring)."""

    def __init__(
        self,
        motion: Motion | None = None,
        truth: TrackballConfig | None = None,
        realtime: bool = True,
        faults: dict[int, str] | None = None,
        replug_after_s: float | None = None,
        max_speed: float = 6.35,
        seed: int = 0,
        clock: Clock | None = None,
    ) -> None:
        super().__init__()
        self.truth = truth or TrackballConfig()
        self.motion = motion or walk(radius=self.truth.ball_radius)
        self.realtime = realtime
        self._clock_now = clock.now if clock is not None else time.monotonic
        self.transfers = 0
        self.faults = dict(faults or {})
        bad = {k: v for k, v in self.faults.items() if v not in FAULT_KINDS}
        if bad:
            raise ValueError(f"unknown emulated trackball fault(s) {bad}; allowed: {', '.join(FAULT_KINDS)}")
        self.replug_after_s = replug_after_s
        self.max_speed = max_speed  # m/s of surface speed a sensor tracks; above it the overflow flag is set
        self._rng = random.Random(seed)
        self._solver = self.truth.solver()
        self._cond = threading.Condition()
        self._plugged = True
        self._generation = 1
        self._unplugged_at: float | None = None
        self._reset_device()
        self._describe()

    # --- the emulated hardware -------------------------------------------------------------------
    def _reset_device(self) -> None:
        self.rate_hz = P.MAX_RATE_HZ
        self.resolution_cpi = self.truth.resolution_cpi
        self.running = False
        self._seq = 0
        self._index = 0  # report index since START (the key of `faults`)
        self._t_dev = 0.0  # device time of the end of the last report (s)
        self._t0 = 0.0  # clock time of START (realtime)
        self._remainder = np.zeros(2 * P.N_SENSORS)
        self._repeat: bytes | None = None  # a report sent again on the next read ("duplicate" fault)

    def _describe(self) -> None:
        self._dev_desc = SimpleNamespace(
            bLength=18, bDescriptorType=1, bcdUSB=0x0200, bDeviceClass=0, bDeviceSubClass=0, bDeviceProtocol=0,
            bMaxPacketSize0=64, idVendor=self.truth.vendor_id, idProduct=self.truth.product_id, bcdDevice=0x0100,
            iManufacturer=0, iProduct=0, iSerialNumber=0, bNumConfigurations=1,
            address=self._generation, bus=1, port_number=1, port_numbers=(1,), speed=2,
        )
        self._cfg_desc = SimpleNamespace(
            bLength=9, bDescriptorType=2, wTotalLength=25, bNumInterfaces=1, bConfigurationValue=1,
            iConfiguration=0, bmAttributes=0x80, bMaxPower=50, extra_descriptors=[],
        )
        self._intf_desc = SimpleNamespace(
            bLength=9, bDescriptorType=4, bInterfaceNumber=0, bAlternateSetting=0, bNumEndpoints=1,
            bInterfaceClass=P.INTERFACE_CLASS_VENDOR, bInterfaceSubClass=0, bInterfaceProtocol=0, iInterface=0,
            extra_descriptors=[],
        )
        self._ep_desc = SimpleNamespace(
            bLength=7, bDescriptorType=5, bEndpointAddress=P.ENDPOINT_IN, bmAttributes=0x03,
            wMaxPacketSize=P.REPORT_SIZE, bInterval=1, bRefresh=0, bSynchAddress=0, extra_descriptors=[],
        )

    def unplug(self) -> None:
        """Pull the cable: every open handle fails with ENODEV, enumeration finds nothing."""
        with self._cond:
            self._plugged = False
            self._unplugged_at = time.monotonic()
            self._cond.notify_all()

    def replug(self) -> None:
        """Plug it back: a fresh device (new address, stopped, seq 0)."""
        with self._cond:
            if not self._plugged:
                self._plugged = True
                self._generation += 1
                self._reset_device()
                self._describe()
                self._cond.notify_all()

    def device_time(self) -> float:
        """Device time (s since START) at the end of the latest report."""
        with self._cond:
            return self._t_dev

    def now(self) -> float:
        """Device time now (s since START) on the device's clock (realtime; 0 before START)."""
        with self._cond:
            return self._clock_now() - self._t0 if self.running else 0.0

    def due(self) -> bool:
        """A realtime device: whether a report is ready to be read now."""
        with self._cond:
            return (self._plugged and self._sending() and self.realtime
                    and self._clock_now() - self._t0 >= self._t_dev + 1.0 / self.rate_hz - _TIME_EPS_S)

    def _sending(self) -> bool:
        """Whether reports come (called with the lock held): started, and the report path not hung."""
        return self.running and self.faults.get(self._index) != "hang"

    def wake(self) -> None:
        """The injected clock moved on: a waiting read looks at it again now."""
        with self._cond:
            self._cond.notify_all()

    @property
    def plugged(self) -> bool:
        with self._cond:
            self._auto_replug()
            return self._plugged

    def _auto_replug(self) -> None:
        if (not self._plugged and self.replug_after_s is not None
                and time.monotonic() - self._unplugged_at >= self.replug_after_s):
            self._plugged = True
            self._generation += 1
            self._reset_device()
            self._describe()

    def _check(self, handle: SimpleNamespace) -> None:
        self._auto_replug()
        if not self._plugged or handle.generation != self._generation:
            raise _no_device()

    def _counts(self, t0: float, t1: float, lift: bool) -> tuple[tuple[int, ...], tuple[bool, bool]]:
        """Integer counts of each sensor axis for the device-time interval [t0, t1] (the motion's exact rotation,
        or the midpoint rule)."""
        dt = t1 - t0
        exact = getattr(self.motion, "rotation", None)
        if exact is not None:
            rotation = np.asarray(exact(t0, t1), dtype=float)
        else:
            rotation = np.asarray(self.motion(0.5 * (t0 + t1)), dtype=float) * dt
        metres = self._solver.readings(rotation)
        scale = self.resolution_cpi / self.truth.resolution_cpi
        cpmm = np.array([c * scale for s in self.truth.sensors for c in s.counts_per_mm])
        signs = np.array([g for s in self.truth.sensors for g in s.signs])
        exact = metres * 1e3 * cpmm * signs + self._remainder
        if lift:
            exact[2:4] = self._remainder[2:4]
        counts = np.trunc(exact)
        self._remainder = exact - counts
        speed = np.abs(metres) / max(dt, 1e-9)
        overflow = (bool(speed[0:2].max() > self.max_speed), bool(speed[2:4].max() > self.max_speed))
        return tuple(int(c) for c in counts), overflow

    def _next_report(self, handle: SimpleNamespace, timeout_ms: int) -> bytes | None:
        """The next transfer's bytes (called with the lock held); None on timeout."""
        if self._repeat is not None:  # a "duplicate" fault: the previous report again
            data, self._repeat = self._repeat, None
            return data
        period = 1.0 / self.rate_hz
        if self.realtime:
            deadline = time.monotonic() + timeout_ms / 1000.0 if timeout_ms else None
            while True:
                self._check(handle)
                now = self._clock_now() - self._t0
                if self._sending() and now >= self._t_dev + period - _TIME_EPS_S:
                    # all whole periods elapsed since the last report go into this one
                    t1 = self._t_dev + period * int((now - self._t_dev) / period + _TIME_EPS_S * self.rate_hz)
                    break
                wait = (self._t_dev + period - now) if self._sending() else 0.05
                if deadline is not None:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        return None
                    wait = min(wait, left)
                self._cond.wait(max(wait, 0.0))
        else:
            if not self._sending():
                return None
            t1 = self._t_dev + period
        fault = self.faults.get(self._index)
        if fault == "unplug":
            del self.faults[self._index]
            self._plugged = False
            self._unplugged_at = time.monotonic()
            raise _no_device()
        self._index += 1
        counts, overflow = self._counts(self._t_dev, t1, lift=fault == "lift")
        self._t_dev = t1
        report = P.Report(self._seq, int(round(t1 * 1e6)), counts, (100, 0 if fault == "lift" else 100), overflow)
        self._seq = (self._seq + 1) & 0xFFFFFFFF
        if fault == "drop":
            return self._next_report(handle, timeout_ms)
        data = P.encode_report(report)
        if fault == "duplicate":
            self._repeat = data
        if fault == "short":
            return data[:7]
        if fault == "garbage":
            return bytes(self._rng.randrange(256) for _ in range(P.REPORT_SIZE - 1)) + b"\x00"
        return data

    # --- IBackend ------------------------------------------------------------------------------
    def enumerate_devices(self):
        with self._cond:
            self._auto_replug()
            if self._plugged:
                return [SimpleNamespace(generation=self._generation)]
            return []

    def get_parent(self, dev):
        return None

    def get_device_descriptor(self, dev):
        return self._dev_desc

    def get_configuration_descriptor(self, dev, config):
        if config != 0:
            raise IndexError(f"Invalid configuration index {config}")
        return self._cfg_desc

    def get_interface_descriptor(self, dev, intf, alt, config):
        if config != 0 or intf != 0:
            raise IndexError(f"Invalid interface index {intf}")
        if alt != 0:
            raise IndexError(f"Invalid alternate setting index {alt}")
        return self._intf_desc

    def get_endpoint_descriptor(self, dev, ep, intf, alt, config):
        if (config, intf, alt, ep) != (0, 0, 0, 0):
            raise IndexError(f"Invalid endpoint index {ep}")
        return self._ep_desc

    def open_device(self, dev):
        with self._cond:
            handle = SimpleNamespace(generation=dev.generation)
            self._check(handle)
            return handle

    def close_device(self, dev_handle):
        return None

    def set_configuration(self, dev_handle, config_value):
        with self._cond:
            self._check(dev_handle)
            if config_value not in (0, 1):
                raise _stall(f"configuration {config_value} does not exist")

    def get_configuration(self, dev_handle):
        with self._cond:
            self._check(dev_handle)
            return 1

    def set_interface_altsetting(self, dev_handle, intf, altsetting):
        with self._cond:
            self._check(dev_handle)
            if (intf, altsetting) != (0, 0):
                raise _stall(f"interface {intf} alternate setting {altsetting} does not exist")

    def claim_interface(self, dev_handle, intf):
        with self._cond:
            self._check(dev_handle)

    def release_interface(self, dev_handle, intf):
        with self._cond:
            self._check(dev_handle)

    def is_kernel_driver_active(self, dev_handle, intf):
        return False

    def clear_halt(self, dev_handle, ep):
        with self._cond:
            self._check(dev_handle)

    def intr_read(self, dev_handle, ep, intf, buff, timeout):
        with self._cond:
            self._check(dev_handle)
            if ep != P.ENDPOINT_IN:
                raise _stall(f"endpoint 0x{ep:02x} is not an IN endpoint")
            data = self._next_report(dev_handle, timeout)
            if data is None:
                raise usb.core.USBTimeoutError("Operation timed out", LIBUSB_ERROR_TIMEOUT, errno.ETIMEDOUT)
            buff[: len(data)] = array.array("B", data)
            self.transfers += 1
            return len(data)

    def ctrl_transfer(self, dev_handle, bmRequestType, bRequest, wValue, wIndex, data, timeout):
        with self._cond:
            self._check(dev_handle)
            if wIndex != 0:
                raise _stall(f"wIndex {wIndex} is not interface 0")
            if bmRequestType == P.REQUEST_TYPE_IN and bRequest == P.REQ_GET_INFO:
                info = P.encode_info(
                    P.Info(P.PROTOCOL_VERSION, P.N_SENSORS, self.rate_hz, self.resolution_cpi, self.running)
                )
                n = min(len(data), len(info))
                data[:n] = array.array("B", info[:n])
                return n
            if bmRequestType != P.REQUEST_TYPE_OUT:
                raise _stall(f"request type 0x{bmRequestType:02x} request 0x{bRequest:02x} not supported")
            if bRequest == P.REQ_START:
                self.running = True
                self._seq = 0
                self._index = 0
                self._t_dev = 0.0
                self._t0 = self._clock_now()
                self._remainder[:] = 0.0
                self._repeat = None
            elif bRequest == P.REQ_STOP:
                self.running = False
            elif bRequest == P.REQ_SET_RATE:
                if not P.RATE_RANGE[0] <= wValue <= P.RATE_RANGE[1]:
                    raise _stall(f"rate {wValue} Hz outside {P.RATE_RANGE}")
                self.rate_hz = wValue
            elif bRequest == P.REQ_SET_RESOLUTION:
                if not P.RESOLUTION_RANGE[0] <= wValue <= P.RESOLUTION_RANGE[1]:
                    raise _stall(f"resolution {wValue} cpi outside {P.RESOLUTION_RANGE}")
                self.resolution_cpi = wValue
            else:
                raise _stall(f"unknown request 0x{bRequest:02x}")
            self._cond.notify_all()
            return 0
